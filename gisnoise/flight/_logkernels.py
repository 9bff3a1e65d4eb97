"""Kernels the flight-log readers share: the common time base, optional columns that cover it,
the phase, and the trajectory with its times referred to the flight's start."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError, MissingColumnError, TrajectoryError
from gisnoise.flight.clock import as_unix_time
from gisnoise.flight.ground import GROUND_TOLERANCE_M, REST_SPEED_M_S
from gisnoise.flight.phases import phase_by_speed
from gisnoise.flight.rest import smoothed_speed
from gisnoise.flight.trajectory import Trajectory
from gisnoise.geo import LocalFrame, geoid_undulation

log = logging.getLogger(__name__)

POWER_WAY_OUT = ("give a constant power (--power-w W, or power_w), merge a power_w column into a flight CSV, "
                 "or use a card that does not need power")


def _power(t: np.ndarray, batteries: Sequence[tuple[np.ndarray, np.ndarray]], power_w: float | None) -> np.ndarray:
    """Summed battery power on ``t`` (W), or the constant ``power_w``."""
    if power_w is not None:
        if not (np.isfinite(power_w) and power_w > 0):
            raise InputError(f"power_w must be a positive number of watts, got {power_w!r}", field="power_w")
        return np.full(len(t), float(power_w))
    power = np.zeros_like(t)
    for tt, pw in batteries:
        power += np.interp(t, tt, pw)
    return power


def _at_rest_low(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray) -> np.ndarray:
    """On the ground where no landed flag tells: at rest (speed below REST_SPEED_M_S, smoothed over 1 s)
    within GROUND_TOLERANCE_M of the track's lowest point."""
    return (smoothed_speed(t, lat, lon, h) < REST_SPEED_M_S) & (h - np.min(h) <= GROUND_TOLERANCE_M)


def _time_base(src: str, tb: np.ndarray, spans: Sequence[tuple[float, float]], rate_hz: float | None) -> np.ndarray:
    t0 = max(s[0] for s in spans)
    t1 = min(s[1] for s in spans)
    if not t1 > t0:
        raise TrajectoryError(f"{src}: position, attitude and power are never logged at the same time",
                              field="t")
    if rate_hz is not None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"rate_hz must be positive, got {rate_hz!r}", field="rate_hz")
        return t0 + np.arange(int(np.floor((t1 - t0) * rate_hz)) + 1) / rate_hz
    t = tb[(tb >= t0) & (tb <= t1)]
    if len(t) < 2:
        raise TrajectoryError(f"{src}: fewer than 2 position samples while attitude and power are logged",
                              field="t")
    return t


def _covering(t: np.ndarray, ts: np.ndarray, v: Any, name: str) -> np.ndarray | None:
    v = np.asarray(v, dtype=float)
    ok = np.isfinite(v)
    ts, v = ts[ok], v[ok]
    if len(ts) < 2 or ts[0] > t[0] or ts[-1] < t[-1]:
        log.info("optional %s left out: it does not cover the flight's time span", name)
        return None
    return np.interp(t, ts, v)


def _phase(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray, vtol: np.ndarray | None) -> np.ndarray:
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0]))
    enu = np.stack(frame.to_enu(lat, lon, h), axis=-1)
    vel = np.gradient(enu, t, axis=0)
    phase = phase_by_speed(t, vel)
    if vtol is not None:
        phase = np.where(vtol == "fw", "horizontal", np.where(vtol == "transition", "transition", phase))
    return phase


def _finish(src: str, t: np.ndarray, cols: dict[str, Any], start_utc: Any, utc_offset: float | None,
            utc_field: str, metadata: dict[str, Any] | None = None) -> Trajectory:
    if start_utc is not None:
        if utc_offset is None:
            raise MissingColumnError(f"{src}: no GPS time in the log ('{utc_field}'), cannot align with start_utc",
                                     field=utc_field)
        t_rel = t + utc_offset - as_unix_time(start_utc)
    else:
        t_rel = t - t[0]
    return Trajectory(t=t_rel, source=src, metadata=dict(metadata or {}), **cols)


def msl_height_datum(field: str, geoid_meta: Mapping[str, Any]) -> str:
    """The ``height_datum`` of heights logged above mean sea level in ``field`` and made ellipsoidal with the
    undulation that ``geoid_meta`` states (:func:`msl_to_ellipsoid_undulation`).

    >>> msl_height_datum("GPS.Alt", {"geoid_model": "EGM96 (egm96_15.gtx)"})
    'mean sea level (GPS.Alt) + geoid undulation: EGM96 (egm96_15.gtx)'
    """
    return f"mean sea level ({field}) + geoid undulation: {geoid_meta['geoid_model']}"


def estimator_height_datum(field: str, anchor_datum: str) -> str:
    """The ``height_datum`` of heights whose course is the estimator's height ``-field`` (NED ``z``, up = ``-z``)
    and whose level is its median offset to heights in ``anchor_datum`` (a GNSS receiver's, over the time both
    are logged).

    >>> print(estimator_height_datum("vehicle_local_position.z", "ellipsoid (gps.alt_ellipsoid)"))
    ellipsoid (gps.alt_ellipsoid), through the median offset of the estimator's height -vehicle_local_position.z to it
    """
    return f"{anchor_datum}, through the median offset of the estimator's height -{field} to it"


def msl_to_ellipsoid_undulation(lat: np.ndarray, lon: np.ndarray, given: float | None,
                                what: str) -> tuple[np.ndarray | float, dict[str, Any]]:
    """The geoid undulation N (m) that turns heights above mean sea level at ``lat``, ``lon`` (deg) into
    ellipsoidal heights, and the metadata that states it (``geoid_model``, ``geoid_undulation_m``: the
    mean over the samples, ``geoid_undulation_range_m``).

    ``given`` (m) overrides the geoid model; without it the grid :func:`gisnoise.geo.geoid_undulation`
    finds gives N per sample, and no grid raises an error naming ``--geoid-undulation``.
    """
    if given is not None:
        if not np.isfinite(given) or abs(given) > 150.0:
            raise InputError(f"geoid_undulation_m must be a finite number of metres within -150..150 (the geoid "
                             f"departs less than 110 m from the ellipsoid), got {given!r}", field="geoid_undulation_m")
        return float(given), {"geoid_model": "given by the user", "geoid_undulation_m": float(given)}
    n, grid = geoid_undulation(lat, lon, what=what)
    return n, {"geoid_model": grid.describe(), "geoid_undulation_m": float(np.mean(n)),
               "geoid_undulation_range_m": [float(np.min(n)), float(np.max(n))]}
