"""Logs cut short: where a PX4 ULog or ArduPilot DataFlash file ends inside a message.

Real logs get cut: the battery dies, the SD card fills, a download stops.  Neither pyulog nor
pymavlink says so: both read up to the last complete message and stop without a word (pyulog
sets no ``file_corruption`` flag for a cut in the data, pymavlink returns no more messages), so
a cut log would be mapped as if the flight ended there.  The framing of both formats tells:

ULog
    a 16-byte file header, then messages of ``uint16 size, uint8 type`` and ``size`` bytes.
    The messages are walked from byte 16 (jumping to the appended-data offsets of the flag-bits
    message, as pyulog does); a complete file ends exactly at the last message's end.  The
    definitions (formats, info, parameters) end at the first subscription or logged string
    (``A``, ``L``, ``C``).  A header pyulog would take as corrupt (an unknown type with size 0,
    type 0 or size above 10 000 bytes) loses the framing: then no claim is made.
DataFlash
    messages of ``0xA3 0x95 type`` and the length the format (``FMT``) of that type states
    (``FMT`` itself: 89 bytes).  Bytes that do not start a known message are skipped to the next
    one, as pymavlink does; a complete file ends at a message's end (or in bytes that start no
    message: padding).  The definitions are the leading format messages (``FMT``, ``FMTU``,
    ``UNIT``, ``MULT``).

:func:`ulog_cut` and :func:`dataflash_cut` give the :class:`LogCut` of a file's bytes, or None
when it ends at a message boundary.  The readers refuse a file cut inside its definitions
(:func:`refuse_cut_definitions`), name the cut in any other error, and record it in the
trajectory's metadata (``log_cut``), from which :func:`cut_warning` makes the one-line warning
that maps and ``gisnoise campaign check`` show (with a log damaged inside and position glitches:
:func:`gisnoise.flight.readnotes.track_warning`).
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from gisnoise.errors import GisnoiseError, TrajectoryError
from gisnoise.flight.logdamage import LogDamage, without_damage

__all__ = ["LogCut", "ulog_cut", "dataflash_cut", "refuse_cut_definitions", "cut_error", "read_cut", "framing",
           "cut_warning"]

_ULOG_MAGIC = b"ULog\x01\x12\x35"
_ULOG_TYPES = frozenset(b"BFIMPQARDLCSO")      # the message types of the ULog specification
_ULOG_DATA_START = frozenset(b"ALC")         # pyulog's end of the definitions section
_DF_HEAD = b"\xa3\x95"
_DF_FMT, _DF_FMT_LEN = 0x80, 89
_DF_FORMAT_NAMES = (b"FMT", b"FMTU", b"UNIT", b"MULT")


@dataclass(frozen=True)
class LogCut:
    """Where a log file ends inside a message.

    Attributes
    ----------
    file_bytes : int
        The file's size, bytes: the byte it ends at.
    message_at : int
        Offset of the message it ends in, bytes; ``file_bytes`` for a ULog that ends at a message boundary
        before its data section begins (``in_definitions``).
    message_end : int or None
        Where that message would end, bytes (its declared size); None when the file ends inside the
        message's header, before its size or type.
    in_definitions : bool
        The file ends before any logged data (inside the formats, info and parameters).
    """

    file_bytes: int
    message_at: int
    message_end: int | None
    in_definitions: bool

    def describe(self) -> str:
        """The cut in words: ``ends mid-message at byte N of M``."""
        if self.message_end is None:
            return f"ends at byte {self.file_bytes} inside the header of the message at byte {self.message_at}"
        return f"ends mid-message at byte {self.file_bytes} of {self.message_end}"

    def moved(self, by: int) -> LogCut:
        """The cut found in bytes ``by`` fewer than the file's (damage left out before it,
        :mod:`gisnoise.flight.logdamage`), in the file's offsets."""
        return LogCut(self.file_bytes + by, self.message_at + by,
                      None if self.message_end is None else self.message_end + by, self.in_definitions)

    def metadata(self, t_last_s: float) -> dict[str, Any]:
        """The trajectory's ``log_cut`` metadata; ``t_last_s`` is its last sample's time, s."""
        return {"file_bytes": self.file_bytes, "message_at_byte": self.message_at,
                "message_end_byte": self.message_end, "t_last_s": float(t_last_s)}


def ulog_cut(data: bytes) -> LogCut | None:
    """The cut of a PX4 ULog file's bytes, or None when its last message ends at the file's end.

    None also when the file is no ULog (too short or no magic: pyulog refuses it) or when a corrupt
    header loses the framing (see the module docstring).

    Examples
    --------
    >>> head = b"ULog\\x01\\x12\\x35\\x01" + bytes(8)
    >>> info = struct.pack("<HB", 4, ord("I")) + b"abcd"          # a 7-byte definition
    >>> sub = struct.pack("<HB", 2, ord("A")) + b"xy"              # the data section begins
    >>> ulog_cut(head + info + sub) is None
    True
    >>> ulog_cut(head + info + sub[:4])
    LogCut(file_bytes=27, message_at=23, message_end=28, in_definitions=False)
    >>> ulog_cut(head + info[:5]).in_definitions
    True
    """
    n = len(data)
    if n < 16 or data[:7] != _ULOG_MAGIC:
        return None
    o = 16
    while o + 3 <= n:                    # the common case first: every message's size leads exactly to the end
        o += 3 + (data[o] | (data[o + 1] << 8))
    if o == n and n > 16 and not (data[18] == ord("B") and n >= 16 + 3 + 40 and data[19 + 8] & 1):
        o = 16
        while data[o + 2] not in _ULOG_DATA_START:
            o += 3 + (data[o] | (data[o + 1] << 8))
            if o + 3 > n:
                return LogCut(n, n, n, True)     # no data section
        return None
    return _ulog_walk(data, n)


def _ulog_walk(data: bytes, n: int) -> LogCut | None:
    """:func:`ulog_cut` message by message: the definitions, the appended data, corrupt headers."""
    appended: list[int] = []
    if n >= 16 + 3 + 40 and data[18] == ord("B"):
        size = data[16] | (data[17] << 8)
        if size >= 40 and 19 + size <= n and data[19 + 8] & 1:     # incompat flag DATA_APPENDED
            appended = sorted(x for x in struct.unpack_from("<3Q", data, 19 + 16) if x > 0)
    o = 16
    while True:   # the definitions
        if o + 3 > n:
            return _ulog_end(data, o, n, True)
        t = data[o + 2]
        if t in _ULOG_DATA_START:
            break
        size = data[o] | (data[o + 1] << 8)
        if _ulog_corrupt(t, size):
            return None
        if o + 3 + size > n:
            return LogCut(n, o, o + 3 + size, True)
        o += 3 + size
    for bound in appended + [n]:
        limit = min(bound, n)
        while o + 3 <= limit:
            size = data[o] | (data[o + 1] << 8)
            end = o + 3 + size
            if end > limit:
                break
            if (size == 0 or size > 10000 or data[o + 2] == 0) and _ulog_corrupt(data[o + 2], size):
                return None
            o = end
        if bound >= n:
            break
        o = max(o, bound)       # pyulog seeks to the appended data, leaving a message written over it
    return _ulog_end(data, o, n, False)


def _ulog_corrupt(msg_type: int, size: int) -> bool:
    """pyulog's test of a corrupt header: an unknown type with size 0, type 0 or more than 10 000 bytes."""
    return msg_type not in _ULOG_TYPES and (msg_type == 0 or size == 0 or size > 10000)


def _ulog_end(data: bytes, o: int, n: int, in_definitions: bool) -> LogCut | None:
    if o == n:
        # ends at a message boundary: complete, unless the data section never began
        return LogCut(n, n, n, True) if in_definitions else None
    end = o + 3 + (data[o] | (data[o + 1] << 8)) if o + 2 <= n else None
    return LogCut(n, o, end, in_definitions)


def dataflash_cut(data: bytes) -> LogCut | None:
    """The cut of an ArduPilot DataFlash file's bytes, or None when it ends at a message's end.

    Examples
    --------
    >>> fmt = b"\\xa3\\x95\\x80" + bytes([0x81, 5]) + b"TEST" + bytes(80)   # FMT: type 0x81 is 5 bytes long
    >>> msg = b"\\xa3\\x95\\x81ab"
    >>> dataflash_cut(fmt + msg + msg) is None
    True
    >>> dataflash_cut(fmt + msg + msg[:4])
    LogCut(file_bytes=98, message_at=94, message_end=99, in_definitions=False)
    >>> dataflash_cut(fmt[:50]).in_definitions
    True
    """
    n = len(data)
    lengths = [0] * 256
    lengths[_DF_FMT] = _DF_FMT_LEN
    formats = {_DF_FMT}
    in_definitions = True
    o = 0
    while o + 3 <= n:
        t = data[o + 2]
        size = lengths[t]
        if data[o] != 0xA3 or data[o + 1] != 0x95 or not size:
            o = _df_next(data, o + 1, lengths)      # pymavlink skips to the next known message
            continue
        if o + size > n:
            return LogCut(n, o, o + size, in_definitions)
        if t == _DF_FMT:
            lengths[data[o + 3]] = data[o + 4]
            if data[o + 5:o + 9].rstrip(b"\x00") in _DF_FORMAT_NAMES:
                formats.add(data[o + 3])
        elif in_definitions and t not in formats:
            in_definitions = False
        o += size
    if o == n or not _DF_HEAD.startswith(data[o:]):
        return None        # the last message ends at the file's end, or padding follows it
    return LogCut(n, o, None, in_definitions)


def _df_next(data: bytes, o: int, lengths: list[int]) -> int:
    """The offset of the next DataFlash header of a known type at or after ``o``; a header cut at the file's
    end counts (its type is unknown); past the end when none follows."""
    n = len(data)
    while True:
        o = data.find(_DF_HEAD, o)
        if o < 0:
            return n - 1 if data[-1:] == _DF_HEAD[:1] else n
        if o + 2 >= n or lengths[data[o + 2]]:
            return o
        o += 1


def refuse_cut_definitions(src: str, cut: LogCut | None, definitions: str) -> None:
    """Refuse a log cut inside its definitions (before any logged data) in one line naming the file;
    ``definitions`` names what they hold."""
    if cut is not None and cut.in_definitions:
        where = f"ends at byte {cut.file_bytes}" if cut.message_at == cut.file_bytes else cut.describe()
        raise TrajectoryError(f"{src}: the log {where}, in its definitions ({definitions}), before any logged "
                              "data: the file was cut", field="path")


def cut_error(src: str, exc: GisnoiseError, cut: LogCut) -> GisnoiseError:
    """The reader's error ``exc`` on a cut log, with the cut named (same class and field)."""
    return type(exc)(f"{exc} (the log {cut.describe()}: the file was cut)", field=exc.field)


def read_cut(src: str, cut: LogCut | None, read: Callable[[], Any]) -> Any:
    """``read()`` (a reader's trajectory) with the cut of its file: named in the reader's errors
    (:func:`cut_error`) and recorded in the trajectory's metadata (``log_cut``)."""
    try:
        traj = read()
    except GisnoiseError as exc:
        if cut is None:
            raise
        raise cut_error(src, exc, cut) from None
    if cut is not None:
        traj.metadata["log_cut"] = cut.metadata(float(traj.t[-1]))
    return traj


def framing(data: bytes, damage_of: Callable[[bytes], LogDamage | None],
            cut_of: Callable[[bytes], LogCut | None]) -> tuple[bytes, LogDamage | None, LogCut | None]:
    """A log's bytes as its parser is to read them, with what their framing holds: the bytes without the damage
    ``damage_of`` finds (:func:`~gisnoise.flight.logdamage.without_damage`), that damage, and the cut ``cut_of``
    finds in them, in the file's offsets (:meth:`LogCut.moved`)."""
    damage = damage_of(data)
    if damage is None:
        return data, None, cut_of(data)
    clean = without_damage(data, damage)
    cut = cut_of(clean)
    return clean, damage, None if cut is None else cut.moved(damage.skipped_bytes)


def cut_warning(traj: Any) -> str | None:
    """The one-line warning for a trajectory read from a cut log (its ``metadata["log_cut"]``), or None."""
    cut = traj.metadata.get("log_cut") if isinstance(traj.metadata, Mapping) else None
    if not cut:
        return None
    c = LogCut(cut["file_bytes"], cut["message_at_byte"], cut["message_end_byte"], False)
    return (f"{traj.source}: the log {c.describe()} (the file was cut: the flight may go on beyond "
            f"t = {cut['t_last_s']:.1f} s)")
