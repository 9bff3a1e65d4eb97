"""The gisnoise web service: ``create_app(settings)`` builds the FastAPI application.

Run it with ``gisnoise serve`` (uvicorn).  OpenAPI at ``/docs`` and ``/openapi.json``.
"""

from __future__ import annotations

import logging
import re
import sqlite3
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import Depends, FastAPI, Request, params

from gisnoise import __version__
from gisnoise.service import routes_campaign, routes_cards, routes_contours, routes_jobs, routes_planning, routes_web
from gisnoise.service.basemap import open_basemap
from gisnoise.service.basemap import router as basemap_router
from gisnoise.service.cardstore import CardStore
from gisnoise.service.deps import State, key_problem
from gisnoise.service.errors import ApiError, install_handlers
from gisnoise.service.jobs import Handler, JobStore, WorkerPool
from gisnoise.service.limits import BodySizeLimit, KeyBeforeBody
from gisnoise.service.models import ErrorBody, MediaType
from gisnoise.service.responses import AsciiJSONResponse
from gisnoise.service.settings import Settings, get_settings
from gisnoise.service.storage import DataDirError, check_data_dir, install_storage_handlers
from gisnoise.service.timing import ServerTiming

__all__ = ["create_app", "ERROR_RESPONSES"]

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).resolve().parent / "static"

ERROR_RESPONSES: dict[int | str, dict] = {
    s: {"model": ErrorBody, "description": d}
    for s, d in [(400, "Bad request"), (401, "API key missing"), (403, "API key not valid"), (404, "Not found"),
                 (409, "Conflict"), (413, "Too large (body, upload or grid)"),
                 (415, "Body not sent as application/json"), (422, "Invalid input"),
                 (503, "The service's storage cannot be read or written now (field storage)"),
                 (507, "No space left on the device of the service's data (field storage)")]
}


async def single_query_values(request: Request) -> None:
    """Every query parameter of this API takes one value: a repeated one is refused (422), not half-read.

    ``async``: FastAPI runs a plain function dependency in a worker thread, a hop on every request.
    """
    seen: set[str] = set()
    for k, _ in request.query_params.multi_items():
        if k in seen:
            raise ApiError(422, f"{k}: given more than once in the query string", field=k)
        seen.add(k)


async def json_media_type(request: Request) -> None:
    """A body the operation reads as JSON must be sent as JSON: another ``Content-Type`` (or none) is 415 naming
    ``application/json``, not a 422 saying the body is 'not a valid dictionary' (FastAPI leaves such a body
    unparsed).  Forms and uploads (multipart) are not JSON bodies; ``+json`` types (``application/geo+json``) are.
    """
    route = request.scope.get("route")
    body = getattr(route, "body_field", None)
    if body is None or isinstance(body.field_info, params.Form):
        return
    given = request.headers.get("content-type")
    if given is None and not await request.body():
        return  # no body: the body's own validation names what is missing
    media = (given or "").split(";", 1)[0].strip().lower()
    if media == MediaType.json.value or (media.startswith("application/") and media.endswith("+json")):
        return
    said = f"{media!r}" if media else "none"
    raise ApiError(415, f"Content-Type: {said} is not read here; send the body as {MediaType.json.value}",
                   field="Content-Type", headers={"Accept-Post": MediaType.json.value})


def _handlers() -> dict[str, Handler]:
    """The job handler of each job kind."""
    return {"contours": routes_contours.run_contour_job, "fit": routes_campaign.run_fit_job,
            "diagnose": routes_campaign.run_diagnose_job}


def create_app(settings: Settings | None = None, *, start_workers: bool = True) -> FastAPI:
    """Build the application.

    Parameters
    ----------
    settings : Settings, optional
        Default: from the environment (``GISNOISE_*``).
    start_workers : bool
        Start the job worker threads with the application (tests may run jobs by hand).
    """
    settings = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        st: State = app.state.gisnoise
        settings.data_dir.mkdir(parents=True, exist_ok=True)
        try:
            n = st.cards.seed(settings.seed_cards_dir)
        except (ApiError, OSError) as exc:  # the storage refused the seed cards (a full disk): seeded next start
            log.error("the card store was not seeded: %s", exc)
            n = 0
        if n:
            log.info("card store seeded with %d cards", n)
        try:
            orphans = st.jobs.remove_orphans()
        except Exception as exc:
            if st.jobs.failure(exc) is None:
                raise
            log.error("cannot look for job folders without a job now: %s", exc)  # done at the next start
            orphans = 0
        if orphans:
            log.warning("removed %d job folder(s) without a job (left by a stop during a submission)", orphans)
        try:
            requeued = st.jobs.requeue_interrupted()
        except Exception as exc:
            failure = st.jobs.failure(exc)
            if failure is None:
                raise
            # the service starts and says it is failing; the workers re-queue before their first claim
            log.error("cannot re-queue the jobs interrupted by the last stop now (%s); the job workers will",
                      failure.reason)
            st.pool.requeue_first()
            requeued = 0
        if requeued:
            log.warning("%d job(s) interrupted by the last stop were re-queued", requeued)
        if start_workers:
            st.pool.start()
        try:
            yield
        finally:
            st.pool.stop()

    app = FastAPI(
        title="gisnoise",
        version=__version__,
        description="Noise contours of small electric VTOL drones: model cards, noise maps (GeoJSON, GeoTIFF), "
                    "fit and diagnose jobs. Errors: one JSON body naming the field. Writes need an `X-API-Key` "
                    "when the service has keys.",
        lifespan=lifespan,
        responses=ERROR_RESPONSES,
        dependencies=[Depends(single_query_values), Depends(json_media_type)],
        default_response_class=AsciiJSONResponse,
        docs_url=None,  # served below from the installed swagger-ui-bundle: no network needed
        redoc_url=None,
    )
    check_data_dir(settings.data_dir)  # one line naming the folder when it cannot be written
    try:
        jobs = JobStore(settings.db_path, settings.jobs_dir)
    except (OSError, sqlite3.Error) as exc:
        raise DataDirError(f"the job database {settings.db_path} cannot be opened or written "
                           f"({type(exc).__name__}: {exc})", field="GISNOISE_DATA_DIR") from None
    basemap = open_basemap(settings.basemap) if settings.basemap is not None else None
    app.state.gisnoise = State(settings=settings, cards=CardStore(settings.cards_dir), jobs=jobs,
                               pool=WorkerPool(jobs, _handlers(), settings.workers), basemap=basemap)
    install_handlers(app)
    install_storage_handlers(app)
    for r in (routes_cards.router, routes_contours.router, routes_jobs.router, routes_campaign.router,
              routes_planning.router, routes_web.router, basemap_router):
        app.include_router(r)
    routes_web.mount_static(app, STATIC_DIR)

    upload_paths = ("/jobs/fit", "/jobs/diagnose", "/layers")

    def limit_for(path: str) -> int:
        return settings.max_upload_bytes if path in upload_paths else settings.max_request_bytes

    app.add_middleware(BodySizeLimit, limit_for=limit_for)

    def refusal(method: str, path: str, query: str, key: str | None) -> tuple[int, str, dict[str, str]] | None:
        if not is_write(method, path, query):
            return None
        problem = key_problem(settings.api_keys, key)
        return None if problem is None else (problem.status, str(problem), problem.headers or {})

    app.add_middleware(KeyBeforeBody, refusal=refusal)  # runs before the body is read
    app.add_middleware(ServerTiming)  # outermost: Server-Timing total from the request's arrival
    return app


_WRITES = [(m, re.compile(p)) for m, p in (
    ("POST", r"/cards"), ("DELETE", r"/cards/[^/]+"), ("POST", r"/jobs/(contours|fit|diagnose)"),
    ("POST", r"/jobs/[^/]+/cancel"), ("DELETE", r"/jobs/[^/]+"), ("POST", r"/layers"))]
"""The writes (method, path) that need a key when the service has keys: refused from the headers."""

_TRUE = {"1", "true", "t", "yes", "y", "on"}
"""The query values a boolean parameter reads as true (pydantic's)."""


def is_write(method: str, path: str, query: str = "") -> bool:
    """Whether a request is a write that needs a key, from its method, path and query string alone (before its
    body): the operations of :data:`_WRITES`, and ``POST /contours?job=true``, which always queues a job.

    (``POST /contours`` without ``job`` becomes a job only when the map is large, which its body decides: that
    case is checked once the request is prepared.)
    """
    if any(m == method and rx.fullmatch(path) for m, rx in _WRITES):
        return True
    if method == "POST" and path == "/contours" and query:
        from urllib.parse import parse_qsl

        return any(k == "job" and v.strip().lower() in _TRUE for k, v in parse_qsl(query, keep_blank_values=True))
    return False
