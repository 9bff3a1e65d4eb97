"""Malformed input never crashes and never passes for data: the probe's CLI findings, one rule set.

Each case is a finding of the adversarial probe (issue 19): a traceback or a silently wrong
result before; now exit 2 with one line naming the field, and the value where there is one.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_campaign import make_campaign, make_wav_campaign
from test_cli_contour import flyover, write_csv

from gisnoise import limits
from gisnoise.errors import InputError, TrajectoryError
from gisnoise.flight import Trajectory, read_flight_csv
from gisnoise.model import ModelCard, save


def run(*args: str):
    # catch_exceptions: a traceback would show up as r.exception other than SystemExit
    return CliRunner().invoke(__import__("gisnoise.cli.main", fromlist=["cli"]).cli, ["-q", *args])


def refused(r, *words: str) -> str:
    """Exit 2, no traceback, one line starting 'Error:' that names every word."""
    assert r.exit_code == 2, (r.exit_code, r.output, r.exception)
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert "Traceback" not in r.output
    lines = [ln for ln in r.output.strip().splitlines() if ln.strip()]
    err = [ln for ln in lines if ln.startswith("Error")]
    assert err, r.output
    for w in words:
        assert w in err[-1], (w, err[-1])
    return err[-1]


@pytest.fixture()
def card(tmp_path):
    c = ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                  parameters=dict(p0=70.0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                  reference_power_w=3000.0, phases=("hover", "transition"))
    return str(save(c, tmp_path / "omni.json"))


def _flight_csv(tmp_path, **changes):
    tr = flyover()
    cols = {k: np.array(getattr(tr, k)) for k in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w")}
    for k, (i, v) in changes.items():
        cols[k][i] = v
    lines = ["t,lat,lon,h,roll,pitch,yaw,power_w"]
    lines += [",".join(repr(float(cols[k][i])) for k in cols) for i in range(len(cols["t"]))]
    p = tmp_path / "f.csv"
    p.write_text("\n".join(lines) + "\n")
    return str(p)


# ------------------------------------------------------------------ tracebacks before
@pytest.mark.parametrize("content", [bytes(range(256)) * 8, "t,lat,lon\n1,2,3\n".encode("utf-16")])
def test_binary_or_utf16_trajectory_csv_is_one_line(tmp_path, card, content):
    p = tmp_path / "f.csv"
    p.write_bytes(content)
    refused(run("contour", str(p), "--card", card, "--out", str(tmp_path / "m")), "f.csv", "UTF-8")


def test_binary_microphone_csv_in_fit_is_one_line(tmp_path):
    root = make_campaign(tmp_path / "c")
    (root / "mics" / "m1" / "f1.csv").write_bytes(b"\xff\xfe\x00\x81" * 100)
    refused(run("fit", str(root), "--phase", "horizontal", "--out", str(tmp_path / "card.json")), "f1.csv")


def _wav(path, fs=48000, n=4800, declared=None):
    # low noise, not zeros: a recording of one value throughout is refused (a dropout, no sound)
    data = np.random.default_rng(0).integers(-300, 300, n).astype("<i2").tobytes()
    size = len(data) if declared is None else declared
    fmt = struct.pack("<HHIIHH", 1, 1, fs, fs * 2, 2, 16)
    path.write_bytes(b"RIFF" + struct.pack("<I", 36 + size) + b"WAVE" + b"fmt " + struct.pack("<I", 16) + fmt
                     + b"data" + struct.pack("<I", size) + data)


def test_wav_header_and_length_checks(tmp_path):
    from gisnoise.acoustics import check_wav_header, read_wav

    p = tmp_path / "a.wav"
    _wav(p, n=4800)
    assert check_wav_header(p) == (1, 48000, 16, 4800)
    assert read_wav(p)[0].shape == (4800,)
    for cut, field in ((20, "header"), (30, "header"), (40, "header")):
        q = tmp_path / f"cut{cut}.wav"
        q.write_bytes(p.read_bytes()[:cut])
        with pytest.raises(InputError) as e:
            read_wav(q)
        assert e.value.field == field
    _wav(p, n=0)
    with pytest.raises(InputError, match="no samples") as e:
        read_wav(p)
    assert e.value.field == "length"
    # half of the samples cut off: refused, the missing part stated (2400 samples at 48 kHz = 0.05 s)
    _wav(p, n=4800)
    q = tmp_path / "half.wav"
    q.write_bytes(p.read_bytes()[:44 + 4800])
    with pytest.raises(InputError, match=r"0\.05 s of audio missing") as e:
        read_wav(q)
    assert e.value.field == "length"


@pytest.mark.parametrize("fault", ["truncated_header", "zero_samples", "ten_ms", "half_truncated"])
def test_campaign_levels_refuses_bad_wavs(tmp_path, fault):
    root = make_wav_campaign(tmp_path / "c", seconds=1.0)
    wav = root / "mics" / "m2" / "f1.wav"
    raw = wav.read_bytes()
    if fault == "truncated_header":
        wav.write_bytes(raw[:30])
        words = ["f1.wav", "fmt"]
    elif fault == "zero_samples":
        _wav(wav, n=0)
        words = ["f1.wav", "no samples"]
    elif fault == "ten_ms":
        _wav(wav, n=480)
        words = ["block_s", "0.01 s"]
    else:
        wav.write_bytes(raw[:len(raw) // 2])
        words = ["f1.wav", "truncated", "missing"]
    refused(run("campaign", "levels", str(root)), *words)
    assert not (root / "mics" / "m2" / "f1.csv").exists()


def test_campaign_levels_huge_block_and_missing_wav_are_named(tmp_path):
    root = make_wav_campaign(tmp_path / "c", seconds=1.0)
    refused(run("campaign", "levels", str(root), "--block", "1e9"), "block_s", "1e+09")
    (root / "mics" / "m2" / "f1.wav").unlink()
    refused(run("campaign", "levels", str(root)), "m2", "f1.wav", "missing")
    assert not (root / "mics" / "m1" / "f1.csv").exists()  # nothing half-written


# ------------------------------------------------------------------ silently wrong before
@pytest.mark.parametrize("column,value,words", [
    ("power_w", 1e300, ["power_w", "1e+300", "100000"]),
    ("lon", 200.0, ["lon", "200", "-180, 180"]),
    ("roll", 1e6, ["roll", "1e+06"]),
    ("t", 1e9, ["t", "gap"]),
    ("h", 50_000.0, ["h", "50000"]),
    ("lat", 91.0, ["lat"]),
])
def test_implausible_flight_values_are_refused_by_contour(tmp_path, card, column, value, words):
    i = -1 if column == "t" else 5
    csv = _flight_csv(tmp_path, **{column: (i, value)})
    refused(run("contour", csv, "--card", card, "--out", str(tmp_path / "m"), "--resolution", "50"), *words)
    assert not (tmp_path / "m").exists()


def test_power_limit_has_an_override(tmp_path):
    csv = _flight_csv(tmp_path, power_w=(3, 2e5))
    with pytest.raises(TrajectoryError, match="max_power_w"):
        read_flight_csv(csv)
    with limits.override(max_power_w=5e5):
        assert read_flight_csv(csv).power_w.max() == 2e5


@pytest.mark.parametrize("args,words", [
    (("--receiver-height", "-10"), ["receiver_height", "-10"]),
    (("--ground-height", "1000"), ["ground_h", "1000", "above the track"]),
])
def test_receivers_below_ground_and_ground_above_track_are_refused(tmp_path, card, args, words):
    csv = write_csv(tmp_path / "f.csv", flyover())
    refused(run("contour", csv, "--card", card, "--out", str(tmp_path / "m"), "--resolution", "50", *args), *words)


def test_ground_at_the_track_bottom_is_accepted(tmp_path):
    tr = flyover()
    limits.check_receivers(1.5, float(tr.h.min()), tr.h)
    limits.check_receivers(0.0, None, tr.h)


def test_card_show_refuses_a_negative_power(card):
    refused(run("card", "show", card, "--p-el", "-1"), "p_el", "-1")
    r = run("card", "show", card, "--p-el", "1.1")
    assert r.exit_code == 0 and "P_el = 1.1" in r.output


def test_operations_daily_count_is_bounded():
    from gisnoise.ops.schedule import Flight

    tr = flyover()
    with pytest.raises(InputError, match=r"counts: 1e\+300 is outside \[0, 100000\]"):
        Flight(id="a", trajectory=tr, counts={"day": 1e300})
    assert Flight(id="a", trajectory=tr, counts={"day": 40}).total == 40


# ------------------------------------------------------------------ the rule set itself
def test_longitudes_are_never_wrapped():
    n = 3
    kw = dict(t=np.arange(n, dtype=float), lat=np.full(n, 52.0), h=np.full(n, 100.0), roll=np.zeros(n),
              pitch=np.zeros(n), yaw=np.zeros(n), power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))
    assert Trajectory(lon=np.full(n, 180.0), **kw).lon[0] == 180.0
    with pytest.raises(TrajectoryError, match=r"lon: 180\.001 deg at sample 0") as e:
        Trajectory(lon=np.full(n, 180.001), **kw)
    assert e.value.field == "lon"


def test_route_samples_are_bounded_before_allocating():
    from gisnoise.flight import read_trajectory

    doc = {"type": "FeatureCollection", "route": {"altitude_reference": "agl", "sample_dt_s": 1e-6},
           "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": c}, "properties": p}
                        for c, p in [([10.54, 52.243], {"alt": 0}), ([10.54, 52.243], {"alt": 60}),
                                     ([10.55, 52.25], {"alt": 60, "speed": 22}), ([10.55, 52.25], {"alt": 0})]]}
    with pytest.raises(limits.WorkLimitError, match="sample_dt_s") as e:
        read_trajectory(doc)
    assert e.value.field == "sample_dt_s"
    doc["route"]["sample_dt_s"] = 0.5
    assert 100 < len(read_trajectory(doc)) < 1000
    hold = json.loads(json.dumps(doc))
    hold["features"][1]["properties"]["hold_s"] = 1e12
    with pytest.raises(TrajectoryError, match=r"hold_s: 1e\+12 s is outside \[0, 86400\] s") as e:
        read_trajectory(hold)
    assert e.value.field == "hold_s"
    slow = json.loads(json.dumps(doc))
    slow["features"][2]["properties"]["speed"] = 1e-9
    with pytest.raises(limits.WorkLimitError):
        read_trajectory(slow)


@pytest.mark.parametrize("value,ok", [("abc", True), ("a.b-c_d", True), ("x\n", False), ("con", False),
                                      ("CON.txt", False), ("nul", False), ("com1", False), (".hidden", False),
                                      ("console", True), ("a" * 128, True), ("a" * 129, False), ("a/b", False),
                                      ("a\x00b", False), ("", False)])
def test_safe_identifier_pattern(value, ok):
    if ok:
        assert limits.check_id(value) == value
    else:
        with pytest.raises(InputError):
            limits.check_id(value)



@pytest.mark.parametrize("alts", [(1.7e308, -1.7e308), (0.0, 5e5)])
def test_waypoint_altitudes_out_of_range_are_refused_before_the_path_is_flown(alts):
    """Altitudes whose difference overflows (a path of infinite length) or above the height ceiling: field alt."""
    from gisnoise.errors import TrajectoryError
    from gisnoise.flight import routes

    doc = {"schema": "gisnoise/waypoints/1", "ground_h_m": 80.0,
           "waypoints": [{"lon": 10.0, "lat": 52.0, "alt": alts[0]}, {"lon": 10.001, "lat": 52.0, "alt": alts[1]}]}
    with pytest.raises(TrajectoryError) as err:
        routes.read_trajectory(doc)
    assert err.value.field == "alt" and "\n" not in str(err.value)


@pytest.mark.parametrize("sep, name", [(";", "';'"), ("\t", "tab")])
def test_a_csv_separated_otherwise_than_by_commas_is_refused_naming_the_separator(tmp_path, card, sep, name):
    """A spreadsheet's export with ';' or tabs between fields (and often decimal commas) is named as such, not
    reported as missing columns or a field count."""
    text = Path(_flight_csv(tmp_path)).read_text()
    p = tmp_path / "sep.csv"
    p.write_text("\n".join(ln.replace(",", sep).replace(".", ",") for ln in text.splitlines()) + "\n")
    refused(run("contour", str(p), "--card", card, "--out", str(tmp_path / "m"), "--ground-height", "0"),
            "separated by " + name, "comma")
    assert not (tmp_path / "m").exists()


def test_an_unknown_phase_is_named_as_written(tmp_path, card):
    """The refusal of an unknown phase quotes the value as the file has it."""
    lines = Path(_flight_csv(tmp_path)).read_text().splitlines()
    p = tmp_path / "phase.csv"
    p.write_text("\n".join([lines[0] + ",phase"] + [ln + ",Hover" for ln in lines[1:]]) + "\n")
    msg = refused(run("contour", str(p), "--card", card, "--out", str(tmp_path / "m"), "--ground-height", "0"),
                  "phase", "'Hover'")
    assert "np." not in msg


def _msl_waypoints(tmp_path):
    """Waypoints with altitudes above mean sea level: take-off at 100 m MSL, cruise at 160 m MSL."""
    lat0, lon0 = 52.27, 10.52
    pts = [(0.0, 100.0), (0.0, 160.0), (0.01, 160.0), (0.01, 100.0)]
    feats = [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon0 + d, lat0, a]},
              "properties": {"alt": a}} for d, a in pts]
    p = tmp_path / "msl.geojson"
    p.write_text(json.dumps({"type": "FeatureCollection", "route": {"altitude_reference": "msl"}, "features": feats}))
    return str(p)


def test_geoid_undulation_is_applied_to_msl_waypoints(tmp_path, no_geoid_grid):
    """--geoid-undulation N makes heights above mean sea level ellipsoidal (h = alt + N) for msl waypoints as for a
    log: without a geoid grid it is the way out the refusal names, and it is the N the map states."""
    from gisnoise.flight import read_route

    path = _msl_waypoints(tmp_path)
    with pytest.raises(InputError, match="--geoid-undulation"):
        read_route(path)
    tr = read_route(path, geoid_undulation_m=40.0).trajectory
    assert float(tr.h.min()) == pytest.approx(140.0, abs=1e-6) and float(tr.h.max()) == pytest.approx(200.0, abs=1e-6)
    assert tr.metadata["geoid_undulation_m"] == 40.0


def test_power_w_on_a_trajectory_that_states_its_power_is_refused(tmp_path, card):
    """--power-w replaces the power of a flight log without battery current; given with a flight CSV, whose power it
    states, it is refused naming the field instead of being ignored."""
    csv = _flight_csv(tmp_path)
    refused(run("contour", csv, "--card", card, "--out", str(tmp_path / "m"), "--ground-height", "0", "--power-w",
                "900"), "power_w")
    assert not (tmp_path / "m").exists()
