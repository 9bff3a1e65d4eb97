"""Background, level trend and disturbing events of microphone levels: why a row is masked
``low_snr`` or ``event``.

Per microphone and flight the background is, in this order: ``background_db`` of
campaign.json; the median level of the blocks whose emission lies outside the flight
log (8 or more; the UAV is not flying then, and the value must not exceed the quiet
end of the in-flight levels); the plateau ``B`` of :func:`fit_level_trend` when the
levels show it and the distances vary enough to tell it from the UAV; else NaN, and
then no row is masked ``low_snr``.
:func:`fit_level_trend` (spreading with distance, loudness with power, an offset per
phase, power-summed with the background) also gives each row's expected level; the
level minus it, on every microphone at once, is what :func:`detect_events` examines.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.measure.samples import series_ids

__all__ = ["detect_events", "fit_level_trend", "spreading_span_db", "DEFAULT_SNR_DB", "DEFAULT_EVENT_DB",
           "PLATEAU_SPAN_DB"]

DEFAULT_SNR_DB = 3.0
"""Rows whose level is below the background plus this, dB, are masked ``low_snr``."""
DEFAULT_EVENT_DB = 6.0
"""Joint rise on all microphones above the geometric trend that flags an ``event``, dB."""
EVENT_SMOOTHING_S = 0.5
PLATEAU_SPAN_DB = 10.0
"""Spherical spreading the distances of a series must span (``20 lg(d_95 / d_5)``, dB: a factor 3.2) before a
background plateau is estimated from its levels alone."""


def spreading_span_db(d: np.ndarray) -> float:
    """``20 lg(d_95 / d_5)``: the spherical spreading the distances ``d`` span between their 5th and 95th
    percentiles, dB (0 for fewer than two distances).

    >>> round(spreading_span_db(np.geomspace(30.0, 3000.0, 201)), 2)
    36.0
    >>> spreading_span_db(np.full(50, 58.3))
    0.0
    """
    d = np.asarray(d, dtype=float)
    d = d[np.isfinite(d) & (d > 0.0)]
    if d.size < 2:
        return 0.0
    lo, hi = np.percentile(d, [5.0, 95.0])
    return float(20.0 * np.log10(hi / lo))


def detect_events(t: Sequence[np.ndarray], excess_db: Sequence[np.ndarray], *, event_db: float = DEFAULT_EVENT_DB,
                  smoothing_s: float = EVENT_SMOOTHING_S) -> list[np.ndarray]:
    """Flag blocks where every microphone's level rises above its expectation at once.

    Parameters
    ----------
    t : sequence of arrays
        Reception times of each microphone's blocks, s (increasing).
    excess_db : sequence of arrays
        Level minus the expectation (geometric trend and background) per block, dB;
        NaN where unknown.
    event_db : float
        Joint rise that flags an event, dB; the flag extends over the neighbouring
        blocks while the joint rise stays above half of it.
    smoothing_s : float
        Width of the moving average applied to each excess first, s.

    Returns
    -------
    list of bool arrays
        Per microphone, True where the block lies in a joint rise.  With fewer than
        two microphones nothing is flagged (a rise on one microphone is geometry's
        or the UAV's as likely as an event's).

    Examples
    --------
    >>> t = [np.arange(10.0), np.arange(10.0) + 0.05]
    >>> e = [np.r_[np.zeros(5), 9, 9, 9, 0, 0], np.r_[np.zeros(5), 8, 8, 8, 0, 0]]
    >>> detect_events(t, e, smoothing_s=0.0)[0].astype(int).tolist()
    [0, 0, 0, 0, 0, 1, 1, 1, 0, 0]
    """
    n = len(t)
    out = [np.zeros(len(tt), dtype=bool) for tt in t]
    if n < 2:
        return out
    smooth = []
    for tt, e in zip(t, excess_db, strict=True):
        tt = np.asarray(tt, dtype=float)
        e = np.asarray(e, dtype=float)
        smooth.append((tt, _moving_mean(tt, e, smoothing_s)))
    for i, (ti, _) in enumerate(smooth):
        joint = np.full(len(ti), np.inf)
        for tj, ej in smooth:
            ok = np.isfinite(ej)
            if ok.sum() < 2:
                joint[:] = -np.inf
                break
            val = np.interp(ti, tj[ok], ej[ok], left=np.nan, right=np.nan)
            joint = np.fmin(joint, np.where(np.isnan(val), -np.inf, val))
        out[i] = _hysteresis(joint, event_db, 0.5 * event_db)
    return out


def _hysteresis(x: np.ndarray, high: float, low: float) -> np.ndarray:
    """True on the runs of ``x > low`` that contain at least one ``x > high``."""
    above = x > low
    if not above.any():
        return above
    run = np.cumsum(np.diff(np.concatenate([[False], above])).astype(bool) & above)  # run id of each start
    run = np.where(above, run, 0)
    hit = np.unique(run[(x > high) & above])
    return np.isin(run, hit[hit > 0])


def _moving_mean(t: np.ndarray, v: np.ndarray, width: float) -> np.ndarray:
    if width <= 0 or len(t) < 2:
        return v
    ok = np.isfinite(v)
    vv = np.where(ok, v, 0.0)
    c = np.concatenate([[0.0], np.cumsum(vv)])
    cn = np.concatenate([[0], np.cumsum(ok)])
    lo = np.searchsorted(t, t - width / 2, side="left")
    hi = np.searchsorted(t, t + width / 2, side="right")
    cnt = cn[hi] - cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, (c[hi] - c[lo]) / np.maximum(cnt, 1), np.nan)


def fit_level_trend(level: Any, d: Any, power_w: Any, *, phase: Any = None, use: Any = None,
                    background_db: float | None = None) -> tuple[np.ndarray, float] | None:
    """Robust fit of ``L = 10 log10(10^((a_phase + b log10(d/40) + c log10 P)/10) + 10^(B/10))``.

    The trend of one microphone during one flight (spreading with distance, loudness
    with power, one offset per flight phase) power-summed with a background plateau
    ``B``; soft-L1 loss (scale 1 dB) so events and directivity do not drag it.  The
    power term is left out when the power does not vary, a phase with fewer than 8
    rows shares the offset of the most common phase.

    The plateau is accepted only where the data show it: at least 10 % of the rows
    within 2 dB above ``B`` and at most 2 % more than 3 dB below it, and only where the
    distances vary enough to tell it from the UAV's own level (their spherical spreading
    spans :data:`PLATEAU_SPAN_DB` or more, :func:`spreading_span_db`): at a steady
    distance (a hover) a steady level is the UAV's as well as a background's, and the
    quiet directions of a turning UAV would be taken for the background.  Otherwise the
    background is not determined (``B`` is NaN) and the trend is refitted alone.

    Parameters
    ----------
    level : array_like
        Levels, dB(A).
    d : array_like
        Distances, m.
    power_w : array_like
        Electric power, W.
    phase : array_like of str, optional
        Flight phase of each row.
    use : array_like of bool, optional
        Rows to fit (default all).
    background_db : float, optional
        Known background; only the trend is fitted then.

    Returns
    -------
    (expected, B) or None
        Expected level of every row, dB(A), and the background, dB(A) (NaN when not
        determined); None with fewer than 8 rows to fit.

    Examples
    --------
    >>> d = np.geomspace(30.0, 3000.0, 200)
    >>> L = 10 * np.log10(10 ** ((70 - 20 * np.log10(d / 40)) / 10) + 10 ** 4.0)
    >>> expected, b = fit_level_trend(L, d, np.full(200, 1000.0))
    >>> round(b, 3), round(float(np.max(np.abs(expected - L))), 3)
    (40.0, 0.0)
    >>> expected, b = fit_level_trend(L[:100], d[:100], np.full(100, 1000.0))  # never near 40 dB
    >>> b
    nan
    """
    from scipy.optimize import least_squares

    level = np.asarray(level, dtype=float)
    n = len(level)
    ld = np.log10(np.maximum(np.asarray(d, dtype=float), 1e-3) / 40.0)
    p = np.maximum(np.asarray(power_w, dtype=float), 1e-9)
    use = np.ones(n, dtype=bool) if use is None else np.asarray(use, dtype=bool)
    if use.sum() < 8:
        return None
    ph = np.full(n, "", dtype=object) if phase is None else np.asarray(phase, dtype=object)
    names, counts = np.unique(ph[use].astype(str), return_counts=True)
    main = names[int(np.argmax(counts))]
    kept = [str(nm) for nm, c in zip(names, counts, strict=True) if c >= 8 and nm != main]
    offsets = [np.ones(n)] + [(ph == nm).astype(float) for nm in kept]  # main phase + differences
    lp = np.log10(p / np.median(p[use]))
    cols = offsets + [ld] + ([lp] if np.std(lp[use]) > 1e-3 else [])
    a = np.column_stack(cols)
    k = a.shape[1]
    i_b = len(offsets)  # column of log10(d / 40)
    lv, au = level[use], a[use]
    top = lv >= np.median(lv)
    coef0, *_ = np.linalg.lstsq(au[top] if top.sum() >= 2 * k else au, lv[top] if top.sum() >= 2 * k else lv,
                                rcond=None)
    ln10 = np.log(10.0) / 10.0
    lower = [-np.inf] * k
    upper = [np.inf] * k
    lower[i_b], upper[i_b] = -60.0, 20.0
    x0 = np.array(coef0, dtype=float)
    x0[i_b] = float(np.clip(x0[i_b], -59.0, 19.0))

    def solve(bg: float | None) -> tuple[np.ndarray, float]:
        if bg is not None:
            def resid(x: np.ndarray) -> np.ndarray:
                return np.logaddexp(au @ x * ln10, bg * ln10) / ln10 - lv
            r = least_squares(resid, x0, bounds=(lower, upper), loss="soft_l1", f_scale=1.0)
            return r.x, bg
        lo_b = float(lv.min()) - 30.0
        xb = np.append(x0, np.clip(np.percentile(lv, 5.0) - 1.0, lo_b + 1e-6, lv.max() - 1e-6))

        def resid_b(x: np.ndarray) -> np.ndarray:
            return np.logaddexp(au @ x[:k] * ln10, x[k] * ln10) / ln10 - lv
        r = least_squares(resid_b, xb, bounds=(lower + [lo_b], upper + [float(lv.max())]), loss="soft_l1",
                          f_scale=1.0)
        return r.x[:k], float(r.x[k])

    if background_db is not None:
        x, b = solve(float(background_db))
    elif spreading_span_db(np.asarray(d, dtype=float)[use]) < PLATEAU_SPAN_DB:
        x, b = solve(-np.inf)  # the UAV's level cannot be told from a plateau at a steady distance
        b = float("nan")
    else:
        x, b = solve(None)
        if np.mean(lv < b + 2.0) < 0.10 or np.mean(lv < b - 3.0) > 0.02:
            x, b = solve(-np.inf)
            b = float("nan")
    expected = np.logaddexp(a @ x * ln10, (b if np.isfinite(b) else -np.inf) * ln10) / ln10
    return expected, b


def _quiet_background(level: np.ndarray, quiet: np.ndarray, flying: np.ndarray) -> float | None:
    """Median level of the blocks whose emission lies outside the flight log (at least 8 of them),
    unless it is not below the quiet end of the in-flight levels (then the UAV was audible)."""
    if quiet.sum() < 8:
        return None
    b = float(np.median(level[quiet]))
    if flying.sum() >= 8 and b > float(np.percentile(level[flying], 5.0)) + 1.0:
        return None
    return b


def _background_and_excess(given: Mapping[str, float | None], mic: np.ndarray, flight: np.ndarray,
                           cat: Mapping[str, np.ndarray], level: np.ndarray, outside: np.ndarray,
                           excluded: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Background per row, level minus expectation per row, and how each background was found.

    ``given`` maps a microphone id to the background campaign.json states for it (or None).
    """
    n = len(level)
    background = np.full(n, np.nan)
    excess = np.full(n, np.nan)
    how: list[dict[str, Any]] = []
    sid = series_ids(mic, flight)
    for s in range(int(sid.max()) + 1 if n else 0):
        idx = np.flatnonzero(sid == s)
        mid, fid = mic[idx[0]], flight[idx[0]]
        use = ~(outside[idx] | excluded[idx])
        bg, source = given.get(mid), "campaign.json"
        if bg is None:
            bg, source = _quiet_background(level[idx], outside[idx] & ~excluded[idx], use), "outside_flight"
        fit = fit_level_trend(level[idx], cat["d"][idx], cat["power_w"][idx], phase=cat["phase"][idx],
                              use=use, background_db=bg)
        if fit is None:
            background[idx] = np.nan if bg is None else bg
            how.append({"mic": str(mid), "flight": str(fid), "background_db": background[idx[0]],
                        "source": source if bg is not None else "none"})
            continue
        expected, b = fit
        if bg is None:
            source = "plateau_fit" if np.isfinite(b) else "none"
        background[idx] = b
        how.append({"mic": str(mid), "flight": str(fid), "background_db": float(b), "source": source})
        ex = level[idx] - expected
        ex[~use] = np.nan
        excess[idx] = ex - np.nanmedian(ex)
    return background, excess, how
