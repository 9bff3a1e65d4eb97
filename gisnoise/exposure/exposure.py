"""Exposure of a map: people and dwellings by 5 dB class, area above each level; ``exposure.json``.

:func:`map_exposure` joins the pieces: people from a population raster
(:func:`gisnoise.exposure.stats.population_exposure`), buildings at their most exposed
façade (:func:`gisnoise.exposure.facades.facade_levels`: needs the flight and its cards),
and the area above each level (:func:`gisnoise.exposure.stats.area_above`).
:func:`write_exposure` writes ``exposure.json`` (schema ``gisnoise/exposure/1``) and a
Markdown table ``exposure.md``.

Lower bounds: where a band's values end inside the grid's extent (the grid's edge, or cells
without a level: receivers outside the DEM) at or above a class's lower edge, the area and the
people of that class go on beyond the map and are not counted.  Such classes carry
``"lower_bound": true`` (in ``area_above`` and in the population's classes and ``above``), and
``warnings`` names the band, its levels and the level the edge reaches
(:func:`gisnoise.maps.clipping.edge_max`, the rule that flags clipped contours).

Where the population raster does not reach: people outside its extent, or on its nodata cells, are unknown, not
none.  The share of each band's area at or above a class's lower edge that the raster leaves uncovered
(:func:`gisnoise.exposure.stats.uncovered_shares`) is kept in ``population.coverage``; a class whose share exceeds
:data:`~gisnoise.exposure.stats.UNCOVERED_SHARE` (1 %) is a lower bound too, and one warning
(:func:`coverage_warning`) names each band's share above its lowest class and those classes.  In ``exposure.md``
people counts that are lower bounds read ``≥ N``.

Buildings whose residents or dwellings are null are classed without them (:func:`gisnoise.exposure.read_buildings`):
each class counts them in ``residents_unknown`` (``dwellings_unknown``), and the reader's warnings join the
document's, as the population reader's do (a raster denser than the densest districts on record).

Buildings are classed by their façade level at the assessment height (``facade.height_m``, 4 m).  When the layer
has heights or storeys, each metric also holds ``storeys``: per building the level at its most exposed storey
(:mod:`gisnoise.exposure.storeys`; null for a building without a height), that storey and its receiver's height,
and the loudest of them all; ``exposure.md`` lists the buildings loudest there.

Areas are on the ground: a cell's area in the map's CRS over the CRS's areal scale at the cell.  People are those on
the map (``total_people``); those on cells without a level are ``people_without_level``.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure.facades import ASSESSMENT_HEIGHT_M, facade_levels
from gisnoise.exposure.layers import Buildings, LevelsRaster, Population
from gisnoise.exposure.stats import (
    EVENT_EDGES,
    UNCOVERED_SHARE,
    area_above,
    class_edges,
    events_area_above,
    population_event_exposure,
    population_exposure,
    population_points,
    uncovered_shares,
)
from gisnoise.exposure.storeys import STOREY_HEIGHT_M
from gisnoise.flight import Trajectory
from gisnoise.jsonio import to_jsonable
from gisnoise.maps.clipping import edge_max

__all__ = ["SCHEMA", "map_exposure", "write_exposure", "exposure_table", "lower_bound_warning", "coverage_warning"]

SCHEMA = "gisnoise/exposure/1"


def _building_classes(level: np.ndarray, weights: np.ndarray | None, edges: Sequence[float]) -> list[float]:
    w = np.ones_like(level) if weights is None else weights
    out = []
    for j, e in enumerate(edges):
        hi = edges[j + 1] if j + 1 < len(edges) else np.inf
        out.append(float(w[(level >= e) & (level < hi)].sum()))
    return out


def map_exposure(levels: LevelsRaster, *, population: Population | None = None, buildings: Buildings | None = None,
                 trajectory: Trajectory | None = None, cards: Any = None, metrics: Sequence[str] | None = None,
                 edges: Sequence[float] | None = None, facade_height_m: float = ASSESSMENT_HEIGHT_M,
                 facade_spacing_m: float = 5.0, ground_h: float | None = None,
                 points: tuple[np.ndarray, np.ndarray, np.ndarray, float] | None = None,
                 facades: dict[str, Any] | None = None, event_edges: Sequence[float] = EVENT_EDGES,
                 storey_height_m: float | None = STOREY_HEIGHT_M) -> dict[str, Any]:
    """The exposure document of a map (see the module docstring).

    Parameters
    ----------
    levels : LevelsRaster
        The map (:func:`gisnoise.exposure.read_levels`).
    population : Population, optional
    buildings : Buildings, optional
        Need ``trajectory`` and ``cards`` (façade levels are computed at the façades' height).
    metrics : sequence of str, optional
        Level bands to class, default every dB(A) band of the map.
    edges : sequence of float, optional
        Lower class edges, dB; default 35, 40, ..., 85 (:func:`class_edges`).
    ground_h : float, optional
        Flat ground's ellipsoidal height for façade points, m; default the map's.
    points : tuple, optional
        The population's sub-cells on the map's grid (:func:`gisnoise.exposure.population_points`),
        when already computed (several routes on one grid).
    facades : dict, optional
        Façade levels already computed (:func:`~gisnoise.exposure.facade_levels`, or
        :func:`~gisnoise.exposure.operations_facade_levels` for a day of operations); then
        ``trajectory`` and ``cards`` are not needed.
    event_edges : sequence of float
        Lower class edges of count bands (unit ``events``: N-above), default :data:`EVENT_EDGES`.
    storey_height_m : float or None
        Storey height, m: turns ``building:levels`` into a height and a height into storeys
        (:mod:`gisnoise.exposure.storeys`); None: no storeys, the façades alone.
    """
    if population is None and buildings is None:
        raise InputError("exposure: give a population raster or buildings (or both)", field="population")
    names = list(metrics) if metrics is not None else levels.level_bands()
    if not names:
        raise InputError("exposure: the map has no level bands", field="metric")
    for n in names:
        if n not in levels.bands:
            raise InputError(f"no band {n!r}; bands: {', '.join(levels.bands)}", field="metric")
    edges = list(edges) if edges is not None else class_edges()
    ev_edges = [float(e) for e in event_edges]
    counts = [n for n in names if levels.units.get(n) == "events"]
    dbs = [n for n in names if n not in counts]
    res = levels.grid.resolution
    top = {n: edge_max(levels.bands[n]) for n in names}  # the highest value where the band's values end
    area: dict[str, Any] = {}
    for n in names:
        e_n, a_n = (ev_edges, events_area_above(levels.bands[n], levels.grid, ev_edges)) if n in counts else \
            (edges, area_above(levels.bands[n], levels.grid, edges))
        area[n] = [{"level_db" if n in dbs else "level": e, "area_m2": a, "lower_bound": bool(top[n] >= e)}
                   for e, a in zip(e_n, a_n, strict=True)]
    doc: dict[str, Any] = {
        "schema": SCHEMA, "class_edges_db": edges, "class_width_db": edges[1] - edges[0] if len(edges) > 1 else None,
        "units": {n: levels.units.get(n, "dB(A)") for n in names},
        "grid": levels.grid.to_dict(),
        "area_above": area,
        "area_rule": f"map cells of {res[0]:g} x {res[1]:g} m in 2 x 2 sub-cells, level linear within each; "
                     "areas on the ground (a cell's area in the map's CRS over the CRS's areal scale there)",
        "lower_bound_rule": "a class is a lower bound (lower_bound: true) when the map's values end at or above "
                            "its lower edge: the grid's edge or a cell next to cells without a level reaches it, "
                            "so its area and people go on beyond the map",
    }
    if counts:
        doc["event_class_edges"] = ev_edges
        doc["event_rule"] = ("count bands (N-above, events) are classed by the count of the map cell holding each "
                             "population sub-cell, and their area in whole cells; a count is not interpolated")
    if population is not None:
        pts = points if points is not None else population_points(population, levels.grid)
        pe: dict[str, Any] = population_exposure(levels, population, metrics=dbs, edges=edges, points=pts) if dbs \
            else {"total_people": float(pts[2].sum()), "subcell_m": pts[3], "metrics": {}}
        for n in counts:
            pe["metrics"][n] = population_event_exposure(levels.bands[n], levels.grid, pts, ev_edges)
        doc["population"] = {"source": population.source, "total_people": pe["total_people"],
                             "subcell_m": pe["subcell_m"], "metrics": {n: pe["metrics"][n] for n in names},
                             "rule": "population cells split into sub-cells of at most half a map cell; level linear "
                                     "within each sub-cell (second-order Taylor about the nearest map cell); the "
                                     "people on the map (sub-cells within its extent) are counted (total_people), "
                                     "those on cells without a level in people_without_level"}
    doc["warnings"] = [w for w in (lower_bound_warning(n, top[n], ev_edges if n in counts else edges,
                                                       doc["units"][n], population is not None) for n in names)
                       if w is not None]
    if population is not None:
        edges_of = {n: list(ev_edges if n in counts else edges) for n in names}
        shares = uncovered_shares({n: levels.bands[n] for n in names}, levels.grid, population, edges_of)
        short = {n: [s is not None and s > UNCOVERED_SHARE for s in shares[n]] for n in names}
        doc["population"]["coverage"] = {
            "uncovered_share": {n: shares[n][0] for n in names}, "threshold": UNCOVERED_SHARE,
            "rule": "share of the map's area at or above the lowest class (map cells by their centres) outside the "
                    "population raster's extent or on its nodata cells: people there are unknown, not none; a class "
                    f"whose share above its lower edge exceeds {100 * UNCOVERED_SHARE:g} % is a lower bound"}
        for n, m in doc["population"]["metrics"].items():
            for c, cut in zip(m["classes"], short[n], strict=True):
                c["lower_bound"] = bool(top[n] >= c.get("from_db", c.get("from")) or cut)
            for a, cut in zip(m["above"], short[n], strict=True):
                a["lower_bound"] = bool(top[n] >= a.get("level_db", a.get("level")) or cut)
        said = coverage_warning(population.source, shares, short, edges_of, doc["units"])
        doc["warnings"] += ([said] if said is not None else []) + list(population.warnings)
    if buildings is not None:
        doc["warnings"] += list(buildings.warnings)
        doc["buildings"] = _buildings_doc(levels, buildings, trajectory, cards, names, edges, facade_height_m,
                                          facade_spacing_m, ground_h, facades, ev_edges, storey_height_m)
    return doc


def coverage_warning(source: str, shares: dict[str, list[float | None]], short: dict[str, list[bool]],
                     edges: dict[str, list[float]], units: dict[str, str]) -> str | None:
    """The warning of a population raster that leaves more than :data:`UNCOVERED_SHARE` of the map's area above some
    class uncovered (``short``: per band and class, whether it does); None when it covers them all.

    >>> print(coverage_warning("pop.tif", {"Lden": [0.5, 0.5, None]}, {"Lden": [True, True, False]},
    ...                        {"Lden": [35.0, 40.0, 45.0]}, {"Lden": "dB(A)"}))
    population: pop.tif does not cover the map where its levels reach the classes: Lden 50.0 % of the area at or above 35 dB(A); no data there is not nobody: the people there are not counted, and the classes with more than 1 % of their area uncovered are lower bounds (lower_bound: true): Lden from 35, 40 dB(A)
    """
    cut = [n for n in short if any(short[n])]
    if not cut:
        return None
    name = Path(source).name
    each = ", ".join(f"{n} {100 * (shares[n][0] or 0.0):.1f} % of the area at or above {edges[n][0]:g} "
                     f"{units.get(n, 'dB(A)')}" for n in cut)
    which = "; ".join(f"{n} from {', '.join(f'{e:g}' for e, s in zip(edges[n], short[n], strict=True) if s)} "
                      f"{units.get(n, 'dB(A)')}" for n in cut)
    return (f"population: {name} does not cover the map where its levels reach the classes: {each}; no data there "
            f"is not nobody: the people there are not counted, and the classes with more than "
            f"{100 * UNCOVERED_SHARE:g} % of their area uncovered are lower bounds (lower_bound: true): {which}")


def lower_bound_warning(name: str, top: float, edges: Sequence[float], unit: str = "dB(A)",
                        people: bool = True) -> str | None:
    """The warning of a band whose values end (grid edge, cells without a level) at ``top``, at or above some
    class edges: those classes' areas (and people) are lower bounds; None when no edge is reached.

    >>> print(lower_bound_warning("LAmax", 42.3, [35.0, 40.0, 45.0], people=False))
    LAmax: the map's edge (the grid's, or cells without a level) reaches 42.3 dB(A): the areas at or above 35, 40 dB(A) are lower bounds (a wider map counts them whole)
    >>> lower_bound_warning("LAmax", 30.0, [35.0, 40.0]) is None
    True
    """
    cut = [e for e in edges if top >= e]
    if not cut:
        return None
    what = "areas and people" if people else "areas"
    return (f"{name}: the map's edge (the grid's, or cells without a level) reaches {top:.1f} {unit}: the {what} "
            f"at or above {', '.join(f'{e:g}' for e in cut)} {unit} are lower bounds (a wider map counts them whole)")


def _buildings_doc(levels: LevelsRaster, b: Buildings, traj: Trajectory | None, cards: Any, names: Sequence[str],
                   edges: Sequence[float], height: float, spacing: float, ground_h: float | None,
                   fl: dict[str, Any] | None, ev_edges: Sequence[float], storey_height: float | None
                   ) -> dict[str, Any]:
    if fl is None:
        if traj is None or cards is None:
            raise InputError("buildings: façade levels need the trajectory and its cards (--trajectory, --card)",
                             field="trajectory")
        if ground_h is None:
            ground_h = levels.metadata.get("ground_h_m")
            if ground_h is None:
                raise InputError("buildings: the map does not state a flat ground height; give --ground-height",
                                 field="ground_h")
        metrics = [n for n in names if n in ("LAmax", "LAeq", "SEL")]
        if not metrics:
            raise InputError("buildings: façade levels are computed for LAmax, LAeq and SEL; the map has none of "
                             "them", field="metric")
        period = levels.metadata.get("period_s")
        fl = facade_levels(b, traj, cards, ground_h=float(ground_h), metrics=metrics, spacing_m=spacing,
                           height_m=height, period_s=period, storey_height_m=storey_height)
    else:
        metrics = [n for n in names if n in fl["buildings"]]
        if not metrics:
            raise InputError(f"buildings: no façade levels of {', '.join(names)}", field="metric")
        height, spacing = fl["points"].height_m, fl["points"].spacing_m
    pts = fl["points"]
    out: dict[str, Any] = {
        "source": b.source, "n_buildings": b.n, "fields": b.fields, "facade_points": int(pts.x.size),
        "facade": {"height_m": height, "spacing_m": spacing, "offset_m": pts.offset_m, "rule": FACADE_RULE},
        "metrics": {},
    }
    st = fl.get("storeys")
    if st is not None:
        sp = st["points"]
        out["facade"]["storeys"] = {"storey_height_m": sp.storey_height_m,
                                    "buildings_with_height": int(np.sum(sp.storeys > 0)),
                                    "per_building_height_m": [float(h) if n else None for h, n in
                                                              zip(sp.roof_m, sp.storeys, strict=True)],
                                    "per_building_storeys": [int(n) for n in sp.storeys], "rule": STOREY_RULE}
    for m in metrics:
        lv = fl["buildings"][m]["level"]
        ev = levels.units.get(m) == "events"
        e_m = ev_edges if ev else edges
        lo, hi = ("from", "to") if ev else ("from_db", "to_db")
        entry: dict[str, Any] = {
            "classes": [{lo: e, hi: e_m[j + 1] if j + 1 < len(e_m) else None,
                         "buildings": nb} for j, (e, nb) in
                        enumerate(zip(e_m, _building_classes(lv, None, e_m), strict=True))],
            "peak_facade_db": float(np.max(lv)),
        }
        for what, w in (("residents", b.residents), ("dwellings", b.dwellings)):
            if w is None:
                continue
            for c, v in zip(entry["classes"], _building_classes(lv, w, e_m), strict=True):
                c[what] = v
            unknown = b.unknown.get(what)
            if unknown is not None and unknown.any():  # no value: not counted above, so the class is a lower bound
                for c, k in zip(entry["classes"], _building_classes(lv, unknown.astype(float), e_m), strict=True):
                    c[f"{what}_unknown"] = int(k)
            occupied = w > 0
            entry[f"peak_db_at_{what}"] = float(np.max(lv[occupied])) if occupied.any() else None
        top = int(np.argmax(lv))
        p = int(fl["buildings"][m]["point"][top])
        entry["most_exposed"] = {"building": top, "wall": int(pts.wall[p]), "lon": float(pts.lon[p]),
                                 "lat": float(pts.lat[p]), "level_db": float(lv[top])}
        entry["per_building_db"] = [float(v) for v in lv]
        if st is not None:
            entry["storeys"] = _storeys_entry(st, pts, m)
        out["metrics"][m] = entry
    return out


FACADE_RULE = ("receivers at the middle of wall segments of at most spacing_m (ground metres), offset_m in front of "
               "each wall facing outdoor air (outer walls, and courtyard walls with the receivers in the courtyard), "
               "height_m above ground; a building's level is its most exposed façade point (the source-side wall); "
               "incident free-field level, no screening")
STOREY_RULE = ("a building's height is its height attribute (m, or ft: '10', '10 m', '12 ft'), else building:levels "
               "x storey_height_m; it has round(height / storey_height_m) storeys (at least 1) of equal height, "
               "and a receiver in front of every façade point at the middle of each storey; the most exposed "
               "storey is the loudest of them (per metric storeys.per_building_db, at per_building_receiver_m above "
               "ground; null: no height, judged at height_m alone); buildings are classed at height_m")


def _storeys_entry(st: dict[str, Any], pts: Any, m: str) -> dict[str, Any]:
    """A metric's levels at the most exposed storey of each building, and the loudest of them."""
    e = st["buildings"][m]
    lv = e["level"]
    has = e["point"] >= 0
    out: dict[str, Any] = {
        "per_building_db": [float(v) if h else None for v, h in zip(lv, has, strict=True)],
        "per_building_storey": [int(v) if h else None for v, h in zip(e["storey"], has, strict=True)],
        "per_building_receiver_m": [float(v) if h else None for v, h in zip(e["z_m"], has, strict=True)],
        "peak_db": None, "most_exposed": None,
    }
    known = has & np.isfinite(lv)
    if known.any():
        top = int(np.flatnonzero(known)[np.argmax(lv[known])])
        p = int(e["facade_point"][top])
        out["peak_db"] = float(lv[top])
        out["most_exposed"] = {"building": top, "storey": int(e["storey"][top]),
                               "storeys": int(st["points"].storeys[top]), "receiver_m": float(e["z_m"][top]),
                               "wall": int(pts.wall[p]), "lon": float(pts.lon[p]), "lat": float(pts.lat[p]),
                               "level_db": float(lv[top])}
    return out


def exposure_table(doc: dict[str, Any]) -> str:
    """A Markdown table per metric: people, buildings, residents, dwellings by class; area above."""
    lines = ["# Exposure", ""]
    if doc.get("warnings"):
        lines += [f"**Warning:** {w}" for w in doc["warnings"]] + [""]
    names = list(doc["area_above"])
    for n in names:
        ev = doc.get("units", {}).get(n) == "events"
        e_n = doc["event_class_edges"] if ev else doc["class_edges_db"]
        lines += [f"## {n}", "", f"| class {'events' if ev else 'dB(A)'} | people | buildings | residents | dwellings "
                  "| area above lower edge km² |", "|---|---|---|---|---|---|"]
        pop = doc.get("population", {}).get("metrics", {}).get(n)
        bld = doc.get("buildings", {}).get("metrics", {}).get(n)
        for j, a in enumerate(doc["area_above"][n]):
            lo = e_n[j]
            hi = e_n[j + 1] if j + 1 < len(e_n) else None
            label = f"{lo:g}-{hi:g}" if hi is not None else f">= {lo:g}"
            label += " *" if a.get("lower_bound") else ""
            low = "≥ " if pop and pop["classes"][j].get("lower_bound") else ""
            cells = [label, f"{low}{pop['classes'][j]['people']:.0f}" if pop else "-"]
            for key in ("buildings", "residents", "dwellings"):
                c = bld["classes"][j] if bld else {}
                cells.append(f"{'≥ ' if c.get(f'{key}_unknown') else ''}{c[key]:.0f}" if key in c else "-")
            cells.append(f"{a['area_m2'] / 1e6:.4f}")
            lines.append("| " + " | ".join(cells) + " |")
        if any(a.get("lower_bound") for a in doc["area_above"][n]):
            lines += ["", "\\* lower bound: the map's edge reaches this class, which goes on beyond the map"]
        if (pop and any(c.get("lower_bound") for c in pop["classes"])) or \
                (bld and any(k.endswith("_unknown") and v for c in bld["classes"] for k, v in c.items())):
            lines += ["", "≥ lower bound: people beyond the map's edge, outside the population raster or on its "
                          "cells without data, or buildings without a value, are not counted (see the warnings)"]
        if pop:
            lines += ["", f"people on the map without a level (on cells without value): {pop['people_without_level']:.0f}"]
        if bld:
            peak = bld["peak_facade_db"]
            lines += [f"peak façade value: {peak:.0f} events" if ev else
                      f"peak façade level: {peak:.1f} dB(A)" if np.isfinite(peak) else
                      "peak façade level: none (no flight in the period)"]
            if "storeys" in bld:
                lines += _storey_lines(bld, doc["buildings"], "events" if ev else "dB(A)")
        lines.append("")
    return "\n".join(lines)


STOREY_ROWS = 10
"""``exposure.md`` lists this many buildings loudest at their most exposed storey (all are in ``exposure.json``)."""


def _storey_lines(bld: dict[str, Any], b: dict[str, Any], unit: str) -> list[str]:
    """The lines of ``exposure.md`` on a metric's most exposed storeys: the loudest, and a table of the buildings
    loudest there, with their façade level at the assessment height beside."""
    st = bld["storeys"]
    at = b["facade"]["height_m"]
    n_height = b["facade"]["storeys"]["buildings_with_height"]
    others = f"; the others are judged at {at:g} m alone" if n_height < b["n_buildings"] else ""
    lines = ["", f"most exposed storeys ({n_height} of {b['n_buildings']} buildings with a height{others}):"]
    top = st.get("most_exposed")
    if top is None:
        return lines + ["none (no building with a height, or no flight in the period)"]

    def val(v: Any) -> str:
        return "-" if v is None or not np.isfinite(v) else f"{v:.0f}" if unit == "events" else f"{v:.1f}"

    rows = sorted((i for i, v in enumerate(st["per_building_db"]) if v is not None and np.isfinite(v)),
                  key=lambda i: -st["per_building_db"][i])[:STOREY_ROWS]
    n_of = b["facade"]["storeys"]["per_building_storeys"]
    lines += ["", f"| building | storey | m above ground | {unit} at that storey | {unit} at {at:g} m |",
              "|---|---|---|---|---|"]
    lines += [f"| {i} | {st['per_building_storey'][i]} of {n_of[i]} | {st['per_building_receiver_m'][i]:.1f} | "
              f"{val(st['per_building_db'][i])} | {val(bld['per_building_db'][i])} |" for i in rows]
    if len(rows) < n_height:
        lines += ["", f"the {len(rows)} loudest of {n_height}; every building in exposure.json (storeys)"]
    return lines


def write_exposure(doc: dict[str, Any], out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Write ``exposure.json`` and ``exposure.md`` into ``out_dir`` (created)."""
    from gisnoise.maps.pipeline import output_folder

    out = output_folder(out_dir)
    j = out / "exposure.json"
    tmp = j.with_name(j.name + ".tmp")
    tmp.write_text(json.dumps(to_jsonable(doc), indent=1, allow_nan=False))
    os.replace(tmp, j)
    md = out / "exposure.md"
    md.write_text(exposure_table(doc))
    return {"exposure": j, "table": md}
