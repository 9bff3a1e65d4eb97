"""The fast engine against the ansatz registry and the reference NumPy evaluator."""

import math

import numpy as np
import pytest
from affine import Affine
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from _enginecases import TOL_DB, assert_fast_equals_numpy, extended_cards, floor_across, with_rpm  # noqa: E402

from gisnoise.errors import CardError, InputError  # noqa: E402
from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import (  # noqa: E402
    GridSpec,
    LocalFrame,  # noqa: E402
    utm_crs,
)
from gisnoise.maps import evaluate_grid  # noqa: E402
from gisnoise.maps import fastkernel as fk  # noqa: E402
from gisnoise.model import ModelCard, get_ansatz  # noqa: E402

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)


def card(phase="horizontal", ansatz="paper-offset", **p):
    base = dict(p0=66.0, p1=20.0, p2=0.15, p3=-0.28, p4=-0.3, p5=1.05, p6=1.0, p7=40.0)
    base.update(p)
    if ansatz == "paper":
        base.pop("p0")
    return ModelCard(id=f"{ansatz}-{phase}", vehicle="test", phase=phase, ansatz=ansatz, parameters=base,
                     reference_power_w=3000.0)


def circle_flight(n=60, radius=300.0, height=60.0, dt=1.0, roll=12.0, phases=("horizontal",)):
    t = np.arange(n) * dt
    ang = 20.0 * t / radius
    lat, lon, h = FRAME.to_wgs84(radius * np.sin(ang), radius * np.cos(ang), np.full(n, height))
    ph = np.array([phases[i * len(phases) // n] for i in range(n)])
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(n, roll), pitch=np.full(n, 4.0),
                      yaw=np.degrees(ang) + 90.0, power_w=3000.0 * (1 + 0.3 * np.sin(t / 7)), phase=ph)


def grid_around(res, nx, ny, x0=0.0, y0=0.0):
    return GridSpec(TMERC, Affine(res, 0.0, x0 - res * nx / 2, 0.0, -res, y0 + res * ny / 2), nx, ny)


def assert_levels_equal(ref, fast, names=("LAmax", "LAeq", "SEL"), tol=TOL_DB):
    for name in names:
        a, b = ref.bands[name], fast.bands[name]
        both = np.isfinite(a) & np.isfinite(b)
        assert both.any()
        assert np.max(np.abs(a[both] - b[both])) <= tol, name


# --------------------------------------------------------------------------- pieces


def test_polynomials_are_accurate_to_float32():
    # the Chebyshev interpolants the kernel evaluates, in float32 as the kernel does
    f = np.linspace(-0.5, 0.5, 100001)
    assert np.max(np.abs(fk._poly_eval(fk._EXP2_C, f) / 2.0 ** f - 1.0)) < 5e-7
    u = np.linspace(math.sqrt(0.5) - 1, math.sqrt(2.0) - 1, 100001)
    assert np.max(np.abs(fk._poly_eval(fk._LOG2_C, u) - np.log2(1 + u))) < 3e-7
    a = np.linspace(0.0, 1.0, 100001)
    assert np.max(np.abs(a * fk._poly_eval(fk._ATAN_C, a * a) - np.arctan(a))) < 1e-6


@pytest.mark.parametrize("ansatz", ["paper", "paper-offset"])
def test_kernel_level_equals_the_registry_ansatz(ansatz):
    # one model definition: the kernel's algebra (no atan2 for phi, polynomial exp2/log2/atan)
    # gives the ansatz of gisnoise.model.ansatz at the emission angles of the same body vectors
    rng = np.random.default_rng(3)
    c = card(ansatz=ansatz, p0=61.0, p1=35.0, p2=0.21, p3=0.9, p4=-0.4, p5=-2.1, p6=1.2)
    n = 20000
    r = 10 ** rng.uniform(0.3, 3.7, n)
    v = rng.normal(size=(n, 3))
    v *= (r / np.linalg.norm(v, axis=1))[:, None]
    power = rng.uniform(800.0, 6000.0, n)
    fast = fk.level_from_body(c, v[:, 0], v[:, 1], v[:, 2], power)
    h = np.hypot(v[:, 0], v[:, 1])
    x = c.inputs(np.maximum(r, 1.0), np.arctan2(v[:, 1], v[:, 0]), np.arctan2(-v[:, 2], h), power)
    ref = c.level_uav(x)
    assert np.max(np.abs(fast - ref)) < 1e-3


def test_extensions_the_kernel_does_not_implement_are_refused():
    # emission_time reads the receiver through bound covariates of a campaign: not a map's term
    et = ModelCard(id="et", vehicle="t", phase="horizontal", ansatz="paper-offset+emission_time",
                   parameters=dict(p0=66.0, p1=20.0, p2=0.1, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0,
                                   **{k: 0.0 for k in get_ansatz("paper-offset+emission_time").params[8:]}),
                   reference_power_w=3000.0)
    with pytest.raises(CardError, match="depends on the receiver") as err:
        evaluate_grid(circle_flight(5), [et], grid_around(50.0, 3, 3), ground_h=0.0, engine="fast")
    assert err.value.field == "ansatz"
    from gisnoise.maps import fast_engine_serves

    assert "emission_time" in fast_engine_serves([et])
    # a ground reflection coefficient outside the effect's bounds [0, 1]: the NumPy engine maps it
    gr = ModelCard(id="gr", vehicle="t", phase="horizontal", ansatz="paper-offset+ground_reflection",
                   parameters=dict(p0=66.0, p1=20.0, p2=0.1, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0,
                                   r_ground=1.5, f_ground=300.0), reference_power_w=3000.0)
    with pytest.raises(CardError, match="r_ground"):
        evaluate_grid(circle_flight(5), [gr], grid_around(50.0, 3, 3), ground_h=0.0, engine="fast")
    res = evaluate_grid(circle_flight(5), [gr], grid_around(50.0, 3, 3), ground_h=0.0)
    assert res.metadata["engine"] == "numpy"


def test_default_engine_is_the_fast_one():
    from gisnoise.maps import DEFAULT_ENGINE, fast_engine_serves

    traj, g = circle_flight(8), grid_around(50.0, 4, 4)
    traj = Trajectory(**{k: getattr(traj, k) for k in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w",
                                                         "phase")}, rpm=np.linspace(3000.0, 5000.0, 8))
    for c in (card(), card(ansatz="paper"), bank_card(), bank_card("paper+bank_angle+rpm")):
        assert fast_engine_serves([c]) is None
        assert evaluate_grid(traj, [c], g, ground_h=0.0).metadata["engine"] == "fast"
    assert DEFAULT_ENGINE == "auto"
    # the uncertainty bands of paper cards are the fast engine's too; those of effect extensions the NumPy engine's
    assert fast_engine_serves([card()], uncertainty=True) is None
    assert fast_engine_serves([card(ansatz="paper")], uncertainty=True) is None
    assert "uncertainty" in fast_engine_serves([bank_card()], uncertainty=True)


def bank_card(ansatz="paper-offset+bank_angle", k_bank=3.0, **p):
    c = card(**p)
    params = dict(c.parameters)
    if ansatz.startswith("paper+"):
        params.pop("p0")
    params["k_bank"] = k_bank
    if "rpm" in ansatz:
        params.update(k_rpm=1.5, rpm_ref=4000.0)
    return ModelCard(id=ansatz, vehicle="test", phase=c.phase, ansatz=ansatz, parameters=params,
                     reference_power_w=3000.0)


def test_bank_angle_term_is_the_model_own():
    # a level turn at 30 deg bank: k_bank |sin 30 deg| = 1.5 dB on every cell and instant (paper 5.3.1)
    traj, g = circle_flight(20, roll=30.0), grid_around(40.0, 6, 5)
    base = evaluate_grid(traj, [card()], g, ground_h=0.0, engine="fast")
    ext = evaluate_grid(traj, [bank_card(k_bank=3.0)], g, ground_h=0.0, engine="fast")
    for name in ("LAmax", "LAeq", "SEL"):
        assert np.max(np.abs(ext.bands[name] - base.bands[name] - 1.5)) < 1e-3, name


def test_fast_engine_refuses_what_it_does_not_compute():
    traj, g = circle_flight(5), grid_around(50.0, 3, 3)
    with pytest.raises(InputError) as err:
        evaluate_grid(traj, [bank_card()], g, ground_h=0.0, engine="fast", uncertainty=True)
    assert err.value.field == "engine"
    with pytest.raises(InputError) as err:
        evaluate_grid(traj, [card()], g, ground_h=0.0, engine="vulkan")
    assert err.value.field == "engine"
    with pytest.raises(InputError) as err:
        evaluate_grid(traj, [card()], g, ground_h=0.0, engine="numpy", floor_db=20.0)  # a fast-engine option
    assert err.value.field == "floor_db"


@settings(max_examples=60, deadline=None)
@given(p2=st.floats(-0.4, 0.4), p3=st.floats(-4, 4), p4=st.floats(-0.6, 0.6), p5=st.floats(-4, 4),
       p6=st.floats(0.3, 2.0), gain=st.floats(-20, 120), floor=st.floats(0, 60), d_min=st.floats(0.5, 5),
       background=st.booleans(), seed=st.integers(0, 2 ** 31))
def test_audibility_radius_bounds_the_level_at_every_angle(p2, p3, p4, p5, p6, gain, floor, d_min, background, seed):
    # beyond the radius the ansatz stays below the floor at any emission angle and any
    # distance (the bound is what makes skipping cells safe)
    c = card(p0=gain, p1=0.0, p2=p2, p3=p3, p4=p4, p5=p5, p6=p6, p7=30.0)
    radius = fk._audibility_radius(np.array([gain]), np.array([p2]), np.array([p4]), np.array([p5]),
                                   np.array([p6]), np.array([30.0]), np.array([40.0]), d_min, floor, background)[0]
    if not np.isfinite(radius):
        assert background and floor <= 30.0  # the background alone reaches the floor
        return
    rng = np.random.default_rng(seed)
    n = 4000
    d = max(radius, 0.0) * (1 + 1e-9) * 10 ** rng.uniform(0, 2, n) + (0.0 if radius > 0 else rng.uniform(0, 3, n))
    phi = rng.uniform(-np.pi, np.pi, n)
    theta = rng.uniform(-np.pi / 2, np.pi / 2, n)
    phi[:8] = p3 + np.array([1, -1, 1, -1, 1, -1, 1, -1]) * np.pi / 2  # the extreme directions
    theta[:8] = np.clip(p5 + np.array([1, 1, -1, -1, 1, 1, -1, -1]) * np.pi / 2, -np.pi / 2, np.pi / 2)
    x = c.inputs(np.maximum(d, d_min), phi, theta, np.full(n, 3000.0))
    assert np.all(c.level(x, background=background) < floor)


# --------------------------------------------------------------------------- whole maps


def test_flyover_matches_numpy_with_thresholds_and_snapshot():
    traj = circle_flight(80, phases=("horizontal", "climb"))
    cards = [card(), card("climb", ansatz="paper", p1=80.0, p2=-0.1, p3=1.0)]
    g = grid_around(12.5, 61, 47)
    # the 'paper' climb card is synthetic (levels near 0 dB(A) at these powers): engines compared, guard off
    kw = dict(ground_h=0.0, threshold_db=[55.0, 62.0], snapshot_t=33.3, check_cards=False)
    ref = evaluate_grid(traj, cards, g, engine="numpy", **kw)
    fast = evaluate_grid(traj, cards, g, engine="fast", **kw)
    assert list(fast.bands) == list(ref.bands)
    assert_levels_equal(ref, fast, ("LAmax", "LAeq", "SEL", "LA@33.3s"))
    for name in ("TA55", "TA62"):  # linear between instants: float32 moves crossings by < 1 ms per instant
        assert np.max(np.abs(ref.bands[name] - fast.bands[name])) < 0.02
    assert fast.metadata["engine"] == "fast" and fast.metadata["cells_below_floor"] == 0


def test_background_substeps_and_dem():
    traj = circle_flight(30, dt=2.0)
    g = grid_around(20.0, 37, 29)
    rng = np.random.default_rng(1)
    dem = 5.0 + 30.0 * rng.random(g.shape)  # rough ground: receivers at their own heights
    dem[:2, :5] = np.nan  # outside the DEM: nodata in both engines
    kw = dict(dem=dem, background=True, substeps=3, threshold_db=45.0, period_s=600.0)
    ref = evaluate_grid(traj, [card()], g, engine="numpy", **kw)
    fast = evaluate_grid(traj, [card()], g, engine="fast", **kw)
    assert_levels_equal(ref, fast)
    for name in fast.bands:
        np.testing.assert_array_equal(np.isnan(fast.bands[name]), np.isnan(ref.bands[name]))


def test_near_field_takeoff_from_a_pad_among_receivers():
    # vertical take-off between receivers (cells every metre, 1.5 m up): distances down to 0.4 m.
    # (The pad is off the cell centres: straight above the UAV, theta = +90 deg, Eq. 9 still
    # depends on phi, which is undefined there: no engine can agree on that cell.)
    n = 40
    t = np.arange(n) * 0.5
    up = np.linspace(0.0, 40.0, n)
    lat, lon, h = FRAME.to_wgs84(np.full(n, 3.3), np.full(n, 1.2), up)
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(n), pitch=np.zeros(n), yaw=np.full(n, 30.0),
                      power_w=np.full(n, 5000.0), phase=np.full(n, "climb"))
    c = card("climb", p2=0.3, p4=-0.5)
    g = grid_around(1.0, 41, 41)
    ref = evaluate_grid(traj, [c], g, ground_h=0.0, engine="numpy")
    fast = evaluate_grid(traj, [c], g, ground_h=0.0, engine="fast")
    assert_levels_equal(ref, fast)


def test_cells_beyond_audibility_are_skipped_and_certainly_below_the_floor():
    # a short hover in one corner of a 6 km x 6 km grid: far cells are skipped
    traj = circle_flight(20, radius=50.0, height=40.0)
    g = grid_around(60.0, 101, 101, x0=2800.0, y0=2800.0)
    c = card(p2=0.03, p4=-0.05)  # about the demo cards' directivity
    floor = 35.0
    ref = evaluate_grid(traj, [c], g, ground_h=0.0, threshold_db=[40.0, 20.0], engine="numpy")
    fast = evaluate_grid(traj, [c], g, ground_h=0.0, threshold_db=[40.0, 20.0], engine="fast", floor_db=floor)
    skipped = np.isnan(fast.bands["LAmax"])
    assert 0 < skipped.sum() == fast.metadata["cells_below_floor"] < skipped.size
    assert np.all(ref.bands["LAmax"][skipped] < floor)
    assert np.all(np.isnan(fast.bands["LAeq"][skipped])) and np.all(np.isnan(fast.bands["SEL"][skipped]))
    assert np.all(fast.bands["TA40"][skipped] == 0.0)  # above the floor: certainly never exceeded
    assert np.all(np.isnan(fast.bands["TA20"][skipped]))  # below the floor: unknown
    assert_levels_equal(ref, fast)


def test_window_tiles_and_threads_give_bitwise_the_same_cells():
    traj = circle_flight(25)
    g = grid_around(3.0, 800, 23)  # 341 cells per segment: three segments per row
    rc = fk.receivers_for(g, [traj], ground_h=0.0)
    fl = fk.prepare_flight(traj, [card()], rc.frame, floor_db=25.0)
    whole = fk.run_grid(fl, rc, [50.0], threads=1)
    two = fk.run_grid(fl, rc, [50.0], threads=2, chunk_cells=600)
    for a, b in ((whole.emax, two.emax), (whole.energy, two.energy), (whole.ta, two.ta)):
        np.testing.assert_array_equal(a, b)
    k = rc.seg
    assert 2 * k < 800 < 3 * k
    for r0, r1, c0, c1 in ((0, 7, 0, k), (7, 23, k, 2 * k), (3, 9, 2 * k, 800), (0, 23, k, 800)):
        w = fk.run_window(fl, rc, r0, r1, c0, c1, [50.0])
        np.testing.assert_array_equal(w.emax, whole.emax[r0:r1, c0:c1])
        np.testing.assert_array_equal(w.energy, whole.energy[r0:r1, c0:c1])
        np.testing.assert_array_equal(w.ta, whole.ta[:, r0:r1, c0:c1])


def test_progress_and_cancel():
    from gisnoise.errors import Cancelled

    traj, g = circle_flight(10), grid_around(10.0, 50, 40)
    seen = []
    evaluate_grid(traj, [card()], g, ground_h=0.0, engine="fast", chunk_cells=200, progress=seen.append)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0) and len(seen) > 3
    with pytest.raises(Cancelled):
        evaluate_grid(traj, [card()], g, ground_h=0.0, engine="fast", chunk_cells=200, cancel=lambda: True)


@st.composite
def cases(draw):
    lat0 = draw(st.floats(-60.0, 70.0))
    lon0 = draw(st.floats(-179.0, 179.0))
    crs = utm_crs(lon0, lat0)
    frame = LocalFrame(lat0, lon0, 0.0)
    res = draw(st.sampled_from([0.7, 3.0, 9.0, 25.0, 60.0]))
    nx, ny = draw(st.integers(1, 28)), draw(st.integers(1, 28))
    g0 = GridSpec(crs, Affine(1.0, 0.0, 0.0, 0.0, -1.0, 0.0), 1, 1)
    x0, y0 = g0.from_wgs84(lon0, lat0)
    grid = GridSpec(crs, Affine(res, 0.0, float(x0) - res * nx / 2, 0.0, -res, float(y0) + res * ny / 2), nx, ny)
    n = draw(st.integers(2, 24))
    ext = max(nx, ny) * res
    e = np.cumsum(draw(st.lists(st.floats(-ext / 3, ext / 3), min_size=n, max_size=n)))
    nn = np.cumsum(draw(st.lists(st.floats(-ext / 3, ext / 3), min_size=n, max_size=n)))
    ground = draw(st.floats(-50.0, 500.0))
    up = ground + np.array(draw(st.lists(st.floats(5.0, 300.0), min_size=n, max_size=n)))
    lat, lon, h = frame.to_wgs84(e, nn, up)
    t = np.cumsum(draw(st.lists(st.floats(0.2, 5.0), min_size=n, max_size=n)))
    ang = lambda lo, hi: np.array(draw(st.lists(st.floats(lo, hi), min_size=n, max_size=n)))  # noqa: E731
    phases = np.array(draw(st.lists(st.sampled_from(["horizontal", "climb"]), min_size=n, max_size=n)))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=ang(-60, 60), pitch=ang(-30, 30), yaw=ang(-180, 180),
                      power_w=3000.0 * ang(0.3, 2.0), phase=phases)
    pars = [dict(p2=draw(st.floats(-0.3, 0.3)), p3=draw(st.floats(-3.1, 3.1)), p4=draw(st.floats(-0.5, 0.5)),
                 p5=draw(st.floats(-3.1, 3.1)), p6=draw(st.floats(0.5, 1.5)), p7=draw(st.floats(20.0, 50.0)))
            for _ in range(2)]
    cards = [card("horizontal", p0=draw(st.floats(40.0, 80.0)), p1=draw(st.floats(0.0, 30.0)), **pars[0]),
             card("climb", ansatz="paper", p1=draw(st.floats(10.0, 90.0)), **pars[1])]
    dem = None
    if draw(st.booleans()):
        rng = np.random.default_rng(draw(st.integers(0, 1000)))
        dem = ground + rng.uniform(0.0, 40.0, grid.shape)
    kw = dict(background=draw(st.booleans()), substeps=draw(st.sampled_from([1, 1, 2])),
              ground_h=None if dem is not None else ground, dem=dem)
    floor_q = draw(st.one_of(st.none(), st.floats(0.0, 1.0)))
    return traj, cards, grid, kw, floor_q


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cases())
def test_fast_equals_numpy_on_random_trajectories_and_grids(case):
    traj, cards, grid, kw, floor_q = case
    kw = dict(kw, check_cards=False)  # random synthetic cards: the engines are compared, not the cards judged
    ref = evaluate_grid(traj, cards, grid, engine="numpy", **kw)
    floor = floor_across(ref, floor_q)
    fast = evaluate_grid(traj, cards, grid, engine="fast", floor_db=floor, **kw)
    assert_fast_equals_numpy(ref, fast, floor)


@st.composite
def extension_cases(draw):
    traj, cards, grid, kw, floor_q = draw(cases())
    chain = draw(st.sampled_from(["+bank_angle", "+rpm", "+bank_angle+rpm", "+rpm+bank_angle"]))
    return with_rpm(draw, traj), extended_cards(draw, cards, chain), grid, kw, floor_q


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(extension_cases())
def test_fast_equals_numpy_for_effect_extensions(case):
    traj, cards, grid, kw, floor_q = case
    kw = dict(kw, check_cards=False)  # random synthetic cards: the engines are compared, not the cards judged
    ref = evaluate_grid(traj, cards, grid, engine="numpy", snapshot_t=float(traj.t[len(traj) // 2]), **kw)
    fast = evaluate_grid(traj, cards, grid, snapshot_t=float(traj.t[len(traj) // 2]), **kw)
    assert_fast_equals_numpy(ref, fast, snapshot=True)
