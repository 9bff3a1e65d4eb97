"""One table from the core's exceptions to HTTP statuses, and the error handlers.

Every error response has the same JSON body (:class:`api.models.ErrorBody`):
``{"detail": "one line naming the field and the value", "field": "grid.resolution_m"}``,
plus ``errors`` listing every invalid field of a rejected request body.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel
from starlette.exceptions import HTTPException as StarletteHTTPException

from gisnoise.errors import (
    CampaignError,
    Cancelled,
    CardError,
    CRSError,
    DesignError,
    FitError,
    GisnoiseError,
    GridTooLargeError,
    InputError,
    InvalidGridError,
    MissingColumnError,
    NotIdentifiableError,
    SchemaVersionError,
    TrajectoryError,
)
from gisnoise.service import models as _models
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse

__all__ = ["STATUS", "ApiError", "status_for", "error_body", "install_handlers"]

log = logging.getLogger(__name__)

STATUS: dict[type[BaseException], int] = {
    GridTooLargeError: 413,
    InvalidGridError: 422,
    CRSError: 422,
    SchemaVersionError: 422,
    CardError: 422,
    MissingColumnError: 422,
    TrajectoryError: 422,
    CampaignError: 422,
    DesignError: 422,
    InputError: 422,
    NotIdentifiableError: 422,
    FitError: 422,
    Cancelled: 409,
    GisnoiseError: 400,
    MemoryError: 413,
}
"""HTTP status of each core exception; the most specific class in the MRO wins."""


class ApiError(Exception):
    """An error of the service itself (not found, conflict, auth, size), with the field it is about."""

    def __init__(self, status: int, message: str, *, field: str | None = None,
                 headers: dict[str, str] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.field = field
        self.headers = headers


def status_for(exc: BaseException) -> int:
    """The HTTP status of a core exception from :data:`STATUS` (500 when it is not a known error)."""
    for cls in type(exc).__mro__:
        if cls in STATUS:
            return STATUS[cls]
    return 500


def error_body(message: str, field: str | None, errors: Sequence[dict[str, Any]] = ()) -> dict[str, Any]:
    """The JSON body of every error response."""
    body: dict[str, Any] = {"detail": message, "field": field}
    if errors:
        body["errors"] = list(errors)
    return body


_TRAJECTORY_TAGS = {"csv", "columns", "rows", "geojson", "waypoints"}
_MODEL_NAMES = {n for n, v in vars(_models).items() if isinstance(v, type) and issubclass(v, BaseModel)}


def _is_tag(part: str, previous: str | None) -> bool:
    """A union member's name that pydantic puts in the location (not a field the client wrote)."""
    if part == "[key]" or part.startswith(("constrained-", "function-")) or part in ("str", "float", "int", "bool"):
        return True
    if part in _MODEL_NAMES:  # a model class name (CardDocument, ...)
        return True
    return previous == "trajectory" and part in _TRAJECTORY_TAGS


def _loc_field(loc: Sequence[Any]) -> str:
    parts: list[str] = []
    previous = None
    for p in loc:
        s = str(p)
        if not _is_tag(s, previous):
            parts.append(s)
        previous = s
    if parts and parts[0] in ("body", "query", "path", "header", "cookie"):
        where, rest = parts[0], parts[1:]
        # a tagged union adds the tag name to the location; users know the field, not the tag
        return ".".join(rest) if rest else where
    return ".".join(parts)


def _validation_errors(exc: RequestValidationError) -> list[dict[str, Any]]:
    out = []
    for e in exc.errors():
        loc = tuple(e.get("loc", ()))
        fld = _loc_field(loc)
        if e.get("type") == "json_invalid":
            fld = "body"
        msg = str(e.get("msg", "invalid"))
        out.append({"field": fld, "message": msg, "type": str(e.get("type", ""))})
    return out


def install_handlers(app: FastAPI) -> None:
    """Register the handlers turning every known error into the common error body."""

    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSONResponse:
        return JSONResponse(error_body(str(exc), exc.field), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(GisnoiseError)
    async def _core_error(request: Request, exc: GisnoiseError) -> JSONResponse:
        status = status_for(exc)
        return JSONResponse(error_body(str(exc), exc.field or "body"), status_code=status)

    @app.exception_handler(MemoryError)
    async def _memory(request: Request, exc: MemoryError) -> JSONResponse:
        return JSONResponse(error_body("the request needs more memory than the server has; use a coarser "
                                       "grid.resolution_m or a smaller grid.margin_m", "grid.resolution_m"),
                            status_code=413)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = _validation_errors(exc)
        first = errors[0] if errors else {"field": "body", "message": "invalid request"}
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        return JSONResponse(error_body(f"{first['field']}: {first['message']}{more}", first["field"], errors),
                            status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        fld = {404: "path", 405: "method", 413: "body", 401: "X-API-Key", 403: "X-API-Key"}.get(exc.status_code)
        detail = str(exc.detail)
        if exc.status_code == 404 and detail == "Not Found":
            detail = f"path: no such resource {request.url.path!r}"
        elif exc.status_code == 405:
            detail = f"method: {request.method} is not allowed on {request.url.path!r}"
        elif fld and not detail.startswith(fld):
            detail = f"{fld}: {detail}"
        return JSONResponse(error_body(detail, fld or "request"), status_code=exc.status_code,
                            headers=getattr(exc, "headers", None))
