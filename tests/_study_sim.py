"""An independent study simulator: wrong campaign metadata written onto simulated campaigns from first principles.

The control campaign comes from ``gisnoise.simulate`` (no effect injected); this
helper then changes what the microphones heard, with forms of its own (none of
the effect library's extension terms, none of the simulator's effect forms):

``elevate``
    A microphone the campaign lists on a ground plate stood ``h`` m above grass.
    Two-ray model per one-third-octave band: pressure ``e^{ikr1}/r1 + Q e^{ikr2}/r2``
    with the plane-wave reflection coefficient ``Q = (Z sin psi - 1) / (Z sin psi + 1)``
    of a locally reacting ground, impedance ``Z`` of Delany & Bazley (1970) with
    flow resistivity ``sigma`` (grass about 200 kPa s/m^2), grazing angle ``psi`` of the
    image path; the energy factor ``|1 + Q (r1/r2) e^{ik(r2-r1)}|^2`` is averaged over
    nine frequencies across each band.  The control's level is the free field
    (the reader removed the plate's pressure doubling), so the factor multiplies it;
    LA is the A-weighted sum of the changed bands.
``clock``
    A microphone's clock runs ``offset_s`` behind: what it stamps ``t`` was heard at
    ``t + offset_s``; its level and band series are resampled (linear interpolation
    of the energy) and rows whose true time falls outside the record are dropped.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from gisnoise.acoustics import a_weighting

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "sample_data" / "scenarios" / "diagnosis_base.json"


def control(seed: int, *, all_plates: bool = False):
    """Samples of the diagnosis base scenario without any effect (all microphones on ground plates if asked)."""
    from gisnoise import simulate

    doc = json.loads(SCENARIO.read_text())
    doc["seed"] = seed
    if all_plates:
        for m in doc["microphones"]:
            m["mount"] = "ground_plate"
            m.pop("height_m", None)
    return simulate.simulate_samples(simulate.run(doc, base_dir=SCENARIO.parent))


def delany_bazley(f, sigma_pa_s_m2: float):
    """Normalized surface impedance of a porous ground (Delany & Bazley), time convention e^{-i omega t}."""
    x = 1.2 * np.asarray(f, dtype=float) / sigma_pa_s_m2
    return 1.0 + 0.0571 * x ** -0.754 + 1j * 0.087 * x ** -0.732


def two_ray_db(band_f, mic_xyz, uav_xyz, h: float, c: float, sigma_pa_s_m2: float = 200e3):
    """Band level change (dB, rows x bands) of a microphone ``h`` m above a porous ground against free field."""
    mic = np.asarray(mic_xyz, dtype=float)
    uav = np.asarray(uav_xyz, dtype=float)
    hs = np.maximum(uav[:, 2] - (mic[:, 2]), 0.5)  # source height above the ground the listed position stands on
    rh = np.hypot(uav[:, 0] - mic[:, 0], uav[:, 1] - mic[:, 1])
    r1 = np.hypot(rh, hs - h)
    r2 = np.hypot(rh, hs + h)
    sin_psi = (hs + h) / r2
    sub = 2.0 ** (np.linspace(-0.5, 0.5, 9) / 3.0)
    f = np.asarray(band_f, dtype=float)[None, :, None] * sub[None, None, :]
    z = delany_bazley(f, sigma_pa_s_m2)
    q = (z * sin_psi[:, None, None] - 1.0) / (z * sin_psi[:, None, None] + 1.0)
    k = 2.0 * np.pi * f / c
    p = 1.0 + q * (r1 / r2)[:, None, None] * np.exp(1j * k * (r2 - r1)[:, None, None])
    return 10.0 * np.log10(np.mean(np.abs(p) ** 2, axis=2))


def _la(bands, band_f):
    return 10.0 * np.log10(np.sum(10.0 ** ((bands + a_weighting(band_f)) / 10.0), axis=1))


def elevate(s, heights: dict[str, float], *, sigma_pa_s_m2: float = 200e3):
    """The samples as heard by microphones standing ``heights[mic]`` m above grass (metadata unchanged)."""
    c = float(s.meta["speed_of_sound_m_s"])
    bands = np.array(s.bands, dtype=float)
    for m, h in heights.items():
        rows = np.flatnonzero(s.mic.astype(str) == m)
        bands[rows] += two_ray_db(s.band_f, s.mic_enu[rows], s.uav_enu[rows], h, c, sigma_pa_s_m2)
    return replace(s, bands=bands, level=_la(bands, s.band_f))


def clock(s, mic: str, offset_s: float):
    """The samples with microphone ``mic``'s clock ``offset_s`` behind (metadata unchanged)."""
    level = np.array(s.level, dtype=float)
    bands = None if s.bands is None else np.array(s.bands, dtype=float)
    keep = np.ones(len(s), dtype=bool)
    for fl in np.unique(s.flight.astype(str)):
        rows = np.flatnonzero((s.mic.astype(str) == mic) & (s.flight.astype(str) == fl))
        rows = rows[np.argsort(s.t_e[rows])]
        t = s.t_e[rows]
        tt = t + offset_s
        keep[rows] = (tt >= t[0]) & (tt <= t[-1])
        level[rows] = 10.0 * np.log10(np.interp(tt, t, 10.0 ** (s.level[rows] / 10.0)))
        if bands is not None:
            for j in range(bands.shape[1]):
                bands[rows, j] = 10.0 * np.log10(np.interp(tt, t, 10.0 ** (s.bands[rows, j] / 10.0)))
    return replace(s, level=level, bands=bands).select(keep)


def wrong_temperature(s, temperature_c: float):
    """The samples with the campaign's temperature (and speed of sound) from a station that logged ``temperature_c``."""
    from gisnoise.acoustics import speed_of_sound

    meta = dict(s.meta)
    weather = dict(meta.get("weather", {}))
    weather["temperature_c"] = temperature_c
    meta["weather"] = weather
    meta["speed_of_sound_m_s"] = float(speed_of_sound(temperature_c))
    return replace(s, meta=meta)


def move_mic(s, mic: str, distance_m: float, bearing_deg: float):
    """The samples as if microphone ``mic`` were listed ``distance_m`` away (towards ``bearing_deg``) from where it stood.

    The geometry the diagnosis reads (microphone position, distance, emission angles) is recomputed for the
    listed position; the levels stay what the true position heard.
    """
    from gisnoise.geo import emission_angles

    rows = s.mic.astype(str) == mic
    b = np.radians(bearing_deg)
    mic_enu = np.array(s.mic_enu, dtype=float)
    mic_enu[rows, 0] += distance_m * np.sin(b)
    mic_enu[rows, 1] += distance_m * np.cos(b)
    d, phi, theta = (np.array(v, dtype=float) for v in (s.d, s.phi, s.theta))
    r = mic_enu[rows] - s.uav_enu[rows]
    d[rows], phi[rows], theta[rows] = emission_angles(r[:, 0], r[:, 1], r[:, 2], np.radians(s.yaw[rows]),
                                                      np.radians(s.pitch[rows]), np.radians(s.roll[rows]))
    return replace(s, mic_enu=mic_enu, d=d, phi=phi, theta=theta)
