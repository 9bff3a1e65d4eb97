"""Flight phases: the names of the flight modes, and the phase of multicopter flight from its speed.

A trajectory row, a waypoint and a model card name one of :data:`PHASES`.
:func:`phase_by_speed` is the rule the flight-log readers apply to multicopter
flight: ``climb`` / ``sink`` when the vertical speed exceeds 1 m/s and the horizontal
speed, else ``hover`` below 3 m/s horizontal speed, else ``horizontal``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = [
    "PHASES",
    "MULTICOPTER_PHASES",
    "phase_by_speed",
    "smoothed_speed",
    "HOVER_MAX_SPEED_M_S",
    "VERTICAL_MIN_SPEED_M_S",
]

PHASES = ("horizontal", "climb", "sink", "hover", "transition")
"""The flight phases (modes), as trajectories, waypoints and model cards name them."""
MULTICOPTER_PHASES = ("climb", "sink", "hover")
"""The phases flown in multicopter mode (lift rotors only)."""
HOVER_MAX_SPEED_M_S = 3.0
"""Horizontal ground speed below which multicopter flight is ``hover``, m/s."""
VERTICAL_MIN_SPEED_M_S = 1.0
"""Vertical speed above which multicopter flight is ``climb`` or ``sink``, m/s."""
PHASE_SMOOTHING_S = 1.0
"""Width of the centred moving average applied to the velocity before the phase rule, s."""


def phase_by_speed(t: Any, vel_enu: Any, *, smoothing_s: float = PHASE_SMOOTHING_S,
                   hover_max_m_s: float = HOVER_MAX_SPEED_M_S,
                   vertical_min_m_s: float = VERTICAL_MIN_SPEED_M_S) -> np.ndarray:
    """Flight phase of multicopter flight from the ground velocity.

    The velocity is smoothed by a centred moving average of ``smoothing_s``; then
    ``climb`` where the upward speed exceeds ``vertical_min_m_s`` and the horizontal
    speed, ``sink`` likewise downward, ``hover`` where the horizontal speed is below
    ``hover_max_m_s``, else ``horizontal``.

    Parameters
    ----------
    t : array_like, shape (n,)
        Times, s, increasing.
    vel_enu : array_like, shape (n, 3)
        Ground velocity east, north, up, m/s.

    Examples
    --------
    >>> phase_by_speed([0.0, 1.0, 2.0], [[0, 0, 2.0], [0, 0, 2.0], [0, 0, 2.0]]).tolist()
    ['climb', 'climb', 'climb']
    >>> phase_by_speed([0.0, 1.0], [[10.0, 0, 0], [10.0, 0, 0]]).tolist()
    ['horizontal', 'horizontal']
    """
    t = np.asarray(t, dtype=float)
    v = np.asarray(vel_enu, dtype=float).reshape(-1, 3)
    if len(t) != len(v):
        raise InputError(f"phase_by_speed: t has {len(t)} samples, vel_enu {len(v)}", field="vel_enu")
    vs = _moving_average(t, v, smoothing_s)
    vh = np.hypot(vs[:, 0], vs[:, 1])
    vu = vs[:, 2]
    out = np.where(vh < hover_max_m_s, "hover", "horizontal").astype("<U10")
    out[(vu > vertical_min_m_s) & (vu > vh)] = "climb"
    out[(-vu > vertical_min_m_s) & (-vu > vh)] = "sink"
    return out


def smoothed_speed(t: Any, enu: Any, *, smoothing_s: float = PHASE_SMOOTHING_S) -> np.ndarray:
    """Speed over the ground, m/s, of positions ``enu`` (shape (n, 3), m) at times ``t``: the velocity
    (central differences) smoothed as :func:`phase_by_speed` smooths it, then its norm.

    >>> smoothed_speed([0.0, 1.0, 2.0, 3.0], [[0, 0, 0], [3, 4, 0], [6, 8, 0], [9, 12, 0]]).tolist()
    [5.0, 5.0, 5.0, 5.0]
    """
    t = np.asarray(t, dtype=float)
    p = np.asarray(enu, dtype=float).reshape(-1, 3)
    if len(t) < 2:
        return np.zeros(len(t))
    v = np.gradient(p, t, axis=0)
    return np.linalg.norm(_moving_average(t, v, smoothing_s), axis=1)


def _moving_average(t: np.ndarray, v: np.ndarray, width: float) -> np.ndarray:
    if len(t) < 2 or width <= 0:
        return v
    c = np.vstack([np.zeros((1, v.shape[1])), np.cumsum(v, axis=0)])
    lo = np.searchsorted(t, t - width / 2, side="left")
    hi = np.searchsorted(t, t + width / 2, side="right")
    return (c[hi] - c[lo]) / (hi - lo)[:, None]
