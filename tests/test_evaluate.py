"""The evaluator against closed-form acoustics of a point source (SPEC section 5)."""

import functools

import numpy as np
import pytest
import shapely
from affine import Affine

from gisnoise.errors import CardError, InputError, TrajectoryError
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, LocalFrame
from gisnoise.maps import Z95, CardSet, contour_features, grid_for_trajectory, reference
from gisnoise.maps import evaluate_grid as _evaluate_grid
from gisnoise.maps.reference import _levels_chunk
from gisnoise.model import ModelCard, level_sum, with_parameters

# these tests check the NumPy reference engine (float64, finite differences of its Jacobian);
# tests/test_fastkernel.py holds the fast engine against it
evaluate_grid = functools.partial(_evaluate_grid, engine="numpy")

LAT0, LON0 = 52.27, 10.52
# a transverse Mercator centred at the origin: grid x, y = local east, north (scale 1 at the centre)
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
G0 = 70.0  # level at 40 m with P_el = 1 (paper-offset: p0 + p1 log10(1))
FRAME = LocalFrame(LAT0, LON0, 0.0)


def omni_card(phase="horizontal", **kw):
    p = dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)
    return ModelCard(id=f"omni-{phase}", vehicle="test", phase=phase, ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0, **kw)


def straight_flight(v=20.0, height=50.0, n0=-1000.0, n1=1000.0, dt=0.05, phase="horizontal", yaw=0.0):
    """Level flight due north along the local meridian (e = 0) at constant speed."""
    t = np.arange(0.0, (n1 - n0) / v + 1e-9, dt)
    n = n0 + v * t
    lat, lon, h = FRAME.to_wgs84(np.zeros_like(n), n, np.full_like(n, height))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full_like(t, yaw),
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, phase), source="flyover")


def centred_grid(res, nx, ny):
    """Grid in TMERC with a cell centre on x = 0 and y = 0 (nx, ny odd)."""
    return GridSpec(TMERC, Affine(res, 0.0, -res * nx / 2, 0.0, -res, res * ny / 2), nx, ny)


def sel_closed_form(x, y, v, height, n0, n1, hr=1.5):
    """SEL of a finite straight track: 10 log10(10^(G/10) 40^2 / (v r) [atan]), exact."""
    r = np.hypot(x, height - hr)
    integral = (np.arctan((n1 - y) / r) - np.arctan((n0 - y) / r)) / (v * r)
    return 10 * np.log10(10 ** (G0 / 10) * 40.0 ** 2 * integral)


@pytest.fixture(scope="module")
def flyover():
    v, height, n0, n1 = 20.0, 50.0, -1000.0, 1000.0
    traj = straight_flight(v, height, n0, n1, dt=0.1)  # 2 m between samples
    grid = centred_grid(20.0, 41, 21)  # x, y = -400 ... 400 m, -200 ... 200 m
    res = evaluate_grid(traj, [omni_card()], grid, ground_h=0.0, threshold_db=60.0, snapshot_t=50.0,
                        metrics=("LAmax", "LAeq", "SEL"))
    return dict(v=v, height=height, n0=n0, n1=n1, traj=traj, grid=grid, res=res)


@pytest.mark.parametrize("offset", [0.0, 40.0, 100.0, 200.0, 400.0])
def test_flyover_sel_and_lamax_equal_closed_form(flyover, offset):
    g, res = flyover["grid"], flyover["res"]
    col = int(np.argmin(np.abs(g.xs - offset)))
    assert g.xs[col] == pytest.approx(offset, abs=1e-6)
    for row in (0, 5, 10, 20):  # several along-track positions
        y = g.ys[row]
        sel = sel_closed_form(offset, y, flyover["v"], flyover["height"], flyover["n0"], flyover["n1"])
        assert res.bands["SEL"][row, col] == pytest.approx(sel, abs=0.1)
        r = np.hypot(offset, flyover["height"] - 1.5)  # closest approach lies inside the track
        assert res.bands["LAmax"][row, col] == pytest.approx(G0 - 20 * np.log10(r / 40.0), abs=0.1)


def test_laeq_is_sel_minus_10log_period(flyover):
    res, traj = flyover["res"], flyover["traj"]
    assert res.metadata["period_s"] == pytest.approx(traj.duration_s)
    np.testing.assert_allclose(res.bands["LAeq"], res.bands["SEL"] - 10 * np.log10(traj.duration_s), atol=1e-9)
    longer = evaluate_grid(traj, [omni_card()], flyover["grid"], ground_h=0.0, metrics=("LAeq", "SEL"),
                           period_s=3600.0)
    np.testing.assert_allclose(longer.bands["LAeq"], longer.bands["SEL"] - 10 * np.log10(3600.0), atol=1e-9)


def test_time_above_equals_closed_form(flyover):
    # L > 60 while r^2 + (v tau)^2 < D^2 with D = 40 * 10^((G - 60)/20): duration 2 sqrt(D^2 - r^2) / v
    g, res = flyover["grid"], flyover["res"]
    d60 = 40.0 * 10 ** ((G0 - 60.0) / 20.0)
    for offset in (0.0, 40.0, 100.0):
        col = int(np.argmin(np.abs(g.xs - offset)))
        r = np.hypot(offset, flyover["height"] - 1.5)
        expected = 2 * np.sqrt(d60 ** 2 - r ** 2) / flyover["v"]
        assert res.bands["TA60"][10, col] == pytest.approx(expected, abs=0.02)
    far = int(np.argmin(np.abs(g.xs - 400.0)))
    assert res.bands["TA60"][10, far] == 0.0


def test_snapshot_is_level_at_interpolated_position(flyover):
    # at t = 50 s the UAV is at n = -1000 + 20 * 50 = 0, e = 0, 50 m up
    g, res = flyover["grid"], flyover["res"]
    x, y = np.meshgrid(g.xs, g.ys)
    d = np.sqrt(x ** 2 + y ** 2 + (flyover["height"] - 1.5) ** 2)
    np.testing.assert_allclose(res.bands["LA@50s"], G0 - 20 * np.log10(d / 40.0), atol=0.01)


def test_substeps_refine_a_coarse_trajectory():
    # samples 200 m apart: the trapezoid rule misses the peak; 40 substeps recover the exact integral
    v, height = 20.0, 30.0
    traj = straight_flight(v, height, -1000.0, 1000.0, dt=10.0)
    grid = centred_grid(10.0, 3, 3)
    exact = sel_closed_form(0.0, grid.ys[1], v, height, -1000.0, 1000.0)
    coarse = evaluate_grid(traj, [omni_card()], grid, ground_h=0.0, metrics=("SEL",))
    fine = evaluate_grid(traj, [omni_card()], grid, ground_h=0.0, metrics=("SEL",), substeps=40)
    assert abs(coarse.bands["SEL"][1, 1] - exact) > 0.5
    assert fine.bands["SEL"][1, 1] == pytest.approx(exact, abs=0.1)
    assert fine.metadata["evaluation_instants"] == 40 * (len(traj) - 1) + 1


def hover(seconds=60.0, height=30.0, phase="hover", yaw=0.0):
    t = np.array([0.0, seconds])
    lat, lon, h = FRAME.to_wgs84(np.zeros(2), np.zeros(2), np.full(2, height))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2), yaw=np.full(2, yaw),
                      power_w=np.full(2, 3000.0), phase=np.full(2, phase), source="hover")


def test_hover_55db_contour_is_the_analytic_circle():
    height, res_m = 30.0, 5.0
    traj = hover(height=height)
    grid = grid_for_trajectory(traj, res_m, 300.0)  # a UTM zone: the real path of the product
    assert grid.crs.to_epsg() == 32632
    res = evaluate_grid(traj, [omni_card("hover")], grid, ground_h=0.0, metrics=("LAmax",))
    d55 = 40.0 * 10 ** ((G0 - 55.0) / 20.0)
    radius = np.sqrt(d55 ** 2 - (height - 1.5) ** 2)
    feats = [f for f in contour_features(res, [55.0]) if f["properties"]["kind"] == "isoline"]
    assert len(feats) == 1
    (line,) = feats[0]["geometry"]["coordinates"]
    lon, lat = np.array(line).T
    assert np.allclose(line[0], line[-1])  # closed
    e, n, _ = FRAME.to_enu(lat, lon, np.zeros_like(lat))
    r = np.hypot(e, n)
    assert np.all(np.abs(r - radius) < res_m / 2)
    assert abs(np.mean(e)) < res_m / 2 and abs(np.mean(n)) < res_m / 2
    # the centre in lon/lat: the mean of the ring is the hover point within half a cell
    poly = shapely.Polygon(np.column_stack([e, n]))
    assert poly.centroid.distance(shapely.Point(0, 0)) < res_m / 2
    assert poly.area == pytest.approx(np.pi * radius ** 2, rel=0.01)


def test_emission_angles_follow_yaw():
    # a directional card; a hovering UAV heading east hears the same ahead (east) as one heading north (north)
    p = dict(p0=70.0, p1=20.0, p2=0.3, p3=-0.28, p4=-0.3, p5=1.05, p6=1.0, p7=40.0)
    card = ModelCard(id="dir", vehicle="t", phase="hover", ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0)
    height = 30.0
    grid = centred_grid(100.0, 5, 5)
    north = evaluate_grid(hover(height=height, yaw=0.0), [card], grid, ground_h=0.0, metrics=("LAmax",))
    east = evaluate_grid(hover(height=height, yaw=90.0), [card], grid, ground_h=0.0, metrics=("LAmax",))
    # receiver 100 m ahead: phi = 0, theta = -atan(28.5 / 100)
    x = {"d": np.hypot(100.0, height - 1.5), "phi": 0.0, "theta": -np.arctan2(height - 1.5, 100.0), "p_el": 1.0}
    expected = card.level_uav(x)
    # (grid x, y differ from ENU by earth curvature and projection scale: under a millimetre here)
    assert north.bands["LAmax"][1, 2] == pytest.approx(expected, abs=1e-3)  # row 1: y = +100 (north)
    assert east.bands["LAmax"][2, 3] == pytest.approx(expected, abs=1e-3)  # col 3: x = +100 (east)
    # starboard of the north-heading UAV is east: phi = +90 deg
    x_sb = dict(x, phi=np.pi / 2)
    assert north.bands["LAmax"][2, 3] == pytest.approx(card.level_uav(x_sb), abs=1e-3)
    np.testing.assert_allclose(np.rot90(east.bands["LAmax"]), north.bands["LAmax"], atol=1e-3)


def test_background_is_added_energetically(flyover):
    res = evaluate_grid(flyover["traj"], [omni_card()], flyover["grid"], ground_h=0.0, metrics=("LAmax",),
                        background=True)
    np.testing.assert_allclose(res.bands["LAmax"], level_sum(flyover["res"].bands["LAmax"], 40.0), atol=1e-9)


def test_blocks_do_not_change_the_result(flyover):
    small = evaluate_grid(flyover["traj"], [omni_card()], flyover["grid"], ground_h=0.0, threshold_db=60.0,
                          snapshot_t=50.0, block_size=3000, chunk_cells=97)
    for name, band in flyover["res"].bands.items():
        np.testing.assert_allclose(small.bands[name], band, rtol=1e-12, atol=1e-9)


def test_receivers_stand_on_the_dem(flyover):
    # a 20 m plateau under the whole grid: the slant distance below the track shrinks by 20 m
    grid = flyover["grid"]
    res = evaluate_grid(flyover["traj"], [omni_card()], grid, dem=np.full(grid.shape, 20.0), metrics=("LAmax",))
    col = int(np.argmin(np.abs(grid.xs)))
    assert res.bands["LAmax"][10, col] == pytest.approx(G0 - 20 * np.log10((50.0 - 21.5) / 40.0), abs=0.01)
    holes = np.full(grid.shape, 20.0)
    holes[:, :3] = np.nan  # outside the DEM: nodata, not a guess
    assert res.metadata["dem_nodata_receivers"] == 0
    for engine in ("numpy", "fast"):
        res = evaluate_grid(flyover["traj"], [omni_card()], grid, dem=holes, metrics=("LAmax",), engine=engine)
        assert np.isnan(res.bands["LAmax"][:, :3]).all() and np.isfinite(res.bands["LAmax"][:, 3:]).all()
        assert res.metadata["dem_nodata_receivers"] == 3 * grid.height  # counted for the map's warning


def test_progress_reaches_one_and_cancel_stops(flyover):
    seen = []
    evaluate_grid(flyover["traj"], [omni_card()], centred_grid(50.0, 5, 5), ground_h=0.0, progress=seen.append,
                  block_size=500)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0)
    from gisnoise.errors import Cancelled

    with pytest.raises(Cancelled):
        evaluate_grid(flyover["traj"], [omni_card()], centred_grid(50.0, 5, 5), ground_h=0.0, cancel=lambda: True)


def test_a_phase_without_card_is_named_with_its_samples():
    traj = straight_flight(dt=1.0)
    phase = traj.phase.copy()
    phase[10:20] = "hover"
    traj = traj.with_(phase=phase)
    with pytest.raises(CardError, match=r"phase 'hover' \(10 samples, samples 10-19, t = 10-19 s\)") as exc:
        evaluate_grid(traj, [omni_card()], centred_grid(50.0, 3, 3), ground_h=0.0)
    assert exc.value.field == "phase"


def test_cardset_precedence_and_ambiguity():
    h = omni_card("horizontal", phases=("transition",))
    tr = omni_card("transition")
    cs = CardSet([h, tr])
    assert cs.card_for("transition") is tr and cs.card_for("horizontal") is h
    with pytest.raises(CardError, match="both serve phase 'horizontal'"):
        CardSet([h, omni_card("horizontal")])
    with pytest.raises(CardError, match="serve phase 'transition'"):
        CardSet([h, omni_card("climb", phases=("transition",))])


def test_phases_pick_their_cards():
    # the first half uses a card 10 dB louder: LAmax where the first half passes is 10 dB up
    traj = straight_flight(dt=0.5)
    phase = np.where(traj.t < traj.duration_s / 2, "climb", "horizontal")
    loud = with_parameters(omni_card("climb"), [G0 + 10, 20, 0, 0, 0, 0, 1, 40])
    res = evaluate_grid(traj.with_(phase=phase), [loud, omni_card()], centred_grid(10.0, 3, 201), ground_h=0.0,
                        metrics=("LAmax",))
    r = 50.0 - 1.5
    assert res.bands["LAmax"][150, 1] == pytest.approx(G0 + 10 - 20 * np.log10(r / 40), abs=0.05)  # y = -500
    assert res.bands["LAmax"][50, 1] == pytest.approx(G0 - 20 * np.log10(r / 40), abs=0.05)  # y = +500


def test_input_errors_name_the_field(flyover):
    traj, grid = flyover["traj"], centred_grid(50.0, 3, 3)
    cases = [
        (dict(metrics=("Lmax",)), "metrics"),
        (dict(period_s=10.0), "period_s"),
        (dict(snapshot_t=1e6), "snapshot_t"),
        (dict(substeps=0), "substeps"),
        (dict(receiver_height=float("nan")), "receiver_height"),
    ]
    for kw, field in cases:
        with pytest.raises(InputError) as exc:
            evaluate_grid(traj, [omni_card()], grid, ground_h=0.0, **kw)
        assert exc.value.field == field
    with pytest.raises(TrajectoryError, match="1 sample; a trajectory needs at least 2"):  # the shared rule set
        evaluate_grid(traj.select(np.arange(len(traj)) == 0), [omni_card()], grid, ground_h=0.0)


def test_levels_chunk_matches_the_ansatz_pointwise():
    # the kernel a fast implementation must reproduce: L for every receiver x instant
    rng = np.random.default_rng(1)
    rcv = rng.uniform(-300, 300, (7, 3))
    src = rng.uniform(-300, 300, (5, 3)) + [0, 0, 400]
    att = rng.uniform(-0.5, 0.5, (5, 3))
    pw = rng.uniform(2000, 4000, 5)
    card = ModelCard(id="d", vehicle="t", phase="horizontal", ansatz="paper",
                     parameters=dict(p1=13.4, p2=0.18, p3=-0.28, p4=-0.37, p5=1.05, p6=0.94, p7=40.4),
                     reference_power_w=1500.0)
    L, _ = _levels_chunk(rcv, src, att, pw, np.zeros(5, int), [card])
    from gisnoise.geo import emission_angles

    for i in range(7):
        for j in range(5):
            d, phi, th = emission_angles(*(rcv[i] - src[j]), *att[j])
            assert L[i, j] == pytest.approx(float(card.level_uav(card.inputs(d, phi, th, pw[j]))), abs=1e-12)


# --------------------------------------------------------------------------- uncertainty


def fitted_card(p4=-0.1):
    p = dict(p0=66.0, p1=20.0, p2=0.05, p3=-0.28, p4=p4, p5=1.05, p6=1.0, p7=40.0)
    std = np.array([0.4, 1.5, 0.01, 0.05, 0.02, 0.05, 0.01, 0.3])
    corr = np.eye(8)
    corr[0, 1] = corr[1, 0] = -0.6
    corr[0, 6] = corr[6, 0] = 0.5
    cov = corr * np.outer(std, std)
    return ModelCard(id="fit", vehicle="t", phase="horizontal", ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0, covariance=tuple(map(tuple, cov)))


def uncertainty_case(dt=1.0, rows=5):
    t = np.arange(0.0, 40.0, dt)
    lat, lon, h = FRAME.to_wgs84(np.zeros_like(t), -400 + 20 * t, np.full_like(t, 50.0))
    power = 3000.0 * (1.0 + 0.3 * np.sin(t / 7.0))  # P_el varies: p1 matters
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=power,
                      phase=np.full(t.size, "horizontal"))
    return traj, centred_grid(60.0, 5, rows)


def test_uncertainty_matches_finite_differences():
    traj, grid = uncertainty_case()
    card = fitted_card()
    res = evaluate_grid(traj, [card], grid, ground_h=0.0, metrics=("LAmax", "LAeq"), uncertainty=True,
                        engine="numpy")  # the reference (the fast engine's bands: tests/test_fast_uncertainty.py)
    grads = {"LAmax": [], "LAeq": []}
    for k in range(8):
        h = 1e-5
        p_hi, p_lo = card.p.copy(), card.p.copy()
        p_hi[k] += h
        p_lo[k] -= h
        hi = evaluate_grid(traj, [with_parameters(card, p_hi)], grid, ground_h=0.0, metrics=("LAmax", "LAeq"),
                           engine="numpy")
        lo = evaluate_grid(traj, [with_parameters(card, p_lo)], grid, ground_h=0.0, metrics=("LAmax", "LAeq"),
                           engine="numpy")
        for m in grads:
            grads[m].append((hi.bands[m] - lo.bands[m]) / (2 * h))
    for m in grads:
        g = np.stack(grads[m], axis=-1)
        std = np.sqrt(np.einsum("...p,pq,...q->...", g, card.cov, g))
        np.testing.assert_allclose(res.bands[f"{m}_std"], std, rtol=1e-5)
        np.testing.assert_allclose(res.bands[f"{m}_p95"], res.bands[m] - Z95 * res.bands[f"{m}_std"], atol=1e-12)


def test_uncertainty_matches_monte_carlo_over_the_covariance():
    # Dense instants (2 m apart): LAmax is then the maximum of a smooth function of time, whose
    # derivative is dL/dp at the maximum (envelope theorem).  With instants far apart, two nearly
    # equal instants can swap places under the parameters' scatter, and the max of the two scatters
    # less than its linearisation (a known limit of the delta method for LAmax).
    traj, grid = uncertainty_case(dt=0.1, rows=3)
    card = fitted_card()
    res = evaluate_grid(traj, [card], grid, ground_h=0.0, metrics=("LAmax", "LAeq"), uncertainty=True)
    rng = np.random.default_rng(20240504)
    draws = rng.multivariate_normal(card.p, card.cov, size=2000)
    samples = {"LAmax": [], "LAeq": []}
    for p in draws:
        r = evaluate_grid(traj, [with_parameters(card, p)], grid, ground_h=0.0, metrics=("LAmax", "LAeq"))
        for m in samples:
            samples[m].append(r.bands[m])
    for m in samples:
        mc = np.std(np.stack(samples[m]), axis=0, ddof=1)  # sampling error of each about 1.6 %
        assert np.all(res.bands[f"{m}_std"] > 1.0)  # a case where the uncertainty matters
        np.testing.assert_allclose(res.bands[f"{m}_std"], mc, rtol=0.05)


def test_lamax_std_does_not_depend_on_how_the_instants_are_blocked(monkeypatch):
    # a circle around the centre cell: there every instant ties for LAmax, around it many nearly tie.  The NumPy
    # engine takes the instants in blocks; where a cell's maximum rises by less than TIE_DB from one block to the
    # next it takes that cell's instants again (the tie rule measures from the final LAmax): the same band
    t = np.arange(0.0, 63.0, 1.5)  # 20 m/s on a circle of 200 m radius: 0.15 rad per instant
    ang = t / 10.0
    lat, lon, h = FRAME.to_wgs84(200.0 * np.sin(ang), 200.0 * np.cos(ang), np.full(t.size, 60.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(t.size, 11.5), pitch=np.zeros(t.size),
                      yaw=np.degrees(ang) + 90.0, power_w=np.full(t.size, 3000.0), phase=np.full(t.size, "horizontal"))
    card, grid = fitted_card(p4=-0.3), centred_grid(20.0, 9, 9)
    kw = dict(ground_h=0.0, metrics=("LAmax",), uncertainty=True, engine="numpy")
    whole = evaluate_grid(traj, [card], grid, **kw)
    redone = []
    redo = reference._redo_ties
    monkeypatch.setattr(reference, "_redo_ties", lambda *a: redone.append(len(a[1])) or redo(*a))
    blocked = evaluate_grid(traj, [card], grid, block_size=27, chunk_cells=3, **kw)  # 3 instants a block
    assert sum(redone) > 0  # some cells were taken again
    for name in ("LAmax", "LAmax_std", "LAmax_p95"):
        np.testing.assert_allclose(blocked.bands[name], whole.bands[name], rtol=0, atol=1e-12, err_msg=name)


def test_uncertainty_needs_a_covariance(flyover):
    with pytest.raises(CardError, match="no covariance") as exc:
        evaluate_grid(flyover["traj"], [omni_card()], centred_grid(50.0, 3, 3), ground_h=0.0, uncertainty=True)
    assert exc.value.field == "covariance"


def test_extended_ansatz_reads_the_bank_angle():
    # paper-offset+bank_angle adds k_bank |sin(bank)| dB to every instant: a constant 20 deg bank
    # raises LAmax and LAeq everywhere by k_bank sin(20 deg)
    from gisnoise.model import get_ansatz

    ansatz = get_ansatz("paper-offset+bank_angle")
    traj = straight_flight(dt=1.0)
    traj = traj.with_(roll=np.full(len(traj), 20.0))
    grid = centred_grid(100.0, 5, 5)
    base = omni_card()
    params = {**base.parameters, ansatz.params[-1]: 3.0}
    ext = ModelCard(id="bank", vehicle="t", phase="horizontal", ansatz=ansatz.name, parameters=params,
                    reference_power_w=3000.0)
    a = evaluate_grid(traj, [base], grid, ground_h=0.0, metrics=("LAmax", "LAeq"))
    b = evaluate_grid(traj, [ext], grid, ground_h=0.0, metrics=("LAmax", "LAeq"))
    for m in ("LAmax", "LAeq"):
        np.testing.assert_allclose(b.bands[m] - a.bands[m], 3.0 * np.sin(np.radians(20.0)), atol=1e-9)


def test_a_replacement_kernel_is_called_with_the_reference_signature(flyover):
    calls = []

    def kernel(*args, **kw):
        calls.append(args[0].shape[0] * args[1].shape[0])
        return _levels_chunk(*args, **kw)

    grid = centred_grid(50.0, 5, 5)
    ref = evaluate_grid(flyover["traj"], [omni_card()], grid, ground_h=0.0)
    alt = evaluate_grid(flyover["traj"], [omni_card()], grid, ground_h=0.0, kernel=kernel)
    assert sum(calls) >= grid.n_cells * len(flyover["traj"])
    for k in ref.bands:
        np.testing.assert_array_equal(alt.bands[k], ref.bands[k])
