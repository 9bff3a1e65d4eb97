"""Events in the residual: windows of transient sound from sources other than the UAV.

The campaign reader masks joint rises of all microphones' levels as ``event``
(:func:`gisnoise.measure.campaign.detect_events`); the diagnosis looks again, in the
card's residual, and keeps a window only when sound added energetically (at every
microphone, or at the rising ones only) explains it better than a louder UAV.
The windows found are the inputs of the ``background_event`` candidate.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from gisnoise.diagnose._series import _intervals, _smoothed
from gisnoise.measure import Samples, series_ids
from gisnoise.model import level_sum

__all__ = ["residual_events"]


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


def residual_events(
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
    sid = series_ids(s.mic, s.flight)
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
