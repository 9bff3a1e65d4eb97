"""The output-error maximum-likelihood fit, judged against seeded synthetic truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _fit_synth import NOISE, REF_W, TRUTH, synthetic_samples
from scipy.optimize import least_squares

from gisnoise.errors import Cancelled, FitError, InputError, NotIdentifiableError
from gisnoise.identify import fit, fit_arrays, fit_campaign
from gisnoise.model import cards, get_ansatz

MODEL = get_ansatz("paper-offset")
P_TRUE = np.array([TRUTH[k] for k in MODEL.params])


@pytest.fixture(scope="module")
def campaign():
    return synthetic_samples(seed=11)


@pytest.fixture(scope="module")
def result(campaign):
    samples, _ = campaign
    return fit(samples, reference_power_w=REF_W)


def test_every_parameter_within_3_std_of_the_truth(result):
    assert result.success
    z = (result.p - P_TRUE) / result.std_array
    assert np.all(np.abs(z) < 3.0), dict(zip(result.param_names, z.round(2), strict=True))
    # and the directivity comes back in the paper's canonical form
    assert result.params["p2"] > 0 and result.params["p4"] < 0


def test_per_microphone_noise_within_10_percent(result):
    for mic, sd in NOISE.items():
        assert result.noise_std[mic] == pytest.approx(sd, rel=0.10)


def test_cost_is_the_gaussian_negative_log_likelihood_at_the_ml_variances(result, campaign):
    samples, _ = campaign
    # at sigma_m^2 = mean(r^2) the NLL is sum_m n_m / 2 (1 + ln(2 pi sigma_m^2))
    nll = 0.0
    for mic in NOISE:
        r = result.residuals[samples.mic == mic]
        nll += len(r) / 2.0 * (1.0 + math.log(2 * math.pi * np.mean(r * r)))
        assert result.noise_std[mic] == pytest.approx(np.sqrt(np.mean(r * r)), rel=1e-12)
    assert result.cost == pytest.approx(nll, rel=1e-12)
    k = len(MODEL.params) + len(NOISE)
    assert result.aic == pytest.approx(2 * nll + 2 * k, rel=1e-12)
    assert result.bic == pytest.approx(2 * nll + k * math.log(result.n), rel=1e-12)
    np.testing.assert_allclose(result.measured - result.fitted, result.residuals)
    np.testing.assert_allclose(result.fitted, MODEL.level(result.p, samples.inputs(REF_W)), atol=1e-9)


def test_same_optimum_as_scipy_least_squares(result, campaign):
    samples, _ = campaign
    x = samples.inputs(REF_W)
    sig = np.array([result.noise_std[m] for m in samples.mic])

    def wres(p):
        return (MODEL.level(p, x) - samples.level) / sig

    ref = least_squares(wres, result.start, jac="2-point", method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                        max_nfev=2000)
    ours = 0.5 * float(np.sum(wres(result.p) ** 2))
    assert abs(ours - ref.cost) / ref.cost < 1e-6
    # same point, within a small fraction of a standard deviation
    assert np.all(np.abs(ref.x - result.p) < 1e-2 * result.std_array)


def test_white_residuals_need_no_autocorrelation_correction(result):
    assert result.autocorr_lag <= 3
    np.testing.assert_allclose(result.std_corrected_array, result.std_array, rtol=0.1)
    c = result.corr
    np.testing.assert_allclose(np.diag(c), 1.0)
    np.testing.assert_allclose(c, c.T)
    assert np.all(np.abs(c) <= 1.0 + 1e-12)


def test_coloured_residuals_widen_the_corrected_deviation():
    # AR(1) noise with coefficient a inflates the variance of a mean by (1 + a) / (1 - a)
    samples, _ = synthetic_samples(seed=5, ar=0.8, altitudes=(40.0, 120.0), speeds=(22.0, 30.0))
    res = fit(samples, reference_power_w=REF_W)
    ratio = res.std_corrected_array / res.std_array
    assert res.autocorr_lag > 5
    # sqrt((1 + 0.8) / (1 - 0.8)) = 3; the truncated lag sum recovers most of it
    assert np.all((ratio > 2.0) & (ratio < 3.6)), ratio


def test_noise_free_data_recover_the_truth():
    samples, clean = synthetic_samples(seed=2, noise={m: 0.0 for m in NOISE}, speeds=(22.0, 30.0))
    res = fit(samples.with_(level=clean), reference_power_w=REF_W)
    np.testing.assert_allclose(res.p, P_TRUE, rtol=1e-6, atol=1e-7)


def test_the_paper_ansatz_fits_too():
    # printed ansatz, no offset: P_el about 7-11 (a small reference power) carries the level
    truth = {k: v for k, v in TRUTH.items() if k != "p0"} | {"p1": 60.0}
    samples, _ = synthetic_samples(seed=4, truth=truth, ansatz="paper", speeds=(22.0, 30.0), ref_w=REF_W / 8,
                                   p_el_scale=8.0)
    res = fit(samples, "paper", reference_power_w=REF_W / 8)
    p = np.array([truth[k] for k in res.param_names])
    assert np.all(np.abs(res.p - p) < 3.5 * res.std_array)


def test_invalid_rows_are_left_out(campaign):
    samples, _ = campaign
    bad = np.zeros(len(samples), dtype=bool)
    bad[::7] = True
    spoiled = samples.with_(level=np.where(bad, np.nan, samples.level), valid=~bad)
    res = fit(spoiled, reference_power_w=REF_W)
    assert res.n == int((~bad).sum())
    assert np.all(np.abs(res.p - P_TRUE) < 3.5 * res.std_array)


def test_fixed_parameters_stay_and_carry_no_variance(campaign):
    samples, _ = campaign
    res = fit(samples, reference_power_w=REF_W, fixed={"p7": 40.0, "p6": 1.0})
    assert res.params["p7"] == 40.0 and res.params["p6"] == 1.0
    i = res.param_names.index("p6")
    assert np.all(res.cov[i] == 0) and np.all(res.cov[:, i] == 0)
    assert res.n_free == 6
    # p6 and p7 held at their true values (TRUTH): the free parameters still find the truth
    free = [res.param_names.index(k) for k in res.param_names if k not in ("p6", "p7")]
    z = (res.p[free] - P_TRUE[free]) / res.std_array[free]
    assert np.all(np.abs(z) < 3.0), z


def test_a_bound_holds_and_is_reported(campaign):
    samples, _ = campaign
    res = fit(samples, reference_power_w=REF_W, bounds={"p6": (0.0, 0.9)})
    assert res.params["p6"] == pytest.approx(0.9, abs=1e-12)
    assert res.at_bounds == ("p6",)
    assert "p6 on a bound" in res.message


def test_flipped_start_converges_to_the_canonical_directivity(campaign):
    samples, _ = campaign
    start = dict(TRUTH, p2=-TRUTH["p2"], p3=TRUTH["p3"] + math.pi, p4=-TRUTH["p4"], p5=TRUTH["p5"] - math.pi)
    res = fit(samples, reference_power_w=REF_W, p0=start)
    assert np.all(np.abs(res.p - P_TRUE) < 3.0 * res.std_array)


def test_start_from_a_card(campaign):
    samples, _ = campaign
    card = cards.load(__import__("pathlib").Path(__file__).parents[1] / "gisnoise/data/cards/demo_horizontal.json")
    res = fit(samples, reference_power_w=REF_W, p0=card)
    assert np.all(np.abs(res.p - P_TRUE) < 3.0 * res.std_array)


def test_one_distance_is_refused_naming_offset_and_spreading(campaign):
    samples, _ = campaign
    rng = np.random.default_rng(0)
    one_d = samples.with_(d=np.full(len(samples), 120.0))
    one_d = one_d.with_(level=MODEL.level(P_TRUE, one_d.inputs(REF_W)) + rng.normal(0, 1.0, len(samples)))
    with pytest.raises(NotIdentifiableError) as exc:
        fit(one_d, reference_power_w=REF_W)
    assert set(exc.value.parameters) == {"p0", "p6"}
    assert "p0, p6 cannot be told apart" in str(exc.value)


def test_one_power_is_refused_naming_offset_and_power_slope(campaign):
    samples, _ = campaign
    rng = np.random.default_rng(1)
    one_p = samples.with_(power_w=np.full(len(samples), 3300.0))
    one_p = one_p.with_(level=MODEL.level(P_TRUE, one_p.inputs(REF_W)) + rng.normal(0, 1.0, len(samples)))
    with pytest.raises(NotIdentifiableError) as exc:
        fit(one_p, reference_power_w=REF_W)
    assert set(exc.value.parameters) == {"p0", "p1"}
    assert exc.value.field == "p0"


def test_non_convergence_raises_and_makes_no_card(campaign):
    samples, _ = campaign
    with pytest.raises(FitError, match="did not converge in 2 iterations"):
        fit(samples, reference_power_w=REF_W, max_iter=2)
    res = fit(samples, reference_power_w=REF_W, max_iter=2, raise_on_failure=False)
    assert not res.success
    with pytest.raises(FitError, match="no card written: did not converge"):
        res.to_card(id="x", vehicle="v")


def test_progress_reports_falling_cost_and_cancel_stops(campaign):
    samples, _ = campaign
    seen = []
    res = fit(samples, reference_power_w=REF_W, progress=lambda i, c: seen.append((i, c)))
    its = [i for i, _ in seen]
    assert its == sorted(its) and its[-1] == res.iterations
    assert seen[-1][1] == pytest.approx(res.cost, rel=1e-9)
    # the reported cost falls: Levenberg-Marquardt accepts only steps that lower the weighted cost, and each
    # relaxation cycle sets the noise variances to their ML values, which minimise the NLL at fixed residuals
    costs = np.array([c for _, c in seen])
    assert np.all(np.diff(costs) <= 1e-9 * abs(costs[0])), np.diff(costs)
    assert costs[0] > costs[-1]
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > 2

    with pytest.raises(Cancelled):
        fit(samples, reference_power_w=REF_W, cancel=cancel)


def test_bad_inputs_name_the_field(campaign):
    samples, _ = campaign
    with pytest.raises(InputError) as e:
        fit(samples, reference_power_w=-5.0)
    assert e.value.field == "reference_power_w"
    with pytest.raises(InputError) as e:
        fit(samples.with_(level=np.where(np.arange(len(samples)) == 3, np.inf, samples.level)), reference_power_w=REF_W)
    assert e.value.field == "level" and "row 3" in str(e.value)
    with pytest.raises(InputError) as e:
        fit(samples, reference_power_w=REF_W, fixed={"q9": 1.0})
    assert e.value.field == "fixed"
    with pytest.raises(InputError) as e:
        fit(samples, reference_power_w=REF_W, bounds={"p6": (2.0, 1.0)})
    assert e.value.field == "bounds.p6"
    with pytest.raises(InputError) as e:
        fit(samples.with_(power_w=np.zeros(len(samples))), reference_power_w=REF_W)
    assert e.value.field == "p_el"
    with pytest.raises(InputError) as e:
        fit(samples, "no-such-ansatz", reference_power_w=REF_W)
    assert e.value.field == "ansatz"


def test_one_noise_variance_for_all_microphones(campaign):
    samples, _ = campaign
    res = fit(samples, reference_power_w=REF_W, per_mic_noise=False)
    pooled = float(np.sqrt(np.mean(res.residuals ** 2)))
    assert list(res.noise_std) == ["m1", "m2", "m3"]
    assert all(v == pytest.approx(pooled, rel=1e-12) for v in res.noise_std.values())
    # and the pooled deviation is the simulated one: sqrt of the row-weighted mean of the true variances
    n_m = {m: int(np.sum(samples.mic == m)) for m in NOISE}
    truth = math.sqrt(sum(n_m[m] * NOISE[m] ** 2 for m in NOISE) / sum(n_m.values()))
    assert pooled == pytest.approx(truth, rel=0.05)
    assert res.aic == pytest.approx(2 * res.cost + 2 * (8 + 1), rel=1e-12)


def test_to_card_round_trips_with_covariance_and_provenance(result, tmp_path):
    card = result.to_card(id="demo-horizontal", vehicle="demo", phases=["transition"],
                          provenance={"data": "synthetic racetrack"})
    path = cards.save(card, tmp_path / "c.json")
    back = cards.load(path)
    assert back.ansatz == "paper-offset" and back.phase == "horizontal" and back.phases == ("transition",)
    np.testing.assert_allclose(back.p, result.p)
    np.testing.assert_allclose(back.cov, result.cov_corrected)
    assert back.provenance["data"] == "synthetic racetrack"
    assert back.provenance["software"].startswith("gisnoise ")
    assert back.statistics["std_cramer_rao"]["p6"] == pytest.approx(result.std["p6"])
    assert back.statistics["noise_std_db"] == pytest.approx(result.noise_std)
    cr = result.to_card(id="x", vehicle="v", covariance="cramer-rao")
    np.testing.assert_allclose(cr.cov, result.cov)


def test_fit_arrays_without_samples():
    rng = np.random.default_rng(3)
    n = 3000
    x = {"d": rng.uniform(20, 500, n), "phi": rng.uniform(-np.pi, np.pi, n), "theta": rng.uniform(-1.5, 0.3, n),
         "p_el": rng.uniform(0.8, 1.5, n)}
    y = MODEL.level(P_TRUE, x) + rng.normal(0, 1.0, n)
    res = fit_arrays(y, x)
    assert res.noise_std == {"all": pytest.approx(1.0, rel=0.05)}
    assert np.all(np.abs(res.p - P_TRUE) < 3.5 * res.std_array)


# --------------------------------------------------------------------------- campaign folders and the CLI

ORIGIN = {"lat": 52.3186, "lon": 10.5564, "h": 125.0}


def _write_csv(path, cols):
    path.parent.mkdir(parents=True, exist_ok=True)
    names = list(cols)
    rows = [",".join(names)]
    for i in range(len(cols[names[0]])):
        rows.append(",".join(str(cols[k][i]) if k == "phase" else repr(float(cols[k][i])) for k in names))
    path.write_text("\n".join(rows) + "\n")


def make_campaign_folder(root, *, seed=0, truth=None):
    """A campaign folder (SPEC 3) whose levels are the truth model at the reader's own emission geometry.

    The flight CSV is a racetrack at 10 Hz; the level CSVs are written twice: first
    with placeholder levels to let the campaign reader solve the emission geometry,
    then with ``truth`` at that geometry + seeded noise per microphone (NOISE).
    """
    from _fit_synth import MICS, racetrack

    from gisnoise.geo import LocalFrame
    from gisnoise.measure import read_campaign

    truth = TRUTH if truth is None else truth
    frame = LocalFrame(ORIGIN["lat"], ORIGIN["lon"], ORIGIN["h"])
    tr = racetrack(altitudes=(40.0, 120.0), speeds=(22.0, 30.0), dt=0.1, seed=seed)
    lat, lon, h = frame.to_wgs84(tr["e"], tr["n"], tr["u"])
    _write_csv(root / "flights" / "f1.csv", {
        "t": tr["t"], "lat": lat, "lon": lon, "h": h, "roll": np.degrees(tr["roll"]),
        "pitch": np.degrees(tr["pitch"]), "yaw": np.degrees(tr["yaw"]), "power_w": tr["p_el"] * REF_W,
        "phase": np.full(len(tr["t"]), "horizontal")})
    mics = []
    for m, enu in MICS.items():
        mlat, mlon, mh = frame.to_wgs84(*enu)
        mics.append({"id": m, "lat": float(mlat), "lon": float(mlon), "h": float(mh), "mount": "free_field",
                     "background_db": truth["p7"]})
    doc = {"schema": "gisnoise/campaign/1", "origin": ORIGIN, "speed_of_sound_m_s": 340.0,
           "weather": {"temperature_c": 15.0, "humidity_pct": 50.0, "pressure_kpa": 101.325},
           "vehicle": {"name": "test eVTOL", "reference_power_w": REF_W}, "microphones": mics,
           "flights": [{"id": "f1", "start_utc": "2024-05-04T10:00:00Z"}]}
    root.mkdir(parents=True, exist_ok=True)
    (root / "campaign.json").write_text(__import__("json").dumps(doc, indent=1))
    t_r = np.arange(5.0, tr["t"][-1] - 1.0, 0.125)
    t_r = t_r[np.all(np.abs(t_r[:, None] - tr["t"][np.nonzero(np.diff(tr["t"]) > 1.0)[0]]) > 8.0, axis=1)]
    for m in MICS:
        _write_csv(root / "mics" / m / "f1.csv", {"t": t_r, "LA": np.full(len(t_r), 60.0)})
    s = read_campaign(root).samples()
    x = s.inputs(REF_W)
    clean = get_ansatz("paper-offset").level(np.array([truth[k] for k in MODEL.params]), x)
    rng = np.random.default_rng(seed)
    for m, sd in NOISE.items():
        sel = s.mic == m
        order = np.argsort(s.t_r[sel])
        la = (clean[sel] + rng.normal(0.0, sd, int(sel.sum())))[order]
        _write_csv(root / "mics" / m / "f1.csv", {"t": s.t_r[sel][order], "LA": la})
    return root


@pytest.fixture(scope="module")
def campaign_folder(tmp_path_factory):
    return make_campaign_folder(tmp_path_factory.mktemp("camp") / "campaign")


def test_fit_campaign_recovers_the_truth_through_the_reader(campaign_folder):
    res = fit_campaign(campaign_folder, "horizontal")
    assert res.reference_power_w == REF_W and res.phase == "horizontal"
    z = (res.p - P_TRUE) / res.std_array
    assert np.all(np.abs(z) < 3.0), dict(zip(res.param_names, z.round(2), strict=True))
    for mic, sd in NOISE.items():
        assert res.noise_std[mic] == pytest.approx(sd, rel=0.10)
    card = res.to_card()
    assert card.vehicle == "test eVTOL" and card.id == "test-evtol-horizontal"
    assert card.provenance["data"]["flights"] == ["f1"]
    assert card.provenance["data"]["microphones"] == ["m1", "m2", "m3"]


def test_fit_campaign_refuses_a_phase_without_samples(campaign_folder):
    with pytest.raises(InputError, match="no usable samples of phase 'climb'.*horizontal") as e:
        fit_campaign(campaign_folder, "climb")
    assert e.value.field == "phase"


def _run(*args):
    from click.testing import CliRunner

    from gisnoise.cli.main import cli

    return CliRunner().invoke(cli, ["-q", *map(str, args)], catch_exceptions=False)


def test_cli_writes_a_card_with_covariance_and_a_report(campaign_folder, tmp_path):
    out = tmp_path / "card.json"
    r = _run("fit", campaign_folder, "--phase", "horizontal", "--out", out, "--report", tmp_path / "rep",
             "--serves", "transition", "--id", "demo-horizontal")
    assert r.exit_code == 0, r.output
    card = cards.load(out)
    assert card.id == "demo-horizontal" and card.phases == ("transition",) and card.ansatz == "paper-offset"
    assert card.cov.shape == (8, 8) and np.all(np.diag(card.cov) > 0)
    z = (card.p - P_TRUE) / np.sqrt(np.diag(card.cov))
    assert np.all(np.abs(z) < 3.0)
    assert card.statistics["n_samples"] > 5000
    for name in ("report.html", "timeseries.png", "directivity.png", "correlation.png", "residuals_f1.png"):
        assert (tmp_path / "rep" / name).is_file()


def test_cli_start_card_and_fixed_parameter(campaign_folder, tmp_path):
    start = tmp_path / "start.json"
    cards.save(cards.load(__import__("pathlib").Path(__file__).parents[1] / "gisnoise/data/cards/demo_horizontal.json"),
               start)
    out = tmp_path / "card.json"
    r = _run("fit", campaign_folder, "--phase", "horizontal", "--out", out, "--start", start, "--fix", "p7=40")
    assert r.exit_code == 0, r.output
    card = cards.load(out)
    assert card.id == "demo-horizontal" and card.phases == ("transition",)  # kept from the start card
    assert card.parameters["p7"] == 40.0 and card.statistics["fixed"] == {"p7": 40.0}


def test_cli_non_convergence_writes_no_card_and_says_why(campaign_folder, tmp_path):
    out = tmp_path / "card.json"
    r = _run("fit", campaign_folder, "--phase", "horizontal", "--out", out, "--max-iter", "1")
    assert r.exit_code == 2
    assert "did not converge in 1 iterations" in r.output
    assert not out.exists()


def test_cli_bad_fix_names_the_option(campaign_folder, tmp_path):
    r = _run("fit", campaign_folder, "--phase", "horizontal", "--out", tmp_path / "c.json", "--fix", "p7")
    assert r.exit_code == 2 and "--fix expects NAME=VALUE" in r.output
    r = _run("fit", campaign_folder, "--phase", "horizontal", "--out", tmp_path / "c.json", "--fix", "q1=3")
    assert r.exit_code == 2 and "unknown parameter(s) q1" in r.output


def test_fit_campaign_can_be_cancelled_while_reading(campaign_folder):
    with pytest.raises(Cancelled, match="reading the campaign"):
        fit_campaign(campaign_folder, "horizontal", cancel=lambda: True)


def test_simulated_sample_campaign_without_effects_recovers_the_truth_card():
    # the simulator's sample campaign with no injected effect, no log noise and a steady background:
    # the model is then exactly right, and the ML estimate must sit within 3 std of the truth card
    from gisnoise.simulate import load_scenario, scenario_copy, simulate_samples

    root = __import__("pathlib").Path(__file__).parents[1]
    sc = load_scenario(root / "sample_data/scenarios/sample_campaign.json")
    veh = dict(sc["vehicle"], log_noise={"position_m": 0.0, "attitude_deg": 0.0, "power_pct": 0.0})
    doc = scenario_copy(sc, effects={}, vehicle=veh, background=dict(sc["background"], fluctuation_db=0.0))
    samples = simulate_samples(doc, base_dir=root / "sample_data/scenarios")
    truth = cards.load(root / "gisnoise/data/cards/demo_horizontal.json")
    from gisnoise.identify import usable_rows

    res = fit(usable_rows(samples, "horizontal"), reference_power_w=samples.meta["reference_power_w"])
    z = (res.p - truth.p) / res.std_array
    assert np.all(np.abs(z) < 3.0), dict(zip(res.param_names, z.round(2), strict=True))
    for mic, sd in samples.meta["noise_std_db"].items():
        assert res.noise_std[mic] == pytest.approx(sd, rel=0.10)


def test_a_start_without_directivity_is_not_refused(campaign):
    # p2 = p4 = 0 leaves p3, p5 without effect at the start; the solve restores them
    samples, _ = campaign
    start = dict(TRUTH, p0=50.0, p1=10.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=0.8, p7=35.0)
    res = fit(samples, reference_power_w=REF_W, p0=start)
    assert np.all(np.abs(res.p - P_TRUE) < 3.0 * res.std_array)


def test_fit_names_a_microphone_listed_50_m_off_and_not_unequal_noise(campaign_folder, tmp_path):
    """Microphones of unequal noise (0.8, 1.2, 1.6 dB) fit silently; m2 listed 50 m east of where its levels were
    measured is named (its residual is steady over seconds, the others' white), the card still written."""
    import json
    import shutil

    from gisnoise.geo import LocalFrame
    from gisnoise.identify.fit import SYSTEMATIC_MIN_DB, systematic_residuals

    clean = fit_campaign(campaign_folder, "horizontal")
    assert clean.info["warnings"] == []
    assert "warnings" not in clean.statistics()
    moved = shutil.copytree(campaign_folder, tmp_path / "moved")
    doc = json.loads((moved / "campaign.json").read_text())
    m2 = doc["microphones"][1]
    assert m2["id"] == "m2"
    frame = LocalFrame(ORIGIN["lat"], ORIGIN["lon"], ORIGIN["h"])
    e, n, u = frame.to_enu(m2["lat"], m2["lon"], m2["h"])
    m2["lat"], m2["lon"], m2["h"] = (float(v) for v in frame.to_wgs84(e + 50.0, n, u))
    (moved / "campaign.json").write_text(json.dumps(doc))
    res = fit_campaign(moved, "horizontal")
    parts = systematic_residuals(res.samples, res.residuals)
    assert parts["m2"][1] > SYSTEMATIC_MIN_DB
    assert len(res.info["warnings"]) == 1
    w = res.info["warnings"][0]
    assert w.startswith(f"microphone 'm2': noise std {res.noise_std['m2']:.2f} dB against")
    assert "position" in w and "gisnoise diagnose" in w
    assert res.statistics()["warnings"] == [w]
    assert res.to_card().statistics["warnings"] == [w]
