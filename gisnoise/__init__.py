"""gisnoise: noise contours of small electric VTOL drones from measurements to maps.

The core library.  It never imports FastAPI or QGIS; the CLI (:mod:`gisnoise.cli`),
the service (``api/``) and the QGIS plugin (``qgis_plugin/``) are thin faces on it.
"""

from __future__ import annotations

__version__ = "0.1.0"

from gisnoise.errors import GisnoiseError  # noqa: E402

__all__ = ["GisnoiseError", "__version__"]
