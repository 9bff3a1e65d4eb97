"""Route planners: exposure layers (population rasters, buildings) stored by id, and candidate routes compared.

``POST /layers`` (multipart: ``kind`` population|buildings, ``id``, ``file``) stores a layer
once, checked by the core's readers (:func:`gisnoise.exposure.read_population`,
:func:`~gisnoise.exposure.read_buildings`); a second upload under the same id becomes a new
version (``id@2``), never overwriting the first.  Population: a GeoTIFF; buildings: a
GeoPackage or GeoJSON file (a Shapefile as a zip of its parts).

``POST /routes/compare`` evaluates candidate routes on one grid and ranks them by exposure
(:func:`gisnoise.planning.compare_routes`, the call ``gisnoise compare`` makes); the answer is
the comparison document, or with ``output=difference`` the difference GeoTIFF.  The grid is
held to ``GISNOISE_MAX_CELLS`` and the work (cells x samples of all routes) to
``GISNOISE_SYNC_WORK_LIMIT`` (413 beyond).

``POST /routes/optimize`` finds a quieter flyable route between two pads
(:func:`gisnoise.planning.optimize_route`, as ``gisnoise route optimize``) and answers its
summary, both routes as waypoint GeoJSON and their comparison.
"""

from __future__ import annotations

import json
import re
import shutil
import tempfile
import threading
import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Response, UploadFile
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, ConfigDict, Field

from gisnoise.errors import GridTooLargeError, InputError
from gisnoise.service.deps import WRITE, State, StateDep
from gisnoise.service.errors import ApiError, request_fields
from gisnoise.service.models import (
    CardDocument,
    CardRef,
    GridRequest,
    MapLevel,
    MediaType,
    PhaseName,
    TrajectoryInput,
)
from gisnoise.service.responses import AsciiJSONResponse as JSONResponse
from gisnoise.service.routes_contours import build_trajectory

__all__ = ["router", "LayerStore", "CompareRequest", "OptimizeRequest"]

router = APIRouter(tags=["route planning"])
_ID = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,127}$")
_SUFFIX = {"population": (".tif", ".tiff"), "buildings": (".gpkg", ".geojson", ".json", ".zip")}
_lock = threading.Lock()
_slots = threading.BoundedSemaphore(2)


class LayerStore:
    """Layers in ``root/<id>/<version>/<file>`` with ``layer.json`` beside; versions are never overwritten."""

    def __init__(self, root: Path) -> None:
        self.root = Path(root)

    def versions(self, layer_id: str) -> list[int]:
        d = self.root / layer_id
        return sorted(int(p.name) for p in d.iterdir() if p.name.isdigit()) if d.is_dir() else []

    def ids(self) -> list[str]:
        return sorted(p.name for p in self.root.iterdir() if p.is_dir()) if self.root.is_dir() else []

    def info(self, layer_id: str, version: int) -> dict[str, Any]:
        return json.loads((self.root / layer_id / str(version) / "layer.json").read_text())

    def resolve(self, ref: str, kind: str, *, field: str) -> Path:
        """The stored file of ``id`` (newest version) or ``id@version``, checked to be of ``kind``."""
        lid, _, v = ref.partition("@")
        if not _ID.match(lid) or (v and not v.isdigit()):
            raise ApiError(422, f"{field}: not a layer id: {ref!r}", field=field)
        vs = self.versions(lid)
        if not vs or (v and int(v) not in vs):
            raise ApiError(404, f"{field}: no layer {ref!r}", field=field)
        ver = int(v) if v else vs[-1]
        info = self.info(lid, ver)
        if info["kind"] != kind:
            raise ApiError(422, f"{field}: layer {ref!r} holds {info['kind']}, not {kind}", field=field)
        return self.root / lid / str(ver) / info["file"]

    def put(self, layer_id: str, kind: str, src: Path, name: str) -> dict[str, Any]:
        """Store a checked file as the next version of ``layer_id``."""
        with _lock:
            ver = (self.versions(layer_id) or [0])[-1] + 1
            d = self.root / layer_id / str(ver)
            tmp = self.root / layer_id / f".{ver}.tmp"
            shutil.rmtree(tmp, ignore_errors=True)
            try:
                tmp.mkdir(parents=True)
                shutil.copytree(src.parent, tmp, dirs_exist_ok=True)
                info = {"id": layer_id, "version": ver, "kind": kind, "file": name}
                (tmp / "layer.json").write_text(json.dumps(info))
                tmp.rename(d)
            except BaseException:  # a full disk, say: nothing of the upload is left
                shutil.rmtree(tmp, ignore_errors=True)
                if ver == 1:
                    shutil.rmtree(self.root / layer_id, ignore_errors=True)
                raise
            return info


def _store(state: State) -> LayerStore:
    return LayerStore(state.settings.data_dir / "layers")


def _check_layer(kind: str, folder: Path, name: str) -> tuple[str, dict[str, Any]]:
    """Unpack a zipped Shapefile, read the layer with the core's reader; the file to keep and a summary."""
    from gisnoise.exposure import read_buildings, read_population

    path = folder / name
    if name.lower().endswith(".zip"):
        try:
            with zipfile.ZipFile(path) as zf:
                members = [m for m in zf.namelist() if "/" not in m and "\\" not in m and ".." not in m]
                if len(members) != len(zf.namelist()) or len(members) > 20:
                    raise ApiError(422, "file: a zipped Shapefile holds its parts at the top, nothing else",
                                   field="file")
                zf.extractall(folder)
        except zipfile.BadZipFile:
            raise ApiError(422, "file: not a zip archive", field="file") from None
        path.unlink()
        shp = [m for m in members if m.lower().endswith(".shp")]
        if len(shp) != 1:
            raise ApiError(422, "file: the zip must hold exactly one .shp", field="file")
        path = folder / shp[0]
    try:
        if kind == "population":
            pop = read_population(path)
            return path.name, {"total_people": pop.total, "shape": list(pop.counts.shape),
                               "crs": pop.crs.to_string(), "warnings": pop.warnings}
        b = read_buildings(path)
        return path.name, {"buildings": b.n, "fields": b.fields, "crs": b.crs.to_string()}
    except InputError as exc:  # the upload is named by its file name, never by the server's folder
        raise ApiError(422, f"file: {str(exc).replace(str(folder) + '/', '')}", field="file") from None


@router.post("/layers", status_code=201, dependencies=WRITE, summary="Upload an exposure layer (new version)")
async def upload_layer(state: StateDep,
                       kind: Annotated[Literal["population", "buildings"], Form(description="Layer kind.")],
                       layer_id: Annotated[str, Form(alias="id", max_length=128, description="Layer id.")],
                       file: Annotated[UploadFile, File(description="Population GeoTIFF; buildings GeoPackage, "
                                                                    "GeoJSON or a zipped Shapefile.")]) -> JSONResponse:
    if not _ID.match(layer_id):
        raise ApiError(422, f"id: not a layer id: {layer_id!r} (letters, digits, _ . -)", field="id")
    name = Path(file.filename or "").name
    if not name.lower().endswith(_SUFFIX[kind]):
        raise ApiError(422, f"file: a {kind} layer is one of {', '.join(_SUFFIX[kind])}, got {name!r}", field="file")
    limit = state.settings.max_upload_bytes
    tmp = Path(tempfile.mkdtemp(prefix="layer-"))
    try:
        folder = tmp / "f"
        folder.mkdir()
        n = 0
        with (folder / name).open("wb") as f:
            while chunk := await file.read(1 << 20):
                n += len(chunk)
                if n > limit:
                    raise ApiError(413, f"file: upload exceeds the limit of {limit} bytes", field="file")
                f.write(chunk)
        kept, summary = await run_in_threadpool(_check_layer, kind, folder, name)
        info = await run_in_threadpool(_store(state).put, layer_id, kind, folder / kept, kept)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return JSONResponse({**info, **summary, "ref": f"{info['id']}@{info['version']}"}, status_code=201)


@router.get("/layers", summary="List exposure layers")
def list_layers(state: StateDep) -> JSONResponse:
    st = _store(state)
    return JSONResponse([st.info(i, v) for i in st.ids() for v in st.versions(i)])


class CompareRequest(BaseModel):
    """Candidate routes ranked by the people they expose."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    routes: list[TrajectoryInput] = Field(min_length=2, max_length=20, description="Candidate routes.")
    names: list[Annotated[str, Field(min_length=1, max_length=64)]] | None = Field(
        default=None, description="Names of the routes (default route1, route2, ...).")
    cards: list[CardRef | CardDocument] = Field(min_length=1, max_length=32, description="Cards by id or inline.")
    phase_cards: dict[PhaseName, CardRef] = Field(default_factory=dict)
    population: str | None = Field(default=None, max_length=160, description="Population layer id ('id[@version]').")
    buildings: str | None = Field(default=None, max_length=160, description="Buildings layer id ('id[@version]').")
    metric: Literal["LAmax", "LAeq", "SEL"] = "LAmax"
    levels: list[MapLevel] = Field(default=[45.0, 50.0, 55.0, 60.0, 65.0], min_length=1, max_length=20,
                                   description="Levels for 'people above', dB(A), ascending, each within [-50, 200].")
    rank_level_db: float = Field(default=55.0, ge=-50, le=200)
    grid: GridRequest = Field(default_factory=lambda: GridRequest(resolution_m=20.0))
    receiver_height_m: float = Field(default=1.5, ge=0, le=1000)
    ground_h_m: float | None = Field(default=None, ge=-1000, le=9000)
    output: Literal["json", "difference"] = Field(default="json", description="The comparison document or the "
                                                                           "difference GeoTIFF.")


_COMPARE_FIELDS = {"rank_level": "rank_level_db", "ground_h": "ground_h_m", "receiver_height": "receiver_height_m",
                   "resolution_m": "grid.resolution_m", "margin_m": "grid.margin_m", "crs": "grid.crs",
                   "card": "cards", "phase": "cards", "power_w": "routes", "": "body"}
"""The names ``compare_routes`` gives its arguments -> the fields of a compare request."""


def _compare(req: CompareRequest, state: State) -> tuple[bytes, str]:
    from gisnoise.exposure import read_buildings, read_population
    from gisnoise.geo import grid_for_points
    from gisnoise.maps import CardSet
    from gisnoise.planning import compare_routes, routes_margin, write_comparison
    from gisnoise.service.routes_contours import resolve_cards

    s = state.settings
    if req.population is None and req.buildings is None:
        raise ApiError(422, "population: give a population or a buildings layer id", field="population")
    if req.names is not None and len(req.names) != len(req.routes):
        raise ApiError(422, f"names: {len(req.names)} names for {len(req.routes)} routes", field="names")
    trajs = []
    for i, r in enumerate(req.routes):
        try:
            trajs.append(build_trajectory(r, max_samples=s.max_trajectory_samples))
        except (InputError, ApiError) as exc:  # build_trajectory names the field of a contour request's trajectory
            rest = (exc.field or "").removeprefix("trajectory").lstrip(".")
            exc.field = f"routes[{i}].{rest}" if rest else f"routes[{i}]"
            raise
    cards = resolve_cards(req, state.cards)  # type: ignore[arg-type]  # same card fields as ContourRequest
    import numpy as np

    margin_said: list[str] = []
    try:
        margin = req.grid.margin_m
        if margin is None:  # from the cards, as the command line: every route's zone above the lowest level closes
            with request_fields(_COMPARE_FIELDS):
                margin, margin_said = routes_margin(trajs, CardSet(cards), req.metric, min(req.levels),
                                                    req.grid.resolution_m, req.grid.crs)
        grid = grid_for_points(np.concatenate([t.lon for t in trajs]), np.concatenate([t.lat for t in trajs]),
                               req.grid.resolution_m, margin, req.grid.crs)
    except GridTooLargeError as exc:
        raise GridTooLargeError(str(exc), field="grid.resolution_m") from None
    except InputError as exc:
        exc.field = f"grid.{exc.field}" if exc.field else "grid"
        raise
    if grid.n_cells > s.max_cells:
        raise GridTooLargeError(f"grid.resolution_m: {grid.n_cells} cells exceed the limit of {s.max_cells}",
                                field="grid.resolution_m")
    work = float(grid.n_cells) * sum(len(t) for t in trajs)
    if work > s.sync_work_limit:
        raise ApiError(413, f"routes: {work:.3g} cell-samples exceed the limit of {s.sync_work_limit:.3g}; use a "
                            "coarser grid.resolution_m or a smaller grid.margin_m", field="grid.resolution_m")
    st = _store(state)
    pop = read_population(st.resolve(req.population, "population", field="population")) if req.population else None
    b = read_buildings(st.resolve(req.buildings, "buildings", field="buildings")) if req.buildings else None
    with _slots, request_fields(_COMPARE_FIELDS):
        cmp = compare_routes(trajs, cards, population=pop, buildings=b, names=req.names, metric=req.metric,
                             levels=req.levels, rank_level_db=req.rank_level_db, grid=grid,
                             receiver_height=req.receiver_height_m, ground_h=req.ground_h_m)
        cmp.doc["warnings"] = margin_said + cmp.doc["warnings"]  # a margin from the cards cut by the cell limit
        if req.output == "difference":
            with tempfile.TemporaryDirectory(prefix="gisnoise-") as tmp:
                return write_comparison(cmp, tmp)["difference"].read_bytes(), MediaType.geotiff.value
    from gisnoise.jsonio import to_jsonable

    return json.dumps(to_jsonable(cmp.doc), allow_nan=False).encode(), "application/json"


@router.post("/routes/compare", response_class=Response, summary="Rank candidate routes by exposure",
             responses={200: {"description": "The comparison (ranking) or the difference GeoTIFF.",
                              "content": {"application/json": {"schema": {"type": "object"}},
                                          MediaType.geotiff.value: {}}}})
async def compare(req: CompareRequest, state: StateDep) -> Response:
    data, media = await run_in_threadpool(_compare, req, state)
    return Response(data, media_type=media)


class OptimizeRequest(BaseModel):
    """A quieter route between two pads."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)
    start: list[float] = Field(min_length=2, max_length=2, description="Take-off pad [lon, lat], deg.")
    goal: list[float] = Field(min_length=2, max_length=2, description="Landing pad [lon, lat], deg.")
    cards: list[CardRef | CardDocument] = Field(min_length=1, max_length=32, description="Cards by id or inline.")
    phase_cards: dict[PhaseName, CardRef] = Field(default_factory=dict)
    population: str | None = Field(default=None, max_length=160, description="Population layer id ('id[@version]').")
    buildings: str | None = Field(default=None, max_length=160, description="Buildings layer id ('id[@version]').")
    avoid: dict[str, Any] | None = Field(default=None, description="No-fly polygons: a GeoJSON FeatureCollection "
                                                                   "(WGS84) of Polygon or MultiPolygon features.")
    altitude_m: float = Field(default=60.0, gt=0, le=1000)
    max_detour_pct: float = Field(default=30.0, ge=0, le=300)
    turn_radius_m: float | None = Field(default=None, gt=0, le=10_000)
    rank_level_db: float = Field(default=55.0, ge=0, le=200)
    resolution_m: float = Field(default=50.0, ge=5, le=1000, description="Cost grid cell, m.")
    ground_h_m: float = Field(default=0.0, ge=-1000, le=9000)


def _avoid_polygons(doc: dict[str, Any] | None) -> list[Any]:
    if doc is None:
        return []
    import shapely.geometry

    feats = doc.get("features") if doc.get("type") == "FeatureCollection" else None
    if not isinstance(feats, list):
        raise ApiError(422, "avoid: expected a GeoJSON FeatureCollection", field="avoid")
    out = []
    for i, f in enumerate(feats):
        try:
            g = shapely.geometry.shape(f["geometry"])
        except (KeyError, TypeError, ValueError, AttributeError):
            raise ApiError(422, f"avoid: feature {i} has no readable geometry", field=f"avoid.features[{i}]") from None
        if g.geom_type not in ("Polygon", "MultiPolygon") or not g.is_valid:
            raise ApiError(422, f"avoid: feature {i} is not a valid polygon", field=f"avoid.features[{i}]")
        out.extend(list(g.geoms) if g.geom_type == "MultiPolygon" else [g])
    return out


_OPTIMIZE_FIELDS = {"from": "start", "to": "goal", "altitude": "altitude_m", "max_detour": "max_detour_pct",
                    "turn_radius": "turn_radius_m", "rank_level": "rank_level_db", "ground_h": "ground_h_m",
                    "card": "cards", "phase": "cards", "": "body"}
"""The names ``optimize_route`` gives its arguments (the command line's options) -> the fields of an optimize
request."""


def _optimize(req: OptimizeRequest, state: State) -> dict[str, Any]:
    from gisnoise.exposure import read_buildings, read_population
    from gisnoise.planning import optimize_route, waypoints_geojson
    from gisnoise.service.routes_contours import resolve_cards

    if req.population is None and req.buildings is None:
        raise ApiError(422, "population: give a population or a buildings layer id", field="population")
    for name, (lon, lat) in (("start", req.start), ("goal", req.goal)):
        if not (-180 <= lon <= 180 and -90 <= lat <= 90):
            raise ApiError(422, f"{name}: [lon, lat] out of range: {[lon, lat]}", field=name)
    s = state.settings
    # the search grid is a square of side (1 + detour) x distance: keep it within the cell limit
    from pyproj import Geod

    dist = Geod(ellps="WGS84").inv(req.start[0], req.start[1], req.goal[0], req.goal[1])[2]
    cells = ((1 + req.max_detour_pct / 100) * dist / req.resolution_m + 4) ** 2
    if cells > min(s.max_cells, 4_000_000):
        raise ApiError(413, f"resolution_m: the search grid would have {cells:.3g} cells; use a coarser resolution_m",
                       field="resolution_m")
    cards = resolve_cards(req, state.cards)  # type: ignore[arg-type]  # same card fields as ContourRequest
    st = _store(state)
    pop = read_population(st.resolve(req.population, "population", field="population")) if req.population else None
    b = read_buildings(st.resolve(req.buildings, "buildings", field="buildings")) if req.buildings else None
    with _slots, request_fields(_OPTIMIZE_FIELDS):
        res = optimize_route((req.start[0], req.start[1]), (req.goal[0], req.goal[1]), cards, population=pop, buildings=b,
                             avoid=_avoid_polygons(req.avoid), altitude_m=req.altitude_m,
                             max_detour_pct=req.max_detour_pct, turn_radius_m=req.turn_radius_m,
                             rank_level_db=req.rank_level_db, resolution_m=req.resolution_m, ground_h=req.ground_h_m)
    return {"summary": res.summary, "route": waypoints_geojson(res.optimized_doc),
            "direct": waypoints_geojson(res.direct_doc), "comparison": res.comparison.doc}


@router.post("/routes/optimize", summary="A quieter flyable route between two pads, compared with the direct one")
async def optimize(req: OptimizeRequest, state: StateDep) -> JSONResponse:
    from gisnoise.jsonio import to_jsonable

    doc = await run_in_threadpool(_optimize, req, state)
    return JSONResponse(to_jsonable(doc))
