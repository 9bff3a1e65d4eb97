"""The fast engine's uncertainty bands equal the NumPy engine's delta method (maps/fast_uncertainty.py)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from test_fastkernel import FRAME, TMERC, bank_card, circle_flight, grid_around  # noqa: E402

from gisnoise.errors import CardError, InputError  # noqa: E402
from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import WGS84, emission_angles, transformer  # noqa: E402
from gisnoise.maps import TIE_DB, Z95, evaluate_grid, tie_std  # noqa: E402
from gisnoise.model import ModelCard  # noqa: E402

STD_TOL_DB = 1e-3
"""The bands' standard deviations agree to this (dB); the levels and the 95 % levels to the product's 0.01 dB."""

BANDS = ("LAmax_std", "LAmax_p95", "LAeq_std", "LAeq_p95", "SEL_std")


def fitted(ansatz="paper-offset", phase="horizontal", seed=0, **p):
    """A card with a covariance of random correlations (its parameters near a fitted card's)."""
    base = dict(p0=66.0, p1=20.0, p2=0.15, p3=-0.28, p4=-0.3, p5=1.05, p6=1.0, p7=40.0)
    base.update(p)
    ref_w = 3000.0
    if ansatz == "paper":  # p1 lg(P_el) is its whole gain: a power well above the reference makes it audible
        base.pop("p0")
        base["p1"], ref_w = 50.0, 100.0
    n = len(base)
    rng = np.random.default_rng(seed)
    std = np.array([0.4, 1.5, 0.01, 0.05, 0.02, 0.05, 0.01, 0.3])[8 - n:]
    a = rng.normal(size=(n, n))
    corr = np.corrcoef(a @ a.T + n * np.eye(n))
    cov = corr * np.outer(std, std)
    return ModelCard(id=f"{ansatz}-{phase}", vehicle="test", phase=phase, ansatz=ansatz, parameters=base,
                     reference_power_w=ref_w, covariance=tuple(map(tuple, cov)))


def assert_bands_agree(ref, fast):
    """Every band of every cell, those where instants tie for LAmax included (the rule of ``tie_std``)."""
    assert list(fast.bands) == list(ref.bands)
    assert fast.metadata["engine"] == "fast" and ref.metadata["engine"] == "numpy"
    assert fast.metadata["uncertainty"] == ref.metadata["uncertainty"]
    for name in fast.bands:
        a, b = ref.bands[name], fast.bands[name]
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
        tol = STD_TOL_DB if name.endswith("_std") else 0.01
        assert np.nanmax(np.abs(a - b)) <= tol, name
    for m in ("LAmax", "LAeq"):
        if f"{m}_p95" in fast.bands:
            np.testing.assert_allclose(fast.bands[f"{m}_p95"], fast.bands[m] - Z95 * fast.bands[f"{m}_std"],
                                       atol=1e-9)


@settings(max_examples=8, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(ansatz=st.sampled_from(["paper", "paper-offset"]), ansatz2=st.sampled_from(["paper", "paper-offset"]),
       background=st.booleans(), two_cards=st.booleans(), p2=st.floats(-0.4, 0.4), p4=st.floats(-0.6, 0.6),
       p3=st.floats(-3, 3), p5=st.floats(-3, 3), height=st.floats(20.0, 120.0), seed=st.integers(0, 2 ** 16))
def test_fast_bands_equal_the_numpy_engines(ansatz, ansatz2, background, two_cards, p2, p4, p3, p5, height, seed):
    phases = ("horizontal", "climb") if two_cards else ("horizontal",)  # two cards: of one ansatz or of both
    cards = [fitted(a, ph, seed + i, p2=p2, p3=p3, p4=p4, p5=p5)
             for i, (ph, a) in enumerate(zip(phases, (ansatz, ansatz2), strict=False))]
    traj = circle_flight(16, height=height, dt=3.0, phases=phases)
    g = grid_around(40.0, 13, 11)
    kw = dict(ground_h=0.0, background=background, check_cards=False)
    assert_bands_agree(evaluate_grid(traj, cards, g, engine="numpy", uncertainty=True, **kw),
                       evaluate_grid(traj, cards, g, engine="fast", uncertainty=True, **kw))


@pytest.mark.parametrize("metrics", [("LAeq", "SEL"), ("LAmax", "LAeq")])
def test_dem_with_and_without_lamax(metrics):
    traj = circle_flight(20, dt=2.0)
    g = grid_around(30.0, 19, 15)
    dem = 5.0 + 20.0 * np.random.default_rng(2).random(g.shape)
    dem[:2, :3] = np.nan  # outside the DEM: NaN in both
    kw = dict(dem=dem, uncertainty=True, metrics=metrics)
    ref = evaluate_grid(traj, [fitted()], g, engine="numpy", **kw)
    fast = evaluate_grid(traj, [fitted()], g, engine="fast", **kw)
    assert ("LAmax_std" in fast.bands) == ("LAmax" in metrics)
    assert_bands_agree(ref, fast)


def two_instants(power_w=(3000.0, 3000.0), a=30.0, h=40.0):
    """Two instants of a flight east at height ``h`` (m), at ``x = -a`` and ``x = +a`` (m) of the frame's origin.

    A receiver at ``x = 0`` hears them from the same distance and polar angle, the first from ahead
    (``phi = 0``), the second from behind (``phi = 180 deg``).  With ``p3 = 0`` the directivity
    ``sin(phi - p3)`` is 0 at both: at equal power they tie exactly, while ``dL/dp3 = -g p2 cos(phi)
    (theta + pi/2) b`` changes sign between them.
    """
    lat, lon, hh = FRAME.to_wgs84(np.array([-a, a]), np.zeros(2), np.full(2, h))
    return Trajectory(t=np.array([0.0, 2.0 * a / 20.0]), lat=lat, lon=lon, h=hh, roll=np.zeros(2),
                      pitch=np.zeros(2), yaw=np.full(2, 90.0), power_w=np.asarray(power_w, dtype=float),
                      phase=np.array(["horizontal"] * 2))


def tie_card():
    """``p3 = 0`` (see :func:`two_instants`) and ``p0``, ``p3`` correlated (0.8): their Jacobians' variances differ."""
    std = np.array([0.4, 1.5, 0.01, 0.05, 0.02, 0.05, 0.01, 0.3])
    corr = np.eye(8)
    corr[0, 3] = corr[3, 0] = 0.8
    return ModelCard(id="tie", vehicle="t", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=66.0, p1=20.0, p2=0.2, p3=0.0, p4=-0.3, p5=1.05, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, covariance=tuple(map(tuple, corr * np.outer(std, std))))


def closed_form(traj, card, grid, receiver_height=1.5):
    """Per cell and instant the level and ``sqrt(J C J^T)`` of the card's model, from the geometry alone."""
    x, y = grid.centres()
    lon, lat = transformer(TMERC, WGS84).transform(x.ravel(), y.ravel())
    rcv = np.stack(FRAME.to_enu(lat, lon, np.full(lat.shape, receiver_height)), axis=-1)  # flat ground at 0
    src = np.stack(FRAME.to_enu(traj.lat, traj.lon, traj.h), axis=-1)
    v = rcv[:, None, :] - src[None, :, :]
    d, phi, theta = emission_angles(v[..., 0], v[..., 1], v[..., 2], np.radians(traj.yaw), np.radians(traj.pitch),
                                    np.radians(traj.roll))
    L, J = card.model.level_and_jacobian(card.p, card.inputs(d, phi, theta, traj.power_w[None, :]),
                                         background=False, d_ref=card.reference_distance_m)
    std = np.sqrt(np.einsum("...p,pq,...q->...", J, card.cov, J))
    return L.reshape(grid.shape + (len(traj),)), std.reshape(grid.shape + (len(traj),))


@pytest.mark.parametrize("engine", ["numpy", "fast"])
def test_where_two_instants_tie_the_band_is_the_larger_standard_deviation(engine):
    traj, card, g = two_instants(), tie_card(), grid_around(20.0, 3, 3)
    L, std = closed_form(traj, card, g)
    tie = np.abs(L[..., 0] - L[..., 1]) < 1e-9  # the middle column (x = 0): the same distance and angles
    assert tie[:, 1].all() and not tie[:, [0, 2]].any()
    assert np.all(std[tie][:, 1] - std[tie][:, 0] > 0.2)  # the later instant's much larger: not the first's
    res = evaluate_grid(traj, [card], g, ground_h=0.0, uncertainty=True, engine=engine, metrics=("LAmax",))
    loudest = np.take_along_axis(std, np.argmax(L, axis=-1)[..., None], axis=-1)[..., 0]
    expected = np.where(tie, std.max(axis=-1), loudest)  # elsewhere one instant is louder by far: its own
    tol = 1e-9 if engine == "numpy" else 1e-4  # (the fast engine's float32 Jacobian and levels)
    np.testing.assert_allclose(res.bands["LAmax_std"], expected, rtol=0, atol=tol)
    np.testing.assert_allclose(res.bands["LAmax_p95"], res.bands["LAmax"] - Z95 * expected, rtol=0, atol=10 * tol)


def test_the_kernel_writes_the_tie_rule_as_defined():
    # the fast kernel spells tie_std out (numba's cache knows its own file's text only): the same numbers
    from gisnoise.maps import _numba_jac

    for s in (0.0, 0.3, 1.7):
        for d in np.linspace(0.0, 0.999 * TIE_DB, 7):
            assert _numba_jac._tie_std(s, d, TIE_DB) == pytest.approx(tie_std(s, d), rel=1e-15, abs=1e-15)


@pytest.mark.parametrize("engine", ["numpy", "fast"])
@pytest.mark.parametrize("below_db", [0.004, 0.03, 0.15])
def test_an_instant_just_below_the_maximum_counts_less_the_further_below(engine, below_db):
    # the second instant a little quieter (its power lower): within TIE_DB it brings its standard deviation less
    # below_db^2 / (TIE_DB (TIE_DB - below_db)) (tie_std), further below nothing
    card, g = tie_card(), grid_around(20.0, 1, 1)
    ab = 1.0 + card.parameters["p4"] * np.sin(-np.arctan2(38.5, 30.0) - card.parameters["p5"])  # a = 1 (p3 = 0)
    traj = two_instants(power_w=(3000.0, 3000.0 * 10.0 ** (-below_db / (card.parameters["p1"] * ab))))
    L, std = closed_form(traj, card, g)
    d = float(L[0, 0, 0] - L[0, 0, 1])
    assert d == pytest.approx(below_db, rel=1e-6)
    expected = max(std[0, 0, 0], std[0, 0, 1] - d * d / (TIE_DB * (TIE_DB - d)) if d < TIE_DB else 0.0)
    res = evaluate_grid(traj, [card], g, ground_h=0.0, uncertainty=True, engine=engine, metrics=("LAmax",))
    assert std[0, 0, 1] - d * d / (TIE_DB * (TIE_DB - d)) > std[0, 0, 0] or d >= TIE_DB  # the quieter one counts
    tol = 1e-9 if engine == "numpy" else 1e-4
    assert res.bands["LAmax_std"][0, 0] == pytest.approx(expected, abs=tol)


def test_p0_variance_alone_is_its_standard_deviation_everywhere():
    # dL/dp0 = 1 for an omnidirectional card without background: LAmax_std = LAeq_std = sqrt(var p0) exactly
    res = evaluate_grid(circle_flight(10), [omni_p0()], grid_around(50.0, 9, 9), ground_h=0.0, uncertainty=True,
                        engine="fast")
    for name in ("LAmax_std", "LAeq_std", "SEL_std"):
        np.testing.assert_allclose(res.bands[name], 0.6, atol=1e-6)


def omni_p0(var=0.36):
    """An omnidirectional card whose covariance is ``var`` on p0 alone: dL_UAV/dp0 = 1 at every instant."""
    cov = np.zeros((8, 8))
    cov[0, 0] = var
    return ModelCard(id="omni", vehicle="t", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=70.0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, covariance=tuple(map(tuple, cov)))


@pytest.mark.filterwarnings("ignore:divide by zero encountered in log10:RuntimeWarning")  # lg P_el of P_el = 0
@pytest.mark.filterwarnings("ignore:invalid value encountered in multiply:RuntimeWarning")  # its -inf times 0
def test_silent_samples_add_nothing_in_both_engines():
    # samples without power (motors off, a current dropout; make_map leaves them out, evaluate_grid takes them)
    # are silent: they add no energy and no Jacobian (their dL/dp1 = lg P_el is -inf); without a background
    # the p0 variance alone stays sqrt(var p0) exactly
    traj = circle_flight(20, dt=2.0)
    pw = traj.power_w.copy()
    pw[5:9] = 0.0
    traj = traj.with_(power_w=pw)
    g = grid_around(40.0, 13, 11)
    for engine in ("numpy", "fast"):
        res = evaluate_grid(traj, [omni_p0()], g, ground_h=0.0, uncertainty=True, engine=engine)
        for name in ("LAmax_std", "LAeq_std", "SEL_std"):
            np.testing.assert_allclose(res.bands[name], 0.6, atol=1e-6, err_msg=f"{engine} {name}")
    kw = dict(ground_h=0.0, uncertainty=True, background=True)  # with it the background's share, finite
    ref = evaluate_grid(traj, [fitted()], g, engine="numpy", **kw)
    fast = evaluate_grid(traj, [fitted()], g, engine="fast", **kw)
    assert all(np.isfinite(ref.bands[n]).all() for n in BANDS)
    assert_bands_agree(ref, fast)


def test_cells_below_the_floor_have_no_bands():
    traj = circle_flight(12, radius=100.0)
    g = grid_around(100.0, 41, 41)
    res = evaluate_grid(traj, [fitted(p2=0.0, p4=0.0)], g, ground_h=0.0, uncertainty=True, engine="fast",
                        floor_db=55.0)
    skipped = np.isnan(res.bands["LAmax"])
    assert res.metadata["cells_below_floor"] == skipped.sum() > 0
    for name in BANDS:
        assert np.all(np.isnan(res.bands[name][skipped])) and np.all(np.isfinite(res.bands[name][~skipped]))


def test_refusals_name_the_field():
    traj, g = circle_flight(5), grid_around(50.0, 3, 3)
    with pytest.raises(InputError) as err:  # the Jacobian of an effect extension: the NumPy engine's
        evaluate_grid(traj, [bank_card()], g, ground_h=0.0, engine="fast", uncertainty=True)
    assert err.value.field == "engine" and "bank_angle" in str(err.value)
    no_cov = ModelCard(**{**fitted().__dict__, "covariance": None})
    with pytest.raises(CardError) as err:
        evaluate_grid(traj, [no_cov], g, ground_h=0.0, engine="fast", uncertainty=True)
    assert err.value.field == "covariance"


def test_progress_covers_the_bands_and_ends_at_one():
    seen = []
    evaluate_grid(circle_flight(20), [fitted()], grid_around(40.0, 21, 17), ground_h=0.0, uncertainty=True,
                  engine="fast", progress=seen.append, chunk_cells=21 * 2)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0)
    assert seen[0] <= 0.25  # the levels' pass reports its part only
    assert sum(f > 0.25 for f in seen) >= 4  # and the bands' pass reports as it goes
    # no band asked: no Jacobian kernel, no bands
    res = evaluate_grid(circle_flight(20), [fitted()], grid_around(40.0, 5, 5), ground_h=0.0, uncertainty=True,
                        engine="fast", metrics=(), threshold_db=60.0)
    assert [n for n in res.bands if "std" in n or "p95" in n] == []


def test_auto_takes_the_fast_engine_unless_a_flown_card_needs_numpy():
    traj, g = circle_flight(12), grid_around(50.0, 5, 5)  # flies "horizontal" only
    unused_effect = bank_card(phase="climb")  # an effect extension for a phase this flight does not fly
    res = evaluate_grid(traj, [fitted(), unused_effect], g, ground_h=0.0, uncertainty=True)
    assert res.metadata["engine"] == "fast" and "LAmax_std" in res.bands
    flown_effect = ModelCard(**{**bank_card().__dict__, "covariance": tuple(map(tuple, 1e-4 * np.eye(9)))})
    res = evaluate_grid(traj, [flown_effect], g, ground_h=0.0, uncertainty=True)
    assert res.metadata["engine"] == "numpy" and "LAmax_std" in res.bands
