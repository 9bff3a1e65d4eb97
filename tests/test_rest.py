"""A vehicle lying upside down does not fly; a flip or a steep bank in the air does (gisnoise.flight.rest).

Inverted, a multicopter's thrust has no upward part: in the air it falls at g or more, so its 1 s mean speed
stays below 0.3 m/s for at most 2 x 0.3 / 9.81 = 0.06 s.  Only something under it keeps it at rest.
"""

import numpy as np
import pytest

from gisnoise.flight import Trajectory
from gisnoise.flight.rest import LYING_MIN_S, REST_SPEED_M_S, inverted
from gisnoise.geo import LocalFrame

FRAME = LocalFrame(52.27, 10.52, 100.0)
G = 9.80665
DT = 0.1


def _track(t, e, n, u, roll, pitch=None, power=300.0, on_ground=None):
    lat, lon, h = FRAME.to_wgs84(e, n, u)
    z = np.zeros_like(t)
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=roll, pitch=z if pitch is None else pitch, yaw=z,
                      power_w=np.full_like(t, power), phase=np.full(t.size, "hover"), on_ground=on_ground)


def _take_off_and_hover(t_end):
    """Motors off on the ground for 2 s, a climb at 2.5 m/s to 50 m, then a hover at 50 m; upright throughout."""
    t = np.arange(0.0, t_end, DT)
    u = np.clip(2.5 * (t - 2.0), 0.0, 50.0)
    return t, u, t < 2.0


@pytest.mark.parametrize("speed", [0.0, 10.0])
def test_a_brief_120_deg_roll_at_50_m_stays_flying(speed):
    """A 120 deg roll for 0.5 s at 50 m, hovering or at 10 m/s: inverted, but not for LYING_MIN_S at rest."""
    t, u, ground = _take_off_and_hover(60.0)
    e = speed * np.clip(t - 22.0, 0.0, None)
    roll = np.where((t >= 40.0) & (t < 40.5 - DT / 2), 120.0, 0.0)
    tr = _track(t, e, 0 * t, u, roll, on_ground=ground)
    assert inverted(tr.roll, tr.pitch).sum() == 5
    np.testing.assert_array_equal(tr.flying, ~ground)
    assert not tr.lying.any()


def test_a_flip_on_a_ballistic_arc_stays_flying_though_its_speed_passes_zero():
    """ArduCopter's FLIP: up at +g x 0.5 s, over through 360 deg of roll in 1 s under gravity alone, apex at mid-flip.
    The 1 s mean speed passes zero at the apex, but only for 2 x 0.3 / g = 0.06 s."""
    t, u, ground = _take_off_and_hover(60.0)
    tau = t - 40.0
    arc = (tau >= 0) & (tau <= 1.0)
    u = np.where(arc, 50.0 + G * 0.5 * tau - G * tau ** 2 / 2, u)
    roll = np.where(arc, (360.0 * tau + 180.0) % 360.0 - 180.0, 0.0)
    tr = _track(t, 0 * t, 0 * t, u, roll, on_ground=ground)
    assert inverted(tr.roll, tr.pitch).sum() == 5                     # 90 < roll < 270 deg: tau 0.3 .. 0.7 s
    np.testing.assert_array_equal(tr.flying, ~ground)


def test_inverted_flight_at_50_m_for_3_s_at_10_m_s_stays_flying():
    """Inverted for longer than LYING_MIN_S but moving: not at rest, so flying (speed is what rules it out)."""
    t, u, ground = _take_off_and_hover(60.0)
    e = 10.0 * np.clip(t - 22.0, 0.0, None)
    roll = np.where((t >= 40.0) & (t < 43.0), 120.0, 0.0)
    tr = _track(t, e, 0 * t, u, roll, on_ground=ground)
    assert inverted(tr.roll, tr.pitch).sum() == 30
    np.testing.assert_array_equal(tr.flying, ~ground)


def test_a_crashed_vehicle_lying_upside_down_with_power_does_not_fly():
    """Falls from 50 m at 40 s (3.19 s free fall to the ground), tumbling, then lies still upside down, motors drawing
    power and no landing flag: from the moment it lies at rest (its 1 s mean speed below 0.3 m/s) it does not fly."""
    t, u, ground = _take_off_and_hover(60.0)
    t_fall = np.sqrt(2 * 50.0 / G)
    tau = t - 40.0
    u = np.where(tau >= 0, np.maximum(50.0 - G * tau ** 2 / 2, 0.0), u)
    roll = np.where(tau >= 0, np.minimum(180.0 * tau / t_fall, 179.0), 0.0)   # turns over while falling
    pitch = np.where(tau >= t_fall, -2.0, 0.0)
    tr = _track(t, 0 * t, 0 * t, u, roll, pitch=pitch, on_ground=ground)
    lying = tr.lying
    # on the ground from 43.19 s (first sample 43.2 s); the velocity there (a central difference) still sees the
    # fall, and the 1 s mean speed sees it for half a window longer
    t_ground = float(t[(tau >= 0) & (u == 0.0)][0])
    t_lie = float(t[lying][0])
    assert 40.0 + t_fall <= t_lie <= t_ground + 0.5 + DT + 1e-9
    np.testing.assert_array_equal(lying, t >= t_lie)
    np.testing.assert_array_equal(tr.flying, ~ground & ~lying)
    assert float(t[-1]) - t_lie >= LYING_MIN_S


def test_lying_needs_lying_min_s_at_rest():
    """Inverted and still for less than LYING_MIN_S (then upright again) flies; for LYING_MIN_S it lies."""
    t = np.arange(0.0, 10.0, DT)
    for held, lies in ((LYING_MIN_S - 2 * DT, False), (LYING_MIN_S + DT, True)):
        roll = np.where((t >= 4.0) & (t < 4.0 + held), 178.0, 0.0)
        tr = _track(t, 0 * t, 0 * t, 0 * t, roll)
        assert tr.lying.any() == lies
        assert tr.flying.all() == (not lies)


def test_at_rest_is_the_1_s_mean_speed():
    """A vehicle creeping at just above REST_SPEED_M_S is not at rest; just below it is."""
    t = np.arange(0.0, 10.0, DT)
    roll = np.full_like(t, 179.0)
    for v, lies in ((REST_SPEED_M_S * 1.1, False), (REST_SPEED_M_S * 0.9, True)):
        tr = _track(t, v * t, 0 * t, 0 * t, roll)
        assert tr.lying.all() == lies and tr.lying.any() == lies
