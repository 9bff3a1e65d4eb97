"""A vehicle at rest, and a vehicle lying upside down.

A multicopter's rotors push along its body axis, away from the landing gear.  With the vehicle
inverted (body axis tilted more than 90 deg from the vertical: ``cos(roll) cos(pitch) < 0`` for
Z-Y-X Euler angles) that push has no upward part, so nothing holds the vehicle up against gravity:
in the air it accelerates downwards at g or more, and its speed averaged over 1 s stays below
:data:`REST_SPEED_M_S` for at most ``2 * 0.3 / 9.81 = 0.06`` s (at the top of a flip).  A vehicle
that is inverted *and* at rest for :data:`LYING_MIN_S` or longer is therefore held up by something
else: it lies upside down on the ground (or on a roof, in a tree) after a crash, its motors often
still drawing power.  Such samples do not fly (:attr:`gisnoise.flight.trajectory.Trajectory.flying`);
a flip or a steep bank in the air, inverted for a moment or inverted while moving, still flies.
ArduCopter's own crash check waits alike for 1 s beyond its angle limits before it disarms.

The heights are not asked: a crashed vehicle's GNSS height wanders by metres, and it may lie above
the take-off point.
"""

from __future__ import annotations

import numpy as np

from gisnoise.geo import LocalFrame

__all__ = ["REST_SPEED_M_S", "LYING_MIN_S", "smoothed_speed", "inverted", "lying_inverted"]

REST_SPEED_M_S = 0.3
"""Speed below which a vehicle is at rest, m/s (smoothed over 1 s, :func:`smoothed_speed`)."""
LYING_MIN_S = 1.0
"""How long a vehicle must stay inverted and at rest to lie on something rather than fly, s."""
_WINDOW_S = 1.0


def smoothed_speed(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Ground speed (m/s) per sample: the velocity averaged over the samples within 0.5 s either side.

    ``t`` in s, ``lat``, ``lon`` in deg, ``h`` in m (arrays of one length, at least two samples).
    Averaging the velocity over 1 s keeps GNSS position noise of a vehicle standing still
    below :data:`REST_SPEED_M_S`; a motion of constant acceleration keeps its speed at the window's centre.

    Examples
    --------
    >>> t = np.arange(0.0, 5.0, 0.2)
    >>> v = smoothed_speed(t, 50.0 + 1e-5 * t, 8.0 + 0 * t, 100.0 + 0 * t)   # 1e-5 deg/s north
    >>> bool(np.allclose(v, 1.113, atol=0.002))
    True
    """
    t = np.asarray(t, dtype=float)
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0]))
    enu = np.stack(frame.to_enu(lat, lon, h), axis=-1)
    vel = np.gradient(enu, t, axis=0)
    c = np.vstack([np.zeros((1, 3)), np.cumsum(vel, axis=0)])
    lo = np.searchsorted(t, t - _WINDOW_S / 2, side="left")
    hi = np.searchsorted(t, t + _WINDOW_S / 2, side="right")
    return np.asarray(np.linalg.norm((c[hi] - c[lo]) / (hi - lo)[:, None], axis=1))


def inverted(roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """True where the body's vertical axis points upwards: ``cos(roll) cos(pitch) < 0`` (deg in, float or array_like).

    Examples
    --------
    >>> inverted(np.array([0.0, 60.0, 120.0, -179.0, 10.0]), np.array([0.0, 0.0, 0.0, -2.0, 95.0])).tolist()
    [False, False, True, True, True]
    """
    r, p = np.radians(np.asarray(roll, dtype=float)), np.radians(np.asarray(pitch, dtype=float))
    return np.asarray(np.cos(r) * np.cos(p) < 0.0)


def lying_inverted(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray, roll: np.ndarray,
                   pitch: np.ndarray) -> np.ndarray:
    """True on samples of a stretch at least :data:`LYING_MIN_S` long that is inverted and at rest throughout.

    ``t`` in s, ``lat``, ``lon``, ``roll``, ``pitch`` in deg, ``h`` in m.  See the module docstring.

    Examples
    --------
    >>> t = np.arange(0.0, 10.0, 0.2)
    >>> still = 0.0 * t
    >>> roll = np.where(t >= 4.0, 179.0, 0.0)          # turned over at 4 s, lying still
    >>> lie = lying_inverted(t, 50.0 + still, 8.0 + still, 100.0 + still, roll, still)
    >>> float(t[lie][0]), int(lie.sum())
    (4.0, 30)
    """
    t = np.asarray(t, dtype=float)
    inv = inverted(roll, pitch)
    out = np.zeros(len(t), dtype=bool)
    if len(t) < 2 or not inv.any():
        return out
    cand = inv & (smoothed_speed(t, lat, lon, h) < REST_SPEED_M_S)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], cand.astype(np.int8), [0]])))
    for i0, i1 in zip(edges[::2], edges[1::2], strict=True):
        if t[i1 - 1] - t[i0] >= LYING_MIN_S:
            out[i0:i1] = True
    return out
