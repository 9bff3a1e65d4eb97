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
