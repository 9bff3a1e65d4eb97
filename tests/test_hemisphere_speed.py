"""A measured hemisphere flown away from the speed it was measured at is said (5 kt: 14 CFR 36 App. H).

Known truths: the M300 file's name states 5 m/s (``F05``); a straight level flight at constant speed v has
ground speed v everywhere; the tolerance is 5 kt = 2.572 m/s.
"""

import dataclasses

import numpy as np
import pytest
from test_evaluate import FRAME, omni_card, straight_flight
from test_hemisphere import M300

from gisnoise.flight import Trajectory
from gisnoise.maps import pipeline
from gisnoise.maps.cardset import CardSet
from gisnoise.maps.conditions import SPEED_TOLERANCE_M_S, check_hemisphere_speeds
from gisnoise.maps.flightchecks import flight_findings
from gisnoise.model import import_hemisphere

pytest.importorskip("openpyxl")


@pytest.fixture(scope="module")
def m300():
    return import_hemisphere(M300, card_id="m300")


def test_the_m300_states_five_metres_per_second_and_the_tolerance_is_five_knots(m300):
    assert m300.condition["speed_m_s"] == 5.0
    assert SPEED_TOLERANCE_M_S == pytest.approx(2.5722, abs=1e-4)


@pytest.mark.parametrize("v", [5.0, 2.5, 7.5])
def test_flown_within_five_knots_of_the_stated_speed_no_warning(m300, v):
    traj = straight_flight(v=v, height=30.0, n0=-100.0, n1=100.0, dt=0.5)
    found = flight_findings(traj, CardSet([m300]))
    assert found.warnings == [] and found.speed_outside == {}


@pytest.mark.parametrize("v", [7.7, 2.3, 20.0])
def test_flown_beyond_five_knots_every_sample_is_named(m300, v):
    traj = straight_flight(v=v, height=30.0, n0=-100.0, n1=100.0, dt=0.5)
    found = flight_findings(traj, CardSet([m300]))
    (w,) = found.warnings
    n = len(traj)
    assert f"hemisphere 'm300' was measured at 5 m/s; {n} of the {n} flying samples it serves fly at " \
           f"{v:.1f}-{v:.1f} m/s ground speed, more than 5 kt from it" in w
    meta = found.speed_outside["m300"]
    assert meta["samples"] == meta["of"] == n and meta["speed"] == "ground speed"
    assert meta["flown_m_s"] == [pytest.approx([v, v], abs=1e-3)]


def test_slower_and_faster_samples_have_their_own_ranges(m300):
    """Hovering (0 m/s) then 12 m/s: two ranges, neither holding the stated 5 m/s."""
    fast = straight_flight(v=12.0, height=30.0, n0=-120.0, n1=120.0, dt=0.5)
    e, n, u = fast.enu(fast.origin())
    n = np.where(np.arange(len(fast)) < 20, n[0], n - (n[20] - n[0]))     # 20 samples at rest, then 12 m/s
    lat, lon, h = fast.origin().to_wgs84(e, n, u)
    traj = fast.with_(lat=lat, lon=lon, h=h)
    (w,) = flight_findings(traj, CardSet([m300])).warnings
    meta = check_hemisphere_speeds(traj, CardSet([m300]))[1]["m300"]
    (slow_lo, slow_hi), (fast_lo, fast_hi) = meta["flown_m_s"]
    assert slow_lo == 0.0 and slow_hi < 5 - SPEED_TOLERANCE_M_S and fast_lo > 5 + SPEED_TOLERANCE_M_S
    assert fast_hi == pytest.approx(12.0, abs=1e-3)
    assert f"fly at 0.0-{slow_hi:.1f} and {fast_lo:.1f}-12.0 m/s ground speed" in w


def test_the_logged_airspeed_is_the_speed_when_there_is_one(m300):
    traj = straight_flight(v=5.0, height=30.0, n0=-100.0, n1=100.0, dt=0.5)     # 5 m/s over the ground
    into_wind = traj.with_(airspeed_m_s=np.full(len(traj), 9.0))                  # 9 m/s through the air
    _, meta = check_hemisphere_speeds(into_wind, CardSet([m300]))
    assert meta["m300"]["speed"] == "airspeed" and meta["m300"]["flown_m_s"] == [[9.0, 9.0]]


def test_only_the_samples_the_hemisphere_serves_count(m300):
    """The hover part is the parametric card's: only the 12 m/s part is the hemisphere's and named."""
    fast = straight_flight(v=12.0, height=30.0, n0=-120.0, n1=120.0, dt=0.5)
    phase = np.where(np.arange(len(fast)) < 10, "hover", "horizontal")
    traj = fast.with_(phase=phase)
    _, meta = check_hemisphere_speeds(traj, CardSet([m300, omni_card("hover")]))
    assert meta["m300"]["of"] == len(traj) - 10 and meta["m300"]["samples"] == len(traj) - 10


def test_samples_on_the_ground_or_lying_after_a_crash_do_not_count(m300):
    """Only the samples the map evaluates count: 10 on the ground before take-off (no power), 40 flying at 15 m/s
    airspeed, 20 lying upside down at rest after a crash (power drawn, airspeed 0): 40 of 40, at 15-15 m/s."""
    t = np.arange(70) * 0.5
    fly = (t >= 5.0) & (t < 25.0)
    north = 15.0 * np.clip(t - 5.0, 0.0, 17.0)                         # still before 5 s and from 22 s
    lat, lon, h = FRAME.to_wgs84(0 * t, north, np.full(t.size, 30.0))  # (it came to lie on a roof)
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.where(t >= 25.0, 178.0, 0.0), pitch=0 * t, yaw=0 * t,
                      power_w=np.where(t < 5.0, 0.0, 3000.0), phase=np.full(t.size, "horizontal"),
                      airspeed_m_s=np.where(fly, 15.0, 0.0), source="crash")
    assert traj.flying.sum() == 40 and traj.lying.sum() == 20            # the construction's truth
    (w,) = flight_findings(traj, CardSet([m300])).warnings[-1:]
    _, meta = check_hemisphere_speeds(traj, CardSet([m300]))
    assert meta["m300"] == {"stated_m_s": 5.0, "flown_m_s": [[15.0, 15.0]], "samples": 40, "of": 40,
                            "speed": "airspeed"}
    assert "40 of the 40 flying samples it serves fly at 15.0-15.0 m/s airspeed" in w


def test_a_map_says_it_in_its_warnings_and_metadata(m300, tmp_path):
    traj = straight_flight(v=15.0, height=30.0, n0=-150.0, n1=150.0, dt=0.5)
    out = pipeline.make_map(traj, [m300], tmp_path / "map", resolution_m=20.0, margin_m=200.0, ground_h=0.0,
                            metrics=["LAmax"], levels=[50])
    n = len(traj)
    assert out["result"].metadata["hemisphere_speed_outside_condition"] == {
        "m300": {"stated_m_s": 5.0, "flown_m_s": [[15.0, 15.0]], "samples": n, "of": n, "speed": "ground speed"}}
    assert sum("hemisphere 'm300' was measured at 5 m/s" in w for w in out["result"].metadata["warnings"]) == 1


def test_a_parametric_card_or_a_hemisphere_without_a_stated_speed_is_not_checked(m300):
    traj = straight_flight(v=20.0, height=30.0, n0=-100.0, n1=100.0, dt=0.5)
    assert check_hemisphere_speeds(traj, CardSet([omni_card()])) == ([], {})
    unstated = dataclasses.replace(m300, condition={"height_m": 10.0})
    assert check_hemisphere_speeds(traj, CardSet([unstated])) == ([], {})
