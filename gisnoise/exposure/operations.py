"""Exposure of a day of operations: façade levels of every flight of a schedule, combined as the map does.

:func:`operations_facade_levels` places the façade receivers of the buildings
(:func:`gisnoise.exposure.facade_points`), evaluates every flight of the schedule that has
a count there (:func:`gisnoise.exposure.point_levels`: the card's model at every sample)
and combines them with the rules of :mod:`gisnoise.ops` (EU Directive 2002/49/EC,
Annex I):

``Lday``, ``Levening``, ``Lnight``
    ``10 log10( sum_f n_f,p 10^(SEL_f/10) / T_p )``;
``Lden``
    :func:`gisnoise.ops.lden` of the three;
``LAmax``
    the loudest flight;
``NA<L>``
    flights of the day whose LAmax exceeds ``L`` (strictly, as the map), events.

:func:`operations_exposure` gives the ``exposure.json`` document of a day of operations:
people by class of every level band and of the N-above bands of the operations' map, and
the buildings at their most exposed façade.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure.exposure import map_exposure
from gisnoise.exposure.facades import ASSESSMENT_HEIGHT_M, facade_points, most_exposed, point_levels
from gisnoise.exposure.layers import Buildings, LevelsRaster, Population
from gisnoise.exposure.stats import EVENT_EDGES
from gisnoise.maps import MapResult
from gisnoise.ops import PERIOD_HOURS, PERIODS, Schedule, lden

__all__ = ["OPERATIONS_LEVELS", "operations_facade_levels", "operations_exposure"]

OPERATIONS_LEVELS = ("Lden", "Lday", "Levening", "Lnight", "LAmax")
"""Level bands of a day of operations that exposure classes (dB(A)); with them every ``NA<L>`` band."""


def operations_facade_levels(b: Buildings, schedule: Schedule, *, ground_h: float,
                             spacing_m: float = 5.0, height_m: float = ASSESSMENT_HEIGHT_M,
                             offset_m: float = 0.1) -> dict[str, Any]:
    """Levels of a day of operations at the façade receivers and per building (see the module docstring).

    Returns what :func:`gisnoise.exposure.facade_levels` returns, with the metrics
    ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` and ``NA<L>`` for each of the
    schedule's thresholds.
    """
    if schedule.dem is not None:
        raise InputError("buildings: façade levels need flat ground; the schedule gives a DEM", field="buildings")
    pts = facade_points(b, spacing_m=spacing_m, height_m=height_m, offset_m=offset_m)
    energy = {p: np.zeros(pts.x.size) for p in PERIODS}
    lmax = np.full(pts.x.size, -np.inf)
    thresholds = [float(v) for v in schedule.thresholds_db]
    na = {thr: np.zeros(pts.x.size) for thr in thresholds}
    for f in schedule.flights:
        if f.total == 0:
            continue
        cards = f.cards if f.cards is not None else schedule.cards
        lv = point_levels(f.trajectory, cards, pts.lon, pts.lat, ground_h + height_m,
                          min_distance_m=schedule.min_distance_m)
        e = 10.0 ** (lv["SEL"] / 10.0)
        for p in PERIODS:
            energy[p] += f.counts[p] * e
        np.maximum(lmax, lv["LAmax"], out=lmax)
        for thr in thresholds:
            na[thr] += f.total * (lv["LAmax"] > thr)
    with np.errstate(divide="ignore"):
        per = {p: 10.0 * np.log10(energy[p] / (PERIOD_HOURS[p] * 3600.0)) for p in PERIODS}
    levels = {"Lden": lden(per["day"], per["evening"], per["night"]), "Lday": per["day"],
              "Levening": per["evening"], "Lnight": per["night"], "LAmax": lmax}
    levels.update({f"NA{thr:g}": v for thr, v in na.items()})
    return most_exposed(b, pts, levels, list(levels))


def operations_exposure(result: MapResult | LevelsRaster, schedule: Schedule | None, *, population: Population | None = None,
                        buildings: Buildings | None = None, edges: Sequence[float] | None = None,
                        event_edges: Sequence[float] = EVENT_EDGES, facade_height_m: float = ASSESSMENT_HEIGHT_M,
                        facade_spacing_m: float = 5.0) -> dict[str, Any]:
    """The exposure document of a day of operations (:func:`gisnoise.ops.evaluate_operations`'s result,
    or its ``operations.tif`` read back with :func:`gisnoise.exposure.read_levels`).

    People by class of ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` (5 dB classes of
    ``edges``) and of every ``NA<L>`` band (classes of ``event_edges``); with ``buildings`` the
    same at each building's most exposed façade (:func:`operations_facade_levels`, flat ground
    of the map).  Cells the map left without value (no flight above the schedule's
    ``floor_db``) hold no level: their people are counted in ``people_without_level``.
    """
    names = [n for n in OPERATIONS_LEVELS if n in result.bands]
    names += [n for n in result.bands if n.startswith("NA") and "_" not in n]
    units = {n: ("events" if n.startswith("NA") else "dB(A)") for n in names}
    lr = LevelsRaster({n: result.bands[n] for n in names}, result.grid, units, dict(result.metadata))
    fl = None
    if buildings is not None:
        if schedule is None:
            raise InputError("buildings: façade levels of a day of operations need its schedule (--schedule)",
                             field="schedule")
        ground_h = result.metadata.get("ground_h_m")
        if ground_h is None:
            raise InputError("buildings: façade levels need flat ground (a ground height in the schedule, not a DEM)",
                             field="buildings")
        fl = operations_facade_levels(buildings, schedule, ground_h=float(ground_h), spacing_m=facade_spacing_m,
                                      height_m=facade_height_m)
    doc = map_exposure(lr, population=population, buildings=buildings, metrics=names, edges=edges, facades=fl,
                       event_edges=event_edges)
    meta = result.metadata
    doc["operations"] = {"schedule": schedule.source if schedule is not None else meta.get("schedule"),
                         "flights": [f["id"] for f in meta.get("flights", [])],
                         "lden": "EU Directive 2002/49/EC, Annex I", "floor_db": meta.get("floor_db")}
    return doc
