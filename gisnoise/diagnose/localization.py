"""Localization of the gap: where the card's residual exceeds what measurement noise explains.

The card's residual (measured minus model, dB) is smoothed per microphone and
flight over a window of ``window_s`` seconds; where the smoothed residual is
larger than the measurement noise explains (``z`` standard errors of a window
mean), the samples are flagged and joined into segments.  The measurement noise
per microphone is the robust spread of first differences of the residual: fast
scatter is noise, slow structure is model error.  Each segment carries its flight
regime (``mixed`` when none holds :data:`REGIME_SHARE` of it), range and microphone;
the residual is also summed up by regime, microphone, flight and geometry bins.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.diagnose._series import _intervals, _rolling_mean, _runs, _smoothed
from gisnoise.measure import Samples, series_ids

__all__ = ["REGIME_SHARE", "measurement_noise", "sample_regimes", "localize"]

TURN_BANK_DEG = 10.0
"""A horizontal-flight sample with |bank| above this is in a turn, deg."""
VERTICAL_SPEED_M_S = 1.5
"""Climb or sink when the vertical speed exceeds this, m/s."""
HOVER_SPEED_M_S = 2.0
"""Hover when the ground speed is below this, m/s."""
REGIME_SHARE = 0.8
"""Share of a segment's samples one regime must hold to label it; below, the segment is ``mixed``."""


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
    for idx in _runs(series_ids(s.mic, s.flight), s.t_e):
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
        ``excess_db`` (mean smoothed residual), ``n``, ``regime`` (the regime of at least
        :data:`REGIME_SHARE` of its samples, else ``mixed``), ``regime_shares`` (share of each
        regime, largest first), ``range`` (near or far), ``d_median_m``, ``bank_abs_mean_deg``.
    flagged : ndarray of bool
        Samples inside a segment.
    """
    reg = sample_regimes(s) if regimes is None else regimes
    sid = series_ids(s.mic, s.flight)
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
            order = np.argsort(-counts, kind="stable")
            shares = {str(vals[i]): float(counts[i] / len(rows)) for i in order}
            top = str(vals[order[0]])
            segs.append({
                "flight": ser.flight, "mic": ser.mic,
                "t0": float(ser.t[a]), "t1": float(ser.t[b]),
                "rms_db": float(np.sqrt(np.mean(r * r))), "mean_db": float(np.mean(r)),
                "excess_db": float(np.mean(ser.excess[a:b + 1])), "n": int(len(rows)),
                "regime": top if shares[top] >= REGIME_SHARE else "mixed", "regime_shares": shares,
                "range": "near" if float(np.median(s.d[rows])) <= d_med else "far",
                "d_median_m": float(np.median(s.d[rows])),
                "bank_abs_mean_deg": float(np.mean(np.abs(s.roll[rows]))),
            })
    segs.sort(key=lambda g: (g["flight"], g["t0"], g["mic"]))
    return segs, flagged


def _group_stats(resid: np.ndarray, labels: np.ndarray, flagged: np.ndarray,
                 order: Sequence[str] | None = None) -> list[dict[str, Any]]:
    """Residual mean, RMS and flagged fraction per label (in ``order``, else sorted)."""
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
    """The residual by regime, microphone, flight, distance, polar angle and azimuth, and its correlations."""
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
