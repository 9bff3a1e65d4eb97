"""Maps of measured hemispheres: the M300 flyover by both engines against the table, mixed with parametric cards."""

import numpy as np
import pytest
from test_evaluate import centred_grid, omni_card, straight_flight
from test_hemisphere import M300, node_level

from gisnoise.errors import InputError
from gisnoise.maps import evaluate_grid
from gisnoise.model import import_hemisphere

openpyxl = pytest.importorskip("openpyxl")
numba = pytest.importorskip("numba")

H, V, N0, N1, DT = 10.0, 5.0, -300.0, 300.0, 0.05


@pytest.fixture(scope="module")
def sheets():
    from test_hemisphere import sheets as fx
    return fx.__wrapped__()


@pytest.fixture(scope="module")
def m300():
    return import_hemisphere(M300)


@pytest.fixture(scope="module")
def flyover(m300):
    traj = straight_flight(v=V, height=H, n0=N0, n1=N1, dt=DT)
    grid = centred_grid(5.0, 9, 3)  # receivers on the ground under the track and beside it
    kw = dict(ground_h=0.0, receiver_height=0.0, metrics=("LAmax", "LAeq", "SEL"))
    ref = evaluate_grid(traj, [m300], grid, engine="numpy", **kw)
    fast = evaluate_grid(traj, [m300], grid, engine="fast", **kw)
    return traj, grid, ref, fast


def under_track_truth(sheets):
    """LAmax and SEL at the receiver under the track from the file's table (column theta = 0)."""
    phi, theta, _ = sheets["1000"]
    j = theta.index(0.0)
    t = np.arange(0.0, (N1 - N0) / V + 1e-9, DT)
    n = N0 + V * t
    d = np.hypot(n, H)
    a = np.degrees(np.arctan2(n, H))  # drone before the receiver: the receiver is ahead, negative phi
    lv = np.empty(n.size)
    for k, (ak, dk) in enumerate(zip(a, d, strict=True)):
        i = min(max(int(np.searchsorted(phi, ak, side="right")) - 1, 0), len(phi) - 2)
        w = (ak - phi[i]) / (phi[i + 1] - phi[i])
        lv[k] = (1 - w) * node_level(sheets, i, j, dk) + w * node_level(sheets, i + 1, j, dk)
    wts = np.zeros(t.size)
    wts[:-1] += 0.5 * DT
    wts[1:] += 0.5 * DT
    return float(lv.max()), float(10 * np.log10(np.sum(wts * 10 ** (lv / 10))))


def test_flyover_both_engines_agree_and_match_the_table(flyover, sheets):
    traj, grid, ref, fast = flyover
    for name in ("LAmax", "LAeq", "SEL"):
        np.testing.assert_allclose(fast.bands[name], ref.bands[name], atol=0.01)
    r, c = 1, 4  # the cell centred on the track at n = 0
    lamax, sel = under_track_truth(sheets)
    assert ref.bands["LAmax"][r, c] == pytest.approx(lamax, abs=0.01)
    assert ref.bands["SEL"][r, c] == pytest.approx(sel, abs=0.01)
    assert fast.bands["LAmax"][r, c] == pytest.approx(lamax, abs=0.01)
    assert fast.bands["SEL"][r, c] == pytest.approx(sel, abs=0.01)
    share = fast.metadata["hemisphere_filled_energy_share"]
    assert 0.0 < share < 1.0
    assert ref.metadata["hemisphere_filled_energy_share"] == pytest.approx(share, abs=1e-6)


def test_hemisphere_and_parametric_cards_mix_by_phase(m300):
    import dataclasses
    hemi = dataclasses.replace(m300, phase="horizontal")
    climb = omni_card("climb")
    traj = straight_flight(v=V, height=H, n0=-100.0, n1=100.0, dt=0.1)
    ph = np.where(np.arange(len(traj)) < len(traj) // 2, "climb", "horizontal")
    traj = dataclasses.replace(traj, phase=ph)
    grid = centred_grid(10.0, 5, 5)
    kw = dict(ground_h=0.0, receiver_height=1.5, metrics=("LAmax", "SEL"))
    ref = evaluate_grid(traj, [hemi, climb], grid, engine="numpy", **kw)
    fast = evaluate_grid(traj, [hemi, climb], grid, engine="fast", **kw)
    for name in ("LAmax", "SEL"):
        np.testing.assert_allclose(fast.bands[name], ref.bands[name], atol=0.01)
    only_h = evaluate_grid(traj, [hemi, dataclasses.replace(hemi, id="h2", phase="climb")], grid, **kw)
    assert not np.allclose(only_h.bands["SEL"], ref.bands["SEL"], atol=0.1)  # the climb half uses the omni card
    assert set(ref.metadata["phases"]) == {"climb", "horizontal"}


def test_fast_engine_time_above_snapshot_and_floor_agree_with_numpy(m300):
    """Time above levels, a snapshot and the audibility floor on the fast hemisphere path equal the reference."""
    traj = straight_flight(v=V, height=H, n0=-150.0, n1=150.0, dt=0.25)
    grid = centred_grid(20.0, 11, 41)  # 200 m along the track, 800 m across
    kw = dict(ground_h=0.0, receiver_height=1.5, metrics=("LAmax", "LAeq"), threshold_db=[45.0, 60.0],
              snapshot_t=30.0)
    ref = evaluate_grid(traj, [m300], grid, engine="numpy", **kw)
    fast = evaluate_grid(traj, [m300], grid, engine="fast", **kw)
    assert fast.metadata["engine"] == "fast"
    for name in ("LAmax", "LAeq", "LA@30s"):
        np.testing.assert_allclose(fast.bands[name], ref.bands[name], atol=0.01)
    for name in ("TA45", "TA60"):  # time above: linear between instants, a level 0.01 dB off moves a crossing
        np.testing.assert_allclose(fast.bands[name], ref.bands[name], atol=0.01)
    assert np.nanmax(ref.bands["TA45"]) > 10.0 and np.nanmin(ref.bands["TA60"]) == 0.0
    # floor: cells certainly below it are skipped (NaN), the others exact
    floor = 50.0
    fl = evaluate_grid(traj, [m300], grid, engine="fast", floor_db=floor, **kw)
    skipped = np.isnan(fl.bands["LAmax"])
    assert fl.metadata["cells_below_floor"] == int(skipped.sum()) > 0
    assert np.all(ref.bands["LAmax"][skipped] < floor)
    np.testing.assert_allclose(fl.bands["LAmax"][~skipped], ref.bands["LAmax"][~skipped], atol=0.01)


def test_fast_engine_refuses_cells_beyond_the_tables_reach(m300):
    from gisnoise.maps import receivers_for
    from gisnoise.maps.hemisource import prepare_flight, run_hemi_window

    traj = straight_flight(v=V, height=H, n0=-20.0, n1=20.0, dt=0.5)
    grid = centred_grid(100.0, 21, 3)  # 2.1 km wide
    rc = receivers_for(grid, [traj], ground_h=0.0)
    fl = prepare_flight(traj, [m300], rc.frame, reach_m=500.0)
    with pytest.raises(InputError, match="reach") as e:
        run_hemi_window(fl, rc, 0, 3, 0, 21)
    assert e.value.field == "grid"


def test_operations_tiles_take_a_hemisphere_card(m300):
    """A day with an M300 flight: the tiles' Lday and TA equal the NumPy engine's single-flight map times the count."""
    import dataclasses

    from gisnoise.ops import Flight, Schedule, evaluate_operations

    traj = dataclasses.replace(straight_flight(v=V, height=H, n0=-150.0, n1=150.0, dt=0.5), source="m300")
    grid = centred_grid(25.0, 12, 9)
    count = 7
    sched = Schedule(flights=(Flight("m300", traj, {"day": count}),), cards=[m300], grid=grid, ground_h_m=0.0,
                     thresholds_db=(55.0,), receiver_height_m=1.5)
    ops = evaluate_operations(sched, threads=1, tile_cells=40)  # several tiles
    assert ops.metadata["tiles"] > 1
    ref = evaluate_grid(traj, [m300], grid, engine="numpy", ground_h=0.0, receiver_height=1.5,
                        metrics=("LAmax", "SEL"), threshold_db=55.0)
    day_s = 12 * 3600.0  # the directive's day: 07-19 h
    lday = ref.bands["SEL"] + 10 * np.log10(count / day_s)
    np.testing.assert_allclose(ops.bands["Lday"], lday, atol=0.01)
    np.testing.assert_allclose(ops.bands["LAmax"], ref.bands["LAmax"], atol=0.01)
    np.testing.assert_allclose(ops.bands["TA55"], count * ref.bands["TA55"], atol=0.01 * count)


def test_two_hemisphere_cards_and_a_parametric_card_by_phase(m300):
    """Several hemisphere cards in one flight (their tables side by side) and a parametric card: fast == NumPy."""
    import dataclasses

    from gisnoise.model import sample_card

    climb = dataclasses.replace(sample_card(omni_card("climb"), phi_deg=np.arange(-90.0, 91.0, 30.0),
                                            theta_deg=np.array([-90.0, -20.0, 0.0, 45.0, 90.0])), phase="climb")
    sink = omni_card("sink")
    traj = straight_flight(v=V, height=H, n0=-90.0, n1=90.0, dt=0.2)
    n = len(traj)
    ph = np.where(np.arange(n) < n // 3, "climb", np.where(np.arange(n) < 2 * n // 3, "horizontal", "sink"))
    traj = dataclasses.replace(traj, phase=ph)
    grid = centred_grid(15.0, 9, 7)
    kw = dict(ground_h=0.0, receiver_height=1.5, metrics=("LAmax", "SEL"), threshold_db=50.0)
    ref = evaluate_grid(traj, [m300, climb, sink], grid, engine="numpy", **kw)
    fast = evaluate_grid(traj, [m300, climb, sink], grid, engine="fast", **kw)
    for name in ("LAmax", "SEL", "TA50"):
        np.testing.assert_allclose(fast.bands[name], ref.bands[name], atol=0.01)
    assert fast.metadata["hemisphere_filled_energy_share"] == pytest.approx(
        ref.metadata["hemisphere_filled_energy_share"], abs=1e-4)


def test_auto_engine_takes_the_fast_engine_for_hemisphere_cards(m300):
    from gisnoise.maps import fast_engine_serves

    assert fast_engine_serves([m300, omni_card("climb")]) is None
    traj = straight_flight(v=V, height=H, n0=-20.0, n1=20.0, dt=0.5)
    res = evaluate_grid(traj, [m300], centred_grid(10.0, 3, 3), ground_h=0.0, metrics=("LAmax",))
    assert res.metadata["engine"] == "fast"
    assert fast_engine_serves([m300], uncertainty=True) is not None


def test_a_phase_no_card_serves_names_the_way_a_hemisphere_serves_it(m300):
    """The M300 table stands for horizontal flight: a climb it does not serve is refused naming the samples, and,
    since a hemisphere card is among the cards, how to import it for that phase too; parametric cards alone get
    no such tip."""
    from gisnoise.errors import CardError
    from gisnoise.maps import CardSet

    phase = np.array(["horizontal"] * 3 + ["climb"] * 2)
    with pytest.raises(CardError) as e:
        CardSet([m300]).assign(phase)
    assert "no model card serves phase 'climb' (2 samples, samples 3-4)" in str(e.value)
    assert str(e.value).endswith("(a measured hemisphere serves further phases when imported with gisnoise card "
                                 "import-hemisphere ... --also-phase climb)")
    with pytest.raises(CardError) as e:
        CardSet([omni_card("horizontal")]).assign(phase)
    assert "--also-phase" not in str(e.value)


def _one_level_table(phi, theta, card_id, phase="horizontal"):
    """80 dB at 1 m in one band (1 kHz) at every node, every node measured."""
    from gisnoise.model import HemisphereCard

    return HemisphereCard(id=card_id, vehicle="v", phase=phase, ansatz="hemisphere", parameters={},
                          reference_power_w=1.0, reference_distance_m=1.0, phi_deg=phi, theta_deg=theta,
                          bands_hz=[1000.0], levels_db=np.full((1, len(phi), len(theta)), 80.0),
                          measured=np.ones((len(phi), len(theta)), bool))


def _passes(n_passes):
    """Passes at 30 m over the grid's centre line at 15 m/s (6 m between samples; none level with a cell centre),
    north, then south after 5 s without power; phases horizontal, then hover."""
    from test_evaluate import FRAME

    from gisnoise.flight import Trajectory

    n = np.arange(-150.0, 150.1, 6.0)
    parts = [n, np.full(13, 150.0), n[::-1]][:2 * n_passes - 1]
    north = np.concatenate(parts)
    t = np.arange(north.size) * 0.4
    power = np.concatenate([np.full(p.size, 0.0 if k == 1 else 3000.0) for k, p in enumerate(parts)])
    phase = np.concatenate([np.full(p.size, "hover" if k == 2 else "horizontal") for k, p in enumerate(parts)])
    lat, lon, h = FRAME.to_wgs84(0 * t, north, np.full(t.size, 30.0))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=power, phase=phase,
                      source="passes")


def test_a_map_mostly_from_unmeasured_directions_says_so(tmp_path):
    """A table of the quarter phi, theta 0..90 deg (behind and starboard) at one level: over a grid symmetric about a
    straight pass, fore and aft, port and starboard give the same energy, so 3/4 of it comes from the directions
    beyond the table (its edge values, filled): above the half that makes the map say so; the full table: none."""
    from test_evaluate import centred_grid

    from gisnoise.maps import make_map
    from gisnoise.maps.hemifill import FILLED_SHARE_WARNING

    grid = centred_grid(10.0, 20, 20)  # even: no cell centre on the track or level with a sample
    kw = dict(metrics=["LAmax", "SEL"], ground_h=0.0, grid=grid, engine="numpy")
    quarter = _one_level_table([0.0, 45.0, 90.0], [0.0, 45.0, 90.0], "quarter")
    out = make_map(_passes(1), [quarter], tmp_path / "q", **kw)
    meta = out["result"].metadata
    assert meta["hemisphere_filled_energy_share"] == pytest.approx(0.75, abs=0.005)
    (w,) = [w for w in out["warnings"] if w.startswith("hemisphere: ")]
    assert "75 % of the map's sound energy came from table directions that were not measured" in w
    assert meta["warnings"] == out["warnings"]
    full = _one_level_table([-90.0, 0.0, 90.0], [-90.0, 0.0, 90.0], "full")
    out = make_map(_passes(1), [full], tmp_path / "f", **kw)
    assert out["result"].metadata["hemisphere_filled_energy_share"] == 0.0
    assert not [w for w in out["warnings"] if w.startswith("hemisphere: ")] and FILLED_SHARE_WARNING == 0.5


def test_the_filled_share_of_a_flight_that_lands_between_passes_weighs_both_passes():
    """Pass 1 with the quarter table (share 3/4), pass 2 with the full table at the same level (share 0) over the
    same line: the two passes bring the same energy, so the map's share is 3/8 (it was the first pass's alone)."""
    from test_evaluate import centred_grid

    from gisnoise.maps import evaluate_flying

    traj = _passes(2)
    assert not traj.flying.all() and traj.flying.sum() == 2 * 51
    cards = [_one_level_table([0.0, 45.0, 90.0], [0.0, 45.0, 90.0], "quarter"),
             _one_level_table([-90.0, 0.0, 90.0], [-90.0, 0.0, 90.0], "full", phase="hover")]
    res = evaluate_flying(traj, cards, centred_grid(10.0, 20, 20), metrics=["SEL"], ground_h=0.0, engine="numpy")
    assert res.metadata["hemisphere_filled_energy_share"] == pytest.approx(0.375, abs=0.003)
