"""Diagnosis of the sim-to-real gap: where the model misses, which effect explains it, how far it shrinks.

Given measured samples and a model card, :func:`diagnose` answers three questions
(paper sections 5.3.1-5.3.3, done there by hand):

Localization
    The card's residual (measured minus model, dB) is smoothed per microphone
    and flight over a window of ``window_s`` seconds; where the smoothed residual
    is larger than the measurement noise explains (``z`` standard errors of a
    window mean, estimated from differences of adjacent window means so that
    coloured noise counts with its correlation), the samples are flagged and
    joined into segments.  The measurement noise per microphone is the robust
    spread of first differences of the residual (``1.4826 MAD / sqrt 2``): fast
    scatter is noise, slow structure is model error.  Each segment carries its
    regime (turn, straight, climb, sink, hover, transition), range (near, far)
    and microphone; statistics are given by regime, microphone and geometry bins.

Attribution
    Every candidate of the effect library (:mod:`gisnoise.model.effects`) that the
    data can test is fitted as an extension of the card's ansatz with the
    output-error fitter (:func:`gisnoise.identify.fit.fit_arrays`) on all data and in a
    two-fold cross-validation (folds are whole flights, or alternating time
    blocks when there is one flight).  A candidate is *significant* when the
    Wald statistic of its extension parameters, with the covariance corrected
    for residual autocorrelation (Morelli & Klein), rejects "no effect" at
    ``alpha`` divided by the number of candidates tested (Bonferroni).
    Candidates are ranked by their held-out improvement of the mean squared
    residual; the verdict names the best significant candidate whose held-out
    improvement reaches :data:`MIN_IMPROVEMENT_DB2` and is significant in a
    paired test over time blocks, with physical evidence (turn excess, band
    slopes, comb pattern, fore/aft asymmetry, ...) breaking near ties.
    Otherwise the verdict is null.

Shrinkage
    Baseline and extended RMS residual on the fitted data and on held-out data
    (out-of-fold predictions: every sample is predicted by a model not fitted to
    it), overall and per segment; the base parameters each effect had biased are
    named (shift larger than ``bias_z`` corrected standard deviations).

The output is a JSON-able dict in the shape of the product specification,
section 6 (``baseline``, ``segments``, ``effects``, ``verdict``) with more detail.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import stats

from gisnoise.errors import Cancelled, FitError, GisnoiseError, InputError, NotIdentifiableError
from gisnoise.identify import FitResult, fit_arrays
from gisnoise.measure import Samples
from gisnoise.model import Ansatz, ModelCard, level_sum
from gisnoise.model import effects as _effects

__all__ = [
    "SCHEMA",
    "Diagnosis",
    "diagnose",
    "run_diagnosis",
    "load_samples",
    "measurement_noise",
    "sample_regimes",
    "localize",
    "detect_events",
    "fold_labels",
    "register_evidence",
]

SCHEMA = "gisnoise/diagnosis/1"
ProgressFn = Callable[[int, int, str], None]
CancelFn = Callable[[], bool]

TURN_BANK_DEG = 10.0
"""A horizontal-flight sample with |bank| above this is in a turn, deg."""
VERTICAL_SPEED_M_S = 1.5
"""Climb or sink when the vertical speed exceeds this, m/s."""
HOVER_SPEED_M_S = 2.0
"""Hover when the ground speed is below this, m/s."""
FIT_TOL = 1e-9
"""Relative cost tolerance of the refits (a fit still creeping after 300 iterations is used as it stands)."""
MIN_IMPROVEMENT_DB2 = 0.005
"""Smallest held-out improvement of the mean squared residual (dB^2) a verdict needs: an effect
whose removal takes less (an RMS contribution below about 0.07 dB) does not matter in practice."""


# --------------------------------------------------------------------------- data


def load_samples(source: Any) -> Samples:
    """Samples from a campaign folder, a :class:`~gisnoise.measure.campaign.Campaign` or :class:`Samples`."""
    if isinstance(source, Samples):
        return source
    if isinstance(source, (str, os.PathLike)):
        from gisnoise.measure import read_campaign

        return _with_mic_heights(read_campaign(source).samples(), source)
    if hasattr(source, "samples") and callable(source.samples):
        s = source.samples()
        if isinstance(s, Samples):
            return s
    raise InputError(f"campaign: expected a campaign folder, Campaign or Samples, got {type(source).__name__}",
                     field="campaign")


def _with_mic_heights(s: Samples, folder: str | os.PathLike[str]) -> Samples:
    """Add the microphones' ``height_agl_m`` from campaign.json to the samples' facts when the reader left it out."""
    import json
    from pathlib import Path

    mics = (s.meta or {}).get("microphones")
    try:
        doc = json.loads((Path(folder) / "campaign.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return s
    heights = {m.get("id"): m["height_agl_m"] for m in doc.get("microphones", [])
               if isinstance(m, Mapping) and isinstance(m.get("height_agl_m"), (int, float))}
    if not heights or not isinstance(mics, Mapping):
        return s
    merged = {k: ({**v, "height_agl_m": heights[k]} if k in heights and "height_agl_m" not in v else v)
              for k, v in mics.items()}
    return s.with_(meta={**s.meta, "microphones": merged})


def _series(s: Samples) -> np.ndarray:
    key = np.char.add(np.char.add(s.mic.astype(str), "\x00"), s.flight.astype(str))
    return np.unique(key, return_inverse=True)[1].ravel()


def _runs(sid: np.ndarray, t: np.ndarray) -> list[np.ndarray]:
    """Row indices of each series in time order."""
    order = np.lexsort((t, sid))
    cuts = np.flatnonzero(np.diff(sid[order])) + 1
    return [o for o in np.split(order, cuts) if len(o)]


# --------------------------------------------------------------------------- noise and regimes


def measurement_noise(resid: np.ndarray, sid: np.ndarray, t: np.ndarray, mic: np.ndarray) -> dict[str, float]:
    """White measurement-noise standard deviation per microphone, dB.

    ``1.4826 MAD(diff r) / sqrt(2)`` over the first differences of the residual
    inside each series: slow model error cancels in the differences, the fast
    scatter of the measurement remains.

    >>> rng = np.random.default_rng(0)
    >>> t = np.arange(4000) * 0.125
    >>> r = 3.0 * np.sin(t / 20.0) + rng.normal(0.0, 0.8, t.size)  # slow model error + noise
    >>> round(measurement_noise(r, np.zeros(t.size, int), t, np.full(t.size, "m1"))["m1"], 1)
    0.8
    """
    out: dict[str, list[np.ndarray]] = {}
    for idx in _runs(sid, t):
        if len(idx) < 3:
            continue
        out.setdefault(str(mic[idx[0]]), []).append(np.diff(resid[idx]))
    res = {}
    for m, parts in out.items():
        dd = np.concatenate(parts)
        res[m] = float(1.4826 * np.median(np.abs(dd - np.median(dd))) / math.sqrt(2.0))
    return res


def sample_regimes(s: Samples) -> np.ndarray:
    """Flight regime of each sample: turn, straight, climb, sink, hover or transition.

    ``hover``: ground speed below :data:`HOVER_SPEED_M_S` or phase hover; ``climb``/``sink``:
    those phases, or vertical speed beyond :data:`VERTICAL_SPEED_M_S`; ``turn``: |bank|
    above :data:`TURN_BANK_DEG`; else ``straight``.  Speeds are 2 s running means.
    """
    n = len(s)
    reg = np.full(n, "straight", dtype=object)
    # velocities differentiated from logged positions are noisy: judge them over ~2 s
    vz = np.empty(n)
    speed = np.empty(n)
    for idx in _runs(_series(s), s.t_e):
        dt = float(np.median(np.diff(s.t_e[idx]))) if len(idx) > 1 else 1.0
        k = max(1, int(round(2.0 / max(dt, 1e-6))))
        vz[idx] = _rolling_mean(s.vel_enu[idx, 2], k)
        speed[idx] = _rolling_mean(np.linalg.norm(s.vel_enu[idx, :2], axis=1), k)
    turn = np.abs(s.roll) > TURN_BANK_DEG
    reg[turn] = "turn"
    reg[(vz > VERTICAL_SPEED_M_S) & ~turn] = "climb"
    reg[(vz < -VERTICAL_SPEED_M_S) & ~turn] = "sink"
    ph = s.phase.astype(str)
    for p in ("climb", "sink", "hover", "transition"):
        reg[ph == p] = p
    reg[(speed < HOVER_SPEED_M_S) & (np.abs(vz) < VERTICAL_SPEED_M_S)] = "hover"
    return reg.astype(str)


def _rolling_mean(v: np.ndarray, n_w: int) -> np.ndarray:
    if len(v) < n_w:
        return np.full(len(v), float(np.mean(v)))
    c = np.convolve(v, np.ones(n_w) / n_w, mode="same")
    # edges: shrink the window instead of padding with zeros
    k = np.convolve(np.ones(len(v)), np.ones(n_w) / n_w, mode="same")
    return c / k


# --------------------------------------------------------------------------- localization


@dataclass
class _Series:
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


def _smoothed(resid, sid, t, mic, flight, noise, window_s, z, relative=False):
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
    runs = []
    for a, b in zip(starts, ends, strict=True):
        if runs and t[a] - t[runs[-1][1]] <= join_gap_s:
            runs[-1] = (runs[-1][0], b)
        else:
            runs.append((a, b))
    return [(a, b) for a, b in runs if t[b] - t[a] >= min_len_s]


def localize(
    s: Samples,
    resid: np.ndarray,
    noise: Mapping[str, float],
    *,
    window_s: float = 2.0,
    z: float = 4.0,
    min_excess_db: float = 0.5,
    regimes: np.ndarray | None = None,
) -> tuple[list[dict[str, Any]], np.ndarray]:
    """Segments per microphone and flight where the residual exceeds what noise explains.

    Parameters
    ----------
    s : Samples
        The samples (emission time ``t_e`` is the time axis).
    resid : ndarray
        Measured minus model, dB, per sample.
    noise : mapping
        White measurement-noise standard deviation per microphone, dB.
    window_s : float
        Smoothing window, s.
    z : float
        Threshold in standard errors.
    min_excess_db : float
        Smallest flagged smoothed residual, dB.
    regimes : ndarray of str, optional
        Regime per sample (default :func:`sample_regimes`).

    Returns
    -------
    segments : list of dict
        ``flight``, ``mic``, ``t0``, ``t1`` (emission time, s), ``rms_db``, ``mean_db``,
        ``excess_db`` (mean smoothed residual), ``n``, ``regime``,
        ``range`` (near or far), ``d_median_m``, ``bank_abs_mean_deg``.
    flagged : ndarray of bool
        Samples inside a segment.
    """
    reg = sample_regimes(s) if regimes is None else regimes
    sid = _series(s)
    flagged = np.zeros(len(s), dtype=bool)
    d_med = float(np.median(s.d)) if len(s) else 0.0
    segs = []
    for ser in _smoothed(resid, sid, s.t_e, s.mic, s.flight, noise, window_s, z):
        mask = (np.abs(ser.excess) > ser.threshold) & (np.abs(ser.excess) >= min_excess_db)
        dt = window_s / ser.n_w
        for a, b in _intervals(mask, ser.t, min_len_s=window_s / 2, join_gap_s=window_s / 2 + dt):
            rows = ser.idx[a:b + 1]
            flagged[rows] = True
            r = resid[rows]
            vals, counts = np.unique(reg[rows], return_counts=True)
            segs.append({
                "flight": ser.flight, "mic": ser.mic,
                "t0": float(ser.t[a]), "t1": float(ser.t[b]),
                "rms_db": float(np.sqrt(np.mean(r * r))), "mean_db": float(np.mean(r)),
                "excess_db": float(np.mean(ser.excess[a:b + 1])), "n": int(len(rows)),
                "regime": str(vals[np.argmax(counts)]),
                "range": "near" if float(np.median(s.d[rows])) <= d_med else "far",
                "d_median_m": float(np.median(s.d[rows])),
                "bank_abs_mean_deg": float(np.mean(np.abs(s.roll[rows]))),
            })
    segs.sort(key=lambda g: (g["flight"], g["t0"], g["mic"]))
    return segs, flagged


def _group_stats(resid: np.ndarray, labels: np.ndarray, flagged: np.ndarray, order: Sequence[str] | None = None):
    out = []
    keys = list(order) if order is not None else sorted(set(labels.tolist()))
    for k in keys:
        m = labels == k
        if not m.any():
            continue
        r = resid[m]
        out.append({"bin": str(k), "n": int(m.sum()), "mean_db": float(np.mean(r)),
                    "rms_db": float(np.sqrt(np.mean(r * r))), "flagged_fraction": float(np.mean(flagged[m]))})
    return out


def _statistics(s: Samples, resid: np.ndarray, flagged: np.ndarray, reg: np.ndarray) -> dict[str, Any]:
    d_edges = np.unique(np.quantile(s.d, [0.0, 0.25, 0.5, 0.75, 1.0]))
    d_bin = np.clip(np.searchsorted(d_edges, s.d, side="right") - 1, 0, max(len(d_edges) - 2, 0))
    d_lab = np.array([f"{d_edges[i]:.0f}-{d_edges[i + 1]:.0f} m" if len(d_edges) > 1 else "all" for i in d_bin])
    th = np.degrees(s.theta)
    th_edges = [-90.0, -60.0, -30.0, 0.0, 30.0, 90.0]
    th_i = np.clip(np.searchsorted(th_edges, th, side="right") - 1, 0, len(th_edges) - 2)
    th_lab = np.array([f"{th_edges[i]:+.0f}..{th_edges[i + 1]:+.0f} deg" for i in th_i])
    az = np.degrees(s.phi)
    sector = np.mod(np.round(az / 45.0), 8).astype(int)
    names = ["ahead", "ahead-starboard", "starboard", "aft-starboard", "aft", "aft-port", "port", "ahead-port"]
    az_lab = np.array([names[i] for i in sector])
    corr_inputs = {"bank_abs": np.abs(s.roll), "distance": s.d, "polar": s.theta, "azimuth": s.phi,
                   "power": s.power_w, "speed": np.linalg.norm(s.vel_enu, axis=1)}
    if s.rpm is not None:
        corr_inputs["rpm"] = s.rpm
    corr = {}
    for k, v in corr_inputs.items():
        v = np.asarray(v, dtype=float)
        ok = np.isfinite(v)
        corr[k] = float(np.corrcoef(v[ok], resid[ok])[0, 1]) if ok.sum() > 2 and np.std(v[ok]) > 0 else None
    return {
        "by_regime": _group_stats(resid, reg, flagged, ["straight", "turn", "climb", "sink", "hover", "transition"]),
        "by_mic": _group_stats(resid, s.mic.astype(str), flagged),
        "by_flight": _group_stats(resid, s.flight.astype(str), flagged),
        "by_distance": _group_stats(resid, d_lab, flagged, list(dict.fromkeys(d_lab[np.argsort(s.d)]))),
        "by_polar": _group_stats(resid, th_lab, flagged, [f"{a:+.0f}..{b:+.0f} deg"
                                                          for a, b in zip(th_edges[:-1], th_edges[1:], strict=True)]),
        "by_azimuth": _group_stats(resid, az_lab, flagged, names),
        "correlation_with_residual": corr,
    }


# --------------------------------------------------------------------------- events


def _best_level(meas: np.ndarray, add: Callable[[np.ndarray], np.ndarray], grid: np.ndarray) -> tuple[float, float]:
    """Grid minimum of ``sum (meas - add(g))^2`` over ``g``: (SSE, g)."""
    pred = add(grid[:, None])
    sse = np.sum((meas[None, :] - pred) ** 2, axis=1)
    i = int(np.argmin(sse))
    return float(sse[i]), float(grid[i])


def _explain_window(level, l_uav, bg, sub, mic_idx, flagged_mics):
    """BIC of three explanations of a window's excess: UAV gain, area event, local event.

    ``sub`` is the sub-window index of each row, ``mic_idx`` its microphone index.
    Gain: one dB gain of the UAV level per sub-window, common to all microphones;
    area event: one added level per sub-window, common to all microphones;
    local event: one added level per sub-window on each flagged microphone only.
    """
    base = level_sum(l_uav, bg)
    n = len(level)
    g_grid = np.arange(-10.0, 25.01, 0.25)
    b_lo = float(np.min(base)) - 30.0
    b_grid = np.arange(b_lo, float(np.max(level)) + 5.0, 0.25)
    sse = {"gain": 0.0, "area": 0.0, "local": 0.0}
    k = {"gain": 0, "area": 0, "local": 0}
    for j in np.unique(sub):
        m = sub == j
        sse_g, _ = _best_level(level[m], lambda g, m=m: level_sum(l_uav[m][None, :] + g, bg[m][None, :]), g_grid)
        sse_a, _ = _best_level(level[m], lambda b, m=m: level_sum(base[m][None, :], b), b_grid)
        sse["gain"] += sse_g
        sse["area"] += sse_a
        k["gain"] += 1
        k["area"] += 1
        for mi in np.unique(mic_idx[m]):
            mm = m & (mic_idx == mi)
            if mi in flagged_mics:
                s_l, _ = _best_level(level[mm], lambda b, mm=mm: level_sum(base[mm][None, :], b), b_grid)
                k["local"] += 1
            else:
                s_l = float(np.sum((level[mm] - base[mm]) ** 2))
            sse["local"] += s_l
    return {name: n * math.log(max(v, 1e-12) / n) + k[name] * math.log(n) for name, v in sse.items()}


def detect_events(
    s: Samples,
    resid: np.ndarray,
    noise: Mapping[str, float],
    l_uav: np.ndarray,
    background_db: np.ndarray,
    *,
    window_s: float = 1.0,
    z: float = 5.0,
    min_db: float = 3.0,
    max_s: float = 180.0,
    sub_s: float = 5.0,
    min_bic: float = 10.0,
) -> tuple[np.ndarray, list[dict[str, Any]]]:
    """Windows of transient sound from sources other than the UAV.

    Candidates are runs (``window_s / 2`` to ``max_s`` long) where the smoothed
    residual of a microphone rises above its series median by more than
    ``min_db`` and ``z`` standard errors of the window mean, and runs the campaign
    reader masked as ``event``.  Overlapping candidates of one flight form a
    window.  A window counts as an event only when added sound explains it
    better than a louder UAV (the reader's mask is a hint, not a proof): within sub-windows of ``sub_s`` seconds the
    measured levels of all microphones are fitted (a) with a gain of the UAV
    level common to all microphones (an unmodelled UAV effect), (b) with a level
    added energetically at every microphone (a distant source heard by all) and
    (c) with a level added at the rising microphones only (a local source); the
    window is an event when (b) or (c) beats (a) by ``min_bic`` in the Bayesian
    information criterion.  Added sound lifts quiet microphones by more dB than
    loud ones; a louder UAV lifts every microphone it dominates by the same dB.

    Parameters
    ----------
    s : Samples
        The samples.
    resid : ndarray
        Measured minus model level, dB.
    noise : mapping
        White measurement-noise standard deviation per microphone, dB.
    l_uav, background_db : ndarray
        Model UAV level and background level per sample, dB.

    Returns
    -------
    window : ndarray of int
        Event parameter index per sample (one per window, sub-window and, for a
        local event, microphone), -1 outside events.
    windows : list of dict
        ``flight``, ``t0``, ``t1`` (emission time, s), ``mics``, ``kind`` (area or
        local), ``source`` (detector or reader), ``excess_db`` (largest mean rise),
        ``z``, ``bic_gain_minus_event``, ``parameters`` (indices).
    """
    sid = _series(s)
    out = np.full(len(s), -1, dtype=int)
    series = _smoothed(resid, sid, s.t_e, s.mic, s.flight, noise, window_s, z, relative=True)
    cands: dict[str, list[tuple[float, float, str, str, float, float]]] = {}
    for ser in series:
        reader = s.mask_reason[ser.idx] == "event"
        for a, b in _intervals(reader, ser.t, min_len_s=0.0, join_gap_s=window_s):
            ex = float(np.mean(ser.excess[a:b + 1]))
            zz = ex / (ser.threshold / z) if ser.threshold > 0 else np.inf
            cands.setdefault(ser.flight, []).append((ser.t[a], ser.t[b], ser.mic, "reader", ex, zz))
        mask = (ser.excess > max(min_db, ser.threshold)) & ~reader
        for a, b in _intervals(mask, ser.t, min_len_s=window_s / 2, join_gap_s=window_s / 2):
            if ser.t[b] - ser.t[a] > max_s:
                continue
            ex = float(np.mean(ser.excess[a:b + 1]))
            zz = ex / (ser.threshold / z) if ser.threshold > 0 else np.inf
            cands.setdefault(ser.flight, []).append((ser.t[a], ser.t[b], ser.mic, "detector", ex, zz))
    mics_all = np.unique(s.mic.astype(str))
    mic_idx = np.searchsorted(mics_all, s.mic.astype(str))
    found: list[dict[str, Any]] = []
    n_par = 0
    for fl, runs in sorted(cands.items()):
        runs.sort()
        clusters: list[list[tuple]] = []
        for r in runs:
            if clusters and r[0] <= max(c[1] for c in clusters[-1]) + 2.0 * window_s:
                clusters[-1].append(r)
            else:
                clusters.append([r])
        in_flight = s.flight.astype(str) == fl
        for cl in clusters:
            t0, t1 = min(c[0] for c in cl), max(c[1] for c in cl)
            rows = np.flatnonzero(in_flight & (s.t_e >= t0) & (s.t_e <= t1))
            if len(rows) < 4:
                continue
            rising = {c[2] for c in cl}
            src = "reader" if any(c[3] == "reader" for c in cl) else "detector"
            sub = np.floor((s.t_e[rows] - t0) / sub_s).astype(int)
            flagged = {int(np.searchsorted(mics_all, m)) for m in rising}
            bic = _explain_window(s.level[rows], l_uav[rows], background_db[rows], sub, mic_idx[rows], flagged)
            kind = "area" if bic["area"] <= bic["local"] else "local"
            margin = bic["gain"] - bic[kind]
            if margin < min_bic:
                continue
            params = []
            for j in np.unique(sub):
                m = sub == j
                if kind == "area":
                    out[rows[m]] = n_par
                    params.append(n_par)
                    n_par += 1
                else:
                    for mi in sorted(flagged):
                        mm = m & (mic_idx[rows] == mi)
                        if mm.any():
                            out[rows[mm]] = n_par
                            params.append(n_par)
                            n_par += 1
            zs = [c[5] for c in cl if np.isfinite(c[5])]
            found.append({"flight": fl, "t0": float(t0), "t1": float(t1), "mics": sorted(rising), "kind": kind,
                          "source": src, "excess_db": float(max(c[4] for c in cl)),
                          "z": float(max(zs)) if zs else None, "bic_gain_minus_event": float(margin),
                          "parameters": params})
    return out, found


# --------------------------------------------------------------------------- folds


def fold_labels(s: Samples, *, block_s: float = 30.0) -> tuple[np.ndarray, np.ndarray, str]:
    """Two cross-validation folds and the time blocks of the paired held-out test.

    With two or more flights the flights alternate between the folds; with one
    flight, consecutive ``block_s`` blocks of emission time alternate (the same
    block of every microphone goes to the same fold).

    Returns ``(fold, block, how)``: fold 0/1 per sample, block label per sample
    (one per microphone and time block), and ``"flights"`` or ``"time blocks"``.
    """
    flights = sorted(set(s.flight.astype(str).tolist()))
    tb = np.floor(s.t_e / block_s).astype(int)
    block_key = np.char.add(np.char.add(np.char.add(s.flight.astype(str), "\x00"), s.mic.astype(str)),
                            np.char.add("\x00", tb.astype(str)))
    block = np.unique(block_key, return_inverse=True)[1].ravel()
    if len(flights) >= 2:
        idx = {f: i % 2 for i, f in enumerate(flights)}
        return np.array([idx[f] for f in s.flight.astype(str)], dtype=int), block, "flights"
    t0 = float(np.min(s.t_e)) if len(s) else 0.0
    fold = (np.floor((s.t_e - t0) / block_s).astype(int) % 2).astype(int)
    return fold, block, "time blocks"


# --------------------------------------------------------------------------- evidence

Evidence = Callable[["_Context", "_Candidate"], dict[str, Any]]
_EVIDENCE: dict[str, Evidence] = {}


def register_evidence(name: str, fn: Evidence) -> Evidence:
    """Register the physical-evidence check of effect ``name``.

    ``fn(context, candidate) -> dict`` with at least ``supports`` (True, False or
    None when the data cannot tell) and ``summary`` (one line).
    """
    _EVIDENCE[name] = fn
    return fn


def _corr(a: np.ndarray, b: np.ndarray) -> float | None:
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.std(a[ok]) == 0 or np.std(b[ok]) == 0:
        return None
    return float(np.corrcoef(a[ok], b[ok])[0, 1])


def _ev_bank(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    r = ctx.resid_base
    turn = ctx.regimes == "turn"
    straight = ctx.regimes == "straight"
    c = _corr(np.abs(np.sin(ctx.s.bank)), r)
    diff = float(np.mean(r[turn]) - np.mean(r[straight])) if turn.any() and straight.any() else None
    sup = None if diff is None or c is None else bool(diff > 0 and c > 0.05)
    return {"supports": sup, "turn_minus_straight_db": diff, "corr_residual_abs_sin_bank": c,
            "summary": (f"turns {diff:+.2f} dB against straight flight, correlation with |sin bank| {c:+.2f}"
                        if diff is not None and c is not None else "no turns and straight flight to compare")}


def _ev_absorption(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    s = ctx.s
    if s.bands is None or s.band_f is None:
        return {"supports": None, "summary": "no band levels"}
    try:
        from gisnoise.acoustics import atmospheric_absorption
    except ImportError:
        return {"supports": None, "summary": "ISO 9613-1 absorption not available"}
    w = (s.meta or {}).get("weather") or {}
    if w.get("temperature_c") is None or w.get("humidity_pct") is None:
        return {"supports": None, "summary": "no temperature and humidity in the campaign"}
    f = np.asarray(s.band_f, dtype=float)
    alpha = np.asarray(atmospheric_absorption(f, float(w["temperature_c"]), float(w["humidity_pct"]),
                                              float(w.get("pressure_kpa", 101.325))), dtype=float)
    bands = np.asarray(s.bands, dtype=float)
    bg = ctx.background_db
    loud = s.level > (bg + 15.0 if bg is not None else np.percentile(s.level, 50))
    slopes, al = [], []
    for j in range(len(f)):
        y = bands[:, j] - s.level
        ok = loud & np.isfinite(y)
        if ok.sum() < 30 or np.ptp(s.d[ok]) < 50.0:
            continue
        # keep rows where this band stands well above its own quietest level (its background)
        floor = np.nanpercentile(bands[:, j], 5)
        ok &= bands[:, j] > floor + 10.0
        if ok.sum() < 30 or np.ptp(s.d[ok]) < 50.0:
            continue
        slopes.append(np.polyfit(s.d[ok], y[ok], 1)[0])
        al.append(alpha[j])
    if len(slopes) < 3:
        return {"supports": None, "summary": "too few band levels above background to see band slopes"}
    sl, al_ = np.array(slopes), np.array(al)
    beta = float(np.polyfit(al_, sl, 1)[0])
    c = _corr(al_, sl)
    sup = bool(beta < -0.3 and c is not None and c < -0.5)
    return {"supports": sup, "band_slope_vs_iso_alpha": beta, "corr_band_slope_iso_alpha": c, "n_bands": len(sl),
            "summary": f"band level slopes with distance follow -{-beta:.2f} x ISO 9613-1 alpha "
                       f"(correlation {c:+.2f} over {len(sl)} bands; -1 means uncorrected absorption)"}


def _ev_ground(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    if cand.fit is None:
        return {"supports": None, "summary": "not fitted"}
    p = cand.fit.params
    tau = _effects.reflection_delay(ctx.x)
    up = np.isfinite(tau)
    r = ctx.resid_base
    cb, _ = _effects.band_cos(2.0 * np.pi * p["f_ground"] * tau[up], False)
    pattern = 10.0 * np.log10(1.0 + p["r_ground"] ** 2 + 2.0 * p["r_ground"] * cb)
    c = _corr(pattern, r[up])
    lift = float(np.mean(r[up]) - np.mean(r[~up])) if (~up).any() else None
    sup = bool(p["r_ground"] > 0.1 and ((c is not None and c > 0.1) or (lift is not None and lift > 0.5)))
    words = [f"R = {p['r_ground']:.2f} at {p['f_ground']:.0f} Hz"]
    if c is not None:
        words.append(f"elevated microphones' residual follows the interference comb with correlation {c:+.2f}")
    if lift is not None:
        words.append(f"they read {lift:+.2f} dB against microphones on the ground")
    return {"supports": sup, "corr_residual_comb": c, "elevated_minus_ground_db": lift, "r_ground": p["r_ground"],
            "f_ground_hz": p["f_ground"], "summary": "; ".join(words)}


def _ev_doppler(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    m = _effects.mach_towards(ctx.x)
    hi = np.max(np.abs(m)) if len(m) else 0.0
    fore, aft = m > 0.3 * hi, m < -0.3 * hi
    if not fore.any() or not aft.any():
        return {"supports": None, "summary": "no approaching and receding samples to compare"}
    diff = float(np.mean(ctx.resid_base[fore]) - np.mean(ctx.resid_base[aft]))
    expect = float(np.mean(-10 * np.log10(1 - m[fore])) - np.mean(-10 * np.log10(1 - m[aft])))
    return {"supports": bool(diff > 0), "fore_minus_aft_db": diff, "fore_minus_aft_per_unit_q_db": expect,
            "summary": f"approaching {diff:+.2f} dB against receding (convective amplification gives "
                       f"{expect:+.2f} dB per unit exponent)"}


def _ev_emission(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    cov = _effects.emission_covariates({**ctx.x})
    rate = np.zeros(len(ctx.s))
    base = ctx.base_model
    x = {**ctx.x, **cov}
    lp = base.level(ctx.p_base, _effects.shifted_inputs(x, 0.05))
    lm = base.level(ctx.p_base, _effects.shifted_inputs(x, -0.05))
    rate = (lp - lm) / 0.1
    c = _corr(rate, ctx.resid_base)
    out = {"supports": None if c is None else bool(abs(c) > 0.1), "corr_residual_model_rate": c,
           "summary": f"residual correlates {c:+.2f} with the model's level rate dL/dt" if c is not None else
           "no level rate"}
    if cand.fit is not None:
        out["dt_clock_s"] = cand.fit.params["dt_clock"]
        out["k_delay"] = cand.fit.params["k_delay"]
    return out


def _ev_wind(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    if cand.fit is None:
        return {"supports": None, "summary": "not fitted"}
    we, wn = cand.fit.params["w_east"], cand.fit.params["w_north"]
    toward = float(np.degrees(np.arctan2(we, wn)) % 360.0)
    w = (ctx.s.meta or {}).get("weather") or {}
    out: dict[str, Any] = {"fitted_downwind_deg": toward, "fitted_db_per_100m": float(math.hypot(we, wn))}
    if w.get("wind_from_deg") is None or not w.get("wind_speed_m_s"):
        out.update(supports=None, summary=f"level gain towards {toward:.0f} deg; no wind reported to compare")
        return out
    blows_to = (float(w["wind_from_deg"]) + 180.0) % 360.0
    diff = abs((toward - blows_to + 180.0) % 360.0 - 180.0)
    out.update(supports=bool(diff < 60.0), reported_downwind_deg=blows_to, angle_difference_deg=diff,
               summary=f"level gain towards {toward:.0f} deg, reported wind blows towards {blows_to:.0f} deg "
                       f"({diff:.0f} deg apart)")
    return out


def _ev_rpm(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    rpm = ctx.s.rpm
    lr = np.log(np.maximum(rpm, 1e-9))
    lp = np.log(np.maximum(ctx.s.power_w, 1e-9))
    # partial correlation of the residual with log rpm given log power
    a = np.column_stack([np.ones_like(lp), lp])
    rr = lr - a @ np.linalg.lstsq(a, lr, rcond=None)[0]
    re = ctx.resid_base - a @ np.linalg.lstsq(a, ctx.resid_base, rcond=None)[0]
    c = _corr(rr, re)
    return {"supports": None if c is None else bool(abs(c) > 0.1), "partial_corr_residual_log_rpm": c,
            "summary": f"partial correlation of the residual with log rpm given power {c:+.2f}" if c is not None
            else "rpm does not vary beyond power"}


def _ev_event(ctx: _Context, cand: _Candidate) -> dict[str, Any]:
    wins = ctx.event_windows
    if not wins:
        return {"supports": False, "summary": "no window of added sound"}
    kinds = sorted({w["kind"] for w in wins})
    margins = [w["bic_gain_minus_event"] for w in wins]
    return {"supports": bool(min(margins) > 0), "windows": len(wins), "kinds": kinds,
            "bic_gain_minus_event_min": float(min(margins)),
            "summary": f"{len(wins)} window(s) where sound added energetically ({', '.join(kinds)}) explains the rise "
                       f"better than a louder UAV (BIC margin >= {min(margins):.0f}); largest rise "
                       f"{max(w['excess_db'] for w in wins):+.1f} dB"}


for _name, _fn in (("bank_angle", _ev_bank), ("atmospheric_absorption", _ev_absorption),
                   ("ground_reflection", _ev_ground), ("doppler", _ev_doppler), ("emission_time", _ev_emission),
                   ("wind", _ev_wind), ("rpm", _ev_rpm), ("background_event", _ev_event)):
    register_evidence(_name, _fn)


# --------------------------------------------------------------------------- attribution


@dataclass
class _Context:
    s: Samples
    x: dict[str, Any]
    regimes: np.ndarray
    resid_base: np.ndarray
    base_model: Ansatz
    p_base: np.ndarray
    background_db: float | None
    event_windows: list[dict[str, Any]]


@dataclass
class _Candidate:
    name: str
    effect: _effects.Effect | None = None
    model: Ansatz | None = None
    testable: bool = True
    reason: str = ""
    fit: FitResult | None = None
    oof: np.ndarray | None = None
    error: str = ""
    summary: dict[str, Any] = field(default_factory=dict)


def _fit(level, x, model, s, rows, *, p0=None, fixed=None, bounds=None, cancel=None) -> FitResult:
    sub = {k: (v[rows] if isinstance(v, np.ndarray) and k != "band_f" and v.shape[:1] == (len(s),) else v)
           for k, v in x.items()}
    mic = s.mic[rows].astype(str)
    series = np.char.add(np.char.add(mic, "\x00"), s.flight[rows].astype(str))
    res = fit_arrays(level[rows], sub, model, mic=mic, series=series, time=s.t_e[rows], p0=p0, fixed=fixed,
                     bounds=bounds, cancel=cancel, reference_power_w=1.0, max_iter=300, tol=FIT_TOL,
                     raise_on_failure=False)
    if not res.success and not (np.isfinite(res.cost) and "did not converge" in res.message
                                and res.iterations >= 300):
        raise FitError(f"fit did not converge: {res.message}", field="fit")
    return res


def _predict(model: Ansatz, p: np.ndarray, x: Mapping[str, Any], rows: np.ndarray, n: int) -> np.ndarray:
    sub = {k: (v[rows] if isinstance(v, np.ndarray) and k != "band_f" and v.shape[:1] == (n,) else v)
           for k, v in x.items()}
    return np.broadcast_to(model.level(p, sub), (len(rows),))


def _wald(res: FitResult, names: Sequence[str]) -> tuple[float, int]:
    idx = [res.param_names.index(k) for k in names if k not in res.fixed and k not in res.at_bounds]
    if not idx:
        return 0.0, len(names)
    q = res.p[idx]
    c = res.cov_corrected[np.ix_(idx, idx)]
    try:
        w = float(q @ np.linalg.solve(c, q))
    except np.linalg.LinAlgError:
        w = float(q @ np.linalg.pinv(c) @ q)
    return max(w, 0.0), len(idx)


def _block_test(e0: np.ndarray, e1: np.ndarray, block: np.ndarray) -> tuple[float, float]:
    """Mean held-out improvement of the squared residual (dB^2) and its one-sided p-value over blocks."""
    dlt = e0 * e0 - e1 * e1
    _, inv = np.unique(block, return_inverse=True)
    cnt = np.bincount(inv)
    means = np.bincount(inv, weights=dlt) / np.maximum(cnt, 1)
    means = means[cnt > 0]
    mean = float(np.mean(dlt))
    if len(means) < 3 or np.std(means) == 0:
        return mean, (0.0 if mean > 0 and np.std(means) == 0 else 1.0)
    t = float(np.mean(means) / (np.std(means, ddof=1) / math.sqrt(len(means))))
    return mean, float(stats.t.sf(t, len(means) - 1))


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v * v))) if len(v) else float("nan")


def _clean(v: Any) -> Any:
    """JSON-able: numpy scalars to Python, NaN/inf to None."""
    if isinstance(v, dict):
        return {str(k): _clean(u) for k, u in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(u) for u in v]
    if isinstance(v, np.ndarray):
        return [_clean(u) for u in v.tolist()]
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        f = float(v)
        return f if math.isfinite(f) else None
    return v


@dataclass
class Diagnosis:
    """Result of :func:`run_diagnosis`: the JSON document and the per-sample arrays behind it.

    Attributes
    ----------
    result : dict
        The diagnosis document (see :func:`diagnose`).
    samples : Samples
        The rows diagnosed.
    arrays : dict
        Per-sample arrays: ``resid_card``, ``resid_baseline`` (in-sample refit),
        ``oof_baseline`` and ``oof/<effect>`` (held-out residuals), ``flagged``,
        ``regime``, ``fold``, ``event_window``.
    """

    result: dict[str, Any]
    samples: Samples
    arrays: dict[str, np.ndarray]

    def to_dict(self) -> dict[str, Any]:
        return self.result


def diagnose(campaign_or_samples: Any, card: ModelCard, *, progress: ProgressFn | None = None,
             cancel: CancelFn | None = None, **kw: Any) -> dict[str, Any]:
    """Where the card misses the measurements, which effect explains it, how far the gap shrinks.

    Parameters
    ----------
    campaign_or_samples : path, Campaign or Samples
        The measurements (a campaign folder is read with :func:`gisnoise.measure.campaign.read_campaign`).
    card : ModelCard
        The model card to diagnose; its ansatz is the base of every extension and
        only samples of the phases it serves are used.
    progress : callable, optional
        ``progress(done, total, what)`` after each step.
    cancel : callable, optional
        Polled between steps and inside fits; True raises :class:`gisnoise.errors.Cancelled`.
    **kw
        See :func:`run_diagnosis`.

    Returns
    -------
    dict
        ``{"schema", "card", "data", "noise_std_db", "baseline": {"rms_db", ...},
        "segments": [...], "statistics": {...}, "event_windows": [...],
        "effects": [{"name", "rank", "testable", "significant", "rms_db_fit",
        "rms_db_holdout", "shrinkage_pct", ...}], "verdict": {"effect", "holdout_shrinkage_pct", ...}}``
    """
    return run_diagnosis(campaign_or_samples, card, progress=progress, cancel=cancel, **kw).result


def run_diagnosis(
    campaign_or_samples: Any,
    card: ModelCard,
    *,
    candidates: Sequence[str] | None = None,
    alpha: float = 0.01,
    window_s: float = 2.0,
    z: float = 4.0,
    block_s: float = 30.0,
    bias_z: float = 3.0,
    include_events: bool = True,
    min_improvement_db2: float = MIN_IMPROVEMENT_DB2,
    progress: ProgressFn | None = None,
    cancel: CancelFn | None = None,
) -> Diagnosis:
    """The diagnosis with its per-sample arrays (for reports); see :func:`diagnose`.

    Parameters
    ----------
    candidates : sequence of str, optional
        Effect names to test (default: the whole library).
    alpha : float
        Family-wise significance level of the extension tests (Bonferroni over candidates).
    window_s, z : float
        Localization window (s) and threshold (standard errors).
    block_s : float
        Time block of the cross-validation with one flight and of the paired held-out test, s.
    bias_z : float
        A base parameter counts as biased by an effect when the extension moves it
        by more than this many corrected standard deviations.
    include_events : bool
        Diagnose samples the campaign reader masked as ``event`` too (they are
        part of the gap and the evidence for ``background_event``).
    min_improvement_db2 : float
        Smallest held-out improvement of the mean squared residual a verdict needs, dB^2.
    """
    if not isinstance(card, ModelCard):
        raise InputError(f"card must be a ModelCard, got {type(card).__name__}", field="card")
    if not (0.0 < alpha < 1.0):
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}", field="alpha")
    for name, v in (("window_s", window_s), ("z", z), ("block_s", block_s), ("bias_z", bias_z),
                    ("min_improvement_db2", min_improvement_db2)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a positive number, got {v!r}", field=name)
    names = list(_effects.effect_names() if candidates is None else candidates)
    for nme in names:
        _effects.get_effect(nme)

    def check_cancel() -> None:
        if cancel is not None and cancel():
            raise Cancelled("diagnosis cancelled", field="cancel")

    total = 3 + len(names)
    step = 0

    def tick(what: str) -> None:
        nonlocal step
        step += 1
        if progress is not None:
            progress(step, total, what)
        check_cancel()

    all_s = load_samples(campaign_or_samples)
    use = np.isin(all_s.phase.astype(str), list(card.served_phases))
    keep = all_s.valid | (all_s.mask_reason.astype(str) == "event") if include_events else all_s.valid.copy()
    s = all_s.select(use & keep)
    if len(s) < 20:
        have = sorted(set(all_s.phase[all_s.valid].astype(str).tolist()))
        raise InputError(f"diagnosis needs usable samples of the card's phase(s) {', '.join(card.served_phases)}; "
                         f"found {len(s)} (phases with usable samples: {', '.join(have) or 'none'})", field="phase")
    n = len(s)
    ref = float(card.reference_power_w)
    x: dict[str, Any] = dict(s.inputs(ref))
    x["mic"] = s.mic.astype(str)
    x["flight"] = s.flight.astype(str)
    base = card.model
    level = np.asarray(s.level, dtype=float)
    rows_all = np.arange(n)

    # ---------------------------------------------------------------- localization on the card's residual
    pred_card = np.broadcast_to(base.level(card.p, x, d_ref=card.reference_distance_m), (n,))
    resid_card = level - pred_card
    sid = _series(s)
    noise = measurement_noise(resid_card, sid, s.t_e, s.mic.astype(str))
    reg = sample_regimes(s)
    segments, flagged = localize(s, resid_card, noise, window_s=window_s, z=z, regimes=reg)
    statistics = _statistics(s, resid_card, flagged, reg)
    tick("localization")

    # ---------------------------------------------------------------- baseline refit, folds
    try:
        base_fit = _fit(level, x, base, s, rows_all, p0=card.p, cancel=cancel)
    except FitError as exc:
        raise FitError(f"diagnosis: the card's ansatz {base.name!r} cannot be refitted to these data: {exc}",
                       field="card") from None
    resid_base = base_fit.residuals
    fold, block, how = fold_labels(s, block_s=block_s)
    if len(np.unique(fold)) < 2:
        raise InputError(f"diagnosis needs data in two cross-validation folds; the data span less than "
                         f"2 x block_s = {2 * block_s:g} s", field="block_s")
    oof_base = np.empty(n)
    base_folds: list[FitResult] = []
    for f in (0, 1):
        tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        r = _fit(level, x, base, s, tr, p0=base_fit.p, cancel=cancel)
        base_folds.append(r)
        oof_base[te] = level[te] - _predict(base, r.p, x, te, n)
    tick("baseline")

    # ---------------------------------------------------------------- events
    l_uav_card = np.broadcast_to(base.level_uav(card.p, x, d_ref=card.reference_distance_m), (n,))
    bg_rows = np.full(n, card.background_db if card.background_db is not None else -np.inf)
    ev_win, ev_list = detect_events(s, resid_card, noise, l_uav_card, bg_rows)
    x_ev = dict(x, event_window=ev_win)

    bg = card.background_db
    ctx = _Context(s=s, x=x, regimes=reg, resid_base=resid_base, base_model=base, p_base=base_fit.p,
                   background_db=bg, event_windows=ev_list)

    # ---------------------------------------------------------------- candidates
    cands: list[_Candidate] = []
    for nme in names:
        eff = _effects.get_effect(nme)
        cand = _Candidate(nme, eff)
        cands.append(cand)
        xe = x_ev if nme == "background_event" else x
        ok, why = _effects.check_testable(eff, xe)
        if nme == "background_event" and ok and not ev_list:
            ok, why = True, ""
        if not ok:
            cand.testable, cand.reason = False, why
            tick(nme)
            continue
        if nme == "background_event" and not ev_list:
            cand.reason = "no window of added sound found: the extension is the baseline"
            cand.oof = oof_base.copy()
            cand.summary["rms_db_fit"] = base_fit.rms_db
            tick(nme)
            continue
        try:
            _attribute(cand, ctx, level, xe, base_fit, fold, cancel, bias_z)
        except (FitError, InputError) as exc:
            if isinstance(exc, Cancelled):
                raise
            cand.error = str(exc)
        except GisnoiseError as exc:
            if isinstance(exc, Cancelled):
                raise
            cand.error = str(exc)
        tick(nme)

    # ---------------------------------------------------------------- ranking and verdict
    tested = [c for c in cands if c.testable and c.fit is not None]
    n_tests = max(len([c for c in cands if c.testable]), 1)
    level_alpha = alpha / n_tests
    mse0 = float(np.mean(oof_base ** 2))
    sig2 = float(np.mean([noise.get(m, 0.0) ** 2 for m in s.mic.astype(str)]))
    for c in cands:
        if c.oof is None:
            continue
        imp, p_ho = _block_test(oof_base, c.oof, block)
        c.summary["holdout_improvement_db2"] = imp
        c.summary["p_holdout"] = p_ho
        c.summary["rms_db_holdout"] = _rms(c.oof)
        c.summary["shrinkage_pct"] = 100.0 * (1.0 - _rms(c.oof) / _rms(oof_base)) if mse0 > 0 else 0.0
        c.summary["excess_explained_pct"] = (100.0 * imp / (mse0 - sig2)) if mse0 - sig2 > 1e-12 else None
        if c.fit is not None and c.name != "background_event":
            w, dof = c.summary.get("wald", 0.0), c.summary.get("wald_dof", 1)
            trials = c.summary.get("look_elsewhere_trials", 1)
            c.summary["p_value"] = float(min(1.0, trials * stats.chi2.sf(w, dof))) if dof else 1.0
        c.summary["significant"] = bool(c.summary.get("p_value", 1.0) < level_alpha)
        ev = _EVIDENCE.get(c.name)
        if ev is not None:
            try:
                c.summary["evidence"] = ev(ctx, c)
            except (GisnoiseError, ValueError, np.linalg.LinAlgError) as exc:
                c.summary["evidence"] = {"supports": None, "summary": f"not computed: {exc}"}
    ranked = sorted([c for c in cands if c.oof is not None],
                    key=lambda c: -c.summary.get("holdout_improvement_db2", -np.inf))
    for i, c in enumerate(ranked):
        c.summary["rank"] = i + 1
    eligible = [c for c in ranked if c.summary["significant"] and c.summary["holdout_improvement_db2"] >= min_improvement_db2
                and c.summary["p_holdout"] < 0.05]
    verdict_c = None
    if eligible:
        verdict_c = eligible[0]
        sup = (verdict_c.summary.get("evidence") or {}).get("supports")
        for other in eligible[1:]:
            close = other.summary["holdout_improvement_db2"] >= 0.8 * verdict_c.summary["holdout_improvement_db2"]
            if close and sup is False and (other.summary.get("evidence") or {}).get("supports") is True:
                verdict_c = other
                break
    # ---------------------------------------------------------------- shrinkage per segment
    top = verdict_c or (ranked[0] if ranked else None)
    for seg in segments:
        m = (s.flight.astype(str) == seg["flight"]) & (s.mic.astype(str) == seg["mic"]) & \
            (s.t_e >= seg["t0"]) & (s.t_e <= seg["t1"])
        seg["rms_db_holdout_baseline"] = _rms(oof_base[m])
        if top is not None and top.oof is not None:
            seg["effect"] = top.name
            seg["rms_db_holdout_extended"] = _rms(top.oof[m])
            b = seg["rms_db_holdout_baseline"]
            seg["shrinkage_pct"] = 100.0 * (1.0 - seg["rms_db_holdout_extended"] / b) if b > 0 else 0.0

    effects_out = []
    for c in sorted(cands, key=lambda c: (c.summary.get("rank", 10 ** 6), c.name)):
        e: dict[str, Any] = {"name": c.name, "rank": c.summary.get("rank"), "testable": c.testable,
                             "description": c.effect.description if c.effect else ""}
        if not c.testable:
            e.update(significant=False, reason=c.reason)
        elif c.error:
            e.update(significant=False, reason=f"fit failed: {c.error}")
        else:
            if c.reason:
                e["reason"] = c.reason
            e.update({k: v for k, v in c.summary.items()})
        effects_out.append(e)

    verdict: dict[str, Any]
    if verdict_c is None:
        why = ("no candidate is significant with a held-out improvement" if tested else
               "no candidate could be tested")
        verdict = {"effect": None, "holdout_shrinkage_pct": 0.0, "reason": why,
                   "rms_db_holdout_baseline": _rms(oof_base)}
    else:
        ev = verdict_c.summary.get("evidence") or {}
        verdict = {"effect": verdict_c.name, "holdout_shrinkage_pct": verdict_c.summary["shrinkage_pct"],
                   "rms_db_holdout_baseline": _rms(oof_base),
                   "rms_db_holdout_extended": verdict_c.summary["rms_db_holdout"],
                   "rms_db_fit_baseline": base_fit.rms_db,
                   "rms_db_fit_extended": verdict_c.summary.get("rms_db_fit"),
                   "p_value": verdict_c.summary.get("p_value"),
                   "biased_parameters": verdict_c.summary.get("biased_parameters", []),
                   "evidence": ev.get("summary"),
                   "reason": f"significant at {level_alpha:.1e} and the largest held-out improvement "
                             f"({verdict_c.summary['holdout_improvement_db2']:.3f} dB^2, paired-block p "
                             f"{verdict_c.summary['p_holdout']:.1e})"}

    result = {
        "schema": SCHEMA,
        "card": {"id": card.id, "ansatz": card.ansatz, "phase": card.phase, "phases": list(card.served_phases)},
        "data": {"n_samples": n, "flights": sorted(set(s.flight.astype(str).tolist())),
                 "microphones": sorted(set(s.mic.astype(str).tolist())),
                 "n_reader_events": int(np.sum(s.mask_reason.astype(str) == "event")),
                 "holdout": how, "block_s": block_s, "window_s": window_s},
        "noise_std_db": noise,
        "baseline": {"rms_db": base_fit.rms_db, "rms_db_card": _rms(resid_card),
                     "rms_db_fit": base_fit.rms_db, "rms_db_holdout": _rms(oof_base),
                     "noise_std_db_fit": dict(base_fit.noise_std), "parameters": base_fit.params,
                     "std_corrected": base_fit.std_corrected, "aic": base_fit.aic, "bic": base_fit.bic},
        "segments": segments,
        "statistics": statistics,
        "event_windows": ev_list,
        "effects": effects_out,
        "alpha": alpha,
        "alpha_per_test": level_alpha,
        "verdict": verdict,
    }
    arrays = {"resid_card": resid_card, "resid_baseline": resid_base, "oof_baseline": oof_base,
              "flagged": flagged, "regime": reg, "fold": fold, "event_window": ev_win, "fitted_card": pred_card}
    for c in cands:
        if c.oof is not None and c.fit is not None:
            arrays[f"oof/{c.name}"] = c.oof
            arrays[f"fit/{c.name}"] = c.fit.residuals
    tick("verdict")
    return Diagnosis(result=_clean(result), samples=s, arrays=arrays)


def _attribute(cand: _Candidate, ctx: _Context, level: np.ndarray, x: dict[str, Any], base_fit: FitResult,
               fold: np.ndarray, cancel: CancelFn | None, bias_z: float) -> None:
    """Fit one candidate on all data and in the two folds; fill its summary."""
    s = ctx.s
    n = len(s)
    eff = _effects.bind(cand.effect, x)
    model = _effects.extend(ctx.base_model, eff)
    cand.model = model
    nb = ctx.base_model.n_params
    start = dict(zip(model.params, np.r_[base_fit.p, np.asarray(eff.start, dtype=float)], strict=True))
    fixed = dict(eff.fixed(x)) if eff.fixed is not None else {}
    trials = 1
    if eff.initial is not None:
        init = dict(eff.initial(x, base_fit.residuals))
        trials = int(init.pop("__trials__", 1))
        start.update(init)
    bounds = {k: b for k, b in zip(eff.params, eff.bounds, strict=True)}
    if cand.name == "background_event":
        win = np.asarray(x["event_window"], dtype=int)
        for j, k in enumerate(eff.params):
            m = win == j
            excess = np.mean(10.0 ** (level[m] / 10.0)) - np.mean(10.0 ** ((level[m] - base_fit.residuals[m]) / 10.0))
            start[k] = float(10.0 * np.log10(max(excess, 1e-2)))
    start.update(fixed)
    rows_all = np.arange(n)
    tested = eff.tested if eff.tested is not None else tuple(k for k in eff.params if k not in fixed)
    def fit_ext(rows: np.ndarray, p0: dict[str, float], fx: dict[str, float]) -> FitResult:
        try:
            return _fit(level, x, model, s, rows, p0=p0, fixed=fx or None, bounds=bounds, cancel=cancel)
        except NotIdentifiableError:
            # a vanishing effect leaves its shape parameters undetermined: hold them at their start values
            shape = {k: float(p0[k]) for k in eff.params if k not in tested and k not in fx}
            if not shape:
                raise
            cand.reason = f"{', '.join(shape)} held at the start value(s) where not identifiable"
            return _fit(level, x, model, s, rows, p0=p0, fixed={**fx, **shape}, bounds=bounds, cancel=cancel)

    full = fit_ext(rows_all, start, fixed)
    cand.fit = full
    oof = np.empty(n)
    for f in (0, 1):
        tr, te = np.flatnonzero(fold != f), np.flatnonzero(fold == f)
        fx = dict(fixed)
        if cand.name == "background_event":
            win = np.asarray(x["event_window"], dtype=int)
            present = set(np.unique(win[tr]).tolist())
            for j, k in enumerate(eff.params):
                if j not in present:
                    fx[k] = float(full.params[k])  # window only in held-out data: its level is a nuisance
        p0 = {k: v for k, v in full.params.items()}
        p0.update(fx)
        r = fit_ext(tr, p0, fx)
        oof[te] = level[te] - _predict(model, r.p, x, te, n)
    cand.oof = oof
    summ = cand.summary
    summ["rms_db_fit"] = full.rms_db
    summ["lr"] = 2.0 * (base_fit.cost - full.cost)
    summ["delta_aic"] = full.aic - base_fit.aic
    summ["delta_bic"] = full.bic - base_fit.bic
    if cand.name == "background_event":
        zs = [w["z"] for w in ctx.event_windows if w.get("z") is not None]
        n_scan = max(1.0, n / 8.0)
        zmax = max(zs) if zs else 0.0
        summ["p_value"] = float(min(1.0, n_scan * stats.norm.sf(zmax))) if zs else 1.0
        summ["test"] = "scan statistic of the strongest window against white measurement noise (Bonferroni)"
    else:
        w, dof = _wald(full, tested)
        summ["wald"] = w
        summ["wald_dof"] = dof
        summ["look_elsewhere_trials"] = trials
        summ["test"] = "Wald test of " + ", ".join(tested) + " with autocorrelation-corrected covariance" + (
            f", p-value times {trials} start values searched" if trials > 1 else "")
    std = full.std_corrected
    summ["parameters"] = {k: {"value": full.params[k], "std": std[k]} for k in eff.params}
    biased = []
    for k in ctx.base_model.params[:nb]:
        sd = std[k]
        dv = full.params[k] - base_fit.params[k]
        if sd > 0 and abs(dv) / sd > bias_z:
            biased.append({"name": k, "baseline": base_fit.params[k], "extended": full.params[k],
                           "shift_in_std": dv / sd})
    summ["biased_parameters"] = biased
    summ["at_bounds"] = list(full.at_bounds)
