"""What the diagnosis says beside the effects: level offsets of one microphone or one flight, mixed segments,
bounds of the height search, effects the card holds already, and an ansatz without the offset the data need.

Every campaign is the diagnosis base scenario (``sample_data/scenarios/diagnosis_base.json``) made by the
simulator with the demonstration card and no effect, or with the bank-angle effect its scenario switch injects
(louder turns, at the simulator's default magnitude); the faults are put into the levels afterwards, so their
size is known exactly: a microphone's levels (overall and bands) raised by 3.00 dB, every microphone of one
flight raised by 2.00 dB.  A constant added to some rows is exactly what one offset parameter describes, so
the candidates judged with the offsets the diagnosis names must score as on the same campaign without the fault.
"""

from __future__ import annotations

import functools
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise import simulate
from gisnoise.cli.main import cli
from gisnoise.diagnose import fold_labels, judged_with, localize, run_diagnosis, with_offsets
from gisnoise.diagnose._offset_model import offset_parameter
from gisnoise.diagnose.diagnosis import _held_in_folds
from gisnoise.errors import FitError
from gisnoise.identify import fit_arrays
from gisnoise.measure import Samples, series_key
from gisnoise.model import cards, get_ansatz

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "sample_data" / "scenarios" / "diagnosis_base.json"
CARDS = ROOT / "gisnoise" / "data" / "cards"
CARD = CARDS / "demo_horizontal.json"


@functools.cache
def control(seed: int = 1, effect: str | None = None) -> Samples:
    """The base scenario, with one effect of the simulator at its default magnitude when ``effect`` is given."""
    doc = json.loads(SCENARIO.read_text())
    doc["seed"] = seed
    if effect:
        doc["effects"] = {effect: {}}
    return simulate.simulate_samples(simulate.run(doc, base_dir=SCENARIO.parent))


def raised(s: Samples, rows: np.ndarray, db: float) -> Samples:
    """The samples with the levels (overall and bands) of ``rows`` raised by ``db``: a calibration error."""
    level = np.array(s.level, dtype=float)
    level[rows] += db
    bands = None if s.bands is None else np.array(s.bands, dtype=float)
    if bands is not None:
        bands[rows] += db
    return s.with_(level=level, bands=bands)


@functools.cache
def diagnosed(case: str, effect: str | None = None):
    s = control(1, effect)
    if case == "m2+3":
        s = raised(s, s.mic.astype(str) == "m2", 3.0)
    elif case == "f2+2":
        s = raised(s, s.flight.astype(str) == "f2", 2.0)
    return run_diagnosis(s, cards.load(CARD)).result


# --------------------------------------------------------------------------- level offsets


def test_a_microphone_3_db_off_is_named_with_its_offset():
    """m2 raised by 3.00 dB in both flights: the verdict stays null (no effect has that shape), and the level offset
    is named, 3 dB within two of its standard deviations; no other microphone and no flight is named."""
    r = diagnosed("m2+3")
    assert r["verdict"]["effect"] is None
    mics = r["metadata"]["level_offsets"]["microphones"]
    assert [m for m, e in mics.items() if e["named"]] == ["m2"]
    m2 = mics["m2"]
    assert 0.0 < m2["std_db"] < 0.1
    assert abs(m2["offset_db"] - 3.0) <= 2.0 * m2["std_db"], m2
    assert not any(e["named"] for e in r["metadata"]["level_offsets"]["flights"].values())
    (sentence,) = r["verdict"]["level_offsets"]
    assert sentence.startswith("microphone 'm2':") and "level offset" in sentence
    assert f"{m2['offset_db']:.2f} dB (+/- {m2['std_db']:.2f} dB) above" in sentence
    # the candidates were judged with m2's offset, and none qualifies: an offset alone names no effect
    (judged,) = r["verdict"]["candidates_judged_with"]["level_offsets"]
    assert (judged["group"], judged["id"], judged["held_in_folds"]) == ("microphone", "m2", False)
    assert abs(judged["offset_db"] - 3.0) <= 3.0 * judged["std_db"], judged
    assert r["verdict"]["effects"] == []


def test_a_flight_2_db_louder_is_named_with_its_offset():
    """Every microphone of f2 raised by 2.00 dB: f2 is named 2 dB louder than f1 within two of its standard
    deviations, no microphone is named (each is off in one flight only), and no effect."""
    r = diagnosed("f2+2")
    assert r["verdict"]["effect"] is None
    fl = r["metadata"]["level_offsets"]["flights"]
    assert fl["f2"]["named"] and not fl["f1"]["named"]
    assert 0.0 < fl["f2"]["std_db"] < 0.1
    assert abs(fl["f2"]["offset_db"] - 2.0) <= 2.0 * fl["f2"]["std_db"], fl
    assert not any(e["named"] for e in r["metadata"]["level_offsets"]["microphones"].values())
    (sentence,) = r["verdict"]["level_offsets"]
    assert sentence.startswith("flight 'f2':") and "louder than flight 'f1'" in sentence
    assert "calibration" in sentence and "vehicle" in sentence
    # the candidates were judged with f2's offset (held in the folds, which are the flights), and none qualifies
    (judged,) = r["verdict"]["candidates_judged_with"]["level_offsets"]
    assert (judged["group"], judged["id"], judged["held_in_folds"]) == ("flight", "f2", True)
    assert abs(judged["offset_db"] - 2.0) <= 3.0 * judged["std_db"], judged
    assert r["verdict"]["effects"] == []
    # with the offset, the held-out baseline is the clean campaign's: the flight's 2 dB no longer weighs on it
    clean = diagnosed("clean")["baseline"]["rms_db_holdout"]
    assert r["baseline"]["rms_db_holdout"] > clean + 0.5
    assert r["baseline"]["with_level_offsets"]["rms_db_holdout"] == pytest.approx(clean, abs=0.02)
    assert r["verdict"]["rms_db_holdout_baseline"] == pytest.approx(clean, abs=0.02)


def test_the_clean_campaign_names_no_offset():
    r = diagnosed("clean")
    assert r["verdict"]["level_offsets"] == []
    assert r["verdict"]["candidates_judged_with"] == {"level_offsets": [], "not_carried": [], "sentence": None}
    assert "with_level_offsets" not in r["baseline"]
    lo = r["metadata"]["level_offsets"]
    assert not any(e["named"] for e in lo["microphones"].values())
    assert not any(e["named"] for e in lo["flights"].values())
    assert abs(lo["flights"]["f2"]["offset_db"]) < 0.1


# --------------------------------------------------------------------------- an effect and an offset together


@pytest.mark.parametrize("case, group, name, truth", [("f2+2", "flights", "f2", 2.0), ("m2+3", "microphones", "m2", 3.0)])
def test_an_effect_and_an_offset_are_both_named_and_the_effect_judged_as_without_the_offset(case, group, name, truth):
    """Louder turns (the simulator's bank-angle effect) and one flight 2.00 dB louder, or one microphone 3.00 dB off:
    the verdict names bank_angle, the offset is named within 3 of its standard deviations of the truth, and the
    candidates were judged with it.  The offset is a constant the offset parameter describes exactly, so the
    effect's held-out scores are those of the same campaign without the fault: the held-out RMS before and after
    the effect within 0.02 dB, the shrinkage within 1 percentage point (the offset's estimate is the only
    difference; judged without the offset, the shrinkage was about half)."""
    ref = diagnosed("clean", "bank_angle")
    r = diagnosed(case, "bank_angle")
    assert ref["verdict"]["effect"] == "bank_angle" and ref["verdict"]["candidates_judged_with"]["level_offsets"] == []
    assert r["verdict"]["candidates_judged_with"]["not_carried"] == []  # bank angle stays significant with the offset
    v = r["verdict"]
    assert v["effect"] == "bank_angle"
    assert [e["effect"] for e in v["effects"]] == [e["effect"] for e in ref["verdict"]["effects"]]
    # the offset: named in the findings, and the one the candidates carried
    e = r["metadata"]["level_offsets"][group][name]
    assert e["named"] and abs(e["offset_db"] - truth) <= 3.0 * e["std_db"], e
    (sentence,) = v["level_offsets"]
    assert sentence.startswith(f"{'flight' if group == 'flights' else 'microphone'} '{name}':")
    (judged,) = v["candidates_judged_with"]["level_offsets"]
    assert judged["id"] == name and abs(judged["offset_db"] - truth) <= 3.0 * judged["std_db"], judged
    assert f"'{name}' ({judged['offset_db']:+.2f} dB" in v["candidates_judged_with"]["sentence"]
    # the effect judged as on the campaign without the offset
    assert v["rms_db_holdout_baseline"] == pytest.approx(ref["verdict"]["rms_db_holdout_baseline"], abs=0.02)
    assert v["rms_db_holdout_extended"] == pytest.approx(ref["verdict"]["rms_db_holdout_extended"], abs=0.02)
    assert v["holdout_shrinkage_pct"] == pytest.approx(ref["verdict"]["holdout_shrinkage_pct"], abs=1.0)
    bank = next(x for x in r["effects"] if x["name"] == "bank_angle")
    bank_ref = next(x for x in ref["effects"] if x["name"] == "bank_angle")
    assert bank["rank"] == 1 and bank["significant"]
    k, k_ref = bank["parameters"]["k_bank"], bank_ref["parameters"]["k_bank"]
    assert abs(k["value"] - k_ref["value"]) <= 2.0 * k_ref["std"], (k, k_ref)
    # the card's ansatz alone (no offset) misses the campaign by more than the offset-free campaign
    assert r["baseline"]["rms_db_holdout"] > ref["baseline"]["rms_db_holdout"] + 0.3


def test_an_offset_that_takes_up_an_effect_is_not_carried():
    """Added sound and ground reflection (the simulator's, at its defaults, seed 301): the reflection is heard at m4
    alone, the one microphone above the ground, and what the library's reflection term leaves there is named a
    level offset of m4.  With that offset in the model the reflection term is no longer significant: a constant at
    m4 takes up the effect, so the candidates are judged without it, both injected effects are named, and the
    verdict says why the offset was not carried."""
    doc = json.loads(SCENARIO.read_text())
    doc["seed"] = 301
    doc["effects"] = {"background_event": {}, "ground_reflection": {}}
    s = simulate.simulate_samples(simulate.run(doc, base_dir=SCENARIO.parent))
    r = run_diagnosis(s, cards.load(CARD)).result
    v = r["verdict"]
    assert sorted(e["effect"] for e in v["effects"]) == ["background_event", "ground_reflection"]
    assert r["metadata"]["level_offsets"]["microphones"]["m4"]["named"]
    judged = v["candidates_judged_with"]
    assert judged["level_offsets"] == [] and "with_level_offsets" not in r["baseline"]
    (n,) = judged["not_carried"]
    assert (n["group"], n["id"]) == ("microphone", "m4")
    (c,) = n["competes_with"]
    assert c["effect"] == "ground_reflection" and c["p_value"] >= r["alpha_per_test"] > c["p_value_without"]
    assert judged["sentence"].startswith("the level offset of microphone 'm4' is not carried into the candidates: "
                                         "with it, ground_reflection is no longer significant")


def test_the_folds_hold_the_offsets_they_cannot_tell_and_the_sentence_names_them():
    """Folds are the flights: f2's offset is held in them (one fold leaves f2 out, the other has f2 alone), and so is
    m4's when m4 was heard in f1 only; m2, heard in both flights, is refitted in each fold."""
    s = control()
    s = s.select(~((s.mic.astype(str) == "m4") & (s.flight.astype(str) == "f2")))
    fold, _, how = fold_labels(s)
    assert how == "flights"
    groups = [("flight", "f2"), ("mic", "m2"), ("mic", "m4")]
    names = [offset_parameter(k, v) for k, v in groups]
    assert _held_in_folds(groups, names, s, fold) == ("flight_offset_f2", "mic_offset_m4")
    # the sentence from a fit that carries the offsets
    level = np.array(s.level, dtype=float) + np.where(s.flight.astype(str) == "f2", 2.0, 0.0)
    model = with_offsets(get_ansatz("paper-offset"), groups)
    x = {**s.inputs(3000.0), "mic": s.mic.astype(str), "flight": s.flight.astype(str)}
    fit = fit_arrays(level, x, model, mic=s.mic.astype(str), series=series_key(s.mic.astype(str), s.flight),
                     time=s.t_e, reference_power_w=1.0)
    got = judged_with(fit, groups, ("flight_offset_f2", "mic_offset_m4"))
    f2, m2, m4 = got["level_offsets"]
    assert (f2["group"], m2["group"], m4["id"]) == ("flight", "microphone", "m4")
    assert [e["held_in_folds"] for e in got["level_offsets"]] == [True, False, True]
    assert abs(f2["offset_db"] - 2.0) <= 3.0 * f2["std_db"] and abs(m2["offset_db"]) <= 3.0 * m2["std_db"], got
    assert "of flight 'f2' (+" in got["sentence"] and "and microphone 'm4' (" in got["sentence"]
    assert "the offsets of flight 'f2', microphone 'm4' are held at their values on all data" in got["sentence"]
    assert judged_with(None, [], ()) == {"level_offsets": [], "not_carried": [], "sentence": None}


def test_the_command_line_and_the_report_name_the_microphone(tmp_path):
    """The researcher's case through the command line: m2's level files raised by 3.00 dB (LA and bands)."""
    camp = simulate.simulate(json.loads(SCENARIO.read_text()), tmp_path / "camp", base_dir=SCENARIO.parent)
    for f in sorted((camp / "mics" / "m2").glob("*.csv")):
        head, *rows = f.read_text().splitlines()
        cols = head.split(",")
        assert cols[0] == "t" and cols[1] == "LA"
        out = [head] + [",".join([v[0]] + [f"{float(x) + 3.0:.2f}" for x in v[1:]])
                        for v in (row.split(",") for row in rows)]
        f.write_text("\n".join(out) + "\n")
    out = tmp_path / "diag"
    run = CliRunner().invoke(cli, ["diagnose", str(camp), "--card", str(CARD), "--out", str(out)])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "diagnosis.json").read_text())
    (sentence,) = doc["verdict"]["level_offsets"]
    assert sentence.startswith("microphone 'm2':")
    m2 = doc["metadata"]["level_offsets"]["microphones"]["m2"]
    assert abs(m2["offset_db"] - 3.0) <= 2.0 * m2["std_db"] + 0.01  # the files round to 0.01 dB
    lines = run.output.splitlines()
    i = next(k for k, t in enumerate(lines) if t.startswith("verdict: "))
    assert lines[i + 1] == f"unexplained: {sentence}"
    judged = doc["verdict"]["candidates_judged_with"]["sentence"]
    assert judged.startswith("the candidates were fitted and judged on held-out data with the level offset of "
                             "microphone 'm2' (+")
    assert lines[i + 2] == f"judged with offsets: {judged}"
    page = (out / "report.html").read_text().replace("&#x27;", "'")
    assert f"Not explained by any effect: {sentence}" in page
    assert f"Judged with level offsets: {judged}" in page


# --------------------------------------------------------------------------- segments covering several regimes


def test_a_segment_over_a_turn_and_a_straight_is_mixed_with_the_shares():
    """A residual of +3 dB over a whole 300 s series whose first 55 % is a 30 deg turn: one segment over all of it,
    labelled mixed (no regime holds 80 %) with the shares 0.55 and 0.45."""
    t = np.arange(0.0, 300.0, 0.125)
    rng = np.random.default_rng(4)
    turn = t < 165.0
    n = t.size
    s = Samples(mic=np.full(n, "m1"), flight=np.full(n, "f1"), t_r=t, t_e=t, level=60.0 + rng.normal(0, 1, n),
                d=np.full(n, 100.0), phi=np.full(n, 0.3), theta=np.full(n, -0.5), power_w=np.full(n, 3000.0),
                phase=np.full(n, "horizontal"), roll=np.where(turn, 30.0, 0.0), pitch=np.full(n, 2.0),
                yaw=np.full(n, 90.0), uav_enu=np.column_stack([20.0 * t, np.zeros(n), np.full(n, 50.0)]),
                mic_enu=np.zeros((n, 3)), vel_enu=np.tile([20.0, 0.0, 0.0], (n, 1)), valid=np.ones(n, bool),
                mask_reason=np.full(n, ""))
    resid = s.level - 57.0
    (seg,), _ = localize(s, resid, {"m1": 1.0})
    assert seg["n"] == n
    assert seg["regime"] == "mixed"
    assert seg["regime_shares"] == {"turn": pytest.approx(0.55), "straight": pytest.approx(0.45)}
    # the same series in a turn throughout keeps its regime
    (whole,), _ = localize(s.with_(roll=np.full(n, 30.0)), resid, {"m1": 1.0})
    assert whole["regime"] == "turn" and whole["regime_shares"] == {"turn": 1.0}


def test_the_offset_microphones_whole_flight_segments_are_mixed():
    segs = [g for g in diagnosed("m2+3")["segments"] if g["mic"] == "m2" and g["t1"] - g["t0"] > 200.0]
    assert len(segs) == 2
    for g in segs:
        assert g["regime"] == "mixed"
        assert max(g["regime_shares"].values()) < 0.8
        assert sum(g["regime_shares"].values()) == pytest.approx(1.0)


# --------------------------------------------------------------------------- metadata, candidates, the card's ansatz


def test_heights_at_the_end_of_the_search_are_bounds_without_a_std():
    """The control has no ground reflection: no comb, and the best comb height is the search's upper end
    (3 m), reported as that bound without a standard deviation, contradicting nothing."""
    for m, h in diagnosed("clean")["metadata"]["microphone_heights"].items():
        assert h["at_search_limit"] is True, m
        assert h["height_m"] == 3.0 and h["std_m"] is None
        assert not h["contradicts"]


def test_an_effect_the_cards_ansatz_holds_is_not_a_candidate():
    base = cards.load(CARD)
    card = cards.from_dict({**base.to_dict(), "ansatz": "paper-offset+bank_angle",
                            "parameters": {**base.parameters, "k_bank": 0.0}, "covariance": None})
    r = run_diagnosis(control(), card, candidates=["bank_angle", "rpm"]).result
    by = {e["name"]: e for e in r["effects"]}
    assert by["bank_angle"]["testable"] is False
    assert by["bank_angle"]["reason"] == "already in the card's ansatz 'paper-offset+bank_angle'"
    assert by["rpm"]["testable"] is True
    assert r["alpha_per_test"] == pytest.approx(r["alpha"])  # one candidate tested


def test_a_card_without_the_offset_the_data_need_is_told_so():
    """published_horizontal (ansatz paper, no p0) on data made with the demo card (paper-offset): the refit cannot
    tell the parameters apart, and the message says the ansatz lacks the offset and gives p0 as the data have it:
    the demo card's p0 + p1 log10(1500 W / 3000 W) (the published card's reference power is half the demo's)."""
    demo = cards.load(CARD)
    pub = cards.load(CARDS / "published_horizontal.json")
    truth = demo.parameters["p0"] + demo.parameters["p1"] * math.log10(pub.reference_power_w / demo.reference_power_w)
    with pytest.raises(FitError) as err:
        run_diagnosis(control(), pub, candidates=["rpm"])
    msg = str(err.value)
    assert "has no level offset p0, and these data need one" in msg and "'paper-offset'" in msg
    got = re.search(r"p0 = ([-\d.]+) dB \(\+/- ([\d.]+) dB\)", msg)
    assert got, msg
    p0, sd = float(got.group(1)), float(got.group(2))
    assert abs(p0 - truth) <= 3.0 * sd + 0.01, (p0, sd, truth)
