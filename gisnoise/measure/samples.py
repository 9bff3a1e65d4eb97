"""Measurement samples at emission time: the common input of fit and diagnosis.

The campaign reader (:mod:`gisnoise.measure.campaign`) produces one :class:`Samples`
table per campaign (all microphones and flights stacked); the simulator, the
fitter, the diagnosis and the design all read and write this one structure.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["Samples", "series_key", "series_ids"]


def series_key(mic: Any, flight: Any) -> np.ndarray:
    """Key of the time series (one microphone, one flight) of each row: ``"<mic>\\x1f<flight>"``.

    The one definition of a series for the reader, the fit, the effects and the diagnosis.

    Examples
    --------
    >>> series_key(["m1", "m2"], ["f1", "f1"]).tolist()
    ['m1\\x1ff1', 'm2\\x1ff1']
    """
    return np.char.add(np.char.add(np.asarray(mic, dtype=str), "\x1f"), np.asarray(flight, dtype=str))


def series_ids(mic: Any, flight: Any) -> np.ndarray:
    """Integer id (0, 1, ...) of the series of each row, in the sorted order of :func:`series_key`.

    Examples
    --------
    >>> series_ids(["m2", "m1", "m2"], ["f1", "f1", "f1"]).tolist()
    [1, 0, 1]
    """
    return np.unique(series_key(mic, flight), return_inverse=True)[1].ravel()


@dataclass(frozen=True, eq=False)
class Samples:
    """A table of samples, one row per (microphone, averaging block).

    All arrays have length ``n``.  Angles of the emission are radians, attitude
    degrees (as in the flight log).

    Attributes
    ----------
    mic, flight : ndarray of str
        Microphone and flight id of each row.
    t_r, t_e : ndarray
        Reception and emission time, s since the flight's start.
    level : ndarray
        Measured A-weighted level, dB(A), free-field (and absorption-corrected
        when the reader was asked to).
    d, phi, theta : ndarray
        Distance (m), azimuth and polar angle (rad) of UAV -> microphone in body axes.
    power_w : ndarray
        Electric power at emission time, W.
    phase : ndarray of str
        Flight phase at emission time.
    roll, pitch, yaw : ndarray
        Attitude at emission time, deg.
    uav_enu, mic_enu, vel_enu : ndarray, shape (n, 3)
        UAV position, microphone position and UAV ground velocity in the
        campaign's ENU frame, m and m/s.
    valid : ndarray of bool
        True where the sample may be used (not masked).
    mask_reason : ndarray of str
        Empty where valid, else why: ``low_snr``, ``event``, ``excluded``, ...
    rpm, airspeed_m_s : ndarray or None
        Optional propeller speed and airspeed.
    band_f : ndarray or None
        Exact mid-band frequencies of band levels, Hz, shape (nb,).
    bands : ndarray or None
        Unweighted one-third-octave band levels, dB, shape (n, nb); NaN where absent.
    background_db : ndarray or None
        Estimated background level per row, dB(A), when known.
    meta : dict
        Free-form facts (weather, speed of sound, reference power, origin).
    """

    mic: np.ndarray
    flight: np.ndarray
    t_r: np.ndarray
    t_e: np.ndarray
    level: np.ndarray
    d: np.ndarray
    phi: np.ndarray
    theta: np.ndarray
    power_w: np.ndarray
    phase: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    uav_enu: np.ndarray
    mic_enu: np.ndarray
    vel_enu: np.ndarray
    valid: np.ndarray
    mask_reason: np.ndarray
    rpm: np.ndarray | None = None
    airspeed_m_s: np.ndarray | None = None
    band_f: np.ndarray | None = None
    bands: np.ndarray | None = None
    background_db: np.ndarray | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.level)
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None or f.name in ("meta", "band_f"):
                continue
            if len(v) != n:
                raise InputError(f"samples: field '{f.name}' has {len(v)} rows, expected {n}", field=f.name)

    def __len__(self) -> int:
        return len(self.level)

    def select(self, mask: Any) -> Samples:
        """Rows where ``mask`` is true (boolean or index array)."""
        m = np.asarray(mask)
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v if (v is None or f.name in ("meta", "band_f")) else v[m]
        return Samples(**kw)

    def usable(self, phase: str | None = None) -> Samples:
        """Valid rows, optionally of one phase."""
        m = self.valid.copy()
        if phase is not None:
            m &= self.phase == phase
        return self.select(m)

    def with_(self, **changes: Any) -> Samples:
        return replace(self, **changes)

    @property
    def bank(self) -> np.ndarray:
        """Bank (roll) angle, rad."""
        return np.radians(self.roll)

    @property
    def speed_m_s(self) -> np.ndarray:
        """Ground speed, m/s."""
        return np.linalg.norm(self.vel_enu, axis=1)

    def inputs(self, reference_power_w: float) -> dict[str, Any]:
        """Model inputs for an ansatz (``d``, ``phi``, ``theta``, ``p_el``) plus the extras
        extensions may read (``bank``, ``rpm``, ``speed``, ``uav_enu``, ``mic_enu``, ``vel_enu``,
        ``band_f``, ``bands``, ``t_e``, ``meta``)."""
        x: dict[str, Any] = {
            "d": self.d, "phi": self.phi, "theta": self.theta,
            "p_el": self.power_w / float(reference_power_w),
            "bank": self.bank, "speed": self.speed_m_s, "t_e": self.t_e, "t_r": self.t_r,
            "uav_enu": self.uav_enu, "mic_enu": self.mic_enu, "vel_enu": self.vel_enu,
            "roll": self.roll, "pitch": self.pitch, "yaw": self.yaw, "meta": self.meta,
        }
        if self.rpm is not None:
            x["rpm"] = self.rpm
        if self.bands is not None:
            x["bands"] = self.bands
            x["band_f"] = self.band_f
        return x
