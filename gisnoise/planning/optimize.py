"""A quieter route: least-exposure path between two pads, flyable, re-evaluated against the direct route.

The method (stated):

1. **Corridor width.**  A straight level leg at the cruise altitude is flown with the
   vehicle model (:func:`gisnoise.flight.route_from_waypoints`) and its ``LAmax`` is
   evaluated across the track with the card (:func:`gisnoise.exposure.point_levels`); the
   half-width ``r`` is the farthest lateral distance where it reaches the ranking level
   (55 dB(A) by default).
2. **Cost grid.**  A grid of ``resolution_m`` cells (local UTM) covers the ellipse of points
   reachable within the detour limit.  Its cost per metre flown is the people a corridor of
   half-width ``r`` sweeps per metre: people within ``r`` of the cell (population sub-cells,
   or building residents at the footprint centroids) divided by ``2 r``.  Cells inside a
   no-fly polygon (grown by half a cell diagonal) or outside the ellipse are closed.
3. **Graph search.**  Dijkstra on the 16-connected cell graph, an edge costing its length
   times (mean cell cost + ``lam``).  ``lam`` (people per metre) trades exposure for length:
   it is raised by bisection until the flyable path keeps the detour limit.
4. **Flyable waypoints.**  The cell path is simplified (Douglas-Peucker within one cell,
   never into a no-fly zone), then vertices are dropped until every leg holds the fly-by
   turns at both its ends at the turn radius ``R = v^2 / (g tan(max_bank))`` (tangent length
   ``R tan(delta / 2)``), choosing each time the drop that adds the least exposure.
5. **Re-evaluation.**  Direct and optimized route are flown from waypoints (vertical
   take-off, climb to altitude, cruise, descent, landing) and compared with the full
   evaluator on one grid (:func:`gisnoise.planning.compare_routes`).  When the optimized
   route is not better than the direct one by the comparison's ranking (people above the
   level, then person-dB, then peak dwelling level; a tie is not better), the direct route
   is kept and returned, and the summary says so (``kept_direct``, ``note``).

The population raster must hold both pads (a pad outside it, or on one of its nodata cells, is
refused: there the search would count nobody); when more than 1 % of the search area lies outside
it or on its nodata cells, a warning says so (the search takes nobody there and may be drawn into
it), and the re-evaluation marks counts that reach such cells as lower bounds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, InputError
from gisnoise.exposure import (
    UNCOVERED_SHARE,
    Buildings,
    Population,
    point_levels,
    population_coverage,
    population_points,
)
from gisnoise.flight import GRAVITY, WAYPOINTS_SCHEMA, VehicleModel, route_from_waypoints
from gisnoise.geo import WGS84, GridSpec, LocalFrame, transformer, utm_crs
from gisnoise.maps import CardSet
from gisnoise.planning._rules import pad_outside
from gisnoise.planning.compare import Comparison, compare_routes

__all__ = ["Optimized", "optimize_route", "corridor_half_width", "waypoints_geojson"]

# 16-connected moves (cells): the 8 neighbours and the knight moves
_MOVES = [(dr, dc) for dr in (-2, -1, 0, 1, 2) for dc in (-2, -1, 0, 1, 2)
          if (dr, dc) != (0, 0) and math.gcd(abs(dr), abs(dc)) == 1]


@dataclass(frozen=True, eq=False)
class Optimized:
    """The optimized route: waypoints (lon, lat), the two route documents and their comparison."""

    lonlat: np.ndarray
    direct_doc: dict[str, Any]
    optimized_doc: dict[str, Any]
    comparison: Comparison
    summary: dict[str, Any]


def _route_doc(lonlat: np.ndarray, altitude: float, ground_h: float, veh: dict[str, Any]) -> dict[str, Any]:
    wps = [{"lon": float(lonlat[0, 0]), "lat": float(lonlat[0, 1]), "alt": 0.0},
           {"lon": float(lonlat[0, 0]), "lat": float(lonlat[0, 1]), "alt": altitude}]
    wps += [{"lon": float(x), "lat": float(y), "alt": altitude} for x, y in lonlat[1:]]
    wps.append({"lon": float(lonlat[-1, 0]), "lat": float(lonlat[-1, 1]), "alt": 0.0})
    return {"schema": WAYPOINTS_SCHEMA, "altitude_reference": "agl", "ground_h_m": ground_h, "sample_dt_s": 0.5,
            "vehicle": veh, "waypoints": wps}


def waypoints_geojson(doc: dict[str, Any], **props: Any) -> dict[str, Any]:
    """A waypoints document as a GeoJSON FeatureCollection of points (readable by ``gisnoise contour``)."""
    feats = [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [w["lon"], w["lat"], w["alt"]]},
              "properties": {"seq": i, "alt": w["alt"]}} for i, w in enumerate(doc["waypoints"])]
    route = {k: v for k, v in doc.items() if k not in ("schema", "waypoints")}
    return {"type": "FeatureCollection", "route": route, "properties": props, "features": feats}


def corridor_half_width(cards: Any, veh: VehicleModel, altitude_m: float, level_db: float,
                        metric: str = "LAmax") -> float:
    """Farthest lateral distance (m) at which a straight level leg reaches ``level_db`` (see the module docstring)."""
    fr = LocalFrame(0.0, 0.0, 0.0)
    lat, lon, _ = fr.to_wgs84(np.array([0.0, 0.0]), np.array([-3000.0, 3000.0]), np.zeros(2))
    traj = route_from_waypoints([{"lon": float(lon[0]), "lat": float(lat[0]), "alt": altitude_m},
                                 {"lon": float(lon[1]), "lat": float(lat[1]), "alt": altitude_m}],
                                {"ground_h_m": 0.0, "sample_dt_s": 0.25, "vehicle": _veh_dict(veh)}).trajectory
    d = np.concatenate([-np.geomspace(4000.0, 1.0, 400), [0.0], np.geomspace(1.0, 4000.0, 400)])
    plat, plon, ph = fr.to_wgs84(d, np.zeros_like(d), np.full_like(d, 1.5))
    lv = point_levels(traj, cards, plon, plat, ph)[metric]
    above = np.abs(d[lv >= level_db])
    if above.size == 0:
        return 0.0
    if above.max() >= 4000.0:
        raise InputError(f"rank_level: {level_db} dB(A) {metric} is reached farther than 4 km from the track; "
                         "choose a higher level", field="rank_level")
    return float(above.max())


def _veh_dict(veh: VehicleModel) -> dict[str, Any]:
    from dataclasses import asdict

    return asdict(veh)


def _closed_cells(grid: GridSpec, avoid: Sequence[Any]) -> np.ndarray:
    from gisnoise.geo import shapes as shapely

    closed = np.zeros(grid.shape, dtype=bool)
    if not avoid:
        return closed
    x, y = grid.centres()
    half_diag = 0.5 * math.hypot(*grid.resolution)
    for poly in avoid:
        g = shapely.buffer(poly, half_diag)
        closed |= shapely.contains_xy(g, x, y)
    return closed


def _people_field(grid: GridSpec, pop: Population | None, b: Buildings | None) -> np.ndarray:
    """People per cell of the cost grid."""
    out = np.zeros(grid.shape)
    t = grid.transform
    if pop is not None:
        x, y, people, _ = population_points(pop, grid)
    elif b is not None:
        w = b.residents if b.residents is not None else b.dwellings
        if w is None:
            raise InputError("buildings: route optimization needs residents or dwellings", field="buildings")
        cx = np.array([p.centroid.x for p in b.polygons])
        cy = np.array([p.centroid.y for p in b.polygons])
        x, y = transformer(b.crs, grid.crs).transform(cx, cy)
        _, first = np.unique(b.part_of, return_index=True)
        people = np.zeros(len(b.polygons))
        people[first] = w[b.part_of[first]]
    else:
        raise InputError("route optimize: give a population raster or buildings", field="population")
    col = np.floor((np.asarray(x) - t.c) / t.a).astype(int)
    row = np.floor((np.asarray(y) - t.f) / t.e).astype(int)
    ok = (row >= 0) & (row < grid.height) & (col >= 0) & (col < grid.width)
    np.add.at(out, (row[ok], col[ok]), people[ok])
    return out


def _cost_field(people: np.ndarray, res: float, r: float) -> np.ndarray:
    from scipy.signal import fftconvolve

    k = int(math.ceil(r / res))
    yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
    disk = ((xx * res) ** 2 + (yy * res) ** 2 <= r * r).astype(float)
    swept = fftconvolve(people, disk, mode="same")
    return np.maximum(swept, 0.0) / max(2.0 * r, res)


def _dijkstra(cost: np.ndarray, closed: np.ndarray, res: float, lam: float, s: int, g: int) -> list[int]:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    h, w = cost.shape
    idx = np.arange(h * w).reshape(h, w)
    rows, cols, wts = [], [], []
    for dr, dc in _MOVES:
        r0, r1 = max(0, -dr), min(h, h - dr)
        c0, c1 = max(0, -dc), min(w, w - dc)
        a = idx[r0:r1, c0:c1].ravel()
        b = idx[r0 + dr:r1 + dr, c0 + dc:c1 + dc].ravel()
        ok = ~closed.ravel()[a] & ~closed.ravel()[b]
        length = res * math.hypot(dr, dc)
        rows.append(a[ok])
        cols.append(b[ok])
        wts.append(length * (0.5 * (cost.ravel()[a[ok]] + cost.ravel()[b[ok]]) + lam) + 1e-12)
    m = coo_matrix((np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w, h * w)).tocsr()
    dist, pred = dijkstra(m, indices=s, return_predecessors=True)
    if not np.isfinite(dist[g]):
        raise InputError("route optimize: no path from --from to --to outside the no-fly zones within the detour "
                         "limit", field="avoid")
    path = [g]
    while path[-1] != s:
        path.append(int(pred[path[-1]]))
    return path[::-1]


def _line_cost(cost: np.ndarray, grid: GridSpec, p: np.ndarray, q: np.ndarray) -> float:
    t = grid.transform
    n = max(2, int(math.hypot(*(q - p)) / (0.5 * t.a)) + 1)
    f = np.linspace(0.0, 1.0, n)
    x, y = p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])
    col = np.clip(((x - t.c) / t.a).astype(int), 0, grid.width - 1)
    row = np.clip(((y - t.f) / t.e).astype(int), 0, grid.height - 1)
    return float(np.mean(cost[row, col]) * math.hypot(*(q - p)))


def _clear(p: np.ndarray, q: np.ndarray, avoid_grown: Any) -> bool:
    from gisnoise.geo import shapes as shapely

    return avoid_grown is None or not shapely.intersects(shapely.LineString([p, q]), avoid_grown)


def _flyable(pts: np.ndarray, radius: float, cost: np.ndarray, grid: GridSpec, avoid_grown: Any) -> np.ndarray:
    """Drop vertices until every leg holds its turns at ``radius`` (see the module docstring)."""
    pl = [np.asarray(p, dtype=float) for p in pts]

    def tangent(i: int) -> float:
        if i <= 0 or i >= len(pl) - 1:
            return 0.0
        a, b = pl[i] - pl[i - 1], pl[i + 1] - pl[i]
        cosd = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
        delta = math.acos(max(-1.0, min(1.0, cosd)))
        return radius * math.tan(min(delta, math.radians(179.0)) / 2.0)

    for _ in range(10 * len(pl)):
        worst, leg = 0.0, -1
        for i in range(len(pl) - 1):
            excess = tangent(i) + tangent(i + 1) - float(np.linalg.norm(pl[i + 1] - pl[i]))
            if excess > worst:
                worst, leg = excess, i
        if leg < 0:
            return np.array(pl)
        best: tuple[float, int] | None = None
        for v in (leg, leg + 1):
            if v <= 0 or v >= len(pl) - 1 or not _clear(pl[v - 1], pl[v + 1], avoid_grown):
                continue
            added = (_line_cost(cost, grid, pl[v - 1], pl[v + 1]) - _line_cost(cost, grid, pl[v - 1], pl[v])
                     - _line_cost(cost, grid, pl[v], pl[v + 1]))
            if best is None or added < best[0]:
                best = (added, v)
        if best is None:
            raise InputError(f"route optimize: the turn radius {radius:.0f} m does not fit between the no-fly zones "
                             "(a leg is too short for its turns)", field="turn_radius")
        del pl[best[1]]
    raise InputError("route optimize: could not make the path flyable", field="turn_radius")


def optimize_route(start: tuple[float, float], goal: tuple[float, float], cards: Any, *,
                   population: Population | None = None, buildings: Buildings | None = None,
                   avoid: Sequence[Any] = (), altitude_m: float = 60.0, max_detour_pct: float = 30.0,
                   turn_radius_m: float | None = None, vehicle: dict[str, Any] | None = None,
                   rank_level_db: float = 55.0, resolution_m: float = 50.0, eval_resolution_m: float = 20.0,
                   ground_h: float = 0.0, levels: Sequence[float] = (45.0, 50.0, 55.0, 60.0, 65.0),
                   progress: Callable[[float], Any] | None = None, cancel: Callable[[], bool] | None = None
                   ) -> Optimized:
    """Least-exposure flyable route from ``start`` to ``goal`` (lon, lat in deg); see the module docstring.

    ``avoid`` are no-fly polygons in WGS84 (shapely).  The result's ``summary`` states the
    corridor width, turn radius, lengths, detour and the re-evaluated people above the ranking
    level of the direct and the returned route (``lower_bound_<level>_direct``, ``..._optimized``: whether each is a
    lower bound, as the comparison flags it); ``kept_direct`` is true (with a one-line ``note``) when
    the searched route was not better than the direct one, which is then returned
    (``searched_length_m``, ``people_above_<level>_searched`` state the searched route); ``warnings``
    (also appended to the comparison's) name a search area partly outside the population raster or on its nodata
    cells.  A pad outside the population raster, or on a nodata cell, is refused (field ``from`` or ``to``).  ``progress`` is called with the
    fraction done (the search up to 0.5, the re-evaluation of both routes after it); ``cancel`` is polled between
    the search's graph solutions and while the routes are evaluated (true raises
    :class:`~gisnoise.errors.Cancelled`).
    """
    from gisnoise.geo import shapes as shapely

    if not (isinstance(altitude_m, (int, float)) and 0 < altitude_m <= 1000):
        raise InputError(f"altitude must be in (0, 1000] m, got {altitude_m!r}", field="altitude")
    if not (isinstance(max_detour_pct, (int, float)) and 0 <= max_detour_pct <= 300):
        raise InputError(f"max_detour must be in [0, 300] %, got {max_detour_pct!r}", field="max_detour")
    if population is not None:
        for fld, pt in (("from", start), ("to", goal)):
            if pad_outside(population, pt):
                raise InputError(f"{fld}: the pad {pt[0]:g},{pt[1]:g} (lon,lat) lies outside the population raster "
                                 f"({population.source}) or on its cells without data: there the search would "
                                 "count nobody (lon and lat swapped?)", field=fld)
    veh = VehicleModel.from_dict(vehicle)
    radius = veh.cruise_speed_m_s ** 2 / (GRAVITY * math.tan(math.radians(veh.max_bank_deg)))
    if turn_radius_m is not None:
        radius = max(radius, float(turn_radius_m))
    cardset = cards if isinstance(cards, CardSet) else CardSet(cards if isinstance(cards, (list, tuple)) else [cards])
    r = corridor_half_width(cardset, veh, altitude_m, rank_level_db)
    mid = ((start[0] + goal[0]) / 2, (start[1] + goal[1]) / 2)
    crs = utm_crs(*mid)
    to_m = transformer(WGS84, crs)
    sx, sy = to_m.transform(*start)
    gx, gy = to_m.transform(*goal)
    direct = math.hypot(gx - sx, gy - sy)
    if direct < 4 * radius:
        raise InputError(f"--from and --to are {direct:.0f} m apart; a route needs at least 4 turn radii "
                         f"({4 * radius:.0f} m)", field="to")
    limit = direct * (1 + max_detour_pct / 100.0)
    a = limit / 2
    cx, cy = (sx + gx) / 2, (sy + gy) / 2
    ext = a + resolution_m * 2
    grid = GridSpec.from_bounds(crs, cx - ext, cy - ext, cx + ext, cy + ext, resolution_m)
    xx, yy = grid.centres()
    inside = np.hypot(xx - sx, yy - sy) + np.hypot(xx - gx, yy - gy) <= limit + 1e-6
    to_grid = transformer(WGS84, crs)
    avoid_m = [shapely.transform(p, lambda c: np.column_stack(to_grid.transform(c[:, 0], c[:, 1])))
               for p in avoid]
    closed = ~inside | _closed_cells(grid, avoid_m)
    avoid_grown = shapely.union_all(avoid_m) if avoid_m else None
    people = _people_field(grid, population, buildings)
    warnings: list[str] = []
    share = 0.0  # of the search area's cells whose centre the population raster does not cover (or holds nodata)
    if population is not None:
        rows_in, cols_in = np.nonzero(inside)
        share = float(np.mean(~population_coverage(population, grid, rows_in, cols_in))) if rows_in.size else 0.0
        if share > UNCOVERED_SHARE:
            warnings.append(f"route optimize: the population raster ({Path(population.source).name}) does not cover "
                            f"{100 * share:.1f} % of the search area (the ellipse the detour limit allows): the search "
                            "counts nobody there, so the route may be drawn into it; give a raster that covers it")
    cost = _cost_field(people, resolution_m, max(r, resolution_m))
    t = grid.transform

    def node(x: float, y: float) -> int:
        c, rr = int((x - t.c) // t.a), int((y - t.f) // t.e)
        if closed[rr, c] and not inside[rr, c]:
            raise InputError("route optimize: pad outside the search area", field="from")
        if closed[rr, c]:
            raise InputError("route optimize: a pad lies in a no-fly zone", field="avoid")
        return rr * grid.width + c

    s_node, g_node = node(sx, sy), node(gx, gy)

    solved = [0]

    def solve(lam: float) -> np.ndarray:
        if cancel is not None and cancel():
            raise Cancelled("route optimize: cancelled")
        if progress is not None:  # at most about 1 + 10 + 10 solutions: the search's half of the bar
            progress(0.5 * min(solved[0] / 20.0, 1.0))
        solved[0] += 1
        path = _dijkstra(cost, closed, resolution_m, lam, s_node, g_node)
        rr, cc = np.divmod(np.asarray(path), grid.width)
        px = t.c + t.a * (cc + 0.5)
        py = t.f + t.e * (rr + 0.5)
        px[0], py[0], px[-1], py[-1] = sx, sy, gx, gy
        line = shapely.LineString(np.column_stack([px, py]))
        simp = line.simplify(resolution_m)
        if avoid_grown is not None and shapely.intersects(simp, avoid_grown):
            simp = line
        return _flyable(np.asarray(simp.coords), radius, cost, grid, avoid_grown)

    def length(p: np.ndarray) -> float:
        return float(np.sum(np.hypot(*np.diff(p, axis=0).T)))

    lam_lo = 1e-9
    best = solve(lam_lo)
    if length(best) > limit:
        scale = float(np.mean(cost[~closed])) + 1e-9
        lam_hi = scale
        cand = solve(lam_hi)
        while length(cand) > limit and lam_hi < scale * 1e6:
            lam_hi *= 4
            cand = solve(lam_hi)
        if length(cand) > limit:
            cand = np.array([[sx, sy], [gx, gy]])
        best = cand
        for _ in range(10):
            mid_l = math.sqrt(lam_lo * lam_hi)
            trial = solve(mid_l)
            if length(trial) <= limit:
                best, lam_hi = trial, mid_l
            else:
                lam_lo = mid_l
    back = transformer(crs, WGS84)
    lon, lat = back.transform(best[:, 0], best[:, 1])
    lonlat = np.column_stack([lon, lat])
    vd = _veh_dict(veh)
    d_doc = _route_doc(np.array([start, goal], dtype=float), altitude_m, ground_h, vd)
    o_doc = _route_doc(lonlat, altitude_m, ground_h, vd)
    for i, doc in enumerate((d_doc, o_doc)):
        route_from_waypoints(doc["waypoints"], doc)  # flyable: the flight model accepts it
        del i
    cmp = compare_routes([d_doc, o_doc], cardset, population=population, buildings=buildings,
                         names=["direct", "optimized"], levels=levels, rank_level_db=rank_level_db,
                         resolution_m=eval_resolution_m, margin_m=None, ground_h=ground_h,
                         progress=None if progress is None else (lambda f: progress(0.5 + 0.5 * f)), cancel=cancel)
    rows = {x["route"]: x for x in cmp.doc["ranking"]}
    key = f"{rank_level_db:g}"

    def above(n: str) -> float:
        x = rows[n]
        return float((x.get("people_above") or x.get("residents_above") or {}).get(key, 0.0))

    def low(n: str) -> bool:  # the count is a lower bound: its zone is cut by the grid or lies partly off the raster
        return bool((rows[n].get("lower_bound") or {}).get(key, False))

    searched = length(best)
    kept = rows["optimized"]["rank"] >= rows["direct"]["rank"]  # a tie is not better: the direct route is simpler
    note = None
    if kept:
        note = (f"kept the direct route: the searched route ({searched:.0f} m, {above('optimized'):.0f} people above "
                f"{key} dB(A) LAmax) is not better than the direct one ({direct:.0f} m, {above('direct'):.0f}) by "
                "the ranking rule")
        lonlat, o_doc, best = np.array([start, goal], dtype=float), d_doc, np.array([[sx, sy], [gx, gy]])
    returned = "direct" if kept else "optimized"
    cmp.doc["warnings"] += warnings
    summary = {
        "method": "least-exposure graph search on a cost grid, smoothed into fly-by waypoints; re-evaluated",
        "corridor_half_width_m": r, "turn_radius_m": radius, "cost_resolution_m": resolution_m,
        "direct_length_m": direct, "optimized_length_m": length(best), "max_detour_pct": max_detour_pct,
        "detour_pct": 100.0 * (length(best) / direct - 1.0), "altitude_m": altitude_m,
        "rank_level_db": rank_level_db, "waypoints": int(len(best)),
        f"people_above_{key}_direct": above("direct"), f"people_above_{key}_optimized": above(returned),
        f"lower_bound_{key}_direct": low("direct"), f"lower_bound_{key}_optimized": low(returned),
        "reduction_people": above("direct") - above(returned),
        "reduction_pct": 100.0 * (1 - above(returned) / above("direct")) if above("direct") > 0 else 0.0,
        "kept_direct": kept, "note": note, "searched_length_m": searched,
        f"people_above_{key}_searched": above("optimized"), "search_area_uncovered_share": share,
        "warnings": warnings,
    }
    return Optimized(lonlat, d_doc, o_doc, cmp, summary)
