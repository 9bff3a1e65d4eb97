"""The fit report shows what it claims: files exist and the numbers behind them are right."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from _fit_synth import REF_W, synthetic_samples

from gisnoise.identify import correlation_data, directivity_data, write_report
from gisnoise.identify.fit import fit

pytest.importorskip("matplotlib")


@pytest.fixture(scope="module")
def result():
    samples, _ = synthetic_samples(seed=21, flights=2, altitudes=(40.0, 120.0), speeds=(22.0, 30.0))
    return fit(samples, reference_power_w=REF_W)


@pytest.fixture(scope="module")
def report(result, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    return out, write_report(result, out)


def test_every_file_is_written_and_linked(report):
    out, files = report
    pngs = ["timeseries.png", "directivity.png", "correlation.png", "residuals_f1.png", "residuals_f2.png"]
    for name in pngs + ["timeseries.json", "directivity.json", "correlation.json", "residuals.json",
                        "parameters.json", "report.html"]:
        assert (out / name).is_file() and files[name] == out / name
    page = (out / "report.html").read_text()
    for name in pngs:
        assert f'src="{name}"' in page
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000  # a real figure, not an empty canvas


def test_correlation_matrix_is_eq_12_to_14_of_the_inputs(result, report):
    out, _ = report
    data = json.loads((out / "correlation.json").read_text())
    s = result.samples
    cols = {"speed": np.linalg.norm(s.vel_enu, axis=1), "power": s.power_w, "bank": s.roll, "distance": s.d,
            "polar": np.degrees(s.theta), "azimuth": np.degrees(s.phi), "residual": s.level - result.fitted}
    assert data["variables"] == list(cols)  # the synthetic log has no rpm and no airspeed
    assert data["left_out"] == ["rpm: not in the data"]
    np.testing.assert_allclose(data["matrix"], np.corrcoef(np.vstack(list(cols.values()))), atol=1e-12)
    # the residual of a maximum-likelihood fit is uncorrelated with the fitted level's inputs (white noise)
    c = np.array(data["matrix"])
    assert np.all(np.abs(c[-1, :-1]) < 0.05)


def test_rpm_and_airspeed_enter_when_logged(result):
    s = result.samples
    rng = np.random.default_rng(0)
    rpm = 3000.0 + rng.normal(0, 50, len(s))
    air = s.speed_m_s + 2.0
    res = type(result)(**{**result.__dict__, "samples": s.with_(rpm=rpm, airspeed_m_s=air)})
    data = correlation_data(res)
    assert data["variables"][:2] == ["speed", "rpm"] and data["left_out"] == []
    ref = np.corrcoef(np.vstack([air, rpm]))
    np.testing.assert_allclose(np.array(data["matrix"])[:2, :2], ref, atol=1e-12)


def test_directivity_peaks_at_the_analytic_azimuth(result, report):
    out, _ = report
    data = json.loads((out / "directivity.json").read_text())
    p = result.params
    # Eq. 9: the azimuth factor 1 + p2 sin(phi - p3)(theta + pi/2) peaks at phi = p3 + 90 deg when the gain is positive
    expect = math.degrees(p["p3"]) + 90.0
    assert data["analytic_max_phi_deg"] == pytest.approx(expect, abs=1e-9)
    assert data["max"]["phi_deg"] == pytest.approx(expect, abs=0.5 + 1e-9)
    assert data["distance_m"] == 30.0
    assert data["p_el"] == pytest.approx(float(np.median(result.samples.power_w)) / REF_W)
    lvl = np.array(data["level_db"])
    assert lvl.shape == (181, 361)
    # every polar row peaks at the same azimuth (the azimuth enters through one factor only)
    row_max = np.array(data["phi_deg"])[np.argmax(lvl[1:], axis=1)]
    assert np.all(np.abs(row_max - expect) <= 0.5 + 1e-9)


def test_directivity_at_the_papers_operating_point(result):
    # paper Fig. 7: 30 m, P_el = 1.1; spherical spreading from 40 m to 30 m adds p6 * 20 log10(4/3) dB
    a = directivity_data(result, distance_m=30.0, p_el=1.1, step_deg=5.0)
    b = directivity_data(result, distance_m=40.0, p_el=1.1, step_deg=5.0)
    diff = np.array(a["level_db"]) - np.array(b["level_db"])
    np.testing.assert_allclose(diff, result.params["p6"] * 20 * math.log10(40 / 30), atol=1e-9)


def test_timeseries_holds_the_measured_and_model_levels(result, report):
    out, _ = report
    data = json.loads((out / "timeseries.json").read_text())
    s = result.samples
    assert sorted(data["microphones"]) == ["m1", "m2", "m3"] and data["flights"] == ["f1", "f2"]
    m = data["microphones"]["m2"]
    sel = s.mic == "m2"
    assert len(m["t_s"]) == int(sel.sum())
    # flights in order, times increasing within each
    f = np.array(m["flight"])
    t = np.array(m["t_s"])
    assert np.all(np.diff(t[f == "f1"]) > 0) and list(dict.fromkeys(f)) == ["f1", "f2"]
    order = np.lexsort((s.t_e[sel], s.flight[sel]))
    np.testing.assert_allclose(m["measured_db"], s.level[sel][order])
    np.testing.assert_allclose(np.array(m["measured_db"]) - np.array(m["model_db"]),
                               result.residuals[sel][order], atol=1e-12)


def test_residual_view_carries_bank_distance_and_rms(result, report):
    out, _ = report
    data = json.loads((out / "residuals.json").read_text())
    s = result.samples
    f1 = data["flights"]["f1"]
    sel = s.flight == "f1"
    assert f1["rms_db"] == pytest.approx(float(np.sqrt(np.mean(result.residuals[sel] ** 2))))
    t, first = np.unique(s.t_e[sel], return_index=True)
    np.testing.assert_allclose(f1["t_s"], t)
    np.testing.assert_allclose(f1["bank_deg"], s.roll[sel][first])
    m3 = f1["microphones"]["m3"]
    i3 = sel & (s.mic == "m3")
    np.testing.assert_allclose(m3["distance_m"], s.d[i3][np.argsort(s.t_e[i3])])
    # coordinated turns of the first loop (22 m/s, R = 160 m): |bank| = atan(v^2 / (g R))
    assert np.max(np.abs(f1["bank_deg"][: 100 * 8])) == pytest.approx(
        math.degrees(math.atan(22.0 ** 2 / (9.80665 * 160.0))), abs=1e-6)


def test_parameter_table_has_both_deviations(result, report):
    out, _ = report
    data = json.loads((out / "parameters.json").read_text())
    rows = {r["name"]: r for r in data["parameters"]}
    assert list(rows) == list(result.param_names)
    for k in result.param_names:
        assert rows[k]["value"] == pytest.approx(result.params[k])
        assert rows[k]["std_cramer_rao"] == pytest.approx(result.std[k])
        assert rows[k]["std_corrected"] == pytest.approx(result.std_corrected[k])
    page = (out / "report.html").read_text()
    assert "std (Cramer-Rao)" in page and f"{result.p[0]:.5g}" in page
