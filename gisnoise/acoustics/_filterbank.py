"""Private kernels of the one-third-octave filter bank (multirate IIR).

The public face is :func:`gisnoise.acoustics.audio.band_levels`.  Design (IEC 61260-1,
base-10, the ANSI S1.11 multirate approach):

* every band is a Butterworth band-pass of prototype order :data:`ORDER`
  (band-pass order ``2 * ORDER``, ``ORDER`` biquad sections) between the exact
  band edges ``fm * G**(-1/6)`` and ``fm * G**(1/6)``, ``G = 10**0.3``;
* a band is filtered at the lowest rate ``fs / 2**k`` at which its upper edge
  stays below ``BETA`` times that rate's Nyquist frequency, so the bilinear
  warping stays mild and the cost of the low bands vanishes;
* the signal reaches rate ``fs / 2**k`` through ``k`` identical half-band
  stages: a Butterworth low-pass (:data:`AA_ORDER`, cut-off at half the
  stage's input Nyquist) followed by keeping every second sample;
* the output of each band is squared and integrated over blocks whose edges
  may fall between samples (each sample holds its value for one sample period,
  centred on its time); block edges are shifted by the band's group delay at
  its mid-band frequency, filter and decimation chain included, so a block
  reports the sound that arrived during its interval.

The signal is processed in chunks with the filter states carried over, so long
recordings (memory-mapped WAV files) never need a full-length copy.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import signal

from gisnoise.acoustics.bands import G, band_edges

__all__ = ["G", "ORDER", "AA_ORDER", "BETA", "FilterBank", "design", "chain_response", "memory_s", "run"]

ORDER = 4
"""Butterworth prototype order of each band (band-pass order 8, four biquads)."""

AA_ORDER = 10
"""Butterworth order of the half-band anti-alias low-pass of each decimation stage."""

BETA = 0.5
"""A band is filtered at the lowest rate where its upper edge is <= BETA * Nyquist."""

MAX_EDGE_FRACTION = 0.95
"""Highest usable upper band edge, as a fraction of the Nyquist frequency of the input."""

CHUNK = 1 << 16
"""Input samples per processing chunk (rounded up to a multiple of 2**levels)."""


@dataclass(frozen=True, eq=False)
class FilterBank:
    """A designed multirate one-third-octave filter bank.

    Attributes
    ----------
    fs_hz : float
        Input sample rate, Hz.
    f_hz : ndarray, shape (nb,)
        Exact mid-band frequencies, Hz.
    level : ndarray of int, shape (nb,)
        Decimation level of each band: it is filtered at ``fs_hz / 2**level``.
    band_sos : tuple of ndarray
        Second-order sections of each band, designed at its own rate.
    aa_sos : ndarray
        Second-order sections of the anti-alias low-pass of one decimation stage.
    delay_s : ndarray, shape (nb,)
        Group delay of each band's whole chain at its mid-band frequency, s.
    """

    fs_hz: float
    f_hz: np.ndarray
    level: np.ndarray
    band_sos: tuple[np.ndarray, ...]
    aa_sos: np.ndarray
    delay_s: np.ndarray

    @property
    def n_levels(self) -> int:
        """Number of decimation stages the deepest band needs."""
        return int(self.level.max()) if self.level.size else 0


def max_centre(fs_hz: float) -> float:
    """Highest mid-band frequency (Hz) whose upper edge is usable at ``fs_hz``."""
    return MAX_EDGE_FRACTION * 0.5 * fs_hz / G ** (1.0 / 6.0)


def _sos_group_delay(sos: np.ndarray, f_hz: float, fs_hz: float) -> float:
    """Group delay of a cascade of second-order sections at one frequency, s."""
    total = 0.0
    for sec in sos:
        _, gd = signal.group_delay((sec[:3], sec[3:]), w=[f_hz], fs=fs_hz)
        total += float(gd[0])
    return total / fs_hz


@lru_cache(maxsize=32)
def _design_cached(fs_hz: float, f_key: tuple[float, ...]) -> FilterBank:
    f = np.asarray(f_key, dtype=float)
    _, f2 = band_edges(f)
    # deepest level k with f2 <= BETA * (fs / 2**k) / 2
    ratio = BETA * 0.5 * fs_hz / f2
    level = np.maximum(np.floor(np.log2(ratio)).astype(int), 0)
    aa_sos = signal.butter(AA_ORDER, 0.5, btype="lowpass", output="sos")
    band_sos = []
    delays = np.empty(f.size)
    for j, (fm, k) in enumerate(zip(f, level, strict=True)):
        fs_k = fs_hz / 2.0**k
        lo, hi = band_edges(fm)
        sos = signal.butter(ORDER, [float(lo), float(hi)], btype="bandpass", fs=fs_k, output="sos")
        band_sos.append(sos)
        delay = _sos_group_delay(sos, float(fm), fs_k)
        for s in range(1, int(k) + 1):  # stage s runs at fs / 2**(s-1)
            delay += _sos_group_delay(aa_sos, float(fm), fs_hz / 2.0 ** (s - 1))
        delays[j] = delay
    for arr in (f, level, delays):
        arr.setflags(write=False)
    return FilterBank(float(fs_hz), f, level, tuple(band_sos), aa_sos, delays)


def design(fs_hz: float, f_hz: Any) -> FilterBank:
    """Design (or fetch from a cache) the bank for a sample rate and mid-band frequencies.

    The caller checks that every upper band edge is below ``MAX_EDGE_FRACTION``
    of the Nyquist frequency (see :func:`max_centre`).
    """
    return _design_cached(float(fs_hz), tuple(float(v) for v in np.atleast_1d(f_hz)))


def _decay_s(sos: np.ndarray, fs_hz: float) -> float:
    """Time (s) in which the slowest pole of a filter decays by 60 dB (amplitude 1/1000)."""
    _, p, _ = signal.sos2zpk(sos)
    r = float(np.max(np.abs(p))) if p.size else 0.0
    return 0.0 if r <= 0.0 else float(np.log(1000.0) / -np.log(r) / fs_hz)


def memory_s(bank: FilterBank) -> tuple[float, float]:
    """How far from a stretch of input the band levels of :func:`run` still depend on it, s: before it,
    the largest group delay of the bands (block edges are shifted by it, and the filters are causal);
    after it, the longest 60 dB decay of a band's chain (its band filter and the anti-alias stages before
    it, their slowest poles, summed): about 1.3 s for the 25 Hz band, some 30 ms at 1 kHz.

    Examples
    --------
    >>> from gisnoise.acoustics.bands import third_octave_centres
    >>> before, after = memory_s(design(48000.0, third_octave_centres(25.0, 20000.0)))
    >>> round(before, 2), round(after, 1)
    (0.16, 1.3)
    """
    if not bank.f_hz.size:
        return 0.0, 0.0
    after = 0.0
    for j, k in enumerate(bank.level):
        t = _decay_s(bank.band_sos[j], bank.fs_hz / 2.0 ** int(k))
        t += sum(_decay_s(bank.aa_sos, bank.fs_hz / 2.0 ** (s - 1)) for s in range(1, int(k) + 1))
        after = max(after, t)
    return float(np.max(bank.delay_s)), after


def _fold(f: np.ndarray, fs: float) -> np.ndarray:
    """Frequency (Hz) a real sinusoid at ``f`` appears at after sampling at ``fs``."""
    r = np.mod(f, fs)
    return np.minimum(r, fs - r)


def chain_response(bank: FilterBank, f_probe: Any, bands: Any = None) -> np.ndarray:
    """Gain of each band's whole chain to a sinusoid of the input, linear.

    A sinusoid at ``f`` passes each anti-alias stage at its current (folded)
    frequency, is folded by the decimation, and meets the band filter at its
    final folded frequency; the product of the stage gains is what the band
    level sees.  This is the exact steady-state sine response of :func:`run`.

    Parameters
    ----------
    bank : FilterBank
    f_probe : array_like
        Input frequencies, Hz, within ``[0, fs/2]``.
    bands : array_like of int, optional
        Indices of the bands to evaluate (default: all).

    Returns
    -------
    ndarray, shape (n_probe, n_bands)
        Amplitude gain (1 = unchanged).
    """
    f0 = np.atleast_1d(np.asarray(f_probe, dtype=float))
    sel = np.arange(bank.f_hz.size) if bands is None else np.atleast_1d(np.asarray(bands, dtype=int))
    n_lev = int(bank.level[sel].max()) if sel.size else 0
    # gain and frequency entering each level
    gains = [np.ones_like(f0)]
    freqs = [f0]
    g, f = gains[0], f0
    for s in range(1, n_lev + 1):
        fs_in = bank.fs_hz / 2.0 ** (s - 1)
        _, h = signal.sosfreqz(bank.aa_sos, worN=f, fs=fs_in)
        g = g * np.abs(h)
        f = _fold(f, fs_in / 2.0)
        gains.append(g)
        freqs.append(f)
    out = np.empty((f0.size, sel.size))
    for i, j in enumerate(sel):
        k = int(bank.level[j])
        _, h = signal.sosfreqz(bank.band_sos[j], worN=freqs[k], fs=bank.fs_hz / 2.0**k)
        out[:, i] = gains[k] * np.abs(h)
    return out


class _BandAccumulator:
    """Block energies of one band from its squared output, chunk by chunk.

    Band sample ``m`` holds its value over ``[m, m + 1)`` in the band's sample
    units; block ``i`` spans ``[u[i], u[i + 1])``.  Whole samples are summed
    straight into their block (no running total, so a block far quieter than
    the start of the recording keeps its precision) and the fractions of the
    samples cut by an edge are moved to the block before it.
    """

    def __init__(self, u: np.ndarray) -> None:
        self.u = u
        self.whole = np.floor(u).astype(np.int64)  # sample holding each edge
        self.frac = u - self.whole  # part of that sample before the edge
        self.energy = np.zeros(u.size + 1)  # [before the first edge, block 0, ..., after the last edge]

    def add(self, z: np.ndarray, m0: int) -> None:
        """Take the squared samples ``z`` covering band samples ``[m0, m0 + len(z))``."""
        m1 = m0 + z.size
        lo = int(np.searchsorted(self.whole, m0, side="left"))
        hi = int(np.searchsorted(self.whole, m1, side="left"))
        cuts = self.whole[lo:hi] - m0
        bounds = np.unique(np.concatenate(([0], cuts)))
        seg = np.add.reduceat(z, bounds)
        slot = np.searchsorted(self.whole, m0 + bounds, side="right")  # 0 = before the first edge
        np.add.at(self.energy, slot, seg)
        moved = self.frac[lo:hi] * z[cuts]
        edge = np.arange(lo, hi)
        np.add.at(self.energy, edge + 1, -moved)
        np.add.at(self.energy, edge, moved)

    def mean_square(self) -> np.ndarray:
        """Mean square of each block (rounding below zero clipped)."""
        return np.maximum(self.energy[1:-1], 0.0) / np.diff(self.u)


def run(
    bank: FilterBank,
    x: Any,
    block_len: float,
    n_blocks: int,
    *,
    scale: float = 1.0,
    chunk: int = CHUNK,
    check: Callable[[np.ndarray, int], None] | None = None,
    progress: Callable[[float], None] | None = None,
) -> np.ndarray:
    """Mean square of each band over consecutive blocks.

    Parameters
    ----------
    bank : FilterBank
    x : array_like, shape (n,)
        Input samples (any real dtype; memory maps are read chunk by chunk).
    block_len : float
        Block length in input samples (need not be an integer).
    n_blocks : int
        Number of blocks, ``n_blocks * block_len <= n``.
    scale : float
        Factor applied to each chunk after conversion to float64 (calibration).
    chunk : int
        Input samples per chunk.
    check : callable, optional
        ``check(chunk_float64, start_index)`` validates each converted chunk.
    progress : callable, optional
        ``progress(fraction_done)`` after each chunk (it may raise to cancel).

    Returns
    -------
    ndarray, shape (n_blocks, nb)
        Block mean square of each band, in the squared unit of ``x * scale``.
    """
    nb = bank.f_hz.size
    if n_blocks <= 0 or nb == 0:
        return np.zeros((max(n_blocks, 0), nb))
    n = len(x)
    n_lev = bank.n_levels
    step = 1 << n_lev
    chunk = max(step, (int(chunk) // step) * step)
    edges_in = np.arange(n_blocks + 1, dtype=float) * block_len  # input-sample units
    accs = []
    need = n  # input samples to process, zero padding included
    for j in range(nb):
        k = int(bank.level[j])
        fs_k = bank.fs_hz / 2.0**k
        # sample m of the band (time m / fs_k) covers [m - 1/2, m + 1/2): shift by +1/2
        u = edges_in / 2.0**k + bank.delay_s[j] * fs_k + 0.5
        accs.append(_BandAccumulator(u))
        need = max(need, int(np.ceil((np.floor(u[-1]) + 2.0) * 2.0**k)))
    need = -(-need // step) * step
    zi_aa = [np.zeros((bank.aa_sos.shape[0], 2)) for _ in range(n_lev)]
    zi_band = [np.zeros((s.shape[0], 2)) for s in bank.band_sos]
    by_level: list[list[int]] = [[] for _ in range(n_lev + 1)]
    for j, k in enumerate(bank.level):
        by_level[int(k)].append(j)
    pos = 0
    while pos < need:
        stop = min(pos + chunk, need)
        if pos < n:
            real = np.asarray(x[pos:min(stop, n)], dtype=np.float64)
            if check is not None:
                check(real, pos)
            if scale != 1.0:
                real = real * scale
            if stop > n:
                cur = np.zeros(stop - pos)
                cur[: real.size] = real
            else:
                cur = np.ascontiguousarray(real)
        else:
            cur = np.zeros(stop - pos)
        for k in range(n_lev + 1):
            if k > 0:
                y, zi_aa[k - 1] = signal.sosfilt(bank.aa_sos, cur, zi=zi_aa[k - 1])
                cur = np.ascontiguousarray(y[::2])
            m0 = pos >> k
            for j in by_level[k]:
                y, zi_band[j] = signal.sosfilt(bank.band_sos[j], cur, zi=zi_band[j])
                np.square(y, out=y)
                accs[j].add(y, m0)
        pos = stop
        if progress is not None:
            progress(pos / need)
    out = np.empty((n_blocks, nb))
    for j, acc in enumerate(accs):
        out[:, j] = acc.mean_square()
    return out
