"""Emission time: when the sound a microphone receives left the UAV on its track."""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.errors import CampaignError

__all__ = ["emission_time"]


def emission_time(t_r: Any, t_nodes: Any, enu_nodes: Any, mic_enu: Any, c_m_s: float, *,
                  tol_s: float = 1e-9, max_iter: int = 60) -> np.ndarray:
    """Solve ``t_r = t_e + |x(t_e) - x_mic| / c`` for the emission times ``t_e``.

    ``x(t)`` is the piecewise-linear track through ``enu_nodes`` at ``t_nodes`` (held
    constant outside them).  Safeguarded Newton iteration, vectorized over ``t_r``:
    each Newton step on the linear segment is kept when it reduces the residual, else
    the fixed-point step ``t_e = t_r - |x(t_e) - x_mic| / c`` (a contraction with factor
    ``|v| / c``) is taken; iterates until every residual is below ``tol_s``.

    Parameters
    ----------
    t_r : float or array_like
        Reception times, s.
    t_nodes : array_like, shape (m,)
        Track times, s, strictly increasing.
    enu_nodes : array_like, shape (m, 3)
        Track positions, m.
    mic_enu : array_like, shape (3,)
        Microphone position, m.
    c_m_s : float
        Speed of sound, m/s.

    Returns
    -------
    ndarray
        Emission times, s, shaped like ``t_r``.

    Examples
    --------
    >>> t_e = emission_time(10.0, [0.0, 100.0], [[0, 0, 340.0], [0, 0, 340.0]], [0, 0, 0], 340.0)
    >>> round(float(t_e), 12)
    9.0
    """
    t_r = np.asarray(t_r, dtype=float)
    tn = np.asarray(t_nodes, dtype=float)
    xn = np.asarray(enu_nodes, dtype=float).reshape(-1, 3)
    m = np.asarray(mic_enu, dtype=float).reshape(3)
    if not (np.isfinite(c_m_s) and c_m_s > 0):
        raise CampaignError(f"speed of sound must be positive, got {c_m_s!r}", field="speed_of_sound_m_s")
    if len(tn) != len(xn) or len(tn) < 2:
        raise CampaignError("emission_time: need at least 2 track nodes with positions", field="t_nodes")
    seg_v = np.diff(xn, axis=0) / np.diff(tn)[:, None]
    vmax = float(np.max(np.linalg.norm(seg_v, axis=1)))
    if vmax >= c_m_s:
        raise CampaignError(f"track speed {vmax:.1f} m/s is not below the speed of sound", field="t_nodes")

    def state(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack([np.interp(t, tn, xn[:, i]) for i in range(3)], axis=-1)
        k = np.searchsorted(tn, t, side="right") - 1
        inside = (k >= 0) & (k < len(tn) - 1)
        v = np.where(inside[..., None], seg_v[np.clip(k, 0, len(tn) - 2)], 0.0)
        return x, v

    flat = t_r.reshape(-1)
    x, _ = state(flat)
    t = flat - np.linalg.norm(x - m, axis=-1) / c_m_s
    for _ in range(max_iter):
        x, v = state(t)
        r = x - m
        dist = np.linalg.norm(r, axis=-1)
        f = t + dist / c_m_s - flat
        if np.all(np.abs(f) < tol_s):
            return t.reshape(t_r.shape)
        fp = 1.0 + np.einsum("ij,ij->i", r, v) / np.maximum(dist, 1e-12) / c_m_s
        t_newton = t - f / fp
        xn_, _ = state(t_newton)
        f_newton = t_newton + np.linalg.norm(xn_ - m, axis=-1) / c_m_s - flat
        t_fixed = flat - dist / c_m_s
        t = np.where(np.abs(f_newton) < np.abs(f), t_newton, t_fixed)
    raise CampaignError(f"emission time did not converge to {tol_s:g} s in {max_iter} iterations",
                        field="t_e")  # pragma: no cover - contraction guarantees convergence
