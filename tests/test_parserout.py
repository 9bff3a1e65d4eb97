"""What log parsers print stays off stdout, and only the reading thread's output is held back.

The service reads flight logs in worker threads: while one thread reads a log whose parser prints,
another thread's output must still reach stdout (a process-wide redirection would swallow it).
"""

import threading

import pytest

from gisnoise.flight import read_flight
from gisnoise.flight.parserout import captured_stdout

pyulog = pytest.importorskip("pyulog")

from test_log_corruption import _damaged, _write  # noqa: E402
from test_real_logs_maps import VTOL  # noqa: E402


def test_a_capture_holds_its_own_threads_output_only(capsys):
    inside, printed = threading.Event(), threading.Event()
    held = []

    def reader():
        with captured_stdout() as said:
            inside.set()
            printed.wait(10)
            print("parser: corrupt data")
        held.append(said.getvalue())

    t = threading.Thread(target=reader)
    t.start()
    inside.wait(10)
    print("another thread's line")     # while the reader captures
    printed.set()
    t.join(10)
    assert capsys.readouterr().out == "another thread's line\n"
    assert held == ["parser: corrupt data\n"]


def test_nested_captures_and_the_stream_restored(capsys):
    import sys
    before = sys.stdout
    with captured_stdout() as outer:
        print("a")
        with captured_stdout() as inner:
            print("b")
        print("c")
    assert sys.stdout is before
    assert (outer.getvalue(), inner.getvalue()) == ("a\nc\n", "b\n")
    print("after")
    assert capsys.readouterr().out == "after\n"


def test_reading_a_damaged_ulog_in_a_thread_keeps_other_threads_output(tmp_path, capsys, monkeypatch):
    """pyulog prints on this copy (64 garbled bytes at 45 %); a line printed meanwhile by the main thread is
    on stdout, pyulog's words are not."""
    raw = VTOL.read_bytes()
    bad = _write(VTOL, _damaged(raw, int(0.45 * len(raw)), 64, "rand"), tmp_path, "rand64")
    real = pyulog.ULog
    inside, printed = threading.Event(), threading.Event()

    def ulog_after_the_other_thread_printed(*a, **k):
        inside.set()
        printed.wait(10)
        return real(*a, **k)

    monkeypatch.setattr(pyulog, "ULog", ulog_after_the_other_thread_printed)
    out = {}
    t = threading.Thread(target=lambda: out.setdefault("traj", read_flight(bad, geoid_undulation_m=0.0)))
    t.start()
    inside.wait(10)
    print("the service's own line")
    printed.set()
    t.join(60)
    assert capsys.readouterr().out == "the service's own line\n"
    assert "log_corrupt" in out["traj"].metadata


def test_a_bin_file_without_a_dataflash_header_is_refused_and_prints_nothing(tmp_path, capfd):
    """Six zero bytes named .BIN: pymavlink's indexer (compiled, its prints beyond Python's reach) printed 'bad header
    0x0000 at N' for every byte on the process's stdout (C's buffer, flushed at exit: seen in the service's log) and
    the refusal said "message 'GPS' missing"; the file holds no message header (A3 95) at all, so it is not a
    DataFlash log and is refused before the parser sees it."""
    from gisnoise.errors import TrajectoryError

    bad = tmp_path / "x.BIN"
    bad.write_bytes(bytes(6))
    with pytest.raises(TrajectoryError, match=r"x.BIN: not a DataFlash log \(no message header") as e:
        read_flight(bad)
    assert e.value.field == "path"
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""
