"""Rows of the samples that the diagnosis' tests take: a subset of the model inputs, effective samples, band entries.

One definition each of what several tests share:

* :func:`_rows_of`: the model inputs of a subset of the samples;
* :func:`_effective_samples`: a residual sampled faster than it decorrelates counts one
  independent sample per second of its span (per series), at most one per sample and at
  least two;
* :func:`_loud_samples` and :func:`_band_entries`: the samples where the UAV stands above the
  background (15 dB above the card's background level, else each microphone's louder half)
  and the band levels of those samples that stand above their own floor.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def _rows_of(x: Mapping[str, Any], rows: np.ndarray, n: int) -> dict[str, Any]:
    """The model inputs ``x`` of ``n`` samples restricted to ``rows``: per-sample arrays indexed, the rest as is.

    ``band_f`` (one value per band, not per sample) is kept whole.
    """
    return {k: (v[rows] if isinstance(v, np.ndarray) and k != "band_f" and v.shape[:1] == (n,) else v)
            for k, v in x.items()}


def _effective_samples(t_s: np.ndarray, series: int = 1) -> float:
    """Independent samples of a residual at times ``t_s`` (s): one per second of their span and series.

    At most one per sample and at least two.

    >>> _effective_samples(np.arange(0.0, 10.0, 0.125)), _effective_samples(np.arange(0.0, 10.0, 0.125), 2)
    (9.875, 19.75)
    >>> _effective_samples(np.array([0.0, 100.0])), _effective_samples(np.array([5.0]))
    (2.0, 2.0)
    """
    t = np.asarray(t_s, dtype=float)
    span = float(np.ptp(t)) if len(t) > 1 else 1.0
    return float(max(min(len(t), span * series), 2.0))


def _loud_samples(level: np.ndarray, mic: np.ndarray, background_db: float | None = None) -> np.ndarray:
    """Samples where the UAV stands well above the background.

    With the card's background level: 15 dB above it.  Without: each microphone's louder
    half (at or above its own median).  Per microphone, not the campaign's median: a
    microphone farther from the track is quieter throughout, and a common median would drop
    it whole, and with it the far end of the distance range that band slopes need; the
    background too is each microphone's own.
    """
    level = np.asarray(level, dtype=float)
    if background_db is not None and np.isfinite(background_db):
        return level > background_db + 15.0
    mics = np.asarray(mic).astype(str)
    loud = np.zeros(len(level), dtype=bool)
    for m in set(mics.tolist()):
        rows = mics == m
        loud |= rows & (level >= np.quantile(level[rows], 0.5))
    return loud


def _band_entries(level: np.ndarray, mic: np.ndarray, bands: np.ndarray, d: np.ndarray, *,
                  background_db: float | None = None, exclude: np.ndarray | None = None,
                  above_floor_db: float = 10.0, min_entries: int = 30, min_span_m: float = 50.0) -> np.ndarray:
    """Entries (sample x band) of band levels that show the UAV, as a boolean matrix.

    An entry is a band of a loud sample (:func:`_loud_samples`, without the ``exclude`` samples)
    that stands ``above_floor_db`` above the band's own quietest level (its 5th percentile:
    its background).  A band keeps its entries only with at least ``min_entries`` of them
    spanning ``min_span_m`` of distance ``d`` (m); otherwise its column is all False.
    """
    bands = np.asarray(bands, dtype=float)
    d = np.asarray(d, dtype=float)
    loud = _loud_samples(level, mic, background_db)
    if exclude is not None:
        loud &= ~np.asarray(exclude, dtype=bool)
    finite = np.isfinite(bands)
    floor = np.full(bands.shape[1], np.inf)  # a band without any level has no entry
    has = finite.any(axis=0)
    floor[has] = np.nanpercentile(bands[:, has], 5, axis=0)
    ok = loud[:, None] & finite & (bands > floor + above_floor_db)
    for j in range(bands.shape[1]):
        if ok[:, j].sum() < min_entries or np.ptp(d[ok[:, j]]) < min_span_m:
            ok[:, j] = False
    return ok
