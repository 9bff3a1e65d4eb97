"""WAV audio: mono recordings in volts, their calibration to pascals, and writing sound pressure as WAV.

Stored values are volts: float WAV as is, integer PCM scaled so that full scale is 1 V.
"""

from __future__ import annotations

import os
import warnings
from typing import Any

import numpy as np

from gisnoise.acoustics._checks import _array, _finite, _positive_scalar, _scalar
from gisnoise.errors import InputError

__all__ = ["calibrate", "read_wav", "write_wav", "check_wav_header"]


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


def _check_clipping(chunk: np.ndarray, start: int, fs_hz: float, dtype: np.dtype[Any], name: str) -> None:
    """Refuse a recording that reached digital full scale in two consecutive samples (clipped).

    A recorder driven past full scale flattens the peaks: the levels of those blocks would be too
    low, silently.  ``chunk`` holds stored values (before calibration) from sample ``start``.
    """
    at = _at_full_scale(chunk, dtype)
    run = at[1:] & at[:-1]
    if run.any():
        i = start + int(np.argmax(run))
        raise InputError(f"{name}: clipped recording: samples at digital full scale from {i / fs_hz:.3f} s "
                         f"(sample {i}); its levels would be too low, re-record with less gain or cut the "
                         "clipped part out", field="samples")


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
    """
    name = os.fspath(path)
    fs, data = _wav_open(name, mmap=False)
    _check_rate(fs, expected_fs_hz, name)
    raw = data.astype(np.float64)
    v = raw * _wav_scale(data, name)
    bad = ~np.isfinite(v)
    if bad.any():  # float WAV holding NaN or infinity: not a recording
        raise InputError(f"{name}: non-finite sample at index {int(np.argmax(bad))}", field="samples")
    _check_clipping(raw, 0, fs, data.dtype, name)
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
