"""ArduPilot DataFlash flight logs (``.bin``, through pymavlink) as trajectories.

Position from ``POS`` when logged, else ``GPS`` (3D fixes only); attitude from
``ATT``; power from ``BAT`` (one battery per ``Instance``) or ``CURR`` (+ ``CUR2``).
Old logs store ``CURR`` voltage and current as integer hundredths of a volt and
ampere; they are recognised by the integer format character of the field and
scaled, newer float fields are taken as V and A.  The GPS clock is the GPS week and
milliseconds minus the leap seconds.  ArduPilot logs heights above mean sea level
only (converted with the geoid model, :mod:`gisnoise.geo.geoid`), and no VTOL state: the phase follows
:func:`~gisnoise.flight.phases.phase_by_speed`.  See :mod:`gisnoise.flight.logs` for
the time base.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Mapping
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
    msl_height_datum,
    msl_to_ellipsoid_undulation,
)
from gisnoise.flight.clock import gps_to_unix
from gisnoise.flight.gaps import gap_metadata
from gisnoise.flight.glitches import mend_glitches
from gisnoise.flight.logcut import dataflash_cut, framing, read_cut, refuse_cut_definitions
from gisnoise.flight.logdamage import dataflash_damage, record_damage
from gisnoise.flight.logspan import left_out
from gisnoise.flight.parserout import captured_stdout
from gisnoise.flight.trajectory import Trajectory
from gisnoise.geo import wrap_angle

__all__ = ["read_dataflash"]

_INTEGER_FORMATS = set("bBhHiIqQ")


def read_dataflash(path: str | os.PathLike[str], *, start_utc: Any = None, geoid_undulation_m: float | None = None,
                   rate_hz: float | None = None, power_w: float | None = None) -> Trajectory:
    """Read an ArduPilot DataFlash ``.bin`` log as a trajectory (see the module docstring).

    ArduPilot logs heights above mean sea level only: they become ellipsoidal heights with
    the undulation of the geoid grid :mod:`gisnoise.geo.geoid` finds at each sample, or with
    ``geoid_undulation_m`` (ellipsoidal minus orthometric height at the site, m) when given.  ``power_w``
    (W) replaces the logged battery power by a constant (for logs without current).
    Samples before arming, after disarming or landing (``EV`` events ARMED 10,
    DISARMED 11, LAND_COMPLETE 18, NOT_LANDED 28, timed by the message before them in
    old logs) are marked ``on_ground``; a log without these events marks samples at rest
    (below 0.3 m/s) within 1 m of the track's lowest point.
    """
    try:
        from pymavlink import DFReader
    except ImportError:  # pragma: no cover - optional extra
        raise InputError("reading ArduPilot logs needs pymavlink (pip install 'gisnoise[logs]')",
                         field="path") from None
    src = str(path)
    if not Path(src).is_file():
        raise TrajectoryError(f"{src}: no such file", field="path")
    data = Path(src).read_bytes()
    if b"\xa3\x95" not in data:   # pymavlink's indexer would print a line per byte (from C: not capturable)
        raise TrajectoryError(f"{src}: not a DataFlash log (no message header, bytes A3 95, in its {len(data)} bytes)",
                              field="path")
    # pymavlink skips damaged bytes without a flag, reading garbage first, and stops at a cut message without a word
    clean, damage, cut = framing(data, dataflash_damage, dataflash_cut)
    refuse_cut_definitions(src, cut, "FMT messages")
    with contextlib.ExitStack() as stack:
        path_read = src
        if damage is not None:    # pymavlink reads a file: the bytes without the damage, in a temporary one
            tmp = stack.enter_context(tempfile.TemporaryDirectory())
            path_read = os.path.join(tmp, "log.bin")
            Path(path_read).write_bytes(clean)
        stack.enter_context(captured_stdout())   # pymavlink prints on corrupt data: never on the user's stdout
        try:
            reader = DFReader.DFReader_binary(path_read, zero_time_base=True)
        except Exception as exc:
            raise TrajectoryError(f"{src}: not a readable DataFlash log ({exc})", field="path") from None
        traj: Trajectory = read_cut(src, cut, lambda: _dataflash_trajectory(src, reader, start_utc, geoid_undulation_m,
                                                                             rate_hz, power_w))
    record_damage(traj, damage, len(data), None)
    return traj


def _dataflash_trajectory(src: str, reader: Any, start_utc: Any, geoid_undulation_m: float | None,
                          rate_hz: float | None, power_w: float | None) -> Trajectory:
    """The trajectory of an opened DataFlash log (see :func:`read_dataflash`); closes the reader."""
    wanted = ["GPS", "POS", "ATT", "BAT", "CURR", "CUR2", "RPM", "ARSP", "EV"]
    rows: dict[str, list[tuple[Any, ...]]] = {k: [] for k in wanted}
    fmts: dict[str, tuple[str, list[str]]] = {}
    events: list[tuple[float, int]] = []   # (boot time s, event id); old EV messages carry no time
    last_t = 0.0
    try:
        while True:
            try:
                m = reader.recv_match(type=wanted)
            except Exception as exc:
                raise TrajectoryError(f"{src}: corrupt DataFlash log ({exc})", field="path") from None
            if m is None:
                break
            name = m.get_type()
            cols_m = m.fmt.columns
            if name == "EV":
                events.append((m.TimeUS / 1e6 if "TimeUS" in cols_m else last_t, int(m.Id)))
                continue
            if "TimeUS" in cols_m:
                last_t = m.TimeUS / 1e6
            elif name != "GPS" and "TimeMS" in cols_m:
                last_t = m.TimeMS / 1e3
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
    n_und, geoid_meta = msl_to_ellipsoid_undulation(lat, lon, geoid_undulation_m,
                                                    f"{src}: message '{pos_name}' gives heights above mean sea level "
                                                    "only")
    h = h_msl + n_und

    att = table("ATT")
    if att is None:
        raise MissingColumnError(f"{src}: message 'ATT' missing (no attitude)", field="ATT")
    t_att = _ardupilot_boot_time("ATT", att)

    named = _ardupilot_batteries(src, table, fmts) if power_w is None else []
    batteries = [(tt, pw) for _, tt, pw in named]
    spans = {"GPS 3D fix" if pos_name == "GPS" else pos_name: (tb[0], tb[-1]), "ATT": (t_att[0], t_att[-1])}
    spans.update({n: (tt[0], tt[-1]) for n, tt, _ in named})
    t = _time_base(src, tb, list(spans.values()), rate_hz)
    lat_i, lon_i, h_i = (np.interp(t, tb, v) for v in (lat, lon, h))
    glitches = mend_glitches(t, lat_i, lon_i, h_i)  # before the phase and the ground are derived
    lat_i, lon_i, h_i = glitches.lat, glitches.lon, glitches.h
    roll, pitch, yaw = (_interp_deg(t, t_att, att[k]) for k in ("Roll", "Pitch", "Yaw"))
    power = _power(t, batteries, power_w)
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
    landed = _landed_from_events(t, events)
    cols["on_ground"] = landed if landed is not None else _at_rest_low(t, lat_i, lon_i, h_i)
    meta = {"height_datum": msl_height_datum(f"{pos_name}.Alt", geoid_meta),
            **geoid_meta,
            "power": "BAT/CURR" if power_w is None else f"constant {power_w:g} W"}
    traj = _finish(src, t, cols, start_utc, utc_offset, "GPS.Week", meta)
    traj.metadata.update({**glitches.metadata(traj.t), **gap_metadata(traj.t)})
    stretches = left_out((t[0], t[-1]), spans, step_s=float(np.median(np.diff(tb))), power=batteries,
                         flag=_airborne_steps(events), offset_s=float(traj.t[0] - t[0]))
    if stretches:
        traj.metadata["log_left_out"] = stretches
    return traj


_EV_ARMED, _EV_DISARMED, _EV_LAND_COMPLETE, _EV_NOT_LANDED = 10, 11, 18, 28


def _landed_from_events(t: np.ndarray, events: list[tuple[float, int]]) -> np.ndarray | None:
    """On the ground (bool per ``t``) from ArduPilot's arming and landing events, or None without them."""
    ev = [(te, i) for te, i in events if i in (_EV_ARMED, _EV_DISARMED, _EV_LAND_COMPLETE, _EV_NOT_LANDED)]
    if not ev:
        return None
    out = np.ones(len(t), dtype=bool)   # a vehicle starts disarmed and landed
    armed, landed = False, True
    t_prev = -np.inf
    for te, i in sorted(ev) + [(np.inf, -1)]:
        seg = (t >= t_prev) & (t < te)
        out[seg] = not (armed and not landed)
        if i == _EV_ARMED:
            armed = True
        elif i == _EV_DISARMED:
            armed, landed = False, True
        elif i == _EV_LAND_COMPLETE:
            landed = True
        elif i == _EV_NOT_LANDED:
            landed = False
        t_prev = te
    return out


def _airborne_steps(events: list[tuple[float, int]]) -> tuple[np.ndarray, np.ndarray] | None:
    """In the air as a step series (times s, bool) from ArduPilot's arming and landing events, or None without
    them (:func:`_landed_from_events`)."""
    te = np.array(sorted({t for t, i in events if i in (_EV_ARMED, _EV_DISARMED, _EV_LAND_COMPLETE, _EV_NOT_LANDED)}))
    if te.size == 0:
        return None
    te = np.concatenate([[-np.inf], te])
    landed = _landed_from_events(te, events)
    return None if landed is None else (te, ~landed)


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
                         fmts: Mapping[str, tuple[str, list[str]]]) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Per battery: (message name, times s, power W)."""
    out = []
    bat = table("BAT")
    if bat is not None:
        t = _ardupilot_boot_time("BAT", bat)
        inst = bat.get("Instance", np.zeros(len(t)))
        for i in np.unique(inst):
            m = inst == i
            v, c = _scaled(fmts["BAT"], "Volt", bat), _scaled(fmts["BAT"], "Curr", bat)
            out.append(("BAT" if len(np.unique(inst)) == 1 else f"BAT[{int(i)}]", t[m], v[m] * c[m]))
        return out
    for name in ("CURR", "CUR2"):
        cur = table(name)
        if cur is None:
            continue
        if "Volt" not in cur or "Curr" not in cur:
            raise MissingColumnError(f"{src}: message '{name}' lacks field 'Volt' or 'Curr'", field=name)
        t = _ardupilot_boot_time(name, cur)
        out.append((name, t, _scaled(fmts[name], "Volt", cur) * _scaled(fmts[name], "Curr", cur)))
    if not out:
        raise MissingColumnError(f"{src}: message 'BAT' or 'CURR' missing (no electric power); {POWER_WAY_OUT}",
                                 field="BAT")
    return out


def _scaled(fmt: tuple[str, list[str]], field: str, tab: Mapping[str, np.ndarray]) -> np.ndarray:
    """Field in SI units: integer-typed voltage/current fields hold hundredths (old CURR)."""
    fchars, cols = fmt
    ch = fchars[cols.index(field)]
    v = tab[field]
    return v / 100.0 if ch in _INTEGER_FORMATS else v


def _interp_deg(t: np.ndarray, ts: np.ndarray, deg: np.ndarray) -> np.ndarray:
    """Angles (deg) interpolated on the circle, wrapped into (-180, 180]."""
    r = np.radians(deg)
    return np.degrees(wrap_angle(np.arctan2(np.interp(t, ts, np.sin(r)), np.interp(t, ts, np.cos(r)))))
