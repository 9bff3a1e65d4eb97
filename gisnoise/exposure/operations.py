"""Exposure of a day of operations: façade levels of every flight of a schedule, combined as the map does.

:func:`operations_facade_levels` places the façade receivers of the buildings
(:func:`gisnoise.exposure.facade_points`), evaluates every flight of the schedule that has
a count there (:func:`gisnoise.exposure.point_levels`: the card's model at every sample)
and combines them with the map's rule (:func:`gisnoise.ops.period_bands`; EU Directive
2002/49/EC, Annex I):

``Lday``, ``Levening``, ``Lnight``
    ``10 log10( sum_f n_f,p 10^(SEL_f/10) / T_p )``; NaN (no level) for an *empty period*,
    one in which no flight of the schedule departs;
``Lden``
    :func:`gisnoise.ops.lden` of the three (an empty period adds no energy);
``LAmax``
    the loudest flight;
``NA<L>``
    flights of the day whose LAmax exceeds ``L`` (strictly, on the float32 ``10^(LAmax/10)``
    as the map), events.

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
from gisnoise.exposure.facades import (
    ASSESSMENT_HEIGHT_M,
    facade_points,
    most_exposed,
    most_exposed_storeys,
    point_levels,
    storey_points,
)
from gisnoise.exposure.layers import Buildings, LevelsRaster, Population
from gisnoise.exposure.stats import EVENT_EDGES
from gisnoise.exposure.storeys import STOREY_HEIGHT_M
from gisnoise.maps import MapResult
from gisnoise.ops import PERIODS, Schedule, add_flight, new_accumulators, period_bands

__all__ = ["OPERATIONS_LEVELS", "check_schedule_of", "operations_facade_levels", "operations_exposure"]

OPERATIONS_LEVELS = ("Lden", "Lday", "Levening", "Lnight", "LAmax")
"""Level bands of a day of operations that exposure classes (dB(A)); with them every ``NA<L>`` band."""

EMPTY_PERIOD_RULE = ("a period in which no flight of the schedule departs (an empty period) has no level: its band "
                     "is without value on the map and at the façades (null), its people are counted in "
                     "people_without_level, and it adds nothing to Lden")


def check_schedule_of(metadata: dict[str, Any], schedule: Schedule) -> None:
    """Refuse a schedule that is not the one a written day was made from (its ``metadata``: ``summary.json``'s, or
    ``operations.tif``'s tags), field ``schedule``.

    The façade levels come from the schedule and the areas and people from the day's map: another schedule would
    mix two days.  A day records the schedule file's SHA-256 (``schedule_sha256``): the file given must hold the
    same bytes (it may lie elsewhere; a schedule built in Python has no digest and is not compared by it).  Its
    flights with a count and their counts must be those the day lists (``flights``), whatever made the day.
    """
    recorded = metadata.get("schedule")
    digest = metadata.get("schedule_sha256")
    why = None
    if digest is not None and schedule.digest is not None and digest != schedule.digest:
        why = f"its contents differ (SHA-256 {schedule.digest[:12]}..., the day's {digest[:12]}...)"
    elif metadata.get("flights") is not None:
        want = {str(f["id"]): {p: float(f["counts"].get(p, 0.0)) for p in PERIODS} for f in metadata["flights"]}
        got = {f.id: {p: float(f.counts[p]) for p in PERIODS} for f in schedule.flights if f.total > 0}
        if got != want:
            diff = sorted(set(got) ^ set(want)) or sorted(i for i in got if got[i] != want[i])
            why = f"its flights or their counts differ (flight {diff[0]})"
    if why is not None:
        raise InputError(f"schedule: {schedule.source} is not the schedule the day was made from ({recorded}): {why}; "
                         f"its façade levels would mix two days: give {recorded}, or make the day anew with gisnoise "
                         f"operations {schedule.source}", field="schedule")


def operations_facade_levels(b: Buildings, schedule: Schedule, *, ground_h: float,
                             spacing_m: float = 5.0, height_m: float = ASSESSMENT_HEIGHT_M,
                             offset_m: float = 0.1, storey_height_m: float = STOREY_HEIGHT_M) -> dict[str, Any]:
    """Levels of a day of operations at the façade receivers and per building (see the module docstring).

    Returns what :func:`gisnoise.exposure.facade_levels` returns, with the metrics
    ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` and ``NA<L>`` for each of the
    schedule's thresholds; at the storeys of buildings with a height too (``storeys``).
    """
    if schedule.dem is not None:
        raise InputError("buildings: façade levels need flat ground; the schedule gives a DEM", field="buildings")
    pts = facade_points(b, spacing_m=spacing_m, height_m=height_m, offset_m=offset_m)
    sp = storey_points(b, pts, storey_height_m=storey_height_m) \
        if b.height_m is not None or b.levels is not None else None
    # the façade points, then the storeys' receivers
    receivers: list[tuple[np.ndarray, np.ndarray, Any]] = [(pts.lon, pts.lat, ground_h + height_m)]
    if sp is not None:
        receivers.append((pts.lon[sp.point], pts.lat[sp.point], ground_h + sp.z))
    thresholds = [float(v) for v in schedule.thresholds_db]
    accs = [new_accumulators((lon.size,), len(thresholds), time_above=False) for lon, _, _ in receivers]
    for f in schedule.flights:
        if f.total == 0:
            continue
        cards = f.cards if f.cards is not None else schedule.cards
        for acc, (lon, lat, h) in zip(accs, receivers, strict=True):
            if lon.size == 0:
                continue
            lv = point_levels(f.trajectory, cards, lon, lat, h, min_distance_m=schedule.min_distance_m)
            add_flight(acc, 10.0 ** (lv["SEL"] / 10.0), 10.0 ** (lv["LAmax"] / 10.0), f.counts, thresholds)
    levels = []
    for acc in accs:
        bands = period_bands(acc, thresholds)
        lv = {n: bands[n] for n in OPERATIONS_LEVELS}
        lv.update({f"NA{thr:g}": bands[f"NA{thr:g}"] for thr in thresholds})
        levels.append(lv)
    out = most_exposed(b, pts, levels[0], list(levels[0]))
    out["storeys"] = None if sp is None else most_exposed_storeys(b, sp, levels[1], list(levels[1]))
    return out


def operations_exposure(result: MapResult | LevelsRaster, schedule: Schedule | None, *, population: Population | None = None,
                        buildings: Buildings | None = None, edges: Sequence[float] | None = None,
                        event_edges: Sequence[float] = EVENT_EDGES, facade_height_m: float = ASSESSMENT_HEIGHT_M,
                        facade_spacing_m: float = 5.0, storey_height_m: float = STOREY_HEIGHT_M) -> dict[str, Any]:
    """The exposure document of a day of operations (:func:`gisnoise.ops.evaluate_operations`'s result,
    or its ``operations.tif`` read back with :func:`gisnoise.exposure.read_levels`).

    People by class of ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` (5 dB classes of
    ``edges``) and of every ``NA<L>`` band (classes of ``event_edges``); with ``buildings`` the
    same at each building's most exposed façade (:func:`operations_facade_levels`, flat ground
    of the map), and for buildings with a height the levels at their most exposed storey.  Cells
    the map left without value (no flight above the schedule's ``floor_db``) hold no level: their
    people are counted in ``people_without_level``; so do all people in the band of an empty
    period (no flight departs in it: ``operations.empty_periods``).
    """
    if schedule is not None:
        check_schedule_of(result.metadata, schedule)  # before any façade is evaluated
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
                                      height_m=facade_height_m, storey_height_m=storey_height_m)
    doc = map_exposure(lr, population=population, buildings=buildings, metrics=names, edges=edges, facades=fl,
                       event_edges=event_edges)
    meta = result.metadata
    flights = meta.get("flights")
    doc["operations"] = {"schedule": meta.get("schedule", schedule.source if schedule is not None else None),
                         "flights": [f["id"] for f in flights or []],
                         "lden": "EU Directive 2002/49/EC, Annex I", "floor_db": meta.get("floor_db"),
                         "empty_periods": None if flights is None else
                         [p for p in PERIODS if not any(float(f["counts"][p]) > 0 for f in flights)],
                         "empty_period_rule": EMPTY_PERIOD_RULE}
    return doc
