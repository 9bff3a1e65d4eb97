"""The campaign's metadata as a prior, not a fact: microphone heights and clocks estimated from the data.

A campaign file can be wrong: a microphone listed on a ground plate stood on a
tripod above grass, a microphone's clock ran behind the others.  The candidates
whose inputs come from such metadata are therefore also given inputs estimated
from the measurements within a physical range:

Microphone height above a reflecting ground (0.3-3 m)
    From the one-third-octave band levels of each microphone.  A microphone
    above ground hears the direct sound and its image; their interference is a
    comb over frequency whose spacing is ``1 / tau`` with the delay
    ``tau = (r_reflected - r_direct) / c``, set by the height and the geometry.
    The band levels, centred per band (the source spectrum) and per sample (the
    overall level), are matched against the band-averaged two-ray comb
    ``10 log10(1 + a^2 + 2 a <cos(2 pi f tau - phi)>_band)`` with an amplitude
    ``a`` and a reflection phase ``phi`` (a soft ground's reflection coefficient
    is complex) over a grid of heights.  The height's uncertainty is the half
    width of the profile where the sum of squares rises by one effective
    sample's share (samples within one second counted as one), at least 0.05 m.
Clock offset per microphone (-3 to 3 s)
    From the overall level: the card's ansatz at the baseline parameters is
    evaluated at inputs moved along each series by an offset (interpolated,
    exact), and each microphone's offset is the one that minimises its residual
    (a parabola through the grid minimum).  The uncertainty comes from the
    curvature of the sum of squares with one effective sample per second.

When the estimate contradicts the metadata by more than 3 standard deviations
and explains a real share of the data, the candidate is fitted with the
estimate and the report says so in one sentence per microphone.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.diagnose._rows import _effective_samples
from gisnoise.measure import Samples, series_ids
from gisnoise.model import Ansatz, Effect, emission_covariates, mic_height_agl, shifted_inputs, speed_of_sound

__all__ = ["CLOCK_RANGE_S", "HEIGHT_RANGE_M", "estimate_clock_offsets", "estimate_mic_heights", "clocks_disagree",
           "clock_note", "mic_clock_effect", "shift_inputs"]

HEIGHT_RANGE_M = (0.3, 3.0)
"""Heights above a reflecting ground a microphone may have, m (below: a ground plate)."""
CLOCK_RANGE_S = (-3.0, 3.0)
"""Clock offsets a microphone may have, s."""
_CONTRA_Z = 3.0  # standard deviations between estimate and metadata that make a contradiction
_MIN_COMB_SHARE = 0.15  # share of the centred band-level variance a comb must explain
_MIN_CLOCK_GAIN = 0.02  # relative reduction of a microphone's residual variance a clock offset must bring
_MIN_HEIGHT_STD_M = 0.05  # floor of the height's uncertainty: the two-ray form is an approximation of real ground
_SUB = np.linspace(-0.5, 0.5, 9)  # sub-frequencies of a third-octave band, in thirds of an octave


def _double_centre(b: np.ndarray) -> np.ndarray:
    """Band levels minus their band means and sample means (grand mean added back)."""
    return b - b.mean(axis=0, keepdims=True) - b.mean(axis=1, keepdims=True) + b.mean()


def _tau(mic: np.ndarray, uav: np.ndarray, ground_z: np.ndarray, h: float, c: float) -> np.ndarray:
    """Delay of the ground-reflected path for a microphone ``h`` above flat ground at ``ground_z``, s."""
    hs = np.maximum(uav[:, 2] - ground_z, 0.0)
    rh2 = np.sum((uav[:, :2] - mic[:, :2]) ** 2, axis=1)
    return (np.sqrt(rh2 + (hs + h) ** 2) - np.sqrt(rh2 + (hs - h) ** 2)) / c


_AMPS = (0.3, 0.6, 0.9)
_PHASES = np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)


def _comb_errors(e: np.ndarray, f: np.ndarray, tau: np.ndarray, fold: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum of squares per fold of the centred band levels ``e`` minus each two-ray comb (amplitude x phase).

    Returns the sums (folds x amplitudes x phases) and the combs' row-centred shapes (amplitudes x phases x rows x bands).
    """
    fs = f[None, :, None] * 2.0 ** (_SUB[None, None, :] / 3.0)
    u = 2.0 * np.pi * fs * tau[:, None, None]
    cbar, sbar = np.cos(u).mean(axis=2), np.sin(u).mean(axis=2)
    ss = np.zeros((2, len(_AMPS), len(_PHASES)))
    shapes = np.zeros((len(_AMPS), len(_PHASES)) + e.shape)
    for i, a in enumerate(_AMPS):
        for j, phi in enumerate(_PHASES):
            g = 10.0 * np.log10(1.0 + a * a + 2.0 * a * (cbar * math.cos(phi) + sbar * math.sin(phi)))
            g = _double_centre(g)  # geometry only: no data of either fold enters the shape
            shapes[i, j] = g
            r2 = np.sum((e - g) ** 2, axis=1)
            for k in (0, 1):
                ss[k, i, j] = float(np.sum(r2[fold == k]))
    return ss, shapes


def estimate_mic_heights(s: Samples, x: Mapping[str, Any], fold: np.ndarray, *, max_rows: int = 600,
                         f_range: tuple[float, float] = (50.0, 5000.0)) -> dict[str, dict[str, Any]]:
    """Each microphone's height above a reflecting ground estimated from its band levels' comb pattern.

    Parameters
    ----------
    s : Samples
        The samples (band levels needed).
    x : mapping
        Their model inputs (``meta`` for the listed heights and the speed of sound).
    fold : ndarray of int
        Cross-validation fold (0 or 1) per sample: the comb fitted on one fold predicts the other.
    max_rows : int
        Samples per microphone used (the louder half, evenly thinned).
    f_range : (float, float)
        Bands used, Hz.

    Returns
    -------
    dict
        Per microphone: ``listed_m``, ``height_m``, ``std_m``, ``at_search_limit`` (the best height is an
        end of the search range: ``height_m`` is that bound and ``std_m`` None), ``comb_share`` (share of
        the centred band-level variance the comb explains; at or below 0 the band levels hold no comb),
        ``contradicts``, ``sentence`` and, for the held-out
        test, ``rows`` (sample indices), ``err0`` and ``err1`` (held-out RMS band residual per row
        without and with the comb); empty when there are no band levels or no speed of sound.
    """
    c = speed_of_sound(x.get("meta"))
    if s.bands is None or s.band_f is None or c is None:
        return {}
    listed = mic_height_agl(x)
    f = np.asarray(s.band_f, dtype=float)
    use_b = (f >= f_range[0]) & (f <= f_range[1])
    out: dict[str, dict[str, Any]] = {}
    mics = s.mic.astype(str)
    grid = np.round(np.arange(HEIGHT_RANGE_M[0], HEIGHT_RANGE_M[1] + 1e-9, 0.05), 3)
    fold = np.asarray(fold, dtype=int)
    for m in sorted(set(mics.tolist())):
        rows = np.flatnonzero((mics == m) & np.all(np.isfinite(s.bands[:, use_b]), axis=1))
        if len(rows) < 50 or use_b.sum() < 6:
            continue
        la = s.level[rows]
        rows = rows[la >= np.quantile(la, 0.5)]  # the UAV well above the background
        rows = rows[np.linspace(0, len(rows) - 1, min(max_rows, len(rows))).astype(int)]
        fr = fold[rows]
        if len(np.unique(fr)) < 2:
            continue
        e = _double_centre(np.asarray(s.bands[rows][:, use_b], dtype=float))
        h_list = float(listed[rows][0]) if listed is not None and np.isfinite(listed[rows][0]) else 0.0
        ground_z = s.mic_enu[rows, 2] - h_list
        ss = np.zeros((len(grid), 2, len(_AMPS), len(_PHASES)))
        for k, h in enumerate(grid):
            ss[k] = _comb_errors(e, f[use_b], _tau(s.mic_enu[rows], s.uav_enu[rows], ground_z, h, c), fr)[0]
        tot = ss.sum(axis=1)
        kh, ka, kp = np.unravel_index(int(np.argmin(tot)), tot.shape)
        h_hat, a, phi = float(grid[kh]), _AMPS[ka], float(_PHASES[kp])
        ss_min, ss0 = float(tot[kh, ka, kp]), float(np.sum(e * e))
        n_eff = _effective_samples(s.t_e[rows])
        prof = tot.reshape(len(grid), -1).min(axis=1)
        inside = grid[prof <= ss_min * (1.0 + 1.0 / n_eff)]
        std = float(max((inside.max() - inside.min()) / 2.0, _MIN_HEIGHT_STD_M))
        share = 1.0 - ss_min / ss0 if ss0 > 0 else 0.0
        # held out: the comb fitted on one fold predicts the other
        err0 = np.sqrt(np.mean(e * e, axis=1))
        err1 = np.empty(len(rows))
        for k in (0, 1):
            kk = np.unravel_index(int(np.argmin(ss[:, 1 - k])), ss[:, 1 - k].shape)
            tau = _tau(s.mic_enu[rows], s.uav_enu[rows], ground_z, float(grid[kk[0]]), c)
            shape = _comb_errors(e, f[use_b], tau, fr)[1][kk[1], kk[2]]
            te = fr == k
            err1[te] = np.sqrt(np.mean((e[te] - shape[te]) ** 2, axis=1))
        contradicts = bool(share >= _MIN_COMB_SHARE and abs(h_hat - h_list) > _CONTRA_Z * std
                           and h_list < HEIGHT_RANGE_M[0])
        # the edge of the grid is a bound, not an estimate: the comb of the best height may lie beyond it
        at_limit = kh in (0, len(grid) - 1)
        where = f"about {h_hat:.1f} m (+/- {std:.2f} m)"
        if at_limit:
            where = (f"{'at least' if kh else 'at most'} {h_hat:.1f} m (the "
                     f"{'upper' if kh else 'lower'} limit of the {HEIGHT_RANGE_M[0]:g}-{HEIGHT_RANGE_M[1]:g} m search)")
        sentence = ""
        if contradicts:
            sentence = (f"the band levels of {m} show the comb pattern of a microphone {where} above a reflecting "
                        f"ground (reflection amplitude about {a:.1f}), not a ground plate as the campaign lists")
        out[m] = {"listed_m": h_list, "height_m": h_hat, "std_m": None if at_limit else std,
                  "at_search_limit": at_limit, "comb_share": share, "amplitude": a,
                  "phase_rad": phi, "contradicts": contradicts, "sentence": sentence,
                  "rows": rows, "err0": err0, "err1": err1}
    return out


# --------------------------------------------------------------------------- clocks

_SHIFTED = ("d", "phi", "theta", "p_el")


def shift_inputs(x: Mapping[str, Any], s: Samples, offsets: Mapping[str, float]) -> dict[str, Any]:
    """The inputs of each microphone's series moved to ``t_e + offset`` (interpolated along the series)."""
    out = dict(x)
    sid = series_ids(s.mic, s.flight)
    mics = s.mic.astype(str)
    n = len(s)
    for k in _SHIFTED:
        out[k] = np.array(np.broadcast_to(np.asarray(x[k], dtype=float), (n,)), dtype=float)
    for j in np.unique(sid):
        rows = np.flatnonzero(sid == j)
        dt = float(offsets.get(str(mics[rows[0]]), 0.0))
        if dt == 0.0 or len(rows) < 2:
            continue
        rows = rows[np.argsort(s.t_e[rows])]
        t = s.t_e[rows]
        for k in _SHIFTED:
            v = np.broadcast_to(np.asarray(x[k], dtype=float), (n,))[rows]
            if k == "phi":
                v = np.unwrap(v)
            out[k][rows] = np.interp(t + dt, t, v)
    return out


def estimate_clock_offsets(s: Samples, x: Mapping[str, Any], model: Ansatz, p: np.ndarray, *,
                           step_s: float = 0.125) -> dict[str, dict[str, Any]]:
    """Each microphone's clock offset: the shift of its inputs that best explains its level.

    Returns
    -------
    dict
        Per microphone: ``offset_s`` (the model is evaluated at ``t_e + offset_s``), ``std_s``,
        ``gain`` (relative reduction of its residual variance against no offset).
    """
    mics = s.mic.astype(str)
    grid = np.arange(CLOCK_RANGE_S[0], CLOCK_RANGE_S[1] + 1e-9, step_s)
    level = np.asarray(s.level, dtype=float)
    names = sorted(set(mics.tolist()))
    ss = np.zeros((len(names), len(grid)))
    for i, dt in enumerate(grid):
        xs = shift_inputs(x, s, {m: float(dt) for m in names})
        r = level - np.broadcast_to(model.level(p, xs), level.shape)
        for k, m in enumerate(names):
            rm = r[mics == m]
            ss[k, i] = float(np.sum((rm - rm.mean()) ** 2))
    out: dict[str, dict[str, Any]] = {}
    i0 = int(np.argmin(np.abs(grid)))
    for k, m in enumerate(names):
        i = int(np.clip(np.argmin(ss[k]), 1, len(grid) - 2))
        y0, y1, y2 = ss[k, i - 1], ss[k, i], ss[k, i + 1]
        curv = (y0 - 2 * y1 + y2) / step_s ** 2
        shift = 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) if curv > 0 else 0.0
        dt = float(grid[i] + np.clip(shift, -1.0, 1.0) * step_s)
        n_m = int(np.sum(mics == m))
        n_eff = _effective_samples(s.t_e[mics == m])
        s2 = y1 / max(n_m, 1)
        # sum of squares ~ n (s2 + k dt^2): curvature per effective sample gives the variance of dt
        std = float(math.sqrt(2.0 * s2 / (curv / n_m * n_eff))) if curv > 0 else float("inf")
        gain = 1.0 - y1 / ss[k, i0] if ss[k, i0] > 0 else 0.0
        out[m] = {"offset_s": dt, "std_s": std, "gain": float(gain)}
    return out


def clocks_disagree(est: Mapping[str, Mapping[str, Any]]) -> list[str]:
    """Microphones whose clock offset differs from the median of the others by more than 3 standard deviations."""
    odd = []
    for m, e in est.items():
        others = [v["offset_s"] for k, v in est.items() if k != m]
        if not others:
            continue
        ref = float(np.median(others))
        if abs(e["offset_s"] - ref) > _CONTRA_Z * max(e["std_s"], 0.02) and e["gain"] >= _MIN_CLOCK_GAIN:
            odd.append(m)
    return odd


def clock_note(mic: str, est: Mapping[str, Mapping[str, Any]]) -> str:
    """The report's sentence on microphone ``mic``'s clock, relative to the median of the others.

    ``offset_s`` > 0 means level(t) = model(t + offset_s): the level comes earlier than the model
    expects, so the microphone's clock runs behind; < 0: later, its clock runs ahead.
    """
    others = [float(v["offset_s"]) for k, v in est.items() if k != mic]
    rel = float(est[mic]["offset_s"]) - (float(np.median(others)) if others else 0.0)
    way, clock = ("earlier", "behind") if rel > 0 else ("later", "ahead of")
    return (f"the level of {mic} follows the model {abs(rel):.2f} s (+/- {float(est[mic]['std_s']):.2f} s) {way} "
            f"than the other microphones': its clock runs that much {clock} theirs, which the campaign does not "
            "state")


def mic_clock_effect(s: Samples, x: Mapping[str, Any], mics: Sequence[str], start: Mapping[str, float],
                     model: Ansatz) -> Effect:
    """The emission-time candidate with one clock offset per microphone (``dt_<mic>``) and the delay factor.

    The inputs are moved exactly to the estimated offsets ``start`` (interpolation
    along each series, computed once) and from there to first order along their
    rates, so the parameters are the total offsets and the Wald test is against zero.
    """
    mics = list(mics)
    pre = shift_inputs(x, s, start)
    cov = emission_covariates({**pre, "mic": s.mic.astype(str), "flight": s.flight.astype(str)})
    mic_idx = np.array([mics.index(m) for m in s.mic.astype(str)])
    pre_dt = np.array([float(start.get(m, 0.0)) for m in mics])[mic_idx]
    values = {**{f"pre_{k}": np.asarray(pre[k], dtype=float) for k in _SHIFTED}, **cov,
              "mic_index": mic_idx, "pre_dt": pre_dt}

    def covariates(_x: Mapping[str, Any]) -> dict[str, np.ndarray]:
        return dict(values)

    def apply(base_kernel, p_base, q, xb, d_ref, want_jac):
        xs = dict(xb)
        for k in _SHIFTED:
            xs[k] = xb[f"pre_{k}"]
        idx = np.asarray(xb["mic_index"], dtype=int)
        tprop = np.asarray(xb["t_prop"], dtype=float)
        k_delay = q[-1]
        delta = np.asarray(q[:-1], dtype=float)[idx] - xb["pre_dt"] + k_delay * tprop
        l_uav, jb = base_kernel(p_base, shifted_inputs(xs, delta), d_ref, want_jac)
        if not want_jac:
            return l_uav, None, None
        h = 1e-3
        lp, _ = base_kernel(p_base, shifted_inputs(xs, delta + h), d_ref, False)
        lm, _ = base_kernel(p_base, shifted_inputs(xs, delta - h), d_ref, False)
        dl = (lp - lm) / (2.0 * h)
        jq = np.zeros(l_uav.shape + (len(mics) + 1,))
        jq[np.arange(len(idx)), idx] = dl
        jq[:, -1] = dl * tprop
        return l_uav, jb, jq

    names = tuple(f"dt_{m}" for m in mics) + ("k_delay",)
    return Effect(
        name="emission_time", params=names, units=("s",) * len(mics) + ("",),
        start=tuple(float(start.get(m, 0.0)) for m in mics) + (0.0,),
        bounds=(CLOCK_RANGE_S,) * len(mics) + ((-2.0, 2.0),),
        needs=(("t_e", "no emission times"),), reads=("t_e", "mic_enu", "uav_enu"), apply=apply,
        description="time-base error with one clock offset per microphone: model at t_e + dt_mic + k_delay d/c",
        covariates=covariates)
