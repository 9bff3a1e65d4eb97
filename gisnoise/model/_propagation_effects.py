"""Effects of the sound path: atmospheric absorption, the ground reflection, wind.

Each is an :class:`~gisnoise.model.effect.Effect` with an additive term ``dL``
(dB) on ``L_UAV``; :mod:`gisnoise.model.effects` registers them in the library.
"""

from __future__ import annotations

import numpy as np

from gisnoise.acoustics import band_edges
from gisnoise.errors import InputError
from gisnoise.model._inputs import mic_height_agl, sound_speed_of, speed_of_sound
from gisnoise.model.effect import Effect, additive

__all__ = ["ATMOSPHERIC_ABSORPTION", "GROUND_REFLECTION", "WIND", "THIRD_OCTAVE", "MIN_REFLECTION_HEIGHT_M",
           "band_cos", "reflection_delay"]

_LN10 = float(np.log(10.0))
_LOWER, _UPPER = band_edges(1.0)
THIRD_OCTAVE = (float(_LOWER), float(_UPPER))
"""Band edges of a one-third octave relative to its centre (:func:`gisnoise.acoustics.band_edges`, base 10)."""

MIN_REFLECTION_HEIGHT_M = 0.3
"""Microphones lower than this (m) count as on the ground: no interference term."""

# --------------------------------------------------------------------------- atmospheric absorption


def _absorption_term(q, x, d_ref, want_jac):
    s = -(np.asarray(x["d"], dtype=float) - d_ref) / 1000.0
    return q[0] * s, (s[..., None] if want_jac else None)


def _absorption_check(x):
    bands = x.get("bands")
    f = x.get("band_f")
    if bands is None or f is None:
        return "no one-third-octave band levels in the microphone files"
    b = np.asarray(bands, dtype=float)
    hi = np.asarray(f, dtype=float) >= 1000.0
    if b.ndim != 2 or not np.any(hi) or not np.any(np.isfinite(b[:, hi])):
        return "no band levels at or above 1 kHz, where absorption acts"
    return None


ATMOSPHERIC_ABSORPTION = Effect(
    name="atmospheric_absorption",
    params=("a_abs",),
    units=("dB/km",),
    start=(0.0,),
    bounds=((0.0, 100.0),),
    needs=(("d", "no distance"), ("bands", "no one-third-octave band levels in the microphone files")),
    reads=("d",),
    apply=additive(_absorption_term),
    description="uncorrected atmospheric absorption: -a_abs (d - d_ref)/1000 dB (paper 5.3.3, ISO 9613-1)",
    check=_absorption_check,
)

# --------------------------------------------------------------------------- ground reflection


def band_cos(u, want_deriv):
    """Cosine ``cos(u)`` averaged over a one-third-octave band about ``u`` (relative band edges).

    Returns ``C(u)`` and ``dC/du``; exact series near ``u = 0``.
    """
    a1, a2 = THIRD_OCTAVE
    u = np.asarray(u, dtype=float)
    small = np.abs(u) < 1e-3
    us = np.where(small, 1.0, u)
    num = np.sin(a2 * us) - np.sin(a1 * us)
    c = np.where(small, 1.0 - (a1 * a1 + a1 * a2 + a2 * a2) * u * u / 6.0, num / ((a2 - a1) * us))
    if not want_deriv:
        return c, None
    dnum = a2 * np.cos(a2 * us) - a1 * np.cos(a1 * us)
    dc = np.where(small, -(a1 * a1 + a1 * a2 + a2 * a2) * u / 3.0, (dnum * us - num) / ((a2 - a1) * us * us))
    return c, dc


def reflection_delay(x):
    """Delay of the ground-reflected path behind the direct one, s (flat ground under the microphone)."""
    h_m = mic_height_agl(x)
    if h_m is None:
        raise InputError("microphone heights above ground unknown: give input mic_agl or meta microphones "
                         "height_agl_m", field="mic_agl")
    c = sound_speed_of(x)
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    ground = mic[..., 2] - h_m
    h_s = np.maximum(uav[..., 2] - ground, 0.0)
    r_h2 = np.sum((uav[..., :2] - mic[..., :2]) ** 2, axis=-1)
    direct = np.sqrt(r_h2 + (h_s - h_m) ** 2)
    reflected = np.sqrt(r_h2 + (h_s + h_m) ** 2)
    tau = (reflected - direct) / c
    # on the ground (plate) the reflection is the pressure doubling the mount correction removes
    return np.where(h_m >= MIN_REFLECTION_HEIGHT_M, tau, np.nan)


def _ground_term(q, x, d_ref, want_jac):
    r, f = q[0], q[1]
    tau = np.asarray(x["tau_ground"], dtype=float) if "tau_ground" in x else reflection_delay(x)
    off = np.isnan(tau)
    tau = np.where(off, 0.0, tau)
    u = 2.0 * np.pi * f * tau
    cb, dcb = band_cos(u, want_jac)
    g = 1.0 + r * r + 2.0 * r * cb
    dl = np.where(off, 0.0, 10.0 * np.log10(g))
    if not want_jac:
        return dl, None
    k = np.where(off, 0.0, 10.0 / (_LN10 * g))
    return dl, np.stack([k * (2.0 * r + 2.0 * cb), k * 2.0 * r * dcb * 2.0 * np.pi * tau], axis=-1)


def _ground_check(x):
    if speed_of_sound(x.get("meta")) is None:
        return "speed of sound unknown (campaign gives neither speed_of_sound_m_s nor temperature)"
    h = mic_height_agl(x)
    if h is None or np.any(np.isnan(h)):
        return "microphone heights above ground unknown"
    if not np.any(h >= MIN_REFLECTION_HEIGHT_M):
        return (f"all microphones on the ground (below {MIN_REFLECTION_HEIGHT_M:g} m): the mount correction "
                "covers the reflection")
    return None


def _ground_initial(x, resid):
    """Grid search of (R, f_g) on the residual (the offset is free), best least-squares match."""
    tau = reflection_delay(x)
    ok = np.isfinite(resid) & np.isfinite(tau)
    best, arg = np.inf, (0.0, 200.0)
    for f in np.geomspace(40.0, 4000.0, 90):
        cb, _ = band_cos(2.0 * np.pi * f * tau[ok], False)
        for r in (0.3, 0.6, 0.9):
            z = 10.0 * np.log10(1.0 + r * r + 2.0 * r * cb)
            z = z - z.mean()
            rr = resid[ok] - resid[ok].mean()
            s = float(np.sum((rr - z) ** 2))
            if s < best:
                best, arg = s, (r, f)
    return {"r_ground": arg[0], "f_ground": arg[1], "__trials__": 90}


GROUND_REFLECTION = Effect(
    name="ground_reflection",
    params=("r_ground", "f_ground"),
    units=("", "Hz"),
    start=(0.0, 200.0),
    bounds=((0.0, 1.0), (20.0, 8000.0)),
    needs=(("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions"),
           ("meta", "no campaign facts (weather, microphone heights)")),
    reads=("mic_enu", "uav_enu"),
    apply=additive(_ground_term),
    description="ground reflection at elevated microphones: 10 log10(1 + R^2 + 2R C(f_g tau)), comb in tau",
    check=_ground_check,
    initial=_ground_initial,
    tested=("r_ground",),
)

# --------------------------------------------------------------------------- wind


def _wind_term(q, x, d_ref, want_jac):
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    h = mic[..., :2] - uav[..., :2]
    rh = np.linalg.norm(h, axis=-1)
    e = h / np.maximum(rh, 1.0)[..., None]
    s = np.asarray(x["d"], dtype=float)[..., None] / 100.0 * e
    return s @ q, (s if want_jac else None)


def _wind_check(x):
    mic = np.asarray(x["mic_enu"], dtype=float)
    uav = np.asarray(x["uav_enu"], dtype=float)
    az = np.arctan2(mic[..., 0] - uav[..., 0], mic[..., 1] - uav[..., 1])
    r = np.hypot(np.mean(np.cos(az)), np.mean(np.sin(az)))
    if r > 0.95:
        return "sound travels in one direction only: wind direction not separable from the level offset"
    return None


WIND = Effect(
    name="wind",
    params=("w_east", "w_north"),
    units=("dB/100 m", "dB/100 m"),
    start=(0.0, 0.0),
    bounds=((-30.0, 30.0), (-30.0, 30.0)),
    needs=(("mic_enu", "no microphone positions"), ("uav_enu", "no UAV positions")),
    reads=("mic_enu", "uav_enu"),
    apply=additive(_wind_term),
    description="wind refraction and convection: (d/100 m) (w_east e_east + w_north e_north)",
    check=_wind_check,
)
