"""Dependencies shared by the routers: the service state and the API-key check."""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Annotated, Any

from fastapi import Depends, Request, Security
from fastapi.security import APIKeyHeader

from gisnoise.service.cardstore import CardStore
from gisnoise.service.errors import ApiError
from gisnoise.service.jobs import JobStore, WorkerPool
from gisnoise.service.settings import Settings

__all__ = ["State", "StateDep", "get_state", "require_key", "key_problem", "WRITE"]

_key_header = APIKeyHeader(name="X-API-Key", auto_error=False,
                           description="Needed for writes (uploads, jobs, deletes) when the service has keys.")


@dataclass
class State:
    settings: Settings
    cards: CardStore
    jobs: JobStore
    pool: WorkerPool
    basemap: Any = None  # gisnoise.service.basemap.Basemap served at /basemap, or None


def get_state(request: Request) -> State:
    return request.app.state.gisnoise


async def _state(request: Request) -> State:
    """:func:`get_state` as a dependency: ``async``, so FastAPI does not hop to a worker thread for it."""
    return get_state(request)


StateDep = Annotated[State, Depends(_state)]


def require_key(request: Request, key: str | None = Security(_key_header)) -> None:
    """Refuse a write without a valid ``X-API-Key`` when keys are configured (401 missing, 403 wrong)."""
    problem = key_problem(get_state(request).settings.api_keys, key)
    if problem is not None:
        raise problem


def key_problem(keys: list[str], key: str | None) -> ApiError | None:
    """The 401/403 error of a write with ``key`` (None: allowed); shared by the route check and the
    middleware that refuses uploads from their headers."""
    if not keys:
        return None
    if not key:
        return ApiError(401, "X-API-Key: this write needs an API key in the X-API-Key header", field="X-API-Key",
                        headers={"WWW-Authenticate": "APIKey"})
    if not any(hmac.compare_digest(key.encode(), k.encode()) for k in keys):
        return ApiError(403, "X-API-Key: the key is not valid", field="X-API-Key")
    return None


WRITE = [Depends(require_key)]
