"""PX4 heights without ``vehicle_global_position``: the estimator's ``-vehicle_local_position.z`` levelled on the
GPS heights by their median offset, checked on two real logs against what is known of their flights (read with
pyulog directly), and on synthetic estimator records whose truth is known (resets, invalid heights)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import read_route
from gisnoise.flight import ulog as ulog_reader
from gisnoise.flight.ulog import estimator_height

pyulog = pytest.importorskip("pyulog")

DATA = Path(__file__).parent / "data"
VTOL = DATA / "pyulog_sample_log_small_vtol.ulg"
QUAD = DATA / "robologs_test_quad_fmuv5.ulg"


def _raw(path):
    u = pyulog.ULog(str(path))
    return {(d.name, d.multi_id): d.data for d in u.data_list}


def _fixes(raw):
    g = raw[("vehicle_gps_position", 0)]
    ok = g["fix_type"] >= 3
    return g["timestamp"][ok] / 1e6, g["alt_ellipsoid"][ok] / 1e3


def _start(raw):
    """Boot time (s) of the trajectory's first sample: GPS fixes, attitude and every battery all logged."""
    tg, _ = _fixes(raw)
    firsts = [tg[0], raw[("vehicle_attitude", 0)]["timestamp"][0] / 1e6]
    firsts += [d["timestamp"][0] / 1e6 for (n, _), d in raw.items() if n == "battery_status"]
    return max(firsts)


def test_quad_height_holds_to_its_hops_and_equals_the_estimator_levelled_on_gps():
    """The quad hops under 0.2 m (data README; land detector: two take-offs of about a second): its height ranges
    less than 0.5 m over the log (the hops plus the estimator's noise), where the raw GPS height climbs more than
    3 m over the same span.  It equals -z, the one z reset of the log (4 resets between two logged samples while the
    primary EKF instance changed) undone, plus the median offset to the GPS heights, computed here from pyulog."""
    raw = _raw(QUAD)
    tr = read_route(QUAD).trajectory
    t_abs = _start(raw) + tr.t
    assert np.ptp(tr.h) < 0.5
    tg, hg = _fixes(raw)
    assert np.ptp(np.interp(t_abs, tg, hg)) > 3.0              # what the raw GPS heights did meanwhile
    lp = raw[("vehicle_local_position", 0)]
    assert lp["z_valid"].all()
    t_lp, z = lp["timestamp"] / 1e6, lp["z"].astype(float)
    k = np.flatnonzero(np.diff(lp["z_reset_counter"].astype(int)))
    assert len(k) == 1 and lp["z_reset_counter"][k[0] + 1] - lp["z_reset_counter"][k[0]] == 4
    z = z - np.where(np.arange(len(z)) > k[0], float(lp["delta_z"][k[0] + 1]), 0.0)   # the last reset's shift
    inside = (tg >= t_lp[0]) & (tg <= t_lp[-1])
    offset = np.median(hg[inside] + np.interp(tg[inside], t_lp, z))
    # delta_z holds the last of the 4 resets; the reader takes the step of z less the motion vz gives: within 1 cm
    np.testing.assert_allclose(tr.h, offset - np.interp(t_abs, t_lp, z), rtol=0, atol=0.01)
    assert tr.metadata["height_resets"] == 4
    assert tr.metadata["height_anchor_m"] == pytest.approx(offset, abs=0.01)
    assert "estimator" in tr.metadata["height_datum"] and tr.metadata["height_datum"].startswith("ellipsoid")


def test_vtol_height_on_the_ground_stays_put_and_follows_the_barometer():
    """The VTOL stands on the ground before its take-off and after its landing (land detector, log messages
    'Takeoff detected' and 'Landing detected'), a hop in place: there the ground's height is one number.  The raw
    GPS height falls 3.9 m over the log; the estimator's drifts about 1 m (its vertical velocity reads -0.2 to
    +0.2 m/s on the ground: it converges), so the landed heights spread less than 1.2 m.  The barometer
    (vehicle_air_data.baro_alt_meter) holds within 0.6 m (its noise): the height above the first sample agrees
    with the barometer's within 1.4 m (the estimator's 1 m drift plus the barometer's +-0.3 m noise), the raw
    GPS's departs by more than 3 m.
    The log has no range finder (no distance_sensor topic; vehicle_local_position.dist_bottom is the estimator's
    terrain state, not a measurement), so the barometer is the independent height sensor."""
    raw = _raw(VTOL)
    assert ("distance_sensor", 0) not in raw
    tr = read_route(VTOL).trajectory
    t_abs = _start(raw) + tr.t
    landed = tr.on_ground
    assert landed[0] and landed[-1] and (~landed).any()
    tg, hg = _fixes(raw)
    gps = np.interp(t_abs, tg, hg)
    assert np.ptp(tr.h[landed]) < 1.2 and np.ptp(gps[landed]) > 3.5
    b = raw[("vehicle_air_data", 0)]
    baro = np.interp(t_abs, b["timestamp"] / 1e6, b["baro_alt_meter"].astype(float))
    assert np.ptp(baro) < 0.6
    assert np.abs((tr.h - tr.h[0]) - (baro - baro[0])).max() < 1.4
    assert np.abs((gps - gps[0]) - (baro - baro[0])).max() > 3.0


def test_synthetic_resets_do_not_jump_the_height():
    """A vehicle climbing at 1 m/s from 100 m (ellipsoidal); the estimator resets z twice: once by -2 m (counter
    steps by one, delta_z tells), once by +5 m in three resets between two logged samples (delta_z holds the last,
    +1 m, only).  The height is the climb, without either jump."""
    t = np.arange(0.0, 10.0, 0.1)
    truth = 100.0 + t
    z = -(truth - 100.0) + 3.0                                   # the estimator's local origin: 3 m below the truth
    counter = np.zeros(len(t), dtype=np.uint8) + 254           # it wraps past 255
    delta = np.zeros(len(t))
    z[40:] -= 2.0
    counter[40:] += 1
    delta[40:] = -2.0
    z[70:] += 5.0
    counter[70:] += 3
    delta[70:] = 1.0
    lp = {"timestamp": t * 1e6, "z": z, "vz": -np.ones(len(t)), "z_valid": np.ones(len(t), dtype=bool),
          "z_reset_counter": counter, "delta_z": delta}
    rng = np.random.default_rng(0)
    t_gps = t[::2]
    h_gps = truth[::2] + rng.normal(0.0, 2.0, len(t_gps))      # GPS heights 2 m noisy about the truth
    th, h, meta = estimator_height(lp, t_gps, h_gps)
    np.testing.assert_array_equal(th, t)
    assert np.abs(np.diff(h) - 0.1).max() < 1e-9                 # 0.1 m per sample: the climb, no jump
    assert meta["height_resets"] == 4
    # the level: the median of the GPS noise about the truth
    assert h[0] - truth[0] == pytest.approx(np.median(h_gps - truth[::2]), abs=1e-9)


def test_synthetic_invalid_or_missing_estimator_keeps_gps_and_says_why():
    t = np.arange(0.0, 5.0, 0.1)
    lp = {"timestamp": t * 1e6, "z": -t, "z_valid": np.ones(len(t), dtype=bool)}
    lp["z_valid"][20:25] = False
    why = estimator_height(lp, t, 100.0 + t)
    assert isinstance(why, str) and "not valid at 5 of its 50 samples" in why
    lp["z_valid"][:] = False
    assert "never valid" in estimator_height(lp, t, 100.0 + t)
    assert "not logged" in estimator_height(None, t, 100.0 + t)
    lp["z_valid"][:] = True
    assert "only 2 GPS fixes" in estimator_height(lp, np.array([1.0, 2.0]), np.array([101.0, 102.0]))


def test_vtol_without_local_position_keeps_the_raw_gps_height_and_says_why(monkeypatch):
    monkeypatch.setattr(ulog_reader, "_ULOG_TOPICS",
                        tuple(n for n in ulog_reader._ULOG_TOPICS if n != "vehicle_local_position"))
    raw = _raw(VTOL)
    tr = read_route(VTOL).trajectory
    tg, hg = _fixes(raw)
    t_abs = _start(raw) + tr.t
    np.testing.assert_allclose(tr.h, np.interp(t_abs, tg, hg), rtol=0, atol=1e-6)
    assert tr.metadata["height_datum"] == "ellipsoid (vehicle_gps_position.alt_ellipsoid)"
    assert tr.metadata["height_note"] == "raw GPS heights (vehicle_gps_position): vehicle_local_position is not logged"


def test_the_map_states_the_height_source(tmp_path):
    out = tmp_path / "m"
    r = CliRunner().invoke(cli, ["-q", "contour", str(VTOL), "--card", "demo-horizontal", "--card", "demo-climb",
                                 "--card", "demo-sink", "--out", str(out), "--resolution", "20", "--margin", "60"],
                           catch_exceptions=False)
    assert r.exit_code == 0, r.output
    import rasterio

    with rasterio.open(out / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])["trajectory"]
    assert "estimator's height -vehicle_local_position.z" in meta["height_datum"]
    assert meta["height_resets"] == 0 and np.isfinite(meta["height_anchor_m"])
    # a hop near the ground no longer put under the receivers by the drifting GPS height
    assert "below the ground taken from its take-off" not in r.stderr
