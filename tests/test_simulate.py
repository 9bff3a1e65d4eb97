"""Campaign simulator: truth bookkeeping, flight physics and each injected effect.

Expected values come from the coordinated-turn formula, the truth card evaluated at
a known geometry, ISO 9613-1 (through ``gisnoise.acoustics``) and the documented
form of each effect evaluated here from the written flight log, never from numbers
the simulator produced once.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.errors import ScenarioError
from gisnoise.flight import read_flight_csv
from gisnoise.geo import LocalFrame
from gisnoise.model import cards, level_sum
from gisnoise.simulate import (
    EFFECTS,
    load_scenario,
    resolve_scenario,
    run,
    simulate,
    simulate_samples,
    synthesize_wav,
)

G = 9.80665
CARDS = Path(__file__).resolve().parent.parent / "gisnoise" / "data" / "cards"
SCENARIOS = Path(__file__).resolve().parent.parent / "sample_data" / "scenarios"
QUIET_VEHICLE = {"power": {"jitter_pct": 0.0}, "rpm": {"jitter_pct": 0.0},
                 "log_noise": {"position_m": 0.0, "attitude_deg": 0.0, "power_pct": 0.0}}


def base(**changes):
    """A small scenario: one flight with a racetrack lap and a fly-by over two microphones."""
    doc = {
        "schema": "gisnoise/scenario/1", "name": "test", "seed": 7,
        "origin": {"lat": 52.0, "lon": 10.0, "h": 100.0},
        "weather": {"temperature_c": 15.0, "humidity_pct": 50.0, "pressure_kpa": 101.325,
                    "wind_speed_m_s": 0.0, "wind_from_deg": 270.0},
        "vehicle": copy.deepcopy(QUIET_VEHICLE),
        "microphones": [{"id": "m1", "e": 0.0, "n": 0.0, "noise_std_db": 0.0},
                        {"id": "m2", "e": 60.0, "n": 30.0, "noise_std_db": 0.0}],
        "background": {"level_dba": 0.0},
        "output": {"format": "levels", "block_s": 0.125},
        "flights": [{"id": "f1", "start": {"e": -200.0, "n": -200.0, "heading_deg": 90.0}, "patterns": [
            {"type": "climb", "to_height_m": 50.0, "rate_m_s": 3.0},
            {"type": "racetrack", "centre": [0.0, 0.0], "heading_deg": 90.0, "straight_m": 250.0,
             "heights_m": [50.0], "laps": 1, "speed_m_s": 24.0},
            {"type": "flyby", "through": [0.0, 0.0], "heading_deg": 0.0, "length_m": 500.0, "height_m": 40.0,
             "speed_m_s": 26.0},
        ]}],
    }
    doc.update(copy.deepcopy(changes))
    return doc


def hover_doc(**changes):
    """Take-off beside a microphone, hover at ``(100, 0)`` 40 m up with a slow yaw."""
    doc = base(flights=[{"id": "f1", "start": {"e": 100.0, "n": 0.0, "heading_deg": 0.0}, "patterns": [
        {"type": "climb", "to_height_m": 40.0, "rate_m_s": 2.0},
        {"type": "hover", "duration_s": 20.0, "yaw_rate_deg_s": 6.0},
        {"type": "sink", "to_height_m": 0.0, "rate_m_s": 2.0}]}])
    doc.update(copy.deepcopy(changes))
    return doc


def truth_blocks(res, flight="f1", mic="m1"):
    return res.levels[flight][mic]


def level_diff(a, b):
    """a - b for block levels that may be -inf or None (UAV not yet heard): NaN there."""
    a = np.array(a, dtype=float)
    b = np.array(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    return np.where(ok, a - np.where(ok, b, 0.0), np.nan)


def log_state(path, origin):
    """Flight log -> (t, ENU positions, ENU velocity, roll rad, power W, rpm)."""
    tr = read_flight_csv(path)
    frame = LocalFrame(origin["lat"], origin["lon"], origin["h"])
    pos = np.stack(tr.enu(frame), axis=1)
    vel = np.stack([np.gradient(pos[:, k], tr.t) for k in range(3)], axis=1)
    return tr, pos, vel


def emission(t_r, tl, pos, mic, c):
    """Solve t_r = t_e + |x(t_e) - mic| / c by fixed-point iteration on the logged track."""
    te = np.array(t_r, dtype=float)
    for _ in range(60):
        x = np.stack([np.interp(te, tl, pos[:, k]) for k in range(3)], axis=1)
        te = t_r - np.linalg.norm(x - mic, axis=1) / c
    return te


def c_of(doc):
    return 331.3 * math.sqrt(1.0 + doc["weather"]["temperature_c"] / 273.15)


# ------------------------------------------------------------------ truth and files


def test_files_and_truth_are_consistent(tmp_path):
    doc = base(effects={"bank_angle": {"db_at_30deg": 2.0}})
    doc["microphones"][0]["noise_std_db"] = 0.7
    out = simulate(doc, tmp_path / "camp")
    camp = json.loads((out / "campaign.json").read_text())
    truth = json.loads((out / "truth.json").read_text())
    assert camp["schema"] == "gisnoise/campaign/1"
    assert [m["id"] for m in camp["microphones"]] == ["m1", "m2"]
    assert truth["microphones"]["m1"]["noise_std_db"] == 0.7
    assert truth["effects"][0]["name"] == "bank_angle" and truth["effects"][0]["parameters"]["db_at_30deg"] == 2.0
    # truth cards are the bundled demo cards, parameter for parameter
    for ph, name in (("horizontal", "demo_horizontal"), ("climb", "demo_climb")):
        assert truth["cards"][ph]["parameters"] == cards.load(CARDS / f"{name}.json").parameters
    # the level CSV holds the truth's measured LA; noise-free microphone: LA == LA_clean
    for mic in ("m1", "m2"):
        data = np.genfromtxt(out / "mics" / mic / "f1.csv", delimiter=",", names=True)
        blk = truth["flights"]["f1"]["blocks"][mic]
        np.testing.assert_allclose(data["t"], blk["t"], atol=1e-4)
        np.testing.assert_allclose(data["LA"], blk["LA"], atol=0.006)
    m2 = truth["flights"]["f1"]["blocks"]["m2"]
    np.testing.assert_allclose(m2["LA"], m2["LA_clean"], atol=0.006)
    m1 = truth["flights"]["f1"]["blocks"]["m1"]
    resid = np.array(m1["LA"]) - np.array(m1["LA_clean"])
    assert abs(np.std(resid) - 0.7) < 0.05  # ~3000 blocks: the std is known to ~1.3 %
    # turns: two 180-degree racetrack turns plus the turns of the Dubins joins, all inside horizontal flight
    turns = truth["flights"]["f1"]["turns"]
    assert len(turns) >= 2
    tr = read_flight_csv(out / "flights" / "f1.csv")
    for t in turns:
        inside = (tr.t > t["t0"] + 0.5) & (tr.t < t["t1"] - 0.5)
        assert np.all(tr.phase[inside] == "horizontal")
        assert np.all(np.abs(tr.roll[inside]) > 5.0)
    outside = np.ones(len(tr.t), dtype=bool)
    for t in turns:
        outside &= ~((tr.t > t["t0"] - 0.5) & (tr.t < t["t1"] + 0.5))
    assert np.all(np.abs(tr.roll[outside]) < 1e-6)


def test_turns_have_the_coordinated_turn_bank_angle(tmp_path):
    doc = base()
    out = simulate(doc, tmp_path / "camp")
    truth = json.loads((out / "truth.json").read_text())
    tr, pos, vel = log_state(out / "flights" / "f1.csv", doc["origin"])
    # speed and turn rate from the logged positions alone
    v = np.hypot(vel[:, 0], vel[:, 1])
    track = np.unwrap(np.arctan2(vel[:, 0], vel[:, 1]))
    omega = np.gradient(track, tr.t)
    checked = 0
    for t in truth["flights"]["f1"]["turns"]:
        inside = (tr.t > t["t0"] + 1.0) & (tr.t < t["t1"] - 1.0)
        if inside.sum() < 5:
            continue
        expected = np.degrees(np.arctan(v[inside] * omega[inside] / G))
        np.testing.assert_allclose(tr.roll[inside], expected, atol=0.1)
        radius = np.median(v[inside] / np.abs(omega[inside]))
        np.testing.assert_allclose(radius, t["radius_m"], rtol=1e-3)
        checked += 1
    assert checked >= 2
    # the default radius gives a 30 degree bank at the pattern's speed
    rt = [t for t in truth["flights"]["f1"]["turns"] if abs(t["speed_m_s"] - 24.0) < 1e-9]
    assert rt and all(abs(t["bank_deg"] - 30.0) < 0.05 for t in rt)


def test_level_below_hovering_uav_equals_card(tmp_path):
    # mic 2 m up on a stand, UAV hovers straight above at 42 m: d = 40 m, theta = -90 deg for any yaw
    doc = base(microphones=[{"id": "m1", "e": 0.0, "n": 0.0, "mount": "free_field", "height_m": 2.0,
                             "noise_std_db": 0.0}],
               background={"level_dba": 40.0},
               flights=[{"id": "f1", "start": {"e": 0.0, "n": 0.0, "height_m": 42.0}, "patterns": [
                   {"type": "hover", "duration_s": 30.0, "yaw_rate_deg_s": 6.0}]}])
    doc["vehicle"]["power"]["hover_w"] = 7500.0
    doc["vehicle"]["cards"] = {"hover": "demo_climb"}
    res = run(doc)
    card = cards.load(CARDS / "demo_climb.json")
    x = card.inputs(40.0, 0.3, -np.pi / 2, 7500.0)
    l_card = float(card.level_uav(x))
    expected = float(level_sum(l_card, 40.0))
    blk = truth_blocks(res)
    t0, t1 = 40.0 / c_of(doc), 30.0 + 40.0 / c_of(doc)
    sel = (blk.t - 0.0625 > t0) & (blk.t + 0.0625 < t1)
    assert sel.sum() > 200
    np.testing.assert_allclose(blk.la_clean[sel], expected, atol=1e-6)
    np.testing.assert_allclose(blk.la_uav[sel], l_card, atol=1e-6)


# ------------------------------------------------------------------ effects


def _pair(doc, effect, params):
    off = run(doc)
    on_doc = copy.deepcopy(doc)
    on_doc["effects"] = {effect: params}
    return off, run(on_doc)


def test_bank_angle_adds_the_documented_level_in_turns():
    doc = base()
    off, on = _pair(doc, "bank_angle", {"db_at_30deg": 3.0, "fluctuation_db": 0.0})
    c = c_of(doc)
    fl = on.flights[0]
    for mic in ("m1", "m2"):
        d = level_diff(on.levels["f1"][mic].la_uav, off.levels["f1"][mic].la_uav)
        t = on.levels["f1"][mic].t
        # straight flight far from any turn: no change (reception delay < 2 s here)
        straight = np.ones(len(t), dtype=bool)
        for t0, t1, _r, _v in fl.turns:
            straight &= ~((t > t0 - 1.0) & (t < t1 + 3.0))
        assert np.nanmax(np.abs(d[straight & np.isfinite(d)])) < 1e-9
        for t0, t1, r, v in fl.turns:
            if t1 - t0 < 6.0:
                continue
            inside = (t > t0 + 3.0) & (t < t1 - 1.0)
            bank = math.atan(v * v / (G * r))
            expected = 3.0 * (math.sin(bank) / math.sin(math.radians(30.0))) ** 2
            np.testing.assert_allclose(d[inside], expected, atol=1e-6)
    assert c > 300


def test_atmospheric_absorption_attenuates_each_band_by_alpha_d():
    from gisnoise.acoustics import atmospheric_absorption

    doc = hover_doc(background={"level_dba": -20.0})
    off, on = _pair(doc, "atmospheric_absorption", {"scale": 1.0})
    d = math.hypot(100.0, 40.0)
    w = doc["weather"]
    alpha = atmospheric_absorption(on.band_f, w["temperature_c"], w["humidity_pct"], w["pressure_kpa"])
    blk_on, blk_off = on.levels["f1"]["m1"], off.levels["f1"]["m1"]
    t = blk_on.t
    sel = (t > 20.0 + d / c_of(doc) + 0.2) & (t < 40.0 + d / c_of(doc) - 0.2)
    diff = blk_on.bands[sel] - blk_off.bands[sel]
    loud = blk_on.bands[sel].min(axis=0) > 10.0  # bands far above the -20 dB(A) background
    assert loud.sum() > 25
    np.testing.assert_allclose(diff[:, loud], np.broadcast_to(-alpha[loud] * d, diff[:, loud].shape), atol=0.01)
    # high bands lose more than low bands: the band slope with distance
    assert diff[:, loud][:, -1].mean() < diff[:, loud][:, 0].mean() - 1.0


def test_ground_reflection_follows_the_image_source_formula():
    doc = hover_doc(microphones=[{"id": "m1", "e": 0.0, "n": 0.0, "mount": "free_field", "height_m": 1.5,
                                  "noise_std_db": 0.0},
                                 {"id": "m2", "e": 0.0, "n": 0.0, "mount": "ground_plate", "noise_std_db": 0.0}])
    q, gamma = 0.8, 0.7
    off, on = _pair(doc, "ground_reflection", {"reflection_coefficient": q, "coherence": gamma})
    c = c_of(doc)
    src = np.array([100.0, 0.0, 40.0])
    mic = np.array([0.0, 0.0, 1.5])
    r1 = np.linalg.norm(src - mic)
    r2 = np.linalg.norm(src - np.array([0.0, 0.0, -1.5]))
    lo, hi = on.band_f * 10 ** -0.05, on.band_f * 10 ** 0.05
    expected = []
    for a, b in zip(lo, hi, strict=True):
        f = np.linspace(a, b, 20001)
        cos_avg = np.mean(np.cos(2 * np.pi * f * (r2 - r1) / c))
        amp = q * r1 / r2
        expected.append(10 * np.log10(1 + amp ** 2 + 2 * amp * gamma * cos_avg))
    expected = np.array(expected)
    t = on.levels["f1"]["m1"].t
    sel = (t > 20.0 + r1 / c + 0.2) & (t < 40.0 + r1 / c - 0.2)
    diff = on.levels["f1"]["m1"].bands[sel] - off.levels["f1"]["m1"].bands[sel]
    loud = off.levels["f1"]["m1"].bands[sel].min(axis=0) > 20.0
    np.testing.assert_allclose(diff[:, loud], np.broadcast_to(expected[loud], diff[:, loud].shape), atol=2e-3)
    assert expected.min() < -2.0 and expected.max() > 3.0  # a comb: a notch and a boost
    # the ground-plate microphone is untouched
    np.testing.assert_array_equal(on.levels["f1"]["m2"].bands, off.levels["f1"]["m2"].bands)


def _flyby_doc():
    return base(flights=[{"id": "f1", "start": {"e": 0.0, "n": -900.0, "heading_deg": 0.0}, "patterns": [
        {"type": "climb", "to_height_m": 30.0, "rate_m_s": 3.0},
        {"type": "flyby", "through": [0.0, 0.0], "heading_deg": 0.0, "length_m": 1200.0, "height_m": 30.0,
         "speed_m_s": 30.0}]}])


def test_doppler_amplifies_ahead_and_attenuates_behind(tmp_path):
    doc = _flyby_doc()
    n = 3.0
    doc["effects"] = {"doppler": {"exponent": n}}
    out = simulate(doc, tmp_path / "on")
    doc_off = copy.deepcopy(doc)
    doc_off["effects"] = {}
    off = run(doc_off)
    truth = json.loads((out / "truth.json").read_text())
    tr, pos, vel = log_state(out / "flights" / "f1.csv", doc["origin"])
    c = c_of(doc)
    on_blk = truth["flights"]["f1"]["blocks"]["m1"]
    t_r = np.array(on_blk["t"])
    d_l = level_diff(on_blk["LA_uav"], off.levels["f1"]["m1"].la_uav)
    te = emission(t_r, tr.t, pos, np.zeros(3), c)
    straight = (np.interp(te, tr.t, pos[:, 1]) > -500) & (np.interp(te, tr.t, pos[:, 1]) < 500)
    x = np.stack([np.interp(te, tr.t, pos[:, k]) for k in range(3)], axis=1)
    v = np.stack([np.interp(te, tr.t, vel[:, k]) for k in range(3)], axis=1)
    r = -x
    cos_m = np.sum(v * r, axis=1) / (np.linalg.norm(r, axis=1) * c)
    expected = -10 * n * np.log10(1 - cos_m)
    np.testing.assert_allclose(d_l[straight], expected[straight], atol=0.02)
    assert expected[straight].max() > 1.0 and expected[straight].min() < -1.0


def test_wind_refraction_gains_downwind_and_loses_upwind(tmp_path):
    doc = _flyby_doc()
    doc["weather"]["wind_speed_m_s"] = 5.0
    doc["weather"]["wind_from_deg"] = 180.0  # from the south: blowing north
    doc["effects"] = {"wind": {"db_per_100m": 2.0, "max_db": 4.0}}
    out = simulate(doc, tmp_path / "on")
    doc_off = copy.deepcopy(doc)
    doc_off["effects"] = {}
    off = run(doc_off)
    truth = json.loads((out / "truth.json").read_text())
    tr, pos, _ = log_state(out / "flights" / "f1.csv", doc["origin"])
    t_r = np.array(truth["flights"]["f1"]["blocks"]["m1"]["t"])
    d_l = level_diff(truth["flights"]["f1"]["blocks"]["m1"]["LA_uav"], off.levels["f1"]["m1"].la_uav)
    te = emission(t_r, tr.t, pos, np.zeros(3), c_of(doc))
    n_uav = np.interp(te, tr.t, pos[:, 1])
    straight = (n_uav > -500) & (n_uav < 500) & (np.abs(n_uav) > 5)
    # mic at the origin, UAV on the north-south line: the wind blows north, so propagation from a UAV
    # south of the mic is downwind (cos psi = +1), from the north upwind (-1); r_h = |n|
    expected = np.clip(2.0 * (5.0 / 5.0) * np.sign(-n_uav) * np.abs(n_uav) / 100.0, -4.0, 4.0)
    np.testing.assert_allclose(d_l[straight], expected[straight], atol=0.05)
    assert expected[straight].max() == 4.0 and expected[straight].min() == -4.0


def test_rpm_effect_follows_log10_rpm_over_rpm_from_power(tmp_path):
    doc = _flyby_doc()
    doc["vehicle"]["rpm"] = {"jitter_pct": 8.0, "jitter_tau_s": 10.0, "cruise_rpm": 5000.0}
    doc["vehicle"]["power"]["cruise_w"] = 3000.0
    doc["effects"] = {"rpm": {"db_per_decade": 50.0}}
    out = simulate(doc, tmp_path / "on")
    doc_off = copy.deepcopy(doc)
    doc_off["effects"] = {}
    off = run(doc_off)
    truth = json.loads((out / "truth.json").read_text())
    tr, pos, _ = log_state(out / "flights" / "f1.csv", doc["origin"])
    t_r = np.array(truth["flights"]["f1"]["blocks"]["m1"]["t"])
    d_l = level_diff(truth["flights"]["f1"]["blocks"]["m1"]["LA_uav"], off.levels["f1"]["m1"].la_uav)
    te = emission(t_r, tr.t, pos, np.zeros(3), c_of(doc))
    sel = (np.interp(te, tr.t, pos[:, 1]) > -500) & (np.interp(te, tr.t, pos[:, 1]) < 500)
    rpm = np.interp(te, tr.t, tr.rpm)
    rpm_p = 5000.0 * (np.interp(te, tr.t, tr.power_w) / 3000.0) ** (1 / 3)
    expected = 50.0 * np.log10(rpm / rpm_p)
    np.testing.assert_allclose(d_l[sel], expected[sel], atol=0.05)  # 10 Hz log vs 50 Hz truth
    assert np.std(expected[sel]) > 0.5  # rpm varies independently of power
    # the rpm column is written with or without the effect; without it the level ignores rpm
    assert tr.rpm is not None


def test_emission_time_offsets_the_log_clock(tmp_path):
    doc = base()
    a = simulate(doc, tmp_path / "a")
    doc["effects"] = {"emission_time": {"offset_s": 0.4}}
    b = simulate(doc, tmp_path / "b")
    ta = read_flight_csv(a / "flights" / "f1.csv")
    tb = read_flight_csv(b / "flights" / "f1.csv")
    np.testing.assert_allclose(tb.t - ta.t, 0.4, atol=1e-6)
    np.testing.assert_allclose(tb.lat, ta.lat, atol=0)
    la = np.genfromtxt(a / "mics" / "m1" / "f1.csv", delimiter=",", names=True)["LA"]
    lb = np.genfromtxt(b / "mics" / "m1" / "f1.csv", delimiter=",", names=True)["LA"]
    np.testing.assert_array_equal(la, lb)


def test_background_event_rises_on_all_mics_at_once():
    doc = base(background={"level_dba": 30.0})
    off, on = _pair(doc, "background_event", {
        "events": [{"flight": "f1", "t_s": 60.0, "duration_s": 20.0, "peak_dba": 80.0}], "mic_spread_db": 0.0})
    for mic in ("m1", "m2"):
        a, b = off.levels["f1"][mic], on.levels["f1"][mic]
        outside = (b.t < 60.0 - 0.07) | (b.t > 80.0 + 0.07)
        np.testing.assert_allclose(b.la_clean[outside], a.la_clean[outside], atol=1e-9)
        k = int(np.argmin(np.abs(b.t - 70.0)))
        added = 10 ** (b.la_clean[k] / 10) - 10 ** (a.la_clean[k] / 10)
        # sin^2 envelope at its peak, averaged over one 0.125 s block: 1 - O(1e-4)
        assert abs(10 * np.log10(added) - 80.0) < 0.01
        # a quarter of the way in, sin^2 = 0.5: 3 dB below the peak
        k = int(np.argmin(np.abs(b.t - 65.0)))
        added = 10 ** (b.la_clean[k] / 10) - 10 ** (a.la_clean[k] / 10)
        envelope = np.sin(np.pi * (b.t[k] - 60.0) / 20.0) ** 2
        assert abs(10 * np.log10(added) - (80.0 + 10 * np.log10(envelope))) < 0.01


def test_random_events_are_listed_in_truth(tmp_path):
    doc = base(background={"level_dba": 30.0},
               effects={"background_event": {"count": 2, "duration_s": 10.0, "peak_dba": 70.0, "mic_spread_db": 0.0}})
    out = simulate(doc, tmp_path / "c")
    truth = json.loads((out / "truth.json").read_text())
    ev = truth["flights"]["f1"]["events"]
    assert len(ev) == 2 and all(abs(e["t1"] - e["t0"] - 10.0) < 1e-9 for e in ev)
    # the listed events are the ones in the levels: each adds 70 dB(A) times its sin^2 envelope over the listed
    # window (averaged over each 0.125 s block; random events may overlap, their energies add); nothing elsewhere
    doc_off = copy.deepcopy(doc)
    doc_off["effects"] = {}
    off = run(doc_off)
    for mic in ("m1", "m2"):
        blk = truth["flights"]["f1"]["blocks"][mic]
        t, on_la = np.array(blk["t"]), np.array(blk["LA_clean"])
        off_la = off.levels["f1"][mic].la_clean
        sub = t[:, None] + np.linspace(-0.0625, 0.0625, 201)[None, :]
        env = np.zeros(t.size)
        outside = np.ones(t.size, dtype=bool)
        for e in ev:
            u = np.clip((sub - e["t0"]) / (e["t1"] - e["t0"]), 0.0, 1.0)
            env += np.mean(np.sin(np.pi * u) ** 2, axis=1) * 10 ** (e["peak_dba"] / 10)
            outside &= (t < e["t0"] - 0.07) | (t > e["t1"] + 0.07)
        strong = env > 10 ** 6.0  # events above 60 dB(A): the 0.01 dB rounding of truth.json stays negligible
        assert strong.sum() > 40
        added = 10 ** (on_la[strong] / 10) - 10 ** (off_la[strong] / 10)
        np.testing.assert_allclose(10 * np.log10(added), 10 * np.log10(env[strong]), atol=0.02)
        np.testing.assert_allclose(on_la[outside], off_la[outside], atol=0.006)  # truth.json rounds to 0.01 dB


# ------------------------------------------------------------------ samples and audio


def test_simulate_samples_rows_match_the_written_levels(tmp_path):
    doc = base()
    doc["microphones"][1]["noise_std_db"] = 1.0
    res = run(doc)
    s = simulate_samples(res)
    assert set(np.unique(s.mic)) == {"m1", "m2"}
    for mic in ("m1", "m2"):
        rows = s.mic == mic
        np.testing.assert_array_equal(s.level[rows], res.levels["f1"][mic].la)
    # emission geometry: t_r = t_e + d / c holds for every row inside the flight
    inside = s.mask_reason != "outside_flight"
    np.testing.assert_allclose(s.t_r[inside], s.t_e[inside] + s.d[inside] / c_of(doc), atol=1e-6)
    assert s.band_f is not None and s.bands.shape == (len(s), len(s.band_f))


def test_synthesized_wav_blocks_hold_the_target_energy():
    f = 1000.0 * 10 ** (np.arange(-16, 14) / 10)
    rng = np.random.default_rng(0)
    target = 60.0 + np.cumsum(rng.normal(0.0, 0.3, (24, len(f))), axis=0)  # slowly varying levels
    x = synthesize_wav(target, f, 0.125, 48000, np.random.default_rng(1))
    blocks = x.reshape(24, 6000)
    la = 10 * np.log10(np.mean(blocks ** 2, axis=1) / 4e-10)
    expected = 10 * np.log10(np.sum(10 ** (target / 10), axis=1))
    np.testing.assert_allclose(la, expected, atol=0.02)


def test_wav_campaign_recovers_true_block_la(tmp_path):
    """A simulated WAV campaign through the whole chain recovers the true block LA within 0.3 dB RMS."""
    campaign = pytest.importorskip("gisnoise.measure.campaign")
    doc = base(output={"format": "wav", "block_s": 0.125, "fs_hz": 48000},
               microphones=[{"id": "m1", "e": 0.0, "n": 0.0, "mount": "ground_plate", "noise_std_db": 0.0},
                            {"id": "m2", "e": 60.0, "n": 30.0, "mount": "free_field", "height_m": 1.5,
                             "noise_std_db": 0.0}],
               background={"level_dba": 40.0},
               flights=[{"id": "f1", "start": {"e": 0.0, "n": -300.0, "heading_deg": 0.0}, "patterns": [
                   {"type": "climb", "to_height_m": 30.0, "rate_m_s": 3.0},
                   {"type": "flyby", "through": [0.0, 0.0], "heading_deg": 0.0, "length_m": 500.0,
                    "height_m": 30.0, "speed_m_s": 25.0}]}])
    out = simulate(doc, tmp_path / "camp")
    r = CliRunner().invoke(cli, ["-q", "campaign", "levels", str(out)])
    assert r.exit_code == 0, r.output
    truth = json.loads((out / "truth.json").read_text())
    samples = campaign.read_campaign(out).samples()
    for mic in ("m1", "m2"):
        blk = truth["flights"]["f1"]["blocks"][mic]
        rows = samples.mic == mic
        t = samples.t_r[rows]
        la = samples.level[rows]
        ref = np.interp(t, blk["t"], blk["LA_clean"])
        keep = (t > 1.0) & (t < blk["t"][-1] - 1.0)  # away from the recording's edges
        rms = float(np.sqrt(np.mean((la[keep] - ref[keep]) ** 2)))
        assert rms < 0.3, (mic, rms)


# ------------------------------------------------------------------ scenario checks and CLI


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["flights"][0]["patterns"][1].update(radius_m=-5), "flights[0].patterns[1].radius_m"),
    (lambda d: d["flights"][0]["patterns"][0].update(type="loop"), "flights[0].patterns[0].type"),
    (lambda d: d.update(effects={"bank_angel": {}}), "effects.bank_angel"),
    (lambda d: d.update(effects={"wind": {}}), "weather.wind_speed_m_s"),
    (lambda d: d["microphones"][0].update(mount="tripod"), "microphones[0].mount"),
    (lambda d: d["output"].update(format="mp3"), "output.format"),
    (lambda d: d["weather"].update(humidity_pct="wet"), "weather.humidity_pct"),
    (lambda d: d["vehicle"].update(cards={"climb": "no_such_card"}), "vehicle.cards.climb"),
    (lambda d: d.update(colour="red"), "colour"),
])
def test_bad_scenario_fields_are_named(mutate, field):
    doc = base()
    mutate(doc)
    with pytest.raises(ScenarioError) as e:
        resolve_scenario(doc)
    assert e.value.field == field
    assert field in str(e.value) and "\n" not in str(e.value)


def test_cli_simulate_and_bad_field(tmp_path):
    good = tmp_path / "s.json"
    good.write_text(json.dumps(hover_doc()))
    r = CliRunner().invoke(cli, ["-q", "simulate", str(good), "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "c" / "campaign.json").exists()
    # the command simulates the given scenario: its level file holds the block levels of the same scenario
    # (same seed) run through the library, to the CSV's 0.01 dB rounding
    written = np.genfromtxt(tmp_path / "c" / "mics" / "m1" / "f1.csv", delimiter=",", names=True)
    ref = run(hover_doc()).levels["f1"]["m1"]
    np.testing.assert_allclose(written["t"], ref.t, atol=1e-4)
    np.testing.assert_allclose(written["LA"], ref.la, atol=0.006)
    doc = hover_doc()
    doc["flights"][0]["patterns"][1]["duration_s"] = 0
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(doc))
    r = CliRunner().invoke(cli, ["simulate", str(bad), "--out", str(tmp_path / "d")])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "flights[0].patterns[1].duration_s" in lines[0]


def test_bundled_scenarios_resolve():
    paths = sorted(SCENARIOS.glob("*.json"))
    assert paths
    for p in paths:
        sc = resolve_scenario(load_scenario(p))
        assert set(sc.doc["effects"]) <= set(EFFECTS)
