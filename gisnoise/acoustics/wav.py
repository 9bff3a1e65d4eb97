"""WAV audio: mono recordings in volts, their calibration to pascals, and writing sound pressure as WAV.

Stored values are volts: float WAV as is, integer PCM scaled so that full scale is 1 V.
A recording is refused, in one line naming the file and the times, where its samples are not sound:
clipped (two samples in a row at digital full scale) or dropped out (:data:`DROPOUT_S` or more of one
exact value, digital zeros among them); the band levels of a WAV file can leave such stretches out
instead (``excluded_s`` of :func:`gisnoise.acoustics.wav_band_levels`).
"""

from __future__ import annotations

import math
import os
import warnings
from typing import Any

import numpy as np

from gisnoise.acoustics._checks import _array, _finite, _positive_scalar, _scalar
from gisnoise.errors import InputError, RecordingError

__all__ = ["calibrate", "read_wav", "write_wav", "check_wav_header", "DROPOUT_S"]


def calibrate(volts: Any, sensitivity_v_per_pa: float) -> np.ndarray:
    """Sound pressure (Pa) from a microphone signal in volts: ``p = v / sensitivity``.

    Examples
    --------
    >>> calibrate([0.05, -0.1], 0.05).tolist()
    [1.0, -2.0]
    """
    s = _positive_scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    return _array(volts, "volts") / s


def _wav_open(path: str | os.PathLike[str], mmap: bool) -> tuple[float, np.ndarray]:
    from scipy.io import wavfile

    name = os.fspath(path)
    if not os.path.isfile(name):
        raise InputError(f"{name}: WAV file not found", field="path")
    check_wav_header(name)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", wavfile.WavFileWarning)  # unknown chunks (LIST, bext, ...)
            try:
                fs, data = wavfile.read(name, mmap=mmap)
            except ValueError:
                if not mmap:
                    raise
                fs, data = wavfile.read(name, mmap=False)  # 24-bit PCM cannot be memory-mapped
    except (ValueError, OSError) as exc:
        raise InputError(f"{name}: not a readable WAV file ({exc})", field="path") from None
    if data.ndim != 1:
        raise InputError(f"{name}: WAV must be mono, got {data.shape[1]} channels", field="channels")
    return float(fs), data


def check_wav_header(path: str | os.PathLike[str]) -> tuple[int, int, int, int]:
    """Check a WAV file's header against its length before its data is read.

    Refuses, in one line naming the field: a file without a RIFF/WAVE header, a missing or
    short ``fmt `` chunk, no ``data`` chunk, a ``data`` chunk holding no sample, and a file
    shorter than its header states (truncated: the missing part is stated).

    Returns
    -------
    channels, sample_rate_hz, bits_per_sample, frames
    """
    name = os.fspath(path)
    size = os.path.getsize(name)
    fmt: tuple[int, int, int] | None = None
    with open(name, "rb") as fh:
        head = fh.read(12)
        if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64") or head[8:12] != b"WAVE":
            raise InputError(f"{name}: not a WAV file (no RIFF/WAVE header)", field="header")
        if head[:4] == b"RF64":  # sizes in a ds64 chunk; scipy checks the rest
            return 0, 0, 0, 0
        pos = 12
        while True:
            ch = fh.read(8)
            if len(ch) < 8:
                raise InputError(f"{name}: WAV header without a 'data' chunk (file ends at byte {pos})",
                                 field="header")
            cid, n = ch[:4], int.from_bytes(ch[4:], "little")
            pos += 8
            if cid == b"fmt ":
                body = fh.read(min(n, 16))
                if n < 16 or len(body) < 16:
                    raise InputError(f"{name}: truncated WAV 'fmt ' chunk ({len(body)} of 16 bytes)", field="header")
                channels = int.from_bytes(body[2:4], "little")
                rate = int.from_bytes(body[4:8], "little")
                bits = int.from_bytes(body[14:16], "little")
                if channels < 1 or rate < 1 or bits < 1:
                    raise InputError(f"{name}: WAV 'fmt ' chunk states {channels} channels, {rate} Hz, {bits} bits",
                                     field="header")
                fmt = (channels, rate, bits)
                fh.seek(pos + n + (n & 1))
            elif cid == b"data":
                if fmt is None:
                    raise InputError(f"{name}: WAV 'data' chunk before its 'fmt ' chunk", field="header")
                channels, rate, bits = fmt
                frame = channels * ((bits + 7) // 8)
                have = size - pos
                if n > have:
                    missing = (n - have) / (frame * rate)
                    raise InputError(f"{name}: truncated WAV: the header states {n} bytes of samples, the file "
                                     f"holds {have} ({missing:.6g} s of audio missing)", field="length")
                frames = n // frame
                if frames < 1:
                    raise InputError(f"{name}: the WAV file holds no samples", field="length")
                return channels, rate, bits, frames
            else:
                fh.seek(pos + n + (n & 1))
            pos = fh.tell()


def _wav_scale(data: np.ndarray, name: str) -> float:
    """Factor from stored WAV values to volts (full-scale integer PCM = 1 V)."""
    kind = data.dtype.kind
    if kind == "f":
        return 1.0
    if kind == "i":
        return 1.0 / float(2 ** (8 * data.dtype.itemsize - 1))
    if kind == "u":  # 8-bit PCM is unsigned, offset 128
        raise InputError(f"{name}: 8-bit unsigned PCM is not supported, use 16/24/32-bit or float",
                         field="sample_format")
    raise InputError(f"{name}: unsupported WAV sample type {data.dtype}", field="sample_format")


def _at_full_scale(chunk: np.ndarray, dtype: np.dtype[Any]) -> np.ndarray:
    """Stored values at digital full scale: integer PCM at or beyond its largest positive code
    (24-bit PCM is read left-justified in int32, so its largest code is 2^31 - 256); float samples
    exactly at +-1.0 (float has no full scale of its own, but a recorder that clips writes 1.0)."""
    if dtype.kind == "i":
        bits = 8 * dtype.itemsize
        return np.abs(chunk) >= float(2 ** (bits - 1) - max(1, 2 ** (bits - 24)))
    return np.abs(chunk) == 1.0


DROPOUT_S = 0.010
"""Shortest stretch of exactly equal samples taken for a dropout (the recorder lost its input), s.

No sound a microphone picks up holds one sample value this long: the microphone's self-noise and the
converter's own noise (about one least significant bit rms even at 16 bits, the noise that dither hides;
many at 24 bits) change the stored value from one sample to the next more often than not, so 10 ms of one
value (80 samples at 8 kHz, 480 at 48 kHz) has a chance below 0.5^80 in a real recording.  A recorder that
drops samples (a buffer overrun, a loose cable, a muted input) writes exact zeros, or holds its last value.
A shorter stretch takes at most 10 ms of a 0.125 s block, its level at most 0.35 dB low."""

_JOIN_S = 0.5
"""Stretches of one kind closer than this (s) are named as one: the clipped peaks of a loud passage come
every half period of its sound, under 20 ms apart above 25 Hz."""

_SCAN_CHUNK = 1 << 20
"""Samples per chunk of :func:`_scan` (memory-mapped files are read chunk by chunk)."""


class _Runs:
    """Maximal runs of samples over which ``cont`` holds, found chunk by chunk: ``cont[i]`` says that sample
    ``i`` continues the run of sample ``i - 1``.  Keeps ``(first, last)`` of each run of ``min_len`` samples
    or more."""

    def __init__(self, min_len: int) -> None:
        self.min_len = max(int(min_len), 2)
        self.open: int | None = None  # first sample of a run still going at the end of the last chunk
        self.found: list[np.ndarray] = []

    def add(self, cont: np.ndarray, start: int) -> None:
        """Take ``cont`` of samples ``start, start + 1, ...`` (``cont[0]`` relates to sample ``start - 1``)."""
        if self.open is not None and not cont[0]:
            self._keep(np.array([self.open]), np.array([start - 1]))
            self.open = None
        d = np.diff(np.concatenate(([0], cont.astype(np.int8), [0])))
        rises, falls = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        first, last = start + rises - 1, start + falls - 1
        if rises.size and rises[0] == 0 and self.open is not None:
            first[0] = self.open
        self.open = None
        if falls.size and falls[-1] == cont.size:  # still going at the chunk's end
            self.open = int(first[-1])
            first, last = first[:-1], last[:-1]
        self._keep(first, last)

    def close(self, n: int) -> np.ndarray:
        """End at sample ``n``: the runs found, shape (k, 2) (first and last sample)."""
        if self.open is not None:
            self._keep(np.array([self.open]), np.array([n - 1]))
            self.open = None
        return np.concatenate(self.found) if self.found else np.zeros((0, 2), dtype=np.int64)

    def _keep(self, first: np.ndarray, last: np.ndarray) -> None:
        ok = last - first + 1 >= self.min_len
        if ok.any():
            self.found.append(np.column_stack([first[ok], last[ok]]).astype(np.int64))


def _scan(data: Any, fs_hz: float, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Stretches of a recording that are not sound, as ``(first, last)`` sample rows: clipped runs (two
    samples or more in a row at digital full scale) and dropouts (:data:`DROPOUT_S` or more of one exact
    value, full scale excepted: that is clipping).  ``data`` holds stored values (a memory map is read chunk
    by chunk); a non-finite sample is refused."""
    n = len(data)
    clip, hold = _Runs(2), _Runs(math.ceil(DROPOUT_S * fs_hz - 1e-9))
    prev_at, prev = False, math.nan
    for pos in range(0, n, _SCAN_CHUNK):
        c = np.asarray(data[pos:pos + _SCAN_CHUNK], dtype=np.float64)
        bad = ~np.isfinite(c)
        if bad.any():  # float WAV holding NaN or infinity: not a recording
            raise InputError(f"{name}: non-finite sample at index {pos + int(np.argmax(bad))}", field="samples")
        at = _at_full_scale(c, data.dtype)
        clip.add(np.concatenate(([prev_at and bool(at[0])], at[1:] & at[:-1])), pos)
        hold.add(np.concatenate(([c[0] == prev], c[1:] == c[:-1])), pos)
        prev_at, prev = bool(at[-1]), float(c[-1])
    held = hold.close(n)
    if held.size:
        held = held[~_at_full_scale(np.asarray(data[held[:, 0]], dtype=np.float64), data.dtype)]
    return clip.close(n), held


def _spans(runs: np.ndarray, fs_hz: float) -> list[tuple[float, float]]:
    """Times (s) of sample runs, ``(first sample, end of the last)``, those closer than ``_JOIN_S`` joined."""
    out: list[tuple[float, float]] = []
    for a, b in zip(runs[:, 0] / fs_hz, (runs[:, 1] + 1) / fs_hz, strict=True):
        if out and a - out[-1][1] < _JOIN_S:
            out[-1] = (out[-1][0], float(b))
        else:
            out.append((float(a), float(b)))
    return out


def _span_text(spans: list[tuple[float, float]]) -> str:
    """``a-b s`` of the first spans; how many more."""
    shown = ", ".join(f"{a:.3f}-{b:.3f} s" for a, b in spans[:3])
    return shown + (f" and {len(spans) - 3} more" if len(spans) > 3 else "")


def _screen(runs: tuple[np.ndarray, np.ndarray], data: Any, fs_hz: float, name: str, volts_per_unit: float,
            excluded_s: Any = None) -> list[tuple[float, float]]:
    """Refuse a recording with clipped or dropped-out stretches (:func:`_scan`) outside ``excluded_s``.

    One line names the file, the kind, the times and the way out; a :class:`~gisnoise.errors.RecordingError`
    whose ``spans`` are those times (none for a recording of one value throughout: no part of it is sound).

    Returns
    -------
    list of (float, float)
        Times (s) of the stretches ``excluded_s`` holds, for their blocks to be left out.
    """
    ex = np.zeros((0, 2)) if excluded_s is None else np.asarray(excluded_s, dtype=float).reshape(-1, 2)
    tol = 0.5 / fs_hz
    accepted: list[tuple[float, float]] = []
    refused = []
    for kind, r in zip(("clipped", "dropout"), runs, strict=True):
        t0, t1 = r[:, 0] / fs_hz, (r[:, 1] + 1) / fs_hz
        inside = np.any((t0[:, None] >= ex[None, :, 0] - tol) & (t1[:, None] <= ex[None, :, 1] + tol), axis=1)
        accepted += _spans(r[inside], fs_hz)
        if not inside.all():
            refused.append((int(r[~inside][0, 0]), kind, r[~inside]))
    if not refused:
        return sorted(accepted)
    i, kind, r = min(refused, key=lambda x: x[0])
    spans = _spans(r, fs_hz)
    n = len(data)
    if kind == "clipped":
        raise RecordingError(
            f"{name}: clipped recording: samples at digital full scale from {i / fs_hz:.3f} s (sample {i}), over "
            f"{_span_text(spans)}; its levels would be too low, re-record with less gain or exclude these times",
            field="samples", spans=tuple(spans))
    v = float(data[i]) * volts_per_unit
    what = "exactly 0 (digital silence)" if v == 0.0 else f"held at one value ({v:.6g} V)"
    if r[0, 0] == 0 and r[0, 1] == n - 1:
        raise RecordingError(f"{name}: the recording holds no sound: all its {n} samples ({n / fs_hz:g} s) are "
                             f"{what.replace('held at ', '')}; a recorder writes this only without an input, "
                             "re-record", field="samples")
    raise RecordingError(
        f"{name}: dropout: samples {what} from {i / fs_hz:.3f} s (sample {i}), over {_span_text(spans)}; no "
        f"microphone's or converter's noise holds one value for {1000 * DROPOUT_S:g} ms: the recorder lost its "
        "input there and the levels would be its filters' decay, not sound; re-record, or exclude these times",
        field="samples", spans=tuple(spans))


def _check_rate(fs: float, expected: float | None, name: str) -> None:
    if expected is not None and abs(fs - float(expected)) > 1e-6 * float(expected):
        raise InputError(f"{name}: sample rate {fs:g} Hz, expected {float(expected):g} Hz", field="sample_rate")


def read_wav(
    path: str | os.PathLike[str],
    sensitivity_v_per_pa: float | None = None,
    *,
    expected_fs_hz: float | None = None,
) -> tuple[np.ndarray, float]:
    """Read a mono WAV file as volts, or as pascals when the sensitivity is given.

    Stored values are volts: float WAV as is, integer PCM scaled so full scale
    is 1 V (int16 32768 -> 1 V; 24-bit PCM is read left-justified in int32).

    Parameters
    ----------
    path : path-like
        WAV file.
    sensitivity_v_per_pa : float, optional
        Microphone sensitivity, V/Pa; when given the result is in Pa.
    expected_fs_hz : float, optional
        Required sample rate, Hz; another rate is an error naming ``sample_rate``.

    Returns
    -------
    signal : ndarray of float64, shape (n,)
        Volts, or pascals with a sensitivity.
    fs_hz : float
        Sample rate, Hz.

    Raises
    ------
    RecordingError
        Field ``samples``: a clipped recording (two samples in a row at digital full scale) or a dropout
        (:data:`DROPOUT_S` or more of one exact value, zeros among them), naming the file and the times;
        :func:`gisnoise.acoustics.wav_band_levels` can leave such stretches out.
    InputError
        A file that is no mono WAV, a non-finite sample, another rate than ``expected_fs_hz``.
    """
    name = os.fspath(path)
    fs, data = _wav_open(name, mmap=False)
    _check_rate(fs, expected_fs_hz, name)
    scale = _wav_scale(data, name)
    _screen(_scan(data, fs, name), data, fs, name, scale)
    v = data.astype(np.float64) * scale
    if sensitivity_v_per_pa is not None:
        v = calibrate(v, sensitivity_v_per_pa)
    return v, fs


def write_wav(
    path: str | os.PathLike[str],
    pressure_pa: Any,
    fs_hz: float,
    sensitivity_v_per_pa: float,
    *,
    dtype: str = "float32",
) -> None:
    """Write sound pressure as a mono WAV of volts (the inverse of :func:`read_wav`).

    Parameters
    ----------
    path : path-like
        Output file.
    pressure_pa : array_like, shape (n,)
        Sound pressure, Pa.
    fs_hz : float
        Sample rate, Hz (a whole number).
    sensitivity_v_per_pa : float
        Microphone sensitivity, V/Pa.
    dtype : {"float32", "float64", "int16", "int32"}
        Sample format; integer PCM has full scale 1 V and clipping is an error.
    """
    from scipy.io import wavfile

    p = _finite(pressure_pa, "pressure_pa")
    if p.ndim != 1:
        raise InputError(f"pressure_pa must be 1-D (mono), got shape {p.shape}", field="pressure_pa")
    fs = _scalar(fs_hz, "fs_hz")
    if fs <= 0 or fs != round(fs):
        raise InputError(f"fs_hz must be a positive whole number for WAV, got {fs}", field="fs_hz")
    s = _positive_scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    v = p * s
    if dtype in ("float32", "float64"):
        data = v.astype(dtype)
    elif dtype in ("int16", "int32"):
        full = float(2 ** (8 * np.dtype(dtype).itemsize - 1))
        q = np.round(v * full)
        if np.any(q > full - 1) or np.any(q < -full):
            peak = float(np.max(np.abs(v)))
            raise InputError(f"signal peak {peak:.3g} V clips {dtype} PCM (full scale 1 V)", field="pressure_pa")
        data = q.astype(dtype)
    else:
        raise InputError(f"dtype must be float32, float64, int16 or int32, got {dtype!r}", field="dtype")
    wavfile.write(os.fspath(path), int(fs), data)
