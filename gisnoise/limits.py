"""One rule set for the quantities every reader takes in: ranges, plausibility limits, work bounds.

The command line, the service and the QGIS plugin read flights, cards, campaigns and
requests through readers that call these checks at the boundary, so one bad value is
refused the same way everywhere: one line naming the field and the value
(:class:`gisnoise.errors.InputError` or the subclass the caller passes).

Limits (a small electric VTOL drone; :data:`DEFAULTS`):

=========================  ===============  ==============================================
quantity                   accepted         why
=========================  ===============  ==============================================
longitude                  -180 .. 180 deg  no silent wrapping (200 deg is an error, not -160)
latitude                   -90 .. 90 deg
roll, pitch                -180 .. 180 deg  Euler angles
yaw                        -360 .. 360 deg  0..360 and -180..180 conventions; wrapped after
electric power             0 .. 100 kW      ``max_power_w``; override for larger vehicles
ellipsoidal height         -500 .. 10 km    ``max_height_m``; below the lowest land, above
                                            any small-UAV ceiling
samples of a trajectory    >= 2             ``MIN_SAMPLES``: one sample has no duration
time gap between samples   <= 600 s         ``max_gap_s``; a longer gap is refused (not split):
                                            a log with a pause is two flights, cut it
flight duration            <= 24 h          ``max_duration_s``
samples of a trajectory    <= 1,000,000     ``max_samples`` (the service sets its own)
work of one map            <= 5e11          ``max_work``: grid cells x time steps (samples
                                            x substeps), checked before evaluating
receiver height            0 .. 1000 m      above ground, never below it
sound level at a mic       -50 .. 200 dB    ``MEASURED_LEVEL_RANGE_DB``: below any microphone's self-noise,
                                            above a jet engine at 1 m (a band may lie lower, down
                                            to -inf: silence)
level asked of a map       -50 .. 200 dB(A) :func:`check_map_level`: contour levels, time-above
                                            thresholds, ranking levels; the range a microphone
                                            records, so a level outside it is no level a
                                            measurement could ever show (a typo: -1000, 1e308)
flights per day            <= 100,000       ``max_daily_count``
=========================  ===============  ==============================================

Override a limit for a block of code with :func:`override` (``with override(max_power_w=5e5):``)
or for the process with the environment variable ``GISNOISE_MAX_POWER_W`` (and likewise
``GISNOISE_MAX_HEIGHT_M``, ``GISNOISE_MAX_GAP_S``, ``GISNOISE_MAX_DURATION_S``,
``GISNOISE_MAX_SAMPLES``, ``GISNOISE_MAX_WORK``).

Gaps: a trajectory whose samples are more than ``max_gap_s`` apart is refused with the gap's
place named, never split silently into segments: the time between two flights is neither
flown nor silent, and only the user knows which (cut the log, or raise ``GISNOISE_MAX_GAP_S``).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["Limits", "WorkLimitError", "DEFAULTS", "current", "override", "check_range", "check_array", "check_lonlat",
           "check_attitude", "check_power", "check_track", "check_heights", "check_times", "check_samples", "check_count",
           "check_receiver_height", "check_ground_below", "check_receivers", "GROUND_TOLERANCE_M", "MAX_UAV_SPEED_M_S", "SAFE_ID_PATTERN", "CARD_REF_PATTERN", "check_id",
           "MIN_SAMPLES", "check_work", "MEASURED_LEVEL_RANGE_DB", "check_levels", "check_map_level"]


@dataclass(frozen=True)
class Limits:
    """Plausibility limits of one run (see the module docstring)."""

    max_power_w: float = 100_000.0
    min_height_m: float = -500.0
    max_height_m: float = 10_000.0
    max_gap_s: float = 600.0
    max_duration_s: float = 86_400.0
    max_samples: int = 1_000_000
    max_receiver_height_m: float = 1000.0
    max_daily_count: float = 100_000.0
    dense_factor: int = 10
    """Internal samples (route integration at 0.1 s, 0.5 m) allowed per output sample."""
    max_work: float = 5e11
    """Grid cells x time steps of one map (a few minutes of the fast engine on one core)."""


MIN_SAMPLES = 2
"""Fewest samples of a trajectory: one sample has no duration, so no LAeq, SEL or time above."""


DEFAULTS = Limits()
_ENV = {"max_power_w": "GISNOISE_MAX_POWER_W", "max_height_m": "GISNOISE_MAX_HEIGHT_M",
        "max_gap_s": "GISNOISE_MAX_GAP_S", "max_duration_s": "GISNOISE_MAX_DURATION_S",
        "max_samples": "GISNOISE_MAX_SAMPLES", "max_work": "GISNOISE_MAX_WORK"}
_current: ContextVar[Limits | None] = ContextVar("gisnoise_limits", default=None)


def _from_env() -> Limits:
    kw: dict[str, Any] = {}
    for name, var in _ENV.items():
        raw = os.environ.get(var)
        if raw is None or raw.strip() == "":
            continue
        try:
            v = float(raw)
        except ValueError:
            raise InputError(f"{var}: not a number: {raw!r}", field=var) from None
        if not math.isfinite(v) or v <= 0:
            raise InputError(f"{var}: must be a positive number, got {raw!r}", field=var)
        kw[name] = int(v) if name == "max_samples" else v
    return dataclasses.replace(DEFAULTS, **kw) if kw else DEFAULTS


def current() -> Limits:
    """The limits in force: an :func:`override` around the call, else the environment, else the defaults."""
    lim = _current.get()
    return lim if lim is not None else _from_env()


@contextmanager
def override(**changes: Any) -> Iterator[Limits]:
    """Change limits for the code inside the ``with`` block (this thread or task only)."""
    lim = dataclasses.replace(current(), **changes)
    token = _current.set(lim)
    try:
        yield lim
    finally:
        _current.reset(token)


def _fmt(v: float) -> str:
    return f"{v:g}"


def check_range(field: str, value: float, lo: float, hi: float, *, unit: str = "", source: str = "",
                error: type[InputError] = InputError, why: str = "") -> float:
    """``value`` if finite and within [lo, hi]; else one line naming the field and the value."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise error(f"{source + ': ' if source else ''}{field}: not a number: {value!r}", field=field) from None
    u = f" {unit}" if unit else ""
    if not math.isfinite(v) or not lo <= v <= hi:
        note = f" ({why})" if why else ""
        raise error(f"{source + ': ' if source else ''}{field}: {_fmt(v)}{u} is outside "
                    f"[{_fmt(lo)}, {_fmt(hi)}]{u}{note}", field=field)
    return v


def check_array(field: str, values: Any, lo: float, hi: float, *, unit: str = "", source: str = "",
                error: type[InputError] = InputError, why: str = "") -> None:
    """Every value of ``values`` finite and within [lo, hi]; the first one outside is named with its index."""
    a = np.asarray(values, dtype=float)
    bad = ~np.isfinite(a) | (a < lo) | (a > hi)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        u = f" {unit}" if unit else ""
        note = f" ({why})" if why else ""
        raise error(f"{source + ': ' if source else ''}{field}: {_fmt(float(a.flat[i]))}{u} at sample {i} is "
                    f"outside [{_fmt(lo)}, {_fmt(hi)}]{u}{note}", field=field)


def check_lonlat(lon: Any, lat: Any, *, source: str = "", error: type[InputError] = InputError,
                 lon_field: str = "lon", lat_field: str = "lat") -> None:
    """Longitude within -180..180 deg (no wrapping) and latitude within -90..90 deg."""
    check_array(lat_field, lat, -90.0, 90.0, unit="deg", source=source, error=error)
    check_array(lon_field, lon, -180.0, 180.0, unit="deg", source=source, error=error,
                why="longitudes are not wrapped")


def check_attitude(roll: Any, pitch: Any, yaw: Any, *, source: str = "",
                   error: type[InputError] = InputError) -> None:
    """Roll and pitch within -180..180 deg, yaw within -360..360 deg."""
    check_array("roll", roll, -180.0, 180.0, unit="deg", source=source, error=error)
    check_array("pitch", pitch, -180.0, 180.0, unit="deg", source=source, error=error)
    check_array("yaw", yaw, -360.0, 360.0, unit="deg", source=source, error=error)


def check_power(power_w: Any, *, field: str = "power_w", source: str = "",
                error: type[InputError] = InputError) -> None:
    """Electric power within 0..max_power_w (a small UAV; override ``max_power_w`` for larger)."""
    check_array(field, power_w, 0.0, current().max_power_w, unit="W", source=source, error=error,
                why="limit max_power_w of a small UAV; set GISNOISE_MAX_POWER_W for a larger vehicle")


def check_heights(h: Any, *, field: str = "h", source: str = "", error: type[InputError] = InputError) -> None:
    """Ellipsoidal heights within min_height_m..max_height_m."""
    lim = current()
    check_array(field, h, lim.min_height_m, lim.max_height_m, unit="m", source=source, error=error,
                why="set GISNOISE_MAX_HEIGHT_M to change the ceiling")


def check_times(t: Any, *, field: str = "t", source: str = "", error: type[InputError] = InputError) -> None:
    """At least :data:`MIN_SAMPLES` samples, no gap between samples longer than ``max_gap_s`` and a duration
    within ``max_duration_s``.

    Examples
    --------
    >>> check_times([0.0, 1.0, 2.0])
    >>> check_times([0.0])
    Traceback (most recent call last):
    ...
    gisnoise.errors.InputError: t: 1 sample; a trajectory needs at least 2
    >>> check_times([0.0, 1.0, 700.0])
    Traceback (most recent call last):
    ...
    gisnoise.errors.InputError: t: gap of 699 s before sample 2 (t=700 s) is longer than 600 s; split the log into flights
    """
    lim = current()
    a = np.asarray(t, dtype=float)
    if a.size < MIN_SAMPLES:
        raise error(f"{source + ': ' if source else ''}{field}: {a.size} sample{'' if a.size == 1 else 's'}; a "
                    f"trajectory needs at least {MIN_SAMPLES}", field=field)
    gaps = np.diff(a)
    if gaps.max() > lim.max_gap_s:
        i = int(np.argmax(gaps > lim.max_gap_s)) + 1
        raise error(f"{source + ': ' if source else ''}{field}: gap of {_fmt(float(gaps[i - 1]))} s before "
                    f"sample {i} (t={_fmt(float(a[i]))} s) is longer than {_fmt(lim.max_gap_s)} s; split the "
                    f"log into flights", field=field)
    dur = float(a[-1] - a[0])
    if dur > lim.max_duration_s:
        raise error(f"{source + ': ' if source else ''}{field}: duration {_fmt(dur)} s is longer than "
                    f"{_fmt(lim.max_duration_s)} s", field=field)


class WorkLimitError(InputError):
    """A request or input would need more samples (time, memory) than the limits allow (413 in the service)."""


def check_track(t: Any, lat: Any, lon: Any, h: Any, roll: Any, pitch: Any, power_w: Any, *, source: str = "",
                error: type[InputError] = InputError) -> None:
    """The rule set of a trajectory: coordinates, heights, attitude, power and time gaps (one call)."""
    check_lonlat(lon, lat, source=source, error=error)
    check_heights(h, source=source, error=error)
    check_array("roll", roll, -180.0, 180.0, unit="deg", source=source, error=error)
    check_array("pitch", pitch, -180.0, 180.0, unit="deg", source=source, error=error)
    check_power(power_w, source=source, error=error)
    check_times(t, source=source, error=error)


def check_samples(n: float, *, field: str, what: str = "trajectory", dense: bool = False) -> int:
    """Refuse a sample count above ``max_samples`` (``dense``: times ``dense_factor``) before allocating.

    Raises :class:`WorkLimitError`.
    """
    lim = current()
    top = lim.max_samples * (lim.dense_factor if dense else 1)
    if not math.isfinite(n) or n > top:
        raise WorkLimitError(f"{field}: the {what} would have {_fmt(n)} samples, more than the limit of {top}",
                    field=field)
    return int(n)


def check_work(cells: float, steps: float, *, field: str = "resolution_m") -> float:
    """Refuse a map of ``cells`` grid cells x ``steps`` time steps above ``max_work`` before evaluating it.

    Raises :class:`WorkLimitError` naming ``field`` (413 in the service, exit 2 in the CLI).

    Examples
    --------
    >>> check_work(1000, 500)
    500000.0
    >>> with override(max_work=1e6):
    ...     check_work(10_000, 500, field="grid.resolution_m")
    Traceback (most recent call last):
    ...
    gisnoise.limits.WorkLimitError: grid.resolution_m: the map needs 10000 cells x 500 time steps = 5e+06, more than the limit of 1e+06 (GISNOISE_MAX_WORK); use a coarser resolution, a smaller margin or fewer substeps
    """
    work = float(cells) * float(steps)
    top = current().max_work
    if not math.isfinite(work) or work > top:
        raise WorkLimitError(f"{field}: the map needs {_fmt(cells)} cells x {_fmt(steps)} time steps = {_fmt(work)}, "
                             f"more than the limit of {_fmt(top)} (GISNOISE_MAX_WORK); use a coarser resolution, a "
                             f"smaller margin or fewer substeps", field=field)
    return work


MEASURED_LEVEL_RANGE_DB = (-50.0, 200.0)
"""Sound levels a microphone can record, dB: below the self-noise of any measurement microphone, above a jet
engine at 1 m."""


def check_levels(values: Any, *, field: str, source: str = "", error: type[InputError] = InputError,
                 silence: bool = False) -> None:
    """Measured levels within :data:`MEASURED_LEVEL_RANGE_DB`.

    ``silence``: a band's level may lie below the range, down to ``-inf`` (digital silence, or the leakage of
    synthetic audio into a band it does not reach); only its top is checked.

    Examples
    --------
    >>> check_levels([40.0, 75.5], field="LA")
    >>> check_levels([40.0, 1e300], field="LA", source="m1.csv")
    Traceback (most recent call last):
    ...
    gisnoise.errors.InputError: m1.csv: LA: 1e+300 dB at sample 1 is outside [-50, 200] dB (no microphone records this level)
    """
    a = np.asarray(values, dtype=float)
    if silence:
        a = np.where(a < MEASURED_LEVEL_RANGE_DB[0], MEASURED_LEVEL_RANGE_DB[0], a)  # -inf and any quieter band: silence
    check_array(field, a, *MEASURED_LEVEL_RANGE_DB, unit="dB", source=source, error=error,
                why="no microphone records this level")


def check_map_level(field: str, value: Any, *, source: str = "", error: type[InputError] = InputError) -> float:
    """One A-weighted level asked of a map (a contour level, a time-above threshold, a ranking level), dB(A):
    finite and within :data:`MEASURED_LEVEL_RANGE_DB`, the levels a microphone records.

    A level outside that range is one no measurement could show (below the self-noise of any measurement
    microphone, above a jet engine at 1 m): a typo, never a map's question.

    Examples
    --------
    >>> check_map_level("levels", 55)
    55.0
    >>> check_map_level("levels", -1000)
    Traceback (most recent call last):
    ...
    gisnoise.errors.InputError: levels: -1000 dB(A) is outside [-50, 200] dB(A) (the A-weighted levels a microphone records: below any measurement microphone's self-noise, above a jet engine at 1 m)
    """
    return check_range(field, value, *MEASURED_LEVEL_RANGE_DB, unit="dB(A)", source=source, error=error,
                       why=MAP_LEVEL_WHY)


MAP_LEVEL_WHY = ("the A-weighted levels a microphone records: below any measurement microphone's self-noise, above a "
                 "jet engine at 1 m")
"""Why a level asked of a map lies within :data:`MEASURED_LEVEL_RANGE_DB` (the words of its refusals)."""


def check_count(field: str, value: float, hi: float, *, source: str = "",
                error: type[InputError] = InputError) -> float:
    """A count within 0..hi."""
    return check_range(field, value, 0.0, hi, source=source, error=error)


def check_receiver_height(value: float, *, field: str = "receiver_height",
                          error: type[InputError] = InputError) -> float:
    """Receivers stand on or above the ground: 0..max_receiver_height_m."""
    return check_range(field, value, 0.0, current().max_receiver_height_m, unit="m", error=error,
                       why="receivers stand on or above the ground")


GROUND_TOLERANCE_M = 1.0
"""How close to the track's lowest point the ground lies, m: a sample that near it may stand on the ground
(:mod:`gisnoise.flight.ground`; GPS heights of a vehicle standing still wander by some decimetres), and a
given ground may lie that far above it (rounding of take-off and landing)."""


MAX_UAV_SPEED_M_S = 150.0
"""Fastest a vehicle of the product's class moves between two samples of its track, m/s (540 km/h: small
electric VTOL drones cruise at 15-40 m/s, racing quadcopters reach about 50 m/s): a sample farther from its
neighbour is a position glitch (:mod:`gisnoise.flight.glitches`)."""


def check_receivers(receiver_height: float, ground_h: float | None, track_h: Any) -> None:
    """Receivers on or above the ground, the ground (when given) below the track: one call for a map."""
    check_receiver_height(receiver_height)
    if ground_h is not None:
        check_ground_below(ground_h, track_h)


def check_ground_below(ground_h: float, track_h: Any, *, field: str = "ground_h",
                       error: type[InputError] = InputError) -> float:
    """The ground lies at or below the lowest point of the track."""
    g = check_range(field, ground_h, current().min_height_m, current().max_height_m, unit="m", error=error)
    lowest = float(np.min(np.asarray(track_h, dtype=float)))
    if g > lowest + GROUND_TOLERANCE_M:
        raise error(f"{field}: ground at {_fmt(g)} m lies above the track's lowest point {_fmt(lowest)} m",
                    field=field)
    return g


_ID_BODY = (r"(?!\.)(?!([cC][oO][nN]|[pP][rR][nN]|[aA][uU][xX]|[nN][uU][lL]|[cC][oO][mM][0-9]|"
            r"[lL][pP][tT][0-9])(\.|@|$))[A-Za-z0-9._-]{1,128}")
SAFE_ID_PATTERN = "^" + _ID_BODY + r"(?![\s\S])$"
CARD_REF_PATTERN = "^" + _ID_BODY + r"(@[1-9][0-9]{0,8})?(?![\s\S])$"
r"""Identifiers (cards, jobs, layers): letters, digits, ``-``, ``_``, ``.``; no leading dot, no reserved
device name (``con``, ``nul``, ``com1`` ...), 1..128 characters.  ``CARD_REF_PATTERN``: an id or
``id@version``.  ``(?![\s\S])`` makes the end exact
(no trailing newline) in Python and ECMAScript alike, so the OpenAPI schema states what is checked."""


def check_id(value: str, *, field: str = "id", error: type[InputError] = InputError) -> str:
    """``value`` if it matches :data:`SAFE_ID_PATTERN`; else one line naming the field."""
    import re

    if not isinstance(value, str) or re.fullmatch(SAFE_ID_PATTERN, value) is None:
        raise error(f"{field}: {value!r} is not a valid identifier (letters, digits, '-', '_', '.', no leading "
                    f"dot, no reserved device name, at most 128 characters)", field=field)
    return value
