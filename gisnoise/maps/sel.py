"""The sound exposure level on a map: its contour levels and the extent that closes them.

``SEL`` (LAE) integrates the whole event, so it lies above ``LAmax`` by ten times the
logarithm of the event's effective duration in seconds: for a straight pass at speed ``v``
and closest distance ``d`` (spherical spreading) ``SEL - LAmax = 10 log10(pi d / v / 1 s)``,
about 10 dB for a drone passing at 20 m/s some 60 m away, more farther out.  Single-event
maps therefore draw SEL at higher levels than the maximum level: gisnoise contours ``SEL``
at the map's levels plus :data:`SEL_OFFSET_DB` (10 dB; the map's ``45,50,55,60`` give SEL
contours at ``55,60,65,70`` dB(A)), so that the SEL and LAmax classes of one map cover
comparable areas near the track, and sizes the default extent so that the lowest of them
closes too (:func:`sel_margin`).

The bound of :func:`sel_margin` is the one of :func:`gisnoise.maps.grids.audible_distance`
taken through the event: each sample's level at a receiver is at most its card's loudest
level over the emission sphere, at the loudest power the track flies with that card, at the
receiver's horizontal distance from the sample (the slant distance is no shorter); the
samples' energies are summed with the map's trapezoid weights.

Examples
--------
>>> metric_levels("SEL", [45.0, 50.0])
[55.0, 60.0]
>>> metric_levels("LAmax", [45.0, 50.0])
[45.0, 50.0]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, transformer
from gisnoise.maps.prepare import trapezoid_weights

__all__ = ["SEL_OFFSET_DB", "metric_levels", "sel_margin", "sel_edge_bound"]

SEL_OFFSET_DB = 10.0
"""How far above the map's levels the ``SEL`` contours lie, dB."""


def metric_levels(metric: str, levels: Sequence[float]) -> list[float]:
    """The contour levels of ``metric`` for a map drawn at ``levels``: ``SEL`` (and ``SEL_p95``) lie
    :data:`SEL_OFFSET_DB` higher; every other metric uses ``levels``."""
    off = SEL_OFFSET_DB if metric == "SEL" or metric.startswith("SEL_p") else 0.0
    return [float(v) + off for v in levels]


def _envelope(table: np.ndarray) -> np.ndarray:
    """Per card, the non-increasing upper envelope of its loudest level (the max over all farther distances)."""
    return np.maximum.accumulate(np.asarray(table, dtype=float)[:, ::-1], axis=1)[:, ::-1]


def sel_edge_bound(traj: Trajectory, card_index: np.ndarray, distances: np.ndarray, table: np.ndarray,
                   rect: tuple[float, float, float, float], crs: Any, *, spacing_m: float,
                   background_db: float | None = None) -> float:
    """Upper bound of ``SEL`` (dB(A)) on the edge of the rectangle ``rect`` (xmin, ymin, xmax, ymax) in ``crs``.

    ``card_index`` gives each sample's row of ``table``, the loudest level of its card over the
    emission sphere at ``distances`` (:func:`gisnoise.maps.grids.level_table`).  Receivers are
    taken every ``spacing_m`` along the edge; the distances are shortened by half that spacing,
    so the bound holds between them too.
    """
    return _edge_bound(_EdgeSources.of(traj, card_index, distances, table, crs), rect, spacing_m, background_db)


@dataclass(frozen=True)
class _EdgeSources:
    """What the edge bound takes of a track, whatever the rectangle: the flying samples' map coordinates in the
    CRS, trapezoid weights and card rows, the envelope table, the track's duration."""

    x: np.ndarray
    y: np.ndarray
    w: np.ndarray
    ci: np.ndarray
    d_tab: np.ndarray
    env: np.ndarray
    duration_s: float

    @classmethod
    def of(cls, traj: Trajectory, card_index: np.ndarray, distances: np.ndarray, table: np.ndarray,
           crs: Any) -> _EdgeSources:
        t = np.asarray(traj.t, dtype=float)
        w = trapezoid_weights(t)
        flying = np.asarray(traj.flying, dtype=bool) & (np.asarray(traj.power_w, dtype=float) > 0)
        tr = transformer(WGS84, crs)
        flying &= np.asarray(card_index) >= 0
        x, y = tr.transform(np.asarray(traj.lon, dtype=float)[flying], np.asarray(traj.lat, dtype=float)[flying])
        return cls(np.asarray(x), np.asarray(y), w[flying], np.asarray(card_index)[flying],
                   np.asarray(distances, dtype=float), _envelope(table), float(t[-1] - t[0]))


def _edge_bound(src: _EdgeSources, rect: tuple[float, float, float, float], spacing_m: float,
                background_db: float | None) -> float:
    """:func:`sel_edge_bound` of sources already prepared."""
    x, y, w, ci, d_tab, env = src.x, src.y, src.w, src.ci, src.d_tab, src.env
    xmin, ymin, xmax, ymax = rect
    nx = max(2, math.ceil((xmax - xmin) / spacing_m) + 1)
    ny = max(2, math.ceil((ymax - ymin) / spacing_m) + 1)
    ex, ey = np.linspace(xmin, xmax, nx), np.linspace(ymin, ymax, ny)
    px = np.concatenate([ex, ex, np.full(ny, xmin), np.full(ny, xmax)])
    py = np.concatenate([np.full(nx, ymin), np.full(nx, ymax), ey, ey])
    energy = np.zeros(px.size)
    for start in range(0, x.size, 256):
        sx, sy, sw, sk = x[start:start + 256], y[start:start + 256], w[start:start + 256], ci[start:start + 256]
        # 0.998: map distances of a conformal projection within its zone differ from the ground's by less
        dist = 0.998 * np.hypot(px[:, None] - sx[None, :], py[:, None] - sy[None, :]) - 0.5 * spacing_m
        j = np.clip(np.searchsorted(d_tab, np.maximum(dist, d_tab[0]), side="right") - 1, 0, d_tab.size - 1)
        lv = env[sk[None, :], j]
        energy += np.sum(sw[None, :] * 10.0 ** (np.where(np.isfinite(lv), lv, -np.inf) / 10.0), axis=1)
    if background_db is not None:
        energy += 10.0 ** (background_db / 10.0) * src.duration_s
    top = float(energy.max()) if energy.size else 0.0
    return 10.0 * math.log10(top) if top > 0 else -math.inf


def sel_margin(traj: Trajectory, card_index: np.ndarray, distances: np.ndarray, table: np.ndarray,
               level_db: float, base_rect: tuple[float, float, float, float], crs: Any, *, start_m: float,
               resolution_m: float, max_margin_m: float, background_db: float | None = None) -> float:
    """The least margin (m, a multiple of the resolution, at least ``start_m``) about ``base_rect`` whose edge
    bound of ``SEL`` (:func:`sel_edge_bound`) is below ``level_db``; ``max_margin_m`` when none up to it is.

    The bound on the edge only falls as the rectangle grows (a receiver's projection onto a
    smaller rectangle is nearer to every sample inside it), so the margin is found by bisection.
    """
    res = float(resolution_m)
    src = _EdgeSources.of(traj, card_index, distances, table, crs)  # once: every step takes the same track

    def bound(m: float) -> float:
        xmin, ymin, xmax, ymax = base_rect
        spacing = max(res, m / 64.0)
        return _edge_bound(src, (xmin - m, ymin - m, xmax + m, ymax + m), spacing, background_db)

    lo = max(float(start_m), res)
    if bound(lo) < level_db:
        return lo
    hi = lo
    while True:
        hi = min(2.0 * hi, max_margin_m)
        if bound(hi) < level_db:
            break
        if hi >= max_margin_m:
            return float(max_margin_m)
        lo = hi
    while hi - lo > res:
        mid = math.ceil(0.5 * (lo + hi) / res) * res
        if mid >= hi:
            break
        if bound(mid) < level_db:
            hi = mid
        else:
            lo = mid
    return float(hi)
