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
        self.problems = None

    def initProcessing(self):  # noqa: N802 - QGIS API
        self.problems = _report_problems(None)
        if self.provider is None:
            from .provider import GisnoiseProvider

            self.provider = GisnoiseProvider()
            QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802 - QGIS API
        self.initProcessing()
        if self.problems and self.iface is not None:
            _report_problems(self.iface, self.problems)

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None


def _report_problems(iface, text=None):
    """Check what the core needs; log the plain message (and show it in the message bar with a GUI)."""
    from qgis.core import Qgis, QgsMessageLog

    if text is None:
        from ._core import load_problems

        text = load_problems()
        if text:
            QgsMessageLog.logMessage(text, "gisnoise", Qgis.Warning)
    if text and iface is not None:
        iface.messageBar().pushMessage("gisnoise", text, level=Qgis.Warning, duration=0)
    return text
