"""Band levels of audio: calibrated sound pressure or a WAV recording -> one-third-octave band
levels per averaging block (IEC 61260-1 class 1 multirate filter bank).

Examples
--------
>>> import numpy as np
>>> from gisnoise.acoustics import band_name, overall_a_level
>>> fs = 48000.0
>>> t = np.arange(int(2 * fs)) / fs
>>> p = np.sqrt(2.0) * np.sin(2 * np.pi * 1000.0 * t)   # 1 Pa RMS, 1 kHz
>>> t_s, f_hz, L = band_levels(p, fs)
>>> band_name(f_hz[16]), round(float(L[8, 16]), 1)
('L_1000', 94.0)
>>> round(float(overall_a_level(L[8], f_hz)), 1)
94.0
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any

import numpy as np

from gisnoise.acoustics import _filterbank
from gisnoise.acoustics._checks import _array, _positive_scalar, _scalar
from gisnoise.acoustics.bands import third_octave_centres
from gisnoise.acoustics.wav import _check_rate, _scan, _screen, _wav_open, _wav_scale
from gisnoise.errors import InputError

__all__ = ["P_REF", "band_levels", "wav_band_levels"]

P_REF = 20e-6
"""Reference sound pressure, Pa."""


def _bands_for(fs_hz: float, f_min: float, f_max: float | None) -> np.ndarray:
    top = _filterbank.max_centre(fs_hz)
    if f_max is None:
        f = third_octave_centres(f_min, 20000.0)
        f = f[f <= top]
    else:
        f = third_octave_centres(f_min, f_max)
        if f[-1] > top:
            raise InputError(
                f"f_max {f_max:g} Hz needs a sample rate above {2 * f[-1] * _filterbank.G ** (1 / 6) / 0.95:.0f} Hz,"
                f" got fs_hz {fs_hz:g}", field="fs_hz")
    if f.size == 0:
        raise InputError(f"fs_hz {fs_hz:g} is too low for any band from {f_min:g} Hz", field="fs_hz")
    return f


def _block_grid(n: int, fs: float, block_s: float) -> tuple[float, int]:
    block_len = block_s * fs
    if block_len < 1.0:
        raise InputError(f"block_s must span at least one sample (1/fs = {1 / fs:g} s), got {block_s}",
                         field="block_s")
    return block_len, int(math.floor(n / block_len + 1e-9))


def _levels_from_ms(ms: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(ms / P_REF**2)


def _filtered_levels(
    x: Any,
    fs: float,
    blk: float,
    f_min: float,
    f_max: float | None,
    progress: Callable[[float], None] | None,
    *,
    scale: float = 1.0,
    blank: list[tuple[float, float]] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Block times, mid-band frequencies and band levels of samples ``x`` (times ``scale``) at ``fs``; NaN in
    the blocks whose levels depend on a stretch of ``blank`` (s; :func:`_filterbank.memory_s`)."""
    f = _bands_for(fs, _scalar(f_min, "f_min"), None if f_max is None else _scalar(f_max, "f_max"))
    block_len, n_blocks = _block_grid(len(x), fs, blk)
    bank = _filterbank.design(fs, f)
    ms = _filterbank.run(bank, x, block_len, n_blocks, scale=scale, progress=progress)
    t = (np.arange(n_blocks) + 0.5) * blk
    levels = _levels_from_ms(ms)
    if blank:
        before, after = _filterbank.memory_s(bank)
        for a, b in blank:
            levels[(t + 0.5 * blk > a - before) & (t - 0.5 * blk < b + after)] = np.nan
    return t, f.copy(), levels

def band_levels(
    pressure_pa: Any,
    fs_hz: float,
    block_s: float = 0.125,
    *,
    f_min: float = 25.0,
    f_max: float | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-third-octave band levels per averaging block (IEC 61260-1 class 1, base 10).

    Each band is an 8th-order Butterworth band-pass (4 biquads) between the exact
    band edges, run at a decimated rate for low bands (half-band anti-alias
    stages); the block mean square of its output, referred to 20 uPa, is the
    band level.  Blocks are consecutive, ``block_s`` long, starting at the
    first sample; a trailing partial block is dropped.  Block edges are shifted
    by each band's group delay, so band levels of one block describe the same
    stretch of sound.  The filters start at rest and the recording ends
    abruptly: the first and last blocks of the low bands hold the filters'
    settling (a steady 25 Hz tone reads about 1 dB low there).  The response of
    every band meets the class 1 acceptance limits of IEC 61260-1:2014
    (checked at 44.1, 48 and 96 kHz).

    Parameters
    ----------
    pressure_pa : array_like, shape (n,)
        Calibrated sound pressure, Pa, sampled at ``fs_hz``.
    fs_hz : float
        Sample rate, Hz.
    block_s : float
        Averaging block length, s (need not be a whole number of samples).
    f_min : float
        Nominal frequency of the lowest band, Hz.
    f_max : float, optional
        Nominal frequency of the highest band, Hz.  Default: 20 kHz, or the
        highest band whose upper edge stays below 95 % of the Nyquist frequency
        (16 kHz at 44.1 kHz).  An explicit ``f_max`` the rate cannot serve is an error.
    progress : callable, optional
        Called as ``progress(fraction_done)`` while filtering; may raise to cancel.

    Returns
    -------
    t_s : ndarray, shape (n_blocks,)
        Block centre times, s after the first sample.
    f_hz : ndarray, shape (nb,)
        Exact mid-band frequencies, Hz.
    L_dB : ndarray, shape (n_blocks, nb)
        Unweighted band levels, dB re 20 uPa (-inf for digital silence).

    Notes
    -----
    Adjacent Butterworth bands overlap: for broadband sound the energy sum of
    all bands exceeds the true overall level by about 0.11 dB (effective
    bandwidth of the 4th-order prototype); for a tone it is exact.
    """
    fs = _positive_scalar(fs_hz, "fs_hz")
    blk = _positive_scalar(block_s, "block_s")
    x = _array(pressure_pa, "pressure_pa")
    if x.ndim != 1:
        raise InputError(f"pressure_pa must be 1-D (mono), got shape {x.shape}", field="pressure_pa")
    if not np.all(np.isfinite(x)):
        raise InputError(f"pressure_pa must be finite, first bad sample at index {int(np.argmin(np.isfinite(x)))}",
                         field="pressure_pa")
    return _filtered_levels(x, fs, blk, f_min, f_max, progress)


def wav_band_levels(
    path: str | os.PathLike[str],
    sensitivity_v_per_pa: float,
    block_s: float = 0.125,
    *,
    expected_fs_hz: float | None = None,
    f_min: float = 25.0,
    f_max: float | None = None,
    progress: Callable[[float], None] | None = None,
    excluded_s: Any = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`band_levels` of a WAV file, read chunk by chunk (memory-mapped when possible).

    The samples are screened first, as :func:`~gisnoise.acoustics.read_wav` does: a clipped stretch (two
    samples in a row at digital full scale) or a dropout (:data:`~gisnoise.acoustics.wav.DROPOUT_S` or more
    of one exact value: a recorder that lost its input writes zeros, and the filters would give their
    decay, not sound) is refused, unless ``excluded_s`` holds it; then the blocks whose levels depend on it
    (from the bands' largest group delay before it to their chains' longest 60 dB decay after it, about
    0.17 s and 1.3 s with the 25 Hz band) are NaN.

    Parameters
    ----------
    path : path-like
        Mono WAV file of volts (see :func:`read_wav`).
    sensitivity_v_per_pa : float
        Microphone sensitivity, V/Pa.
    block_s, f_min, f_max, progress
        As in :func:`band_levels`.
    expected_fs_hz : float, optional
        Required sample rate, Hz.
    excluded_s : array_like, shape (k, 2), optional
        Intervals ``(t0, t1)``, s from the first sample, in which clipped or dropped-out stretches are
        accepted (and their blocks left NaN).

    Returns
    -------
    t_s, f_hz, L_dB
        As in :func:`band_levels`; ``t_s`` counts from the first sample; NaN rows for the blocks of the
        stretches ``excluded_s`` holds.

    Raises
    ------
    RecordingError
        A clipped or dropped-out stretch outside ``excluded_s`` (field ``samples``; its ``spans``, s).
    """
    name = os.fspath(path)
    s = _positive_scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    blk = _positive_scalar(block_s, "block_s")
    fs, data = _wav_open(name, mmap=True)
    _check_rate(fs, expected_fs_hz, name)
    if len(data) < blk * fs:  # a file's levels: at least one block, never an empty result
        raise InputError(f"block_s: {blk:g} s is longer than the recording {name} ({len(data)} samples, "
                         f"{len(data) / fs:g} s): no block of levels", field="block_s")
    ex = None if excluded_s is None else _array(excluded_s, "excluded_s")
    if ex is not None and (ex.ndim != 2 or ex.shape[1] != 2 or not np.all(ex[:, 0] <= ex[:, 1])):
        raise InputError(f"excluded_s must be (t0, t1) pairs with t0 <= t1, s, got {excluded_s!r}",
                         field="excluded_s")
    volts = _wav_scale(data, name)
    blank = _screen(_scan(data, fs, name), data, fs, name, volts, ex)
    return _filtered_levels(data, fs, blk, f_min, f_max, progress, scale=volts / s, blank=blank)
