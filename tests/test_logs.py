"""Flight logs: real PX4 and ArduPilot logs against pyulog / pymavlink read directly,
and small synthetic DataFlash logs whose truth is known."""

from __future__ import annotations

import struct
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pytest

from gisnoise.errors import InputError, MissingColumnError
from gisnoise.flight import gps_to_unix, phase_by_speed, quaternion_to_euler, read_flight
from gisnoise.flight import ulog as logs

pyulog = pytest.importorskip("pyulog")
pytest.importorskip("pymavlink")

DATA = Path(__file__).parent / "data"
ULG = DATA / "pyulog_sample_log_small_vtol.ulg"
BIN = DATA / "dronekit_la_testdata_log171_copter.bin"


def _circ_diff(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


# ----------------------------------------------------------------------------- PX4
@pytest.fixture(scope="module")
def ulog_raw():
    u = pyulog.ULog(str(ULG))
    return {(d.name, d.multi_id): d.data for d in u.data_list}


def test_ulog_positions_attitude_power_equal_pyulog(ulog_raw):
    from scipy.spatial.transform import Rotation, Slerp

    start = datetime(2021, 4, 21, 6, 30, 58, tzinfo=timezone.utc)
    tr = read_flight(ULG, start_utc=start)
    gps = ulog_raw[("vehicle_gps_position", 0)]
    fix = gps["fix_type"] >= 3
    t_boot = gps["timestamp"][fix] / 1e6
    # the time base is the GPS fixes inside the span of attitude and both batteries
    att = ulog_raw[("vehicle_attitude", 0)]
    b0, b1 = ulog_raw[("battery_status", 0)], ulog_raw[("battery_status", 1)]
    lo = max(t_boot[0], att["timestamp"][0] / 1e6, b0["timestamp"][0] / 1e6, b1["timestamp"][0] / 1e6)
    hi = min(t_boot[-1], att["timestamp"][-1] / 1e6, b0["timestamp"][-1] / 1e6, b1["timestamp"][-1] / 1e6)
    keep = (t_boot >= lo) & (t_boot <= hi)
    assert len(tr) == keep.sum() >= 25
    tb = t_boot[keep]
    # positions: 1e-7 deg integers; the height: the estimator's -vehicle_local_position.z (valid throughout, no
    # reset) plus its median offset to the ellipsoidal GPS height (mm) over the fixes inside its span
    np.testing.assert_allclose(tr.lat, gps["lat"][fix][keep] / 1e7, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.lon, gps["lon"][fix][keep] / 1e7, rtol=0, atol=1e-12)
    lp = ulog_raw[("vehicle_local_position", 0)]
    t_lp, up = lp["timestamp"] / 1e6, -lp["z"].astype(float)
    assert lp["z_valid"].all() and not np.any(np.diff(lp["z_reset_counter"]))
    inside = (t_boot >= t_lp[0]) & (t_boot <= t_lp[-1])
    offset = np.median(gps["alt_ellipsoid"][fix][inside] / 1e3 - np.interp(t_boot[inside], t_lp, up))
    np.testing.assert_allclose(tr.h, np.interp(tb, t_lp, up) + offset, rtol=0, atol=1e-9)
    # times: UTC of each fix, from the GPS clock (jitter of the publication stamps < 30 ms)
    utc = gps["time_utc_usec"][fix][keep] / 1e6
    np.testing.assert_allclose(tr.t + start.timestamp(), utc, rtol=0, atol=0.03)
    # attitude: scipy's slerp of the raw quaternions (scipy order x, y, z, w), Z-Y-X Euler
    q = np.stack([att[f"q[{i}]"] for i in (1, 2, 3, 0)], axis=-1)
    slerp = Slerp(att["timestamp"] / 1e6, Rotation.from_quat(q))
    yaw, pitch, roll = slerp(tb).as_euler("ZYX", degrees=True).T
    assert _circ_diff(tr.roll, roll).max() < 0.01
    assert _circ_diff(tr.pitch, pitch).max() < 0.01
    assert _circ_diff(tr.yaw, yaw).max() < 0.01
    # power: sum over the two batteries of V * I, I the mean current of each log interval from the coulomb count
    p = sum(np.interp(tb, *_coulomb_power(b)) for b in (b0, b1))
    np.testing.assert_allclose(tr.power_w, p, rtol=1e-12)
    # multicopter-mode hop (vtol_in_rw_mode = 1): never wing-borne, never in transition
    assert set(np.unique(tr.phase)) <= {"hover", "climb", "sink"}
    # airspeed from the 'airspeed' topic (airspeed_validated does not cover the span)
    a = ulog_raw[("airspeed", 0)]
    np.testing.assert_allclose(tr.airspeed_m_s, np.interp(tb, a["timestamp"] / 1e6, a["true_airspeed_m_s"]))


def _coulomb_power(b):
    """(t s, W) of one battery_status instance read with pyulog: V x 3.6 dQ/dt at the middle of each interval
    (the first and last means held to the log's ends), dQ in mAh."""
    t = b["timestamp"] / 1e6
    c = 3.6 * np.diff(b["discharged_mah"].astype(float)) / np.diff(t)
    tm = np.r_[t[0], (t[1:] + t[:-1]) / 2, t[-1]]
    return tm, np.interp(tm, t, b["voltage_v"].astype(float)) * np.r_[c[0], c, c[-1]]


def test_ulog_power_is_the_coulomb_count_not_the_aliased_instant_current(ulog_raw):
    """current_a is one reading per 0.3 s and reads 0 A where the coulomb count grows; the electric energy of the
    trajectory over its span equals what the batteries counted (integral of V dQ) within 1 %, where the
    instantaneous current would miss about a fifth of it."""
    tr = read_flight(ULG, rate_hz=50.0)
    bats = [ulog_raw[("battery_status", k)] for k in (0, 1)]
    gps = ulog_raw[("vehicle_gps_position", 0)]
    t_fix = gps["timestamp"][gps["fix_type"] >= 3] / 1e6
    t0 = max([t_fix[0], ulog_raw[("vehicle_attitude", 0)]["timestamp"][0] / 1e6]
             + [b["timestamp"][0] / 1e6 for b in bats])
    tt = np.linspace(t0, t0 + tr.t[-1], 20001)
    e_counted = e_instant = 0.0
    for b in bats:
        t, v = b["timestamp"] / 1e6, b["voltage_v"].astype(float)
        assert np.any((b["current_a"][1:] == 0) & (np.diff(b["discharged_mah"]) > 0))  # 0 A while the count grows
        q, vv = np.interp(tt, t, b["discharged_mah"]), np.interp(tt, t, v)
        e_counted += float(np.sum(0.5 * (vv[1:] + vv[:-1]) * np.diff(q) * 3.6))      # J: V x mAh x 3.6 As/mAh
        e_instant += float(np.trapezoid(np.interp(tt, t, v * b["current_a"]), tt))
    e_traj = float(np.trapezoid(tr.power_w, tr.t))
    assert e_traj == pytest.approx(e_counted, rel=0.01)
    assert abs(e_instant / e_counted - 1.0) > 0.1          # what reading current_a alone would have given


def test_ulog_without_start_utc_starts_at_zero(ulog_raw):
    tr = read_flight(ULG)
    assert tr.t[0] == 0.0
    # without start_utc: seconds since the first kept fix, on the log's own (boot) clock, read with pyulog
    gps = ulog_raw[("vehicle_gps_position", 0)]
    t_boot = gps["timestamp"][gps["fix_type"] >= 3] / 1e6
    att = ulog_raw[("vehicle_attitude", 0)]
    b0, b1 = ulog_raw[("battery_status", 0)], ulog_raw[("battery_status", 1)]
    lo = max(t_boot[0], att["timestamp"][0] / 1e6, b0["timestamp"][0] / 1e6, b1["timestamp"][0] / 1e6)
    hi = min(t_boot[-1], att["timestamp"][-1] / 1e6, b0["timestamp"][-1] / 1e6, b1["timestamp"][-1] / 1e6)
    tb = t_boot[(t_boot >= lo) & (t_boot <= hi)]
    np.testing.assert_allclose(tr.t, tb - tb[0], rtol=0, atol=1e-6)


def test_ulog_missing_topic_is_named(monkeypatch):
    monkeypatch.setattr(logs, "_ULOG_TOPICS", tuple(t for t in logs._ULOG_TOPICS if t != "battery_status"))
    with pytest.raises(MissingColumnError, match=r"pyulog_sample_log_small_vtol\.ulg: topic 'battery_status'") as e:
        read_flight(ULG)
    assert e.value.field == "battery_status"
    monkeypatch.setattr(logs, "_ULOG_TOPICS", ("battery_status", "vehicle_attitude"))
    with pytest.raises(MissingColumnError, match="vehicle_global_position"):
        read_flight(ULG)


# ----------------------------------------------------------------------------- ArduPilot
@pytest.fixture(scope="module")
def dataflash_raw():
    from pymavlink import mavutil

    m = mavutil.mavlink_connection(str(BIN))
    out: dict[str, list] = {"GPS": [], "ATT": [], "CURR": []}
    while True:
        msg = m.recv_match(type=list(out))
        if msg is None:
            break
        out[msg.get_type()].append(msg)
    m.close()
    return out


def test_dataflash_positions_attitude_power_equal_pymavlink(dataflash_raw):
    n_geoid = 19.5  # any undulation: heights are AMSL + N
    start = "2015-11-21T23:44:00Z"
    tr = read_flight(BIN, start_utc=start, geoid_undulation_m=n_geoid)
    gps = [g for g in dataflash_raw["GPS"] if g.Status >= 3]
    t_gps = np.array([g.T for g in gps]) / 1e3
    att, cur = dataflash_raw["ATT"], dataflash_raw["CURR"]
    t_att = np.array([a.TimeMS for a in att]) / 1e3
    t_cur = np.array([c.TimeMS for c in cur]) / 1e3
    keep = (t_gps >= max(t_att[0], t_cur[0])) & (t_gps <= min(t_att[-1], t_cur[-1]))
    assert len(tr) == keep.sum() > 1000
    tb = t_gps[keep]
    np.testing.assert_allclose(tr.lat, [g.Lat for g, k in zip(gps, keep, strict=True) if k], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.lon, [g.Lng for g, k in zip(gps, keep, strict=True) if k], rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.h, np.array([g.Alt for g, k in zip(gps, keep, strict=True) if k]) + n_geoid, atol=1e-9)
    # attitude interpolated on the circle from ATT (deg); the log ends upside down (roll -181 deg)
    for name in ("Roll", "Pitch", "Yaw"):
        r = np.radians([getattr(a, name) for a in att])
        ref = np.degrees(np.arctan2(np.interp(tb, t_att, np.sin(r)), np.interp(tb, t_att, np.cos(r))))
        assert _circ_diff(getattr(tr, name.lower()), ref).max() < 1e-9
    assert np.all(np.abs(tr.roll) <= 180.0) and np.all(np.abs(tr.yaw) <= 180.0)
    # power: this ArduCopter 3.3 CURR logs int16 hundredths of volt and ampere
    assert cur[0].fmt.format[cur[0].fmt.columns.index("Volt")] == "h"
    p = np.array([c.Volt / 100.0 * c.Curr / 100.0 for c in cur])
    np.testing.assert_allclose(tr.power_w, np.interp(tb, t_cur, p), rtol=1e-12)
    assert 5.0 < tr.power_w.min() and tr.power_w.max() < 16.8 * 30  # a 4S pack, under 30 A
    # time: GPS week/ms minus 17 leap seconds (IERS Bulletin C, 2015-07-01 .. 2016-12-31);
    # pymavlink's own _timestamp subtracts a fixed 18 s, so it reads exactly 1 s early here
    # (boot and GPS clocks are tied by the median over all fixes; single fixes jitter by ~15 ms)
    kept = [g for g, k in zip(gps, keep, strict=True) if k]
    err = np.abs(tr.t + datetime(2015, 11, 21, 23, 44, tzinfo=timezone.utc).timestamp()
                 - gps_to_unix([g.Week for g in kept], [g.TimeMS for g in kept]))
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.03
    assert abs(float(gps_to_unix(kept[0].Week, kept[0].TimeMS)) - kept[0]._timestamp - 1.0) < 1e-6
    # a quad: every phase comes from the speed rule; it flew at up to 12 m/s
    assert {"hover", "horizontal"} <= set(np.unique(tr.phase))


def test_dataflash_without_a_geoid_grid_names_geoid_undulation(no_geoid_grid):
    with pytest.raises(InputError, match="--geoid-undulation") as e:
        read_flight(BIN)
    assert e.value.field == "geoid_undulation_m" and "proj-data" in str(e.value)


# ----------------------------------------------------------------------------- synthetic DataFlash
def _fmt(type_id: int, name: str, fmt: str, cols: str, length: int) -> bytes:
    return b"\xa3\x95\x80" + struct.pack("<BB4s16s64s", type_id, length, name.encode(), fmt.encode(), cols.encode())


_STRUCT = {"Q": "Q", "B": "B", "I": "I", "H": "H", "L": "i", "f": "f", "h": "h"}


def _write_dataflash(path: Path, messages: dict[str, tuple[str, str, list[tuple]]]) -> None:
    """Write a DataFlash log: name -> (format, columns, rows)."""
    out = bytearray(_fmt(128, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns", 89))
    ids = {}
    for i, (name, (fmt, cols, _)) in enumerate(messages.items()):
        ids[name] = 129 + i
        out += _fmt(ids[name], name, fmt, cols, 3 + struct.calcsize("<" + "".join(_STRUCT[c] for c in fmt)))
    events = []
    for name, (_, _, rows) in messages.items():
        for r in rows:
            events.append((r[0], name, r))
    for _, name, r in sorted(events, key=lambda e: e[0]):
        fmt = messages[name][0]
        out += b"\xa3\x95" + bytes([ids[name]]) + struct.pack("<" + "".join(_STRUCT[c] for c in fmt), *r)
    path.write_bytes(bytes(out))


def _synthetic(tmp_path: Path, *, power: str = "BAT") -> tuple[Path, dict]:
    t = np.arange(0.0, 20.0, 0.2)  # 5 Hz GPS
    week, gms0 = 2300, 100_000_000  # 2024-02-04 + 100000 s; GPS - UTC = 18 s
    lat = 52.0 + 1e-5 * t  # about 1.1 m/s north
    lon = np.full_like(t, 10.0)
    alt = 100.0 + 0.5 * t
    gps = [(int(round(ti * 1e6)), 3, gms0 + int(round(ti * 1000)), week, int(round(la * 1e7)), int(round(lo * 1e7)), al)
           for ti, la, lo, al in zip(t, lat, lon, alt, strict=True)]
    ta = np.arange(0.0, 20.0, 0.05)
    att = [(int(round(ti * 1e6)), 10.0 * np.sin(ti), -3.0, (170.0 + 5.0 * ti) % 360.0) for ti in ta]
    msgs = {"GPS": ("QBIHLLf", "TimeUS,Status,GMS,GWk,Lat,Lng,Alt", gps),
            "ATT": ("Qfff", "TimeUS,Roll,Pitch,Yaw", att)}
    tb = np.arange(0.0, 20.0, 0.1)
    if power == "BAT":
        bat = [(int(round(ti * 1e6)), i, 44.0 + i, 20.0 + i + ti) for ti in tb for i in (0, 1)]
        msgs["BAT"] = ("QBff", "TimeUS,Instance,Volt,Curr", bat)
    elif power == "CURR":
        msgs["CURR"] = ("Qhh", "TimeUS,Volt,Curr", [(int(round(ti * 1e6)), 2220, 1500 + int(round(ti * 10))) for ti in tb])
    path = tmp_path / "synthetic.bin"
    _write_dataflash(path, msgs)
    truth = {"t": t, "lat": np.round(lat * 1e7) / 1e7, "lon": lon, "alt": alt, "week": week, "gms0": gms0}
    return path, truth


def test_synthetic_dataflash_bat_instances_are_summed(tmp_path):
    path, truth = _synthetic(tmp_path)
    utc0 = gps_to_unix(truth["week"], truth["gms0"])
    tr = read_flight(path, start_utc=float(utc0) - 5.0, geoid_undulation_m=47.0)
    t = truth["t"][truth["t"] <= 19.9]  # ATT and BAT end at 19.95 and 19.9 s
    np.testing.assert_allclose(tr.t, t + 5.0, atol=1e-6)
    np.testing.assert_allclose(tr.lat, truth["lat"][: len(t)], atol=1e-7)
    np.testing.assert_allclose(tr.h, truth["alt"][: len(t)] + 47.0, atol=1e-4)
    # two batteries: (44 V)(20 A + t) + (45 V)(21 A + t)
    np.testing.assert_allclose(tr.power_w, 44.0 * (20.0 + t) + 45.0 * (21.0 + t), rtol=1e-5)
    np.testing.assert_allclose(tr.pitch, -3.0, atol=1e-5)
    # yaw crosses 180 deg (170 + 5 t) and is wrapped into (-180, 180]
    assert _circ_diff(tr.yaw, 170.0 + 5.0 * t).max() < 1e-3
    assert tr.yaw.max() <= 180.0 and tr.yaw.min() > -180.0
    # GPS - UTC was 18 s in 2024
    assert abs(float(utc0) - (315964800 + 2300 * 604800 + 100000 - 18)) < 1e-6


def test_synthetic_dataflash_old_curr_hundredths(tmp_path):
    path, truth = _synthetic(tmp_path, power="CURR")
    tr = read_flight(path, geoid_undulation_m=0.0)
    t = tr.t
    np.testing.assert_allclose(tr.power_w, 22.20 * (15.0 + 0.1 * t), rtol=1e-9)  # 2220 -> 22.20 V, 1500 -> 15.00 A


def test_synthetic_dataflash_without_power_names_the_message(tmp_path):
    path, _ = _synthetic(tmp_path, power="none")
    with pytest.raises(MissingColumnError, match=r"synthetic\.bin: message 'BAT' or 'CURR' missing") as e:
        read_flight(path, geoid_undulation_m=0.0)
    assert e.value.field == "BAT"


# ----------------------------------------------------------------------------- helpers
def test_quaternion_to_euler_matches_scipy():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    eul = np.column_stack([rng.uniform(-180, 180, 50), rng.uniform(-85, 85, 50), rng.uniform(-180, 180, 50)])
    q = Rotation.from_euler("ZYX", eul, degrees=True).as_quat()  # x y z w
    roll, pitch, yaw = quaternion_to_euler(q[:, [3, 0, 1, 2]])
    assert _circ_diff(yaw, eul[:, 0]).max() < 1e-9
    np.testing.assert_allclose(pitch, eul[:, 1], atol=1e-9)
    assert _circ_diff(roll, eul[:, 2]).max() < 1e-9


def test_phase_by_speed_rule():
    t = np.arange(0.0, 10.0, 0.1)
    v = np.zeros((len(t), 3))
    v[t < 2] = [0.5, 0.0, 0.0]       # hover (drift < 3 m/s)
    v[(t >= 4) & (t < 6)] = [0.0, 0.0, 2.5]    # climb
    v[t >= 8] = [12.0, 0.0, -2.0]    # fast forward and descending: horizontal
    ph = phase_by_speed(t, v)
    assert set(ph[t < 1.4]) == {"hover"}
    assert set(ph[(t > 4.6) & (t < 5.4)]) == {"climb"}
    assert set(ph[t > 8.6]) == {"horizontal"}
    ph = phase_by_speed(t, -v)
    assert set(ph[(t > 4.6) & (t < 5.4)]) == {"sink"}


def test_read_flight_dispatch(tmp_path):
    p = tmp_path / "f.txt"
    p.write_text("x")
    with pytest.raises(InputError, match=r"f\.txt: unknown flight log type '\.txt'"):
        read_flight(p)
