"""Façade receivers of buildings and the levels of a flight at them.

Façade points
-------------
Every outer wall of a footprint (an edge of its exterior ring) is cut into equal segments
no longer than ``spacing_m`` (default 5 m); one receiver stands at the middle of each
segment, ``offset_m`` (0.1 m) in front of the wall on the outside, at ``height_m`` above
the ground (4 m, the usual assessment height of the Environmental Noise Directive).  The
level at a receiver is the incident free-field level: neither the wall's own reflection nor
screening by this or other buildings is modelled.

The most exposed façade
-----------------------
A building's façade level is the highest level of its receivers; the wall that holds it
is reported as the source-side façade (its index in the exterior ring and the receiver's
position), so a building beside a flight is judged at the wall facing the flight.

Levels at points use the card's ansatz (the one model definition) through
:meth:`gisnoise.model.ModelCard.level`, at every sample of the trajectory (trapezoid rule
for SEL and LAeq, as the map evaluator).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure.layers import Buildings
from gisnoise.flight import Trajectory, flying_segments
from gisnoise.geo import WGS84, LocalFrame, centre_lon, emission_angles, transformer
from gisnoise.maps import CardSet
from gisnoise.model import ModelCard

__all__ = ["FacadePoints", "facade_points", "point_levels", "facade_levels", "most_exposed", "ASSESSMENT_HEIGHT_M"]

ASSESSMENT_HEIGHT_M = 4.0
"""Default height of façade receivers above the ground, m."""

_BASE = {"d", "phi", "theta", "p_el"}


@dataclass(frozen=True, eq=False)
class FacadePoints:
    """Façade receivers: position in the buildings' CRS and WGS84, the building and wall they belong to."""

    x: np.ndarray
    y: np.ndarray
    lon: np.ndarray
    lat: np.ndarray
    building: np.ndarray
    wall: np.ndarray
    height_m: float
    spacing_m: float
    offset_m: float


def _metric_crs(b: Buildings) -> Any:
    """A CRS in metres for placing points: the buildings' own when projected, else their local UTM zone."""
    from gisnoise.geo import utm_crs

    if b.crs.is_projected:
        return b.crs
    c = b.polygons[0].centroid
    return utm_crs(c.x, c.y)


def facade_points(b: Buildings, *, spacing_m: float = 5.0, height_m: float = ASSESSMENT_HEIGHT_M,
                  offset_m: float = 0.1) -> FacadePoints:
    """Receivers along every outer wall (see the module docstring)."""
    for name, v in (("facade_spacing", spacing_m), ("facade_height", height_m)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise InputError(f"{name} must be a number > 0, got {v!r}", field=name)
    if not (math.isfinite(offset_m) and offset_m >= 0):
        raise InputError(f"facade_offset must be >= 0, got {offset_m!r}", field="facade_offset")
    crs = _metric_crs(b)
    to_m = transformer(b.crs, crs)
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    bid: list[np.ndarray] = []
    wid: list[np.ndarray] = []
    for poly, owner in zip(b.polygons, b.part_of, strict=True):
        ring = np.asarray(poly.exterior.coords)[:, :2]
        rx, ry = to_m.transform(ring[:, 0], ring[:, 1])
        rx, ry = np.asarray(rx), np.asarray(ry)
        ccw = 0.5 * np.sum(rx[:-1] * ry[1:] - rx[1:] * ry[:-1]) > 0  # shoelace: outside is to the right
        for w in range(len(rx) - 1):
            dx, dy = rx[w + 1] - rx[w], ry[w + 1] - ry[w]
            length = math.hypot(dx, dy)
            if length <= 0:
                continue
            n = max(1, math.ceil(length / spacing_m - 1e-9))
            f = (np.arange(n) + 0.5) / n
            nx, ny = (dy / length, -dx / length) if ccw else (-dy / length, dx / length)
            xs.append(rx[w] + f * dx + offset_m * nx)
            ys.append(ry[w] + f * dy + offset_m * ny)
            bid.append(np.full(n, owner))
            wid.append(np.full(n, w))
    x, y = np.concatenate(xs), np.concatenate(ys)
    lon, lat = transformer(crs, WGS84).transform(x, y)
    bx, by = transformer(crs, b.crs).transform(x, y)
    return FacadePoints(np.asarray(bx), np.asarray(by), np.asarray(lon), np.asarray(lat), np.concatenate(bid),
                        np.concatenate(wid), float(height_m), float(spacing_m), float(offset_m))


def _trapezoid_weights(t: np.ndarray) -> np.ndarray:
    w = np.zeros_like(t)
    if t.size > 1:
        dt = np.diff(t)
        w[:-1] += 0.5 * dt
        w[1:] += 0.5 * dt
    return w


def point_levels(traj: Trajectory, cards: CardSet | Iterable[ModelCard] | ModelCard, lon: Any, lat: Any,
                 h: Any, *, period_s: float | None = None, min_distance_m: float = 1.0,
                 chunk: int = 2048) -> dict[str, np.ndarray]:
    """``LAmax``, ``LAeq``, ``SEL`` (dB(A), UAV alone) of a flight at points ``lon, lat`` (deg), ``h`` (m ellipsoidal).

    Every trajectory sample is an evaluation instant; as on a map, only the flying stretches
    sound (:func:`gisnoise.flight.flying_segments`: samples on the ground make no noise).  Cards
    with ansatzes that need inputs beyond distance, angles and power are refused (the map
    evaluator serves those).
    """
    cs = cards if isinstance(cards, CardSet) else CardSet(cards)
    idx = cs.assign(traj.phase, traj.t, source=traj.source)
    for k in np.unique(idx):
        c = cs.cards[int(k)]
        extra = set(c.model.inputs) - _BASE - {"meta", "mic_agl"}
        if extra:
            raise InputError(f"card {c.id!r}: ansatz {c.ansatz!r} needs {', '.join(sorted(extra))}; "
                             "façade levels take the base ansatzes only", field="card")
    lon, lat = np.atleast_1d(np.asarray(lon, dtype=float)), np.atleast_1d(np.asarray(lat, dtype=float))
    h = np.broadcast_to(np.asarray(h, dtype=float), lon.shape)
    frame = LocalFrame(float(np.mean(lat)), centre_lon(lon), float(np.mean(h)))
    re, rn, ru = frame.to_enu(lat, lon, h)
    se, sn, su = frame.to_enu(traj.lat, traj.lon, traj.h)
    yaw, pitch, roll = (np.radians(a) for a in (traj.yaw, traj.pitch, traj.roll))
    t = np.asarray(traj.t, dtype=float)
    sounds = np.zeros(t.size, dtype=bool)
    w = np.zeros(t.size)
    for i0, i1 in flying_segments(traj):
        sounds[i0:i1] = True
        w[i0:i1] = _trapezoid_weights(t[i0:i1])
    period = traj.duration_s if period_s is None else float(period_s)
    if not period > 0:
        raise InputError(f"period must be > 0 s, got {period!r}", field="period")
    lmax = np.empty(lon.size)
    energy = np.empty(lon.size)
    ks = np.unique(idx)
    for s in range(0, lon.size, chunk):
        sl = slice(s, s + chunk)
        d, phi, theta = emission_angles(re[sl, None] - se[None, :], rn[sl, None] - sn[None, :],
                                        ru[sl, None] - su[None, :], yaw, pitch, roll)
        d = np.maximum(d, min_distance_m)
        L = np.empty(d.shape)
        for k in ks:
            c = cs.cards[int(k)]
            m = idx == k
            x = c.inputs(d[:, m], phi[:, m], theta[:, m], traj.power_w[None, m])
            x["meta"] = {}
            L[:, m] = c.level(x, background=False)
        L[:, ~sounds] = -np.inf
        lmax[sl] = L.max(axis=1)
        energy[sl] = (10.0 ** (L / 10.0)) @ w
    with np.errstate(divide="ignore"):
        sel = 10 * np.log10(energy)
    return {"LAmax": lmax, "LAeq": sel - 10 * np.log10(period), "SEL": sel}


def facade_levels(b: Buildings, traj: Trajectory, cards: Any, *, ground_h: float, metrics: Sequence[str] = ("LAmax",
                  "LAeq", "SEL"), spacing_m: float = 5.0, height_m: float = ASSESSMENT_HEIGHT_M,
                  offset_m: float = 0.1, period_s: float | None = None) -> dict[str, Any]:
    """Level of each building at its most exposed façade, per metric.

    Returns ``points`` (:class:`FacadePoints`), ``levels`` (metric -> levels at the points) and
    ``buildings`` (metric -> per building: level, the point index, the wall index).
    """
    pts = facade_points(b, spacing_m=spacing_m, height_m=height_m, offset_m=offset_m)
    lv = point_levels(traj, cards, pts.lon, pts.lat, ground_h + height_m, period_s=period_s)
    return most_exposed(b, pts, lv, metrics)


def most_exposed(b: Buildings, pts: FacadePoints, lv: dict[str, np.ndarray], metrics: Sequence[str]
                 ) -> dict[str, Any]:
    """Per building and metric the highest value of its façade points ``lv[metric]`` (one per point of ``pts``),
    the point and its wall; the same return as :func:`facade_levels`."""
    per: dict[str, Any] = {}
    for m in metrics:
        if m not in lv:
            raise InputError(f"façade levels: no metric {m!r}; metrics: {', '.join(lv)}", field="metric")
        level = np.full(b.n, -np.inf)
        arg = np.full(b.n, -1)
        order = np.lexsort((-lv[m], pts.building))  # per building, highest first
        first = np.ones(order.size, dtype=bool)
        first[1:] = pts.building[order][1:] != pts.building[order][:-1]
        top = order[first]
        level[pts.building[top]] = lv[m][top]
        arg[pts.building[top]] = top
        per[m] = {"level": level, "point": arg, "wall": np.where(arg >= 0, pts.wall[np.maximum(arg, 0)], -1)}
    return {"points": pts, "levels": lv, "buildings": per}
