"""Contours: a noise map of one trajectory as GeoJSON or GeoTIFF; large maps become jobs.

The request is turned into the core's objects (trajectory, cards, grid) once,
here; the map is made by :func:`gisnoise.maps.pipeline.make_map`, the same call the
command line makes, so the HTTP result equals the CLI's for the same input.
A job stores the request with its cards resolved to full documents, so a
later change of the card store does not change a queued job's result.
"""

from __future__ import annotations

import base64
import binascii
import csv
import dataclasses
import io
import json
import tempfile
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Query, Request, Response
from fastapi.concurrency import run_in_threadpool

from gisnoise import limits
from gisnoise.errors import GisnoiseError, GridTooLargeError, InputError, TrajectoryError
from gisnoise.flight import Trajectory, from_columns, read_flight_csv
from gisnoise.geo import GridSpec
from gisnoise.model import ModelCard
from gisnoise.model import cards as gcards
from gisnoise.service.cardstore import CardStore
from gisnoise.service.deps import WRITE, State, StateDep, require_key
from gisnoise.service.errors import ApiError, request_fields
from gisnoise.service.jobs import JobContext
from gisnoise.service.models import (
    CardDocument,
    ColumnsTrajectory,
    ContourRequest,
    CsvTrajectory,
    GeoJSONTrajectory,
    JobInfo,
    LogTrajectory,
    MediaType,
    OutputFormat,
    RowsTrajectory,
)
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse
from gisnoise.service.routes_jobs import JOB_LINKS, job_info
from gisnoise.service.trajcache import TrajectoryCache, route_key

__all__ = ["router", "run_contour_job", "build_trajectory", "resolve_cards", "make_map_files", "map_geojson_text"]

router = APIRouter(tags=["contours"])

_sync_slots = threading.BoundedSemaphore(2)

ROUTE_CACHE = TrajectoryCache(32)
"""Trajectories of GeoJSON and waypoint routes, by the route's canonical JSON and the sample limit."""


# ------------------------------------------------------------------ request -> core objects
@contextmanager
def _prefixed(prefix: str) -> Iterator[None]:
    """Re-raise core errors with their field under ``prefix`` (``t`` -> ``trajectory.t``)."""
    try:
        yield
    except GisnoiseError as exc:
        fld = exc.field
        exc.field = prefix if not fld else (fld if fld.startswith(prefix) else f"{prefix}.{fld}")
        raise


_CORE_FIELDS = {"resolution_m": "grid.resolution_m", "margin_m": "grid.margin_m", "crs": "grid.crs",
                "ground_h": "ground_h_m", "receiver_height": "receiver_height_m", "card": "cards", "phase": "cards",
                "trajectory": "trajectory", "out": "body", "power_w": "trajectory.power_w", "": "body"}
"""Core argument names -> request fields, for the errors of ``make_map`` (:func:`~gisnoise.service.errors.request_fields`)."""


def build_trajectory(spec: Any, *, max_samples: int) -> Trajectory:
    """The trajectory of a request (csv text, columns, rows, GeoJSON, waypoints or a flight log)."""
    with _prefixed("trajectory"):
        if isinstance(spec, CsvTrajectory):
            # universal newlines, as reading the same file from disk (the CLI) would give
            text = spec.text.replace("\r\n", "\n").replace("\r", "\n")
            try:
                traj = read_flight_csv(io.StringIO(text), source="trajectory")
            except csv.Error as exc:
                raise TrajectoryError(f"trajectory: not a readable CSV: {exc}", field="text") from None
        elif isinstance(spec, ColumnsTrajectory):
            cols = spec.columns.model_dump(exclude_none=True)
            lengths = {k: len(v) for k, v in cols.items()}
            ref = "t" if "t" in cols else next(iter(cols), None)
            bad = [k for k, n in lengths.items() if ref is not None and n != lengths[ref]]
            if bad:
                assert ref is not None
                raise TrajectoryError(f"trajectory: column '{bad[0]}' has {lengths[bad[0]]} values, column "
                                      f"'{ref}' has {lengths[ref]}", field=f"columns.{bad[0]}")
            with _prefixed("columns"):  # a column's fault is the request's trajectory.columns.<name>
                traj = from_columns(_numeric_columns(cols), source="trajectory")
        elif isinstance(spec, RowsTrajectory):
            rows = [r.model_dump(exclude_none=True) for r in spec.rows]
            keys = list(rows[0])
            for i, row in enumerate(rows):
                if set(row) != set(keys):
                    missing = sorted(set(keys) ^ set(row))
                    raise TrajectoryError(f"trajectory: rows[{i}] has different fields than rows[0] "
                                          f"({', '.join(missing)})", field=f"rows[{i}].{missing[0]}")
            cols = {k: [r[k] for r in rows] for k in keys}
            with _prefixed("rows"):
                traj = from_columns(_numeric_columns(cols), source="trajectory")
        elif isinstance(spec, GeoJSONTrajectory):
            from gisnoise.flight import routes

            with _prefixed("data"):  # what the route reader names lies in the request's trajectory.data
                traj = ROUTE_CACHE.get(route_key(spec.data, spec.format, max_samples, repr(limits.current())),
                                       lambda: routes.read_trajectory(spec.data))
        elif isinstance(spec, LogTrajectory):
            traj = _read_log(spec)
        else:  # pragma: no cover - the request model admits no other
            raise InputError("trajectory: unknown format", field="format")
    if len(traj) > max_samples:
        raise ApiError(413, f"trajectory: {len(traj)} samples exceed the limit of {max_samples}",
                       field="trajectory")
    return traj


def _read_log(spec: LogTrajectory) -> Trajectory:
    """A flight log upload through the one trajectory reader; messages name the upload, not the server's folder."""
    from gisnoise.flight import read_route

    try:
        raw = base64.b64decode(spec.data_base64, validate=True)
    except (binascii.Error, ValueError):
        raise TrajectoryError("trajectory.data_base64: not valid base64 (RFC 4648)", field="data_base64") from None
    with tempfile.TemporaryDirectory(prefix="gisnoise-log-") as tmp:
        path = Path(tmp) / spec.name
        path.write_bytes(raw)
        try:
            traj = read_route(path, geoid_undulation_m=spec.geoid_undulation_m, power_w=spec.power_w).trajectory
        except GisnoiseError as exc:
            msg = str(exc).replace(str(path), spec.name).replace(tmp, "")
            # what the log's bytes hold (a topic, a message, its times, the file itself) is data_base64's fault
            fld = exc.field if exc.field in _LOG_FIELDS else "data_base64"
            raise type(exc)(msg, field=fld) from None
    return dataclasses.replace(traj, source=spec.name)


_LOG_FIELDS = {"power_w", "geoid_undulation_m"}
"""The fields of a log trajectory besides its bytes that the log reader's errors may name."""


def _numeric_columns(cols: Mapping[str, list[Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for k, vals in cols.items():
        if k == "phase":
            if not all(isinstance(v, str) for v in vals):
                raise TrajectoryError("trajectory: column 'phase' must hold strings", field="phase")
            out[k] = list(vals)
            continue
        bad = next((i for i, v in enumerate(vals) if isinstance(v, str)), None)
        if bad is not None:
            raise TrajectoryError(f"trajectory: column '{k}' value {bad} is not a number: {vals[bad]!r}", field=k)
        out[k] = vals
    return out


def resolve_cards(req: ContourRequest, store: CardStore) -> list[ModelCard]:
    """The request's cards: ids from the store, inline documents validated, ``phase_cards`` bound to a phase."""
    out: list[ModelCard] = []
    for i, ref in enumerate(req.cards):
        fld = f"cards[{i}]"
        if isinstance(ref, str):
            out.append(store.resolve(ref, field=fld))
        else:
            with _prefixed(fld):
                out.append(gcards.from_dict(ref.model_dump(by_alias=True), source=fld))
    for phase, ref in req.phase_cards.items():
        card = store.resolve(ref, field=f"phase_cards.{phase}")
        out.append(dataclasses.replace(card, phase=phase, phases=()))
    if not out:
        raise ApiError(422, "cards: give at least one card (id or inline document) or phase_cards", field="cards")
    return out


def _auto_margin(traj: Trajectory, cards: list[ModelCard], req: ContourRequest, max_cells: int) -> ContourRequest:
    """The request with its grid's margin set: as given, or from the cards within ``max_cells``."""
    if req.grid.margin_m is not None:
        return req
    from gisnoise.maps import CardSet, auto_margin

    with request_fields(_CORE_FIELDS):
        margin, _ = auto_margin(traj, CardSet(cards), min(req.levels), resolution_m=req.grid.resolution_m,
                                crs=req.grid.crs, background=req.background, cell_limit=max_cells,
                                sel="SEL" in req.metrics)
    return req.model_copy(update={"grid": req.grid.model_copy(update={"margin_m": margin})})


def _checked_grid(traj: Trajectory, req: ContourRequest, max_cells: int) -> GridSpec:
    """The request's receiver grid, refused (413 on ``grid.resolution_m``) above ``max_cells`` cells."""
    from gisnoise.maps import grid_for_trajectory

    with _prefixed("grid"):
        try:
            assert req.grid.margin_m is not None, "_auto_margin sets the margin first"
            grid = grid_for_trajectory(traj, req.grid.resolution_m, req.grid.margin_m, crs=req.grid.crs)
        except GridTooLargeError as exc:
            raise GridTooLargeError(str(exc), field="grid.resolution_m") from None
    cells = grid.n_cells
    if cells > max_cells:
        raise GridTooLargeError(f"grid.resolution_m: the grid has {cells} cells ({grid.width} x {grid.height}), "
                                f"more than the limit of {max_cells}; use a coarser resolution_m or a smaller "
                                f"margin_m", field="grid.resolution_m")
    return grid


def make_map_files(traj: Trajectory, cards: list[ModelCard], req: ContourRequest, out_dir: Path, *,
                   progress: Callable[..., None] | None = None,
                   cancel: Callable[[], bool] | None = None,
                   files: tuple[str, ...] = ("levels.tif", "contours.geojson"),
                   timing: dict[str, float] | None = None, grid: GridSpec | None = None) -> dict[str, Path]:
    """Write levels.tif and/or contours.geojson (``files``) for a request with the core's ``make_map``.

    Returns the paths by file name; ``timing`` (when given) receives ``make_map``'s seconds
    (``evaluate``, ``total``); ``grid``: the request's grid when it was built already.
    """
    paths = _make_map(traj, cards, req, out_dir, tuple(_OUTPUTS[f] for f in files), progress, cancel, timing,
                      grid)
    return {f: Path(paths[_OUTPUTS[f]]) for f in files}


def map_geojson_text(traj: Trajectory, cards: list[ModelCard], req: ContourRequest, *,
                     timing: dict[str, float] | None = None, grid: GridSpec | None = None) -> str:
    """The text of contours.geojson for a request, made in memory (no folder): the same text the file has."""
    return str(_make_map(traj, cards, req, None, ("contours",), None, None, timing, grid)["contours_text"])


def _make_map(traj: Trajectory, cards: list[ModelCard], req: ContourRequest, out_dir: Path | None,
              outputs: tuple[str, ...], progress: Callable[..., None] | None, cancel: Callable[[], bool] | None,
              timing: dict[str, float] | None, grid: GridSpec | None = None) -> dict[str, Any]:
    from gisnoise.maps import make_map

    ground_h = req.ground_h_m
    if ground_h is None and isinstance(req.trajectory, GeoJSONTrajectory):
        # the ground a waypoints route states (as the CLI takes it from the same file), not the track's
        # lowest point recomputed from the flown heights (which differs from it by rounding)
        from gisnoise.flight import routes

        with _prefixed("trajectory.data"):
            route = routes.read_route(req.trajectory.data)
        ground_h = route.ground_h_m
    with request_fields(_CORE_FIELDS):
        paths = make_map(traj, cards, out_dir, resolution_m=req.grid.resolution_m, margin_m=req.grid.margin_m,
                         levels=tuple(req.levels), metrics=tuple(req.metrics), crs=req.grid.crs, dem=None,
                         receiver_height=req.receiver_height_m, ground_h=ground_h,
                         uncertainty=req.uncertainty, plot=False,
                         period_s=req.period_s, threshold_db=req.threshold_db, snapshot_t=req.snapshot_t,
                         substeps=req.substeps, background=req.background, progress=progress, cancel=cancel,
                         outputs=outputs, grid=grid)
    if timing is not None:
        timing.update(paths["timing_s"])
    return paths


_OUTPUTS = {"levels.tif": "levels", "contours.geojson": "contours"}
"""File names of a map -> ``make_map``'s outputs."""


def _want_tiff(req: ContourRequest, accept: str) -> bool:
    if req.output is not None:
        return req.output == OutputFormat.geotiff
    return "image/tiff" in accept and "geo+json" not in accept


def _job_request(req: ContourRequest, cards: list[ModelCard]) -> dict[str, Any]:
    doc = req.model_dump(mode="json", by_alias=True)
    doc["cards"] = [c.to_dict() for c in cards]
    doc["phase_cards"] = {}
    return doc


# ------------------------------------------------------------------ routes
_CONTOUR_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"description": "The map: GeoJSON contours (isobands and isolines, WGS84) or a GeoTIFF, one band per metric.",
          "content": {MediaType.geojson.value: {"schema": {"type": "object"}}, MediaType.geotiff.value: {}}},
    202: {"model": JobInfo, "description": "The map is large: a job was queued (see Location).",
          "links": JOB_LINKS},
}


def _prepare(req: ContourRequest, state: State) -> tuple[ContourRequest, Trajectory, list[ModelCard], GridSpec]:
    """The request with its margin set, trajectory, cards and receiver grid (in a worker thread: routes and grids
    take CPU)."""
    s = state.settings
    with limits.override(max_samples=s.max_trajectory_samples):  # bounds routes before they are sampled
        traj = build_trajectory(req.trajectory, max_samples=s.max_trajectory_samples)
    stated = traj.metadata.get("ground_h_m")
    if req.ground_h_m is None and isinstance(req.trajectory, GeoJSONTrajectory) and stated is not None:
        # the ground the waypoints route states, read with the trajectory (make_map_files would read the route again)
        req = req.model_copy(update={"ground_h_m": float(stated)})
    cards = resolve_cards(req, state.cards)
    req = _auto_margin(traj, cards, req, s.max_cells)
    grid = _checked_grid(traj, req, s.max_cells)
    with limits.override(max_work=s.max_work):  # the work bound, before a job is queued or a map evaluated
        limits.check_work(grid.n_cells, len(traj) * req.substeps, field="grid.resolution_m")
    return req, traj, cards, grid


def _queue(request: Request, state: State, req: ContourRequest, traj: Trajectory, cards: list[ModelCard],
           grid: GridSpec) -> JSONResponse:
    j = state.jobs.submit("contours", {"cells": grid.n_cells, "samples": len(traj)},
                          {"request.json": json.dumps(_job_request(req, cards)).encode()})
    info = job_info(request, j)
    return JSONResponse(info.model_dump(), status_code=202, headers={"Location": info.url})


@router.post("/contours", response_class=Response, responses=_CONTOUR_RESPONSES,
             summary="Noise map of a trajectory (small at once, large as a job)")
async def contours(req: ContourRequest, request: Request, state: StateDep,
                   job: bool = Query(False, description="Always answer with a job (202).")) -> Response:
    timing: dict[str, float] = {}
    # one worker-thread hop for a small map: prepare, and make it unless it becomes a job
    req, traj, cards, grid, data = await run_in_threadpool(_prepare_and_map, req, state, job,
                                                           request.headers.get("accept", ""), timing)
    if data is None:
        require_key(request, request.headers.get("x-api-key"))  # a job is a write
        return await run_in_threadpool(_queue, request, state, req, traj, cards, grid)
    tiff = _want_tiff(req, request.headers.get("accept", ""))
    # where the time went (W3C Server-Timing, ms): the evaluator and the whole map (route planners tune with it)
    headers = {"Server-Timing": f"evaluate;dur={1000 * timing['evaluate']:.1f}, map;dur={1000 * timing['total']:.1f}"}
    if tiff:
        headers["Content-Disposition"] = 'attachment; filename="levels.tif"'
        return Response(data, media_type=MediaType.geotiff.value, headers=headers)
    return Response(data, media_type=MediaType.geojson.value, headers=headers)


def _prepare_and_map(req: ContourRequest, state: State, job: bool, accept: str, timing: dict[str, float]
                     ) -> tuple[ContourRequest, Trajectory, list[ModelCard], GridSpec, bytes | None]:
    """:func:`_prepare`, then the map's bytes, or None when the request becomes a job (``job`` or large work)."""
    req, traj, cards, grid = _prepare(req, state)
    if job or float(grid.n_cells) * len(traj) * req.substeps > state.settings.sync_work_limit:
        return req, traj, cards, grid, None
    return req, traj, cards, grid, _sync_map(traj, cards, req, _want_tiff(req, accept), timing, grid)


def _sync_map(traj: Trajectory, cards: list[ModelCard], req: ContourRequest, tiff: bool,
              timing: dict[str, float] | None = None, grid: GridSpec | None = None) -> bytes:
    """The map's bytes (GeoJSON text or GeoTIFF) on ``grid``, the grid :func:`_prepare` checked."""
    with _sync_slots:
        if not tiff:  # only the file the answer carries, and no folder for it
            return map_geojson_text(traj, cards, req, timing=timing, grid=grid).encode("utf-8")
        with tempfile.TemporaryDirectory(prefix="gisnoise-") as tmp:
            return make_map_files(traj, cards, req, Path(tmp), files=("levels.tif",), timing=timing, grid=grid)[
                "levels.tif"].read_bytes()


@router.post("/jobs/contours", status_code=202, response_model=JobInfo, dependencies=WRITE,
             responses={202: {"links": JOB_LINKS}},
             summary="Queue a noise map as a job")
async def contour_job(req: ContourRequest, request: Request, state: StateDep) -> JSONResponse:
    req, traj, cards, grid = await run_in_threadpool(_prepare, req, state)
    return await run_in_threadpool(_queue, request, state, req, traj, cards, grid)


# ------------------------------------------------------------------ job handler
def run_contour_job(ctx: JobContext) -> dict[str, Any]:
    """Job handler: the stored request -> levels.tif and contours.geojson in the result folder."""
    doc = json.loads((ctx.input_dir / "request.json").read_text(encoding="utf-8"))
    req = ContourRequest.model_validate(doc)
    traj = build_trajectory(req.trajectory, max_samples=10**9)
    cards = [gcards.from_dict(c.model_dump(by_alias=True) if isinstance(c, CardDocument) else c)
             for c in req.cards if not isinstance(c, str)]
    ctx.progress(0.0, "evaluating the grid")
    paths = make_map_files(traj, cards, req, ctx.output_dir, progress=ctx.progress, cancel=ctx.cancel)
    return {"files": sorted(paths), "samples": len(traj),
            "metrics": list(req.metrics), "levels": list(req.levels)}
