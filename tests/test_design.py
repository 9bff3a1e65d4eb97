"""Measurement design: plan checks, the design model against the simulator, both objectives,
the paper's qualitative results (section 6, Fig. 18) and a short closing-the-loop check.

Expected values come from closed forms (the signal-to-noise distance of a card without
directivity, numpy's correlation coefficients), from the simulator flying the same pattern,
from the fit of simulated campaigns with a known truth, and from the paper's statements
about its optima; never from numbers the design code produced once.  The long study (full
Fig. 18 grid, many seeds) is in test_design_study.py (slow).
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import shapely
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.design import (
    PATTERN_PAIRS,
    Design,
    DesignModel,
    campaign_scenario,
    correlation_matrix,
    evaluate,
    load_plan,
    max_abs_correlation,
    optimize,
    resolve_plan,
    run_design,
    snr_distance,
    study,
    verify,
)
from gisnoise.design.objectives import _corr_batch, _objective_batch
from gisnoise.errors import DesignError
from gisnoise.geo import LocalFrame
from gisnoise.model import cards
from gisnoise.simulate import run

ROOT = Path(__file__).resolve().parent.parent
PLAN = ROOT / "sample_data" / "plans" / "paper_racetrack.json"
CARD = ROOT / "gisnoise" / "data" / "cards" / "demo_horizontal.json"


def plan_doc(**changes):
    doc = json.loads(PLAN.read_text(encoding="utf-8"))
    doc.update(copy.deepcopy(changes))
    return doc


def make_plan(**changes):
    return resolve_plan(plan_doc(**changes), base_dir=PLAN.parent)


@pytest.fixture(scope="module")
def model():
    return DesignModel.build(load_plan(PLAN))


def geojson_polygon(frame, e0, n0, e1, n1):
    """A lon/lat GeoJSON Polygon of the local rectangle [e0, e1] x [n0, n1] m."""
    es = np.array([e0, e1, e1, e0, e0], dtype=float)
    ns = np.array([n0, n0, n1, n1, n0], dtype=float)
    lat, lon, _ = frame.to_wgs84(es, ns, np.zeros(5))
    return {"type": "Polygon", "coordinates": [[[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]]}


# --------------------------------------------------------------------------- plan


def test_sample_plan_is_the_papers_base_solution():
    plan = load_plan(PLAN)
    assert plan.n_reps == 3 and np.all(plan.base.altitudes == 60.0)
    assert plan.n_mics == 3
    # microphones near the pattern's centre: inside the racetrack's straights
    pat = plan.doc["pattern"]
    assert np.all(np.abs(plan.base.mic_e - pat["centre"][0]) < pat["straight_m"] / 2)
    assert np.all(np.abs(plan.base.mic_n - pat["centre"][1]) < pat["radius_m"])
    # the simulator's default radius: a 30 degree coordinated turn at the pattern's speed
    assert math.degrees(math.atan(pat["speed_m_s"] ** 2 / (9.80665 * pat["radius_m"]))) == pytest.approx(30.0, abs=0.05)


def test_snr_distance_closed_form_without_directivity():
    """With p2 = p4 = 0, L_UAV = p0 + p1 log10(P_el) - 20 p6 log10(d / 40 m) in every direction."""
    card = cards.load(CARD)
    p = dict(card.parameters)
    p.update(p2=0.0, p4=0.0)
    flat = cards.with_parameters(card, [p[k] for k in card.model.params])
    level, power = 43.0, 1.2 * card.reference_power_w
    expect = 40.0 * 10 ** ((p["p0"] + p["p1"] * math.log10(1.2) - level) / (20.0 * p["p6"]))
    assert snr_distance(flat, level, power_w=power) == pytest.approx(expect, rel=1e-6)
    # the plan computes it from background + margin at the cruise power
    plan = make_plan(snr={"background_db": 40.0, "margin_db": 5.0})
    assert plan.max_distance_m == pytest.approx(snr_distance(plan.card, 45.0, power_w=plan.card.reference_power_w),
                                                rel=1e-9)
    assert make_plan(snr={"max_distance_m": 250.0}).max_distance_m == 250.0


@pytest.mark.parametrize("change, fld", [
    ({"altitudes": [{"base_m": 60, "min_m": 35, "max_m": 200}, {"base_m": 60, "min_m": 150, "max_m": 50},
                    {"base_m": 60}]}, "altitudes[1].min_m"),
    ({"microphones": [{"id": "m1", "e": 0, "n": 0, "max_shift_m": -5}]}, "microphones[0].max_shift_m"),
    ({"microphones": [{"id": "m1", "e": 0, "n": 0, "max_shift_m": [10, 10, 10]}]}, "microphones[0].max_shift_m"),
    ({"pattern": {"type": "flyby", "through": [0, 0]}}, "pattern.type"),
    ({"pattern": {"type": "racetrack", "centre": [0, 0], "radius_m": 1.0}}, "pattern.radius_m"),
    ({"study": {"altitude_ranges_m": [[35, 200], [150, 50]]}}, "study.altitude_ranges_m[1]"),
    ({"objectives": ["a-optimal"]}, "objectives"),
    ({"colour": "red"}, "colour"),
    ({"card": "no_such_card"}, "card"),
    ({"card": {**cards.load(CARD).to_dict(), "ansatz": "paper-offset+rpm",
               "parameters": {**cards.load(CARD).parameters, "k_rpm": 0.0, "rpm_ref": 4800.0}, "covariance": None}},
     "card"),
])
def test_bad_plans_are_refused_naming_the_field(change, fld):
    with pytest.raises(DesignError) as err:
        make_plan(**change)
    assert err.value.field == fld
    assert fld in str(err.value)


def test_a_displacement_limit_beyond_the_patterns_reach_is_refused(model):
    """Every point of the racetrack lies within straight/2 + radius of its centre; m1 stands at the centre.  Moved
    east along the long axis by that plus the signal-to-noise distance, it hears nothing; 20 m less, it hears the
    turn's far end.  A limit beyond that reach is refused naming the field (1e9 m put m1 1e8 m away, n_usable 0)."""
    plan = model.plan
    pat = plan.doc["pattern"]
    assert (plan.base.mic_e[0], plan.base.mic_n[0]) == tuple(pat["centre"]) == (0.0, 0.0) and pat["heading_deg"] == 90
    reach = pat["straight_m"] / 2 + pat["radius_m"] + plan.max_distance_m
    for shift, heard in ((reach + 1.0, False), (reach - 20.0, True)):
        d = Design(plan.base.mic_e + np.array([shift, 0.0, 0.0]), plan.base.mic_n, plan.base.altitudes)
        assert (evaluate(model, d).n_usable_per_mic["m1"] > 0) is heard, shift
    mics = copy.deepcopy(plan_doc()["microphones"])
    mics[0]["max_shift_m"] = 1e9
    with pytest.raises(DesignError) as err:
        make_plan(microphones=mics)
    assert err.value.field == "microphones[0].max_shift_m"
    msg = str(err.value)
    assert "\n" not in msg and f"beyond {reach:.0f} m" in msg
    assert f"signal-to-noise distance ({plan.max_distance_m:.0f} m)" in msg
    mics[0]["max_shift_m"] = math.floor(reach) - 1.0
    assert make_plan(microphones=mics).max_shift[0, 0] == math.floor(reach) - 1.0
    with pytest.raises(DesignError) as err:
        make_plan(study={"displacements_m": [0, 100, 5000]})
    assert err.value.field == "study.displacements_m"


def test_a_deaf_microphone_and_a_base_outside_its_range_are_warned(tmp_path):
    """m4 at 3 km east, fixed: 2.7 km from the pattern's nearest point, beyond the signal-to-noise distance, so it
    hears nothing in the base or any optimum; repetition 0 based at 20 m, below its 35 m minimum.  Both are said on
    the console (also with -q), in design.json and, for the microphone, in layout.geojson."""
    doc = plan_doc(optimizer={"maxiter": 3, "popsize": 5}, study=None, verify={"seeds": 0})
    doc["altitudes"][0] = {"base_m": 20.0, "min_m": 35.0, "max_m": 200.0}
    doc["microphones"].append({"id": "m4", "e": 3000.0, "n": 0.0, "max_shift_m": 0.0})
    p = tmp_path / "plan.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["-q", "design", str(p), "--out", str(out), "--no-report"])
    assert r.exit_code == 0, r.output
    res = json.loads((out / "design.json").read_text())
    said = [ln.removeprefix("warning: ") for ln in r.stderr.splitlines() if ln.startswith("warning: ")]
    assert said == res["warnings"] and len(said) == 4
    assert said[0].startswith("altitudes[0].base_m (20 m) is below altitudes[0].min_m (35 m)")
    assert res["base"]["feasible"] is False and res["base"]["altitudes_m"][0] == 20.0
    for label, w in zip(("the base design", "the paper optimum", "the d-optimal optimum"), said[1:], strict=True):
        assert w.startswith(f"{label} has microphone 'm4' at e 3000 m, n 0 m") and "no usable sample" in w
    gj = json.loads((out / "layout.geojson").read_text())
    assert gj["warnings"] == res["warnings"]
    for f in gj["features"]:
        if f["properties"]["kind"] == "microphone":
            deaf = f["properties"]["id"] == "m4"
            assert ("warning" in f["properties"]) is deaf and (f["properties"]["n_usable"] == 0) is deaf


def test_exclusions_covering_every_allowed_position_are_refused():
    frame = LocalFrame(52.3186, 10.5564, 125.0)
    # m2 may move +-200 m about (40, 20): a polygon over (-165..245) x (-185..225) covers all of it,
    # while m1 and m3 keep a strip west of -165 m
    cover = geojson_polygon(frame, -165.0, -185.0, 245.0, 225.0)
    with pytest.raises(DesignError) as err:
        make_plan(exclusions={"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": cover}]})
    assert err.value.field == "exclusions" and "every allowed position of microphone 'm2'" in str(err.value)
    # a point that may not move, inside a polygon
    mics = [{"id": "m1", "e": 0.0, "n": 0.0, "max_shift_m": 0.0}]
    with pytest.raises(DesignError, match="exclusions"):
        make_plan(microphones=mics, exclusions=geojson_polygon(frame, -5.0, -5.0, 5.0, 5.0))
    # not a polygon
    with pytest.raises(DesignError) as err:
        make_plan(exclusions={"type": "Point", "coordinates": [10.5, 52.3]})
    assert err.value.field == "exclusions.type"


def test_cli_refuses_an_infeasible_plan_with_exit_2(tmp_path):
    doc = plan_doc(altitudes=[{"base_m": 60, "min_m": 120, "max_m": 80}] * 3)
    p = tmp_path / "plan.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    r = CliRunner().invoke(cli, ["design", str(p), "--out", str(tmp_path / "out")])
    assert r.exit_code == 2
    assert "altitudes[0].min_m" in r.output and "Traceback" not in r.output
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- design model


def test_design_model_flies_the_simulators_pattern(model):
    """Heights from the pattern's climb rule (u = W h) and distances equal the simulator's own flight."""
    plan = model.plan
    design = Design(plan.base.mic_e + np.array([30.0, -20.0, 10.0]), plan.base.mic_n - 15.0,
                    np.array([40.0, 90.0, 150.0]))
    sim = run(campaign_scenario(model, design, seed=plan.seed))  # the power jitter of the model's flights
    tr = sim.flights[0].true
    i0 = int(np.argmax(tr["phase"] == "horizontal"))
    t = tr["t"][i0:] - tr["t"][i0]
    u_sim = np.interp(model.t, t, tr["u"][i0:])
    np.testing.assert_allclose(model.weights @ design.altitudes, u_sim, atol=1e-6)
    # each repetition flies at its altitude once the climb (first straight and turn) is done
    for k, h in enumerate(design.altitudes):
        late = (model.repetition == k) & (model.t > (k + 0.6) * model.duration_s / plan.n_reps)
        np.testing.assert_allclose(u_sim[late], h, atol=1e-6)
    # climbs cost power and raise the nose as in the simulator (flight-path angle, climb power)
    st = model.state(design.altitudes[None, :])
    np.testing.assert_allclose(st["power_w"][0], np.interp(model.t, t, tr["power_w"][i0:]), rtol=1e-9)
    np.testing.assert_allclose(st["pitch"][0], np.interp(model.t, t, tr["pitch"][i0:]), atol=1e-9)
    climbing = st["vz"][0] > 1.0
    assert climbing.sum() > 20 and np.all(st["power_w"][0][climbing] > model.power_level_w[climbing] + 100.0)
    s = model.samples(design)
    e_sim, n_sim = np.interp(model.t, t, tr["e"][i0:]), np.interp(model.t, t, tr["n"][i0:])
    for i in range(plan.n_mics):
        d = np.sqrt((design.mic_e[i] - e_sim) ** 2 + (design.mic_n[i] - n_sim) ** 2 + u_sim ** 2)
        np.testing.assert_allclose(s["d"][s["mic"] == i], d, rtol=1e-9)
    assert model.duration_s == pytest.approx(3 * (2 * 400.0 + 2 * math.pi * plan.doc["pattern"]["radius_m"]) / 24.0,
                                             abs=0.05)


def test_correlations_are_numpys(model):
    rng = np.random.default_rng(5)
    cols = {"a": rng.normal(size=200), "b": rng.normal(size=200)}
    cols["c"] = cols["a"] * 2.0 + 0.1 * rng.normal(size=200)
    np.testing.assert_allclose(correlation_matrix(cols), np.corrcoef(np.vstack(list(cols.values()))), atol=1e-12)
    assert max_abs_correlation(cols) == pytest.approx(abs(np.corrcoef(cols["a"], cols["c"])[0, 1]))
    assert max_abs_correlation(cols, skip=[("a", "c")]) == pytest.approx(
        max(abs(np.corrcoef(cols["a"], cols["b"])[0, 1]), abs(np.corrcoef(cols["b"], cols["c"])[0, 1])))
    # a constant column cannot be told from an offset: correlation 1
    assert max_abs_correlation({"a": cols["a"], "k": np.full(200, 3.0)}) == 1.0
    # the batched kernel of the optimizer over a design's usable rows
    plan = model.plan
    designs = [plan.base, Design(plan.base.mic_e + 150.0, plan.base.mic_n - 120.0, np.array([35.0, 200.0, 80.0]))]
    s = model.samples_batch(np.array([d.mic_e for d in designs]), np.array([d.mic_n for d in designs]),
                            np.array([d.altitudes for d in designs]))
    s["usable"][1, ::3] = False  # some rows beyond the signal-to-noise distance
    corr = _corr_batch(model, s)
    j = s["sample"]
    for i in range(2):
        u = s["usable"][i]
        x = np.vstack([s["power_w"][i][u], np.degrees(s["theta"][i][u]), s["d"][i][u], np.degrees(model.roll[j][u])])
        np.testing.assert_allclose(corr[i], np.corrcoef(x), atol=1e-10)
    ev = evaluate(model)
    assert ev.max_abs_corr == pytest.approx(np.max(np.abs(ev.correlation[[0, 0, 1, 1, 2], [1, 2, 2, 3, 3]])))
    assert PATTERN_PAIRS == (("power", "bank"),)
    assert ev.max_abs_corr_all >= ev.max_abs_corr


# --------------------------------------------------------------------------- the paper's results (section 6)


def test_paper_objective_puts_altitudes_at_their_bounds_and_a_microphone_at_its_limit(model):
    res = optimize(model, "paper", maxiter=80, popsize=10)
    plan = model.plan
    lo, hi = plan.altitude_range[0]
    span = hi - lo
    near = [min(abs(h - lo), abs(h - hi)) / span for h in res.design.altitudes]
    assert max(near) < 0.02, res.design.altitudes
    assert min(res.design.altitudes) < lo + 0.02 * span and max(res.design.altitudes) > hi - 0.02 * span
    shifts = np.abs(np.column_stack([res.design.mic_e - plan.base.mic_e, res.design.mic_n - plan.base.mic_n]))
    assert np.any(shifts >= 0.99 * plan.max_shift), shifts
    assert any(res.at_shift_limit.values())
    # the base solution is as strongly correlated as the paper's (0.89); the optimum far less
    assert res.base_value > 0.85
    assert res.value < 0.6 * res.base_value
    assert res.evaluation.feasible


def test_objective_falls_with_allowed_displacement_and_altitude_spread(model):
    pts = study(model.plan, model=model, objectives=["paper"], displacements_m=[0.0, 50.0, 200.0],
                altitude_ranges_m=[[60.0, 60.0], [35.0, 200.0]], maxiter=30, popsize=8)
    val = {(p.altitude_range_m, p.max_shift_m): p.value for p in pts}
    for rng in ((60.0, 60.0), (35.0, 200.0)):
        v = [val[(rng, s)] for s in (0.0, 50.0, 200.0)]
        assert v[0] - v[1] > 0.02 and v[1] - v[2] > 0.05, (rng, v)
    for s in (0.0, 50.0, 200.0):
        assert val[((35.0, 200.0), s)] < val[((60.0, 60.0), s)] - 0.05
    # no displacement, fixed altitude: the base design itself
    assert val[((60.0, 60.0), 0.0)] == pytest.approx(evaluate(model).max_abs_corr)


def test_an_exclusions_file_with_a_byte_order_mark_reads_as_the_object(tmp_path):
    """An exclusions GeoJSON file saved with a UTF-8 byte-order mark gives the same polygons as the object itself."""
    frame = load_plan(PLAN).frame
    pond = geojson_polygon(frame, 100.0, -300.0, 140.0, -260.0)
    f = tmp_path / "pond.geojson"
    f.write_bytes(b"\xef\xbb\xbf" + json.dumps(pond).encode())
    assert make_plan(exclusions=str(f)).exclusions == make_plan(exclusions=pond).exclusions


def test_exclusions_are_respected(model):
    frame = model.plan.frame
    # the unconstrained optima move microphones east of the pattern's centre; forbid that area
    east = geojson_polygon(frame, 100.0, -300.0, 400.0, 300.0)
    plan = make_plan(exclusions={"type": "Feature", "properties": {"name": "pond"}, "geometry": east},
                     snr={"max_distance_m": model.plan.max_distance_m})
    sub = DesignModel.build(plan)
    res = optimize(sub, "paper", maxiter=25, popsize=8)
    poly = shapely.box(100.0, -300.0, 400.0, 300.0)
    assert not np.any(shapely.contains_xy(poly, res.design.mic_e, res.design.mic_n))
    assert res.evaluation.feasible
    assert "constraints" in res.settings["exclusions"]
    assert res.value < res.base_value
    # a design with a microphone in the polygon is flagged
    bad = Design(plan.base.mic_e + np.array([0.0, 150.0, 0.0]), plan.base.mic_n, plan.base.altitudes)
    assert not evaluate(sub, bad).feasible


def test_optimizer_is_seeded_and_reproducible(model):
    a = optimize(model, "d-optimal", maxiter=4, popsize=5, seed=11)
    b = optimize(model, "d-optimal", maxiter=4, popsize=5, seed=11)
    c = optimize(model, "d-optimal", maxiter=4, popsize=5, seed=12)
    np.testing.assert_array_equal(a.design.vector(model.plan.base), b.design.vector(model.plan.base))
    assert not np.array_equal(a.design.vector(model.plan.base), c.design.vector(model.plan.base))
    calls = []
    optimize(model, "paper", maxiter=3, popsize=5, progress=calls.append)
    assert calls and calls[-1] == 1.0 and all(0 <= f <= 1 for f in calls)


# --------------------------------------------------------------------------- closing the loop (short)


def test_d_optimal_design_shrinks_the_scatter_of_refitted_campaigns(model):
    """Campaigns simulated with the card as truth and refitted: the D-optimal design's estimates
    scatter less than the base design's (same pattern and flight time, same noise), about as much
    less as the Cramer-Rao bounds of the design model predict."""
    plan = model.plan
    opt = optimize(model, "d-optimal", maxiter=40, popsize=8)
    assert opt.evaluation.log_det_fisher > opt.base.log_det_fisher + 5.0
    ver = verify(model, {"base": plan.base, "d-optimal": opt.design}, list(range(500, 506)))
    assert not ver.failures["base"] and not ver.failures["d-optimal"]
    assert ver.duration_s["base"] == pytest.approx(ver.duration_s["d-optimal"], abs=1e-6)
    ratio = ver.ratio("d-optimal")
    assert ver.geometric_mean_ratio("d-optimal") < 0.5, ratio
    assert np.sum(ratio < 1.0) >= 7, ratio
    # the design model's expected standard deviations are the fits' Cramer-Rao bounds
    # (p7, the background, is nonlinear where the UAV is loud; p1 depends on the power jitter drawn)
    names = list(ver.param_names)
    for d in ("base", "d-optimal"):
        for k in ("p0", "p2", "p3", "p4", "p5", "p6"):
            i = names.index(k)
            assert ver.expected_std[d][i] == pytest.approx(ver.mean_cr_std[d][i], rel=0.25), (d, k)


# --------------------------------------------------------------------------- outputs and CLI


def test_cli_writes_layout_variables_and_report(tmp_path):
    doc = plan_doc(optimizer={"maxiter": 6, "popsize": 5},
                   study={"displacements_m": [0, 100], "altitude_ranges_m": [[60, 60]], "maxiter": 4, "popsize": 5},
                   verify={"seeds": 2})
    p = tmp_path / "plan.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["-q", "design", str(p), "--out", str(out)])
    assert r.exit_code == 0, r.output
    for name in ("design.json", "layout.geojson", "report.html", "layout.png", "correlation.png", "study.png",
                 "std.png"):
        assert (out / name).is_file(), name
    res = json.loads((out / "design.json").read_text())
    assert res["schema"] == "gisnoise/design-result/1"
    assert res["warnings"] == [] and "warning" not in r.stderr
    assert set(res["optima"]) == {"paper", "d-optimal"}
    plan = load_plan(PLAN)
    base = evaluate(DesignModel.build(plan))
    assert res["base"]["objectives"]["paper"] == pytest.approx(base.max_abs_corr)
    assert res["base"]["objectives"]["d-optimal"] == pytest.approx(base.log_det_fisher)
    for o in res["optima"].values():
        assert o["value"] <= o["base_value"] + 1e-12
        lo, hi = np.array(res["variables"]["lower"]), np.array(res["variables"]["upper"])
        v = np.array(o["design"]["variables"])
        assert np.all(v >= lo - 1e-9) and np.all(v <= hi + 1e-9)
    assert len(res["study"]) == 2 and res["verify"]["designs"]["d-optimal"]["n_fits"] == 2
    gj = json.loads((out / "layout.geojson").read_text())
    assert gj["warnings"] == [] and not any("warning" in f["properties"] for f in gj["features"])
    kinds = [(f["properties"]["kind"], f["properties"]["design"]) for f in gj["features"]]
    assert kinds.count(("microphone", "base")) == 3 and kinds.count(("track", "d-optimal")) == 1
    # microphone coordinates are lon/lat of the design's local positions
    for f in gj["features"]:
        if f["properties"]["kind"] == "microphone":
            lon, lat, h = f["geometry"]["coordinates"]
            e, n, _ = plan.frame.to_enu(lat, lon, h)
            assert float(e) == pytest.approx(f["properties"]["e_m"], abs=1e-3)
            assert float(n) == pytest.approx(f["properties"]["n_m"], abs=1e-3)
        else:
            hs = np.array(f["geometry"]["coordinates"])[:, 2] - plan.doc["origin"]["h"]
            assert hs.min() == pytest.approx(min(f["properties"]["altitudes_m"]), abs=0.5)
    page = (out / "report.html").read_text()
    assert "Closing the loop" in page and "times less than with the base design" in page


def test_run_design_without_study_or_verification(model):
    plan = model.plan.with_limits(max_shift_m=0.0, altitude_range_m=(60.0, 60.0))
    res = run_design(plan, objectives=["paper"], with_study=False, verify_seeds=0)
    o = res.optima["paper"]
    assert o.nit == 0 and o.value == pytest.approx(o.base_value)
    assert res.study == [] and res.verify is None
    with pytest.raises(DesignError):
        model.plan.with_limits(altitude_range_m=(80.0, 40.0))


@pytest.mark.parametrize("effect, extra", [("bank_angle", {"k_bank": 3.0}), ("doppler", {"q_doppler": 4.0})])
def test_extended_ansatz_cards_are_designed_for(model, effect, extra):
    """A card with a model extension (the paper asks for the bank angle in future models): its extra
    parameter gets an expected standard deviation, and the batched Fisher information of the optimizer
    equals the one of a single design."""
    base = cards.load(CARD)
    card = cards.from_dict({**base.to_dict(), "ansatz": f"paper-offset+{effect}",
                            "parameters": {**base.parameters, **extra}, "covariance": None})
    plan = resolve_plan(plan_doc(), base_dir=PLAN.parent, card=card)
    m = dataclasses.replace(model, plan=plan)
    ev = evaluate(m)
    (name,) = extra
    assert np.isfinite(ev.expected_std[name]) and ev.expected_std[name] > 0
    other = Design(plan.base.mic_e + 80.0, plan.base.mic_n, np.array([40.0, 120.0, 180.0]))
    batch = _objective_batch(m, "d-optimal")([plan.base, other])
    np.testing.assert_allclose(-batch, [ev.log_det_fisher, evaluate(m, other).log_det_fisher], rtol=1e-9)
