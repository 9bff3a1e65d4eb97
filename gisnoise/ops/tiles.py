"""The work of a day of operations in tiles: the plan, the tiles, one flight on one tile, tiles on threads.

The work runs on the fast engine (:mod:`gisnoise.maps.fastkernel`) in tiles of the grid
whose column edges fall on the kernel's segments (:func:`tile_windows`), so that every
tile's cells equal the whole grid's bit for bit.  Each tile takes the flights in schedule
order (:func:`_tile_step` per flight), so the single-process path (:func:`run_local`,
tiles on threads) and the Dask path (:mod:`gisnoise.ops.scale`) form the same sums in
the same order: bitwise the same bands.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, InputError
from gisnoise.flight import Trajectory, flying_parts
from gisnoise.geo import GridSpec
from gisnoise.maps import (
    CardSet,
    ChosenGround,
    FlightInstants,
    Receivers,
    WindowResult,
    map_threads,
    prepare_flight,
    receivers_for,
    require_numba,
    run_window,
    window_lattice,
)
from gisnoise.ops.accumulate import accumulate, new_accumulators
from gisnoise.ops.schedule import Schedule

__all__ = ["DEFAULT_TILE_CELLS", "FlightParts", "DAY_GROUND_SOURCE", "Plan", "flights_ground", "make_plan", "run_local", "tile_windows"]

log = logging.getLogger(__name__)

DEFAULT_TILE_CELLS = 1 << 18
"""Cells per tile (about 512 x 512): the unit of work and of memory per task."""


def tile_windows(shape: tuple[int, int], seg: int, tile_cells: int = DEFAULT_TILE_CELLS) -> list[tuple[int, ...]]:
    """Tiles ``(r0, r1, c0, c1)`` of a grid of ``shape`` with column edges on multiples of ``seg``.

    Aligned edges make every tile's cells bitwise equal to the whole grid's.

    >>> tile_windows((5, 10), seg=4, tile_cells=12)
    [(0, 3, 0, 4), (0, 3, 4, 8), (0, 3, 8, 10), (3, 5, 0, 4), (3, 5, 4, 8), (3, 5, 8, 10)]
    """
    H, W = shape
    tile_cells = max(1, int(tile_cells))
    side = max(1, int(math.sqrt(tile_cells)))
    cols = min(W, seg * max(1, round(side / seg)))
    rows = max(1, min(H, tile_cells // max(cols, 1)))
    out: list[tuple[int, ...]] = []
    for r0 in range(0, H, rows):
        for c0 in range(0, W, cols):
            out.append((r0, min(r0 + rows, H), c0, min(c0 + cols, W)))
    return out


@dataclass(frozen=True, eq=False)
class FlightParts:
    """One flight's instants: one part per flying stretch (samples on the ground make no noise, as on a map).

    The parts' results on a tile combine into the flight's: the largest ``10^(L/10)``, the sums
    of exposure and of time above; so N-above counts the flight once.
    """

    parts: tuple[FlightInstants, ...]

    @property
    def duration_s(self) -> float:
        """Time the flight sounds (its flying stretches), s."""
        return float(sum(p.duration_s for p in self.parts))

    @property
    def n(self) -> int:
        """Evaluation instants."""
        return int(sum(p.n for p in self.parts))


def flight_parts(traj: Trajectory, prepare: Callable[[Trajectory], FlightInstants]) -> FlightParts:
    """The parts of ``traj`` that make noise (:func:`gisnoise.flight.flying_parts`, as a map's), each prepared by
    ``prepare``."""
    return FlightParts(tuple(prepare(p) for p in flying_parts(traj)))


@dataclass(frozen=True, eq=False)
class Plan:
    """What every tile needs: receivers and the flights' instants in their frame."""

    rc: Receivers
    flights: tuple[FlightParts, ...]  # schedule order, flights without counts left out
    counts: tuple[dict[str, float], ...]
    ids: tuple[str, ...]
    thresholds: tuple[float, ...]
    floor_db: float | None = None


def flights_ground(schedule: Schedule) -> float | None:
    """The flat ground the flights give when the schedule states neither ground nor DEM: the lowest of their
    stated grounds and take-off or landing points (:attr:`Flight.ground_h_m`); None when the schedule gives it."""
    if schedule.ground_h_m is not None or schedule.dem is not None:
        return None
    stated = [f.ground_h_m for f in schedule.flights if f.ground_h_m is not None]
    return min(stated) if stated else None


DAY_GROUND_SOURCE = "take-off or landing point of a flight, or a route's stated ground"
"""The metadata's ``ground_h_source`` when a day's ground came from its flights (the schedule gives neither
``ground_h_m`` nor ``dem``)."""


def make_plan(schedule: Schedule, grid: GridSpec) -> Plan:
    """The receivers of ``grid`` and every flight with a count in their frame, in schedule order.

    Without a DEM or a ground height, flat ground lies at the lowest of the flights' own grounds (stated by
    their routes, or their take-off or landing points: :func:`flights_ground`); flights all in the air
    throughout are refused (:func:`gisnoise.maps.checked_ground`).  The schedule's ground is checked against
    each flight by :func:`gisnoise.ops.schedule_findings`, which names the flight.
    """
    require_numba()
    day = flights_ground(schedule)
    ground = (ChosenGround(schedule.ground_h_m) if schedule.ground_h_m is not None
              else None if day is None else ChosenGround(day, DAY_GROUND_SOURCE))
    rc = receivers_for(grid, [f.trajectory for f in schedule.flights], receiver_height=schedule.receiver_height_m,
                       dem=schedule.dem, ground_h=ground, dem_offset_m=schedule.dem_offset_m)
    frame = rc.frame
    flights, counts, ids = [], [], []
    for f in schedule.flights:
        if f.total == 0:
            log.info("flight %s has no counts; left out", f.id)
            continue
        cards = f.cards if f.cards is not None else schedule.cards
        cards = cards if isinstance(cards, CardSet) else CardSet(cards)
        flights.append(flight_parts(f.trajectory, partial(prepare_flight, cards=cards, frame=frame,
                                                          substeps=schedule.substeps,
                                                          min_distance_m=schedule.min_distance_m,
                                                          floor_db=schedule.floor_db)))
        counts.append(dict(f.counts))
        ids.append(f.id)
    if not flights:
        raise InputError(f"{schedule.source}: no flight has a count above 0", field="counts")
    return Plan(rc, tuple(flights), tuple(counts), tuple(ids), schedule.thresholds_db, schedule.floor_db)


def _tile_step(acc: dict[str, np.ndarray] | None, fl: FlightParts, counts: Mapping[str, float], rc: Receivers,
               window: tuple[int, ...], thresholds: Sequence[float], copy: bool = False,
               lattice: Any = None, floor_db: float | None = None) -> dict[str, np.ndarray]:
    """One flight on one tile, added to the tile's accumulators.

    ``copy=True`` leaves ``acc`` untouched (a cluster task must not change its inputs:
    a retried task would add twice); the sums are the same either way.  ``lattice``: the
    tile's receiver lattice when already computed; ``floor_db``: the flights' floor.
    """
    r0, r1, c0, c1 = window
    if acc is None:
        acc = new_accumulators((r1 - r0, c1 - c0), len(thresholds))
    elif copy:
        acc = {k: v.copy() for k, v in acc.items()}
    res = run_window(fl.parts[0], rc, r0, r1, c0, c1, thresholds, lattice=lattice)
    for part in fl.parts[1:]:
        more = run_window(part, rc, r0, r1, c0, c1, thresholds, lattice=lattice)
        res = WindowResult(np.maximum(res.emax, more.emax), res.energy + more.energy, res.ta + more.ta,
                           res.computed | more.computed)
    bound = 0.0 if floor_db is None else fl.duration_s * 10.0 ** (floor_db / 10.0)
    return accumulate(acc, res, counts, thresholds, bound)


def _tile_all(plan: Plan, window: tuple[int, ...], cancel: Callable[[], bool] | None = None) -> dict:
    """Every flight, in schedule order, on one tile."""
    rc = plan.rc.for_window(*window)
    lattice = window_lattice(rc, *window)
    acc = None
    for fl, counts in zip(plan.flights, plan.counts, strict=True):
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")
        acc = _tile_step(acc, fl, counts, rc, window, plan.thresholds, lattice=lattice, floor_db=plan.floor_db)
    assert acc is not None
    return acc


def run_local(plan: Plan, windows: Sequence[tuple[int, ...]], put: Callable[[tuple[int, ...], dict], None],
              threads: int, cancel: Callable[[], bool] | None) -> None:
    """Every tile of ``plan`` on ``threads`` threads of this process, ``put(window, accumulators)`` as each finishes."""
    map_threads(lambda w: _tile_all(plan, w, cancel), windows, put, threads)
