"""The gisnoise web service (FastAPI): a thin face on the core library.

``create_app(settings)`` builds the application; ``gisnoise serve`` runs it
under uvicorn.  The core (:mod:`gisnoise`) never imports this package.
"""

from __future__ import annotations

from gisnoise.service.app import create_app
from gisnoise.service.settings import Settings, get_settings

__all__ = ["create_app", "Settings", "get_settings"]
