"""Stretches of a real log left out of its trajectory (a topic starting late) are recorded and said.

The truth is each log's own topic times, read here with pyulog and pymavlink directly.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.flight import read_flight, track_warning
from gisnoise.flight.logspan import left_out

pyulog = pytest.importorskip("pyulog")
DFReader = pytest.importorskip("pymavlink.DFReader")

DATA = Path(__file__).parent / "data"
QUAD = DATA / "robologs_test_quad_fmuv5.ulg"
VTOL = DATA / "pyulog_sample_log_small_vtol.ulg"
COPTER = DATA / "dronekit_la_testdata_log171_copter.bin"


@pytest.fixture(scope="module")
def quad():
    """The quad's topics as pyulog reads them (s after boot): first and last times, the landed flag, the battery."""
    u = pyulog.ULog(str(QUAD))
    d = {x.name: x.data for x in u.data_list}
    gps = d["vehicle_gps_position"]
    fix = gps["fix_type"] >= 3
    spans = {"gps": gps["timestamp"][fix] / 1e6, "attitude": d["vehicle_attitude"]["timestamp"] / 1e6,
             "battery": d["battery_status"]["timestamp"] / 1e6, "local": d["vehicle_local_position"]["timestamp"] / 1e6}
    return {"start": u.start_timestamp / 1e6, "spans": spans, "land": d["vehicle_land_detected"],
            "battery": d["battery_status"]}


def test_quad_attitude_starting_late_leaves_out_the_first_hop_and_says_so(quad):
    """vehicle_attitude begins 3.5 s after the logger: the first hop (battery current, land detector airborne)
    lies before it.  The trajectory starts at the first GPS fix inside the span of all its topics; the stretch
    before is in the metadata with the late topic, its span, its flight time and power, and in the warning."""
    tr = read_flight(QUAD)
    sp = quad["spans"]
    t_att = sp["attitude"][0]
    # the facts of the log: attitude starts over a second after GPS, battery and local position
    assert t_att - max(sp["gps"][0], sp["battery"][0], sp["local"][0]) > 1.0
    kept0 = sp["gps"][sp["gps"] >= max(s[0] for s in sp.values())][0]    # the trajectory's first sample
    first = max(min(s[0] for s in sp.values()), quad["start"])

    stretches = tr.metadata["log_left_out"]
    assert [s["part"] for s in stretches] == ["start"]
    s = stretches[0]
    assert list(s["topics"]) == ["vehicle_attitude"]
    assert s["topics"]["vehicle_attitude"] == pytest.approx(t_att, abs=1e-6)
    assert s["log_s"] == pytest.approx([first, kept0], abs=1e-6)
    assert s["t_s"] == pytest.approx([first - kept0, 0.0], abs=1e-6) and tr.t[0] == 0.0

    # in the air by the land detector: the seconds of landed == 0 inside the stretch, summed step by step
    land = quad["land"]
    tl, up = land["timestamp"] / 1e6, land["landed"] == 0
    air = 0.0
    for i in range(len(tl)):
        lo, hi = max(tl[i], first), min(tl[i + 1] if i + 1 < len(tl) else np.inf, kept0)
        if up[i] and hi > lo:
            air += hi - lo
    assert air > 1.0 and s["airborne_s"] == pytest.approx(air, abs=1e-6)

    # battery current was drawn there (the logged current reads over 10 A); the power is the coulomb count's
    b = quad["battery"]
    tb = b["timestamp"] / 1e6
    inside = (tb >= first) & (tb <= kept0)
    assert b["current_a"][inside].max() > 10.0
    q = b["discharged_mah"].astype(float)
    mid = 0.5 * (tb[1:] + tb[:-1])
    p_mid = np.interp(mid, tb, b["voltage_v"]) * 3.6 * np.diff(q) / np.diff(tb)
    assert s["max_power_w"] == pytest.approx(p_mid[(mid >= first) & (mid <= kept0)].max(), abs=1e-3)

    said = track_warning(tr)
    assert said is not None and said.startswith(f"{QUAD}: the first ")
    for part in (f"vehicle_attitude starts at {t_att:.2f} s", f"{first:.2f}-{kept0:.2f} s after boot",
                 f"in the air for {air:.1f} s", "missing from maps"):
        assert part in said


def test_quad_end_within_a_sampling_step_is_not_named(quad):
    """The GPS's last fix comes half a second before attitude's last sample: the sampling's own edge."""
    tr = read_flight(QUAD)
    sp = quad["spans"]
    assert 0.0 < max(s[-1] for s in sp.values()) - sp["gps"][-1] < 1.0
    assert not [s for s in tr.metadata["log_left_out"] if s["part"] == "end"]


def test_quad_map_carries_the_warning(tmp_path, omni_card):
    out = tmp_path / "m"
    r = CliRunner().invoke(cli, ["contour", str(QUAD), "--card", omni_card, "--out", str(out), "--resolution", "20",
                                 "--margin", "100"])
    assert r.exit_code == 0, r.output
    assert "vehicle_attitude starts at" in r.stderr
    doc = json.loads((out / "contours.geojson").read_text())
    assert any("vehicle_attitude starts at" in w for w in doc["gisnoise"]["warnings"])


def test_vtol_whose_topics_start_together_has_nothing_left_out():
    """The VTOL log's GPS, attitude and batteries start within 0.4 s of one another."""
    u = pyulog.ULog(str(VTOL), ["vehicle_gps_position", "vehicle_attitude", "battery_status"])
    firsts = [x.data["timestamp"][0] / 1e6 for x in u.data_list]
    assert max(firsts) - min(firsts) < 1.0
    tr = read_flight(VTOL)
    assert "log_left_out" not in tr.metadata and track_warning(tr) is None


def test_copter_before_its_first_fix_is_recorded_not_warned():
    """ArduCopter log171: GPS has no 3D fix for its first half minute, while the vehicle sits disarmed; the
    stretch is recorded (the GPS fix as the late topic, no time in the air) and not warned about."""
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    fixes, att, armed, last = [], [], [], 0.0
    try:
        while (m := r.recv_match(type=["GPS", "ATT", "EV"])) is not None:
            if m.get_type() == "EV":
                if m.Id == 10:                          # ARMED; this log's events carry no time: the message before
                    armed.append(last)
            elif m.get_type() == "GPS":                 # ArduCopter 3.3: boot time in T (ms), TimeMS is GPS time
                last = m.T / 1e3
                if m.Status >= 3:
                    fixes.append(last)
            else:                                       # ATT: boot time in TimeMS
                last = m.TimeMS / 1e3
                att.append(last)
    finally:
        r.close()
    tr = read_flight(COPTER, geoid_undulation_m=22.0)
    (s,) = tr.metadata["log_left_out"]
    assert s["part"] == "start" and list(s["topics"]) == ["GPS 3D fix"]
    assert s["topics"]["GPS 3D fix"] == pytest.approx(fixes[0], abs=1e-6) and fixes[0] - att[0] > 20.0
    assert s["log_s"][0] <= att[0] + 0.1 and s["log_s"][1] == pytest.approx(fixes[0], abs=1e-6)
    assert armed and armed[0] > fixes[0]                    # armed only after the fix: no flight before it
    assert s["airborne_s"] == 0.0 and track_warning(tr) is None


def test_no_landed_flag_and_power_drawn_is_warned():
    """Without a landed flag a stretch with battery power counts as one where the vehicle may have flown."""
    t = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    st = left_out((3.0, 4.0), {"position": (3.0, 4.0), "battery": (0.0, 4.0)}, step_s=0.2,
                  power=[(t, np.array([0.0, 50.0, 0.0, 0.0, 0.0]))])
    assert st == [{"part": "start", "log_s": [0.0, 3.0], "t_s": [0.0, 3.0], "duration_s": 3.0,
                   "topics": {"position": 3.0}, "max_power_w": 50.0, "airborne_s": None}]

    class Tr:
        source, metadata = "x.ulg", {"log_left_out": st}

    assert "the log has no landed flag and the batteries drew up to 50 W" in track_warning(Tr())
    Tr.metadata = {"log_left_out": [{**st[0], "max_power_w": 0.0}]}
    assert track_warning(Tr()) is None
