"""Band-level held-out tests: evidence in the one-third-octave band levels that feeds the verdict.

Atmospheric absorption hardly shows in the A-weighted level (the base model's
distance term takes most of it) but it is plain in the band levels: a band loses
``alpha_f d`` dB over the path (ISO 9613-1), so the band levels relative to each
other tilt with distance, more the higher the band.  :func:`absorption_band_holdout`
fits the band levels against the overall level (the spectrum's shape) with
per-band means and a common slope with distance, with and without a multiple
``beta >= 0`` of the ISO 9613-1 coefficients (at the campaign's temperature,
humidity and pressure) times distance, on one cross-validation fold, and
predicts the other fold's band levels with both: only the tilt of the spectrum
with distance, steeper the higher the band, is tested.  Its held-out
improvement of the mean squared band residual gets the paired block test of the
verdict (``band_holdout`` in the candidate).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from gisnoise.acoustics import atmospheric_absorption
from gisnoise.diagnose._rows import _band_entries, _effective_samples
from gisnoise.diagnose.verdict import _block_test, _rms
from gisnoise.measure import Samples

__all__ = ["absorption_band_holdout"]


def absorption_band_holdout(s: Samples, x: Mapping[str, Any], fold: np.ndarray, block: np.ndarray, *,
                            background_db: float | None = None, exclude: np.ndarray | None = None,
                            f_range: tuple[float, float] = (200.0, 10000.0),
                            above_floor_db: float = 10.0) -> dict[str, Any] | None:
    """Held-out test of uncorrected atmospheric absorption in the band levels, or None when it cannot be made.

    Parameters
    ----------
    s : Samples
        The samples (band levels needed).
    x : mapping
        Their model inputs (``meta`` with the weather).
    fold : ndarray of int
        Cross-validation fold (0 or 1) per sample.
    block : ndarray of int
        Block label per sample (paired test).
    background_db : float, optional
        The card's background level, dB(A): samples 15 dB above it are used (else each microphone's louder half).
    exclude : ndarray of bool, optional
        Samples not to use (windows of added sound: their spectrum is another source's).
    f_range : (float, float)
        Bands used, Hz.
    above_floor_db : float
        A band is used where it stands this far above its own quietest level (its background).

    Returns
    -------
    dict or None
        ``improvement_db2``, ``p_value`` (one-sided paired block test), ``rms_db_baseline``,
        ``rms_db_extended``, ``shrinkage_pct``, ``iso_multiple`` (the ISO multiple fitted without its >= 0 bound on all rows used) and
        ``iso_multiple_std``, ``n_rows``, ``n_bands``, ``what``.
    """
    meta = x.get("meta") or {}
    w = meta.get("weather") or {}
    if s.bands is None or s.band_f is None or w.get("temperature_c") is None or w.get("humidity_pct") is None:
        return None
    f = np.asarray(s.band_f, dtype=float)
    use_b = (f >= f_range[0]) & (f <= f_range[1])
    if use_b.sum() < 4:
        return None
    alpha = np.asarray(atmospheric_absorption(f[use_b], float(w["temperature_c"]), float(w["humidity_pct"]),
                                              float(w.get("pressure_kpa", 101.325))), dtype=float)  # dB/m
    bands = np.asarray(s.bands, dtype=float)[:, use_b]
    level = np.asarray(s.level, dtype=float)
    mics = s.mic.astype(str)
    d = np.asarray(s.d, dtype=float)
    # entries: a band well above its own quietest level (its background), on a loud sample
    ok = _band_entries(level, mics, bands, d, background_db=background_db, exclude=exclude,
                       above_floor_db=above_floor_db)
    good_b = ok.any(axis=0)
    if good_b.sum() < 4:
        return None
    rows = np.flatnonzero(ok.any(axis=1))
    fold = np.asarray(fold, dtype=int)
    if len(rows) < 100 or len(np.unique(fold[rows])) < 2:
        return None
    y = bands[rows] - level[rows, None]  # band level against the overall level: the spectrum's shape
    ok, d, fr = ok[rows], d[rows], fold[rows]
    jj = np.nonzero(ok)[1]
    ii = np.nonzero(ok)[0]

    def fit(sel_rows: np.ndarray, with_abs: bool) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Per-band means of y and d, common slope and ISO multiple (>= 0) on the entries of rows ``sel_rows``."""
        m = sel_rows[ii]
        cnt = np.bincount(jj[m], minlength=len(alpha))
        yb = np.bincount(jj[m], weights=y[ii[m], jj[m]], minlength=len(alpha)) / np.maximum(cnt, 1)
        db = np.bincount(jj[m], weights=d[ii[m]], minlength=len(alpha)) / np.maximum(cnt, 1)
        yc = y[ii[m], jj[m]] - yb[jj[m]]
        dc = d[ii[m]] - db[jj[m]]
        s0 = float(np.dot(dc, yc) / np.dot(dc, dc)) if np.dot(dc, dc) > 0 else 0.0
        if not with_abs:
            return yb, db, s0, 0.0
        a = np.column_stack([dc, -alpha[jj[m]] * dc])
        coef = np.linalg.lstsq(a, yc, rcond=None)[0]
        if coef[1] <= 0:
            return yb, db, s0, 0.0
        return yb, db, float(coef[0]), float(coef[1])

    def row_rms(sel_rows: np.ndarray, par: tuple[np.ndarray, np.ndarray, float, float]) -> np.ndarray:
        yb, db, s0, beta = par
        m = sel_rows[ii]
        e = y[ii[m], jj[m]] - yb[jj[m]] - (s0 - beta * alpha[jj[m]]) * (d[ii[m]] - db[jj[m]])
        cnt = np.bincount(ii[m], minlength=len(rows))
        return np.sqrt(np.bincount(ii[m], weights=e * e, minlength=len(rows)) / np.maximum(cnt, 1))[sel_rows]

    err0, err1 = np.empty(len(rows)), np.empty(len(rows))
    for k in (0, 1):
        tr, te = fr != k, fr == k
        err0[te] = row_rms(te, fit(tr, False))
        err1[te] = row_rms(te, fit(tr, True))
    imp, p = _block_test(err0, err1, np.asarray(block)[rows])
    all_rows = np.ones(len(rows), dtype=bool)
    yb, db, _, _ = fit(all_rows, False)  # per-band means of all rows used
    # the multiple and its standard error: unconstrained fit on all rows used, one effective sample per second
    # and microphone
    dc = d[ii] - db[jj]
    a = np.column_stack([dc, -alpha[jj] * dc])
    coef, *_ = np.linalg.lstsq(a, y[ii, jj] - yb[jj], rcond=None)
    resid = y[ii, jj] - yb[jj] - a @ coef
    n_eff = _effective_samples(s.t_e[rows], len(set(mics[rows].tolist())))
    try:
        cov = np.linalg.inv(a.T @ a) * float(np.mean(resid * resid)) * len(rows) / n_eff
        sd = float(math.sqrt(max(cov[1, 1], 0.0)))
    except np.linalg.LinAlgError:
        sd = math.inf
    return {"improvement_db2": imp, "p_value": p, "rms_db_baseline": _rms(err0), "rms_db_extended": _rms(err1),
            "shrinkage_pct": 100.0 * (1.0 - _rms(err1) / _rms(err0)) if _rms(err0) > 0 else 0.0,
            "iso_multiple": float(coef[1]), "iso_multiple_std": sd, "n_rows": len(rows),
            "n_bands": int(good_b.sum()),
            "what": "band levels against the overall level (loud samples, bands 10 dB above their floor): per-band "
                    "means and a common slope with distance, against those plus a multiple of the ISO 9613-1 "
                    "coefficients times distance, fitted on the other fold"}
