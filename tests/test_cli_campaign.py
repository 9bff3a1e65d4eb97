"""``gisnoise campaign check`` and ``gisnoise campaign levels`` on tiny campaigns."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_campaign import make_campaign, make_wav_campaign, straight_track, write_flight_csv

from gisnoise import simulate
from gisnoise.acoustics import a_weighting
from gisnoise.cli.main import cli
from gisnoise.measure import read_campaign, read_level_csv, spreading_outliers, write_level_csv


def run(*args: str):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def test_check_clean_campaign_summary(tmp_path):
    root = make_campaign(tmp_path / "c")
    res = run("campaign", "check", str(root))
    assert res.exit_code == 0, res.output
    out = res.stdout
    n_blocks = len(np.arange(3.0, 58.0, 0.125))
    assert f"samples {3 * n_blocks}, valid {3 * n_blocks}, masked 0" in out
    flight_line = next(ln for ln in out.splitlines() if ln.startswith("f1 "))
    assert "f1.csv" in flight_line and " 70.0 " in flight_line and "horizontal 141" in flight_line
    assert sum(ln.startswith(("m1 ", "m2 ", "m3 ")) for ln in out.splitlines()) == 3
    assert "no problems found" in out


def test_check_reports_masked_counts_by_reason(tmp_path):
    root = make_campaign(tmp_path / "c", doc_changes={"exclusions": [{"flight": "f1", "t0": 10.0, "t1": 11.0}]})
    res = run("campaign", "check", str(root))
    assert res.exit_code == 0, res.output
    assert "masked 27, excluded 27" in res.stdout


@pytest.mark.parametrize("fault, file, field", [
    ("missing_mic", "mics/m2/f1.wav", "missing microphone file"),
    ("unknown_mount", "campaign.json", "field 'microphones[0].mount'"),
    ("sample_rate", "mics/m3/f1.wav", "sample_rate_hz is 44100 Hz"),
    ("no_power", "flights/f1.csv", "missing column(s) power_w"),
])
def test_each_fault_is_one_line_naming_file_and_field_exit_2(tmp_path, fault, file, field):
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000,
                                                 "m3": 44100 if fault == "sample_rate" else 48000}, seconds=0.5)
    if fault == "missing_mic":
        (root / "mics" / "m2" / "f1.wav").unlink()
    elif fault == "unknown_mount":
        doc = json.loads((root / "campaign.json").read_text())
        doc["microphones"][0]["mount"] = "on_a_stick"
        (root / "campaign.json").write_text(json.dumps(doc))
    elif fault == "no_power":
        track = straight_track()
        del track["power_w"]
        write_flight_csv(root / "flights" / "f1.csv", track)
    res = run("campaign", "check", str(root))
    assert res.exit_code == 2
    errors = [ln for ln in res.stderr.splitlines() if ln.startswith("Error: ")]
    assert len(errors) == 1, res.stderr
    assert str(root / file) in errors[0] and field in errors[0]


def test_levels_writes_csv_beside_the_wav_and_refuses_to_overwrite(tmp_path):
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000}, seconds=2.0)
    res = run("campaign", "levels", str(root), "--block", "0.25")
    assert res.exit_code == 0, res.output
    assert "wrote 2 level file(s)" in res.stdout
    lv = read_level_csv(root / "mics" / "m1" / "f1.csv")
    assert abs(np.median(np.diff(lv.t)) - 0.25) < 1e-6
    steady = (lv.t > 0.4) & (lv.t < 1.6)
    # 1 Pa RMS at 1 kHz on a ground plate: 94 - 6 = 88 dB(A), free field
    np.testing.assert_allclose(lv.la[steady], 88.0, atol=0.1)
    assert lv.band_f is not None and lv.band_f.min() < 30.0
    # the reader now takes the level CSVs, not the WAVs: their 0.25 s blocks (the WAV default is 0.125 s) and
    # the same 88 dB(A), the ground plate's 6 dB taken off once only (twice would read 82 dB(A))
    camp = read_campaign(root)
    for lvm in camp.levels:
        assert abs(np.median(np.diff(lvm.t)) - 0.25) < 1e-6
        np.testing.assert_allclose(lvm.la[(lvm.t > 0.4) & (lvm.t < 1.6)], 88.0, atol=0.1)
    again = run("campaign", "levels", str(root))
    assert again.exit_code == 2
    assert "exists; use --force" in again.stderr and "mics/m1/f1.csv" in again.stderr
    forced = run("campaign", "levels", str(root), "--force")
    assert forced.exit_code == 0
    # the reader now takes the level CSVs (same levels, no mount correction again)
    res = run("campaign", "check", str(root))
    assert res.exit_code == 0, res.output


def test_levels_without_wav_is_an_error(tmp_path):
    root = make_campaign(tmp_path / "c")
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 2
    assert "no WAV file" in res.stderr


def test_levels_writes_nothing_when_one_recording_is_refused(tmp_path):
    """m2's recording is clipped (refused): campaign levels exits 2 naming it and writes no level CSV at all,
    so the campaign is left as it was (not half converted, no stale CSV for the next run to refuse)."""
    from scipy.io import wavfile

    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000}, seconds=1.0)
    fs, data = wavfile.read(root / "mics" / "m2" / "f1.wav")
    full = np.iinfo(np.int16).max if data.dtype == np.int16 else 1.0
    data = np.clip(data.astype(float) * 1e6, -full, full).astype(data.dtype)
    wavfile.write(root / "mics" / "m2" / "f1.wav", fs, data)
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 2
    assert "mics/m2/f1.wav" in res.stderr and "clipped" in res.stderr
    assert sorted(p.name for p in (root / "mics").rglob("*.csv")) == []


def test_check_an_unmasked_loud_sound_at_one_microphone_names_no_position(tmp_path):
    """The diagnosis base campaign (four honest microphones) with an 85 dB(A) sound of 4 s (sin^2 in energy) that
    only m2 heard in f1: no joint rise, so the reader leaves it valid.  Its loudest sample puts the source about
    30 dB off (the rule on one block names m2); over its loudest 20 s the sound is a minority and nothing is
    named."""
    scenario = Path(__file__).resolve().parents[1] / "sample_data" / "scenarios" / "diagnosis_base.json"
    root = simulate.simulate(json.loads(scenario.read_text()), tmp_path / "c", base_dir=scenario.parent)
    csv = root / "mics" / "m2" / "f1.csv"
    lv = read_level_csv(csv)
    u = (lv.t - 120.0) / 4.0
    energy = np.where((u > 0) & (u < 1), np.sin(np.pi * np.clip(u, 0, 1)) ** 2, 0.0) * 10.0 ** 8.5
    flat = 10.0 * np.log10(np.sum(10.0 ** (np.asarray(a_weighting(lv.band_f)) / 10.0)))  # equal band levels, 85 dB(A)
    csv.unlink()
    write_level_csv(csv, lv.t, 10 * np.log10(10 ** (lv.la / 10) + energy), lv.band_f,
                    10 * np.log10(10 ** (lv.bands / 10) + energy[:, None] * 10 ** (-flat / 10)))
    s = read_campaign(root).samples()
    heard = (s.mic == "m2") & (s.flight == "f1") & (s.t_r > 121.0) & (s.t_r < 123.0)
    assert heard.sum() == 16 and s.valid[heard].all() and s.level[heard].max() > 84.0
    assert [m for m, *_ in spreading_outliers(s, window_s=0.125)] == ["m2"]
    res = run("campaign", "check", str(root))
    assert res.exit_code == 0, res.output
    assert "check its position" not in res.output and "no problems found" in res.stdout
