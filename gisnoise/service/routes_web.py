"""The web page at ``/`` (Leaflet map), its static files, its config, the sample route and health."""

from __future__ import annotations

import json
from pathlib import Path

from fastapi import APIRouter, FastAPI, Response
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from gisnoise import __version__
from gisnoise.data import data_path
from gisnoise.errors import InputError
from gisnoise.service.basemap import TILE_URL
from gisnoise.service.deps import StateDep
from gisnoise.service.errors import ApiError
from gisnoise.service.models import Health, MediaType, WorkerHealth
from gisnoise.service.storage import LOW_SPACE_BYTES, NO_SPACE, free_bytes

router = APIRouter()

SAMPLE_ROUTE = data_path("routes")


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def index() -> FileResponse:
    return FileResponse(Path(__file__).resolve().parent / "static" / "index.html", media_type=MediaType.html.value)


@router.get("/docs", response_class=HTMLResponse, include_in_schema=False)
def docs() -> HTMLResponse:
    """The OpenAPI documentation (swagger-ui served by the service itself)."""
    from fastapi.openapi.docs import get_swagger_ui_html

    return get_swagger_ui_html(openapi_url="/openapi.json", title="gisnoise API",
                               swagger_js_url="/static/vendor/swagger-ui/swagger-ui-bundle.js",
                               swagger_css_url="/static/vendor/swagger-ui/swagger-ui.css",
                               swagger_favicon_url="/static/vendor/swagger-ui/favicon-32x32.png")


@router.get("/health", response_model=Health, tags=["service"], summary="Liveness, job workers, storage and queue",
            responses={503: {"model": Health, "description": "Failing: a job worker died or the storage fails "
                                                             "(`problems` says which)."}})
def health(state: StateDep) -> Response:
    """``ok`` (200), or ``failing`` (503) with one line per problem: a dead job worker, a job database that
    cannot be read or written (after a failed write, a small write tells whether it works again), job ends
    not written yet, less than 1 MiB free on the data folder's device."""
    problems: list[str] = []
    queued = running = None
    try:
        counts = state.jobs.counts()
        queued, running = counts["queued"], counts["running"]
    except Exception as exc:  # noqa: BLE001 - reported, whatever it is
        failure = state.jobs.failure(exc)
        problems.append(f"storage: {failure.reason}" if failure is not None else
                        f"storage: cannot read the job database ({type(exc).__name__}: {exc})")
    failure = state.jobs.check_writable()
    if failure is not None and f"storage: {failure.reason}" not in problems:
        problems.append(f"storage: {failure.reason}")
    started, alive = state.pool.workers()
    if alive < started:
        problems.append(f"workers: {started - alive} of {started} job worker(s) stopped; queued jobs are not run "
                        "until the service is restarted")
    unwritten = state.pool.unwritten
    if unwritten:
        problems.append(f"jobs: the end of {len(unwritten)} job(s) is not written yet (written as soon as the "
                        "storage takes it)")
    free = free_bytes(state.settings.data_dir)
    if free is not None and free < LOW_SPACE_BYTES:
        problems.append(f"storage: {NO_SPACE} of the data folder ({free} bytes free)")
    body = Health(status="failing" if problems else "ok", version=__version__, queued=queued, running=running,
                  workers=WorkerHealth(started=started, alive=alive), free_bytes=free, problems=problems)
    return Response(body.model_dump_json(), status_code=503 if problems else 200, media_type=MediaType.json.value)


@router.get("/config.json", tags=["service"], summary="Settings the web page needs",
            responses={200: {"content": {MediaType.json.value: {"schema": {"type": "object"}}}}})
def config(state: StateDep) -> Response:
    from gisnoise.maps import palette_doc

    s = state.settings
    tile_url, credit = s.tile_url, s.tile_attribution
    zooms = None
    if state.basemap is not None:  # gisnoise serve --basemap FILE.mbtiles
        try:
            served = state.basemap.opened()
        except InputError as exc:  # the served file was removed or replaced by one that is not a basemap
            raise ApiError(503, f"path: the basemap cannot be read now: {exc}", field="path") from None
        tile_url, credit, zooms = TILE_URL, served.attribution, [served.min_zoom, served.max_zoom]
    body = {"version": __version__, "tile_url": tile_url, "tile_attribution": credit,
            "basemap_zoom": zooms,
            "api_key_required": bool(s.api_keys),
            "sample_route": _sample_route_path() is not None, "palette": palette_doc()}
    return Response(json.dumps(body), media_type=MediaType.json.value)


def _sample_route_path() -> Path | None:
    for name in ("delivery_route.geojson", "delivery_route.json"):
        p = SAMPLE_ROUTE / name
        if p.is_file():
            return p
    return None


@router.get("/samples/route", tags=["service"], summary="The sample delivery route (waypoints GeoJSON)",
            responses={200: {"content": {MediaType.geojson.value: {"schema": {"type": "object"}}}}})
def sample_route() -> Response:
    p = _sample_route_path()
    if p is None:
        raise ApiError(404, "path: this installation has no sample route", field="path")
    return Response(p.read_bytes(), media_type=MediaType.geojson.value)


def mount_static(app: FastAPI, folder: Path) -> None:
    """The page's files under ``/static``; swagger-ui (for ``/docs``) from the installed ``swagger-ui-bundle``."""
    from swagger_ui_bundle import swagger_ui_path

    app.mount("/static/vendor/swagger-ui", StaticFiles(directory=Path(str(swagger_ui_path))), name="swagger-ui")
    app.mount("/static", StaticFiles(directory=folder), name="static")
