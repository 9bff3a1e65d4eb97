"""A timed GeoJSON LineString is flown straight between its vertices and heard all along each leg.

Known truth: a level leg at constant speed over a receiver; its LAmax under the track is the level at
the closest distance (the card's spherical spreading), and its SEL the closed form of a finite straight
track (tests/test_evaluate.py).  Before, a two-vertex leg was evaluated at its two vertices only: 100 s of
flight heard twice, 30+ dB low at the leg's middle.
"""

import numpy as np
import pytest
from test_evaluate import FRAME, G0, centred_grid, evaluate_grid, omni_card, sel_closed_form

from gisnoise.errors import TrajectoryError
from gisnoise.flight import read_trajectory

H, N0, N1, T1 = 10.0, -250.0, 250.0, 100.0      # 500 m at 10 m height in 100 s: 5 m/s


def leg(times=(0.0, T1), **props):
    lat, lon, h = FRAME.to_wgs84(np.zeros(2), np.array([N0, N1]), np.full(2, H))
    coords = [[float(lon[i]), float(lat[i]), float(h[i])] for i in range(2)]
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
            "properties": {"times": list(times), "power_w": [3000.0, 3000.0], "phase": ["horizontal"] * 2, **props}}


def test_a_leg_is_cut_into_parts_no_longer_than_sample_dt_s_and_keeps_its_vertices():
    for dt, n in ((None, 201), (2.0, 51), (0.3, 335)):           # ceil(100 / dt) parts + 1
        tr = read_trajectory(leg(**({} if dt is None else {"sample_dt_s": dt})))
        assert len(tr) == n and tr.t[0] == 0.0 and tr.t[-1] == T1
        assert np.diff(tr.t).max() <= (dt or 0.5) + 1e-12
        e, nn, u = FRAME.to_enu(tr.lat, tr.lon, tr.h)
        np.testing.assert_allclose(nn, N0 + 5.0 * tr.t, atol=1e-3)     # straight, at constant speed
        np.testing.assert_allclose(e, 0.0, atol=1e-3)


def test_the_leg_is_heard_all_along_it():
    tr = read_trajectory(leg())
    grid = centred_grid(100.0, 1, 5)                                # x = 0; y = -200, -100, 0, 100, 200
    res = evaluate_grid(tr, [omni_card()], grid, ground_h=0.0, metrics=("LAmax", "SEL"))
    lamax = res.band("LAmax")[:, 0]
    closest = H - 1.5                                              # receivers at 1.5 m
    np.testing.assert_allclose(lamax, G0 + 20 * np.log10(40.0 / closest), atol=0.01)
    y = np.array([200.0, 100.0, 0.0, -100.0, -200.0])
    np.testing.assert_allclose(res.band("SEL")[:, 0], sel_closed_form(0.0, y, 5.0, H, N0, N1), atol=0.05)


def test_a_dense_path_is_kept_as_it_is():
    doc = leg()
    t = np.arange(0.0, 3.0, 0.25)                                   # vertices 0.25 s apart: no leg is cut
    lat, lon, h = FRAME.to_wgs84(np.zeros(t.size), N0 + 5.0 * t, np.full(t.size, H))
    doc["geometry"]["coordinates"] = [[float(a), float(b), float(c)] for a, b, c in zip(lon, lat, h, strict=True)]
    doc["properties"] = {"times": t.tolist()}
    tr = read_trajectory(doc)
    np.testing.assert_array_equal(tr.t, t)


def test_times_that_do_not_increase_are_refused_naming_times():
    with pytest.raises(TrajectoryError, match="properties.times must increase strictly; vertex 1") as e:
        read_trajectory(leg(times=(5.0, 5.0)))
    assert e.value.field == "times"


def test_a_leg_faster_than_any_uav_is_refused_naming_it():
    """500 m in 2 s is 250 m/s (limit 150 m/s): the times are wrong; before, the power derived from that speed
    was refused with advice to raise the power limit."""
    with pytest.raises(TrajectoryError, match=r"the leg from vertex 0 to 1 is 500 m long in 2 s \(250 m/s") as e:
        read_trajectory(leg(times=(0.0, 2.0)))
    assert e.value.field == "times"
    assert len(read_trajectory(leg(times=(0.0, 500.0 / 149.0)))) > 2   # just below the limit: flown


def _climb_cruise_land(step_s=None):
    """A vertical take-off to 50 m in 20 s, 1500 m north in 75 s (20 m/s), a vertical landing in 20 s: its four
    vertices, or the same positions and times with a vertex every ``step_s`` s."""
    t_v = np.array([0.0, 20.0, 95.0, 115.0])
    n_v, u_v = np.array([0.0, 0.0, 1500.0, 1500.0]), np.array([0.0, 50.0, 50.0, 0.0])
    t = t_v if step_s is None else np.arange(0.0, 115.0 + 1e-9, step_s)
    lat, lon, h = FRAME.to_wgs84(np.zeros(t.size), np.interp(t, t_v, n_v), np.interp(t, t_v, u_v))
    coords = [[float(lon[i]), float(lat[i]), float(h[i])] for i in range(t.size)]
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
            "properties": {"times": t.tolist()}}


def test_a_cruise_leg_between_two_vertices_is_flown_at_its_own_speed_and_phase():
    # the states come from the motion of the sampled legs: 1500 m in 75 s is 20 m/s, level, in cruise, all along
    # the leg.  Before, they were derived from the four vertices alone and interpolated: the 20 s climb beside
    # the cruise gave it 4.65 m/s, phase transition, pitch +-25 deg and 7.4-8.3 kW (1.6 kW flown), 20 dB louder
    tr = read_trajectory(_climb_cruise_land())
    cruise = (tr.t > 20.5) & (tr.t < 94.5)
    np.testing.assert_allclose(tr.airspeed_m_s[cruise], 20.0, atol=1e-3)
    assert set(tr.phase[cruise]) == {"horizontal"}
    np.testing.assert_allclose(tr.pitch[cruise], 0.0, atol=0.02)
    # the same flight written with a vertex every 0.5 s (the samples' own times) is the same trajectory, within the
    # difference of a path linear in longitude, latitude and height from one level in the local frame (0.18 m of
    # the Earth's curvature over the 1.5 km leg: 0.1 % of the power)
    dense = read_trajectory(_climb_cruise_land(0.5))
    np.testing.assert_array_equal(tr.t, dense.t)
    for k, rtol, atol in (("airspeed_m_s", 0.0, 1e-3), ("power_w", 2e-3, 0.0), ("pitch", 0.0, 0.02),
                          ("roll", 0.0, 0.02), ("yaw", 0.0, 0.02)):
        np.testing.assert_allclose(getattr(tr, k), getattr(dense, k), rtol=rtol, atol=atol, err_msg=k)
    assert list(tr.phase) == list(dense.phase)


def test_given_states_are_linear_between_their_vertices_angles_the_shorter_way():
    doc = leg(yaw=[170.0, -170.0], power_w=[1000.0, 3000.0])
    tr = read_trajectory(doc)
    mid = int(np.argmin(np.abs(tr.t - 50.0)))
    assert tr.t[mid] == 50.0
    assert tr.power_w[mid] == pytest.approx(2000.0)
    assert abs(tr.yaw[mid]) == pytest.approx(180.0)   # across north-south's 180 deg, not through 0
    assert set(tr.phase) == {"horizontal"}
