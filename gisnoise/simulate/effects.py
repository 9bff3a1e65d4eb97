"""The injected effects of the simulator: their names, defaults, written forms and level changes.

A scenario's ``effects`` object turns effects on; :mod:`gisnoise.simulate.propagation`
applies them to the sound reaching each microphone (the clock offset acts on the
flight log in :mod:`gisnoise.simulate.flying`, the events on the background).

Injected effects (``effects`` object; each key turns one on, ``{}`` takes defaults)
----------------------------------------------------------------------------------
``bank_angle``
    Interaction noise of the non-axial propeller inflow in turning flight:
    ``dL = db_at_30deg * (sin|bank| / sin 30deg)^2`` plus a random fluctuation
    (Ornstein-Uhlenbeck in time, ``fluctuation_tau_s``) whose standard deviation is
    ``fluctuation_db`` scaled by the same factor.  Defaults 3 dB, 1 dB, 0.3 s.
``atmospheric_absorption``
    ISO 9613-1 pure-tone absorption at each band's exact mid-band frequency over
    the whole path: ``dL_band = -scale * alpha(f, T, h_r, p) * d``.  Default scale 1.
    (The card is the absorption-free emission, which the reader's per-band
    correction recovers.)
``ground_reflection``
    Microphones above ground (``height_m > 0``, mount ``free_field``) receive an image
    source: band energy factor ``1 + (r1/r2)^2 q^2 + 2 (r1/r2) q gamma <cos k dr>``
    with the band average of ``cos(2 pi f dr / c)`` over the band edges, path
    difference ``dr = r2 - r1``, reflection coefficient ``q`` (real) and coherence
    ``gamma``.  Defaults q = 0.9, gamma = 0.9.
``doppler``
    Convective amplification of a moving source:
    ``dL = -10 n log10(1 - M cos(angle))``, ``M = |v_ground| / c``, angle between the
    velocity and the emission direction.  Default exponent n = 4.
``emission_time``
    A clock offset between log and audio: the flight log's time stamps are late by
    ``offset_s`` (log time = true time + offset).  Default 0.5 s.
``wind``
    Refraction by the wind's speed gradient: downwind propagation gains, upwind
    loses, growing with horizontal range:
    ``dL = db_per_100m * (w / 5 m/s) * cos(psi) * (r_h / 100 m)``, clipped to
    +-``max_db``; ``psi`` is the angle between the direction the wind blows to and
    the horizontal direction UAV -> microphone.  Defaults 1.5 dB, 6 dB.  Needs
    ``weather.wind_speed_m_s > 0``.
``rpm``
    Propeller speed changing the level beyond what power explains:
    ``dL = db_per_decade * log10(rpm / rpm_p)``, with ``rpm_p`` the propeller speed
    the power alone sets.  Default 40 dB per decade.  (The rpm column is written
    in every campaign and varies independently of power by ``vehicle.rpm.jitter_pct``
    whether this effect is on or not.)
``background_event``
    Transient background sound heard on all microphones at once (a jet take-off):
    energy envelope ``sin^2(pi (t - t0) / duration)`` over ``[t0, t0 + duration]``,
    peak ``peak_dba`` (A-weighted), a low-frequency broadband spectrum and a small
    random offset per microphone (``mic_spread_db``).  Either ``events``: a list of
    ``{"flight", "t_s" (start), "duration_s", "peak_dba"}`` or ``count`` events per
    flight placed at random.  Defaults 1 per flight, 40 s, 62 dB(A), 1 dB.

Each effect's form and parameters are written to ``truth.json``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gisnoise.acoustics import band_edges

__all__ = ["EFFECTS", "bank_angle_db", "doppler_db", "wind_db", "ground_reflection_db"]

EFFECTS = ("bank_angle", "atmospheric_absorption", "ground_reflection", "doppler", "emission_time", "wind",
           "rpm", "background_event")

_EFFECT_KEYS: dict[str, dict[str, Any]] = {
    "bank_angle": {"db_at_30deg": 3.0, "fluctuation_db": 1.0, "fluctuation_tau_s": 0.3},
    "atmospheric_absorption": {"scale": 1.0},
    "ground_reflection": {"reflection_coefficient": 0.9, "coherence": 0.9},
    "doppler": {"exponent": 4.0},
    "emission_time": {"offset_s": 0.5},
    "wind": {"db_per_100m": 1.5, "max_db": 6.0},
    "rpm": {"db_per_decade": 40.0},
    "background_event": {"count": 1, "duration_s": 40.0, "peak_dba": 62.0, "mic_spread_db": 1.0, "events": None},
}
_EFFECT_FORMS = {
    "bank_angle": "dL = db_at_30deg * (sin|bank| / sin 30deg)^2 + OU fluctuation (std fluctuation_db * same factor,"
                  " correlation time fluctuation_tau_s)",
    "atmospheric_absorption": "dL_band = -scale * alpha_ISO9613-1(f_mid, T, RH, p) * d",
    "ground_reflection": "band energy * (1 + a^2 + 2 a coherence <cos(2 pi f dr / c)>_band), a = q r1 / r2;"
                         " microphones above ground, not ground-plate",
    "doppler": "dL = -10 exponent log10(1 - M cos(angle(v, source->mic))), M = |v_ground| / c",
    "emission_time": "flight log time = true time + offset_s",
    "wind": "dL = clip(db_per_100m * (w / 5 m/s) * cos(psi) * r_h / 100 m, +-max_db), psi from downwind direction",
    "rpm": "dL = db_per_decade * log10(rpm / rpm_from_power)",
    "background_event": "event energy peak_dba * sin^2(pi (t - t0) / duration_s) on all microphones at once"
                        " (+ per-mic offset N(0, mic_spread_db)), jet-like spectrum",
}


def bank_angle_db(bank_rad: Any, db_at_30deg: float) -> np.ndarray:
    """Turning-flight interaction noise, ``db_at_30deg (sin|bank| / sin 30deg)^2``, dB."""
    s = np.sin(np.abs(np.asarray(bank_rad, dtype=float))) / 0.5
    return db_at_30deg * s * s


def doppler_db(vel_enu: np.ndarray, r_enu: np.ndarray, c: float, exponent: float) -> np.ndarray:
    """Convective amplification ``-10 n log10(1 - M cos)``, dB.

    ``vel_enu`` (..., 3) m/s source velocity, ``r_enu`` (..., 3) source -> observer."""
    d = np.linalg.norm(r_enu, axis=-1)
    m_cos = np.sum(vel_enu * r_enu, axis=-1) / (c * np.where(d > 0, d, 1.0))
    return -10.0 * exponent * np.log10(1.0 - m_cos)


def wind_db(r_enu: np.ndarray, wind_speed: float, wind_from_deg: float, db_per_100m: float,
            max_db: float) -> np.ndarray:
    """Refraction gain of downwind / loss of upwind propagation, dB (see module docstring)."""
    to = math.radians(wind_from_deg) + math.pi
    w = np.array([math.sin(to), math.cos(to)])
    rh = np.hypot(r_enu[..., 0], r_enu[..., 1])
    cos_psi = (r_enu[..., 0] * w[0] + r_enu[..., 1] * w[1]) / np.where(rh > 0, rh, 1.0)
    return np.clip(db_per_100m * wind_speed / 5.0 * cos_psi * rh / 100.0, -max_db, max_db)


def ground_reflection_db(src_enu: np.ndarray, mic_enu: np.ndarray, mic_height: float, f_mid: np.ndarray, c: float,
                         q: float, coherence: float) -> np.ndarray:
    """Band level change by a ground image source, dB, shape (..., n_bands).

    The ground plane lies ``mic_height`` m below the microphone; ``src_enu`` (..., 3)."""
    ground = mic_enu[2] - mic_height
    r1 = np.linalg.norm(src_enu - mic_enu, axis=-1)
    img = src_enu.copy()
    img[..., 2] = 2.0 * ground - img[..., 2]
    r2 = np.linalg.norm(img - mic_enu, axis=-1)
    dr = (r2 - r1)[..., None]
    lo, hi = band_edges(f_mid)
    k_lo, k_hi = 2 * np.pi * lo / c, 2 * np.pi * hi / c
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = (np.sin(k_hi * dr) - np.sin(k_lo * dr)) / ((k_hi - k_lo) * dr)
    avg = np.where(dr > 1e-9, avg, 1.0)
    a = (r1 / r2)[..., None] * q
    return 10.0 * np.log10(1.0 + a * a + 2.0 * a * coherence * avg)

