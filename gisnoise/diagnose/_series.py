"""Time-series kernels of the diagnosis: each microphone's series per flight, smoothed, thresholded, cut into runs.

A series is one microphone during one flight (:func:`gisnoise.measure.series_ids`).
The smoothed residual of a series and the standard error of its window mean
are what localization and event detection both threshold.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


def _runs(sid: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Row indices of each series in time order."""
    order = np.lexsort((t, sid))
    cuts = np.flatnonzero(np.diff(sid[order])) + 1
    return [o for o in np.split(order, cuts) if len(o)]


def _rolling_mean(v: np.ndarray, n_w: int) -> np.ndarray:
    """Running mean over ``n_w`` samples, the window shrinking at the edges."""
    if len(v) < n_w:
        return np.full(len(v), float(np.mean(v)))
    c = np.convolve(v, np.ones(n_w) / n_w, mode="same")
    # edges: shrink the window instead of padding with zeros
    k = np.convolve(np.ones(len(v)), np.ones(n_w) / n_w, mode="same")
    return c / k


@dataclass
class _Series:
    """One series smoothed: rows, ids, times, smoothed residual (``excess``) and its threshold, window length."""

    idx: np.ndarray
    mic: str
    flight: str
    t: np.ndarray
    excess: np.ndarray
    threshold: float
    n_w: int


def _window_mean_error(r: np.ndarray, n_w: int, sigma_white: float) -> float:
    """Standard error of a mean over ``n_w`` consecutive samples of measurement noise, dB.

    The residual minus its running mean over ``4 n_w`` samples keeps the fast
    scatter and drops slow model error.  Its robust variance and its lag-1 and
    lag-2 autocorrelations give the noise variance and the coefficient ``rho``
    of first-order (AR(1)) noise, corrected for what the running mean removed;
    then ``var(mean) = var / n_w (1 + 2 sum_k (1 - k/n_w) rho^k)``: coloured
    noise counts with its correlation.  Never below the white-noise value
    ``sigma_white / sqrt(n_w)``.
    """
    white = sigma_white / math.sqrt(n_w)
    if len(r) < 8 * n_w:
        return white
    e = r - _rolling_mean(r, 4 * n_w)
    e = e - np.median(e)
    var = float((1.4826 * np.median(np.abs(e))) ** 2)
    full = float(np.mean(e * e))
    if full <= 0.0:
        return white
    a1 = float(np.mean(e[1:] * e[:-1])) / full
    a2 = float(np.mean(e[2:] * e[:-2])) / full
    # the running mean lowers every short-lag autocorrelation by about the same c:
    # a_k = (rho^k - c) / (1 - c), so rho = (a1 - a2) / (1 - a1) and var = var_e / (1 - c)
    rho = min(max((a1 - a2) / (1.0 - a1), 0.0), 0.99) if a1 < 1.0 else 0.0
    c = min(max((rho - a1) / (1.0 - a1), 0.0), 0.9) if a1 < 1.0 else 0.0
    k = np.arange(1, n_w)
    factor = 1.0 + 2.0 * float(np.sum((1.0 - k / n_w) * rho ** k))
    return max(white, math.sqrt(var / (1.0 - c) * factor / n_w))


def _smoothed(resid: np.ndarray, sid: np.ndarray, t: np.ndarray, mic: np.ndarray, flight: np.ndarray,
              noise: Mapping[str, float], window_s: float, z: float, relative: bool = False) -> list[_Series]:
    """Each series' residual smoothed over ``window_s`` (minus its median when ``relative``), threshold ``z`` errors."""
    out = []
    for idx in _runs(sid, t):
        tt = t[idx]
        dt = float(np.median(np.diff(tt))) if len(tt) > 1 else 1.0
        n_w = max(3, int(round(window_s / max(dt, 1e-6))))
        rm = _rolling_mean(resid[idx], n_w)
        ex = rm - np.median(rm) if relative else rm
        thr = z * _window_mean_error(resid[idx], n_w, noise.get(str(mic[idx[0]]), 0.0))
        out.append(_Series(idx, str(mic[idx[0]]), str(flight[idx[0]]), tt, ex, thr, n_w))
    return out


def _intervals(mask: np.ndarray, t: np.ndarray, min_len_s: float, join_gap_s: float) -> list[tuple[int, int]]:
    """Runs of True in ``mask`` (time-ordered ``t``) as (first, last) positions, joined and filtered."""
    if not mask.any():
        return []
    m = np.r_[False, mask, False].astype(int)
    starts = np.flatnonzero(np.diff(m) == 1)
    ends = np.flatnonzero(np.diff(m) == -1) - 1
    runs: list[tuple[int, int]] = []
    for a, b in zip(starts, ends, strict=True):
        if runs and t[a] - t[runs[-1][1]] <= join_gap_s:
            runs[-1] = (runs[-1][0], int(b))
        else:
            runs.append((int(a), int(b)))
    return [(a, b) for a, b in runs if t[b] - t[a] >= min_len_s]
