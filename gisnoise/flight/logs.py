"""Flight logs: the flight CSV, PX4 ULog and ArduPilot DataFlash as :class:`Trajectory`.

:func:`read_flight` dispatches on the file suffix:

``.csv``
    The flight CSV of the specification (:func:`gisnoise.flight.trajectory.read_flight_csv`);
    ``t`` is already seconds since the flight's start.
``.ulg``
    PX4 ULog through pyulog.  Position from ``vehicle_global_position`` when logged,
    else from ``vehicle_gps_position`` / ``sensor_gps`` (3D fixes only); attitude
    from the ``vehicle_attitude`` quaternion (Hamilton, body FRD -> NED) as Z-Y-X
    Euler angles; electric power as the sum over ``battery_status`` instances of
    voltage x current; optional ``rpm`` (``rpm`` or ``esc_status``) and airspeed
    (``airspeed_validated`` or ``airspeed``).
``.bin``
    ArduPilot DataFlash through pymavlink.  Position from ``POS`` when logged, else
    ``GPS`` (3D fixes only); attitude from ``ATT``; power from ``BAT`` (one battery per
    ``Instance``) or ``CURR`` (+ ``CUR2``).  Old logs store ``CURR`` voltage and current
    as integer hundredths of a volt and ampere; they are recognised by the integer
    format character of the field and scaled, newer float fields are taken as V and A.

Time base
    The samples of the position source (or a uniform grid at ``rate_hz``), trimmed to
    the span where position, attitude and power are all logged; attitude and power are
    interpolated onto it (attitude on the circle).  With ``start_utc`` the times are
    seconds since that instant, mapped through the GPS clock in the log (PX4
    ``time_utc_usec``; ArduPilot GPS week and milliseconds minus the leap seconds);
    without it, seconds since the first kept sample.

Heights
    Trajectories hold ellipsoidal heights.  PX4 logs give them (``alt_ellipsoid``);
    where only heights above mean sea level exist (ArduPilot, some PX4 topics), the
    geoid undulation N (ellipsoidal minus orthometric height, m) must be given as
    ``geoid_undulation_m``; it is never guessed.

Phase (see :func:`phase_by_speed`)
    A PX4 VTOL's state (``vtol_vehicle_status``, else ``vehicle_status``) gives
    ``horizontal`` in fixed-wing mode and ``transition`` while transitioning.  In
    multicopter mode, and for logs without a VTOL state (all ArduPilot logs), the
    phase follows the ground velocity smoothed over 1 s: ``climb`` / ``sink`` when the
    vertical speed exceeds 1 m/s and the horizontal speed, else ``hover`` below 3 m/s
    horizontal speed, else ``horizontal``.

A missing topic or message raises :class:`~gisnoise.errors.MissingColumnError`
naming it and the file.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError, MissingColumnError, TrajectoryError
from gisnoise.flight.trajectory import Trajectory, read_flight_csv
from gisnoise.geo import LocalFrame, wrap_angle, wrap_deg

__all__ = [
    "read_flight",
    "read_ulog",
    "read_dataflash",
    "quaternion_to_euler",
    "phase_by_speed",
    "gps_to_unix",
    "as_unix_time",
    "FLIGHT_SUFFIXES",
    "HOVER_MAX_SPEED_M_S",
    "VERTICAL_MIN_SPEED_M_S",
]

log = logging.getLogger(__name__)

FLIGHT_SUFFIXES = (".csv", ".ulg", ".bin")
HOVER_MAX_SPEED_M_S = 3.0
"""Horizontal ground speed below which multicopter flight is ``hover``, m/s."""
VERTICAL_MIN_SPEED_M_S = 1.0
"""Vertical speed above which multicopter flight is ``climb`` or ``sink``, m/s."""
PHASE_SMOOTHING_S = 1.0
"""Width of the centred moving average applied to the velocity before the phase rule, s."""

_GPS_EPOCH_UNIX = 315964800.0  # 1980-01-06T00:00:00Z
# (first unix second of validity, GPS - UTC in s); IERS bulletin C
_LEAP_SECONDS = (
    (820454400.0, 11),   # 1996-01-01
    (867715200.0, 12),   # 1997-07-01
    (915148800.0, 13),   # 1999-01-01
    (1136073600.0, 14),  # 2006-01-01
    (1230768000.0, 15),  # 2009-01-01
    (1341100800.0, 16),  # 2012-07-01
    (1435708800.0, 17),  # 2015-07-01
    (1483228800.0, 18),  # 2017-01-01
)


# --------------------------------------------------------------------- public helpers
def read_flight(path: str | os.PathLike[str], *, start_utc: Any = None,
                geoid_undulation_m: float | None = None, rate_hz: float | None = None) -> Trajectory:
    """Read a flight log (``.csv``, ``.ulg`` or ``.bin``) as a trajectory.

    Parameters
    ----------
    path : path-like
        The log file; the suffix selects the reader.
    start_utc : datetime, str (ISO 8601), float (unix s) or None
        For ``.ulg`` and ``.bin``: the instant that becomes ``t = 0`` (the flight's
        ``start_utc``).  Ignored for ``.csv``, whose ``t`` is already relative to it.
    geoid_undulation_m : float, optional
        Ellipsoidal minus orthometric height, m, for logs that only give heights
        above mean sea level.
    rate_hz : float, optional
        Resample logs onto a uniform grid at this rate, Hz (default: the position
        samples).

    Returns
    -------
    Trajectory
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".csv":
        return read_flight_csv(p)
    if suffix == ".ulg":
        return read_ulog(p, start_utc=start_utc, geoid_undulation_m=geoid_undulation_m, rate_hz=rate_hz)
    if suffix == ".bin":
        return read_dataflash(p, start_utc=start_utc, geoid_undulation_m=geoid_undulation_m, rate_hz=rate_hz)
    raise InputError(f"{p}: unknown flight log type {p.suffix!r}; expected one of {', '.join(FLIGHT_SUFFIXES)}",
                     field="path")


def quaternion_to_euler(q: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Z-Y-X Euler angles (roll, pitch, yaw), deg, of Hamilton quaternions ``(w, x, y, z)``.

    The quaternion rotates body (FRD) vectors into NED, as PX4 logs it.  Yaw is
    wrapped into (-180, 180].

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions ``w, x, y, z``; normalised here.

    Examples
    --------
    >>> import numpy as np
    >>> h = np.radians(30.0) / 2
    >>> r, p, y = quaternion_to_euler([np.cos(h), 0.0, 0.0, np.sin(h)])  # 30 deg right turn
    >>> round(float(r), 9), round(float(p), 9), round(float(y), 9)
    (0.0, 0.0, 30.0)
    """
    q = np.asarray(q, dtype=float)
    if q.shape[-1] != 4:
        raise InputError(f"quaternion must have 4 components, got shape {q.shape}", field="q")
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    roll = np.arctan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return np.degrees(roll), np.degrees(pitch), wrap_deg(np.degrees(yaw))


def phase_by_speed(t: Any, vel_enu: Any, *, smoothing_s: float = PHASE_SMOOTHING_S,
                   hover_max_m_s: float = HOVER_MAX_SPEED_M_S,
                   vertical_min_m_s: float = VERTICAL_MIN_SPEED_M_S) -> np.ndarray:
    """Flight phase of multicopter flight from the ground velocity.

    The velocity is smoothed by a centred moving average of ``smoothing_s``; then
    ``climb`` where the upward speed exceeds ``vertical_min_m_s`` and the horizontal
    speed, ``sink`` likewise downward, ``hover`` where the horizontal speed is below
    ``hover_max_m_s``, else ``horizontal``.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times, s, increasing.
    vel_enu : array_like, shape (n, 3)
        Ground velocity east, north, up, m/s.

    Examples
    --------
    >>> phase_by_speed([0.0, 1.0, 2.0], [[0, 0, 2.0], [0, 0, 2.0], [0, 0, 2.0]]).tolist()
    ['climb', 'climb', 'climb']
    >>> phase_by_speed([0.0, 1.0], [[10.0, 0, 0], [10.0, 0, 0]]).tolist()
    ['horizontal', 'horizontal']
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(vel_enu, dtype=float).reshape(-1, 3)
    if len(t) != len(v):
        raise InputError(f"phase_by_speed: t has {len(t)} samples, vel_enu {len(v)}", field="vel_enu")
    vs = _moving_average(t, v, smoothing_s)
    vh = np.hypot(vs[:, 0], vs[:, 1])
    vu = vs[:, 2]
    out = np.where(vh < hover_max_m_s, "hover", "horizontal").astype("<U10")
    out[(vu > vertical_min_m_s) & (vu > vh)] = "climb"
    out[(-vu > vertical_min_m_s) & (-vu > vh)] = "sink"
    return out


def gps_to_unix(week: Any, ms_of_week: Any) -> np.ndarray:
    """Unix time (UTC, s) of GPS week and milliseconds of week, leap seconds removed.

    Examples
    --------
    >>> float(gps_to_unix(1871, 603882400.0))  # 2015-11-21 23:44:25.4 UTC (GPS - UTC = 17 s)
    1448149465.4
    """
    g = _GPS_EPOCH_UNIX + np.asarray(week, dtype=float) * 604800.0 + np.asarray(ms_of_week, dtype=float) / 1000.0
    leap = np.zeros_like(g)
    for start, n in _LEAP_SECONDS:
        leap = np.where(g - n >= start, n, leap)
    return g - leap


def as_unix_time(value: Any, *, field: str = "start_utc") -> float:
    """Unix seconds (UTC) of a datetime, an ISO 8601 string (``Z`` allowed) or a number."""
    if isinstance(value, datetime):
        dt = value if value.tzinfo else value.replace(tzinfo=timezone.utc)
        return dt.timestamp()
    if isinstance(value, str):
        s = value.strip()
        if s.endswith(("Z", "z")):
            s = s[:-1] + "+00:00"
        try:
            dt = datetime.fromisoformat(s)
        except ValueError:
            raise InputError(f"{field}: not an ISO 8601 time: {value!r}", field=field) from None
        return as_unix_time(dt, field=field)
    if isinstance(value, (int, float, np.number)) and np.isfinite(value):
        return float(value)
    raise InputError(f"{field}: expected an ISO 8601 time, got {value!r}", field=field)


# --------------------------------------------------------------------- PX4 ULog
_ULOG_TOPICS = ("vehicle_global_position", "vehicle_gps_position", "sensor_gps", "vehicle_attitude",
                "battery_status", "vtol_vehicle_status", "vehicle_status", "airspeed_validated", "airspeed",
                "rpm", "esc_status")


def read_ulog(path: str | os.PathLike[str], *, start_utc: Any = None, geoid_undulation_m: float | None = None,
              rate_hz: float | None = None) -> Trajectory:
    """Read a PX4 ULog as a trajectory (see the module docstring for the topics used).

    Parameters
    ----------
    path : path-like
        ``.ulg`` file.
    start_utc : datetime, str or float, optional
        Instant of ``t = 0``; needs GPS UTC time in the log.
    geoid_undulation_m : float, optional
        Used only when no ellipsoidal height is logged, m.
    rate_hz : float, optional
        Uniform resampling rate, Hz.
    """
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - optional extra
        raise InputError("reading PX4 ULog needs pyulog (pip install 'gisnoise[logs]')", field="path") from None
    src = str(path)
    try:
        ulog = ULog(src, list(_ULOG_TOPICS))
    except FileNotFoundError:
        raise TrajectoryError(f"{src}: no such file", field="path") from None
    except Exception as exc:  # pyulog raises bare exceptions on corrupt files
        raise TrajectoryError(f"{src}: not a readable ULog ({exc})", field="path") from None
    topics: dict[str, list[dict[str, np.ndarray]]] = {}
    for d in ulog.data_list:
        topics.setdefault(d.name, []).append(d.data)

    def first(*names: str) -> tuple[str, dict[str, np.ndarray]] | None:
        for n in names:
            if n in topics:
                return n, topics[n][0]
        return None

    # position
    gps = first("vehicle_gps_position", "sensor_gps")
    gps_cols = _px4_gps_columns(*gps) if gps else None
    glob = first("vehicle_global_position")
    if glob is not None:
        g = glob[1]
        tb = g["timestamp"] / 1e6
        lat, lon = g["lat"].astype(float), g["lon"].astype(float)
        if "alt_ellipsoid" in g:
            h = g["alt_ellipsoid"].astype(float)
        else:
            n_und = _undulation(src, gps_cols, geoid_undulation_m, "vehicle_global_position.alt_ellipsoid")
            h = g["alt"].astype(float) + n_und
        pos_name = "vehicle_global_position"
    elif gps_cols is not None:
        tb, lat, lon, h_ell, h_msl = (gps_cols[k] for k in ("t", "lat", "lon", "h_ell", "h_msl"))
        h = h_ell if h_ell is not None else h_msl + _undulation(src, None, geoid_undulation_m,
                                                               f"{gps[0]}.alt_ellipsoid")  # type: ignore[index]
        pos_name = gps[0]  # type: ignore[index]
    else:
        raise MissingColumnError(f"{src}: topic 'vehicle_global_position' or 'vehicle_gps_position' missing "
                                 "(no position)", field="vehicle_global_position")
    if len(tb) < 2:
        raise TrajectoryError(f"{src}: topic '{pos_name}' has fewer than 2 valid samples", field=pos_name)

    # attitude
    att = first("vehicle_attitude")
    if att is None:
        raise MissingColumnError(f"{src}: topic 'vehicle_attitude' missing (no attitude)", field="vehicle_attitude")
    a = att[1]
    t_att = a["timestamp"] / 1e6
    q = np.stack([a[f"q[{i}]"] for i in range(4)], axis=-1).astype(float)

    # power: sum over battery instances of V * I
    if "battery_status" not in topics:
        raise MissingColumnError(f"{src}: topic 'battery_status' missing (no electric power)", field="battery_status")
    batteries = []
    for b in topics["battery_status"]:
        if "connected" in b and not np.any(b["connected"]):
            continue
        batteries.append((b["timestamp"] / 1e6, b["voltage_v"].astype(float) * b["current_a"].astype(float)))
    if not batteries:
        raise MissingColumnError(f"{src}: topic 'battery_status' has no connected battery", field="battery_status")

    spans = [(tb[0], tb[-1]), (t_att[0], t_att[-1])] + [(tt[0], tt[-1]) for tt, _ in batteries]
    t = _time_base(src, tb, spans, rate_hz)
    lat_i, lon_i, h_i = (np.interp(t, tb, v) for v in (lat, lon, h))
    roll, pitch, yaw = quaternion_to_euler(_interp_quaternion(t, t_att, q))
    power = np.zeros_like(t)
    for tt, pw in batteries:
        power += np.interp(t, tt, pw)

    cols: dict[str, Any] = {"lat": lat_i, "lon": lon_i, "h": h_i, "roll": roll, "pitch": pitch, "yaw": yaw,
                            "power_w": power}
    # optional columns, when the topic covers the whole span
    for name in ("airspeed_validated", "airspeed"):
        if name in topics and "true_airspeed_m_s" in topics[name][0]:
            d = topics[name][0]
            cols["airspeed_m_s"] = _covering(t, d["timestamp"] / 1e6, d["true_airspeed_m_s"], name)
            if cols["airspeed_m_s"] is not None:
                break
    rpm = _px4_rpm(topics)
    if rpm is not None:
        cols["rpm"] = _covering(t, rpm[0], rpm[1], "rpm")
    cols = {k: v for k, v in cols.items() if v is not None}

    vtol = _px4_vtol_state(topics, t)
    cols["phase"] = _phase(t, lat_i, lon_i, h_i, vtol)

    utc_offset = None
    if gps_cols is not None and gps_cols["utc_offset"] is not None:
        utc_offset = gps_cols["utc_offset"]
    return _finish(src, t, cols, start_utc, utc_offset, "vehicle_gps_position.time_utc_usec")


def _px4_gps_columns(name: str, g: Mapping[str, np.ndarray]) -> dict[str, Any]:
    if "latitude_deg" in g:
        lat, lon = g["latitude_deg"].astype(float), g["longitude_deg"].astype(float)
        h_msl = g["altitude_msl_m"].astype(float) if "altitude_msl_m" in g else None
        h_ell = g["altitude_ellipsoid_m"].astype(float) if "altitude_ellipsoid_m" in g else None
    else:
        lat, lon = g["lat"] / 1e7, g["lon"] / 1e7
        h_msl = g["alt"] / 1e3 if "alt" in g else None
        h_ell = g["alt_ellipsoid"] / 1e3 if "alt_ellipsoid" in g else None
    ok = g["fix_type"] >= 3 if "fix_type" in g else np.ones(len(lat), dtype=bool)
    ts = g["timestamp"].astype(float)
    utc_offset = None
    if "time_utc_usec" in g:
        has = ok & (g["time_utc_usec"] > 0)
        if has.any():
            utc_offset = float(np.median(g["time_utc_usec"][has].astype(float) - ts[has])) / 1e6
    sel = (lambda v: None if v is None else v[ok])  # noqa: E731
    return {"t": ts[ok] / 1e6, "lat": lat[ok], "lon": lon[ok], "h_ell": sel(h_ell), "h_msl": sel(h_msl),
            "utc_offset": utc_offset}


def _undulation(src: str, gps_cols: Mapping[str, Any] | None, given: float | None, what: str) -> float:
    if given is not None:
        return float(given)
    if gps_cols is not None and gps_cols["h_ell"] is not None and gps_cols["h_msl"] is not None \
            and len(gps_cols["h_ell"]):
        return float(np.median(gps_cols["h_ell"] - gps_cols["h_msl"]))
    raise MissingColumnError(f"{src}: '{what}' missing (only heights above mean sea level); "
                             "give geoid_undulation_m", field="geoid_undulation_m")


def _px4_rpm(topics: Mapping[str, list[dict[str, np.ndarray]]]) -> tuple[np.ndarray, np.ndarray] | None:
    if "rpm" in topics and "indicated_frequency_rpm" in topics["rpm"][0]:
        r = topics["rpm"][0]
        return r["timestamp"] / 1e6, r["indicated_frequency_rpm"].astype(float)
    if "esc_status" in topics:
        e = topics["esc_status"][0]
        keys = [k for k in e if k.startswith("esc[") and k.endswith("].esc_rpm")]
        if keys:
            n = e["esc_count"].astype(int) if "esc_count" in e else np.full(len(e["timestamp"]), len(keys))
            vals = np.stack([e[k].astype(float) for k in sorted(keys)], axis=-1)
            used = np.arange(len(keys))[None, :] < n[:, None]
            mean = np.where(used, np.abs(vals), 0.0).sum(axis=1) / np.maximum(used.sum(axis=1), 1)
            return e["timestamp"] / 1e6, mean
    return None


def _px4_vtol_state(topics: Mapping[str, list[dict[str, np.ndarray]]], t: np.ndarray) -> np.ndarray | None:
    """Per time: 'mc', 'fw', 'transition', or None when the vehicle is not a VTOL."""
    if "vtol_vehicle_status" in topics:
        v = topics["vtol_vehicle_status"][0]
        tv = v["timestamp"] / 1e6
        if "vehicle_vtol_state" in v:
            s = v["vehicle_vtol_state"].astype(int)
            state = np.where(s == 4, "fw", np.where((s == 1) | (s == 2), "transition", "mc"))
        else:
            rw = v["vtol_in_rw_mode"].astype(bool)
            tr = v["vtol_in_trans_mode"].astype(bool)
            state = np.where(tr, "transition", np.where(rw, "mc", "fw"))
        return _step(t, tv, state)
    if "vehicle_status" in topics:
        v = topics["vehicle_status"][0]
        tv = v["timestamp"] / 1e6
        if "is_vtol" in v and np.any(v["is_vtol"]):
            fw = v["vehicle_type"].astype(int) == 2
            tr = v["in_transition_mode"].astype(bool) if "in_transition_mode" in v else np.zeros(len(tv), bool)
            state = np.where(tr, "transition", np.where(fw, "fw", "mc"))
            return _step(t, tv, state)
        if "vehicle_type" in v and np.all(v["vehicle_type"].astype(int) == 2):
            return np.full(len(t), "fw")
    return None


def _step(t: np.ndarray, tv: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The last value published at or before each t (the first before the first publication)."""
    i = np.clip(np.searchsorted(tv, t, side="right") - 1, 0, len(tv) - 1)
    return np.asarray(values)[i]


# --------------------------------------------------------------------- ArduPilot DataFlash
_INTEGER_FORMATS = set("bBhHiIqQ")


def read_dataflash(path: str | os.PathLike[str], *, start_utc: Any = None, geoid_undulation_m: float | None = None,
                   rate_hz: float | None = None) -> Trajectory:
    """Read an ArduPilot DataFlash ``.bin`` log as a trajectory (see the module docstring).

    ArduPilot logs heights above mean sea level only, so ``geoid_undulation_m``
    (ellipsoidal minus orthometric height at the site, m) is required.
    """
    try:
        from pymavlink import DFReader
    except ImportError:  # pragma: no cover - optional extra
        raise InputError("reading ArduPilot logs needs pymavlink (pip install 'gisnoise[logs]')",
                         field="path") from None
    src = str(path)
    if not Path(src).is_file():
        raise TrajectoryError(f"{src}: no such file", field="path")
    try:
        reader = DFReader.DFReader_binary(src, zero_time_base=True)
    except Exception as exc:
        raise TrajectoryError(f"{src}: not a readable DataFlash log ({exc})", field="path") from None
    wanted = ["GPS", "POS", "ATT", "BAT", "CURR", "CUR2", "RPM", "ARSP"]
    rows: dict[str, list[tuple[Any, ...]]] = {k: [] for k in wanted}
    fmts: dict[str, tuple[str, list[str]]] = {}
    try:
        while True:
            try:
                m = reader.recv_match(type=wanted)
            except Exception as exc:
                raise TrajectoryError(f"{src}: corrupt DataFlash log ({exc})", field="path") from None
            if m is None:
                break
            name = m.get_type()
            if name not in fmts:
                fmts[name] = (m.fmt.format, list(m.fmt.columns))
            rows[name].append(tuple(getattr(m, c) for c in m.fmt.columns))
    finally:
        reader.close()

    def table(name: str) -> dict[str, np.ndarray] | None:
        if not rows.get(name):
            return None
        cols = fmts[name][1]
        arr = list(zip(*rows[name], strict=True))
        out = {}
        for c, v in zip(cols, arr, strict=True):
            try:
                out[c] = np.asarray(v, dtype=float)
            except (TypeError, ValueError):
                continue
        return out

    # position
    gps = table("GPS")
    utc_offset = _ardupilot_utc_offset(gps) if gps is not None else None
    pos = table("POS")
    if pos is not None:
        tb = _ardupilot_boot_time("POS", pos)
        lat, lon, h_msl = pos["Lat"], pos["Lng"], pos["Alt"]
        pos_name = "POS"
    elif gps is not None:
        ok = gps["Status"] >= 3
        tb = _ardupilot_boot_time("GPS", gps)[ok]
        lat, lon, h_msl = gps["Lat"][ok], gps["Lng"][ok], gps["Alt"][ok]
        pos_name = "GPS"
    else:
        raise MissingColumnError(f"{src}: message 'GPS' missing (no position)", field="GPS")
    if len(tb) < 2:
        raise TrajectoryError(f"{src}: message '{pos_name}' has fewer than 2 samples with a 3D fix",
                              field=pos_name)
    keep = np.concatenate([[True], np.diff(tb) > 0])  # duplicated stamps
    tb, lat, lon, h_msl = tb[keep], lat[keep], lon[keep], h_msl[keep]
    if geoid_undulation_m is None:
        raise MissingColumnError(f"{src}: message '{pos_name}' gives heights above mean sea level only; "
                                 "give geoid_undulation_m", field="geoid_undulation_m")
    h = h_msl + float(geoid_undulation_m)

    att = table("ATT")
    if att is None:
        raise MissingColumnError(f"{src}: message 'ATT' missing (no attitude)", field="ATT")
    t_att = _ardupilot_boot_time("ATT", att)

    batteries = _ardupilot_batteries(src, table, fmts)
    spans = [(tb[0], tb[-1]), (t_att[0], t_att[-1])] + [(tt[0], tt[-1]) for tt, _ in batteries]
    t = _time_base(src, tb, spans, rate_hz)
    lat_i, lon_i, h_i = (np.interp(t, tb, v) for v in (lat, lon, h))
    roll, pitch, yaw = (_interp_deg(t, t_att, att[k]) for k in ("Roll", "Pitch", "Yaw"))
    power = np.zeros_like(t)
    for tt, pw in batteries:
        power += np.interp(t, tt, pw)
    cols: dict[str, Any] = {"lat": lat_i, "lon": lon_i, "h": h_i, "roll": roll, "pitch": pitch, "yaw": yaw,
                            "power_w": power}
    arsp = table("ARSP")
    if arsp is not None and "Airspeed" in arsp:
        cols["airspeed_m_s"] = _covering(t, _ardupilot_boot_time("ARSP", arsp), arsp["Airspeed"], "ARSP")
    rpm = table("RPM")
    if rpm is not None and "rpm1" in rpm:
        cols["rpm"] = _covering(t, _ardupilot_boot_time("RPM", rpm), rpm["rpm1"], "RPM")
    cols = {k: v for k, v in cols.items() if v is not None}
    cols["phase"] = _phase(t, lat_i, lon_i, h_i, None)
    return _finish(src, t, cols, start_utc, utc_offset, "GPS.Week")


def _ardupilot_boot_time(name: str, tab: Mapping[str, np.ndarray]) -> np.ndarray:
    """Boot time, s: ``TimeUS``; old logs: ``TimeMS`` (``T`` for GPS, whose TimeMS is GPS time)."""
    if "TimeUS" in tab:
        return tab["TimeUS"] / 1e6
    if name == "GPS" and "T" in tab:
        return tab["T"] / 1e3
    return tab["TimeMS"] / 1e3


def _ardupilot_utc_offset(gps: Mapping[str, np.ndarray]) -> float | None:
    week = gps.get("GWk", gps.get("Week"))
    ms = gps.get("GMS", gps.get("TimeMS") if "TimeUS" not in gps else None)
    if week is None or ms is None:
        return None
    ok = (gps["Status"] >= 3) & (week > 0)
    if not ok.any():
        return None
    boot = _ardupilot_boot_time("GPS", gps)
    return float(np.median(gps_to_unix(week[ok], ms[ok]) - boot[ok]))


def _ardupilot_batteries(src: str, table: Callable[[str], dict[str, np.ndarray] | None],
                         fmts: Mapping[str, tuple[str, list[str]]]) -> list[tuple[np.ndarray, np.ndarray]]:
    out = []
    bat = table("BAT")
    if bat is not None:
        t = _ardupilot_boot_time("BAT", bat)
        inst = bat.get("Instance", np.zeros(len(t)))
        for i in np.unique(inst):
            m = inst == i
            v, c = _scaled(fmts["BAT"], "Volt", bat), _scaled(fmts["BAT"], "Curr", bat)
            out.append((t[m], v[m] * c[m]))
        return out
    for name in ("CURR", "CUR2"):
        cur = table(name)
        if cur is None:
            continue
        if "Volt" not in cur or "Curr" not in cur:
            raise MissingColumnError(f"{src}: message '{name}' lacks field 'Volt' or 'Curr'", field=name)
        t = _ardupilot_boot_time(name, cur)
        out.append((t, _scaled(fmts[name], "Volt", cur) * _scaled(fmts[name], "Curr", cur)))
    if not out:
        raise MissingColumnError(f"{src}: message 'BAT' or 'CURR' missing (no electric power)", field="BAT")
    return out


def _scaled(fmt: tuple[str, list[str]], field: str, tab: Mapping[str, np.ndarray]) -> np.ndarray:
    """Field in SI units: integer-typed voltage/current fields hold hundredths (old CURR)."""
    fchars, cols = fmt
    ch = fchars[cols.index(field)]
    v = tab[field]
    return v / 100.0 if ch in _INTEGER_FORMATS else v


# --------------------------------------------------------------------- shared kernels
def _time_base(src: str, tb: np.ndarray, spans: Sequence[tuple[float, float]], rate_hz: float | None) -> np.ndarray:
    t0 = max(s[0] for s in spans)
    t1 = min(s[1] for s in spans)
    if not t1 > t0:
        raise TrajectoryError(f"{src}: position, attitude and power are never logged at the same time",
                              field="t")
    if rate_hz is not None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"rate_hz must be positive, got {rate_hz!r}", field="rate_hz")
        return t0 + np.arange(int(np.floor((t1 - t0) * rate_hz)) + 1) / rate_hz
    t = tb[(tb >= t0) & (tb <= t1)]
    if len(t) < 2:
        raise TrajectoryError(f"{src}: fewer than 2 position samples while attitude and power are logged",
                              field="t")
    return t


def _interp_quaternion(t: np.ndarray, tq: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Normalised linear interpolation of quaternions with sign continuity."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    s = np.ones(len(q))
    flips = np.sum(q[1:] * q[:-1], axis=1) < 0
    s[1:] = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    q = q * s[:, None]
    out = np.stack([np.interp(t, tq, q[:, i]) for i in range(4)], axis=-1)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def _interp_deg(t: np.ndarray, ts: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """Angles (deg) interpolated on the circle, wrapped into (-180, 180]."""
    r = np.radians(deg)
    return np.degrees(wrap_angle(np.arctan2(np.interp(t, ts, np.sin(r)), np.interp(t, ts, np.cos(r)))))


def _covering(t: np.ndarray, ts: np.ndarray, v: Any, name: str) -> np.ndarray | None:
    v = np.asarray(v, dtype=float)
    ok = np.isfinite(v)
    ts, v = ts[ok], v[ok]
    if len(ts) < 2 or ts[0] > t[0] or ts[-1] < t[-1]:
        log.info("optional %s left out: it does not cover the flight's time span", name)
        return None
    return np.interp(t, ts, v)


def _moving_average(t: np.ndarray, v: np.ndarray, width: float) -> np.ndarray:
    if len(t) < 2 or width <= 0:
        return v
    c = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(v, axis=0)])
    lo = np.searchsorted(t, t - width / 2, side="left")
    hi = np.searchsorted(t, t + width / 2, side="right")
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def _phase(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray, vtol: np.ndarray | None) -> np.ndarray:
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0]))
    enu = np.stack(frame.to_enu(lat, lon, h), axis=-1)
    vel = np.gradient(enu, t, axis=0)
    phase = phase_by_speed(t, vel)
    if vtol is not None:
        phase = np.where(vtol == "fw", "horizontal", np.where(vtol == "transition", "transition", phase))
    return phase


def _finish(src: str, t: np.ndarray, cols: dict[str, Any], start_utc: Any, utc_offset: float | None,
            utc_field: str) -> Trajectory:
    if start_utc is not None:
        if utc_offset is None:
            raise MissingColumnError(f"{src}: no GPS time in the log ('{utc_field}'), cannot align with start_utc",
                                     field=utc_field)
        t_rel = t + utc_offset - as_unix_time(start_utc)
    else:
        t_rel = t - t[0]
    return Trajectory(t=t_rel, source=src, **cols)
