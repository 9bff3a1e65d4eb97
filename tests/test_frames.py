"""Frames and angles: WGS84 <-> ENU and body-axis emission angles (SPEC section 1)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gisnoise.geo import LocalFrame, emission_angles, wrap_deg


@settings(max_examples=50, deadline=None)
@given(
    lat0=st.floats(-80, 80), lon0=st.floats(-179, 179), h0=st.floats(-50, 3000),
    de=st.floats(-20000, 20000), dn=st.floats(-20000, 20000), du=st.floats(-100, 2000),
)
def test_enu_round_trip_under_1mm(lat0, lon0, h0, de, dn, du):
    f = LocalFrame(lat0, lon0, h0)
    lat, lon, h = f.to_wgs84(de, dn, du)
    e, n, u = f.to_enu(lat, lon, h)
    assert np.sqrt((e - de) ** 2 + (n - dn) ** 2 + (u - du) ** 2) < 1e-3


def test_point_1km_north_is_enu_0_1000():
    from pyproj import Geod

    f = LocalFrame(52.3, 10.5, 0.0)  # geodesic distances are measured on the ellipsoid (h = 0)
    lon, lat, _ = Geod(ellps="WGS84").fwd(10.5, 52.3, 0.0, 1000.0)
    e, n, u = f.to_enu(lat, lon, 0.0)
    assert abs(e) < 1e-6
    assert n == pytest.approx(1000.0, abs=0.001)  # arc vs chord: 1000^3 / (6 R^2) = 4e-6 m
    assert abs(u) < 0.1  # the ellipsoid curves away: 1000^2 / (2 R) = 0.08 m


def test_angles_of_level_uav():
    # observer ahead, below, to starboard of a UAV heading east (yaw 90 deg)
    yaw = np.radians(90.0)
    d, phi, theta = emission_angles(100.0, 0.0, 0.0, yaw, 0.0, 0.0)
    assert (d, np.degrees(phi), np.degrees(theta)) == pytest.approx((100.0, 0.0, 0.0))
    d, phi, theta = emission_angles(0.0, -100.0, 0.0, yaw, 0.0, 0.0)  # south = starboard when heading east
    assert np.degrees(phi) == pytest.approx(90.0)
    d, phi, theta = emission_angles(0.0, 0.0, -30.0, yaw, 0.0, 0.0)
    assert np.degrees(theta) == pytest.approx(-90.0)
    d, phi, theta = emission_angles(-100.0, 0.0, 0.0, yaw, 0.0, 0.0)  # behind
    assert np.degrees(phi) == pytest.approx(180.0)


def test_roll_right_wing_down_moves_ground_point_to_starboard():
    # heading north, rolled 30 deg right: the point straight below appears 30 deg to starboard
    d, phi, theta = emission_angles(0.0, 0.0, -50.0, 0.0, 0.0, np.radians(30.0))
    assert np.degrees(phi) == pytest.approx(90.0)
    assert np.degrees(theta) == pytest.approx(-60.0)


def test_pitch_nose_up_puts_ground_point_behind():
    d, phi, theta = emission_angles(0.0, 0.0, -50.0, 0.0, np.radians(20.0), 0.0)
    assert np.degrees(phi) == pytest.approx(180.0)
    assert np.degrees(theta) == pytest.approx(-70.0)


def test_yaw_wrapping():
    np.testing.assert_allclose(wrap_deg([350.0, -190.0, 180.0, -180.0, 720.0]), [-10.0, 170.0, 180.0, 180.0, 0.0])
