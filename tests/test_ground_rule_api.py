"""The ground rule of maps holds for the in-memory calls as for the command line: the ground given (or a DEM), else
the ground the route states, else the track's own take-off or landing point, else refused naming ground_h; and the
receiver checks of ``make_map`` (receivers on or above the ground, a given ground below the flight) hold alike."""

import math

import numpy as np
import pytest

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.maps import (
    ChosenGround,
    evaluate_flying,
    evaluate_grid,
    evaluate_grid_fast,
    grid_for_trajectory,
    make_map,
    receivers_for,
)
from gisnoise.model import ModelCard

FRAME = LocalFrame(52.27, 10.52, 0.0)
G0, HR, CRUISE_H = 65.0, 1.5, 150.0
ENGINES = ["numpy", pytest.param("fast", marks=pytest.mark.skipif(
    __import__("importlib").util.find_spec("numba") is None, reason="numba not installed"))]


def omni():
    """G0 dB(A) at 40 m in every direction at the reference power, spherical spreading, every phase."""
    return ModelCard(id="omni", vehicle="test", phase="horizontal", phases=["climb", "sink", "hover"],
                     ansatz="paper-offset", reference_power_w=3000.0,
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0))


def cruise(h=CRUISE_H, n=61, source="cruise", **extra):
    """A cruise northwards at 20 m/s and a constant ellipsoidal height ``h`` (m): in the air throughout."""
    t = np.arange(n, dtype=float)
    lat, lon, hh = FRAME.to_wgs84(np.zeros(n), 20.0 * t - 600.0, np.full(n, h))
    return Trajectory(t=t, lat=lat, lon=lon, h=hh, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=np.full(n, 3000.0),
                      phase=np.full(n, "horizontal"), source=source, **extra)


def hop(end_dh=0.0):
    """On the ground at h = 0 (landed flag at the first sample), climb to 60 m, cruise, sink to ``end_dh`` m still
    flying."""
    n = 61
    t = np.arange(n, dtype=float)
    k = np.arange(n)
    h = np.interp(t, [0.0, 10.0, 50.0, 60.0], [0.0, 60.0, 60.0, end_dh])
    lat, lon, hh = FRAME.to_wgs84(np.zeros(n), 10.0 * t - 300.0, h)
    phase = np.where(k <= 10, "climb", np.where(k >= 50, "sink", "horizontal"))
    return Trajectory(t=t, lat=lat, lon=lon, h=hh, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full(n, 3000.0), phase=phase, on_ground=k == 0, source="hop")


def grid_of(traj, res=20.0):
    return grid_for_trajectory(traj, resolution_m=res, margin_m=200.0)


def refusal(call):
    with pytest.raises(InputError) as err:
        call()
    return err.value


@pytest.mark.parametrize("engine", ENGINES)
def test_a_track_in_the_air_is_refused_by_every_in_memory_call_naming_ground_h(engine):
    """A cruise at 150 m says nothing about the ground: before, evaluate_grid put the receivers 1.5 m under it (its
    lowest point) with a logging warning; now every call refuses it in one line naming ground_h, as make_map does."""
    tr, card = cruise(), omni()
    g = grid_of(tr)
    calls = {"evaluate_grid": lambda: evaluate_grid(tr, card, g, metrics=("LAmax",), engine=engine),
             "evaluate_flying": lambda: evaluate_flying(tr, card, g, metrics=("LAmax",), engine=engine),
             "receivers_for": lambda: receivers_for(g, [tr])}
    if engine == "fast":
        calls["evaluate_grid_fast"] = lambda: evaluate_grid_fast(tr, card, g, metrics=("LAmax",))
    for name, call in calls.items():
        e = refusal(call)
        assert e.field == "ground_h", name
        msg = str(e)
        assert "\n" not in msg and "give ground_h" in msg and "lowest point 150.0 m" in msg, (name, msg)
        assert msg.startswith("cruise: ground unknown: the track neither starts nor ends on the ground"), name
    e = refusal(lambda: make_map(tr, [card], None, outputs=("contours",), grid=g, metrics=("LAmax",)))
    assert e.field == "ground_h" and "--ground-height" in str(e)


@pytest.mark.parametrize("engine", ENGINES)
def test_with_the_ground_given_the_cruise_is_heard_from_its_height(engine):
    """With the ground at 0 m the loudest cell lies under the track, 148.5 m below the source: LAmax = G0 -
    20 lg(148.5 / 40) within the cell-centre offset (at most 14.1 m beside the track on 20 m cells: 0.04 dB), and the
    band is the one make_map gives on the same grid."""
    tr, card = cruise(), omni()
    g = grid_of(tr)
    res = evaluate_grid(tr, card, g, metrics=("LAmax",), ground_h=0.0, engine=engine)
    top = G0 - 20.0 * math.log10((CRUISE_H - HR) / 40.0)
    assert float(np.max(res.bands["LAmax"])) == pytest.approx(top, abs=0.05)
    assert res.metadata["ground_h_m"] == 0.0 and res.metadata["ground_h_source"] == "given"
    mm = make_map(tr, [card], None, outputs=("contours",), grid=g, metrics=("LAmax",), ground_h=0.0, engine=engine)
    np.testing.assert_array_equal(mm["result"].bands["LAmax"], res.bands["LAmax"])


@pytest.mark.parametrize("engine", ENGINES)
def test_a_track_that_takes_off_gives_its_ground_and_a_slice_of_it_in_the_air_does_not(engine):
    """A hop whose first sample stands on the ground (landed flag) gives the ground at that sample: the same bands as
    with that ground given, and the metadata say where it came from.  A minute's slice of it in the air starts and
    ends in cruise: it says nothing about the ground (before, its lowest point, 60 m up, became the ground) and is
    refused; with the ground given it is mapped over the hop's ground."""
    tr, card = hop(), omni()
    g = grid_of(tr)
    own = evaluate_grid(tr, card, g, metrics=("LAmax",), engine=engine)
    given = evaluate_grid(tr, card, g, metrics=("LAmax",), ground_h=float(tr.h[0]), engine=engine)
    np.testing.assert_array_equal(own.bands["LAmax"], given.bands["LAmax"])
    assert own.metadata["ground_h_m"] == float(tr.h[0])
    assert own.metadata["ground_h_source"] == "take-off or landing point of the track"
    part = tr.select((tr.t >= 15.0) & (tr.t <= 45.0))
    e = refusal(lambda: evaluate_grid(part, card, g, metrics=("LAmax",), engine=engine))
    assert e.field == "ground_h" and "lowest point 60.0 m" in str(e)
    sliced = evaluate_grid(part, card, g, metrics=("LAmax",), ground_h=float(tr.h[0]), engine=engine)
    # under the cruise 58.5 m below it; the nearest cell centre lies up to half a diagonal (14.1 m) beside the track
    top = G0 - 20.0 * math.log10((60.0 - HR) / 40.0)
    assert top - 10.0 * math.log10(1.0 + (10.0 * math.sqrt(2.0) / (60.0 - HR)) ** 2) <= float(
        np.max(sliced.bands["LAmax"])) <= top + 1e-6


def test_the_ground_a_route_states_is_taken():
    """A waypoints route states its ground (``metadata["ground_h_m"]``): a cruise in the air throughout is mapped
    over it, and the metadata say so."""
    tr = cruise(metadata={"ground_h_m": 20.0})
    res = evaluate_grid(tr, omni(), grid_of(tr), metrics=("LAmax",), engine="numpy")
    assert res.metadata["ground_h_m"] == 20.0 and res.metadata["ground_h_source"] == "stated by the route"
    top = G0 - 20.0 * math.log10((CRUISE_H - 20.0 - HR) / 40.0)
    assert float(np.max(res.bands["LAmax"])) == pytest.approx(top, abs=0.05)


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize(("kw", "field"), [(dict(receiver_height=-5.0, ground_h=100.0), "receiver_height"),
                                           (dict(receiver_height=float("nan"), ground_h=100.0), "receiver_height"),
                                           (dict(ground_h=200.0), "ground_h"),
                                           (dict(ground_h=float("nan")), "ground_h")])
def test_the_receiver_checks_of_make_map_hold_for_evaluate_grid(engine, kw, field):
    """Receivers below the ground and a ground above a 150 m cruise were mapped without a word by evaluate_grid; it
    refuses them now in make_map's words, and receivers_for (the fast engine's receivers) does alike."""
    tr, card = cruise(), omni()
    g = grid_of(tr)
    mm = refusal(lambda: make_map(tr, [card], None, outputs=("contours",), grid=g, metrics=("LAmax",), **kw))
    ev = refusal(lambda: evaluate_grid(tr, card, g, metrics=("LAmax",), engine=engine, **kw))
    rc = refusal(lambda: receivers_for(g, [tr], **kw))
    assert mm.field == ev.field == rc.field == field
    assert str(mm) == str(ev) == str(rc)


def test_the_flying_stretches_share_the_whole_tracks_ground():
    """A hop that sinks 3 m below its take-off point, still flying, at its end (GPS heights drift): its flying
    stretch alone would land 3 m lower.  evaluate_flying takes the whole track's ground (its take-off point), does
    not refuse the stretch as flying below a given ground, and gives make_map's band."""
    tr, card = hop(end_dh=-3.0), omni()
    g = grid_of(tr, 40.0)
    res = evaluate_flying(tr, card, g, metrics=("LAmax", "SEL"), engine="numpy")
    assert res.metadata["ground_h_m"] == float(tr.h[0])
    assert res.metadata["ground_h_source"] == "take-off or landing point of the track"
    assert res.metadata["flying_stretches"] == [[1.0, 60.0]]
    mm = make_map(tr, [card], None, outputs=("contours",), grid=g, metrics=("LAmax", "SEL"), engine="numpy")
    for name in ("LAmax", "SEL"):
        np.testing.assert_array_equal(mm["result"].bands[name], res.bands[name])
    assert any("below the ground" in w for w in mm["warnings"])
    e = refusal(lambda: evaluate_flying(tr, card, g, metrics=("LAmax",), ground_h=float(tr.h[0]), engine="numpy"))
    assert e.field == "ground_h" and "lies above the track's lowest point" in str(e)


def test_a_chosen_ground_is_taken_as_it_is():
    """A ground chosen once for a whole day or a set of routes (:class:`ChosenGround`) is taken as it is: not
    checked again against the part of a track it is given, and its source reaches the metadata."""
    tr = hop(end_dh=-3.0)
    part = tr.select(tr.t >= 1.0)
    chosen = ChosenGround(float(tr.h[0]), "take-off or landing point of the track")
    res = evaluate_grid(part, omni(), grid_of(tr, 40.0), metrics=("LAmax",), ground_h=chosen, engine="numpy")
    assert res.metadata["ground_h_m"] == float(tr.h[0])
    assert res.metadata["ground_h_source"] == "take-off or landing point of the track"
    assert type(res.metadata["ground_h_m"]) is float
