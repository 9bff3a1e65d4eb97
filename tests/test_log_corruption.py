"""Flight logs damaged inside (bytes zeroed or garbled mid-file): said in one line, garbage never mapped.

Expectations come from the formats' framing and from what the copies were given: the damaged bytes are
known (the test writes them), samples logged before them are the uncut file's (read as the file cut at
the damage, which the cut-log tests hold equal to the uncut file's), and no value the damage made reaches
the trajectory.  pyulog alone reads the message the damage begins in with its zeroed bytes, and a garbled
size running past the file's end makes it drop the rest of the flight without a flag; pymavlink reads the
damaged message's zeros too.
"""

import json
import struct

import numpy as np
import pytest

from gisnoise.flight import dataflash_damage, left_out_warning, read_flight, track_warning, ulog_damage

pyulog = pytest.importorskip("pyulog")
pytest.importorskip("pymavlink.DFReader")

from test_real_logs_maps import COPTER, N_SITE, QUAD, VTOL  # noqa: E402

CORRUPT = "the log is corrupt inside"


def _damage_of(path):
    return ulog_damage if path.suffix == ".ulg" else dataflash_damage


def _read(path):
    return read_flight(path, geoid_undulation_m=N_SITE)


def _write(path, raw, tmp_path, name):
    out = tmp_path / f"{path.stem}_{name}{path.suffix}"
    out.write_bytes(bytes(raw))
    return out


def _damaged(raw, at, span, mode):
    b = bytearray(raw)
    b[at:at + span] = bytes(span) if mode == "zero" else np.random.default_rng(at).integers(
        0, 256, span, dtype=np.uint8).tobytes()
    return bytes(b)


# ----------------------------------------------------------------------------- whole logs
@pytest.mark.parametrize("path", [VTOL, QUAD, COPTER], ids=lambda p: p.stem)
def test_whole_logs_have_no_damage_and_no_warning(path, capfd):
    assert _damage_of(path)(path.read_bytes()) is None
    tr = _read(path)
    # the one warning a whole log may carry: the quad's first hop, before its attitude is logged (test_log_left_out)
    assert "log_corrupt" not in tr.metadata and track_warning(tr) == left_out_warning(tr)
    assert (left_out_warning(tr) is None) == (path != QUAD)
    assert capfd.readouterr().out == ""


# ----------------------------------------------------------------------------- damaged copies
# the quad's attitude begins late and its flight is 10 samples long: its damage lies later
CASES = [(p, f, span, mode) for p in (VTOL, COPTER)
         for f, span, mode in ((0.3, 4096, "zero"), (0.45, 64, "rand"), (0.6, 4096, "rand"))] \
    + [(QUAD, f, span, mode) for f, span, mode in ((0.75, 4096, "zero"), (0.78, 64, "rand"), (0.85, 4096, "rand"))]


@pytest.mark.parametrize("path,fraction,span,mode", CASES, ids=lambda v: getattr(v, "stem", str(v)))
def test_damaged_log_warns_once_prints_nothing_and_keeps_the_samples_before(tmp_path, capfd, path, fraction, span,
                                                                           mode):
    raw = path.read_bytes()
    at = int(fraction * len(raw))
    bad = _write(path, _damaged(raw, at, span, mode), tmp_path, f"{mode}{span}")
    tr_full = _read(path)
    capfd.readouterr()
    tr = _read(bad)
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""                  # nothing on the user's stdout (nor stderr)
    # one warning naming the file; every damaged byte left out; the metadata is JSON
    warning = track_warning(tr)
    assert warning is not None and "\n" not in warning and warning.count(CORRUPT) == 1
    assert warning.startswith(f"{bad}: {CORRUPT}") and "are missing" in warning
    meta = json.loads(json.dumps(tr.metadata["log_corrupt"]))
    assert meta["file_bytes"] == len(raw)
    assert any(a <= at and at + span <= b for a, b in meta["spans"])
    assert "log_cut" not in tr.metadata
    # the samples logged before the damage: those of the file cut there, which are the whole file's
    tr_cut = _read(_write(path, raw[:at], tmp_path, "cut"))
    k = len(tr_cut) - 2                                     # the last ones interpolate towards the cut
    assert k >= 2
    for col in ("t", "lat", "lon", "roll", "pitch", "yaw"):
        np.testing.assert_array_equal(getattr(tr, col)[:k], getattr(tr_full, col)[:k], err_msg=col)
    # nothing outside the whole flight's positions
    for col in ("lat", "lon"):
        v, full = getattr(tr, col), getattr(tr_full, col)
        assert np.all((v >= full.min()) & (v <= full.max())), col


# ----------------------------------------------------------------------------- what the parsers alone do
def _ulog_messages(raw):
    """(offset, type, size) of the messages of a whole ULog, and its subscriptions {name: msg_id}."""
    o, out, subs = 16, [], {}
    while o + 3 <= len(raw):
        size, t = struct.unpack_from("<HB", raw, o)
        if t == ord("A"):
            subs[raw[o + 6:o + 3 + size].decode()] = struct.unpack_from("<H", raw, o + 4)[0]
        out.append((o, chr(t), size))
        o += 3 + size
    assert o == len(raw)
    return out, subs


def test_ulog_zeros_from_inside_a_gps_fix_reach_no_sample(tmp_path):
    """Zeros from a fix's last fields over the next message's header: the fix is left out."""
    raw = QUAD.read_bytes()
    msgs, subs = _ulog_messages(raw)
    gps = subs["vehicle_gps_position"]
    o, _, size = next(m for m in msgs[len(msgs) // 2:]
                      if m[1] == "D" and struct.unpack_from("<H", raw, m[0] + 3)[0] == gps)
    at = o + 3 + size - 24                                  # the fix's last fields and the next message's head
    bad = _write(QUAD, _damaged(raw, at, 64, "zero"), tmp_path, "gpszero")
    # pyulog alone: the fix with its last fields zeroed is read, as a row the whole file does not hold
    def fixes(p):
        g = next(d.data for d in pyulog.ULog(str(p)).data_list if d.name == "vehicle_gps_position")
        return {tuple(float(g[k][i]) for k in sorted(g)) for i in range(len(g["timestamp"]))}
    assert fixes(bad) - fixes(QUAD)
    tr, tr_full = _read(bad), _read(QUAD)
    assert np.all((tr.lat >= tr_full.lat.min()) & (tr.lat <= tr_full.lat.max()))
    assert track_warning(tr).startswith(f"{bad}: {CORRUPT}")


def test_ulog_garbled_size_past_the_end_loses_no_flight(tmp_path):
    raw = VTOL.read_bytes()
    msgs, _ = _ulog_messages(raw)
    o = next(m[0] for m in msgs if m[0] > 0.95 * len(raw) and m[1] == "D")
    b = bytearray(raw)
    b[o:o + 3] = struct.pack("<HB", 0xC5DB, 0xA6)           # a size beyond the file's end, an unknown type
    bad = _write(VTOL, b, tmp_path, "size")
    # pyulog alone: reads it as a cut, drops the rest, says nothing
    u = pyulog.ULog(str(bad))
    assert not u.file_corruption
    full = pyulog.ULog(str(VTOL))
    n_bad = sum(len(d.data["timestamp"]) for d in u.data_list)
    assert n_bad < sum(len(d.data["timestamp"]) for d in full.data_list)
    tr, tr_full = _read(bad), _read(VTOL)
    assert tr.t[-1] == tr_full.t[-1]                       # the flight after it is read
    warning = track_warning(tr)
    assert warning.startswith(f"{bad}: {CORRUPT}") and tr.metadata["log_corrupt"]["spans"][0][0] <= o


def test_dataflash_zeros_from_inside_a_gps_message_reach_no_sample(tmp_path):
    raw = COPTER.read_bytes()
    i = raw.index(b"GPS\x00", 0)                            # the GPS format: its type byte 5 bytes before the name
    gps_type = raw[i - 2]
    o = raw.index(b"\xa3\x95" + bytes([gps_type]), int(0.5 * len(raw)))
    bad = _write(COPTER, _damaged(raw, o + 10, 64, "zero"), tmp_path, "gpszero")
    tr, tr_full = _read(bad), _read(COPTER)
    assert np.all((tr.lat >= tr_full.lat.min()) & (tr.lat <= tr_full.lat.max()))
    assert np.all((tr.lon >= tr_full.lon.min()) & (tr.lon <= tr_full.lon.max()))
    assert track_warning(tr).startswith(f"{bad}: {CORRUPT}")
