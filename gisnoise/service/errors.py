"""One table from the core's exceptions to HTTP statuses, and the error handlers.

Every error response has the same JSON body (:class:`api.models.ErrorBody`):
``{"detail": "one line naming the field and the value", "field": "grid.resolution_m"}``,
plus ``errors`` listing every invalid field of a rejected request body.
"""

from __future__ import annotations

import logging
import math
import re
import struct
import tempfile
import zipfile
import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
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
from gisnoise.flight import GROUND_HINT_CLI
from gisnoise.limits import WorkLimitError
from gisnoise.service import models as _models
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse

__all__ = ["STATUS", "ApiError", "status_for", "error_body", "install_handlers", "scrub_paths", "UNREADABLE",
           "allowed_methods", "request_fields", "request_words", "CLI_WORDS", "core_detail"]

log = logging.getLogger(__name__)

STATUS: dict[type[BaseException], int] = {
    GridTooLargeError: 413,
    WorkLimitError: 413,
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
    UnicodeError: 422,
    zlib.error: 422,
    struct.error: 422,
    zipfile.BadZipFile: 422,
    EOFError: 422,
}
"""HTTP status of each core exception; the most specific class in the MRO wins."""


class ApiError(Exception):
    """An error of the service itself (not found, conflict, auth, size), with the field it is about."""

    def __init__(self, status: int, message: str, *, field: str | None = None,
                 headers: dict[str, str] | None = None, scrub: bool = True) -> None:
        super().__init__(message)
        self.status = status
        self.field = field
        self.headers = headers
        self.scrub = scrub
        """False: the message quotes the client's own input (a zip member's name, an absolute one in the temporary folder say), answered as
        it is, not cut as a server path."""


def status_for(exc: BaseException) -> int:
    """The HTTP status of a core exception from :data:`STATUS` (500 when it is not a known error)."""
    for cls in type(exc).__mro__:
        if cls in STATUS:
            return STATUS[cls]
    return 500


UNREADABLE: tuple[type[BaseException], ...] = (UnicodeError, zlib.error, struct.error, zipfile.BadZipFile, EOFError)
"""Errors of decoding malformed input (text encoding, deflate data, binary headers): 422, never 500."""


def scrub_paths(message: str, roots: Iterable[str | object] = (), *, any_path: bool = True) -> str:
    """``message`` without the server's folders (the data folder, the temporary folder, ``roots``).

    ``any_path``: also cut any other absolute file path down to its file name (not for messages
    naming URL paths of the service).
    """
    out = message
    for root in [*roots, tempfile.gettempdir()]:
        r = str(root).rstrip("/")
        if len(r) > 1:
            out = out.replace(r + "/", "").replace(r, "")
    if not any_path:
        return out
    # any other absolute path of this machine: keep the file name only
    return re.sub(r"(?<![\w.:/])/(?:[^\s'\"/:]+/)+([^\s'\"/:]+)", r"\1", out)


# ------------------------------------------------------------------ the core's words -> the request's
CLI_WORDS: tuple[tuple[str, str], ...] = (
    (GROUND_HINT_CLI, "ground_h_m"),
    ("--ground-height M (field ground_h_m)", "ground_h_m"),
    ("--ground-height", "ground_h_m"),
    ("--power-w W, field power_w", "trajectory.power_w"),
    ("--power-w W, or power_w", "trajectory.power_w"),
    ("--power-w W", "trajectory.power_w"),
    ("--geoid-undulation N, field geoid_undulation_m", "trajectory.geoid_undulation_m"),
    ("no path from --from to --to", "no path from start to goal"),
    ("--from and --to", "start and goal"),
    ("give --margin", "give grid.margin_m"),
)
"""What the core's messages say to the command line's user (its options) -> what a request says instead (its
fields), longest phrase first: a request has no ``--dem`` or ``--from``, and the client needs the field to set."""


def request_words(message: str) -> str:
    """``message`` with the command line's options of :data:`CLI_WORDS` named as the request's fields."""
    for said, field in CLI_WORDS:
        message = message.replace(said, field)
    return message


@contextmanager
def request_fields(table: Mapping[str, str], *, default: str | None = None) -> Iterator[None]:
    """Core errors raised inside name the request's field: the core's field (an argument or an option of the
    command line) -> the request's by ``table``; a field the table lacks becomes ``default`` (when given) or
    stays (it is the request's already)."""
    try:
        yield
    except GisnoiseError as exc:
        fld = exc.field or ""
        exc.field = table.get(fld, fld if default is None else default) or default
        raise


def core_detail(message: str, field: str | None) -> str:
    """The ``detail`` of a core error: its message in the request's words (:func:`request_words`), led by the
    field when the message does not name it (``trajectory.data_base64: x.ulg: not a readable ULog``)."""
    msg = request_words(message)
    if field:
        leaf = re.split(r"[.\[]", field)[-1] or field
        if not re.search(rf"(?<![\w-]){re.escape(leaf)}(?![\w-])", msg):
            msg = f"{field}: {msg}"
    return msg


def allowed_methods(app: FastAPI, path: str) -> list[str]:
    """Every method the OpenAPI schema of ``app`` states for ``path`` (the ``Allow`` header of a 405).

    Several routes share a path (``GET`` and ``DELETE /cards/{card_id}``); the router's own
    405 names only the first, so the schema, which lists them all, is the source.
    """
    table = getattr(app.state, "allow_table", None)
    if table is None:
        table = []
        for template, ops in app.openapi().get("paths", {}).items():
            rx = re.escape(template)
            rx = re.sub(r"\\\{[^}]*:path\\\}", ".+", rx)
            rx = re.sub(r"\\\{[^}]*\\\}", "[^/]+", rx)
            table.append((re.compile(rx), "{" not in template,
                          {m.upper() for m in ops if m.lower() in _HTTP_METHODS}))
        app.state.allow_table = table
    # a literal path ('/jobs/fit') is its own resource, not an instance of '/jobs/{job_id}'
    matching = [(literal, ms) for rx, literal, ms in table if rx.fullmatch(path)]
    if any(literal for literal, _ in matching):
        matching = [(literal, ms) for literal, ms in matching if literal]
    methods: set[str] = set()
    for _, ms in matching:
        methods |= ms
    if "GET" in methods:
        methods.add("HEAD")
    return sorted(methods)


_HTTP_METHODS = {"get", "put", "post", "delete", "patch", "head", "options", "trace"}


def error_body(message: str, field: str | None, errors: Sequence[dict[str, Any]] = ()) -> dict[str, Any]:
    """The JSON body of every error response."""
    body: dict[str, Any] = {"detail": message, "field": field}
    if errors:
        body["errors"] = list(errors)
    return body


_TRAJECTORY_TAGS = {"csv", "columns", "rows", "geojson", "waypoints", "log"}
_MODEL_NAMES = {n for n, v in vars(_models).items() if isinstance(v, type) and issubclass(v, BaseModel)}


def _is_tag(part: str, before: Sequence[str]) -> bool:
    """A union member's name that pydantic puts in the location (not a field the client wrote); ``before``: the
    location up to it."""
    if part == "[key]" or part.startswith(("constrained-", "function-")) or part in ("str", "float", "int", "bool"):
        return True
    if part in _MODEL_NAMES:  # a model class name (CardDocument, ...)
        return True
    # the format tag of a trajectory: the request's trajectory, or one of a comparison's routes
    return part in _TRAJECTORY_TAGS and (before[-1:] == ["trajectory"] or
                                         (before[-2:-1] == ["routes"] and before[-1].isdigit()))


def _loc_field(loc: Sequence[Any]) -> str:
    parts: list[str] = []
    before: list[str] = []
    for p in loc:
        s = str(p)
        if not _is_tag(s, before):
            parts.append(s)
        before.append(s)
    if parts and parts[0] in ("body", "query", "path", "header", "cookie"):
        where, rest = parts[0], parts[1:]
        # a tagged union adds the tag name to the location; users know the field, not the tag
        return ".".join(rest) if rest else where
    return ".".join(parts)


_STORE_NAMES = {"card_id": "id"}
"""Path parameter -> the name a store's errors give it (the card store says ``id``, as a card document does):
an error about the parameter names it as the URL template does (``/cards/{card_id}``)."""

_COMPARISONS = {"greater_than", "greater_than_equal", "less_than", "less_than_equal", "multiple_of"}


def _validation_errors(exc: RequestValidationError) -> list[dict[str, Any]]:
    out = []
    raw = list(exc.errors())
    # a union member that does not fit the input's type (a card id string where an inline card object was sent)
    # is noise beside the errors of the member that does fit: keep the deeper ones
    flds = [_loc_field(tuple(e.get("loc", ()))) for e in raw]
    raw = [e for e, f in zip(raw, flds, strict=True)
           if not (str(e.get("type", "")).endswith("_type") and any(o.startswith(f + ".") for o in flds))]
    for e in raw:
        loc = tuple(e.get("loc", ()))
        fld = _loc_field(loc)
        if e.get("type") == "json_invalid":
            fld = "body"
        msg = str(e.get("msg", "invalid")).removeprefix("Value error, ")
        got = e.get("input")
        if e.get("type") in _COMPARISONS and isinstance(got, float) and not math.isfinite(got):
            msg, e["type"] = "Input should be a finite number", "finite_number"  # NaN is not 'above 100000'

        if e.get("type") != "missing" and isinstance(got, (int, float, str)) and len(repr(got)) <= 40:
            msg += f", got {got!r}"  # the bad value, as every other refusal names it
        out.append({"field": fld, "message": msg, "type": str(e.get("type", ""))})
    return out


def install_handlers(app: FastAPI) -> None:
    """Register the handlers turning every known error into the common error body."""

    def roots() -> list[str]:
        st = getattr(app.state, "gisnoise", None)
        if st is None:
            return []
        d = st.settings.data_dir
        return [str(d.resolve()), str(d)]

    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSONResponse:
        fld, msg = exc.field, str(exc)
        for param, said in _STORE_NAMES.items():
            if fld == said and param in request.path_params:
                fld, msg = param, (param + msg[len(said):] if msg.startswith(f"{said}:") else msg)
        if exc.scrub:
            msg = scrub_paths(msg, roots(), any_path=False)
        return JSONResponse(error_body(msg, fld), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(GisnoiseError)
    async def _core_error(request: Request, exc: GisnoiseError) -> JSONResponse:
        status = status_for(exc)
        fld = exc.field or "body"
        return JSONResponse(error_body(core_detail(scrub_paths(str(exc), roots()), fld), fld), status_code=status)

    @app.exception_handler(Exception)
    async def _last_resort(request: Request, exc: Exception) -> JSONResponse:
        """Nothing escapes as a bare 500: unreadable input is 422, anything else a 500 without details."""
        fld = getattr(exc, "field", None)
        if isinstance(exc, UNREADABLE):
            msg = scrub_paths(f"{fld or 'body'}: the input cannot be read ({type(exc).__name__}: {exc})", roots())
            return JSONResponse(error_body(msg, fld or "body"), status_code=422)
        log.error("%s %s crashed", request.method, request.url.path, exc_info=exc)
        return JSONResponse(error_body(f"{fld or 'request'}: internal error ({type(exc).__name__})",
                                       fld or "request"), status_code=500)

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
            allow = ", ".join(allowed_methods(app, request.url.path)) or (getattr(exc, "headers", None) or {}).get(
                "Allow", "")
            return JSONResponse(error_body(detail, "method"), status_code=405, headers={"Allow": allow})
        elif fld and not detail.startswith(fld):
            detail = f"{fld}: {detail}"
        return JSONResponse(error_body(detail, fld or "request"), status_code=exc.status_code,
                            headers=getattr(exc, "headers", None))
