"""PX4 ULog flight logs (through pyulog) as trajectories.

Position from ``vehicle_global_position`` when logged (the estimator's), else from
``vehicle_gps_position`` / ``sensor_gps`` (3D fixes only) with the height from the
estimator where it is logged (:func:`estimator_height`); attitude from the
``vehicle_attitude`` quaternion (Hamilton, body FRD -> NED) as Z-Y-X Euler angles;
electric power as the sum over ``battery_status`` instances of voltage x current (the mean
current over each log interval from the coulomb count ``discharged_mah`` where it is
logged, see :func:`battery_power`);
optional ``rpm`` (``rpm`` or ``esc_status``) and airspeed (``airspeed_validated`` or
``airspeed``).  Heights are ellipsoidal (``alt_ellipsoid``) where logged.  The GPS
clock is ``time_utc_usec``.  A VTOL's state (``vtol_vehicle_status``, else
``vehicle_status``) gives ``horizontal`` in fixed-wing mode and ``transition`` while
transitioning; multicopter flight follows :func:`~gisnoise.flight.phases.phase_by_speed`.
See :mod:`gisnoise.flight.logs` for the time base.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError, MissingColumnError, TrajectoryError
from gisnoise.flight._logkernels import (
    POWER_WAY_OUT,
    _at_rest_low,
    _covering,
    _finish,
    _phase,
    _power,
    _time_base,
    estimator_height_datum,
    msl_height_datum,
    msl_to_ellipsoid_undulation,
)
from gisnoise.flight.gaps import gap_metadata
from gisnoise.flight.glitches import mend_glitches
from gisnoise.flight.logcut import framing, read_cut, refuse_cut_definitions, ulog_cut
from gisnoise.flight.logdamage import record_damage, ulog_damage
from gisnoise.flight.logspan import left_out
from gisnoise.flight.parserout import captured_stdout
from gisnoise.flight.trajectory import Trajectory
from gisnoise.geo import wrap_deg

__all__ = ["read_ulog", "quaternion_to_euler", "battery_power", "estimator_height"]

_ULOG_TOPICS = ("vehicle_global_position", "vehicle_gps_position", "sensor_gps", "vehicle_attitude",
                "battery_status", "vtol_vehicle_status", "vehicle_status", "airspeed_validated", "airspeed",
                "rpm", "esc_status", "vehicle_land_detected", "vehicle_local_position")


def read_ulog(path: str | os.PathLike[str], *, start_utc: Any = None, geoid_undulation_m: float | None = None,
              rate_hz: float | None = None, power_w: float | None = None) -> Trajectory:
    """Read a PX4 ULog as a trajectory (see the module docstring for the topics used).

    Parameters
    ----------
    path : path-like
        ``.ulg`` file.
    start_utc : datetime, str or float, optional
        Instant of ``t = 0``; needs GPS UTC time in the log.
    geoid_undulation_m : float, optional
        Geoid undulation, m, for logs with heights above mean sea level only; given, it
        overrides the geoid model.  Ellipsoidal heights are taken as logged; MSL heights get
        this N, else the GNSS receiver's (its ellipsoidal minus MSL height), else the geoid
        grid's (:mod:`gisnoise.geo.geoid`).
    rate_hz : float, optional
        Uniform resampling rate, Hz.
    power_w : float, optional
        A constant electric power, W, in place of the logged battery power (for logs
        without battery current).

    Samples where ``vehicle_land_detected.landed`` is set are marked ``on_ground``; without
    that topic, samples at rest near the track's lowest point.
    """
    try:
        from pyulog import ULog
    except ImportError:  # pragma: no cover - optional extra
        raise InputError("reading PX4 ULog needs pyulog (pip install 'gisnoise[logs]')", field="path") from None
    src = str(path)
    try:
        data = Path(src).read_bytes()
    except FileNotFoundError:
        raise TrajectoryError(f"{src}: no such file", field="path") from None
    file_bytes = len(data)
    # pyulog reads through damage with garbage, or drops the rest as if cut; it reads a cut file up to its last
    # whole message without a word
    data, damage, cut = framing(data, ulog_damage, ulog_cut)
    refuse_cut_definitions(src, cut, "formats, info, parameters")
    try:
        with captured_stdout() as said:  # pyulog prints what it finds corrupt: never on the user's stdout
            ulog = ULog(io.BytesIO(data), list(_ULOG_TOPICS))
    except Exception as exc:  # pyulog raises bare exceptions on corrupt files
        raise TrajectoryError(f"{src}: not a readable ULog ({exc})", field="path") from None
    traj: Trajectory = read_cut(src, cut, lambda: _ulog_trajectory(src, ulog, start_utc, geoid_undulation_m, rate_hz, power_w))
    parser_said = said.getvalue().strip().splitlines()[:1] or (["pyulog found the file corrupt"]
                                                                if ulog.file_corruption else [])
    record_damage(traj, damage, file_bytes, parser_said[0] if parser_said else None)
    return traj


def _ulog_trajectory(src: str, ulog: Any, start_utc: Any, geoid_undulation_m: float | None, rate_hz: float | None,
                     power_w: float | None) -> Trajectory:
    """The trajectory of a parsed ULog (see :func:`read_ulog`)."""
    topics: dict[str, list[dict[str, np.ndarray]]] = {}
    for d in ulog.data_list:
        topics.setdefault(d.name, []).append(d.data)

    def first(*names: str) -> tuple[str, dict[str, np.ndarray]] | None:
        for n in names:
            if n in topics:
                return n, topics[n][0]
        return None

    # position
    geoid_meta: dict[str, Any] = {}
    height_meta: dict[str, Any] = {}
    h_series: tuple[np.ndarray, np.ndarray] | None = None   # (times, heights) when not at the position samples
    gps = first("vehicle_gps_position", "sensor_gps")
    gps_cols = _px4_gps_columns(*gps) if gps else None
    glob = first("vehicle_global_position")
    if glob is not None:
        g = glob[1]
        tb = g["timestamp"] / 1e6
        lat, lon = g["lat"].astype(float), g["lon"].astype(float)
        if "alt_ellipsoid" in g:
            h = g["alt_ellipsoid"].astype(float)
            datum = "ellipsoid (vehicle_global_position.alt_ellipsoid)"
        else:
            n_und, geoid_meta = _undulation(src, gps_cols, geoid_undulation_m, lat, lon,
                                            "vehicle_global_position.alt")
            datum = msl_height_datum("vehicle_global_position.alt", geoid_meta)
            h = g["alt"].astype(float) + n_und
        pos_name = "vehicle_global_position"
    elif gps_cols is not None:
        tb, lat, lon, h_ell, h_msl = (gps_cols[k] for k in ("t", "lat", "lon", "h_ell", "h_msl"))
        pos_name = gps[0]  # type: ignore[index]
        if h_ell is not None:
            h, datum = h_ell, f"ellipsoid ({pos_name}.alt_ellipsoid)"
        elif h_msl is None:
            raise MissingColumnError(f"{src}: topic '{pos_name}' has no altitude", field=f"{pos_name}.alt")
        else:
            n_und, geoid_meta = _undulation(src, None, geoid_undulation_m, lat, lon, f"{pos_name}.alt")
            h = h_msl + n_und
            datum = msl_height_datum(f"{pos_name}.alt", geoid_meta)
        lp = topics["vehicle_local_position"][0] if "vehicle_local_position" in topics else None
        est = estimator_height(lp, tb, h)
        if isinstance(est, str):
            height_meta["height_note"] = f"raw GPS heights ({pos_name}): {est}"
        else:
            h_series, height_meta = (est[0], est[1]), est[2]
            datum = estimator_height_datum("vehicle_local_position.z", datum)
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
    batteries = []
    battery_names: list[str] = []
    if power_w is None:
        if "battery_status" not in topics:
            raise MissingColumnError(f"{src}: topic 'battery_status' missing (no electric power); {POWER_WAY_OUT}",
                                     field="battery_status")
        for i, b in enumerate(topics["battery_status"]):
            if "connected" in b and not np.any(b["connected"]):
                continue
            if "current_a" not in b or "voltage_v" not in b:
                continue
            batteries.append(battery_power(b))
            battery_names.append("battery_status" if len(topics["battery_status"]) == 1 else f"battery_status[{i}]")
        if not batteries:
            raise MissingColumnError(f"{src}: topic 'battery_status' has no connected battery with voltage and "
                                     f"current; {POWER_WAY_OUT}", field="battery_status")

    spans = {pos_name if glob is not None else f"{pos_name} 3D fix": (tb[0], tb[-1]),
             "vehicle_attitude": (t_att[0], t_att[-1])}
    spans.update({n: (tt[0], tt[-1]) for n, (tt, _) in zip(battery_names, batteries, strict=True)})
    if h_series is not None:
        spans["vehicle_local_position"] = (h_series[0][0], h_series[0][-1])
    t = _time_base(src, tb, list(spans.values()), rate_hz)
    lat_i, lon_i, h_i = (np.interp(t, tb, v) for v in (lat, lon, h))
    if h_series is not None:
        h_i = np.interp(t, *h_series)
    glitches = mend_glitches(t, lat_i, lon_i, h_i)  # before the phase and the ground are derived
    lat_i, lon_i, h_i = glitches.lat, glitches.lon, glitches.h
    roll, pitch, yaw = quaternion_to_euler(_interp_quaternion(t, t_att, q))
    power = _power(t, batteries, power_w)

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
    flag = None
    if "vehicle_land_detected" in topics and "landed" in topics["vehicle_land_detected"][0]:
        ld = topics["vehicle_land_detected"][0]
        flag = (ld["timestamp"] / 1e6, ~ld["landed"].astype(bool))
        cols["on_ground"] = _step(t, ld["timestamp"] / 1e6, ld["landed"].astype(bool)).astype(bool)
    else:
        cols["on_ground"] = _at_rest_low(t, lat_i, lon_i, h_i)

    utc_offset = None
    if gps_cols is not None and gps_cols["utc_offset"] is not None:
        utc_offset = gps_cols["utc_offset"]
    meta = {"height_datum": datum, **height_meta, **geoid_meta, "power": "battery_status" if power_w is None else f"constant {power_w:g} W"}
    traj = _finish(src, t, cols, start_utc, utc_offset, "vehicle_gps_position.time_utc_usec", meta)
    traj.metadata.update({**glitches.metadata(traj.t), **gap_metadata(traj.t)})
    stretches = left_out((t[0], t[-1]), spans, step_s=float(np.median(np.diff(tb))), power=batteries, flag=flag,
                         log_start=ulog.start_timestamp / 1e6, offset_s=float(traj.t[0] - t[0]))
    if stretches:
        traj.metadata["log_left_out"] = stretches
    return traj


def estimator_height(lp: Mapping[str, np.ndarray] | None, t_gps: np.ndarray,
                     h_gps: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict[str, Any]] | str:
    """Heights from the estimator's ``vehicle_local_position.z`` levelled on the GPS heights: (times s, heights m,
    metadata), or the reason (a sentence) why the GPS heights stay.

    The estimator (EKF2) fuses barometer, GPS, accelerometers and range finders into ``z`` (NED, m, about a local
    origin); a GNSS receiver's height wanders by metres over seconds near the ground, while the estimator's course
    holds to decimetres.  The height is ``-z + offset`` with ``offset`` the median over the GPS fixes inside the
    estimator's span of ``h_gps - (-z)``; the metadata states it (``height_anchor_m``), how far the GPS heights
    wander from the estimator's (``height_anchor_range_m``, GPS minus estimator height less ``offset``) and how many
    height resets were undone (``height_resets``).

    Samples count where ``z`` is finite and ``z_valid`` (when logged) is set; the estimator's span is its first to
    its last valid sample, and an invalid one inside it keeps the GPS heights (a gap says the estimator lost its
    height).  A reset (``z_reset_counter`` steps) shifts ``z`` by ``delta_z`` at once: it is undone, so the course
    stays continuous.  When the counter steps by more than one between two logged samples, ``delta_z`` holds the
    last reset only; the shift is then the step of ``z`` less the motion the vertical velocity ``vz`` gives
    (trapezoid rule).  Fewer than 3 GPS fixes inside the span keep the GPS heights.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(5.0)                      # a reset at t = 3 s shifts z by -2 m; the vehicle stands still
    >>> lp = {"timestamp": t * 1e6, "z": np.array([-1.0, -1.0, -1.0, -3.0, -3.0]), "z_valid": np.ones(5),
    ...       "z_reset_counter": np.array([7, 7, 7, 8, 8]), "delta_z": np.array([0.0, 0, 0, -2, -2])}
    >>> th, h, meta = estimator_height(lp, t, np.array([100.0, 101.0, 102.0, 101.0, 100.0]))
    >>> [float(v) for v in h], meta["height_anchor_m"], meta["height_resets"]
    ([101.0, 101.0, 101.0, 101.0, 101.0], 100.0, 1)
    """
    if lp is None:
        return "vehicle_local_position is not logged"
    if "z" not in lp:
        return "vehicle_local_position has no z"
    t = lp["timestamp"].astype(float) / 1e6
    z = lp["z"].astype(float)
    ok = np.isfinite(z) & (lp["z_valid"].astype(bool) if "z_valid" in lp else True)
    if not ok.any():
        return "vehicle_local_position.z is never valid"
    i0, i1 = int(np.argmax(ok)), len(ok) - 1 - int(np.argmax(ok[::-1]))
    if not ok[i0:i1 + 1].all():
        bad = int(np.sum(~ok[i0:i1 + 1]))
        return f"vehicle_local_position.z is not valid at {bad} of its {i1 + 1 - i0} samples between valid ones"
    t, z = t[i0:i1 + 1], z[i0:i1 + 1]
    if len(t) < 2 or np.any(np.diff(t) <= 0):
        return "vehicle_local_position has fewer than 2 valid samples in time order"
    resets = 0
    if "z_reset_counter" in lp:
        steps = np.mod(np.diff(lp["z_reset_counter"][i0:i1 + 1].astype(np.int64)), 256)
        resets = int(steps.sum())
        shift = np.zeros(len(steps))
        one = (steps == 1) & ("delta_z" in lp)
        if one.any():
            shift[one] = lp["delta_z"][i0 + 1:i1 + 1].astype(float)[one]
        many = (steps > 0) & ~one
        if many.any():
            vz = lp["vz"][i0:i1 + 1].astype(float) if "vz" in lp else np.zeros(len(t))
            motion = np.nan_to_num(0.5 * (vz[1:] + vz[:-1]) * np.diff(t))
            shift[many] = (np.diff(z) - motion)[many]
        z = z - np.concatenate([[0.0], np.cumsum(shift)])
    inside = (t_gps >= t[0]) & (t_gps <= t[-1]) & np.isfinite(h_gps)
    if inside.sum() < 3:
        return f"only {int(inside.sum())} GPS fixes lie inside the span of vehicle_local_position (3 needed)"
    gap = h_gps[inside] + np.interp(t_gps[inside], t, z)      # GPS height minus the estimator's (-z)
    offset = float(np.median(gap))
    meta = {"height_anchor_m": offset,
            "height_anchor_range_m": [float(np.min(gap)) - offset, float(np.max(gap)) - offset],
            "height_resets": resets}
    return t, offset - z, meta


def battery_power(b: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Electric power (W) of one ``battery_status`` instance: (times s, power W).

    PX4 logs ``current_a`` as one instantaneous reading per logged sample (5 Hz by default),
    which aliases the ripple of the motor currents: real logs show 0 A on samples between
    12 A readings while the battery's coulomb count grows.  The battery driver integrates
    every reading into ``discharged_mah``, so where that count is logged, finite and never
    decreasing (no reset) and grows, the current is its mean over each log interval,
    ``I = 3.6 dQ[mAh] / dt[s]``, placed at the interval's middle (the first and last
    intervals' means also at the log's first and last sample, so the span stays the log's);
    else ``current_a``.  The power is ``voltage_v`` x that current.

    Examples
    --------
    >>> import numpy as np
    >>> b = {"timestamp": np.array([0, 1e6, 2e6]), "voltage_v": np.array([16.0, 16.0, 16.0]),
    ...      "current_a": np.array([0.0, 0.0, 0.0]), "discharged_mah": np.array([0.0, 5.0, 5.0])}
    >>> t, p = battery_power(b)         # 5 mAh in the first second: 18 A, then nothing
    >>> [float(v) for v in t], [round(float(v), 6) for v in p]
    ([0.0, 0.5, 1.5, 2.0], [288.0, 288.0, 0.0, 0.0])
    """
    t = b["timestamp"] / 1e6
    v = b["voltage_v"].astype(float)
    q = b["discharged_mah"].astype(float) if "discharged_mah" in b else None
    if q is not None and len(q) >= 2 and np.all(np.isfinite(q)) and np.all(np.diff(t) > 0) \
            and np.all(np.diff(q) >= 0) and q[-1] > q[0]:
        c = 3.6 * np.diff(q) / np.diff(t)
        tm = np.concatenate([t[:1], 0.5 * (t[1:] + t[:-1]), t[-1:]])   # the log's span, means at the middles
        current = np.concatenate([c[:1], c, c[-1:]])
        return tm, np.interp(tm, t, v) * current
    return t, v * b["current_a"].astype(float)


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


def _undulation(src: str, gps_cols: Mapping[str, Any] | None, given: float | None, lat: np.ndarray,
                lon: np.ndarray, what: str) -> tuple[np.ndarray | float, dict[str, Any]]:
    """N (m) for heights above mean sea level: given, else the GNSS receiver's own (ellipsoidal minus MSL
    height it logs), else the geoid grid (:func:`~gisnoise.flight._logkernels.msl_to_ellipsoid_undulation`)."""
    if given is None and gps_cols is not None and gps_cols["h_ell"] is not None and gps_cols["h_msl"] is not None \
            and len(gps_cols["h_ell"]):
        n = float(np.median(gps_cols["h_ell"] - gps_cols["h_msl"]))
        return n, {"geoid_model": "the GNSS receiver's (alt_ellipsoid - alt)", "geoid_undulation_m": n}
    return msl_to_ellipsoid_undulation(lat, lon, given, f"{src}: '{what}' gives heights above mean sea level only")


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


def _interp_quaternion(t: np.ndarray, tq: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Normalised linear interpolation of quaternions with sign continuity."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    s = np.ones(len(q))
    flips = np.sum(q[1:] * q[:-1], axis=1) < 0
    s[1:] = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    q = q * s[:, None]
    out = np.stack([np.interp(t, tq, q[:, i]) for i in range(4)], axis=-1)
    return out / np.linalg.norm(out, axis=1, keepdims=True)
