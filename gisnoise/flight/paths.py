"""Timed paths: attitude, phase and power of a time-stamped path derived from its motion (no wind)."""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.errors import TrajectoryError
from gisnoise.flight.glitches import mend_glitches
from gisnoise.flight.phases import MULTICOPTER_PHASES
from gisnoise.flight.trajectory import Trajectory
from gisnoise.flight.vehicle import GRAVITY, VehicleModel
from gisnoise.geo import LocalFrame, wrap_angle

__all__ = ["derive_states", "trajectory_from_path"]


def derive_states(t: Any, e: Any, n: Any, u: Any, vehicle: VehicleModel | None = None, *,
                  phase: Any = None) -> dict[str, np.ndarray]:
    """Attitude, phase and power of a timed path from its motion (no wind).

    Parameters
    ----------
    t : array_like
        Time, s, strictly increasing.
    e, n, u : array_like
        Local ENU positions, m.
    vehicle : VehicleModel, optional
    phase : array_like of str, optional
        Given phases; derived when None: horizontal speed below 1 m/s is ``hover``
        (vertical speed below 0.3 m/s), ``climb`` or ``sink``; below the transition speed
        ``transition``; else ``horizontal``.

    Returns
    -------
    dict
        ``yaw`` (course), ``pitch`` (flight-path angle, 0 in multicopter phases),
        ``roll`` (coordinated-turn bank ``atan(v chi_dot / g)``), all deg; ``power_w`` (W),
        ``phase``, ``airspeed_m_s``.
    """
    veh = vehicle or VehicleModel()
    t = np.asarray(t, dtype=float)
    pos = np.stack([np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)], axis=-1)
    if t.size < 2:
        vel = np.zeros_like(pos)
    else:
        vel = np.gradient(pos, t, axis=0, edge_order=1)
    vh = np.hypot(vel[:, 0], vel[:, 1])
    w = vel[:, 2]
    moving = vh > 0.5
    course = np.arctan2(vel[:, 0], vel[:, 1])
    if moving.any():
        idx = np.flatnonzero(moving)
        nearest = idx[np.clip(np.searchsorted(idx, np.arange(t.size)), 0, idx.size - 1)]
        course = np.where(moving, course, course[nearest])
    else:
        course = np.zeros(t.size)
    unwrapped = np.unwrap(course)
    rate = np.gradient(unwrapped, t) if t.size > 1 else np.zeros(t.size)
    speed = np.sqrt(vh ** 2 + w ** 2)
    accel = np.gradient(speed, t) if t.size > 1 else np.zeros(t.size)
    if phase is None:
        ph = np.where(vh < 1.0, np.where(w > 0.3, "climb", np.where(w < -0.3, "sink", "hover")),
                      np.where(vh < veh.transition_speed_m_s, "transition", "horizontal"))
    else:
        ph = np.asarray(phase).astype(str)
    multi = np.isin(ph, MULTICOPTER_PHASES)
    bank = np.where(multi, 0.0, np.arctan(vh * rate / GRAVITY))
    pitch = np.where(multi, 0.0, np.arctan2(w, np.maximum(vh, 1e-9)))
    f = np.where(multi, 0.0, np.where(ph == "transition", veh.wing_fraction(vh), 1.0))
    p_fwd = veh.power_w(vh, w, bank, accel, f)
    p_rot = veh.rotor_power_w(veh.weight_n, w) + veh.systems_power_w
    power = np.where(multi, p_rot, p_fwd)
    return {"yaw": np.degrees(wrap_angle(course)), "pitch": np.degrees(pitch), "roll": np.degrees(bank),
            "power_w": power, "phase": ph, "airspeed_m_s": speed}


def trajectory_from_path(t: Any, lat: Any, lon: Any, h: Any, *, vehicle: VehicleModel | None = None,
                         source: str = "path", **given: Any) -> Trajectory:
    """A trajectory from a timed path; fields in ``given`` (flight-CSV names) win over derived ones."""
    t = np.asarray(t, dtype=float)
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    h = np.asarray(h, dtype=float)
    if t.size == 0:
        raise TrajectoryError(f"{source}: the trajectory is empty", field="t")
    for name, a in (("t", t), ("lat", lat), ("lon", lon), ("h", h)):
        if not np.all(np.isfinite(a)):
            raise TrajectoryError(f"{source}: field '{name}' has NaN or infinite values", field=name)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise TrajectoryError(f"{source}: field 't' is not strictly increasing at sample {i}", field="t")
    glitches = mend_glitches(t, lat, lon, h)  # before the states are derived from them
    lat, lon, h = glitches.lat, glitches.lon, glitches.h
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h.min()))
    e, n, u = frame.to_enu(lat, lon, h)
    der = derive_states(t, e, n, u, vehicle, phase=given.get("phase"))
    kw: dict[str, Any] = {"t": t, "lat": lat, "lon": lon, "h": h}
    for k in ("roll", "pitch", "yaw", "power_w", "phase", "airspeed_m_s"):
        kw[k] = given[k] if given.get(k) is not None else der[k]
    if given.get("rpm") is not None:
        kw["rpm"] = given["rpm"]
    return Trajectory(**kw, source=source, metadata=glitches.metadata(t))
