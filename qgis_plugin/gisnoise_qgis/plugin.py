"""The plugin object: registers the Processing provider and nothing else."""

from __future__ import annotations

from qgis.core import QgsApplication


class GisnoisePlugin:
    """Adds the "Drone noise (gisnoise)" provider to the Processing registry.

    ``initProcessing`` is called by QGIS (and by ``qgis_process``) without a
    GUI; ``initGui`` calls it too, as QGIS desktop expects.
    """

    def __init__(self, iface=None):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 - QGIS API
        if self.provider is None:
            from .provider import GisnoiseProvider

            self.provider = GisnoiseProvider()
            QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802 - QGIS API
        self.initProcessing()

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
