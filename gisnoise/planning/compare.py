"""Comparison of candidate routes: one common grid, a ranked table, difference maps.

:func:`compare_routes` reads every candidate (flight CSV, GeoJSON LineString with times,
waypoints), puts one receiver grid around all of them (so every cell is judged the same
for every route), evaluates each with the map evaluator and measures its exposure
(:mod:`gisnoise.exposure`): people above each level, the peak level at any dwelling
(most exposed façade), and the total exposure in person-dB above the lowest level
(``sum over people of max(L - L_low, 0)``).  Routes are ranked by people above the
ranking level, then by person-dB, then by the peak dwelling level, each to the step the table shows
(the whole person, the whole person-dB, 0.1 dB; :data:`~gisnoise.planning._rules.TIE_STEPS`); routes equal
in all three share a rank (``tie``), and the order of the arguments never decides.

Every route is judged alike: over one flat ground (a given ground is checked against every route as a
map checks it; routes that state different grounds are refused unless the ground is given), and for
``LAeq`` over one averaging period (``LAeq,T = SEL - 10 lg T`` with the same ``T``, by default the longest
route's duration).  Each route is checked as a map of it is (:func:`gisnoise.maps.flight_findings`: a log
cut short, a track below the ground taken from the routes, airborne samples without power, a crash, powers
outside a card's fitted range) before any evaluation; its warnings, named by route, lead the document's
``warnings``.  Counts that are lower bounds (a level's zone cut by the grid's edge, or partly outside the
population raster or on its nodata cells) carry ``lower_bound`` per level; the population reader's warnings
join the document's.

:func:`write_comparison` writes ``comparison.json`` (schema ``gisnoise/comparison/1``),
``comparison.md`` (the table), ``levels.tif`` (the metric of every route, one band per
route) and ``difference.tif`` (each other route minus the best, one band per route, dB).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure import (
    UNCOVERED_SHARE,
    Buildings,
    LevelsRaster,
    Population,
    area_above,
    map_exposure,
    population_points,
    population_scores,
    uncovered_shares,
)
from gisnoise.flight import Trajectory, read_route
from gisnoise.geo import GridSpec, grid_for_points
from gisnoise.jsonio import to_jsonable
from gisnoise.limits import check_map_level
from gisnoise.maps import (
    SEL_OFFSET_DB,
    CardSet,
    ChosenGround,
    MapResult,
    auto_margin,
    crs_scale_warning,
    evaluate_flying,
    flight_findings,
    write_geotiff,
)
from gisnoise.maps.clipping import edge_max
from gisnoise.maps.grids import resolution_warning_of
from gisnoise.maps.pipeline import flight_height
from gisnoise.planning._rules import (
    TIE_STEPS,
    common_ground,
    common_period,
    rank_rows,
)

__all__ = ["COMPARISON_SCHEMA", "Comparison", "compare_routes", "routes_margin", "score_route", "write_comparison",
           "comparison_table"]

COMPARISON_SCHEMA = "gisnoise/comparison/1"

GROUND_FROM_ROUTES = "a route's take-off or landing point or stated ground"
"""Where the common ground came from when no ground is given (the words of the below-ground warning)."""


@dataclass(frozen=True, eq=False)
class Comparison:
    """Candidates on one grid: their bands, their scores (ranked) and the document."""

    names: list[str]
    grid: GridSpec
    bands: dict[str, np.ndarray]
    metric: str
    doc: dict[str, Any]
    trajectories: dict[str, Trajectory] = field(default_factory=dict)

    @property
    def best(self) -> str:
        return str(self.doc["ranking"][0]["route"])


def _names(routes: Sequence[Any], names: Sequence[str] | None) -> list[str]:
    if names is not None:
        if len(names) != len(routes):
            raise InputError(f"names: {len(names)} names for {len(routes)} routes", field="names")
        out = [str(n) for n in names]
    else:
        out = [Path(r).stem if isinstance(r, (str, os.PathLike)) else f"route{i + 1}" for i, r in enumerate(routes)]
    seen: dict[str, int] = {}
    for i, n in enumerate(out):
        if n in seen:
            seen[n] += 1
            out[i] = f"{n}-{seen[n]}"
        else:
            seen[n] = 1
    return out


def score_route(traj: Trajectory, cards: CardSet, grid: GridSpec, *, population: Population | None = None,
                buildings: Buildings | None = None, metric: str = "LAmax",
                levels: Sequence[float] = (45.0, 50.0, 55.0, 60.0, 65.0), receiver_height: float = 1.5,
                ground_h: float | None = None, engine: str = "numpy",
                points: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None,
                period_s: float | None = None, progress: Callable[[float], Any] | None = None,
                cancel: Callable[[], bool] | None = None) -> tuple[dict[str, Any], np.ndarray]:
    """The exposure scores of one route on a given grid, and its band of ``metric``.

    One evaluator call for ``metric`` alone (no GeoTIFF, no contours), then people above each
    level and person-dB in one pass over the population (:func:`gisnoise.exposure.population_scores`)
    and the area above each level, both counted only where a level can be reached: the same
    numbers as the exposure of the full map (``docs/planning.md``).

    ``points`` are the population's sub-cells on this grid
    (:func:`gisnoise.exposure.population_points`), computed once when several routes share the grid.
    ``period_s``: the averaging period of ``LAeq``, s (default the route's own duration; routes compared on
    ``LAeq`` share one, :func:`compare_routes`).  ``progress`` (fraction 0-1) and ``cancel`` (true raises
    :class:`~gisnoise.errors.Cancelled`) go to the evaluator.  ``ground_h``: the flat ground's ellipsoidal height,
    m, by the ground rule of every map (:mod:`gisnoise.maps.ground`: checked at or below the route's lowest flying
    point; default the route's stated ground, else its take-off or landing point; a route in the air throughout
    is refused).
    """
    lv = [float(v) for v in levels]
    res = evaluate_flying(traj, cards, grid, metrics=(metric,), receiver_height=receiver_height,
                          ground_h=ground_h, engine=engine, period_s=period_s, progress=progress,
                          cancel=cancel)  # samples on the ground make no noise
    band = res.bands[metric]
    ground_h = res.metadata.get("ground_h_m")  # the ground the rule took
    lr = LevelsRaster({metric: band}, grid, {metric: "dB(A)"}, {"ground_h_m": ground_h,
                                                               "period_s": res.metadata.get("period_s")})
    pts = points if points is not None or population is None else population_points(population, grid)
    row: dict[str, Any] = {"duration_s": traj.duration_s, "track_length_m": _track_length(traj)}
    if population is not None and pts is not None:
        ps = population_scores(band, grid, pts, lv)  # one pass: people above each level and person-dB
        row["people_above"] = {f"{e:g}": a for e, a in zip(lv, ps["above"], strict=True)}
        row["person_db"] = ps["person_db"]
        row["people_without_level"] = ps["people_without_level"]
    if buildings is None:
        area = area_above(band, grid, lv)
    else:
        ex = map_exposure(lr, buildings=buildings, trajectory=traj, cards=cards, metrics=[metric], edges=lv,
                          ground_h=ground_h, storey_height_m=None)  # ranked at the façades: no storeys
        area = [a["area_m2"] for a in ex["area_above"][metric]]
        bm = ex["buildings"]["metrics"][metric]
        row["peak_facade_db"] = bm["peak_facade_db"]
        row["peak_dwelling_db"] = bm.get("peak_db_at_dwellings", bm.get("peak_db_at_residents"))
        row["residents_above"] = _cumulative(bm["classes"], "residents")
        row["dwellings_above"] = _cumulative(bm["classes"], "dwellings")
    row["area_above_m2"] = {f"{e:g}": a for e, a in zip(lv, area, strict=True)}
    return row, band


def compare_routes(routes: Sequence[Any], cards: Any, *, population: Population | None = None,
                   buildings: Buildings | None = None, names: Sequence[str] | None = None, metric: str = "LAmax",
                   levels: Sequence[float] = (45.0, 50.0, 55.0, 60.0, 65.0), rank_level_db: float = 55.0,
                   resolution_m: float = 20.0, margin_m: float | None = None, crs: Any = None,
                   receiver_height: float = 1.5, ground_h: float | None = None, engine: str = "auto",
                   grid: GridSpec | None = None, period_s: float | None = None,
                   progress: Callable[[float], Any] | None = None, cancel: Callable[[], bool] | None = None
                   ) -> Comparison:
    """Evaluate candidate routes on one grid and rank them by exposure (see the module docstring).

    Parameters
    ----------
    routes : sequence of path, dict or Trajectory
        At least two candidates.
    cards : card paths or ids, ModelCard or CardSet
        Serving every phase of every route.
    population, buildings : optional
        Exposure layers (:func:`gisnoise.exposure.read_population`, :func:`~gisnoise.exposure.read_buildings`);
        at least one.  A route whose area above a level lies more than 1 % outside the population raster or on its
        nodata cells (the
        exposure's rule: :func:`gisnoise.exposure.uncovered_shares`, :data:`~gisnoise.exposure.UNCOVERED_SHARE`) is
        named in a warning with that share, and its people above that level are flagged ``lower_bound``: outside
        the raster people are unknown, not none.
    metric : str
        ``LAmax``, ``LAeq`` or ``SEL``: the metric judged.
    levels : sequence of float
        Levels for "people above", dB(A), ascending; person-dB counts above the first.
    rank_level_db : float
        Routes are ranked by the people above this level first; must be one of ``levels``.
    resolution_m, margin_m, crs, receiver_height, engine
        The common grid and the evaluator, as ``gisnoise contour``; ``margin_m=None`` (the default): from the
        cards, the largest over the routes of the margin at which no edge cell reaches the lowest level
        (:func:`routes_margin`), so no count is cut by the edge (a fixed 500 m cut the bundled route's zones
        above 45-55 dB(A): people above 45 dB(A) 10 114 against 17 000 on 20 people per hectare);
        ``engine="auto"``: the fast engine where it serves the cards (levels within 0.01 dB of the NumPy
        engine's).
    ground_h : float, optional
        Flat ground's ellipsoidal height, m, checked against every route as ``gisnoise contour`` checks it (at
        or below the lowest flying point; refused naming the route).  Default the ground the routes state
        (waypoints; routes that state grounds more than :data:`~gisnoise.limits.GROUND_TOLERANCE_M` apart are
        refused: over one flat ground the route on higher ground would be judged as flying higher), else the
        lowest take-off or landing point of the routes that start or end on the ground
        (:func:`gisnoise.flight.ground_from_track`); routes all in the air throughout are refused.  Routes
        whose own ground differs from the one used are named in a warning.
    grid : GridSpec, optional
        A given common grid instead of one around the routes.
    period_s : float, optional
        ``LAeq`` only: the averaging period T, s, the same for every route (``LAeq,T = SEL - 10 lg(T / 1 s)``,
        so the routes rank as by SEL); default the longest route's duration; shorter than a route is refused.
    progress : callable, optional
        Called with the fraction of the routes evaluated (0-1).
    cancel : callable, optional
        Polled while each route is evaluated; returning true raises :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    Comparison
        Its ``doc`` (``comparison.json``): ``ranking`` (rows best first: ``rank``, ``tie``, ``people_above``,
        ``lower_bound`` and ``uncovered_share`` per level, ``population_uncovered_share``, ``person_db``,
        ...), ``period_s``, ``ground_h_m``, the rules and ``warnings``.
    """
    if len(routes) < 2:
        raise InputError(f"routes: give at least two candidate routes, got {len(routes)}", field="routes")
    if population is None and buildings is None:
        raise InputError("compare: give a population raster or buildings (or both)", field="population")
    if metric not in ("LAmax", "LAeq", "SEL"):
        raise InputError(f"metric must be LAmax, LAeq or SEL, got {metric!r}", field="metric")
    lv = [check_map_level("levels", v) for v in levels]
    if not lv or any(b <= a for a, b in zip(lv, lv[1:], strict=False)):
        raise InputError(f"levels must be ascending, got {levels!r}", field="levels")
    if float(rank_level_db) not in lv:
        raise InputError(f"rank_level must be one of the levels {lv}, got {rank_level_db!r}", field="rank_level")
    nm = _names(routes, names)
    rs = [read_route(r) for r in routes]
    cardset = cards if isinstance(cards, CardSet) else CardSet(cards if isinstance(cards, (list, tuple)) else [cards])
    trajs = {n: r.trajectory for n, r in zip(nm, rs, strict=True)}
    period = common_period(trajs, metric, period_s)
    stated = {n: r.ground_h_m if r.ground_h_m is not None else r.trajectory.metadata.get("ground_h_m")
              for n, r in zip(nm, rs, strict=True)}
    # one flat ground for all: given (checked against every route), else stated by the routes, else a take-off
    # or landing point; ``taken`` is the ground when the routes gave it: each track is checked against it
    ground_h, taken, warnings = common_ground(nm, trajs, stated, ground_h, receiver_height)
    # chosen once for all routes (a given one checked against each): each route is evaluated over it as it is
    chosen = ChosenGround(ground_h, "given" if taken is None else GROUND_FROM_ROUTES)
    outside: dict[str, Any] = {}
    found_said: list[str] = []
    for n, traj in trajs.items():  # each route as a map of it is checked, before any evaluation
        found = flight_findings(traj, cardset, ground_h=taken, ground_from=GROUND_FROM_ROUTES,
                                ground_hint="--ground-height M (field ground_h_m)")
        found_said += [f"{n}: {w}" for w in found.warnings]
        if found.power_outside:
            outside[n] = found.power_outside
    warnings = found_said + warnings + (list(population.warnings) if population is not None else [])
    lon = np.concatenate([t.lon for t in trajs.values()])
    lat = np.concatenate([t.lat for t in trajs.values()])
    if grid is None:
        if margin_m is None:
            margin_m, said = routes_margin(trajs.values(), cardset, metric, lv[0], resolution_m, crs)
            warnings += said
        grid = grid_for_points(lon, lat, resolution_m, margin_m, crs)
    scale = crs_scale_warning(grid, lon, lat)
    warnings += [scale] if scale is not None else []
    coarse = resolution_warning_of(float(grid.resolution[0]), {
        n: flight_height(t, ground_h, None, 0.0, receiver_height) for n, t in trajs.items()}, "route")
    warnings += [coarse] if coarse is not None else []
    pts = population_points(population, grid) if population is not None else None
    bands: dict[str, np.ndarray] = {}
    rows: list[dict[str, Any]] = []
    for k, (n, traj) in enumerate(trajs.items()):
        def part(f: float, k: int = k) -> None:  # route k of the routes, in the comparison's fraction done
            if progress is not None:
                progress((k + min(max(f, 0.0), 1.0)) / len(trajs))

        row, band = score_route(traj, cardset, grid, population=population, buildings=buildings, metric=metric,
                                levels=lv, receiver_height=receiver_height, ground_h=chosen, engine=engine,
                                points=pts, period_s=period, progress=part, cancel=cancel)
        row["route"] = n
        bands[n] = band
        rows.append(row)
    shares = uncovered_shares(bands, grid, population, {n: lv for n in bands}) if population is not None else None
    for row in rows:
        warnings += _lower_bounds(row, bands[row["route"]], lv, metric, population,
                                  None if shares is None else shares[row["route"]])
    ranked = rank_rows(rows, f"{float(rank_level_db):g}")
    over = f" over T = {period:g} s" if period is not None else ""
    doc = {"schema": COMPARISON_SCHEMA, "metric": metric, "levels_db": lv, "rank_level_db": float(rank_level_db),
           "ranking_rule": f"people above {rank_level_db:g} dB(A) {metric}{over}, then person-dB above {lv[0]:g} "
                           "dB(A), then peak level at a dwelling; lower is better",
           "tie_rule": f"scores rounded to {TIE_STEPS[0]:g} person above {rank_level_db:g} dB(A), "
                       f"{TIE_STEPS[1]:g} person-dB and {TIE_STEPS[2]:g} dB of peak dwelling level (as the table "
                       "shows them); routes with equal scores share a rank (tie: true), listed by name, and the "
                       "next rank skips",
           "dose_metric": f"person-dB: sum over people of max({metric} - {lv[0]:g} dB, 0)",
           "period_s": period,
           "period_rule": None if period is None else (
               "LAeq,T = SEL - 10 lg(T / 1 s) with one T for every route: the longest route's duration unless "
               "given (period_s, --period)"),
           "lower_bound_rule": "a route's counts above a level are a lower bound (lower_bound: true) when its "
                               "values at the grid's edge (or next to cells without a level) reach that level, "
                               f"or when the population raster leaves more than {UNCOVERED_SHARE:.0%} of its area "
                               "above that level uncovered, outside its extent or on its nodata cells (people above "
                               "it; the exposure's rule, by cell centres)",
           "grid": grid.to_dict(), "ground_h_m": ground_h, "cards": cardset.phases, "ranking": ranked,
           "warnings": warnings}
    if outside:
        doc["power_outside_card_range"] = outside
    return Comparison(nm, grid, bands, metric, doc, trajs)


def _lower_bounds(row: dict[str, Any], band: np.ndarray, levels: Sequence[float], metric: str,
                  population: Population | None, shares: list[float | None] | None) -> list[str]:
    """Set the row's ``lower_bound``, ``uncovered_share`` (per level: the share of its area above the level that the
    population raster does not cover, None where no cell reaches it) and ``population_uncovered_share`` (that of the
    lowest level), and return the warnings of a cut grid edge and of a raster that does not cover the route."""
    name = row["route"]
    top = edge_max(band)  # the outer cells and those next to a cell without a level, as a map's contours
    flags = {f"{v:g}": bool(np.isfinite(top) and top >= v) for v in levels}
    said = [w for w in [_clipped(name, band, levels, metric)] if w is not None]
    if population is not None and shares is not None:
        row["uncovered_share"] = {f"{v:g}": s for v, s in zip(levels, shares, strict=True)}
        row["population_uncovered_share"] = shares[0]
        cut = [v for v, s in zip(levels, shares, strict=True) if s is not None and s > UNCOVERED_SHARE]
        for v in cut:
            flags[f"{v:g}"] = True
        if cut:
            said.append(f"{name}: the population raster ({Path(population.source).name}) does not cover "
                        f"{100 * (shares[0] or 0.0):.1f} % of its area above {levels[0]:g} dB(A) {metric}: people "
                        f"there are unknown, not none; the people above {', '.join(f'{v:g}' for v in cut)} dB(A) "
                        "are lower bounds (a raster that covers the route's zone counts them)")
    row["lower_bound"] = flags
    return said


def routes_margin(trajs: Any, cards: CardSet, metric: str, lowest_db: float, resolution_m: float,
                  crs: Any) -> tuple[float, list[str]]:
    """The common grid's margin from the cards: the largest over the routes of :func:`gisnoise.maps.auto_margin`
    at the lowest level (``LAmax``, and ``LAeq``, which stays below it; ``SEL`` by its own bound), and what it
    warned (a margin cut by the cell limit), once each."""
    margin, said = 0.0, []
    for traj in trajs:
        if metric == "SEL":  # auto_margin bounds the SEL at its lowest level + SEL_OFFSET_DB
            m, w = auto_margin(traj, cards, lowest_db - SEL_OFFSET_DB, resolution_m=resolution_m, crs=crs, sel=True)
        else:
            m, w = auto_margin(traj, cards, lowest_db, resolution_m=resolution_m, crs=crs, sel=False)
        margin = max(margin, m)
        said += [x for x in w if x not in said]
    return margin, said


def _clipped(name: str, band: np.ndarray, levels: Sequence[float], metric: str) -> str | None:
    """The warning for a route whose band reaches a level at the grid's edge: the counts above it miss the people
    beyond the edge (as a map flags its clipped contours)."""
    top = edge_max(band)  # the outer cells and those next to a cell without a level, as a map's contours
    cut = [v for v in levels if np.isfinite(top) and top >= v]
    if not cut:
        return None
    return (f"{name}: {metric} reaches {top:.1f} dB(A) at the grid's edge: the people, buildings and areas above "
            f"{', '.join(f'{v:g}' for v in cut)} dB(A) are lower bounds (a wider margin counts them whole)")


def _track_length(traj: Trajectory) -> float:
    from gisnoise.geo import LocalFrame

    fr = LocalFrame(float(traj.lat[0]), float(traj.lon[0]), 0.0)
    e, n, _ = fr.to_enu(traj.lat, traj.lon, np.zeros_like(traj.lat))
    return float(np.sum(np.hypot(np.diff(e), np.diff(n))))


def _cumulative(classes: list[dict[str, Any]], what: str) -> dict[str, float] | None:
    if not classes or what not in classes[0]:
        return None
    vals = [c[what] for c in classes]
    cum = np.cumsum(vals[::-1])[::-1]
    return {f"{c['from_db']:g}": float(v) for c, v in zip(classes, cum, strict=True)}


def comparison_table(doc: dict[str, Any], *, warnings: bool = True) -> str:
    """The ranking as a Markdown table: tied ranks say so, counts that are lower bounds carry a star and a
    footnote, and the warnings follow the table (``warnings=False``: not, for a terminal that prints them apart)."""
    lv = [f"{v:g}" for v in doc["levels_db"]]
    m = doc["metric"]
    period = doc.get("period_s")
    over = f", over T = {period:g} s" if period is not None else ""
    head = ["rank", "route"] + [f"people > {v}" for v in lv] + ["person-dB", "peak dwelling dB(A)", "length km"]
    lines = [f"# Candidate routes by exposure ({m}{over})", "", doc["ranking_rule"], ""]
    if period is not None:
        lines += [f"{m} of every route over the same period T = {period:g} s: {doc.get('period_rule', '')}", ""]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    starred = False
    for r in doc["ranking"]:
        pa = r.get("people_above") or r.get("residents_above") or {}
        low = r.get("lower_bound") or {}
        peak = r.get("peak_dwelling_db")
        rank = f"{r['rank']} (tie)" if r.get("tie") else str(r["rank"])
        cells = [rank, r["route"]]
        for v in lv:
            cells.append(f"{pa.get(v, float('nan')):.0f}" + (" *" if low.get(v) else ""))
            starred = starred or bool(low.get(v))
        cells += [f"{r.get('person_db', float('nan')):.0f}", "-" if peak is None else f"{peak:.1f}",
                  f"{r['track_length_m'] / 1000:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    if starred:
        lines += ["", "\\* lower bound: the zone above this level reaches the grid's edge (a wider --margin counts it "
                  "whole) or lies partly outside the population raster or on its cells without data (people there "
                  "are unknown); see the warnings. A route ranked by a starred count may rank too well"]
    if any(r.get("tie") for r in doc["ranking"]):
        lines += ["", f"(tie): {doc.get('tie_rule', 'equal scores share a rank')}"]
    if warnings and doc.get("warnings"):
        lines += ["", "## Warnings", ""] + [f"* {w}" for w in doc["warnings"]]
    return "\n".join(lines) + "\n"


def write_comparison(cmp: Comparison, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Write comparison.json, comparison.md, levels.tif (one band per route) and difference.tif."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: output exists and is not a folder", field="out")
    out.mkdir(parents=True, exist_ok=True)
    best = cmp.best
    paths: dict[str, Path] = {}
    meta = {"metric": cmp.metric, "best": best}
    lv = MapResult(dict(cmp.bands), cmp.grid, {"units": {n: "dB(A)" for n in cmp.bands}, **meta})
    paths["levels"] = write_geotiff(lv, out / "levels.tif")
    diff = {f"{n} - {best}": cmp.bands[n] - cmp.bands[best] for n in cmp.names if n != best}
    dr = MapResult(diff, cmp.grid, {"units": {n: "dB" for n in diff}, **meta,
                                    "meaning": f"{cmp.metric} of each route minus the best route's, dB"})
    paths["difference"] = write_geotiff(dr, out / "difference.tif")
    j = out / "comparison.json"
    tmp = j.with_name(j.name + ".tmp")
    tmp.write_text(json.dumps(to_jsonable(cmp.doc), indent=1, allow_nan=False))
    os.replace(tmp, j)
    paths["comparison"] = j
    md = out / "comparison.md"
    md.write_text(comparison_table(cmp.doc))
    paths["table"] = md
    return paths
