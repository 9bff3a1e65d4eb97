"""A day of operations: many flights with counts per period -> LAeq per period, Lden, N-above, time above.

A *schedule* lists the flights a place expects on an average day, each a trajectory
(flight CSV, GeoJSON LineString with times or waypoints; :func:`gisnoise.flight.routes.read_route`)
flown a number of times in each period of the day.  The periods and the day-evening-night
level are those of EU Directive 2002/49/EC, Annex I:

``day``
    07:00-19:00 (12 h);
``evening``
    19:00-23:00 (4 h), weighted +5 dB in Lden;
``night``
    23:00-07:00 (8 h), weighted +10 dB in Lden;

    Lden = 10 log10( (12 10^(Lday/10) + 4 10^((Levening+5)/10) + 8 10^((Lnight+10)/10)) / 24 )

with ``Lday``, ``Levening``, ``Lnight`` the A-weighted equivalent levels of each period,
``10 log10( sum_f n_f,p E_f / T_p )`` over the flights ``f`` with counts ``n_f,p`` in period
``p`` of length ``T_p`` and single-event exposure ``E_f = integral 10^(L/10) dt`` (s;
``SEL_f = 10 log10 E_f``).  A flight counts in the period in which it departs.  Further
bands per period and threshold level ``L``:

``NA<L>_<period>``
    number of flights whose LAmax exceeds ``L`` (N-above), events;
``TA<L>_<period>``
    time the level exceeds ``L``, summed over the flights, s;

and over the whole day ``LAmax`` (the loudest flight), ``NA<L>`` and ``TA<L>``.

The work runs on the fast engine (:mod:`gisnoise.maps.fastkernel`) in tiles of the grid;
each tile takes the flights in schedule order, so the single-process path
(:func:`evaluate_operations` without a cluster, tiles on threads) and the Dask path
(:mod:`gisnoise.ops.scale`, ``scheduler=`` or ``workers=``) give bitwise the same bands.

Schedule document (JSON, ``"schema": "gisnoise/operations/1"``; paths relative to it)::

    {"schema": "gisnoise/operations/1",
     "cards": ["cards/horizontal.json", "cards/climb.json"],
     "grid": {"resolution_m": 10, "margin_m": 500, "crs": null},
     "receiver_height_m": 1.5,
     "ground_h_m": 80.0,                   # or "dem": "dem.tif", "dem_offset_m": 0
     "levels_db": [45, 50, 55, 60, 65],    # contour levels of Lden and Lnight
     "thresholds_db": [60, 70],            # N-above and time-above levels
     "floor_db": null,                     # audibility floor of the fast engine
     "flights": [
        {"id": "north", "trajectory": "routes/north.json",
         "counts": {"day": 24, "evening": 4, "night": 1}},
        {"id": "south", "trajectory": "routes/south.csv",
         "departures": ["07:30", "12:10", "19:45", "23:20"], "cards": ["cards/other.json"]}]}

``grid`` may instead give ``"crs"``, ``"bounds": [left, bottom, right, top]`` (m) and
``"resolution_m"``; by default it covers every flight plus the margin in the local UTM zone.
Counts may be fractional (averages over a year).  With ``floor_db`` the fast engine
skips a flight at cells where it is certainly below the floor; its exposure there is
below ``duration 10^(floor/10)``, so each level band is kept where the skipped flights
could move it by at most 0.01 dB and NaN elsewhere (LAmax: kept where at or above the
floor).  N-above and time above are exact; their thresholds must not lie below the floor.

Examples
--------
>>> round(float(lden(50.0, 50.0, 50.0)), 2)
56.4
>>> period_of("06:59"), period_of("07:00"), period_of("22:59:59"), period_of("23:00")
('night', 'day', 'evening', 'night')
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, check_cell_limit, grid_for_trajectory, parse_crs
from gisnoise.jsonio import read_json_file

__all__ = [
    "PERIODS",
    "PERIOD_HOURS",
    "PENALTY_DB",
    "SCHEMA",
    "Flight",
    "Schedule",
    "evaluate_operations",
    "lden",
    "load_schedule",
    "period_of",
    "schedule_from_dict",
    "tile_windows",
    "write_operations",
]

log = logging.getLogger(__name__)

SCHEMA = "gisnoise/operations/1"
PERIODS = ("day", "evening", "night")
PERIOD_START_H = {"day": 7.0, "evening": 19.0, "night": 23.0}
"""Local clock time (h) at which each period begins (EU Directive 2002/49/EC, Annex I)."""
PERIOD_HOURS = {"day": 12.0, "evening": 4.0, "night": 8.0}
PENALTY_DB = {"day": 0.0, "evening": 5.0, "night": 10.0}
DEFAULT_TILE_CELLS = 1 << 18
"""Cells per tile (about 512 x 512): the unit of work and of memory per task."""


# --------------------------------------------------------------------------- the formulas


def lden(l_day: Any, l_evening: Any, l_night: Any) -> np.ndarray:
    """Day-evening-night level (EU Directive 2002/49/EC, Annex I), dB.

    ``10 log10((12 10^(Ld/10) + 4 10^((Le + 5)/10) + 8 10^((Ln + 10)/10)) / 24)``.
    Levels in dB(A), float or array_like (they broadcast); ``-inf`` for a period
    without sound.
    """
    ld, le, ln = (np.asarray(v, dtype=float) for v in (l_day, l_evening, l_night))
    e = _lden_energy(10.0 ** (ld / 10.0), 10.0 ** (le / 10.0), 10.0 ** (ln / 10.0))
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(e)


def _lden_energy(e_day: Any, e_evening: Any, e_night: Any) -> Any:
    """The weighted mean of the period energies ``10^(L/10)`` behind :func:`lden`."""
    return (PERIOD_HOURS["day"] * e_day * 10.0 ** (PENALTY_DB["day"] / 10.0)
            + PERIOD_HOURS["evening"] * e_evening * 10.0 ** (PENALTY_DB["evening"] / 10.0)
            + PERIOD_HOURS["night"] * e_night * 10.0 ** (PENALTY_DB["night"] / 10.0)) / 24.0


def period_of(clock: str | float) -> str:
    """The period (``day``, ``evening``, ``night``) of a local clock time ``"HH:MM[:SS]"`` or hours."""
    if isinstance(clock, str):
        parts = clock.strip().split(":")
        try:
            if not 2 <= len(parts) <= 3:
                raise ValueError
            hh, mm = int(parts[0]), int(parts[1])
            ss = float(parts[2]) if len(parts) == 3 else 0.0
        except ValueError:
            raise InputError(f"departures: {clock!r} is not a clock time HH:MM[:SS]", field="departures") from None
        if not (0 <= hh <= 23 and 0 <= mm <= 59 and 0 <= ss < 60):
            raise InputError(f"departures: {clock!r} is not a clock time HH:MM[:SS]", field="departures")
        hours = hh + mm / 60.0 + ss / 3600.0
    else:
        hours = float(clock)
        if not (math.isfinite(hours) and 0.0 <= hours < 24.0):
            raise InputError(f"departures: {clock!r} h is not within 0-24 h", field="departures")
    if PERIOD_START_H["day"] <= hours < PERIOD_START_H["evening"]:
        return "day"
    if PERIOD_START_H["evening"] <= hours < PERIOD_START_H["night"]:
        return "evening"
    return "night"


# --------------------------------------------------------------------------- the schedule


@dataclass(frozen=True, eq=False)
class Flight:
    """One kind of flight of the day.

    Attributes
    ----------
    id : str
    trajectory : Trajectory
    counts : dict of str -> float
        Flights per period (``day``, ``evening``, ``night``; missing periods 0).
    cards : sequence of ModelCard or CardSet, optional
        Cards for this flight; default the schedule's.
    ground_h_m : float, optional
        Ground height the route states (waypoints with AGL altitudes).
    """

    id: str
    trajectory: Trajectory
    counts: Mapping[str, float]
    cards: Any = None
    ground_h_m: float | None = None

    def __post_init__(self) -> None:
        counts = {p: 0.0 for p in PERIODS}
        for k, v in dict(self.counts).items():
            if k not in PERIODS:
                raise InputError(f"flight {self.id!r}: unknown period {k!r}; periods: {', '.join(PERIODS)}",
                                 field="counts")
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise InputError(f"flight {self.id!r}: count of {k!r} must be a number, got {v!r}",
                                 field="counts") from None
            if not (math.isfinite(f) and f >= 0):
                raise InputError(f"flight {self.id!r}: count of {k!r} must be >= 0, got {v!r}", field="counts")
            counts[k] = f
        object.__setattr__(self, "counts", counts)

    @property
    def total(self) -> float:
        return float(sum(self.counts.values()))


@dataclass(frozen=True, eq=False)
class Schedule:
    """A day of operations (see the module docstring).

    Attributes
    ----------
    flights : tuple of Flight
    cards : CardSet or None
        Default cards of the flights.
    grid : GridSpec or None
        Receivers; None: chosen around the flights from ``resolution_m``, ``margin_m``, ``crs``.
    resolution_m, margin_m : float
    crs : str or None
    receiver_height_m : float
    ground_h_m : float or None
    dem : path or None
    dem_offset_m : float
    thresholds_db : tuple of float
        N-above and time-above levels, dB(A).
    levels_db : tuple of float
        Contour levels, dB(A).
    floor_db : float or None
        Audibility floor of the fast engine, dB(A).
    substeps : int
        Sub-intervals per trajectory sample interval.
    source : str
    """

    flights: tuple[Flight, ...]
    cards: Any = None
    grid: GridSpec | None = None
    resolution_m: float = 10.0
    margin_m: float = 500.0
    crs: Any = None
    receiver_height_m: float = 1.5
    ground_h_m: float | None = None
    dem: Any = None
    dem_offset_m: float = 0.0
    thresholds_db: tuple[float, ...] = ()
    levels_db: tuple[float, ...] = (45.0, 50.0, 55.0, 60.0, 65.0)
    floor_db: float | None = None
    substeps: int = 1
    source: str = "schedule"
    min_distance_m: float = 1.0

    def __post_init__(self) -> None:
        if not self.flights:
            raise InputError(f"{self.source}: the schedule has no flights", field="flights")
        ids = [f.id for f in self.flights]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise InputError(f"{self.source}: flight id {dup[0]!r} is used twice", field="flights")
        thr = tuple(float(v) for v in self.thresholds_db)
        if not all(math.isfinite(v) for v in thr):
            raise InputError(f"{self.source}: thresholds_db must be finite, got {list(thr)}", field="thresholds_db")
        object.__setattr__(self, "thresholds_db", thr)
        if self.floor_db is not None:
            low = [v for v in thr if v < self.floor_db]
            if low:
                raise InputError(f"{self.source}: threshold {low[0]:g} dB lies below floor_db {self.floor_db:g} dB: "
                                 "N-above and time above are only exact above the floor", field="thresholds_db")
        if any(f.cards is None for f in self.flights) and self.cards is None:
            raise InputError(f"{self.source}: give 'cards' for the schedule or for every flight", field="cards")

    def receiver_grid(self) -> GridSpec:
        """The receivers: :attr:`grid`, or the grid around every flight plus the margin."""
        if self.grid is not None:
            return self.grid
        return grid_for_trajectory(_union_track(f.trajectory for f in self.flights), self.resolution_m,
                                   self.margin_m, self.crs)


def _union_track(trajs: Iterable[Trajectory]) -> Trajectory:
    """All samples of several trajectories as one track (for the grid's extent only)."""
    ts = list(trajs)
    lat = np.concatenate([t.lat for t in ts])
    lon = np.concatenate([t.lon for t in ts])
    h = np.concatenate([t.h for t in ts])
    z = np.zeros(lat.size)
    return Trajectory(t=np.arange(lat.size, dtype=float), lat=lat, lon=lon, h=h, roll=z, pitch=z, yaw=z,
                      power_w=np.ones(lat.size), phase=np.full(lat.size, "horizontal"), source="schedule")


def _num(doc: Mapping[str, Any], key: str, default: Any, source: str, *, minimum: float | None = None,
         strict: bool = False) -> Any:
    v = doc.get(key, default)
    if v is None:
        return None
    if isinstance(v, bool):
        raise InputError(f"{source}: {key} must be a number, got {v!r}", field=key)
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{source}: {key} must be a number, got {v!r}", field=key) from None
    if not math.isfinite(f) or (minimum is not None and (f < minimum or (strict and f == minimum))):
        raise InputError(f"{source}: {key} must be {'>' if strict else '>='} {minimum:g}, got {v!r}"
                         if minimum is not None else f"{source}: {key} must be finite, got {v!r}", field=key)
    return f


def _levels(doc: Mapping[str, Any], key: str, default: Sequence[float], source: str) -> tuple[float, ...]:
    from gisnoise.maps import parse_levels

    v = doc.get(key, default)
    if v is None or (isinstance(v, list) and not v):
        return ()
    try:
        return tuple(parse_levels(v, field=key))
    except InputError as exc:
        raise InputError(f"{source}: {exc}", field=key) from None


def schedule_from_dict(doc: Mapping[str, Any], *, base_dir: str | os.PathLike[str] = ".",
                       source: str = "schedule") -> Schedule:
    """A :class:`Schedule` from its JSON document; relative paths are taken from ``base_dir``."""
    from gisnoise.flight import read_route
    from gisnoise.maps import CardSet

    if not isinstance(doc, Mapping):
        raise InputError(f"{source}: expected a JSON object", field="schedule")
    schema = doc.get("schema")
    if schema != SCHEMA:
        raise InputError(f"{source}: schema {schema!r} is not supported (reads {SCHEMA!r})", field="schema")
    base = Path(base_dir)

    def path(v: Any, key: str) -> Path:
        if not isinstance(v, str) or not v.strip():
            raise InputError(f"{source}: {key} must be a file path, got {v!r}", field=key)
        p = Path(v)
        return p if p.is_absolute() else base / p

    def cardset(v: Any, key: str) -> Any:
        if v is None:
            return None
        if isinstance(v, str):
            v = [v]
        if not isinstance(v, list) or not v:
            raise InputError(f"{source}: {key} must be a list of card files", field=key)
        return CardSet([path(c, key) for c in v])

    dem = doc.get("dem")
    dem_path = None if dem is None else path(dem, "dem")
    dem_offset = _num(doc, "dem_offset_m", 0.0, source)
    g = doc.get("grid") or {}
    if not isinstance(g, Mapping):
        raise InputError(f"{source}: grid must be an object", field="grid")
    resolution = _num(g, "resolution_m", 10.0, source, minimum=0.0, strict=True)
    margin = _num(g, "margin_m", 500.0, source, minimum=0.0)
    grid = None
    if g.get("bounds") is not None:
        b = g["bounds"]
        if not (isinstance(b, list) and len(b) == 4):
            raise InputError(f"{source}: grid.bounds must be [left, bottom, right, top] in metres", field="bounds")
        if g.get("crs") is None:
            raise InputError(f"{source}: grid.bounds needs grid.crs", field="crs")
        grid = GridSpec.from_bounds(parse_crs(g["crs"]), *(float(v) for v in b), resolution)
        check_cell_limit(grid.width, grid.height)
    flights_doc = doc.get("flights")
    if not isinstance(flights_doc, list) or not flights_doc:
        raise InputError(f"{source}: flights must be a non-empty list", field="flights")
    flights = []
    for i, fd in enumerate(flights_doc):
        if not isinstance(fd, Mapping):
            raise InputError(f"{source}: flights[{i}] must be an object", field="flights")
        fid = str(fd.get("id", f"flight{i + 1}"))
        if "trajectory" not in fd:
            raise InputError(f"{source}: flight {fid!r} has no 'trajectory'", field="trajectory")
        route = read_route(path(fd["trajectory"], "trajectory"), dem=dem_path, dem_offset_m=dem_offset)
        counts: dict[str, float] = {p: 0.0 for p in PERIODS}
        given = fd.get("counts")
        if given is not None:
            if not isinstance(given, Mapping):
                raise InputError(f"{source}: flight {fid!r}: counts must be an object of periods", field="counts")
            counts = dict(given)
            for p in PERIODS:
                counts.setdefault(p, 0.0)
        deps = fd.get("departures") or []
        if not isinstance(deps, list):
            raise InputError(f"{source}: flight {fid!r}: departures must be a list of clock times",
                             field="departures")
        for d in deps:
            p = period_of(d)
            counts[p] = float(counts[p]) + 1.0
        if given is None and not deps:
            raise InputError(f"{source}: flight {fid!r} needs 'counts' or 'departures'", field="counts")
        flights.append(Flight(fid, route.trajectory, counts, cardset(fd.get("cards"), "cards"), route.ground_h_m))
    return Schedule(
        flights=tuple(flights), cards=cardset(doc.get("cards"), "cards"), grid=grid, resolution_m=resolution,
        margin_m=margin, crs=g.get("crs"), receiver_height_m=_num(doc, "receiver_height_m", 1.5, source),
        ground_h_m=_num(doc, "ground_h_m", None, source), dem=dem_path, dem_offset_m=dem_offset,
        thresholds_db=_levels(doc, "thresholds_db", (), source),
        levels_db=_levels(doc, "levels_db", (45.0, 50.0, 55.0, 60.0, 65.0), source),
        floor_db=_num(doc, "floor_db", None, source), substeps=int(_num(doc, "substeps", 1, source, minimum=1.0)),
        source=source)


def load_schedule(path: str | os.PathLike[str]) -> Schedule:
    """Read a schedule JSON file (paths in it relative to the file)."""
    p = Path(path)
    doc = read_json_file(p, what="schedule", error=InputError, field="schedule")
    return schedule_from_dict(doc, base_dir=p.parent, source=str(p))


# --------------------------------------------------------------------------- the work: tiles x flights


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
    out = []
    for r0 in range(0, H, rows):
        for c0 in range(0, W, cols):
            out.append((r0, min(r0 + rows, H), c0, min(c0 + cols, W)))
    return out


def _band_names(thresholds: Sequence[float]) -> list[str]:
    names = ["Lden", "Lday", "Levening", "Lnight", "LAmax"]
    for thr in thresholds:
        names += [f"NA{thr:g}_{p}" for p in PERIODS] + [f"NA{thr:g}"]
        names += [f"TA{thr:g}_{p}" for p in PERIODS] + [f"TA{thr:g}"]
    return names


def _new_acc(shape: tuple[int, int], n_thr: int) -> dict[str, np.ndarray]:
    acc = {f"E_{p}": np.zeros(shape) for p in PERIODS}
    acc.update({f"O_{p}": np.zeros(shape) for p in PERIODS})  # bound of the exposure left out below the floor
    acc["emax"] = np.zeros(shape, np.float32)
    acc["any"] = np.zeros(shape, bool)
    for k in range(n_thr):
        for p in PERIODS:
            acc[f"NA{k}_{p}"] = np.zeros(shape)
            acc[f"TA{k}_{p}"] = np.zeros(shape)
    return acc


def _accumulate(acc: dict[str, np.ndarray], res: Any, counts: Mapping[str, float],
                thresholds: Sequence[float], omitted_bound: float = 0.0) -> dict[str, np.ndarray]:
    """Add one flight's kernel result (``WindowResult``) with its counts per period, in place.

    ``omitted_bound`` (s): an upper bound of the flight's exposure where the kernel skipped it
    (``duration 10^(floor/10)``).
    """
    np.maximum(acc["emax"], res.emax, out=acc["emax"])
    acc["any"] |= res.computed
    skipped = None if omitted_bound == 0.0 else ~res.computed
    # LAmax > L  <=>  emax > 10^(L/10) (emax holds 10^(LAmax/10) in float32)
    above = [res.emax > np.float32(10.0 ** (thr / 10.0)) for thr in thresholds]
    for p in PERIODS:
        n = counts[p]
        if n == 0:
            continue
        acc[f"E_{p}"] += n * res.energy
        if skipped is not None:
            acc[f"O_{p}"] += (n * omitted_bound) * skipped
        for k in range(len(thresholds)):
            acc[f"NA{k}_{p}"] += n * above[k]
            acc[f"TA{k}_{p}"] += n * res.ta[k]
    return acc


UNCERTAIN_DB = 0.01
"""With a floor, level bands are NaN where the flights left out could move them by more than this, dB."""


def _finish(acc: dict[str, np.ndarray], thresholds: Sequence[float], floor_db: float | None = None
            ) -> dict[str, np.ndarray]:
    """Bands from the accumulators."""
    with np.errstate(divide="ignore"):
        e = {p: acc[f"E_{p}"] / (PERIOD_HOURS[p] * 3600.0) for p in PERIODS}
        o = {p: acc[f"O_{p}"] / (PERIOD_HOURS[p] * 3600.0) for p in PERIODS}
        e_den = _lden_energy(e["day"], e["evening"], e["night"])
        bands = {"Lden": 10.0 * np.log10(e_den),
                 "Lday": 10.0 * np.log10(e["day"]), "Levening": 10.0 * np.log10(e["evening"]),
                 "Lnight": 10.0 * np.log10(e["night"]), "LAmax": 10.0 * np.log10(acc["emax"].astype(np.float64))}
    for a in bands.values():
        a[~np.isfinite(a)] = np.nan  # no sound (above the floor) in that period: nodata
    if floor_db is not None:
        # what the skipped flights may add: at most o; the level is kept where that is < 0.01 dB
        rel = 10.0 ** (UNCERTAIN_DB / 10.0) - 1.0
        for p, name in (("day", "Lday"), ("evening", "Levening"), ("night", "Lnight")):
            bands[name][o[p] > rel * e[p]] = np.nan
        bands["Lden"][_lden_energy(o["day"], o["evening"], o["night"]) > rel * e_den] = np.nan
        skipped = (acc["O_day"] + acc["O_evening"] + acc["O_night"]) > 0
        bands["LAmax"][skipped & ~(bands["LAmax"] >= floor_db)] = np.nan
    for k, thr in enumerate(thresholds):
        for kind in ("NA", "TA"):
            total = np.zeros(acc["emax"].shape)
            for p in PERIODS:
                bands[f"{kind}{thr:g}_{p}"] = acc[f"{kind}{k}_{p}"]
                total = total + acc[f"{kind}{k}_{p}"]
            bands[f"{kind}{thr:g}"] = total
    return bands


@dataclass(frozen=True, eq=False)
class _Plan:
    """What every tile needs: receivers and the flights' instants in their frame."""

    rc: Any
    flights: tuple[Any, ...]  # FlightInstants, schedule order, flights without counts left out
    counts: tuple[dict[str, float], ...]
    ids: tuple[str, ...]
    thresholds: tuple[float, ...]
    floor_db: float | None = None


def _plan(schedule: Schedule, grid: GridSpec) -> _Plan:
    from gisnoise.maps import CardSet
    from gisnoise.maps import fastkernel as fk

    fk._require_numba()
    ground_h = schedule.ground_h_m
    if ground_h is None and schedule.dem is None:
        stated = [f.ground_h_m for f in schedule.flights if f.ground_h_m is not None]
        if stated:
            ground_h = min(stated)
    rc = fk.receivers_for(grid, [f.trajectory for f in schedule.flights], receiver_height=schedule.receiver_height_m,
                          dem=schedule.dem, ground_h=ground_h, dem_offset_m=schedule.dem_offset_m)
    frame = rc.frame
    flights, counts, ids = [], [], []
    for f in schedule.flights:
        if f.total == 0:
            log.info("flight %s has no counts; left out", f.id)
            continue
        cards = f.cards if f.cards is not None else schedule.cards
        cards = cards if isinstance(cards, CardSet) else CardSet(cards)
        flights.append(fk.prepare_flight(f.trajectory, cards, frame, substeps=schedule.substeps,
                                         min_distance_m=schedule.min_distance_m, floor_db=schedule.floor_db))
        counts.append(dict(f.counts))
        ids.append(f.id)
    if not flights:
        raise InputError(f"{schedule.source}: no flight has a count above 0", field="counts")
    return _Plan(rc, tuple(flights), tuple(counts), tuple(ids), schedule.thresholds_db, schedule.floor_db)


def _tile_step(acc: dict[str, np.ndarray] | None, fl: Any, counts: Mapping[str, float], rc: Any,
               window: tuple[int, ...], thresholds: Sequence[float], copy: bool = False,
               lattice: Any = None, floor_db: float | None = None) -> dict[str, np.ndarray]:
    """One flight on one tile, added to the tile's accumulators.

    ``copy=True`` leaves ``acc`` untouched (a cluster task must not change its inputs:
    a retried task would add twice); the sums are the same either way.  ``lattice``: the
    tile's receiver lattice when already computed; ``floor_db``: the flights' floor.
    """
    from gisnoise.maps import fastkernel as fk

    r0, r1, c0, c1 = window
    if acc is None:
        acc = _new_acc((r1 - r0, c1 - c0), len(thresholds))
    elif copy:
        acc = {k: v.copy() for k, v in acc.items()}
    res = fk.run_window(fl, rc, r0, r1, c0, c1, thresholds, lattice=lattice)
    bound = 0.0 if floor_db is None else fl.duration_s * 10.0 ** (floor_db / 10.0)
    return _accumulate(acc, res, counts, thresholds, bound)


def _tile_all(plan: _Plan, window: tuple[int, ...], cancel: Callable[[], bool] | None = None) -> dict:
    """Every flight, in schedule order, on one tile."""
    from gisnoise.maps import fastkernel as fk

    rc = plan.rc.for_window(*window)
    lattice = fk.window_lattice(rc, *window)
    acc = None
    for fl, counts in zip(plan.flights, plan.counts, strict=True):
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")
        acc = _tile_step(acc, fl, counts, rc, window, plan.thresholds, lattice=lattice, floor_db=plan.floor_db)
    assert acc is not None
    return acc


def _run_local(plan: _Plan, windows: Sequence[tuple[int, ...]], put: Callable[[tuple[int, ...], dict], None],
               threads: int, cancel: Callable[[], bool] | None) -> None:
    from gisnoise.maps.fastkernel import _map_threads

    _map_threads(lambda w: _tile_all(plan, w, cancel), windows, put, threads)


def evaluate_operations(
    schedule: Schedule,
    *,
    grid: GridSpec | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    tile_cells: int = DEFAULT_TILE_CELLS,
    threads: int | None = None,
    memory_limit: str | None = None,
    progress: Callable[[float], Any] | None = None,
    cancel: Callable[[], bool] | None = None,
) -> Any:
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
    tile_cells : int
        Cells per tile (whole segments): the memory of one task.
    threads : int, optional
        Threads of the single-process path (default :func:`gisnoise.maps.fastkernel.default_threads`).
    memory_limit : str, optional
        Memory limit per worker of a local cluster (Dask syntax, e.g. ``"2GiB"``).
    progress : callable, optional
        Called with the fraction of tiles done (0-1).
    cancel : callable, optional
        Polled between flights; true raises :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    MapResult
        Bands ``Lden``, ``Lday``, ``Levening``, ``Lnight``, ``LAmax`` (dB(A); NaN where no
        flight is above the floor in that period), ``NA<L>_<period>``, ``NA<L>`` (events)
        and ``TA<L>_<period>``, ``TA<L>`` (s) per threshold.
    """
    from gisnoise.maps import fastkernel as fk
    from gisnoise.maps.evaluate import MapResult, _unit

    if not isinstance(schedule, Schedule):
        raise InputError(f"schedule must be a Schedule, got {type(schedule).__name__}", field="schedule")
    grid = schedule.receiver_grid() if grid is None else grid
    plan = _plan(schedule, grid)
    windows = tile_windows(grid.shape, plan.rc.seg, tile_cells)
    acc = _new_acc(grid.shape, len(plan.thresholds))
    done = 0

    def put(w: tuple[int, ...], tile: dict) -> None:
        nonlocal done
        r0, r1, c0, c1 = w
        for k, a in tile.items():
            acc[k][r0:r1, c0:c1] = a
        done += 1
        if progress is not None:
            progress(done / len(windows))

    address = scheduler or (None if workers else os.environ.get("GISNOISE_DASK_SCHEDULER") or None)
    if address is not None or workers:
        from gisnoise.ops.scale import run_on_dask

        how = run_on_dask(plan, windows, put, scheduler=address, workers=workers, memory_limit=memory_limit,
                          cancel=cancel)
    else:
        n = fk.default_threads() if threads is None else max(1, int(threads))
        _run_local(plan, windows, put, n, cancel)
        how = {"executor": "threads", "threads": n}
    bands = _finish(acc, plan.thresholds, plan.floor_db)
    if plan.rc.valid is not None and not plan.rc.valid.all():
        for a in bands.values():
            a[~plan.rc.valid] = np.nan
    units = {}
    for k in bands:
        units[k] = "events" if k.startswith("NA") else _unit(k)
    meta = {
        "grid": grid.to_dict(),
        "units": units,
        "schedule": schedule.source,
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
    }
    return MapResult(bands=bands, grid=grid, metadata=meta)


def write_operations(result: Any, out_dir: str | os.PathLike[str], levels: Any = None,
                     contour_bands: Sequence[str] = ("Lden", "Lnight")) -> dict[str, Path]:
    """Write ``DIR/operations.tif`` (every band), ``DIR/contours.geojson`` (of ``contour_bands``)
    and ``DIR/summary.json`` (metadata and per-band ranges)."""
    from gisnoise.geo import write_geotiff
    from gisnoise.maps import write_geojson

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: output exists and is not a folder", field="out")
    out.mkdir(parents=True, exist_ok=True)
    lv = result.metadata.get("levels_db") if levels is None else levels
    paths = {"levels": write_geotiff(result, out / "operations.tif")}
    if lv:
        paths["contours"] = write_geojson(result, out / "contours.geojson", lv, metrics=list(contour_bands))
    summary = {"metadata": result.metadata, "bands": {}}
    for k, a in result.bands.items():
        fin = a[np.isfinite(a)]
        summary["bands"][k] = {"unit": result.units.get(k, ""), "min": float(fin.min()) if fin.size else None,
                               "max": float(fin.max()) if fin.size else None}
    p = out / "summary.json"
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps(summary, indent=1, allow_nan=False, default=float), encoding="utf-8")
    os.replace(tmp, p)
    paths["summary"] = p
    return paths
