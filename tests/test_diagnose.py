"""The diagnosis: localization, event detection, folds, and blind proofs on simulated campaigns.

The simulated campaigns come from the simulator (``gisnoise.simulate.simulate``) with one
effect injected by its scenario switch; the diagnosis does not know which, and
the simulator's forms are its own (the library's extension terms are not
copies of them).  The control has no effect.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path

import _study_sim as study  # the independent study simulator (tests/_study_sim.py)
import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise import simulate
from gisnoise.cli.diagnose import command as diagnose_command
from gisnoise.cli.main import cli
from gisnoise.diagnose import (
    DIAGNOSIS_FILE,
    SCHEMA,
    Diagnosis,
    diagnose,
    fold_labels,
    localize,
    measurement_noise,
    residual_events,
    run_diagnosis,
    write_diagnosis,
)
from gisnoise.diagnose._rows import _band_entries, _loud_samples
from gisnoise.diagnose._series import _window_mean_error
from gisnoise.errors import Cancelled, InputError
from gisnoise.measure import Samples
from gisnoise.model import cards, level_sum

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "sample_data" / "scenarios" / "diagnosis_base.json"
CARD = ROOT / "gisnoise" / "data" / "cards" / "demo_horizontal.json"
EFFECTS = ["bank_angle", "atmospheric_absorption", "ground_reflection", "doppler", "emission_time", "wind", "rpm",
           "background_event"]


# --------------------------------------------------------------------------- helpers


def table(t, mic, level, *, flight="f1", d=100.0, roll=0.0):
    """A minimal Samples table (UAV flying east at 20 m/s, 50 m up)."""
    n = len(t)
    arr = lambda v: np.broadcast_to(np.asarray(v, dtype=float), (n,)).copy()  # noqa: E731
    uav = np.column_stack([20.0 * np.asarray(t), np.zeros(n), np.full(n, 50.0)])
    return Samples(mic=np.asarray(mic).astype(str), flight=np.broadcast_to(np.asarray(flight), (n,)).astype(str),
                   t_r=np.asarray(t, float), t_e=np.asarray(t, float), level=np.asarray(level, float), d=arr(d),
                   phi=arr(0.3), theta=arr(-0.5), power_w=arr(3000.0), phase=np.full(n, "horizontal"), roll=arr(roll),
                   pitch=arr(2.0), yaw=arr(90.0), uav_enu=uav, mic_enu=np.zeros((n, 3)),
                   vel_enu=np.tile([20.0, 0.0, 0.0], (n, 1)), valid=np.ones(n, bool), mask_reason=np.full(n, ""))


@functools.cache
def simulated(effect: str | None, seed: int = 1):
    """(SimulationResult, Samples) of the diagnosis base scenario with one effect at its default magnitude."""
    doc = json.loads(SCENARIO.read_text())
    doc["seed"] = seed
    if effect:
        doc["effects"] = {effect: {}}
    res = simulate.run(doc, base_dir=SCENARIO.parent)
    return res, simulate.simulate_samples(res)


@functools.cache
def diagnosed(effect: str | None, seed: int = 1):
    _, samples = simulated(effect, seed)
    return run_diagnosis(samples, cards.load(CARD))


# --------------------------------------------------------------------------- pure parts


def test_window_mean_error_counts_coloured_noise():
    # AR(1) noise, rho = 0.8: the standard error of a 16-sample mean is
    # sigma sqrt(1/n (1 + 2 sum_k (1 - k/n) rho^k)), far above the white sigma / 4
    rng = np.random.default_rng(3)
    rho, sigma, n_w, n = 0.8, 1.0, 16, 200_000
    z = rng.normal(0.0, sigma * math.sqrt(1 - rho * rho), n)
    e = np.empty(n)
    e[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + z[i]
    k = np.arange(1, n_w)
    exact = sigma * math.sqrt((1 + 2 * np.sum((1 - k / n_w) * rho ** k)) / n_w)
    white = measurement_noise(e, np.zeros(n, int), np.arange(n) * 0.125, np.full(n, "m"))["m"]
    got = _window_mean_error(e, n_w, white)
    assert got == pytest.approx(exact, rel=0.05)
    assert white / math.sqrt(n_w) < 0.6 * exact


def test_loud_samples_are_each_microphones_louder_half_or_15_db_above_the_background():
    """One rule for the band-level test and the band-slope evidence: without the card's background a
    microphone's louder half (its own median), so a far microphone, quieter throughout, keeps its half."""
    t = np.arange(100.0)
    level = np.r_[t, t - 200.0]  # microphone b entirely below a's quietest sample
    mic = np.r_[np.full(100, "a"), np.full(100, "b")]
    loud = _loud_samples(level, mic)
    assert np.array_equal(loud, np.r_[t >= 50.0, t >= 50.0])  # median 49.5 of 0..99 (and of -200..-101 + 200)
    assert np.array_equal(_loud_samples(level, mic, background_db=40.0), level > 55.0)
    # band entries: loud samples, bands 10 dB above their 5th percentile, >= 30 of them over >= 50 m
    bands = np.column_stack([level, np.full(200, 7.0), level])
    d = np.r_[2.0 * t, 2.0 * t]  # the louder half spans 98 m
    ok = _band_entries(level, mic, bands, d, exclude=np.r_[np.zeros(100, bool), np.ones(100, bool)])
    floor = np.percentile(level, 5)  # 5th percentile of the band levels: -190.05
    assert np.array_equal(ok[:, 0], np.r_[t >= 50.0, np.zeros(100, bool)]) and floor + 10 < 50.0
    assert not ok[:, 1].any()  # a flat band never stands above its own floor
    assert np.array_equal(ok[:, 2], ok[:, 0])
    short = _band_entries(level, mic, bands, np.zeros(200))  # no distance span: no band
    assert not short.any()
    unmeasured = np.column_stack([level, np.full(200, np.nan)])  # a band without any level: no entry, no warning
    got = _band_entries(level, mic, unmeasured, d)
    assert np.array_equal(got[:, 0], _band_entries(level, mic, bands, d)[:, 0]) and not got[:, 1].any()
    assert np.array_equal(got[:, 0], np.r_[t >= 50.0, t >= 50.0])  # no exclusion: both microphones' louder half


def test_localize_finds_a_known_excess_and_nothing_in_noise():
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 300.0, 0.125)
    r = rng.normal(0.0, 1.0, t.size)
    bump = (t >= 100.0) & (t < 130.0)
    level = 60.0 + r + 3.0 * bump
    s = table(t, np.full(t.size, "m1"), level, roll=np.where(bump, 30.0, 0.0))
    resid = level - 60.0
    noise = measurement_noise(resid, np.zeros(t.size, int), t, s.mic)
    segs, flagged = localize(s, resid, noise)
    assert len(segs) == 1
    g = segs[0]
    assert g["t0"] == pytest.approx(100.0, abs=1.5) and g["t1"] == pytest.approx(130.0, abs=1.5)
    assert g["regime"] == "turn" and g["excess_db"] == pytest.approx(3.0, abs=0.3)
    quiet, flagged_q = localize(s, r, noise)
    assert quiet == [] and not flagged_q.any()


def three_mics(extra):
    """Three microphones hearing the UAV at 70, 55 and 45 dB over 40 dB background for 120 s; ``extra(t, l_uav, bg)``
    returns the measured level."""
    t = np.arange(0.0, 120.0, 0.125)
    rows = []
    for m, lu in (("m1", 70.0), ("m2", 55.0), ("m3", 45.0)):
        l_uav = np.full(t.size, lu)
        bg = np.full(t.size, 40.0)
        rows.append((t, np.full(t.size, m), l_uav, bg, extra(t, l_uav, bg)))
    cat = [np.concatenate(c) for c in zip(*rows, strict=True)]
    rng = np.random.default_rng(1)
    level = cat[4] + rng.normal(0.0, 0.5, cat[0].size)
    s = table(cat[0], cat[1], level)
    resid = level - level_sum(cat[2], cat[3])
    noise = measurement_noise(resid, np.searchsorted(["m1", "m2", "m3"], cat[1]), cat[0], cat[1])
    return s, resid, noise, cat[2], cat[3]


def test_added_sound_is_an_event_a_louder_uav_is_not():
    inside = lambda t: (t > 40.0) & (t < 70.0)  # noqa: E731
    # a distant source at 60 dB heard by all: +0.04 dB at the loud microphone, +5.5 and +14.6 dB at the quiet ones
    s, r, nz, lu, bg = three_mics(lambda t, l_uav, b: level_sum(level_sum(l_uav, b), np.where(inside(t), 60.0, -99)))
    win, found = residual_events(s, r, nz, lu, bg)
    assert len(found) == 1 and found[0]["source"] == "detector"
    assert found[0]["t0"] == pytest.approx(40.0, abs=1.0) and found[0]["t1"] == pytest.approx(70.0, abs=1.0)
    assert np.all(win[inside(s.t_e) & (s.mic != "m1")] >= 0)
    # the UAV 6 dB louder for the same 30 s: every microphone it dominates rises by the same dB -> no event
    s, r, nz, lu, bg = three_mics(lambda t, l_uav, b: level_sum(l_uav + np.where(inside(t), 6.0, 0.0), b))
    win, found = residual_events(s, r, nz, lu, bg)
    assert found == [] and np.all(win < 0)


def test_folds_alternate_flights_or_time_blocks():
    t = np.arange(0.0, 200.0, 0.125)
    two = table(np.r_[t, t], np.full(2 * t.size, "m1"), np.zeros(2 * t.size),
                flight=np.r_[np.full(t.size, "a"), np.full(t.size, "b")])
    fold, _, how = fold_labels(two)
    assert how == "flights" and set(fold[:t.size]) == {0} and set(fold[t.size:]) == {1}
    one = table(t, np.full(t.size, "m1"), np.zeros(t.size))
    fold, block, how = fold_labels(one, block_s=30.0)
    assert how == "time blocks"
    np.testing.assert_array_equal(fold, (np.floor(t / 30.0) % 2).astype(int))
    assert len(np.unique(block)) == math.ceil(200.0 / 30.0)


# --------------------------------------------------------------------------- blind proofs on simulated campaigns


def test_control_gives_no_effect():
    r = diagnosed(None).result
    assert r["verdict"]["effect"] is None
    assert r["segments"] == [] and r["event_windows"] == []
    names = {e["name"] for e in r["effects"]}
    assert names == set(EFFECTS)
    # measurement noise recovered from the fast scatter: the scenario's noise_std_db per microphone
    truth = simulated(None)[1].meta["noise_std_db"]
    for m, sd in truth.items():
        assert r["noise_std_db"][m] == pytest.approx(sd, rel=0.1)


@pytest.mark.parametrize("effect", EFFECTS)
def test_each_injected_effect_is_named_with_held_out_shrinkage(effect):
    r = diagnosed(effect).result
    v = r["verdict"]
    assert v["effect"] == effect, [(e["name"], e.get("significant"), e.get("holdout_improvement_db2"))
                                   for e in r["effects"]]
    assert v["holdout_shrinkage_pct"] > 0.0
    assert v["rms_db_holdout_extended"] < v["rms_db_holdout_baseline"]
    top = next(e for e in r["effects"] if e["name"] == effect)
    assert top["rank"] == 1 and top["significant"]
    # the effect explains the gap: no microphone or flight is left with a level offset
    assert v["level_offsets"] == [], v["level_offsets"]


def test_bank_angle_segments_lie_in_the_simulated_turns():
    res, _ = simulated("bank_angle")
    segs = diagnosed("bank_angle").result["segments"]
    turns = {f.id: f.turns for f in res.flights}
    flagged = inside = 0.0
    for g in segs:
        flagged += g["t1"] - g["t0"]
        inside += sum(max(0.0, min(g["t1"], b) - max(g["t0"], a)) for a, b, *_ in turns[g["flight"]])
    assert flagged > 0 and inside / flagged >= 0.8
    # and most of the turn time is flagged at some microphone (turns served by the horizontal card)
    s = diagnosed("bank_angle").samples
    covered = total = 0.0
    for fl, tt in turns.items():
        te = np.sort(s.t_e[s.flight == fl])
        for a, b, *_ in tt:
            if not np.any((te > a) & (te < b)):
                continue
            grid = np.arange(a, b, 0.25)
            hit = np.zeros(grid.size, bool)
            for g in segs:
                if g["flight"] == fl:
                    hit |= (grid >= g["t0"]) & (grid <= g["t1"])
            covered += hit.sum()
            total += grid.size
    assert covered / total >= 0.8


def test_missing_inputs_make_candidates_not_testable():
    _, s = simulated(None)
    bare = s.with_(rpm=None, bands=None, band_f=None)
    r = diagnose(bare, cards.load(CARD), candidates=["rpm", "atmospheric_absorption", "bank_angle"])
    by = {e["name"]: e for e in r["effects"]}
    assert by["rpm"]["testable"] is False and by["rpm"]["reason"] == "no rpm column in the flight logs"
    assert by["atmospheric_absorption"]["testable"] is False
    assert "band levels" in by["atmospheric_absorption"]["reason"]
    assert by["bank_angle"]["testable"] is True and by["bank_angle"]["rank"] == 1
    assert r["verdict"]["effect"] is None


def test_cancel_stops_and_progress_counts():
    _, s = simulated(None)
    seen = []
    with pytest.raises(Cancelled):
        run_diagnosis(s, cards.load(CARD), progress=lambda d, n, what: seen.append((d, n, what)),
                      cancel=lambda: len(seen) >= 2)
    assert seen[0][:2] == (1, 11) and seen[0][2] == "localization"


def test_no_samples_of_the_cards_phase_is_refused():
    _, s = simulated(None)
    climb = cards.load(ROOT / "gisnoise" / "data" / "cards" / "demo_climb.json")
    only = s.select(s.phase == "horizontal")
    with pytest.raises(InputError, match="phase"):
        diagnose(only, climb)


# --------------------------------------------------------------------------- WAV campaign through the command line


def wav_scenario():
    return {
        "schema": "gisnoise/scenario/1", "name": "diag_wav", "seed": 7,
        "origin": {"lat": 52.3186, "lon": 10.5564, "h": 125.0},
        "weather": {"temperature_c": 15.0, "humidity_pct": 60.0, "pressure_kpa": 101.3},
        "microphones": [
            {"id": "m1", "e": 0.0, "n": 0.0, "mount": "ground_plate", "noise_std_db": 0.8},
            {"id": "m2", "e": 60.0, "n": 40.0, "mount": "ground_plate", "noise_std_db": 0.8}],
        "background": {"level_dba": 40.0, "spectrum": "ambient"},
        "output": {"format": "wav", "block_s": 0.125, "fs_hz": 16000, "band_max_hz": 5000.0},
        "flights": [{"id": "f1", "start": {"e": -200.0, "n": -100.0, "heading_deg": 90.0}, "patterns": [
            {"type": "climb", "to_height_m": 40.0, "rate_m_s": 4.0},
            {"type": "racetrack", "centre": [0.0, 20.0], "heading_deg": 90.0, "straight_m": 250.0,
             "heights_m": [40.0, 70.0], "laps": 1, "turn": "left", "speed_m_s": 24.0},
            {"type": "flyby", "through": [20.0, 10.0], "heading_deg": 0.0, "length_m": 400.0, "height_m": 35.0,
             "speed_m_s": 26.0}]}],
        "effects": {"rpm": {}},
    }


def test_wav_campaign_diagnosed_from_the_command_line(tmp_path):
    camp = simulate.simulate(wav_scenario(), tmp_path / "camp", base_dir=SCENARIO.parent)
    assert list((camp / "mics" / "m1").glob("*.wav"))
    out = tmp_path / "diag"
    run = CliRunner().invoke(cli, ["-q", "diagnose", str(camp), "--card", str(CARD), "--out", str(out)])
    assert run.exit_code == 0, run.output
    doc = json.loads((out / "diagnosis.json").read_text())
    # the SPEC section 6 shape
    assert isinstance(doc["baseline"]["rms_db"], float)
    for g in doc["segments"]:
        assert {"flight", "t0", "t1", "rms_db", "regime"} <= set(g)
    for e in doc["effects"]:
        assert {"name", "rank", "significant"} <= set(e)
        if e["testable"]:
            assert {"rms_db_fit", "rms_db_holdout", "shrinkage_pct"} <= set(e)
    assert doc["verdict"]["effect"] == "rpm" and doc["verdict"]["holdout_shrinkage_pct"] > 0
    assert doc["data"]["holdout"] == "time blocks"
    for f in ("report.html", "timeline_f1.png", "inputs.png", "before_after.png"):
        assert (out / f).stat().st_size > 1000
    # the numbers behind the before/after figure are the diagnosis' held-out RMS values
    ba = json.loads((out / "before_after.json").read_text())
    first = ba["candidates"][0]
    assert first["name"] == "rpm"
    by = {e["name"]: e for e in doc["effects"]}
    assert first["rms_db_holdout_after"] == pytest.approx(by["rpm"]["rms_db_holdout"], rel=1e-9)
    assert first["rms_db_holdout_before"] == pytest.approx(doc["baseline"]["rms_db_holdout"], rel=1e-9)
    assert "rpm" in (out / "report.html").read_text()


def test_cli_names_a_missing_card(tmp_path):
    run = CliRunner().invoke(cli, ["diagnose", str(tmp_path), "--card", str(tmp_path / "no.json"),
                                   "--out", str(tmp_path / "o")])
    assert run.exit_code == 2 and "no such card file" in run.output


def test_one_writer_of_diagnosis_json(tmp_path):
    """Every face writes diagnosis.json through write_diagnosis: strict JSON, indent 2, the campaign named."""
    diag = Diagnosis(result={"schema": SCHEMA, "verdict": {"effect": None, "p_value": float("nan")}},
                     samples=None, arrays={})
    path = write_diagnosis(diag, tmp_path, campaign="field day")
    assert path == tmp_path / DIAGNOSIS_FILE
    expected = {"schema": SCHEMA, "verdict": {"effect": None, "p_value": None}, "campaign": "field day"}
    assert path.read_text(encoding="utf-8") == json.dumps(expected, indent=2) + "\n"
    other = write_diagnosis(diag, tmp_path / "other.json", campaign="c")
    assert other == tmp_path / "other.json" and json.loads(other.read_text())["campaign"] == "c"
    assert "campaign" not in diag.result
    assert sorted(p.name for p in tmp_path.iterdir()) == [DIAGNOSIS_FILE, "other.json"]


# --------------------------------------------------------------------------- the campaign's metadata as a prior

TRIPOD_HEIGHTS = {"m1": 1.0, "m2": 1.2, "m3": 1.5, "m4": 1.3}


@functools.cache
def plates_control(seed: int = 5):
    """Samples of the base scenario with every microphone listed (and simulated) on a ground plate."""
    return study.control(seed, all_plates=True)


def test_position_radius_option_searches_or_takes_the_listed_positions(tmp_path):
    """m1 listed 30 m north of where it stood: by default (radius POSITION_RADIUS_M) the diagnosis places it back
    (within 5 m) and says so; with --position-radius 0 it takes the listed positions (no estimate)."""
    from gisnoise.diagnose.positions import POSITION_RADIUS_M

    camp = simulate.simulate(wav_scenario(), tmp_path / "camp", base_dir=SCENARIO.parent)
    meta = json.loads((camp / "campaign.json").read_text())
    m1 = next(m for m in meta["microphones"] if m["id"] == "m1")
    m1["lat"] += 30.0 / 111_200.0  # about 30 m north (a degree of latitude is 111.2 km here)
    (camp / "campaign.json").write_text(json.dumps(meta))
    default = next(p for p in diagnose_command.params if p.name == "position_radius").default
    assert default == POSITION_RADIUS_M
    docs, said = {}, {}
    for radius in (None, "0"):
        out = tmp_path / f"diag{radius}"
        args = ["diagnose", str(camp), "--card", str(CARD), "--out", str(out), "--effect", "rpm", "--no-report"]
        run = CliRunner().invoke(cli, args + ([] if radius is None else ["--position-radius", radius]))
        assert run.exit_code == 0, run.output
        docs[radius] = json.loads((out / "diagnosis.json").read_text())
        said[radius] = run.output
    est = docs[None]["metadata"]["microphone_positions"]["m1"]
    assert est["contradicts"] and abs(est["relative_n_m"] + 30.0) < 5.0 and abs(est["relative_e_m"]) < 5.0
    assert "microphone_positions" not in docs["0"]["metadata"]
    # m2 stood where it is listed: its own level puts it there, so it is not moved, although with two
    # microphones its offset against the other one's is as large as m1's
    assert [m for m, e in docs[None]["metadata"]["microphone_positions"].items() if e["contradicts"]] == ["m1"]
    # the command line says what the campaign got wrong, not only the verdict
    sentences = docs[None]["metadata"]["contradictions"]
    assert sentences and all(t in said[None] for t in sentences)
    assert "not where the campaign lists it" not in said["0"]


def test_two_ray_physics_of_the_study_simulator():
    """Hard ground at low frequency doubles the pressure (+6.02 dB); grass reflects less than a hard ground."""
    mic = np.zeros((1, 3))
    uav = np.array([[0.0, 0.0, 1000.0]])  # overhead and far: r1/r2 -> 1, normal incidence
    hard = study.two_ray_db([25.0], mic, uav, 0.01, 340.0, sigma_pa_s_m2=1e15)
    assert hard[0, 0] == pytest.approx(20 * math.log10(2.0), abs=0.01)
    # normal incidence, Delany-Bazley grass at 1 kHz: |Q| = |Z - 1| / |Z + 1| from the impedance itself
    z = study.delany_bazley(1000.0, 200e3)
    q = abs((z - 1) / (z + 1))
    assert 0.4 < q < 0.9
    # a quarter-wave geometry over the hard ground: the band around the first dip loses energy
    f_dip = 340.0 / (4 * 1.0)  # path difference 2 h = lambda / 2 for h = 1 m
    dip = study.two_ray_db([f_dip], mic, uav, 1.0, 340.0, sigma_pa_s_m2=1e15)
    assert dip[0, 0] < -3.0


def test_ground_plates_that_stood_above_grass_are_found_from_the_band_levels():
    """Listed on ground plates, heard 1.0-1.5 m above grass: ground_reflection, heights within 0.3 m, and said so."""
    s = study.elevate(plates_control(), TRIPOD_HEIGHTS)
    r = run_diagnosis(s, cards.load(CARD)).result
    v = r["verdict"]
    assert v["effect"] == "ground_reflection", (v["reason"], r["metadata"]["contradictions"])
    assert v["effects"][0]["effect"] == "ground_reflection"
    est = r["metadata"]["microphone_heights"]
    for m, h in TRIPOD_HEIGHTS.items():
        assert est[m]["listed_m"] == 0.0
        assert est[m]["height_m"] == pytest.approx(h, abs=0.3)
        assert est[m]["contradicts"]
        assert est[m]["at_search_limit"] is False and 0.0 < est[m]["std_m"] < 0.3  # an estimate, not a bound
    sentence = next(t for t in v["metadata_contradicted"] if "m2" in t)
    assert "comb pattern" in sentence and "not a ground plate" in sentence
    assert f"about {est['m2']['height_m']:.1f} m" in sentence
    assert v["band_holdout"]["shrinkage_pct"] > 10.0


def test_ground_plates_on_the_ground_contradict_nothing():
    r = run_diagnosis(plates_control(), cards.load(CARD)).result
    assert r["verdict"]["effect"] is None and r["verdict"]["effects"] == []
    assert r["metadata"]["contradictions"] == []
    assert not any(h["contradicts"] for h in r["metadata"]["microphone_heights"].values())


def test_an_unstated_clock_offset_on_one_microphone_is_estimated():
    """m2's clock 0.8 s behind, the campaign silent: emission_time with 0.8 s on m2 (within 0.15 s), 0 elsewhere."""
    s = study.clock(plates_control(), "m2", 0.8)
    r = run_diagnosis(s, cards.load(CARD)).result
    v = r["verdict"]
    assert v["effect"] == "emission_time", v["reason"]
    p = v["parameters"]
    assert p["dt_m2"]["value"] == pytest.approx(0.8, abs=0.15)
    for m in ("m1", "m3", "m4"):
        assert p[f"dt_{m}"]["value"] == pytest.approx(0.0, abs=0.15)
    assert any("m2" in t and "clock" in t for t in v["metadata_contradicted"])
    assert r["metadata"]["clock_offsets"]["m2"]["offset_s"] == pytest.approx(0.8, abs=0.15)


def test_two_effects_at_once_are_both_named_in_order():
    """A clock offset on m2 and the simulator's wind together: forward selection names both, each shrinking."""
    doc = json.loads(SCENARIO.read_text())
    doc["seed"] = 11
    doc["effects"] = {"wind": {}}
    s = study.clock(simulate.simulate_samples(simulate.run(doc, base_dir=SCENARIO.parent)), "m2", 0.8)
    v = run_diagnosis(s, cards.load(CARD)).result["verdict"]
    named = [e["effect"] for e in v["effects"]]
    assert set(named) == {"wind", "emission_time"}, named
    assert named[0] == v["effect"]
    assert all(e["holdout_shrinkage_pct"] > 0 for e in v["effects"])
    assert v["effects"][-1]["cumulative_shrinkage_pct"] > v["effects"][0]["cumulative_shrinkage_pct"]


def test_evidence_that_contradicts_the_leader_gives_no_verdict():
    """A fit that wins on numbers but whose physical evidence says otherwise is not named: null with the reason."""
    from gisnoise.diagnose.candidates import _Candidate
    from gisnoise.diagnose.verdict import _choose, _gate

    def cand(name, imp, supports):
        c = _Candidate(name)
        c.summary.update(significant=True, holdout_improvement_db2=imp, p_holdout=1e-4,
                         evidence={"supports": supports, "summary": f"{name} evidence"})
        return c

    lead = _choose([cand("bank_angle", 0.05, False), cand("wind", 0.01, None)], 0.005)
    assert lead is not None and lead.name == "bank_angle"
    why = _gate(lead)
    assert why is not None and "bank_angle" in why and "contradicts" in why
    # a close runner-up whose evidence supports it takes the place (the tie-break)
    lead = _choose([cand("bank_angle", 0.05, False), cand("wind", 0.045, True)], 0.005)
    assert lead is not None and lead.name == "wind" and _gate(lead) is None


def test_a_microphone_listed_30_m_off_is_placed_from_its_level_and_no_effect_is_named():
    """m3 listed 30 m north-east of where it stood: its position is estimated (within 5 m), said so, nothing named."""
    moved = study.move_mic(plates_control(), "m3", 30.0, 45.0)
    r = run_diagnosis(moved, cards.load(CARD)).result
    est = r["metadata"]["microphone_positions"]
    # the level places m3 back where it stood: 30 m towards 225 deg from the listed position
    back = np.array([-30.0 * math.sin(math.radians(45.0)), -30.0 * math.cos(math.radians(45.0))])
    got = np.array([est["m3"]["relative_e_m"], est["m3"]["relative_n_m"]])
    assert np.hypot(*(got - back)) < 5.0, got
    assert est["m3"]["contradicts"] and 0 < est["m3"]["std_m"] < 5.0
    assert not any(est[m]["contradicts"] for m in ("m1", "m2", "m4"))
    sentence = next(t for t in r["metadata"]["contradictions"] if "m3" in t)
    assert "from its listed position" in sentence and f"{est['m3']['relative_m']:.0f} m" in sentence
    assert r["verdict"]["effect"] is None, r["verdict"]


def test_absorption_in_the_band_levels_is_measured_as_a_multiple_of_iso_9613_1():
    """Band levels losing 0.7 x ISO 9613-1 alpha d (15 C, 50 %): the multiple comes back and predicts held-out data."""
    from dataclasses import replace

    from gisnoise.acoustics import atmospheric_absorption, overall_a_level, third_octave_centres
    from gisnoise.diagnose.bandtests import absorption_band_holdout

    rng = np.random.default_rng(3)
    n = 4000
    t = np.arange(n) * 0.25
    base = table(t, np.where(np.arange(n) % 2, "m1", "m2"), np.zeros(n), flight=np.where(t < t[-1] / 2, "f1", "f2"),
                 d=rng.uniform(30.0, 300.0, n))
    f = third_octave_centres(100.0, 10000.0)
    alpha = atmospheric_absorption(f, 15.0, 50.0, 101.325)
    spectrum = 70.0 - 3.0 * np.log2(f / 1000.0) ** 2
    meta = {"weather": {"temperature_c": 15.0, "humidity_pct": 50.0, "pressure_kpa": 101.325}}

    def campaign(scale):
        bands = (spectrum[None, :] - 20.0 * np.log10(base.d)[:, None] - scale * alpha[None, :] * base.d[:, None]
                 + rng.normal(0.0, 0.5, (n, len(f))))
        return replace(base, bands=bands, band_f=f, level=overall_a_level(bands, f), meta=meta)

    fold, block, _ = fold_labels(base)
    s = campaign(0.7)
    band = absorption_band_holdout(s, s.inputs(1.0), fold, block)
    assert band["iso_multiple"] == pytest.approx(0.7, abs=0.05)
    assert band["p_value"] < 1e-6 and band["improvement_db2"] > 0.05
    s = campaign(0.0)
    band = absorption_band_holdout(s, s.inputs(1.0), fold, block)
    assert band["iso_multiple"] == pytest.approx(0.0, abs=0.05)
    assert band["p_value"] > 0.01


def test_a_hemisphere_card_is_refused_naming_the_conversion():
    """A measured hemisphere has no parameters to extend: diagnose refuses it naming the card and the way to a
    parametric card (card fit-hemisphere), not 'all parameters are fixed'."""
    from gisnoise.model import import_hemisphere

    _, s = simulated(None)
    hemi = import_hemisphere(ROOT / "tests" / "data" / "hemispheres" / "Hem_Ed_M3_10_F05_Y_W_dw_2.xlsx")
    with pytest.raises(InputError, match="fit-hemisphere") as err:
        diagnose(s, hemi)
    assert err.value.field == "card"


def test_the_clock_sentence_says_which_way_the_clock_is_off():
    """``offset_s`` is the shift at which the model explains the level: level(t) = model(t + offset_s).
    A positive offset relative to the other microphones means the level comes *earlier* than the
    model: the microphone's clock runs behind theirs (the study's ``clock(.., +0.8)``); a negative one
    means later, its clock runs ahead (its time stamps were written 0.8 s late)."""
    from gisnoise.diagnose.metadata import clock_note

    est = {"m1": {"offset_s": 0.02, "std_s": 0.04}, "m2": {"offset_s": 0.82, "std_s": 0.05},
           "m3": {"offset_s": -0.02, "std_s": 0.04}, "m4": {"offset_s": 0.0, "std_s": 0.04}}
    behind = clock_note("m2", est)
    assert "m2" in behind and "0.82 s (+/- 0.05 s) earlier" in behind and "behind" in behind
    assert "later" not in behind and "ahead" not in behind and "-0." not in behind
    est["m2"]["offset_s"] = -0.78
    ahead = clock_note("m2", est)
    assert "0.78 s (+/- 0.05 s) later" in ahead and "ahead" in ahead
    assert "earlier" not in ahead and "behind" not in ahead and "-0." not in ahead
    est["m2"]["offset_s"] = 0.5  # relative to the median of the others (0.0), not to zero
    est["m1"]["offset_s"] = est["m3"]["offset_s"] = est["m4"]["offset_s"] = 0.3
    assert "0.20 s" in clock_note("m2", est)


def test_cli_says_how_far_the_card_itself_misses(tmp_path):
    """A card whose reference power is 10 x the campaign's flown power scale predicts every level
    p1 log10(10) = p1 dB too low (Eq. 9 at P_el / 10; less near the background, Eq. 8): the command line
    states the card's RMS miss and the refit's level offset p0 moving by p1, not only 'no effect'."""
    scenario = {**wav_scenario(), "effects": {}}  # the card's model itself: the refit is unbiased
    camp = simulate.simulate(scenario, tmp_path / "camp", base_dir=SCENARIO.parent)
    doc = json.loads(CARD.read_text())
    doc["reference_power_w"] *= 10.0
    doc["id"] = "demo-horizontal-tenfold"
    card = tmp_path / "card.json"
    card.write_text(json.dumps(doc))
    out = tmp_path / "diag"
    run = CliRunner().invoke(cli, ["diagnose", str(camp), "--card", str(card), "--out", str(out), "--effect", "rpm",
                                   "--no-report", "--position-radius", "0"])
    assert run.exit_code == 0, run.output
    base = json.loads((out / "diagnosis.json").read_text())["baseline"]
    assert base["rms_db_card"] > 5.0 > base["rms_db_fit"]  # the background term caps the miss near 40 dB(A)
    line = next(t for t in run.output.splitlines() if t.startswith("card: "))
    assert f"rms {base['rms_db_card']:.2f} dB" in line and f"refitted {base['rms_db_fit']:.2f} dB" in line
    moved = base["parameters"]["p0"] - doc["parameters"]["p0"]
    assert moved == pytest.approx(doc["parameters"]["p1"], abs=1.0)
    assert f"p0 {moved:+.3g}" in line


def test_a_microphone_listed_km_off_is_left_out_and_the_verdict_is_the_controls(tmp_path):
    """One microphone of the base scenario (no effect injected) listed 0.05 deg (5.6 km) north of where its levels
    were made: beyond the position search, its loudest 20 s from the listed position put the source more than
    20 dB off the others' (the rule of campaign check) in both flights.  The diagnosis leaves it out, says so first,
    and finds what the scenario holds: no effect (with it, the far microphone's residuals were a background event)."""
    from gisnoise.diagnose.positions import far_off_microphones
    from gisnoise.measure import read_campaign

    camp = simulate.simulate(json.loads(SCENARIO.read_text()), tmp_path / "camp", base_dir=SCENARIO.parent)
    assert far_off_microphones(read_campaign(camp).samples()) == ({}, [])  # the unmoved campaign: nothing named
    cj = camp / "campaign.json"
    doc = json.loads(cj.read_text())
    doc["microphones"][0]["lat"] += 0.05
    cj.write_text(json.dumps(doc))
    out = tmp_path / "diag"
    run = CliRunner().invoke(cli, ["diagnose", str(camp), "--card", str(CARD), "--out", str(out), "--no-report"])
    assert run.exit_code == 0, run.output
    r = json.loads((out / "diagnosis.json").read_text())
    far = r["data"]["excluded_microphones"]
    assert list(far) == ["m1"] and sorted(e["flight"] for e in far["m1"]) == ["f1", "f2"]
    assert all(e["offset_db"] > 20.0 and e["listed_distance_m"] > 5000.0 for e in far["m1"])
    assert r["data"]["microphones"] == ["m2", "m3", "m4"]
    sentence = r["metadata"]["contradictions"][0]
    assert sentence.startswith("microphone 'm1' (") and "left out of the diagnosis" in sentence
    assert all(f"{e['offset_db']:+.0f} dB in '{e['flight']}'" in sentence for e in far["m1"])
    assert [ln for ln in run.output.splitlines() if ln.startswith("campaign: ")][0] == f"campaign: {sentence}"
    assert r["verdict"]["effect"] is None, r["verdict"]


@pytest.mark.parametrize("effect", [None, *EFFECTS])
def test_no_honest_microphone_of_the_diagnosis_scenarios_is_named_far_off(effect):
    """The diagnosis base scenario with each effect at its default magnitude: every microphone is where campaign.json
    lists it, and the spreading rule names none (the directivity, ground and effects change the source level by a
    few dB, not 20)."""
    from gisnoise.measure import spreading_outliers

    assert spreading_outliers(simulated(effect)[1]) == []


def _spread_table(offsets_db):
    """Three microphones a, b, c per flight, each hearing 70 dB(A) at a listed distance 10^(offset/20) x 40 m: their
    source levels from the listed positions lie ``offsets_db[flight][mic]`` dB apart (spherical spreading)."""
    cols: dict[str, list[np.ndarray]] = {"t": [], "mic": [], "flight": [], "d": []}
    for k, (flight, offs) in enumerate(offsets_db.items()):
        for mic, off in offs.items():
            t = 1000.0 * k + np.arange(0.0, 120.0, 0.125)
            cols["t"].append(t)
            cols["mic"].append(np.full(t.size, mic))
            cols["flight"].append(np.full(t.size, flight))
            cols["d"].append(np.full(t.size, 40.0 * 10.0 ** (off / 20.0)))
    t, mic, flight, d = (np.concatenate(cols[k]) for k in ("t", "mic", "flight", "d"))
    return table(t, mic, 70.0 - 10.0 * np.cos(t / 20.0) ** 2, flight=flight, d=d)


def test_a_microphone_far_off_in_one_flight_only_is_kept_with_a_note():
    """A listed position is the same in every flight: c beyond 20 dB in f1 but agreeing in f2 is not left out, the
    note names it; b, 30 dB off in both flights, is."""
    from gisnoise.diagnose.positions import far_off_microphones

    s = _spread_table({"f1": {"a": 0.0, "b": 30.0, "c": -25.0}, "f2": {"a": 0.0, "b": 30.0, "c": 2.0}})
    far, notes = far_off_microphones(s)
    # against the median: a in f1 (0 dB), c in f2 (2 dB)
    assert list(far) == ["b"] and [e["offset_db"] for e in far["b"]] == [pytest.approx(30.0), pytest.approx(28.0)]
    assert len(notes) == 1 and notes[0].startswith("microphone 'c'") and "-25 dB in 'f1'" in notes[0]


def test_a_diagnosis_left_with_one_microphone_is_refused_naming_the_far_ones():
    """b 30 dB above and c 30 dB below a's source level: the rule names both, and a alone is vouched for by none."""
    s = _spread_table({"f1": {"a": 0.0, "b": 30.0, "c": -30.0}})
    with pytest.raises(InputError, match=r"^microphones: 'b', 'c' contradict .* leaving 'a'; the diagnosis needs 2"):
        run_diagnosis(s, cards.load(CARD))
