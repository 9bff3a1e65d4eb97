"""Position glitches: a fix no UAV can reach is mended from the track around it, said once, never mapped.

The truths: the speed bound (150 m/s between two samples), the straight uniform flight between the samples
around a glitch, and the real ArduPilot log171 as logged: a copy with one fix moved to latitude 0, longitude 0
or 1.1 km north maps as the log itself does, and the real logs have no glitch to mend.
"""

import json

import numpy as np
import pytest
import rasterio
from test_real_logs_maps import COPTER, N_SITE, QUAD, VTOL  # noqa: E402

from gisnoise.flight import Trajectory, read_flight, read_route
from gisnoise.flight.glitches import GLITCH_MAX_S, glitch_warning, mend_glitches
from gisnoise.geo import LocalFrame
from gisnoise.maps import make_map
from gisnoise.model import ModelCard, save

FRAME = LocalFrame(52.0, 10.0, 100.0)


def _track(n=101, dt=0.1, v=10.0):
    """Eastwards at v m/s, 30 m up, n samples dt apart."""
    t = np.arange(n) * dt
    lat, lon, h = FRAME.to_wgs84(v * t, 0 * t, 0 * t + 30.0)
    return t, lat, lon, h


@pytest.mark.parametrize("path", [VTOL, QUAD, COPTER], ids=lambda p: p.stem)
def test_the_real_logs_have_no_glitch(path):
    tr = read_flight(path, geoid_undulation_m=N_SITE)
    assert "position_glitches" not in tr.metadata


def test_a_track_without_glitches_keeps_every_position_bit_for_bit():
    t, lat, lon, h = _track(v=149.0)  # just below the bound
    g = mend_glitches(t, lat, lon, h)
    assert g.runs == () and g.lat is not None
    assert np.array_equal(g.lat, lat) and np.array_equal(g.lon, lon) and np.array_equal(g.h, h)


def test_a_run_inside_the_track_flies_straight_between_its_neighbours():
    """Three samples (a 5 Hz fix resampled at 10 Hz: ramp, glitch, ramp) 2 km off: mended onto the straight
    flight at 10 m/s, within a millimetre; the other samples untouched."""
    t, lat, lon, h = _track()
    bad = [40, 41, 42]
    lat2, lon2, h2 = lat.copy(), lon.copy(), h.copy()
    lat2[bad], lon2[bad], _ = FRAME.to_wgs84(np.array([410.0, 2000.0, 420.0]), np.array([1000.0, 2000.0, 1000.0]),
                                             np.full(3, 30.0))
    g = mend_glitches(t, lat2, lon2, h2)
    assert [r[:2] for r in g.runs] == [(40, 43)]
    e, n, u = FRAME.to_enu(g.lat, g.lon, g.h)
    np.testing.assert_allclose(e, 10.0 * t, atol=1e-3)
    np.testing.assert_allclose(n, 0.0, atol=1e-3)
    np.testing.assert_allclose(u, 30.0, atol=1e-3)
    keep = np.setdiff1d(np.arange(t.size), bad)
    assert np.array_equal(g.lat[keep], lat[keep]) and np.array_equal(g.lon[keep], lon[keep])


@pytest.mark.parametrize("where", ["start", "end"])
def test_a_glitch_at_either_end_takes_the_nearest_good_position(where):
    t, lat, lon, h = _track()
    i = 0 if where == "start" else t.size - 1
    lat2, lon2 = lat.copy(), lon.copy()
    lat2[i], lon2[i] = 0.0, 0.0
    g = mend_glitches(t, lat2, lon2, h)
    j = 1 if where == "start" else t.size - 2
    assert [r[:2] for r in g.runs] == [(0, 1) if where == "start" else (t.size - 1, t.size)]
    assert (g.lat[i], g.lon[i]) == (lat[j], lon[j])


def test_a_jump_the_track_does_not_come_back_from_is_kept_and_named():
    """From t = 15 s on the 30 s track runs 3 km north: a reset or two tracks joined, not a glitch of at most 10 s
    on either side; which side is right is unknown, so both stay as logged and the warning names the jump.  A jump
    5 s before the end is the track's end glitching (held at its last good position)."""
    t, lat, lon, h = _track(n=301)
    lat2, lon2, _ = FRAME.to_wgs84(10.0 * t, np.where(t >= 15.0, 3000.0, 0.0), 0 * t + 30.0)
    assert 15.0 > GLITCH_MAX_S
    g = mend_glitches(t, lat2, lon2, h)
    assert g.runs == () and [j[0] for j in g.jumps] == [149] and g.jumps[0][1] == pytest.approx(3000.0, abs=0.1)
    assert np.array_equal(g.lat, lat2) and np.array_equal(g.lon, lon2)
    tr = Trajectory(t=t, lat=lat2, lon=lon2, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t + 90.0,
                    power_w=0 * t + 3000.0, phase=np.full(t.size, "horizontal"), source="joined.csv",
                    metadata=g.metadata(t))
    assert glitch_warning(tr).startswith("joined.csv: the position jumps 3,000 m between t = 14.90 and 15.00 s "
                                         "(30,000 m/s, faster than any UAV flies) and does not come back within 10 s")
    lat3, lon3, _ = FRAME.to_wgs84(10.0 * t, np.where(t >= 25.0, 3000.0, 0.0), 0 * t + 30.0)
    g = mend_glitches(t, lat3, lon3, h)
    assert [r[:2] for r in g.runs] == [(250, 301)] and np.all(g.lat[250:] == lat3[249])


@pytest.fixture(scope="module")
def copter_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("glitch")
    tr = read_route(COPTER, geoid_undulation_m=N_SITE).trajectory
    tr.to_csv(d / "log171.csv")
    card = ModelCard(id="omni", vehicle="test", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=65.0, p1=10.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=300.0, phases=("horizontal", "climb", "sink", "transition"))
    return d, tr, str(save(card, d / "omni.json"))


@pytest.mark.parametrize("glitch", ["null island", "1.1 km north"])
def test_log171_with_a_glitch_maps_as_the_log_itself(copter_csv, glitch):
    """One sample at t = 80 s moved to latitude 0, longitude 0 (before: a grid of 1e12 cells refused as too
    large) or 0.01 deg north (before: mapped, a noise spot 1.1 km from the flight): the map equals the log's
    own within 0.01 dB, and the warning names the file and the time once."""
    d, tr, card = copter_csv
    lines = (d / "log171.csv").read_text().splitlines()
    head = lines[0].split(",")
    i = int(np.argmin(np.abs(tr.t - 80.0)))
    row = lines[i + 1].split(",")
    if glitch == "null island":
        row[head.index("lat")], row[head.index("lon")] = "0.0", "0.0"
    else:
        row[head.index("lat")] = repr(float(row[head.index("lat")]) + 0.01)
    lines[i + 1] = ",".join(row)
    bad = d / f"glitch_{glitch.split()[0]}.csv"
    bad.write_text("\n".join(lines) + "\n")
    kw = dict(resolution_m=10.0, margin_m=150.0, outputs=("levels",))
    ref = make_map(d / "log171.csv", [card], d / "ref", **kw)
    got = make_map(bad, [card], d / glitch.split()[0], **kw)
    said = [w for w in got["warnings"] if "position glitch" in w]
    assert len(said) == 1 and said[0].startswith(f"{bad}: 1 sample in a position glitch (t = {tr.t[i]:.1f} s;")
    assert not [w for w in ref["warnings"] if "position glitch" in w]
    with rasterio.open(ref["levels"]) as a, rasterio.open(got["levels"]) as b:
        assert a.transform == b.transform and a.shape == b.shape
        for k in range(1, a.count + 1):
            np.testing.assert_allclose(b.read(k), a.read(k), atol=0.01)
        meta = json.loads(b.tags()["gisnoise"])
    assert any("position glitch" in w for w in meta["warnings"])


def test_the_quick_bound_never_misses_a_step_the_frame_finds_too_fast():
    """The cheap test that skips the local frame bounds every step from above: on random steps near the bound,
    anywhere on the globe (poles, antimeridian, up to 10 km), a step the frame finds faster than 150 m/s is
    always among those the bound lets through."""
    from gisnoise.flight.glitches import _may_be_fast
    from gisnoise.limits import MAX_UAV_SPEED_M_S

    rng = np.random.default_rng(7)
    for _ in range(300):
        lat0, lon0 = rng.uniform(-89.9, 89.9), rng.uniform(-180.0, 180.0)
        h0 = rng.uniform(-400.0, 9000.0)
        fr = LocalFrame(lat0, lon0, h0)
        az, el = rng.uniform(0, 2 * np.pi), rng.uniform(-np.pi / 2, np.pi / 2)
        d = MAX_UAV_SPEED_M_S * rng.uniform(0.98, 1.02)  # a 1 s step within 2 % of the bound
        la, lo, hh = fr.to_wgs84(np.array([0.0, d * np.cos(el) * np.sin(az)]),
                                 np.array([0.0, d * np.cos(el) * np.cos(az)]), np.array([0.0, d * np.sin(el)]))
        lo = (lo + 180.0) % 360.0 - 180.0
        t = np.array([0.0, 1.0])
        e, n, u = LocalFrame(float(la[0]), float(lo[0]), float(hh[0])).to_enu(la, lo, hh)
        if np.hypot(np.hypot(e[1] - e[0], n[1] - n[0]), u[1] - u[0]) > MAX_UAV_SPEED_M_S:
            assert _may_be_fast(t, la, lo, hh)
