"""Flight logs cut short (a dead battery, a full SD card, a broken download): said, not mapped as complete.

Expectations come from the formats' framing (ULog: 16-byte header, then ``uint16 size, uint8 type`` and
``size`` bytes; DataFlash: ``0xA3 0x95 type`` and the length the format states, ``FMT`` 89 bytes) and from
pyulog and pymavlink reading the uncut files: what a cut file gives is the uncut file's data up to the cut.
"""

import json
import shutil
import struct

import numpy as np
import pytest

from gisnoise.errors import TrajectoryError
from gisnoise.flight import dataflash_cut, left_out_warning, read_flight, track_warning, ulog_cut

pyulog = pytest.importorskip("pyulog")
DFReader = pytest.importorskip("pymavlink.DFReader")

# the real logs, their site's geoid undulation and the command runner
from test_real_logs_maps import COPTER, N_SITE, QUAD, VTOL, run  # noqa: E402

CUT = "the file was cut"


def _cut_of(path):
    return ulog_cut if path.suffix == ".ulg" else dataflash_cut


def _write_cut(src, k, tmp_path):
    out = tmp_path / f"{src.stem}_cut{k}{src.suffix}"
    out.write_bytes(src.read_bytes()[:k])
    return out


def _read(path):
    return read_flight(path, geoid_undulation_m=N_SITE)


# ----------------------------------------------------------------------------- complete logs
@pytest.mark.parametrize("path", [VTOL, QUAD, COPTER], ids=lambda p: p.stem)
def test_uncut_logs_end_at_a_message_end_and_give_no_warning(path):
    assert _cut_of(path)(path.read_bytes()) is None
    tr = _read(path)
    # the one warning a whole log may carry: the quad's first hop, before its attitude is logged (test_log_left_out)
    assert "log_cut" not in tr.metadata and track_warning(tr) == left_out_warning(tr)
    assert (left_out_warning(tr) is None) == (path != QUAD)


# ----------------------------------------------------------------------------- cut in the data
def _ulog_data(path):
    u = pyulog.ULog(str(path))
    return {(d.name, d.multi_id): d.data for d in u.data_list}


def _dataflash_messages(path, types=("GPS", "ATT", "CURR", "EV")):
    r = DFReader.DFReader_binary(str(path), zero_time_base=True)
    out = []
    while (m := r.recv_match(type=list(types))) is not None:
        out.append((m.get_type(), tuple(getattr(m, c) for c in m.fmt.columns)))
    r.close()
    return out


CASES = [(VTOL, f) for f in (0.5, 0.9, 0.999)] + [(QUAD, f) for f in (0.9, 0.999)] \
    + [(COPTER, f) for f in (0.5, 0.9, 0.999)]


@pytest.mark.parametrize("path,fraction", CASES, ids=lambda v: getattr(v, "stem", str(v)))
def test_cut_log_warns_and_reads_the_uncut_samples_up_to_the_cut(tmp_path, path, fraction):
    raw = path.read_bytes()
    k = int(fraction * len(raw))
    cut_path = _write_cut(path, k, tmp_path)
    cut = _cut_of(path)(raw[:k])
    # the file ends inside one message; the bytes up to that message's start are whole
    assert cut is not None and cut.file_bytes == k and not cut.in_definitions
    assert cut.message_at < k < cut.message_end <= len(raw)
    assert _cut_of(path)(raw[:cut.message_at]) is None and _cut_of(path)(raw[:cut.message_end]) is None
    # the libraries read the uncut file's messages up to the cut, no more, no less
    if path.suffix == ".ulg":
        full, part = _ulog_data(path), _ulog_data(cut_path)
        assert set(part) <= set(full)
        for key, cols in part.items():
            n = len(cols["timestamp"])
            assert n <= len(full[key]["timestamp"])
            for c, v in cols.items():
                np.testing.assert_array_equal(v, full[key][c][:n], err_msg=f"{key} {c}")
    else:
        full_m, part_m = _dataflash_messages(path), _dataflash_messages(cut_path)
        assert 0 < len(part_m) < len(full_m) and part_m == full_m[:len(part_m)]
    # the trajectory: the uncut file's samples up to the cut, and a warning naming the cut
    tr_full, tr = _read(path), _read(cut_path)
    n = len(tr)
    assert 2 <= n <= len(tr_full)
    for col in ("t", "lat", "lon", "roll", "pitch", "yaw"):
        np.testing.assert_array_equal(getattr(tr, col), getattr(tr_full, col)[:n], err_msg=col)
    assert tr.metadata["log_cut"]["file_bytes"] == k
    said = f"{cut_path}: the log ends mid-message at byte {k} of {cut.message_end} " \
           f"({CUT}: the flight may go on beyond t = {tr.t[-1]:.1f} s)"
    left = left_out_warning(tr)       # the quad's first hop, before its attitude is logged, as in the uncut file
    assert left == (None if left_out_warning(tr_full) is None else left_out_warning(tr_full).replace(str(path),
                                                                                                   str(cut_path)))
    assert track_warning(tr) == (said if left is None else f"{said}; {left}")


@pytest.mark.parametrize("path,fraction", [(QUAD, 0.5), (COPTER, 0.1)], ids=["quad", "copter"])
def test_cut_log_too_short_to_read_names_the_cut_in_its_error(tmp_path, path, fraction):
    k = int(fraction * path.stat().st_size)
    cut_path = _write_cut(path, k, tmp_path)
    with pytest.raises(TrajectoryError) as e:
        _read(cut_path)
    msg = str(e.value)
    assert msg.startswith(str(cut_path)) and f"ends mid-message at byte {k} of " in msg and CUT in msg
    assert "\n" not in msg


# ----------------------------------------------------------------------------- cut in the definitions
@pytest.mark.parametrize("path,k", [
    (VTOL, 17),      # inside the first message's header (the file header is 16 bytes)
    (VTOL, 100),
    (QUAD, 100),
    (COPTER, 50),    # inside the first FMT message (89 bytes)
    (COPTER, 100),   # inside the second one
], ids=lambda v: getattr(v, "stem", str(v)))
def test_log_cut_in_its_definitions_is_refused_in_one_line(tmp_path, path, k):
    cut_path = _write_cut(path, k, tmp_path)
    with pytest.raises(TrajectoryError) as e:
        _read(cut_path)
    msg = str(e.value)
    assert msg.startswith(f"{cut_path}: the log ") and f"byte {k}" in msg and "definitions" in msg and CUT in msg
    assert "\n" not in msg and e.value.field == "path"
    r = run("contour", str(cut_path), "--card", "unused.json", "--out", str(tmp_path / "m"))
    assert r.exit_code == 2 and "definitions" in r.output and len(r.output.strip().splitlines()) == 1


def test_ulog_ending_right_after_its_definitions_is_refused():
    """A ULog whose last whole message is the last definition has no data section: nothing was logged."""
    head = b"ULog\x01\x12\x35\x01" + bytes(8)
    info = struct.pack("<HB", 4, ord("I")) + b"abcd"
    cut = ulog_cut(head + info)
    assert cut is not None and cut.in_definitions and cut.file_bytes == 23


# ----------------------------------------------------------------------------- the framing
def _df_fmt(mtype, length, name):
    return b"\xa3\x95\x80" + bytes([mtype, length]) + name.ljust(4, b"\x00") + bytes(80)


def test_dataflash_framing_padding_bad_bytes_and_a_cut_header():
    fmt = _df_fmt(0x81, 6, b"TEST")
    msg = b"\xa3\x95\x81abc"
    assert len(fmt) == 89 and dataflash_cut(fmt + msg) is None
    # padding after the last message (flash pages, 0xFF) is no message: complete, as pymavlink reads it
    assert dataflash_cut(fmt + msg + b"\xff" * 200) is None
    # bad bytes between messages are skipped to the next message, as pymavlink does
    assert dataflash_cut(fmt + msg + b"\x00\x01\x02" + msg) is None
    cut = dataflash_cut(fmt + msg + b"\x00\x01\x02" + msg[:4])
    assert (cut.message_at, cut.message_end, cut.file_bytes) == (98, 104, 102)
    # cut inside a header: its signature bytes only
    for tail in (b"\xa3", b"\xa3\x95"):
        cut = dataflash_cut(fmt + msg + tail)
        assert cut is not None and cut.message_at == 95 and cut.message_end is None
    # formats only, then data: the definitions end at the first message of a logged type
    unit = _df_fmt(0x82, 5, b"UNIT")
    assert dataflash_cut(fmt + unit + msg + msg[:3]).in_definitions is False
    assert dataflash_cut(fmt + unit + b"\xa3\x95\x82ab" + msg[:3]).in_definitions is True   # a UNIT is no data
    assert dataflash_cut(fmt + unit[:40]).in_definitions is True


def test_ulog_framing_header_cut_and_appended_data():
    head = b"ULog\x01\x12\x35\x01" + bytes(8)
    sub = struct.pack("<HB", 2, ord("A")) + b"xy"
    data = struct.pack("<HB", 3, ord("D")) + b"abc"
    assert ulog_cut(head + sub + data) is None
    one = ulog_cut(head + sub + data[:1])              # one byte of the size: the message's end unknown
    assert (one.message_at, one.message_end) == (21, None)
    two = ulog_cut(head + sub + data[:2])              # the size: the end known
    assert (two.message_at, two.message_end) == (21, 27)
    # appended data (incompat flag bit 0, offsets in the flag-bits message): the message written over the
    # appended offset is left, as pyulog does, and the file is whole when the appended part ends whole
    flags = struct.pack("<HB", 40, ord("B"))
    body_len = 16 + 3 + 40 + 5 + 3                     # header, flag bits, subscription, 3 bytes of a message
    appended = body_len
    bits = flags + bytes(8) + bytes([1]) + bytes(7) + struct.pack("<3Q", appended, 0, 0)
    base = head + bits + sub + data[:3]
    assert len(base) == appended
    assert ulog_cut(base + data) is None
    cut = ulog_cut(base + data[:4])
    assert (cut.message_at, cut.message_end, cut.file_bytes) == (appended, appended + 6, appended + 4)


# ----------------------------------------------------------------------------- the faces
def test_map_of_a_cut_log_says_so_once_and_in_the_contours(tmp_path, omni_card):
    cut_path = _write_cut(VTOL, int(0.9 * VTOL.stat().st_size), tmp_path)
    out = tmp_path / "m"
    r = run("contour", str(cut_path), "--card", omni_card, "--out", str(out), "--resolution", "20", "--margin", "100")
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if CUT in ln]
    assert len(lines) == 1 and lines[0].startswith(f"warning: {cut_path}: the log ends mid-message at byte ")
    doc = json.loads((out / "contours.geojson").read_text())
    assert sum(CUT in w for w in doc["gisnoise"]["warnings"]) == 1
    # the uncut log: no such warning
    r = run("contour", str(VTOL), "--card", omni_card, "--out", str(tmp_path / "u"), "--resolution", "20", "--margin",
            "100")
    assert r.exit_code == 0 and CUT not in r.output
    doc = json.loads((tmp_path / "u" / "contours.geojson").read_text())
    assert not any(CUT in w for w in doc["gisnoise"]["warnings"])


def _campaign(tmp_path, log):
    root = tmp_path / "camp"
    (root / "flights").mkdir(parents=True)
    (root / "mics" / "m1").mkdir(parents=True)
    shutil.copy(log, root / "flights" / ("f1" + log.suffix))
    from datetime import datetime, timezone

    tr = read_flight(log, start_utc=0.0)   # t in unix seconds (GPS clock of the log)
    start = datetime.fromtimestamp(float(tr.t[0]) - 1.0, tz=timezone.utc).isoformat().replace("+00:00", "Z")
    lat, lon = float(tr.lat[0]), float(tr.lon[0])
    doc = {"schema": "gisnoise/campaign/1", "origin": {"lat": lat, "lon": lon, "h": float(tr.h.min())},
           "speed_of_sound_m_s": 340.0, "weather": {"temperature_c": 10.0},
           "vehicle": {"name": "v", "reference_power_w": 300.0},
           "microphones": [{"id": "m1", "lat": lat + 1e-4, "lon": lon, "h": float(tr.h.min()) + 1.5,
                            "mount": "free_field"}],
           "flights": [{"id": "f1", "start_utc": start}]}
    (root / "campaign.json").write_text(json.dumps(doc))
    t_r = np.arange(0.0, tr.duration_s + 2.0, 0.125)
    (root / "mics" / "m1" / "f1.csv").write_text("t,LA\n" + "".join(f"{t:.3f},60.0\n" for t in t_r))
    return root


def test_campaign_check_names_a_cut_log_without_failing(tmp_path):
    cut_path = _write_cut(VTOL, int(0.9 * VTOL.stat().st_size), tmp_path)
    r = run("campaign", "check", str(_campaign(tmp_path / "a", cut_path)))
    assert r.exit_code == 0, r.output
    lines = [ln for ln in r.stderr.splitlines() if CUT in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "f1.ulg: the log ends mid-message" in lines[0]
    r = run("campaign", "check", str(_campaign(tmp_path / "b", VTOL)))
    assert r.exit_code == 0 and CUT not in r.output


def test_route_comparison_names_a_cut_log(tmp_path, omni_card):
    import rasterio
    from affine import Affine
    from pyproj import CRS

    from gisnoise.exposure import read_population
    from gisnoise.planning import compare_routes

    cut_path = _write_cut(VTOL, int(0.9 * VTOL.stat().st_size), tmp_path)
    tr = _read(VTOL)
    tmerc = f"+proj=tmerc +lat_0={tr.lat[0]} +lon_0={tr.lon[0]} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
    with rasterio.open(tmp_path / "pop.tif", "w", driver="GTiff", width=20, height=20, count=1, dtype="float32",
                       crs=CRS.from_user_input(tmerc).to_wkt(), transform=Affine(10.0, 0, -100.0, 0, -10.0, 100.0)) as d:
        d.write(np.ones((20, 20), dtype=np.float32), 1)
    cmp = compare_routes([cut_path, VTOL], [omni_card], population=read_population(tmp_path / "pop.tif"),
                         names=["cut", "whole"], margin_m=100.0)
    named = [w for w in cmp.doc["warnings"] if CUT in w]
    assert len(named) == 1 and named[0].startswith(f"cut: {cut_path}: the log ends mid-message at byte ")


def test_diagnose_names_a_cut_log_before_it_diagnoses(tmp_path, omni_card):
    """The diagnosis reads the campaign as campaign check does and says a cut log once, first (whatever the
    diagnosis of this one-microphone campaign then finds); the uncut log's campaign gets no such line."""
    cut_path = _write_cut(VTOL, int(0.9 * VTOL.stat().st_size), tmp_path)
    r = run("diagnose", str(_campaign(tmp_path / "a", cut_path)), "--card", omni_card, "--out", str(tmp_path / "d"),
            "--no-report")
    lines = [ln for ln in r.stderr.splitlines() if CUT in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "f1.ulg: the log ends mid-message" in lines[0]
    assert r.stderr.splitlines()[0] == lines[0]
    r = run("diagnose", str(_campaign(tmp_path / "b", VTOL)), "--card", omni_card, "--out", str(tmp_path / "e"),
            "--no-report")
    assert CUT not in r.stderr


def test_fit_names_a_cut_log_before_it_fits(tmp_path):
    """``gisnoise fit`` reads the campaign as campaign check does and says a cut log once, first (whatever the fit
    of this one-microphone campaign then gives); the uncut log's campaign gets no such line."""
    cut_path = _write_cut(VTOL, int(0.9 * VTOL.stat().st_size), tmp_path)
    r = run("fit", str(_campaign(tmp_path / "a", cut_path)), "--phase", "hover", "--out", str(tmp_path / "a.json"))
    lines = [ln for ln in r.stderr.splitlines() if CUT in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "f1.ulg: the log ends mid-message" in lines[0]
    assert r.stderr.splitlines()[0] == lines[0]
    r = run("fit", str(_campaign(tmp_path / "b", VTOL)), "--phase", "hover", "--out", str(tmp_path / "b.json"))
    assert CUT not in r.stderr
