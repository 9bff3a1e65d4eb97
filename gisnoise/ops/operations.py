"""A day of operations: many flights with counts per period -> LAeq per period, Lden, N-above, time above.

:func:`evaluate_operations` takes a :class:`~gisnoise.ops.schedule.Schedule` (the flights
of an average day, each flown a number of times in each period of EU Directive
2002/49/EC, Annex I: :mod:`gisnoise.ops.periods`) and forms on a receiver grid

``Lday``, ``Levening``, ``Lnight``
    ``10 log10( sum_f n_f,p E_f / T_p )`` over the flights ``f`` with counts ``n_f,p`` in
    period ``p`` of length ``T_p`` and single-event exposure ``E_f = integral 10^(L/10) dt``
    (s; ``SEL_f = 10 log10 E_f``); a flight counts in the period in which it departs;
``Lden``
    the day-evening-night level (:func:`~gisnoise.ops.periods.lden`);
``NA<L>_<period>``
    number of flights whose LAmax exceeds ``L`` (N-above), events;
``TA<L>_<period>``
    time the level exceeds ``L``, summed over the flights, s;

and over the whole day ``LAmax`` (the loudest flight), ``NA<L>`` and ``TA<L>``
(:mod:`gisnoise.ops.accumulate`).

The work runs on the fast engine in tiles of the grid (:mod:`gisnoise.ops.tiles`); each
tile takes the flights in schedule order, so the single-process path (without a
cluster, tiles on threads) and the Dask path (:mod:`gisnoise.ops.scale`, ``scheduler=``
or ``workers=``) give bitwise the same bands.  With the schedule's ``floor_db`` the fast
engine skips a flight at cells where it is certainly below the floor; its exposure
there is below ``duration 10^(floor/10)``, so each level band is kept where the skipped
flights could move it by at most 0.01 dB and NaN elsewhere (LAmax: kept where at or
above the floor).  N-above and time above are exact; their thresholds must not lie
below the floor.

Every flight is checked as a map of it is (:func:`schedule_findings`, :mod:`gisnoise.maps.flightchecks`): a log
cut short, a track below the ground taken from the flights, airborne samples without power, a crashed vehicle
lying upside down, powers outside a card's fitted range; the warnings are the result's ``metadata["warnings"]``
(kept in ``summary.json`` and the contours' GeoJSON, printed by ``gisnoise operations``) and the refusals come
before any evaluation.

The day's flat ground is checked against each flight as a map checks a given ground: a schedule's ``ground_h_m``
above a flight's lowest flying point is refused (:func:`gisnoise.limits.check_ground_below`, the words of ``contour
--ground-height``, naming the flight).  One flat ground serves every flight, so a flight whose own ground (its
route's, or its take-off or landing point) lies far from it is mapped as if it flew that much higher or lower
above the receivers: where that moves its levels under the track by more than :data:`GROUND_SHIFT_DB` the day
says so (:func:`ground_warnings`), with the schedule's ground, or, without one, naming every flight's ground and
the lowest, which the day takes.  A DEM puts the receivers on each place's own ground.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import ground_from_track
from gisnoise.geo import GridSpec
from gisnoise.limits import check_ground_below, check_receiver_height
from gisnoise.maps import CardSet, MapResult, band_unit, crs_scale_warning, default_threads, flight_findings
from gisnoise.maps.clipping import edge_max
from gisnoise.maps.grids import resolution_warning_of
from gisnoise.maps.pipeline import flight_height
from gisnoise.ops.accumulate import new_accumulators, period_bands
from gisnoise.ops.periods import PENALTY_DB, PERIOD_HOURS, PERIOD_START_H, PERIODS
from gisnoise.ops.scale import SCHEDULER_ENV, run_on_dask
from gisnoise.ops.schedule import Flight, Schedule
from gisnoise.ops.tiles import DEFAULT_TILE_CELLS, flights_ground, make_plan, run_local, tile_windows

__all__ = ["GROUND_SHIFT_DB", "evaluate_operations", "ground_shift_db", "schedule_findings"]

_LOCAL_TILES_PER_THREAD = 8
"""Tiles per thread at least, in one process: every thread busy, the progress in steps of a few per cent."""


def evaluate_operations(
    schedule: Schedule,
    *,
    grid: GridSpec | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    tile_cells: int | None = None,
    threads: int | None = None,
    memory_limit: str | None = None,
    progress: Callable[[float], Any] | None = None,
    cancel: Callable[[], bool] | None = None,
    single_process: bool = False,
) -> MapResult:
    """Noise of a day of operations on a grid (see the module docstring).

    Parameters
    ----------
    schedule : Schedule
    grid : GridSpec, optional
        Receivers; default :meth:`Schedule.receiver_grid`.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``); the work goes there.
    workers : int, optional
        Without ``scheduler``: start a local Dask cluster of this many worker processes.
        Without either (and no ``GISNOISE_DASK_SCHEDULER``): one process, tiles on threads.
    tile_cells : int, optional
        Cells per tile (whole segments): the memory of one task.  Default ``DEFAULT_TILE_CELLS``
        (2^18), in one process also small enough for eight tiles a thread, so that every thread
        works and the progress moves (the bands are bitwise the same for any tiling).
    threads : int, optional
        Threads of the single-process path (default :func:`gisnoise.maps.default_threads`).
    memory_limit : str, optional
        Memory limit per worker of a local cluster (Dask syntax, e.g. ``"2GiB"``).
    progress : callable, optional
        Called with the fraction of tiles done (0-1).
    cancel : callable, optional
        Polled between flights; true raises :class:`~gisnoise.errors.Cancelled`.
    single_process : bool
        One process, tiles on threads, even when ``GISNOISE_DASK_SCHEDULER`` is set
        (``scheduler`` and ``workers`` must then be None).

    Returns
    -------
    MapResult
        Bands ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` (dB(A); NaN where no
        flight is above the floor in that period), ``NA<L>_<period>``, ``NA<L>`` (events)
        and ``TA<L>_<period>``, ``TA<L>`` (s) per threshold.
    """
    if not isinstance(schedule, Schedule):
        raise InputError(f"schedule must be a Schedule, got {type(schedule).__name__}", field="schedule")
    grid = schedule.receiver_grid() if grid is None else grid
    warnings, outside = schedule_findings(schedule, grid)  # before any evaluation: a refusal costs none
    plan = make_plan(schedule, grid)
    if single_process and (scheduler or workers):
        raise InputError("single_process excludes scheduler and workers", field="single_process")
    address = scheduler or (None if workers or single_process else os.environ.get(SCHEDULER_ENV) or None)
    local = address is None and not workers
    n = (default_threads() if threads is None else max(1, int(threads))) if local else 0
    cells = DEFAULT_TILE_CELLS if tile_cells is None else int(tile_cells)
    if local and tile_cells is None:  # tiles for every thread and a progress that moves: eight a thread at least
        cells = min(cells, max(1, grid.width * grid.height // (_LOCAL_TILES_PER_THREAD * n)))
    windows = tile_windows(grid.shape, plan.rc.seg, cells)
    acc = new_accumulators(grid.shape, len(plan.thresholds))
    done = 0

    def put(w: tuple[int, ...], tile: dict) -> None:
        nonlocal done
        r0, r1, c0, c1 = w
        for k, a in tile.items():
            acc[k][r0:r1, c0:c1] = a
        done += 1
        if progress is not None:
            progress(done / len(windows))

    if not local:
        how = run_on_dask(plan, windows, put, scheduler=address, workers=workers, memory_limit=memory_limit,
                          cancel=cancel)
    else:
        run_local(plan, windows, put, n, cancel)
        how = {"executor": "threads", "threads": n}
    bands = period_bands(acc, plan.thresholds, plan.floor_db)
    if plan.rc.valid is not None and not plan.rc.valid.all():
        for a in bands.values():
            a[~plan.rc.valid] = np.nan
    units = {}
    for k in bands:
        units[k] = "events" if k.startswith("NA") else band_unit(k)
    meta = {
        "grid": grid.to_dict(),
        "units": units,
        "schedule": schedule.source,
        **({"schedule_sha256": schedule.digest} if schedule.digest is not None else {}),
        "periods": {p: {"start_h": PERIOD_START_H[p], "hours": PERIOD_HOURS[p], "penalty_db": PENALTY_DB[p]}
                    for p in PERIODS},
        "lden": "EU Directive 2002/49/EC, Annex I",
        "flights": [{"id": i, "counts": c, "duration_s": fl.duration_s, "instants": fl.n}
                    for i, c, fl in zip(plan.ids, plan.counts, plan.flights, strict=True)],
        "thresholds_db": list(plan.thresholds),
        "levels_db": list(schedule.levels_db),
        "floor_db": schedule.floor_db,
        "cells_below_floor": int((~acc["any"]).sum()),
        "receiver_height_m": schedule.receiver_height_m,
        **(plan.rc.ground or {}),
        "engine": "fast",
        "tiles": len(windows),
        "execution": how,
        "warnings": warnings + reach_warnings(bands, plan.thresholds),
    }
    if outside:
        meta["power_outside_card_range"] = outside
    return MapResult(bands=bands, grid=grid, metadata=meta)


def reach_warnings(bands: dict[str, np.ndarray], thresholds: Any) -> list[str]:
    """One line per threshold whose day's N-above (``NA<L>``) is above zero at the grid's edge: the area where
    flights exceed it reaches beyond the map (its time above and the people it counts are cut there too)."""
    out = []
    for k in thresholds:
        na = bands.get(f"NA{k:g}")
        if na is None or na.ndim != 2 or not na.size:
            continue
        top = edge_max(na)  # the outer cells and those next to cells without a value
        if np.isfinite(top) and top > 0.0:
            out.append(f"NA{k:g}: up to {top:g} flights a day exceed {k:g} dB(A) at the grid's edge: "
                       f"the area where they do reaches beyond the map (a wider margin shows it whole)")
    return out


GROUND_FROM_FLIGHTS = "a take-off or landing point of a flight, or a route's stated ground"
"""Where a day's ground came from when the schedule gives neither ``ground_h_m`` nor ``dem``."""


def schedule_findings(schedule: Schedule, grid: GridSpec) -> tuple[list[str], dict[str, Any]]:
    """The checks a map makes of its flight (:func:`gisnoise.maps.flight_findings`) on every flight with a count,
    the ground the day is mapped over against each flight's own (:func:`ground_warnings`), and the grid's CRS
    scale check at the flights.

    Returns the warnings (a warning several flights share is one line naming them all: ``flights a, b: ...``) and,
    per flight, the cards used outside the powers they were fitted at.  Raises
    :class:`~gisnoise.errors.InputError` as a map of the flight would: a schedule's ``ground_h_m`` above a flight's
    lowest flying point (:func:`gisnoise.limits.check_ground_below`, the check of ``contour --ground-height``,
    naming the flight), receivers below the ground, a card valid only at the power flown meeting other powers,
    no airborne sample drawing power.
    """
    check_receiver_height(schedule.receiver_height_m, field="receiver_height_m")
    flown = [f for f in schedule.flights if f.total > 0]
    if schedule.ground_h_m is not None:
        for f in flown:
            try:
                check_ground_below(schedule.ground_h_m, f.trajectory.flying_heights(), field="ground_h_m")
            except InputError as exc:
                raise InputError(f"{schedule.source}: flight {f.id!r}: {exc}", field="ground_h_m") from None
    ground = flights_ground(schedule)
    dem = None
    if schedule.dem is not None and not isinstance(schedule.dem, np.ndarray):  # an array: heights per cell
        from gisnoise.geo import Dem, read_dem

        dem = schedule.dem if isinstance(schedule.dem, Dem) else read_dem(schedule.dem)
    said: dict[str, list[str]] = {}
    outside: dict[str, Any] = {}
    for f in flown:
        cards = f.cards if f.cards is not None else schedule.cards
        found = flight_findings(f.trajectory, cards if isinstance(cards, CardSet) else CardSet(cards),
                                ground_h=ground, ground_from=GROUND_FROM_FLIGHTS,
                                ground_hint="the schedule's ground_h_m or dem", dem=dem,
                                dem_offset_m=schedule.dem_offset_m)
        for w in found.warnings:
            said.setdefault(w, []).append(f.id)
        if found.power_outside:
            outside[f.id] = found.power_outside
    warnings = [f"flight{'s' if len(ids) > 1 else ''} {', '.join(ids)}: {w}" for w, ids in said.items()]
    warnings += ground_warnings(schedule)
    flat = schedule.ground_h_m if schedule.ground_h_m is not None else ground
    heights = {f.id: flight_height(f.trajectory, flat, schedule.dem if dem is None else dem, schedule.dem_offset_m,
                                   schedule.receiver_height_m)
               for f in flown}
    coarse = resolution_warning_of(float(grid.resolution[0]), heights)  # the day's LAmax, N-above need the footprint
    warnings += [coarse] if coarse is not None else []
    lon = np.concatenate([f.trajectory.lon for f in schedule.flights])
    lat = np.concatenate([f.trajectory.lat for f in schedule.flights])
    scale = crs_scale_warning(grid, lon, lat)
    return warnings + ([scale] if scale is not None else []), outside


GROUND_SHIFT_DB = 1.0
"""How far a flight's levels under its track may move because the day's flat ground is not its own, dB, before the
day says so (:func:`ground_warnings`).  The limit the map's resolution warning keeps LAmax under the track within.
By spherical spreading a flight ``H`` m above the receivers on its own ground moves by 1 dB when the day's ground
lies about ``0.12 H`` away from its own: 3.5 m for a flight 30 m up, 12 m for one 100 m up (a pad on a roof of
that town stays silent, a log on another height datum does not)."""


def own_ground(flight: Flight) -> float | None:
    """A flight's own flat ground, m: the one its route states or its take-off or landing point
    (:attr:`~gisnoise.ops.Flight.ground_h_m`, else :func:`gisnoise.flight.ground_from_track`); None when the
    track is in the air throughout."""
    return flight.ground_h_m if flight.ground_h_m is not None else ground_from_track(flight.trajectory)


def ground_shift_db(flight: Flight, ground_h: float, receiver_height: float = 1.5, *, own: float | None = None
                    ) -> tuple[float, float, float] | None:
    """How a flight's levels under its track change when it is mapped over flat ground at ``ground_h`` (m) rather
    than its own (:func:`own_ground`).

    Returns ``(shift_db, height_own_m, height_used_m)``: the flight's median height above the receivers while
    flying over each ground (:func:`gisnoise.maps.pipeline.flight_height`) and ``20 lg(height_own /
    height_used)``, the change of a level under the track by spherical spreading (negative: lower; +inf when the
    flight would be at or below the receivers over ``ground_h``).  None when the flight has no ground of its own,
    or one it does not rise above the receivers over (a hover whose first sample, at rest at its lowest point, the
    ground rule takes for a vehicle standing on the ground: no take-off).  ``own``: the flight's own ground when the
    caller has it already.
    """
    own = own_ground(flight) if own is None else own
    if own is None:
        return None
    h_own = flight_height(flight.trajectory, own, None, 0.0, receiver_height)
    h_used = flight_height(flight.trajectory, ground_h, None, 0.0, receiver_height)
    if h_own is None or h_used is None or h_own <= 0.0:
        return None
    if h_used <= 0.0:
        return np.inf, h_own, h_used
    return 20.0 * float(np.log10(h_own / h_used)), h_own, h_used


def _shifted(s: float, h_own: float, h_used: float) -> str:
    how = "lower" if s < 0 else "higher"
    return (f"its levels under the track {abs(s):.1f} dB {how} (it flies {h_used:.1f} m above the receivers "
            f"instead of {h_own:.1f} m, median while flying; more where it flies lower, at take-off and landing)")


def ground_warnings(schedule: Schedule) -> list[str]:
    """Flights mapped over a flat ground far from their own (see :data:`GROUND_SHIFT_DB`).

    With the schedule's ``ground_h_m``: one line per flight whose levels under its track move by more than
    :data:`GROUND_SHIFT_DB` over it, naming its own ground and the schedule's.  Without it (and without a DEM) the
    day lies on the lowest of the flights' grounds (:func:`gisnoise.ops.tiles.flights_ground`): one line naming
    every flight's ground and the one used when that moves some flight's levels by more.  A DEM puts every
    receiver on its own ground: nothing to say.
    """
    if schedule.dem is not None:
        return []
    flown = [f for f in schedule.flights if f.total > 0]
    used = schedule.ground_h_m if schedule.ground_h_m is not None else flights_ground(schedule)
    if used is None:
        return []
    owns = {f.id: own_ground(f) for f in flown}
    far: list[tuple[Flight, float, tuple[float, float, float]]] = []
    for f in flown:
        own = owns[f.id]
        shift = None if own is None else ground_shift_db(f, used, schedule.receiver_height_m, own=own)
        if shift is not None and own is not None and abs(shift[0]) > GROUND_SHIFT_DB:
            far.append((f, own, shift))
    if schedule.ground_h_m is not None:
        return [f"flight {f.id}: its own ground (stated by its route, or its take-off or landing point) lies at "
                f"{own:.1f} m, {abs(own - used):.1f} m {'above' if own > used else 'below'} the schedule's ground_h_m "
                f"{used:.1f} m: mapped over that ground, {_shifted(*s)}; check the flight's heights (a log's "
                f"geoid_undulation_m) and the ground, or give a dem, which maps each flight over its own ground"
                for f, own, s in far]
    if not far:
        return []
    grounds: dict[str, list[str]] = {}
    for f in flown:
        own = owns[f.id]
        if own is not None:
            grounds.setdefault(f"{own:.1f} m", []).append(f.id)
    listed = "; ".join(f"{', '.join(ids)} {g}" for g, ids in grounds.items())
    moved = "; ".join(f"flight {f.id}: {_shifted(*s)}" for f, _, s in far)
    return [f"ground: the flights' own grounds (stated by their routes, or their take-off or landing points) differ "
            f"({listed}); the day is mapped over the lowest, {used:.1f} m, as one flat ground: {moved}; give a dem, "
            f"which maps each flight over its own ground, or the schedule's ground_h_m"]
