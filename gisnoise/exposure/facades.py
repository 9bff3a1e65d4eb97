"""Façade receivers of buildings and the levels of a flight at them.

Façade points
-------------
Every wall that faces outdoor air is cut into equal segments no longer than ``spacing_m``
(default 5 m); one receiver stands at the middle of each segment, ``offset_m`` (0.1 m) in front of
the wall, at ``height_m`` above the ground (4 m, the assessment height of the Environmental Noise
Directive).  The walls are the edges of a footprint's exterior ring, receivers outside it, and of
each of its holes (courtyards), receivers in the courtyard.  Spacing and offset are ground metres:
the points are placed in the buildings' CRS when it is projected in metres true to scale within
:data:`SCALE_TOLERANCE` at the first building (a UTM zone, a national grid), else in that
building's UTM zone (a geographic CRS, Web Mercator, a CRS in feet).  The level at a receiver is
the incident free-field level: neither the wall's own reflection nor screening by this or other
buildings is modelled.

The most exposed façade
-----------------------
A building's façade level is the highest level of its receivers; the wall that holds it
is reported as the source-side façade (its index: the exterior ring's edges first, then each
courtyard's in turn; and the receiver's position), so a building beside a flight is judged at
the wall facing the flight.

The most exposed storey
-----------------------
A building with a height (its ``height``, else ``building:levels`` x the storey height:
:mod:`gisnoise.exposure.storeys`) also has receivers at the middle of each of its storeys, in
front of every façade point (:func:`storey_points`); its most exposed storey is the loudest of
them.  A source above the buildings is nearer the upper storeys, so they may be louder than the
façade at the assessment height, which stays the building's level for classing.

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
from gisnoise.exposure.storeys import STOREY_HEIGHT_M, roof_heights, storey_receiver_heights
from gisnoise.flight import Trajectory, flying_segments
from gisnoise.geo import WGS84, LocalFrame, centre_lon, emission_angles, transformer, utm_crs
from gisnoise.maps import CardSet
from gisnoise.model import ModelCard

__all__ = ["FacadePoints", "StoreyPoints", "facade_points", "storey_points", "point_levels", "facade_levels",
           "most_exposed", "most_exposed_storeys", "ASSESSMENT_HEIGHT_M", "SCALE_TOLERANCE"]

ASSESSMENT_HEIGHT_M = 4.0
"""Default height of façade receivers above the ground, m."""
SCALE_TOLERANCE = 0.002
"""A CRS whose metre is a ground metre within this fraction (0.2 %: 1 cm in 5 m) places façade points itself."""

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


@dataclass(frozen=True, eq=False)
class StoreyPoints:
    """Receivers at the storeys of the buildings with a height (:mod:`gisnoise.exposure.storeys`).

    Attributes
    ----------
    point : ndarray of int
        The façade point (of a :class:`FacadePoints`) each receiver stands in front of.
    building, wall : ndarray of int
        Its building and wall (those of the façade point).
    storey : ndarray of int
        Its storey, 1 the ground floor.
    z : ndarray of float
        Its height above the ground, m: the middle of the storey.
    roof_m : ndarray of float
        Per building its height, m (NaN: unknown, no storeys).
    storeys : ndarray of int
        Per building its number of storeys (0: unknown height).
    storey_height_m : float
        The storey height the storeys were made with, m.
    """

    point: np.ndarray
    building: np.ndarray
    wall: np.ndarray
    storey: np.ndarray
    z: np.ndarray
    roof_m: np.ndarray
    storeys: np.ndarray
    storey_height_m: float


def _true_to_scale(crs: Any, x: float, y: float) -> bool:
    """Whether 100 units of ``crs`` along x and along y at ``x, y`` are 100 m on the ground within
    :data:`SCALE_TOLERANCE`."""
    from pyproj import Geod

    lon, lat = transformer(crs, WGS84).transform(np.array([x, x + 100.0, x]), np.array([y, y, y + 100.0]))
    _, _, d = Geod(ellps="WGS84").inv(np.array([lon[0], lon[0]]), np.array([lat[0], lat[0]]), lon[1:], lat[1:])
    return bool(np.all(np.abs(np.asarray(d) / 100.0 - 1.0) <= SCALE_TOLERANCE))


def _metric_crs(b: Buildings) -> Any:
    """A CRS in ground metres for placing points (see the module docstring)."""
    c = b.polygons[0].centroid
    if b.crs.is_projected and _true_to_scale(b.crs, c.x, c.y):
        return b.crs
    lon, lat = transformer(b.crs, WGS84).transform(c.x, c.y)
    return utm_crs(float(lon), float(lat))


def _rings(poly: Any) -> list[tuple[np.ndarray, bool]]:
    """The rings of a footprint with whether each is a courtyard (a hole), x and y as a (k, 2) array."""
    return [(np.asarray(poly.exterior.coords)[:, :2], False)] + \
        [(np.asarray(r.coords)[:, :2], True) for r in poly.interiors]


def facade_points(b: Buildings, *, spacing_m: float = 5.0, height_m: float = ASSESSMENT_HEIGHT_M,
                  offset_m: float = 0.1) -> FacadePoints:
    """Receivers along every wall facing outdoor air, courtyards' too (see the module docstring)."""
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
        w0 = 0  # walls numbered on along the courtyards' rings
        for ring, courtyard in _rings(poly):
            rx, ry = to_m.transform(ring[:, 0], ring[:, 1])
            rx, ry = np.asarray(rx), np.asarray(ry)
            ccw = 0.5 * np.sum(rx[:-1] * ry[1:] - rx[1:] * ry[:-1]) > 0  # shoelace: a ccw ring's inside is left
            right = ccw != courtyard  # air lies outside an exterior ring and inside a courtyard's
            for w in range(len(rx) - 1):
                dx, dy = rx[w + 1] - rx[w], ry[w + 1] - ry[w]
                length = math.hypot(dx, dy)
                if length <= 0:
                    continue
                n = max(1, math.ceil(length / spacing_m - 1e-9))
                f = (np.arange(n) + 0.5) / n
                nx, ny = (dy / length, -dx / length) if right else (-dy / length, dx / length)
                xs.append(rx[w] + f * dx + offset_m * nx)
                ys.append(ry[w] + f * dy + offset_m * ny)
                bid.append(np.full(n, owner))
                wid.append(np.full(n, w0 + w))
            w0 += len(rx) - 1
    x, y = np.concatenate(xs), np.concatenate(ys)
    lon, lat = transformer(crs, WGS84).transform(x, y)
    bx, by = transformer(crs, b.crs).transform(x, y)
    return FacadePoints(np.asarray(bx), np.asarray(by), np.asarray(lon), np.asarray(lat), np.concatenate(bid),
                        np.concatenate(wid), float(height_m), float(spacing_m), float(offset_m))


def storey_points(b: Buildings, pts: FacadePoints, *, storey_height_m: float = STOREY_HEIGHT_M) -> StoreyPoints:
    """Receivers at the middle of each storey of every building with a height, in front of its façade points
    ``pts`` (see the module docstring)."""
    if not (isinstance(storey_height_m, (int, float)) and math.isfinite(storey_height_m) and storey_height_m > 0):
        raise InputError(f"storey_height must be a number > 0, got {storey_height_m!r}", field="storey_height")
    roof = roof_heights(b.height_m, b.levels, b.n, float(storey_height_m))
    zs = [storey_receiver_heights(float(h), float(storey_height_m)) for h in roof]
    count = np.array([z.size for z in zs], dtype=int)
    per_point = count[pts.building]
    point = np.repeat(np.arange(pts.building.size), per_point)
    z = np.concatenate([zs[k] for k in pts.building]) if point.size else np.zeros(0)
    storey = np.concatenate([np.arange(1, c + 1) for c in per_point]) if point.size else np.zeros(0, dtype=int)
    return StoreyPoints(point, pts.building[point], pts.wall[point], storey.astype(int), z, roof, count,
                        float(storey_height_m))


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
                  offset_m: float = 0.1, period_s: float | None = None,
                  storey_height_m: float | None = STOREY_HEIGHT_M) -> dict[str, Any]:
    """Level of each building at its most exposed façade, per metric, and at its most exposed storey.

    Returns ``points`` (:class:`FacadePoints`), ``levels`` (metric -> levels at the points),
    ``buildings`` (metric -> per building: level, the point index, the wall index) and ``storeys``:
    None when the layer has neither heights nor storeys (or ``storey_height_m`` is None: the façades
    alone), else :func:`most_exposed_storeys`'s return.
    """
    pts = facade_points(b, spacing_m=spacing_m, height_m=height_m, offset_m=offset_m)
    lv = point_levels(traj, cards, pts.lon, pts.lat, ground_h + height_m, period_s=period_s)
    out = most_exposed(b, pts, lv, metrics)
    out["storeys"] = None
    if storey_height_m is not None and (b.height_m is not None or b.levels is not None):
        sp = storey_points(b, pts, storey_height_m=storey_height_m)
        ls = point_levels(traj, cards, pts.lon[sp.point], pts.lat[sp.point], ground_h + sp.z, period_s=period_s) \
            if sp.z.size else {m: np.zeros(0) for m in lv}
        out["storeys"] = most_exposed_storeys(b, sp, ls, metrics)
    return out


def most_exposed(b: Buildings, pts: FacadePoints | StoreyPoints, lv: dict[str, np.ndarray], metrics: Sequence[str]
                 ) -> dict[str, Any]:
    """Per building and metric the highest value of its façade points ``lv[metric]`` (one per point of ``pts``),
    the point and its wall; the same return as :func:`facade_levels`.  A building without points has level
    -inf and point -1."""
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


def most_exposed_storeys(b: Buildings, sp: StoreyPoints, ls: dict[str, np.ndarray], metrics: Sequence[str]
                         ) -> dict[str, Any]:
    """Per building and metric its loudest storey receiver (levels ``ls[metric]``, one per receiver of ``sp``).

    Returns ``points`` (``sp``), ``levels`` (``ls``) and ``buildings``: metric -> per building ``level`` (NaN for
    a building without storeys), ``point`` (index of the receiver in ``sp``, -1 without), ``facade_point`` (the
    façade point it stands in front of), ``wall``, ``storey`` (1 the ground floor, 0 without) and ``z_m`` (its
    height above ground, NaN without).
    """
    out = most_exposed(b, sp, ls, metrics)
    for m in metrics:
        e = out["buildings"][m]
        has = e["point"] >= 0
        i = np.maximum(e["point"], 0)
        e["level"] = np.where(has, e["level"], np.nan)
        e["facade_point"] = np.where(has, sp.point[i] if sp.point.size else -1, -1)
        e["storey"] = np.where(has, sp.storey[i] if sp.storey.size else 0, 0)
        e["z_m"] = np.where(has, sp.z[i] if sp.z.size else np.nan, np.nan)
    return out
