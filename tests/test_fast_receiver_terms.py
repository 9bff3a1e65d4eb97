"""Receiver-dependent effect terms on the fast engine: the closed forms, the NumPy engine, the floor.

``+atmospheric_absorption``, ``+wind``, ``+doppler`` and ``+ground_reflection`` (and their
chains with ``+bank_angle``, ``+rpm``) run in the kernel of ``gisnoise/maps/_numba_receiver.py``;
the NumPy engine evaluates the model's own definition with the receiver as the microphone.
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from _enginecases import TOL_DB, assert_fast_equals_numpy, extended_cards, floor_across, with_rpm  # noqa: E402
from test_fastkernel import FRAME, card, cases, circle_flight, grid_around  # noqa: E402

from gisnoise.acoustics import speed_of_sound  # noqa: E402
from gisnoise.errors import CardError, InputError  # noqa: E402
from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import WGS84, LocalFrame, transformer  # noqa: E402
from gisnoise.maps import evaluate_grid, fast_engine_serves  # noqa: E402
from gisnoise.maps import fastkernel as fk  # noqa: E402
from gisnoise.model import THIRD_OCTAVE, ModelCard, band_cos, sample_card  # noqa: E402

C15 = float(speed_of_sound(15.0))  # the maps' default temperature (temperature_c=15)

PARAMS = {
    "atmospheric_absorption": dict(a_abs=8.0),
    "wind": dict(w_east=1.5, w_north=-0.7),
    "doppler": dict(q_doppler=2.0),
    "ground_reflection": dict(r_ground=0.8, f_ground=300.0),
    "bank_angle": dict(k_bank=3.0),
    "rpm": dict(k_rpm=1.5, rpm_ref=4000.0),
}


def ext(chain, base=None, **params):
    """The card ``card()`` extended by ``chain`` (``"+a+b"``) with PARAMS, overridden by ``params``."""
    c = base or card()
    p = dict(c.parameters)
    for e in chain.strip("+").split("+"):
        p.update(PARAMS[e])
    p.update(params)
    return ModelCard(id=c.id + chain, vehicle="test", phase=c.phase, ansatz=c.ansatz + chain, parameters=p,
                     reference_power_w=c.reference_power_w)


def hover(n=5, east=0.0, north=0.0, height=60.0, dt=1.0):
    t = np.arange(n) * dt
    lat, lon, h = FRAME.to_wgs84(np.full(n, east), np.full(n, north), np.full(n, height))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(n), pitch=np.zeros(n), yaw=np.full(n, 20.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))


def receivers_enu(grid, hr):
    """ENU positions (m) of the grid's receivers in the test frame (the grid is centred on its origin)."""
    x, y = grid.flat_centres(0, grid.n_cells)
    lon, lat = transformer(grid.crs, WGS84).transform(x, y)
    return np.stack(FRAME.to_enu(lat, lon, np.full(lat.shape, hr)), axis=-1).reshape(grid.shape + (3,))


def snap_diff(traj, chain_card, grid, t_s, hr=1.5, **kw):
    """Snapshot level of ``chain_card`` minus that of its base card (fast engine), dB."""
    base = evaluate_grid(traj, [card()], grid, ground_h=0.0, engine="fast", snapshot_t=t_s, metrics=(),
                         receiver_height=hr, **kw)
    extd = evaluate_grid(traj, [chain_card], grid, ground_h=0.0, engine="fast", snapshot_t=t_s, metrics=(),
                         receiver_height=hr, **kw)
    name = next(iter(extd.bands))
    return extd.bands[name] - base.bands[name]


# --------------------------------------------------------------------------- the pieces


def test_band_cos_of_the_kernel_equals_the_model():
    from gisnoise.maps._numba_receiver import _band_cos_points

    u = np.concatenate([np.linspace(0.0, 2e-3, 2001), np.linspace(0.0, 40.0, 40001), np.linspace(40.0, 4000.0, 40001)])
    ref, _ = band_cos(u, False)
    assert np.max(np.abs(_band_cos_points(u).astype(float) - ref)) < 2e-6
    # a known value: C vanishes where sin(a2 u) = sin(a1 u), at u = pi / (a1 + a2)
    a1, a2 = THIRD_OCTAVE
    assert abs(float(_band_cos_points(np.array([math.pi / (a1 + a2)]))[0])) < 1e-6


def test_absorption_follows_the_distance_to_each_receiver():
    # -a_abs (d - d_ref) / 1000 with d the receiver's distance from the hovering UAV (paper 5.3.3)
    traj, g = hover(height=20.0), grid_around(40.0, 31, 31)
    diff = snap_diff(traj, ext("+atmospheric_absorption", a_abs=12.0), g, 2.0)
    d = np.linalg.norm(receivers_enu(g, 1.5) - np.array([0.0, 0.0, 20.0]), axis=-1)
    np.testing.assert_allclose(diff, -12.0 * (d - 40.0) / 1000.0, atol=1e-3)
    assert diff.max() > 0.2 and diff.min() < -6.0  # cells nearer and farther than d_ref = 40 m


def test_wind_adds_along_the_direction_of_propagation():
    # (d / 100 m)(w_east e_east + w_north e_north), e the horizontal unit vector UAV -> receiver
    traj, g = hover(east=-35.0, north=20.0), grid_around(30.0, 25, 21)
    diff = snap_diff(traj, ext("+wind", w_east=2.0, w_north=-1.0), g, 2.0)
    r = receivers_enu(g, 1.5) - np.array([-35.0, 20.0, 60.0])
    h = r[..., :2] / np.maximum(np.hypot(r[..., 0], r[..., 1]), 1.0)[..., None]
    want = np.linalg.norm(r, axis=-1) / 100.0 * (2.0 * h[..., 0] - 1.0 * h[..., 1])
    np.testing.assert_allclose(diff, want, atol=1e-3)


def test_doppler_amplifies_ahead_and_attenuates_behind():
    # straight and level at 25 m/s east: -q 10 lg(1 - M_r), M_r = v . r / (d c), c at 15 C
    n, v = 21, 25.0
    t = np.arange(n) * 1.0
    lat, lon, h = FRAME.to_wgs84(-250.0 + v * t, np.full(n, 10.0), np.full(n, 50.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(n), pitch=np.zeros(n), yaw=np.full(n, 90.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))
    g = grid_around(25.0, 41, 17)
    diff = snap_diff(traj, ext("+doppler", q_doppler=2.0), g, 10.0)  # the UAV at (0, 10, 50)
    r = receivers_enu(g, 1.5) - np.array([0.0, 10.0, 50.0])
    mr = v * r[..., 0] / np.linalg.norm(r, axis=-1) / C15
    np.testing.assert_allclose(diff, -20.0 * np.log10(1.0 - mr), atol=1e-3)
    assert diff[:, -1].min() > 0.4 and diff[:, 0].max() < -0.4  # ahead louder, behind quieter


def test_ground_reflection_comb_at_a_known_receiver_height():
    # straight below the hovering UAV tau = 2 h_r / c; at f_g = 1 / (2 (a1 + a2) tau) the band-averaged
    # cosine vanishes and the term is 10 lg(1 + R^2): 3.0103 dB for R = 1
    hr = 1.5
    a1, a2 = THIRD_OCTAVE
    f = C15 / (2.0 * (a1 + a2) * 2.0 * hr)
    traj, g = hover(height=80.0), grid_around(20.0, 21, 21)  # cell (10, 10) straight below the UAV
    diff = snap_diff(traj, ext("+ground_reflection", r_ground=1.0, f_ground=f), g, 2.0, hr=hr)
    assert diff[10, 10] == pytest.approx(10.0 * math.log10(2.0), abs=1e-3)
    # with a low comb frequency every path is nearly in phase: close to the largest gain 20 lg(1 + R)
    low = snap_diff(traj, ext("+ground_reflection", r_ground=1.0, f_ground=20.0), g, 2.0, hr=hr)
    u = 2 * math.pi * 20.0 * 2 * hr / C15
    assert low[10, 10] == pytest.approx(10.0 * math.log10(2.0 + 2.0 * float(band_cos(u, False)[0])), abs=1e-3)
    assert np.all(low <= 20.0 * math.log10(2.0) + 1e-4)
    # receivers lower than 0.3 m count as on the ground: no term
    flat = snap_diff(traj, ext("+ground_reflection", r_ground=1.0, f_ground=f), g, 2.0, hr=0.2)
    assert np.max(np.abs(flat)) < 1e-4


# --------------------------------------------------------------------------- against the NumPy engine


def test_chain_matches_numpy_with_thresholds_snapshot_dem_and_default_engine():
    traj = circle_flight(50, phases=("horizontal", "climb"))
    rpm = np.linspace(3000.0, 5000.0, len(traj))
    traj = Trajectory(**{k: getattr(traj, k) for k in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w",
                                                         "phase")}, rpm=rpm)
    cards = [ext("+bank_angle+ground_reflection+doppler"),
             ext("+rpm+atmospheric_absorption+wind", base=card("climb", ansatz="paper", p1=70.0))]
    assert fast_engine_serves(cards) is None
    g = grid_around(15.0, 51, 43)
    rng = np.random.default_rng(4)
    dem = 3.0 + 20.0 * rng.random(g.shape)
    kw = dict(dem=dem, threshold_db=[50.0, 58.0], snapshot_t=21.5, substeps=2, receiver_height=4.0,
              temperature_c=-5.0, check_cards=False)
    ref = evaluate_grid(traj, cards, g, engine="numpy", **kw)
    fast = evaluate_grid(traj, cards, g, **kw)  # the default engine
    assert fast.metadata["engine"] == "fast"
    assert fast.metadata["speed_of_sound_m_s"] == ref.metadata["speed_of_sound_m_s"]
    assert list(fast.bands) == list(ref.bands)
    for name in ("LAmax", "LAeq", "SEL", "LA@21.5s"):
        assert np.max(np.abs(ref.bands[name] - fast.bands[name])) <= TOL_DB, name
    for name in ("TA50", "TA58"):
        assert np.max(np.abs(ref.bands[name] - fast.bands[name])) < 0.02


def test_window_tiles_and_threads_give_bitwise_the_same_cells():
    traj = circle_flight(25)
    g = grid_around(3.0, 800, 23)
    rc = fk.receivers_for(g, [traj], ground_h=0.0)
    fl = fk.prepare_flight(traj, [ext("+ground_reflection+doppler+atmospheric_absorption")], rc.frame,
                           floor_db=25.0)
    assert fl.rx is not None
    whole = fk.run_grid(fl, rc, [50.0], threads=1)
    two = fk.run_grid(fl, rc, [50.0], threads=2, chunk_cells=600)
    np.testing.assert_array_equal(whole.emax, two.emax)
    np.testing.assert_array_equal(whole.energy, two.energy)
    k = rc.seg
    for r0, r1, c0, c1 in ((0, 7, 0, k), (7, 23, k, 2 * k), (3, 9, 2 * k, 800)):
        w = fk.run_window(fl, rc, r0, r1, c0, c1, [50.0])
        np.testing.assert_array_equal(w.emax, whole.emax[r0:r1, c0:c1])
        np.testing.assert_array_equal(w.energy, whole.energy[r0:r1, c0:c1])
        np.testing.assert_array_equal(w.ta, whole.ta[:, r0:r1, c0:c1])


def test_what_stays_refused_is_refused_in_one_line():
    # faster than sound: the Doppler term is undefined; refused, naming the field
    n = 4
    t = np.arange(n) * 1.0
    lat, lon, h = FRAME.to_wgs84(400.0 * t, np.zeros(n), np.full(n, 50.0))
    fast = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(n), pitch=np.zeros(n), yaw=np.full(n, 90.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))
    with pytest.raises(InputError, match="speed of sound") as err:
        evaluate_grid(fast, [ext("+doppler")], grid_around(50.0, 5, 5), ground_h=0.0)
    assert err.value.field == "trajectory" and "\n" not in str(err.value)
    # with measured hemisphere cards in the same request: the NumPy engine (auto says why)
    hemi = sample_card(card("climb"))
    why = fast_engine_serves([ext("+ground_reflection"), hemi])
    assert why is not None and "hemisphere" in why
    with pytest.raises(CardError, match="hemisphere") as cerr:
        evaluate_grid(circle_flight(6, phases=("horizontal", "climb")), [ext("+ground_reflection"), hemi],
                      grid_around(50.0, 5, 5), ground_h=0.0, engine="fast")
    assert cerr.value.field == "ansatz"


# --------------------------------------------------------------------------- the audibility floor


def test_floor_radius_counts_the_largest_gain_of_the_ground_reflection():
    # R = 1 at a low comb frequency adds up to 20 lg 2 = 6 dB near the UAV: cells whose base level
    # lies below the floor but whose level with the reflection reaches it must be computed
    traj, g = hover(n=4, height=30.0), grid_around(40.0, 101, 101)
    omni = card(p2=0.0, p4=0.0)  # no directivity: the base card's radius is tight
    refl = ext("+ground_reflection", base=omni, r_ground=1.0, f_ground=20.0)
    base_ref = evaluate_grid(traj, [omni], g, ground_h=0.0, engine="numpy", metrics=("LAmax",))
    ext_ref = evaluate_grid(traj, [refl], g, ground_h=0.0, engine="numpy", metrics=("LAmax",))
    floor = 66.0 - 20.0 * math.log10(750.0 / 40.0)  # the base card's level 750 m from the UAV
    gained = (base_ref.bands["LAmax"] < floor) & (ext_ref.bands["LAmax"] >= floor)
    assert gained.sum() > 50
    base_fast = evaluate_grid(traj, [omni], g, ground_h=0.0, floor_db=floor, metrics=("LAmax",))
    assert np.isnan(base_fast.bands["LAmax"][gained]).any()  # the base card's radius would skip them
    fast = evaluate_grid(traj, [refl], g, ground_h=0.0, floor_db=floor, metrics=("LAmax",))
    assert np.isfinite(fast.bands["LAmax"][gained]).all()
    skipped = np.isnan(fast.bands["LAmax"])
    assert skipped.any() and np.all(ext_ref.bands["LAmax"][skipped] < floor)
    ok = ~skipped
    assert np.max(np.abs(fast.bands["LAmax"][ok] - ext_ref.bands["LAmax"][ok])) <= TOL_DB


def test_floor_with_absorption_skips_more_and_wind_skips_nothing():
    traj, g = hover(n=4, height=40.0), grid_around(60.0, 101, 101)
    floor = 45.0
    quiet = card(p2=0.03, p4=-0.05)  # about the demo cards' directivity
    plain = evaluate_grid(traj, [quiet], g, ground_h=0.0, floor_db=floor, metrics=("LAmax",))
    absorb = ext("+atmospheric_absorption", base=quiet, a_abs=20.0)
    fast = evaluate_grid(traj, [absorb], g, ground_h=0.0, floor_db=floor, metrics=("LAmax",))
    ref = evaluate_grid(traj, [absorb], g, ground_h=0.0, engine="numpy", metrics=("LAmax",))
    skipped = np.isnan(fast.bands["LAmax"])
    assert fast.metadata["cells_below_floor"] > plain.metadata["cells_below_floor"] > 0
    assert np.all(ref.bands["LAmax"][skipped] < floor)
    assert np.max(np.abs(fast.bands["LAmax"][~skipped] - ref.bands["LAmax"][~skipped])) <= TOL_DB
    # wind grows with distance (downwind): no radius bounds it, so no cell is skipped
    windy = evaluate_grid(traj, [ext("+wind", base=quiet)], g, ground_h=0.0, floor_db=floor, metrics=("LAmax",))
    assert windy.metadata["cells_below_floor"] == 0


# --------------------------------------------------------------------------- hypothesis: every term and chain

KINDS = ["+atmospheric_absorption", "+wind", "+doppler", "+ground_reflection",
         "+ground_reflection+doppler", "+bank_angle+ground_reflection+doppler",
         "+atmospheric_absorption+wind+doppler+ground_reflection", "+rpm+wind+bank_angle",
         "+doppler+rpm+atmospheric_absorption"]


@st.composite
def receiver_cases(draw):
    traj, cards, grid, kw, floor_q = draw(cases())
    # retimed to at most 90 m/s between samples (subsonic: the Doppler term is defined)
    e, nn, u = LocalFrame(traj.lat[0], traj.lon[0], 0.0).to_enu(traj.lat, traj.lon, traj.h)
    step = np.hypot(np.hypot(np.diff(e), np.diff(nn)), np.diff(u))
    dt = np.maximum(np.diff(traj.t), step / 90.0)
    traj = with_rpm(draw, traj, np.concatenate([[0.0], np.cumsum(dt)]))
    out = extended_cards(draw, cards, draw(st.sampled_from(KINDS)))
    kw = dict(kw, receiver_height=draw(st.sampled_from([0.2, 1.5, 4.0])) + draw(st.floats(0.0, 2.0)),
              temperature_c=draw(st.floats(-20.0, 40.0)))
    return traj, out, grid, kw, floor_q


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(receiver_cases())
def test_fast_equals_numpy_for_receiver_dependent_terms(case):
    traj, cards, grid, kw, floor_q = case
    kw = dict(kw, check_cards=False)  # random synthetic cards: the engines are compared, not the cards judged
    snap = float(traj.t[len(traj) // 2])
    ref = evaluate_grid(traj, cards, grid, engine="numpy", snapshot_t=snap, **kw)
    floor = floor_across(ref, floor_q)
    fast = evaluate_grid(traj, cards, grid, snapshot_t=snap, floor_db=floor, **kw)
    assert_fast_equals_numpy(ref, fast, floor, snapshot=True)


# --------------------------------------------------------------------------- the command


def test_contour_default_engine_is_fast_for_a_chain_and_equals_numpy(tmp_path):
    import json
    from pathlib import Path

    import rasterio
    from click.testing import CliRunner

    from gisnoise.cli.main import cli
    from gisnoise.model import load, save

    root = Path(__file__).resolve().parents[1]
    chain = "+bank_angle+ground_reflection+doppler"
    paths = []
    for ph in ("horizontal", "climb", "sink"):
        c = load(root / f"gisnoise/data/cards/demo_{ph}.json")
        p = dict(c.parameters, k_bank=3.0, r_ground=0.7, f_ground=400.0, q_doppler=2.0)
        c = ModelCard(id=c.id + "-ext", vehicle=c.vehicle, phase=c.phase, phases=c.phases, ansatz=c.ansatz + chain,
                      parameters=p, reference_power_w=c.reference_power_w)
        paths.append(save(c, tmp_path / f"{ph}.json"))
    bands = {}
    for engine in ("auto", "numpy"):
        out = tmp_path / engine
        args = ["contour", str(root / "gisnoise/data/routes/delivery_route.geojson"), "--out", str(out),
                "--resolution", "50", "--margin", "300", "--receiver-height", "4", "--engine", engine]
        for pth in paths:
            args += ["--card", str(pth)]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        with rasterio.open(out / "levels.tif") as ds:
            meta = json.loads(ds.tags()["gisnoise"])
            bands[engine] = {d: ds.read(i + 1) for i, d in enumerate(ds.descriptions)}
        assert meta["engine"] == ("fast" if engine == "auto" else "numpy")
        assert f"engine {meta['engine']}" in res.output
    for name in ("LAmax", "LAeq", "SEL"):
        np.testing.assert_allclose(bands["auto"][name], bands["numpy"][name], atol=TOL_DB, err_msg=name)


def test_a_day_of_operations_with_receiver_terms_equals_the_map_of_its_flight():
    from affine import Affine
    from test_fastkernel import TMERC

    from gisnoise.geo import GridSpec
    from gisnoise.ops import Flight, Schedule, evaluate_operations

    n = 40
    t = np.arange(n) * 1.0
    lat, lon, h = FRAME.to_wgs84(-400.0 + 20.0 * t, np.full(n, 30.0), np.full(n, 60.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(n, 10.0), pitch=np.zeros(n), yaw=np.full(n, 90.0),
                      power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"), source="line")
    c = ext("+bank_angle+ground_reflection+doppler+atmospheric_absorption")
    grid = GridSpec(TMERC, Affine(10.0, 0.0, -600.0, 0.0, -10.0, 300.0), 120, 60)
    sched = Schedule(flights=(Flight("a", traj, {"day": 1}),), cards=[c], grid=grid, ground_h_m=0.0,
                     receiver_height_m=4.0, floor_db=30.0)
    tiles = evaluate_operations(sched, threads=2, single_process=True, tile_cells=1500)
    whole = evaluate_operations(sched, threads=1, single_process=True, tile_cells=10**6)
    assert tiles.metadata["tiles"] > 1
    for name, band in whole.bands.items():  # tiles on the kernel's segments: the same bits
        assert np.array_equal(tiles.bands[name], band, equal_nan=True), name
    ref = evaluate_grid(traj, [c], grid, ground_h=0.0, receiver_height=4.0, engine="numpy", metrics=("LAmax",))
    ok = np.isfinite(whole.bands["LAmax"])
    assert ok.mean() > 0.5
    assert np.max(np.abs(whole.bands["LAmax"][ok] - ref.bands["LAmax"][ok])) <= TOL_DB
