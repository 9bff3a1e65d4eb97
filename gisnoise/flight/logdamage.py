"""Logs damaged inside: bytes zeroed or garbled in the middle of a PX4 ULog or ArduPilot DataFlash file.

A file can be damaged inside without being cut (a bad SD card sector, a broken copy).  Neither format
carries checksums, and the parsers only half say it:

pyulog
    meets a header it takes as corrupt (type 0, size 0 or above 10 000 bytes and an unknown type),
    steps one byte and jumps to the next sync sequence (``S`` messages, about one a second in PX4 logs),
    losing the whole stretch between; sets ``file_corruption`` and may ``print`` to stdout (a message
    id without subscription).  A garbled header whose size runs past the file's end is read as a cut:
    the rest of the file is dropped without a flag.  The message the damage begins in is read with its
    damaged bytes: a sample of zeros or garbage reaches the data.
pymavlink
    skips bytes that do not start ``0xA3 0x95`` and a known type, without a flag (its indexer writes a
    line per skipped byte to the process's standard error); the message the damage begins in is read
    with its damaged bytes too.

So the framing is walked here, stricter than the parsers: a ULog header counts when its type is known
and, for logged data (``D``), its message id was subscribed (``A``) and its size is that id's size; a
DataFlash header when it is ``0xA3 0x95`` with a type a format (``FMT``) defined.  Where the walk meets
a header that does not count, it resumes at the first offset where a chain of headers counts again;
the bytes left out start at the message before (its payload holds the damage's first bytes) and end
there.  :func:`ulog_damage` and :func:`dataflash_damage` give the :class:`LogDamage` of a file's
bytes; :func:`without_damage` gives the bytes the parsers then read: every damaged byte left out, so
no garbage value reaches a trajectory.  The readers record it in the trajectory's metadata
(``log_corrupt``), from which :func:`log_damage_warning` makes the one-line warning.

Damage lying wholly inside one message's payload leaves the framing whole: no framing walk can tell
it from data.  A ULog with appended data (the flag bits' ``DATA_APPENDED``) is not walked.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["LogDamage", "ulog_damage", "dataflash_damage", "without_damage", "record_damage", "log_damage_warning"]

_ULOG_MAGIC = b"ULog\x01\x12\x35"
_SYNC = b"\x2f\x73\x13\x20\x25\x0c\xbb\x12"
_D, _A, _F, _S, _O = (ord(c) for c in "DAFSO")
_ULOG_KNOWN = frozenset(b"FIMPQARLCSOD")       # the message types a ULog holds after its flag bits
_ULOG_MIN_SIZE = {ord("I"): 2, ord("M"): 3, ord("P"): 2, ord("Q"): 3, ord("A"): 4, ord("R"): 2, ord("L"): 9,
                  ord("C"): 11, ord("F"): 3}
_CHAIN = 4                                      # headers that must count in a row where the walk resumes
_DF_FMT, _DF_FMT_LEN = 0x80, 89


@dataclass(frozen=True)
class LogDamage:
    """The damaged stretches of a log file, left out of what the parser reads.

    Attributes
    ----------
    file_bytes : int
        The file's size, bytes.
    spans : tuple of (int, int)
        The stretches left out, ``[start, end)`` byte offsets, in file order.
    times_s : tuple of (float or None, float or None)
        Per stretch, the log's clock (s since boot) of the last whole message before it and of the first
        after it; None where no timed message is there.
    """

    file_bytes: int
    spans: tuple[tuple[int, int], ...]
    times_s: tuple[tuple[float | None, float | None], ...]

    @property
    def skipped_bytes(self) -> int:
        """The bytes left out, in all."""
        return sum(b - a for a, b in self.spans)

    def metadata(self) -> dict[str, Any]:
        """The trajectory's ``log_corrupt`` metadata (JSON-serialisable)."""
        return {"file_bytes": self.file_bytes, "skipped_bytes": self.skipped_bytes,
                "spans": [[a, b] for a, b in self.spans], "times_s": [list(t) for t in self.times_s]}


def without_damage(data: bytes, damage: LogDamage) -> bytes:
    """``data`` with the damaged spans left out.

    Examples
    --------
    >>> without_damage(b"abcdefgh", LogDamage(8, ((1, 3), (5, 6)), ((None, None), (None, None))))
    b'adegh'
    """
    parts, o = [], 0
    for a, b in damage.spans:
        parts.append(data[o:a])
        o = b
    parts.append(data[o:])
    return b"".join(parts)


def _text(b: bytes) -> bool:
    """Printable ASCII, not empty."""
    return bool(b) and all(32 <= c < 127 for c in b)


def _plausible(data: bytes, o: int, t: int, size: int) -> bool:
    """The payload of a ULog ``I``, ``M``, ``P``, ``Q`` (a key ``type name``), ``L``, ``C`` (text) or ``R``
    message looks like one."""
    if t == ord("R"):
        return size == 2
    if t in b"IP" or t in b"MQ":
        k = o + 3 + (t in b"MQ")
        key_len = data[k]
        key = data[k + 1:k + 1 + key_len]
        return 0 < key_len < size - (t in b"MQ") and b" " in key and _text(key)
    head = 9 if t == ord("L") else 11                 # level, (tag,) timestamp
    return _text(data[o + 3 + head:o + 3 + size].rstrip(b"\x00")[:64])


def _damage(n: int, spans: list[tuple[int, int]], times: list[tuple[float | None, float | None]]) -> LogDamage | None:
    """The :class:`LogDamage` of the spans found, spans that touch joined; None when there are none."""
    if not spans:
        return None
    out, out_t = [spans[0]], [times[0]]
    for (a, b), t in zip(spans[1:], times[1:], strict=True):
        if a <= out[-1][1]:
            out[-1], out_t[-1] = (out[-1][0], b), (out_t[-1][0], t[1])
        else:
            out.append((a, b))
            out_t.append(t)
    return LogDamage(n, tuple(out), tuple(out_t))


# ----------------------------------------------------------------------------- ULog
class _ULogWalk:
    """The state of a ULog walk: the subscriptions, their sizes, which formats lead with the timestamp."""

    def __init__(self, data: bytes) -> None:
        self.data, self.n = data, len(data)
        self.timed_formats: dict[bytes, bool] = {}
        self.subs: dict[int, bool] = {}            # message id -> its format leads with uint64_t timestamp
        self.sizes: dict[int, int] = {}            # message id -> size of its D messages

    def end(self, o: int, learn: bool, pending: set[int] | None = None) -> int:
        """The end of the message at ``o`` when its header counts, else -1.

        ``learn`` (the walk itself, not a look ahead) takes in the definitions and each id's size, and lets a
        header whose contents say little (an id without subscription; ``L``, ``C``, ``R``) count only when a
        chain of headers that count follows it.  ``pending`` holds the ids a
        look ahead has seen subscribed."""
        data, n = self.data, self.n
        if o + 3 > n:
            return -1
        size = data[o] | (data[o + 1] << 8)
        t = data[o + 2]
        end = o + 3 + size
        if t == _D:
            if size < 2:
                return -1
            if o + 5 > n:
                return end                    # cut inside the message id: a cut
            mid = data[o + 3] | (data[o + 4] << 8)
            known = self.sizes.get(mid)
            if known is not None:
                return end if size == known else -1
            if mid not in self.subs and (pending is None or mid not in pending) \
                    and not (learn and self.resumes(end)):
                return -1                    # an id whose subscription the damage took is read by its size
            if learn:
                self.sizes[mid] = size
            return end
        if t not in _ULOG_KNOWN or size < _ULOG_MIN_SIZE.get(t, 1) or size > 10000 and not learn:
            return -1
        if t == _S:
            return end if size == 8 and data[o + 3:o + 11] == _SYNC[:min(8, n - o - 3)] else -1
        if t == _O:
            return end if size == 2 else -1
        if end > n:
            return end if size <= 10000 else -1     # a cut, of a size pyulog would read
        if t == _F:
            name, colon, fields = data[o + 3:end].partition(b":")
            if not colon or not _text(name):
                return -1
            if learn:
                self.timed_formats[name] = fields.startswith(b"uint64_t timestamp;")
            return end
        if t == _A:
            name = data[o + 6:end].rstrip(b"\x00")
            if name not in self.timed_formats:
                return -1
            mid = data[o + 4] | (data[o + 5] << 8)
            if learn:
                self.subs[mid] = self.timed_formats[name]
            elif pending is not None:
                pending.add(mid)
            return end
        if not _plausible(data, o, t, size) or learn and t in b"LCR" and not self.resumes(end):
            return -1                         # a key says more than a text: only texts need the chain
        return end

    def resumes(self, o: int) -> bool:
        """A chain of headers counts from ``o`` (or runs to the file's end)."""
        pending: set[int] = set()
        for _ in range(_CHAIN):
            if o == self.n:
                return True
            e = self.end(o, False, pending)
            if e < 0 or e > self.n:
                return False
            o = e
        return True

    def next_time(self, o: int) -> float | None:
        """The timestamp (s) of the first timed data message at or after ``o`` (within 64 messages)."""
        for _ in range(64):
            e = self.end(o, False)
            if e < 0 or e > self.n:
                return None
            t = self.time(o)
            if t is not None:
                return t
            o = e
        return None

    def time(self, o: int) -> float | None:
        """The timestamp (s) of the data message at ``o``, when its format leads with it."""
        data = self.data
        if o + 13 <= self.n and data[o + 2] == _D and self.subs.get(data[o + 3] | (data[o + 4] << 8)):
            return float(struct.unpack_from("<Q", data, o + 5)[0]) / 1e6
        return None


def ulog_damage(data: bytes) -> LogDamage | None:
    """The damaged stretches of a PX4 ULog file's bytes, or None when its framing is whole.

    None also for no ULog, and for a ULog with appended data (see the module docstring).  A message that
    runs past the file's end is a cut (:func:`gisnoise.flight.logcut.ulog_cut`), not damage.

    Examples
    --------
    >>> head = b"ULog\\x01\\x12\\x35\\x01" + bytes(8)
    >>> fmt = b"t:uint64_t timestamp;float x;"
    >>> defs = struct.pack("<HB", len(fmt), ord("F")) + fmt + struct.pack("<HBBH", 4, ord("A"), 0, 7) + b"t"
    >>> msgs = [struct.pack("<HBHQf", 14, ord("D"), 7, k * 1_000_000, 2.5) for k in (1, 2, 3, 4)]
    >>> log = head + defs + b"".join(msgs)             # the data messages start at 55, 72, 89, 106
    >>> ulog_damage(log) is None
    True
    >>> bad = log[:80] + bytes(10) + log[90:]          # zeros over the second message's end and the third's head
    >>> d = ulog_damage(bad)                           # the second and third left out, the fourth read
    >>> d.spans, d.times_s
    (((72, 106),), ((1.0, 4.0),))
    """
    n = len(data)
    if n < 16 or data[:7] != _ULOG_MAGIC:
        return None
    if n >= 16 + 3 + 40 and data[18] == ord("B") and data[19 + 8] & 1:
        return None                                   # appended data: not walked
    w = _ULogWalk(data)
    spans: list[tuple[int, int]] = []
    times: list[tuple[float | None, float | None]] = []
    o, prev = 16, -1
    t_last: float | None = None            # the time of the last timed data message taken
    t_prev: float | None = None            # t_last before the message at prev was taken
    if n >= 19 and data[18] == ord("B"):
        o = 19 + (data[16] | (data[17] << 8))
    while o + 3 <= n:                                  # a header cut at the end is a cut
        end = w.end(o, True)
        if end >= 0:
            if end > n:
                break                                 # a cut: ulog_cut says it
            t_prev = t_last
            if data[o + 2] == _D:
                t = w.time(o)
                t_last = t if t is not None else t_last
            prev, o = o, end
            continue
        dropped = prev >= 0 and data[prev + 2] == _D     # a data payload may hold the damage's start
        q = o + 1
        while q + 3 <= n and not (data[q + 2] in _ULOG_KNOWN and w.resumes(q)):
            q += 1
        q = q if q + 3 <= n else n
        spans.append((prev if dropped else o, q))
        times.append((t_prev if dropped else t_last, w.next_time(q)))
        prev, o = -1, q
    return _damage(n, spans, times)


# ----------------------------------------------------------------------------- DataFlash
def dataflash_damage(data: bytes) -> LogDamage | None:
    """The damaged stretches of an ArduPilot DataFlash file's bytes, or None when its framing is whole.

    Bytes after the last message that start no message are padding, not damage; a message that runs past
    the file's end is a cut (:func:`gisnoise.flight.logcut.dataflash_cut`).

    Examples
    --------
    >>> fmt = b"\\xa3\\x95\\x80" + bytes([0x81, 5]) + b"TEST" + bytes(80)   # FMT: type 0x81 is 5 bytes long
    >>> msg = b"\\xa3\\x95\\x81ab"
    >>> dataflash_damage(fmt + msg * 4) is None
    True
    >>> log = fmt + msg + msg[:3] + bytes(4) + msg + msg + msg    # at 94 a message whose last 2 bytes are zeroed
    >>> dataflash_damage(log).spans                             # it and the 2 bytes after it left out
    ((94, 101),)
    """
    n = len(data)
    lengths = [0] * 256
    lengths[_DF_FMT] = _DF_FMT_LEN
    timed = [0] * 256                      # 1: leads with TimeUS (uint64, us), 2: with TimeMS (uint32, ms)

    def counts(o: int) -> int:
        """The end of the message at ``o`` when its header counts, else -1."""
        if o + 3 > n or data[o] != 0xA3 or data[o + 1] != 0x95:
            return -1
        size = lengths[data[o + 2]]
        return o + size if size else -1

    def resumes(o: int) -> bool:
        for _ in range(_CHAIN):
            e = counts(o)
            if e < 0:
                return False
            if e >= n - 2:
                return True
            o = e
        return True

    def time(o: int) -> float | None:
        kind = timed[data[o + 2]]
        if kind == 1 and o + 11 <= n:
            return float(struct.unpack_from("<Q", data, o + 3)[0]) / 1e6
        if kind == 2 and o + 7 <= n:
            return float(struct.unpack_from("<I", data, o + 3)[0]) / 1e3
        return None

    spans: list[tuple[int, int]] = []
    times: list[tuple[float | None, float | None]] = []
    o, prev = 0, -1
    while o + 3 <= n:
        end = counts(o)
        if end >= 0:
            if end > n:
                break                                  # a cut: dataflash_cut says it
            if data[o + 2] == _DF_FMT:
                t, size = data[o + 3], data[o + 4]
                lengths[t] = size
                fmt_chars, cols = data[o + 9:o + 25], data[o + 25:o + 89]
                timed[t] = 1 if fmt_chars[:1] == b"Q" and cols.startswith(b"TimeUS") else \
                    2 if fmt_chars[:1] == b"I" and cols.startswith(b"TimeMS") else 0
            prev, o = o, end
            continue
        q = o + 1
        while q + 3 <= n and not resumes(q):
            q = data.find(b"\xa3\x95", q + 1)
            if q < 0:
                q = n
        if q + 3 > n:
            break                                      # nothing after: padding at the end
        start = prev if prev >= 0 and data[prev + 2] != _DF_FMT else o
        spans.append((start, q))
        times.append((time(prev) if prev >= 0 else None, time(q)))
        prev, o = -1, q
    return _damage(n, spans, times)


# ----------------------------------------------------------------------------- the warning
def record_damage(traj: Any, damage: LogDamage | None, file_bytes: int, parser_said: str | None) -> None:
    """Record in ``traj.metadata["log_corrupt"]`` the damage left out of its log and the first line the
    parser said about corrupt data (None: nothing); nothing when there is neither."""
    if damage is None and parser_said is None:
        return
    meta = damage.metadata() if damage is not None else {"file_bytes": file_bytes, "skipped_bytes": 0, "spans": [],
                                                          "times_s": []}
    if parser_said is not None:
        meta["parser_said"] = parser_said
    traj.metadata["log_corrupt"] = meta


def log_damage_warning(traj: Any) -> str | None:
    """The one-line warning for a trajectory read from a log damaged inside (its
    ``metadata["log_corrupt"]``), or None."""
    bad = traj.metadata.get("log_corrupt") if isinstance(traj.metadata, Mapping) else None
    if not bad:
        return None
    spans = bad.get("spans") or []
    if not spans:
        return (f"{traj.source}: the log is corrupt inside ({bad.get('parser_said', 'the parser says so')}): "
                "samples may be missing")
    a, b = spans[0]
    more = f", {len(spans) - 1} more damaged stretches, {bad['skipped_bytes']} bytes in all," if len(spans) > 1 \
        else ""
    t0, t1 = bad["times_s"][0][0], bad["times_s"][-1][1]
    when = f"between {t0:.2f} s and {t1:.2f} s after boot" if t0 is not None and t1 is not None else \
        f"from {t0:.2f} s after boot on" if t0 is not None else "there"
    return (f"{traj.source}: the log is corrupt inside ({b - a} damaged bytes at byte {a} of {bad['file_bytes']} "
            f"left out{more}): the samples logged {when} are missing")
