"""Effects in time: a misaligned time base (emission time) and transient background events.

Both need facts beyond a single row (the rates of the inputs along each time
series, the detected event windows), computed once per data set by their
``covariates`` and attached to the rows by :func:`gisnoise.model.effect.bind`;
:mod:`gisnoise.model.effects` registers them in the library.
"""

from __future__ import annotations

import numpy as np

from gisnoise.errors import InputError
from gisnoise.model._inputs import series_ids, sound_speed_of, speed_of_sound
from gisnoise.model.effect import Effect

__all__ = ["EMISSION_TIME", "BACKGROUND_EVENT", "emission_covariates", "shifted_inputs"]

# --------------------------------------------------------------------------- emission time

_SHIFTED = ("d", "phi", "theta", "p_el")
_DT = 1e-3  # s, step of the central difference along the time derivative of the inputs


def _series_gradient(v: np.ndarray, t: np.ndarray, sid: np.ndarray) -> np.ndarray:
    """d v / d t along each series (rows sorted by time within a series), 0 for single rows."""
    out = np.zeros_like(v, dtype=float)
    order = np.lexsort((t, sid))
    s, ts, vs = sid[order], t[order], v[order]
    cuts = np.flatnonzero(np.diff(s)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(s)], strict=True):
        if b - a >= 2:
            tt = ts[a:b]
            if np.all(np.diff(tt) > 0):
                out[order[a:b]] = np.gradient(vs[a:b], tt)
    return out


def _unwrap_series(v, t, sid):
    out = v.copy()
    order = np.lexsort((t, sid))
    s = sid[order]
    cuts = np.flatnonzero(np.diff(s)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(s)], strict=True):
        out[order[a:b]] = np.unwrap(v[order[a:b]])
    return out


def emission_covariates(x):
    """Rates ``rate_d``, ``rate_phi``, ``rate_theta``, ``rate_p_el`` along each time series and ``t_prop = d/c``."""
    sid = series_ids(x)
    t = np.asarray(x["t_e"], dtype=float)
    out = {}
    for k in _SHIFTED:
        v = np.broadcast_to(np.asarray(x[k], dtype=float), t.shape)
        if k == "phi":
            v = _unwrap_series(v, t, sid)
        out[f"rate_{k}"] = _series_gradient(v, t, sid)
    out["t_prop"] = np.broadcast_to(np.asarray(x["d"], dtype=float), t.shape) / sound_speed_of(x)
    return out


def shifted_inputs(x, delta):
    """The inputs ``x`` moved ``delta`` seconds along their rates (first order; needs :func:`emission_covariates`)."""
    xs = dict(x)
    xs["d"] = np.maximum(np.asarray(x["d"], dtype=float) + delta * x["rate_d"], 0.1)
    xs["phi"] = np.asarray(x["phi"], dtype=float) + delta * x["rate_phi"]
    xs["theta"] = np.clip(np.asarray(x["theta"], dtype=float) + delta * x["rate_theta"], -np.pi / 2, np.pi / 2)
    xs["p_el"] = np.maximum(np.asarray(x["p_el"], dtype=float) + delta * x["rate_p_el"], 1e-6)
    return xs


def _emission_apply(base_kernel, p_base, q, x, d_ref, want_jac):
    if "rate_d" not in x:
        x = {**x, **emission_covariates(x)}
    tprop = np.asarray(x["t_prop"], dtype=float)
    delta = q[0] + q[1] * tprop
    l_uav, jb = base_kernel(p_base, shifted_inputs(x, delta), d_ref, want_jac)
    if not want_jac:
        return l_uav, None, None
    lp, _ = base_kernel(p_base, shifted_inputs(x, delta + _DT), d_ref, False)
    lm, _ = base_kernel(p_base, shifted_inputs(x, delta - _DT), d_ref, False)
    dl = (lp - lm) / (2.0 * _DT)
    return l_uav, jb, np.stack([dl, dl * tprop], axis=-1)


def _emission_check(x):
    if speed_of_sound(x.get("meta")) is None:
        return "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)"
    if len(np.atleast_1d(x["t_e"])) < 10:
        return "fewer than 10 samples: no time series to shift"
    return None


EMISSION_TIME = Effect(
    name="emission_time",
    params=("dt_clock", "k_delay"),
    units=("s", ""),
    start=(0.0, 0.0),
    bounds=((-5.0, 5.0), (-2.0, 2.0)),
    needs=(("t_e", "no emission times"), ("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions"),
           ("meta", "no campaign facts (speed of sound)")),
    reads=("t_e", "mic_enu", "uav_enu"),
    apply=_emission_apply,
    description="time-base error: model at t_e + dt_clock + k_delay d/c (first order in the input rates)",
    check=_emission_check,
    covariates=emission_covariates,
)

# --------------------------------------------------------------------------- background events


def _event_apply(base_kernel, p_base, q, x, d_ref, want_jac):
    l_uav, jb = base_kernel(p_base, x, d_ref, want_jac)
    win = np.asarray(x["event_window"], dtype=int)
    inside = win >= 0
    ev = np.full(l_uav.shape, -np.inf)
    if len(q):
        ev[inside] = np.asarray(q, dtype=float)[win[inside]]
    hi = np.maximum(l_uav, ev)
    total = np.where(inside, hi + 10.0 * np.log10(10.0 ** ((l_uav - hi) / 10.0) + 10.0 ** ((ev - hi) / 10.0)), l_uav)
    if not want_jac:
        return total, None, None
    w_ev = np.where(inside, 10.0 ** ((ev - total) / 10.0), 0.0)
    jb = jb * (1.0 - w_ev)[..., None]
    jq = np.zeros(l_uav.shape + (len(q),))
    if len(q):
        rows = np.flatnonzero(inside)
        jq[rows, win[inside]] = w_ev[inside]
    return total, jb, jq


def _event_covariates(x):
    """Event windows from the rows marked by the detector (input ``event_window``) or by the reader."""
    win = x.get("event_window")
    if win is None:
        raise InputError("background_event needs the input 'event_window' (window index per row, -1 outside)",
                         field="event_window")
    win = np.asarray(win, dtype=int)
    k = int(win.max()) + 1 if win.size and win.max() >= 0 else 0
    return {"event_window": win, "__params__": tuple(f"ev{j + 1}" for j in range(k))}


BACKGROUND_EVENT = Effect(
    name="background_event",
    params=(),
    units=(),
    start=(),
    bounds=(),
    needs=(("event_window", "no event windows detected"),),
    reads=("t_e", "mic_enu", "uav_enu"),
    apply=_event_apply,
    description="transient background events: model energetically summed with a level ev_j in window j",
    covariates=_event_covariates,
    dynamic=("dB", -20.0, 140.0),
)
