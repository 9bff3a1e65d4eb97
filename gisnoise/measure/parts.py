"""The campaign and its parts: microphones, flights, excluded intervals, level series, problems found.

Value objects only; :func:`gisnoise.measure.campaign.read_campaign` builds them from a
campaign folder and :meth:`Campaign.samples` stacks the levels at emission time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.measure.events import DEFAULT_EVENT_DB, DEFAULT_SNR_DB
from gisnoise.measure.samples import Samples
from gisnoise.measure.table import build_samples

__all__ = ["Campaign", "Microphone", "Flight", "Exclusion", "LevelSeries", "Problem"]

ProgressFn = Callable[[float, float], None]
"""``progress(done, total)``; may raise :class:`~gisnoise.errors.Cancelled`."""


@dataclass(frozen=True)
class Problem:
    """One problem found in a campaign: the file, the field and a one-line message."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class Microphone:
    """A microphone: id, WGS84 position (deg, deg, m ellipsoidal), mount, calibration."""

    id: str
    lat: float
    lon: float
    h: float
    mount: str = "free_field"
    sensitivity_v_per_pa: float | None = None
    full_scale_v: float = 1.0
    background_db: float | None = None
    height_agl_m: float | None = None
    """Height of the capsule above the ground, m (for ground reflection); None when not stated."""


@dataclass(frozen=True)
class Flight:
    """A flight: id, start instant (unix s, UTC), its log file, geoid undulation (m) and, for logs
    without battery current, a constant electric power (W)."""

    id: str
    start_utc: float
    log: str
    geoid_undulation_m: float | None = None
    power_w: float | None = None


@dataclass(frozen=True)
class Exclusion:
    """A user-excluded reception-time interval [t0, t1] s of one flight (one or all mics)."""

    flight: str
    t0: float
    t1: float
    mic: str | None = None
    reason: str = ""


@dataclass(frozen=True, eq=False)
class LevelSeries:
    """Levels of one microphone during one flight.

    Attributes
    ----------
    mic, flight : str
    source : str
        File the levels came from.
    t : ndarray
        Reception time at the block centre, s since the flight's start.
    la : ndarray
        A-weighted level, free field, dB(A).
    band_f : ndarray or None
        Exact mid-band frequencies, Hz.
    bands : ndarray or None
        Unweighted band levels, free field, dB, shape (n, nb).
    sample_rate_hz : float or None
        Sample rate of the WAV recording the levels were computed from, Hz (read from it, or from the level
        file's source record); None for levels a user brings.
    """

    mic: str
    flight: str
    source: str
    t: np.ndarray
    la: np.ndarray
    band_f: np.ndarray | None = None
    bands: np.ndarray | None = None
    sample_rate_hz: float | None = None


@dataclass(frozen=True, eq=False)
class Campaign:
    """A read and checked campaign.  Build with :func:`~gisnoise.measure.campaign.read_campaign`.

    Attributes
    ----------
    folder : Path
    origin : LocalFrame
        ENU frame of the campaign (``origin`` of campaign.json).
    weather : dict
        ``temperature_c``, ``humidity_pct``, ``pressure_kpa`` and optional wind.
    vehicle : dict
        ``name`` and ``reference_power_w`` (W).
    speed_of_sound_m_s : float
    microphones : tuple of Microphone
    flights : tuple of Flight
    trajectories : dict flight id -> Trajectory
    levels : tuple of LevelSeries
    exclusions : tuple of Exclusion
    absorption : bool
    snr_db, event_db : float
    """

    folder: Path
    origin: LocalFrame
    weather: Mapping[str, Any]
    vehicle: Mapping[str, Any]
    speed_of_sound_m_s: float
    microphones: tuple[Microphone, ...]
    flights: tuple[Flight, ...]
    trajectories: Mapping[str, Trajectory]
    levels: tuple[LevelSeries, ...]
    exclusions: tuple[Exclusion, ...] = ()
    absorption: bool = False
    snr_db: float = DEFAULT_SNR_DB
    event_db: float = DEFAULT_EVENT_DB
    _samples: list[Samples] = field(default_factory=list, repr=False, compare=False)

    @property
    def reference_power_w(self) -> float:
        return float(self.vehicle["reference_power_w"])

    def microphone(self, mic_id: str) -> Microphone:
        for m in self.microphones:
            if m.id == mic_id:
                return m
        raise KeyError(mic_id)

    def mic_enu(self, mic_id: str) -> np.ndarray:
        """ENU position of a microphone, m."""
        m = self.microphone(mic_id)
        return np.array([float(v) for v in self.origin.to_enu(m.lat, m.lon, m.h)])

    def samples(self) -> Samples:
        """All microphones and flights stacked at emission time (computed once)."""
        if not self._samples:
            self._samples.append(build_samples(self))
        return self._samples[0]
