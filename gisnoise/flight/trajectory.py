"""Trajectories: time-stamped position, attitude, power and phase of a UAV.

The flight CSV (one row per log sample, sorted by time) has the columns
``t`` (s), ``lat``, ``lon`` (deg), ``h`` (m, ellipsoidal), ``roll``, ``pitch``,
``yaw`` (deg), ``power_w`` (W) and optionally ``rpm``, ``airspeed_m_s``,
``phase`` and ``on_ground`` (1 or 0).

Samples on the ground (a disarmed or landed vehicle) are part of a real log and are
kept, marked as not flying: a sample is *not flying* when its ``on_ground`` flag is
set, or its electric power is zero or negative (no current drawn, or a current sensor's
offset at rest), or it lies upside down: inverted (``cos(roll) cos(pitch) < 0``) and at rest
for 1 s or longer, which no vehicle can be in the air, since neither its rotors nor anything
else hold it up (:func:`gisnoise.flight.rest.lying_inverted`; a crashed vehicle whose motors
still draw power and whose land detector never fired).  Not-flying samples make no noise on a map
and are masked in fits; :attr:`Trajectory.flying` is the one definition of the rule.  :class:`Trajectory` keeps angles in degrees as in the file; use
:meth:`Trajectory.enu` and :meth:`Trajectory.attitude_rad` for the model.

A :class:`Trajectory` owns its arrays: it copies what it is given (numpy arrays, lists, pandas columns) and
makes the copies read-only, so the checks made when it is built hold for its life; editing the caller's
arrays afterwards changes nothing in it, and writing into its own raises ``ValueError``.  Derive a changed
trajectory with :meth:`Trajectory.with_` or :meth:`Trajectory.select`.

Times ``t`` are seconds since the flight's start.  A ``timedelta64`` column (numpy or pandas, or
``datetime.timedelta`` values) is a duration with its unit in the data, so it is converted to seconds
exactly; a ``datetime64`` column (dates and times of day) is refused naming ``t``, since only the caller
knows the instant the flight starts: pass ``(t - t[0]) / np.timedelta64(1, "s")``.
"""

from __future__ import annotations

import csv
import datetime
import io
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import MissingColumnError, TrajectoryError
from gisnoise.flight.gaps import gap_metadata
from gisnoise.flight.glitches import mend_glitches
from gisnoise.flight.phases import PHASES
from gisnoise.flight.rest import lying_inverted
from gisnoise.geo import LocalFrame, wrap_angle, wrap_deg
from gisnoise.limits import check_track

__all__ = ["Trajectory", "read_flight_csv", "from_columns", "column", "REQUIRED_COLUMNS", "OPTIONAL_COLUMNS"]

REQUIRED_COLUMNS = ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w")
OPTIONAL_COLUMNS = ("rpm", "airspeed_m_s", "phase", "on_ground")


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A UAV trajectory; arrays of equal length ``n``.

    Attributes
    ----------
    t : ndarray
        Time, s, strictly increasing.
    lat, lon : ndarray
        WGS84 position, deg.
    h : ndarray
        Ellipsoidal height, m.
    roll, pitch, yaw : ndarray
        Z-Y-X Euler angles, deg (yaw wrapped into (-180, 180]).
    power_w : ndarray
        Electric power, W (zero or negative on samples that are not flying).
    phase : ndarray of str
        Flight phase of each sample (``horizontal`` when the source has none).
    rpm, airspeed_m_s : ndarray or None
        Optional propeller speed (1/min) and airspeed (m/s).
    on_ground : ndarray of bool or None
        True where the source marks the vehicle as on the ground (landed, disarmed).
    metadata : dict
        Provenance the reader states, e.g. ``height_datum`` and ``geoid_undulation_m``.
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    power_w: np.ndarray
    phase: np.ndarray
    rpm: np.ndarray | None = None
    airspeed_m_s: np.ndarray | None = None
    on_ground: np.ndarray | None = None
    source: str = field(default="trajectory", compare=False)
    metadata: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        src = self.source
        n = None
        for f in fields(self):
            if f.name in ("source", "metadata"):
                continue
            v = getattr(self, f.name)
            if v is None:
                continue
            if f.name == "phase":
                arr = np.array(v, dtype=object).astype(str)
                if arr.ndim != 1:
                    raise TrajectoryError(f"{src}: field 'phase' must be one-dimensional, got shape {arr.shape}",
                                          field=f.name)
            elif f.name == "on_ground":
                arr = column(f.name, v, source=src, finite=False)
                if not np.all((arr == 0) | (arr == 1)):
                    raise TrajectoryError(f"{src}: field 'on_ground' must hold 0 or 1 per sample", field=f.name)
                arr = arr.astype(bool)
            else:
                arr = column(f.name, v, source=src)
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise TrajectoryError(f"{src}: field '{f.name}' has {arr.shape[0]} samples, expected {n}",
                                      field=f.name)
            if f.name == "yaw":
                arr = wrap_deg(arr)
            arr.flags.writeable = False   # its own copy, never changed: the checks below hold for its life
            object.__setattr__(self, f.name, arr)
        if not n:
            raise TrajectoryError(f"{src}: the trajectory is empty", field="t")
        dt = np.diff(self.t)
        if np.any(dt <= 0):
            i = int(np.flatnonzero(dt <= 0)[0]) + 1
            raise TrajectoryError(f"{src}: field 't' is not strictly increasing at sample {i} "
                                  f"(t={self.t[i]:g} s after {self.t[i - 1]:g} s)", field="t")
        if np.any(np.abs(self.lat) > 90):
            raise TrajectoryError(f"{src}: field 'lat' outside [-90, 90] deg", field="lat")
        check_track(self.t, self.lat, self.lon, self.h, self.roll, self.pitch, self.power_w, source=src,
                    error=TrajectoryError)  # the shared rule set (gisnoise.limits)
        bad = [p for p in np.unique(self.phase) if p not in PHASES]
        if bad:
            raise TrajectoryError(f"{src}: field 'phase' has unknown value {str(bad[0])!r}; known: {', '.join(PHASES)}",
                                  field="phase")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def flying(self) -> np.ndarray:
        """True on samples that fly: not marked ``on_ground``, with positive electric power, not :attr:`lying`."""
        fly = self.power_w > 0
        if self.on_ground is not None:
            fly &= ~self.on_ground
        return fly & ~self.lying

    def flying_heights(self) -> np.ndarray:
        """Heights (m) of the samples that fly (:attr:`flying`), or of every sample when none does: the heights a
        ground given for a map of this flight must lie below."""
        fly = self.flying
        return self.h[fly] if fly.any() else self.h

    @cached_property
    def lying(self) -> np.ndarray:
        """True on samples where the vehicle lies upside down: inverted and at rest for 1 s or longer
        (:func:`gisnoise.flight.rest.lying_inverted`).  Found once per trajectory (its arrays are read-only copies,
        never changed after it is made; :meth:`select` and :meth:`with_` make new ones); read-only."""
        out = lying_inverted(self.t, self.lat, self.lon, self.h, self.roll, self.pitch)
        out.flags.writeable = False
        return out

    def origin(self) -> LocalFrame:
        """A local frame at the first sample's ground point (h0 = min height)."""
        return LocalFrame(float(self.lat[0]), float(self.lon[0]), float(np.min(self.h)))

    def enu(self, frame: LocalFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions in ``frame``, m."""
        return frame.to_enu(self.lat, self.lon, self.h)

    def attitude_rad(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(yaw, pitch, roll) in radians."""
        return np.radians(self.yaw), np.radians(self.pitch), np.radians(self.roll)

    def interpolate(self, t: Any) -> dict[str, np.ndarray]:
        """Linear interpolation of the state at times ``t`` (s); angles on the circle.

        Phase is taken from the nearest earlier sample.  Times outside the
        trajectory are clamped to its ends.
        """
        t = np.asarray(t, dtype=float)
        out: dict[str, np.ndarray] = {}
        for name in ("lat", "lon", "h", "power_w", "rpm", "airspeed_m_s"):
            v = getattr(self, name)
            if v is not None:
                out[name] = np.interp(t, self.t, v)
        for name in ("roll", "pitch", "yaw"):
            v = np.radians(getattr(self, name))
            c = np.interp(t, self.t, np.cos(v))
            s = np.interp(t, self.t, np.sin(v))
            out[name] = np.degrees(wrap_angle(np.arctan2(s, c)))
        idx = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self) - 1)
        out["phase"] = self.phase[idx]
        return out

    def flying_at(self, t: Any) -> np.ndarray:
        """Whether the vehicle flies at times ``t`` (s): both samples around ``t`` fly (see :attr:`flying`)."""
        t = np.asarray(t, dtype=float)
        idx = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self) - 1)
        fly = self.flying
        return fly[idx] & fly[np.clip(idx + 1, 0, len(self) - 1)] & (t >= self.t[0]) & (t <= self.t[-1])

    def select(self, mask: Any) -> Trajectory:
        """A trajectory of the samples where ``mask`` is true."""
        m = np.asarray(mask)
        kw: dict[str, Any] = {f.name: (None if getattr(self, f.name) is None else getattr(self, f.name)[m])
              for f in fields(self) if f.name not in ("source", "metadata")}
        return Trajectory(**kw, source=self.source, metadata=dict(self.metadata))

    def with_(self, **changes: Any) -> Trajectory:
        return replace(self, **changes)

    def columns(self) -> dict[str, np.ndarray]:
        """The flight-CSV columns as arrays."""
        out = {k: getattr(self, k) for k in REQUIRED_COLUMNS}
        for k in ("rpm", "airspeed_m_s"):
            if getattr(self, k) is not None:
                out[k] = getattr(self, k)
        out["phase"] = self.phase
        if self.on_ground is not None:
            out["on_ground"] = self.on_ground.astype(int)
        return out

    def to_csv(self, path: str | os.PathLike[str] | None = None) -> str:
        """Write the flight CSV (to ``path`` if given); returns the text."""
        cols = self.columns()
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(list(cols))
        fmt = {"lat": "{:.9f}", "lon": "{:.9f}"}
        for i in range(len(self)):
            w.writerow([v[i] if k in ("phase", "on_ground") else fmt.get(k, "{:.6g}").format(v[i]) for k, v in cols.items()])
        text = buf.getvalue()
        if path is not None:
            Path(path).write_text(text, encoding="utf-8")
        return text


def from_columns(cols: Mapping[str, Any], *, source: str = "trajectory") -> Trajectory:
    """Build a trajectory from named columns (the flight-CSV names; a dict of arrays or a pandas DataFrame).

    Errors name the column.  The trajectory copies the columns (see the module docstring): editing them
    afterwards leaves it unchanged.  ``t`` is seconds since the flight's start; a ``timedelta64`` ``t`` is
    converted to seconds, a ``datetime64`` one refused (:func:`column`).
    """
    missing = [c for c in REQUIRED_COLUMNS if c not in cols]
    if missing:
        raise MissingColumnError(f"{source}: missing column(s) {', '.join(missing)}", field=missing[0])
    kw: dict[str, Any] = {}
    for c in REQUIRED_COLUMNS + ("rpm", "airspeed_m_s", "on_ground"):
        if c not in cols:
            continue
        kw[c] = column(c, cols[c], source=source, finite=c != "on_ground")
        if kw[c].shape[0] != kw["t"].shape[0]:
            raise TrajectoryError(f"{source}: column '{c}' has {kw[c].shape[0]} samples, column 't' has "
                                  f"{kw['t'].shape[0]}", field=c)
    n = kw["t"].shape[0]
    kw["phase"] = np.asarray(cols["phase"], dtype=str) if "phase" in cols else np.full(n, "horizontal")
    glitches = mend_glitches(kw["t"], kw["lat"], kw["lon"], kw["h"])  # unchanged without glitches
    kw.update(lat=glitches.lat, lon=glitches.lon, h=glitches.h)
    return Trajectory(**kw, source=source, metadata={**glitches.metadata(kw["t"]), **gap_metadata(kw["t"])})


def column(name: str, values: Any, *, source: str = "trajectory", finite: bool = True) -> np.ndarray:
    """One numeric column of a trajectory as a new one-dimensional float64 array (a copy, never a view).

    Parameters
    ----------
    name : str
        The field, named in errors.
    values : array_like
        Numbers; for ``t`` also durations (``timedelta64``, numpy or pandas, or ``datetime.timedelta``),
        converted to seconds exactly.
    source : str
        The file or caller, named in errors.
    finite : bool
        Refuse NaN and infinite values.

    Raises
    ------
    TrajectoryError
        Naming ``name``: dates and times (``datetime64``; for ``t`` with the way to seconds), durations in a
        field other than ``t``, a non-numeric value, a shape other than one-dimensional, a NaN.

    Examples
    --------
    >>> column("t", np.array([0, 90, 150], dtype="timedelta64[s]"))
    array([  0.,  90., 150.])
    >>> column("t", np.array(["2024-05-04T10:00", "2024-05-04T10:01"], dtype="datetime64[m]"))
    Traceback (most recent call last):
    ...
    gisnoise.errors.TrajectoryError: trajectory: field 't' holds dates and times (datetime64), not seconds since the flight's start; pass (t - t[0]) / np.timedelta64(1, "s")
    """
    kind = _time_kind(values)
    if kind == "M":
        what = "seconds since the flight's start; pass (t - t[0]) / np.timedelta64(1, \"s\")" if name == "t" \
            else "numbers"
        raise TrajectoryError(f"{source}: field '{name}' holds dates and times (datetime64), not {what}", field=name)
    if kind == "m":
        if name != "t":
            raise TrajectoryError(f"{source}: field '{name}' holds durations (timedelta64), not numbers", field=name)
        arr = _seconds(values)
    else:
        try:
            arr = np.array(values, dtype=float)
        except (TypeError, ValueError):
            raise TrajectoryError(f"{source}: field '{name}' has a non-numeric value", field=name) from None
    if arr.ndim != 1:
        raise TrajectoryError(f"{source}: field '{name}' must be one-dimensional, got shape {arr.shape}", field=name)
    if finite:
        bad = ~np.isfinite(arr)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise TrajectoryError(f"{source}: field '{name}' has NaN or infinite value at sample {i}", field=name)
    return arr


def _time_kind(values: Any) -> str | None:
    """``"M"`` for dates and times, ``"m"`` for durations, else None (numbers, strings)."""
    kind = getattr(getattr(values, "dtype", None), "kind", None)   # numpy and pandas dtypes (tz-aware ones too)
    if kind in ("M", "m"):
        return str(kind)
    if kind == "O":
        items: Any = np.asarray(values).ravel()
    elif kind is None and isinstance(values, (list, tuple)):
        items = values
    else:
        return None
    first = next((x for x in items if x is not None), None)
    if isinstance(first, (datetime.date, np.datetime64)):   # datetime.datetime and pandas Timestamp too
        return "M"
    if isinstance(first, (datetime.timedelta, np.timedelta64)):
        return "m"
    return None


def _seconds(values: Any) -> np.ndarray:
    """Durations (``timedelta64`` or ``datetime.timedelta``) in seconds; NaT becomes NaN."""
    if getattr(getattr(values, "dtype", None), "kind", None) == "m":
        return np.asarray(np.asarray(values) / np.timedelta64(1, "s"), dtype=float)
    flat = np.asarray(values, dtype=object)
    secs = [np.nan if x is None else float(x / np.timedelta64(1, "s")) if isinstance(x, np.timedelta64)
            else float(x.total_seconds()) for x in flat.ravel()]
    return np.array(secs, dtype=float).reshape(flat.shape)


def read_flight_csv(path: str | os.PathLike[str] | io.TextIOBase, *, source: str | None = None) -> Trajectory:
    """Read a flight CSV (see module docstring); errors name the file and column."""
    if isinstance(path, (str, os.PathLike)):
        src = source or str(path)
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except FileNotFoundError:
            raise TrajectoryError(f"{src}: no such file", field="trajectory") from None
        except UnicodeDecodeError as exc:
            raise TrajectoryError(f"{src}: not a UTF-8 text CSV (byte {exc.start}: {exc.reason})", field="csv") from None
    else:
        src = source or "flight CSV"
        text = path.read().removeprefix("\ufeff")  # a byte-order mark, as a file read with utf-8-sig drops it
    reader = csv.reader(io.StringIO(text, newline=None))
    try:
        header = [h.strip() for h in next(reader)]
        rows = [r for r in reader if r and any(x.strip() for x in r)]
    except StopIteration:
        raise TrajectoryError(f"{src}: the file is empty", field="t") from None
    except csv.Error as exc:
        raise TrajectoryError(f"{src}: malformed CSV at line {reader.line_num}: {exc}", field="csv") from None
    for sep, name in ((";", "';'"), ("\t", "tab")):
        if len(header) == 1 and sep in header[0]:  # a spreadsheet's export in a decimal-comma locale
            raise TrajectoryError(f"{src}: fields are separated by {name}; a flight CSV separates them by a comma "
                                  "and writes numbers with a decimal point", field="csv")
    cols: dict[str, list[str]] = {h: [] for h in header}
    for ln, r in enumerate(rows, start=2):
        if len(r) != len(header):
            raise TrajectoryError(f"{src}: line {ln} has {len(r)} fields, header has {len(header)}", field="csv")
        for h, v in zip(header, r, strict=True):
            cols[h].append(v.strip())
    out: dict[str, Any] = {}
    for h, vals in cols.items():
        if h == "phase":
            out[h] = vals
            continue
        if h not in REQUIRED_COLUMNS + OPTIONAL_COLUMNS:
            continue
        try:
            out[h] = np.array([float(v) if v != "" else np.nan for v in vals])
        except ValueError:
            bad = next(i for i, v in enumerate(vals) if not _isfloat(v))
            raise TrajectoryError(f"{src}: column '{h}' line {bad + 2}: not a number: {vals[bad]!r}",
                                  field=h) from None
    return from_columns(out, source=src)


def _isfloat(v: str) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True
