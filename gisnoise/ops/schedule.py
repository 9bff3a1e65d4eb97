"""The schedule of a day of operations: which flights, how often in each period, on which receivers.

A *schedule* lists the flights a place expects on an average day, each a trajectory
(flight CSV, PX4 or ArduPilot flight log, GeoJSON LineString with times or waypoints;
:func:`gisnoise.flight.read_route`)
flown a number of times in each period of the day (:mod:`gisnoise.ops.periods`), given
as counts or as departure clock times (``"HH:MM"`` or ``"HH:MM:SS"``, local; a plain number is hours
after midnight: 7.5 is 07:30).

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
         "departures": ["07:30", "12:10", "19:45", "23:20"], "cards": ["cards/other.json"]},
        {"id": "logged", "trajectory": "logs/00000042.BIN", "counts": {"day": 2},
         "geoid_undulation_m": 47.3,       # a log's heights above mean sea level made ellipsoidal
         "power_w": 2400}]}                # a log without battery current: a constant power

A flight's ``geoid_undulation_m`` and ``power_w`` are those of ``gisnoise contour``'s
``--geoid-undulation`` and ``--power-w`` (for flight logs; a source that states its power refuses
``power_w``).  Without ``ground_h_m`` and ``dem`` the ground is the take-off or landing point of the flights that
start or end on the ground (the lowest of them), as for a map; a schedule whose flights are all
in the air throughout is refused (field ``ground_h_m``).  Each flight keeps its own ground
(:attr:`Flight.ground_h_m`): a ``ground_h_m`` above a flight's lowest flying point is refused in the words
``contour --ground-height`` refuses it with, naming the flight, and a flight mapped over a ground far from its
own (the schedule's, or the lowest of the flights') is named in a warning (:func:`gisnoise.ops.schedule_findings`).

``grid`` may instead give ``"crs"``, ``"bounds": [left, bottom, right, top]`` (m) and
``"resolution_m"``; by default it covers every flight plus the margin in the local UTM zone.
Counts may be fractional (averages over a year).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory, ground_from_track, read_route
from gisnoise.geo import GridSpec, check_cell_limit, grid_for_points, parse_crs
from gisnoise.jsonio import read_json_file
from gisnoise.limits import check_count, current
from gisnoise.maps import CardSet, parse_levels
from gisnoise.ops.periods import PERIODS, period_of

__all__ = ["SCHEMA", "Flight", "Schedule", "load_schedule", "schedule_from_dict"]

SCHEMA = "gisnoise/operations/1"


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
        The flight's own ground: the ground height the route states (waypoints with AGL altitudes), else the
        track's take-off or landing point (:func:`gisnoise.flight.ground_from_track`, the ground rule of the
        maps); None for a track in the air throughout.  A schedule without ``ground_h_m`` or ``dem`` is mapped
        over the lowest of them; a schedule's ground far from it is said (:func:`gisnoise.ops.schedule_findings`).
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
                if isinstance(v, (bool, np.bool_, str, bytes)):  # float(True) is 1, float("5") is 5: no counts
                    raise TypeError
                f = float(v)
            except (TypeError, ValueError):
                raise InputError(f"flight {self.id!r}: count of {k!r} must be a number, got {v!r}",
                                 field="counts") from None
            if not (math.isfinite(f) and f >= 0):
                raise InputError(f"flight {self.id!r}: count of {k!r} must be >= 0, got {v!r}", field="counts")
            counts[k] = check_count("counts", f, current().max_daily_count, source=f"flight {self.id!r}: {k}")
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
    digest : str or None
        SHA-256 of the schedule file (hex; :func:`load_schedule`), kept in the day's metadata as
        ``schedule_sha256``: the exposure of a written day refuses another schedule by it.
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
    digest: str | None = None

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
        lon = np.concatenate([f.trajectory.lon for f in self.flights])
        lat = np.concatenate([f.trajectory.lat for f in self.flights])
        return grid_for_points(lon, lat, self.resolution_m, self.margin_m, self.crs)


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
    v = doc.get(key, default)
    if v is None or (isinstance(v, (list, tuple)) and not v):  # left out (the default ()), null or []
        return ()
    try:
        return tuple(parse_levels(v, field=key))
    except InputError as exc:
        raise InputError(f"{source}: {exc}", field=key) from None


_FIELDS = ("schema", "cards", "grid", "receiver_height_m", "ground_h_m", "dem", "dem_offset_m", "levels_db",
           "thresholds_db", "floor_db", "substeps", "flights")
_GRID_FIELDS = ("resolution_m", "margin_m", "crs", "bounds")
_FLIGHT_FIELDS = ("id", "trajectory", "counts", "departures", "cards", "geoid_undulation_m", "power_w")


def _known(doc: Mapping[str, Any], known: Sequence[str], where: str, source: str) -> None:
    """Refuse a field the schedule does not know (a misspelt one would be left out without a word)."""
    unknown = [k for k in doc if k not in known]
    if unknown:
        raise InputError(f"{source}: {where}unknown field {unknown[0]!r} (known: {', '.join(known)})",
                         field=str(unknown[0]))


def schedule_from_dict(doc: Mapping[str, Any], *, base_dir: str | os.PathLike[str] = ".",
                       source: str = "schedule") -> Schedule:
    """A :class:`Schedule` from its JSON document; relative paths are taken from ``base_dir``."""
    if not isinstance(doc, Mapping):
        raise InputError(f"{source}: expected a JSON object", field="schedule")
    schema = doc.get("schema")
    if schema != SCHEMA:
        raise InputError(f"{source}: schema {schema!r} is not supported (reads {SCHEMA!r})", field="schema")
    base = Path(base_dir)
    _known(doc, _FIELDS, "", source)

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
    _known(g, _GRID_FIELDS, "grid: ", source)
    resolution = _num(g, "resolution_m", 10.0, source, minimum=0.0, strict=True)
    margin = _num(g, "margin_m", 500.0, source, minimum=0.0)
    grid = None
    if g.get("bounds") is not None:
        b = g["bounds"]
        if not (isinstance(b, list) and len(b) == 4):
            raise InputError(f"{source}: grid.bounds must be [left, bottom, right, top] in metres", field="bounds")
        if g.get("crs") is None:
            raise InputError(f"{source}: grid.bounds needs grid.crs", field="crs")
        left, bottom, right, top = (float(v) for v in b)
        grid = GridSpec.from_bounds(parse_crs(g["crs"]), left, bottom, right, top, resolution)
        check_cell_limit(grid.width, grid.height)
    ground_h = _num(doc, "ground_h_m", None, source)
    flights_doc = doc.get("flights")
    if not isinstance(flights_doc, list) or not flights_doc:
        raise InputError(f"{source}: flights must be a non-empty list", field="flights")
    flights = []
    for i, fd in enumerate(flights_doc):
        if not isinstance(fd, Mapping):
            raise InputError(f"{source}: flights[{i}] must be an object", field="flights")
        fid = str(fd.get("id", f"flight{i + 1}"))
        _known(fd, _FLIGHT_FIELDS, f"flight {fid!r}: ", source)
        if "trajectory" not in fd:
            raise InputError(f"{source}: flight {fid!r} has no 'trajectory'", field="trajectory")
        route = read_route(path(fd["trajectory"], "trajectory"), dem=dem_path, dem_offset_m=dem_offset,
                           geoid_undulation_m=_num(fd, "geoid_undulation_m", None, f"{source}: flight {fid!r}"),
                           power_w=_num(fd, "power_w", None, f"{source}: flight {fid!r}", minimum=0.0, strict=True))
        counts: dict[str, float] = {p: 0.0 for p in PERIODS}
        given = fd.get("counts")
        if given is not None and fd.get("departures"):  # either the counts of a timetable or its clock times
            raise InputError(f"{source}: flight {fid!r} gives both 'counts' and 'departures': give one (the "
                             f"departures are counted into their periods, so both would count each flight twice)",
                             field="departures")
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
            try:
                p = period_of(d)
            except InputError as exc:
                raise InputError(f"{source}: flight {fid!r}: {exc}", field="departures") from None
            counts[p] = float(counts[p]) + 1.0
        if given is None and not deps:
            raise InputError(f"{source}: flight {fid!r} needs 'counts' or 'departures'", field="counts")
        ground = route.ground_h_m  # the flight's own ground, also beside a schedule's (checked against it)
        if ground is None:
            ground = ground_from_track(route.trajectory)
        flights.append(Flight(fid, route.trajectory, counts, cardset(fd.get("cards"), "cards"), ground))
    if ground_h is None and dem_path is None and all(f.ground_h_m is None for f in flights):
        raise InputError(f"{source}: ground unknown: no flight starts or ends on the ground (a take-off or landing) "
                         f"or states its ground; give ground_h_m or dem", field="ground_h_m")
    return Schedule(
        flights=tuple(flights), cards=cardset(doc.get("cards"), "cards"), grid=grid, resolution_m=resolution,
        margin_m=margin, crs=g.get("crs"), receiver_height_m=_num(doc, "receiver_height_m", 1.5, source),
        ground_h_m=ground_h, dem=dem_path, dem_offset_m=dem_offset,
        thresholds_db=_levels(doc, "thresholds_db", (), source),
        levels_db=_levels(doc, "levels_db", (45.0, 50.0, 55.0, 60.0, 65.0), source),
        floor_db=_num(doc, "floor_db", None, source), substeps=int(_num(doc, "substeps", 1, source, minimum=1.0)),
        source=source)


def load_schedule(path: str | os.PathLike[str]) -> Schedule:
    """Read a schedule JSON file (paths in it relative to the file); its :attr:`Schedule.digest` is the file's
    SHA-256."""
    p = Path(path)
    doc = read_json_file(p, what="schedule", error=InputError, field="schedule")
    sched = schedule_from_dict(doc, base_dir=p.parent, source=str(p))
    return dataclasses.replace(sched, digest=hashlib.sha256(p.read_bytes()).hexdigest())
