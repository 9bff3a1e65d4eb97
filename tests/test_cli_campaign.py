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
from gisnoise.measure import check_campaign, read_campaign, read_level_csv, spreading_outliers, write_level_csv


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


# ----------------------------------------------------------------------------- dropouts
def _zero(wav: Path, t0: float, t1: float) -> None:
    from scipy.io import wavfile

    fs, data = wavfile.read(wav)
    data[int(t0 * fs):int(t1 * fs)] = 0
    wavfile.write(wav, fs, data)


def test_levels_refuses_a_dropout_in_one_line_and_reads_it_once_excluded(tmp_path):
    """1 s of digital zeros (2-3 s) in m2's recording: campaign levels wrote filter decay there (LA 70.5 ... -47.6
    dB) and check counted it valid.  Now levels refuses in one line naming the file, the times and the exclusion
    that leaves them out, writing nothing; with that exclusion in campaign.json, the blocks it touches are left
    out and every level written is the recording's 1 Pa at 1 kHz on a ground plate: 94.0 - 6 = 88.0 dB(A)."""
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000}, seconds=6.0)
    wav = root / "mics" / "m2" / "f1.wav"
    _zero(wav, 2.0, 3.0)
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 2
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    assert str(wav) in lines[0] and "dropout" in lines[0] and "2.000-3.000 s" in lines[0]
    hint = lines[0].split('campaign.json "exclusions": ')[1]
    # whole milliseconds outwards (the int16 sine's own zero at 3 s, sample 144000, ends the stretch)
    assert json.loads(hint) == [{"flight": "f1", "mic": "m2", "t0": 2.0, "t1": 3.001}]
    assert list((root / "mics").rglob("*.csv")) == []
    chk = run("campaign", "check", str(root))  # reading the WAV itself: the same line, as a problem
    assert chk.exit_code == 2 and "2.000-3.000 s" in chk.stderr and hint in chk.stderr
    doc = json.loads((root / "campaign.json").read_text())
    doc["exclusions"] = json.loads(hint)  # the way out, as the message gives it
    (root / "campaign.json").write_text(json.dumps(doc))
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 0, res.output
    lv = read_level_csv(root / "mics" / "m2" / "f1.csv")
    assert lv.t.min() < 2.0 and lv.t.max() > 5.0
    assert not np.any((lv.t > 2.0) & (lv.t < 3.0))  # the dropout's blocks are not in the file
    inner = (lv.t > 0.5) & (lv.t < 5.5)  # the filters' start and end of the recording aside
    np.testing.assert_allclose(lv.la[inner], 88.0, atol=0.1)
    assert run("campaign", "check", str(root)).exit_code == 0


def test_a_recording_of_zeros_writes_no_level_file(tmp_path):
    """An all-zero WAV wrote LA = -inf and check refused its own output; now levels and check refuse the WAV."""
    from scipy.io import wavfile

    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000, "m2": 48000}, seconds=1.0)
    wav = root / "mics" / "m1" / "f1.wav"
    wavfile.write(wav, 48000, np.zeros(48000, dtype=np.int16))
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 2 and "holds no sound" in res.stderr and str(wav) in res.stderr
    assert "exclusions" not in res.stderr  # nothing of it is sound: no exclusion to offer
    assert list((root / "mics").rglob("*.csv")) == []
    chk = run("campaign", "check", str(root))
    assert chk.exit_code == 2 and "holds no sound" in chk.stderr


# ----------------------------------------------------------------------------- sample rates below 44.1 kHz
def _pink_table_loss(top_nominal: float) -> float:
    """A-weighted level a pink spectrum (equal energy in each band 25 Hz-20 kHz) loses without the bands above
    ``top_nominal``, dB, from IEC 61672-1 Table 3 (test_acoustics.IEC61672_TABLE3_A)."""
    from test_acoustics import IEC61672_TABLE3_A

    rows = [(f, a) for f, a in IEC61672_TABLE3_A if f >= 25]
    w = np.array([10 ** (a / 10) for _, a in rows])
    return float(10 * np.log10(w.sum() / w[[f <= top_nominal for f, _ in rows]].sum()))


@pytest.mark.parametrize("fs, top, loss", [(16000, "6.3 kHz", "0.6"), (8000, "3.15 kHz", "1.8")])
def test_a_sample_rate_below_44k_is_said_by_levels_and_check(tmp_path, fs, top, loss):
    """Bands stop at 6.3 kHz at 16 kHz and at 3.15 kHz at 8 kHz (95 % of Nyquist): campaign levels and check say
    so, naming the files, the rate, the highest band and what a pink source's A-weighted level loses without
    the missing bands (IEC 61672-1 Table 3: 0.61 and 1.85 dB)."""
    assert f"{_pink_table_loss(float(top.split()[0]) * 1000):.1f}" == loss
    root = make_wav_campaign(tmp_path / "c", fs={"m1": fs, "m2": fs}, seconds=1.0)
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 0, res.output
    said = [ln for ln in res.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(said) == 1, res.stderr
    for part in ("mics/m1/f1.wav", "mics/m2/f1.wav", f"{fs} Hz", f"up to {top}", "pink", f"{loss} dB(A) low"):
        assert part in said[0], said[0]
    chk = run("campaign", "check", str(root))  # from the level CSVs' source records
    assert chk.exit_code == 0, chk.output
    said = [ln for ln in chk.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(said) == 1 and "mics/m1/f1.csv" in said[0] and f"{loss} dB(A) low" in said[0]


def test_44k_recordings_carry_the_bands_class_1_needs_and_are_not_named(tmp_path):
    """At 44.1 kHz the bands reach 16 kHz (IEC 61672-1 class 1 allows the 20 kHz band to be missing; a pink
    source would lose 0.03 dB): nothing to say."""
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 44100}, seconds=1.0)
    res = run("campaign", "levels", str(root))
    assert res.exit_code == 0 and "warning" not in res.stderr


# ----------------------------------------------------------------------------- stale level files
def _set_mic(root: Path, **fields) -> None:
    doc = json.loads((root / "campaign.json").read_text())
    doc["microphones"][0].update(fields)
    (root / "campaign.json").write_text(json.dumps(doc))


def test_a_level_file_computed_with_another_sensitivity_is_refused_until_recomputed(tmp_path):
    """sensitivity_v_per_pa typed as 50 (mV/Pa) instead of 0.05 V/Pa: the levels read 20 lg(50 / 0.05) = 60 dB
    low (28 dB(A) for the 88 dB(A) recorded).  Once campaign.json says 0.05, check and the reader refuse the
    stale CSV in one line naming it, the field and the command that mends it; after it, 88.0 dB(A)."""
    from gisnoise.errors import CampaignError

    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000}, seconds=1.0)
    _set_mic(root, sensitivity_v_per_pa=50.0)
    assert run("campaign", "levels", str(root)).exit_code == 0
    csv = root / "mics" / "m1" / "f1.csv"
    lv = read_level_csv(csv)
    np.testing.assert_allclose(lv.la[(lv.t > 0.3) & (lv.t < 0.7)], 88.0 - 60.0, atol=0.1)
    _set_mic(root, sensitivity_v_per_pa=0.05)
    chk = run("campaign", "check", str(root))
    assert chk.exit_code == 2
    errors = [ln for ln in chk.stderr.splitlines() if ln.startswith("Error: ")]
    assert len(errors) == 1, chk.stderr
    for part in (str(csv), "sensitivity_v_per_pa 50.0", "now states 0.05", "60.0 dB too low",
                 f"gisnoise campaign levels {root} --force"):
        assert part in errors[0], errors[0]
    with pytest.raises(CampaignError) as err:
        read_campaign(root)
    assert err.value.field == "sensitivity_v_per_pa"
    assert run("campaign", "levels", str(root), "--force").exit_code == 0
    assert run("campaign", "check", str(root)).exit_code == 0
    lv = read_level_csv(csv)
    np.testing.assert_allclose(lv.la[(lv.t > 0.3) & (lv.t < 0.7)], 88.0, atol=0.1)


@pytest.mark.parametrize("change, field, said", [
    ({"mount": "free_field"}, "mount", "6.0 dB too low"),             # the ground plate's -6 dB no longer applies
    ({"full_scale_v": 2.0}, "full_scale_v", "6.0 dB too low"),        # 20 lg 2 = 6.02 dB
    ("wav", "wav", "f1.wav changed after its levels were computed"),  # another recording, the same size
])
def test_a_level_file_whose_calibration_or_wav_changed_is_refused(tmp_path, change, field, said):
    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000}, seconds=1.0)
    assert run("campaign", "levels", str(root)).exit_code == 0
    if change == "wav":
        from scipy.io import wavfile

        wav = root / "mics" / "m1" / "f1.wav"
        fs, data = wavfile.read(wav)
        wavfile.write(wav, fs, (data // 2).astype(data.dtype))
    else:
        _set_mic(root, **change)
    problems = check_campaign(root)
    assert [p.field for p in problems] == [field]
    assert said in problems[0].message and "mics/m1/f1.csv" in problems[0].message


def test_a_copied_campaign_and_level_files_without_a_record_read_as_before(tmp_path):
    """A copy changes the WAV's modification time, not its content (SHA-256): its levels stand.  A level CSV a
    user brings has no source record and is read as it is, whatever campaign.json's calibration says."""
    import os
    import shutil

    root = make_wav_campaign(tmp_path / "c", fs={"m1": 48000}, seconds=1.0)
    assert run("campaign", "levels", str(root)).exit_code == 0
    copy = tmp_path / "copy"
    shutil.copytree(root, copy, copy_function=shutil.copy)  # contents, fresh modification times
    wav = copy / "mics" / "m1" / "f1.wav"
    os.utime(wav, ns=(wav.stat().st_atime_ns, wav.stat().st_mtime_ns + 10**9))
    assert check_campaign(copy) == []
    brought = make_campaign(tmp_path / "b")
    _set_mic(brought, sensitivity_v_per_pa=50.0, mount="ground_plate")
    assert check_campaign(brought) == []
