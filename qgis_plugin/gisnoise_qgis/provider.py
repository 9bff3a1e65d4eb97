"""The Processing provider "Drone noise (gisnoise)": one algorithm per operation."""

from __future__ import annotations

import os

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

PROVIDER_ID = "gisnoise"
ICON_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "icon.svg")


class GisnoiseProvider(QgsProcessingProvider):
    """Holds the noise map, fit, diagnose and layout-design algorithms."""

    def id(self):
        return PROVIDER_ID

    def name(self):
        return "Drone noise (gisnoise)"

    def longName(self):  # noqa: N802 - QGIS API
        from . import _core

        version = "unknown version"
        init = os.path.join(_core.EXT_DIR, "gisnoise", "__init__.py")
        if os.path.exists(init):
            with open(init, encoding="utf-8") as fh:
                for line in fh:
                    if line.startswith("__version__"):
                        version = line.split("=", 1)[1].strip().strip("\"'")
        return f"Drone noise (gisnoise {version})"

    def icon(self):
        return QIcon(ICON_PATH)

    def svgIconPath(self):  # noqa: N802 - QGIS API
        return ICON_PATH

    def loadAlgorithms(self):  # noqa: N802 - QGIS API
        from .algorithms import ALGORITHMS

        for cls in ALGORITHMS:
            self.addAlgorithm(cls())
