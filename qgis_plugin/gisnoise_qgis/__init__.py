"""QGIS plugin "Drone noise (gisnoise)": the gisnoise core in the Processing toolbox.

QGIS calls :func:`classFactory`; everything else is imported lazily so that
loading QGIS costs nothing until the plugin is used.
"""


def classFactory(iface):  # noqa: N802 - name fixed by QGIS
    """Return the plugin instance (called by QGIS with its interface object)."""
    from .plugin import GisnoisePlugin

    return GisnoisePlugin(iface)
