"""Planar geometry on shapely 2 or shapely 1.8: the shapely 2 names the core uses.

QGIS 3.22 LTR and the Linux distributions that package it (Debian 12, Ubuntu 22.04) bring
shapely 1.8 in the Python QGIS runs; a compiled shapely 2 cannot be shipped in a plugin zip
that must load on every platform.  The core therefore calls shapely through this module
(``from gisnoise.geo import shapes as shapely``): with shapely 2 each name is shapely's own
function; with shapely 1.8 the same result is computed with 1.8's API (``shapely.ops``,
``shapely.vectorized``, methods of the geometries).  :data:`NAMES` lists what is offered;
a test checks that the core uses nothing else of it.

Arrays of coordinates keep their shape (``contains_xy``, ``points``, ``distance``), as in
shapely 2.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import shapely as _shapely
from shapely import wkb as _wkb
from shapely.geometry import GeometryCollection, LineString, MultiLineString, MultiPolygon, Point, Polygon, box
from shapely.validation import make_valid

__all__ = ["LineString", "MultiLineString", "MultiPolygon", "NAMES", "Point", "Polygon", "SHAPELY2", "VERSION",
           "box", "buffer", "contains_xy", "distance", "from_wkb", "intersects", "make_valid", "points", "prepare",
           "repaired", "ring_polygon_areas", "ring_polygons", "set_precision", "transform", "union_all",
           "winding_polygons"]

#: The installed shapely's version.
VERSION: str = str(_shapely.__version__)
#: True with shapely 2.x (its vectorised functions are used), False with 1.8 (tests set it to compare).
SHAPELY2: bool = int(VERSION.split(".")[0]) >= 2
#: The names the core may use through this module.
NAMES = frozenset(n for n in __all__ if n not in ("NAMES", "SHAPELY2", "VERSION"))


def union_all(geoms: Sequence[Any]) -> Any:
    """Union of the geometries (shapely 1.8: ``shapely.ops.unary_union``)."""
    if SHAPELY2:
        return _shapely.union_all(list(geoms))
    from shapely.ops import unary_union

    return unary_union(list(geoms))


def winding_polygons(geom: Any) -> list[Polygon]:
    """The area a polygon's rings wind around, as valid polygons, however the rings touch or overlap.

    A point lies in the result where the exterior winds around it (a winding number other than
    zero) and no hole does, as GEOS's "structure" repair reads rings.  The rings are noded
    (:func:`union_all` of their lines) and polygonized; a face is kept by that rule at a point
    inside it, and the kept faces are merged.  A part of a ring run along once each way (a
    sliver of no width, a spike) winds around nothing; ``make_valid`` (GEOS's "linework" method,
    the only one of shapely 1.8) takes such a run as an edge and may fill the area beside it.
    The same calls on shapely 2 and 1.8.

    >>> ring = [(0, 0), (4, 0), (4, 2), (2, 2), (2, 4), (2, 2), (0, 2), (0, 0)]  # a spike up x = 2
    >>> [p.area for p in winding_polygons(Polygon(ring))]
    [8.0]
    """
    if geom.is_empty:
        return []
    rings = [np.asarray(r.coords, dtype=float)[:, :2] for r in (geom.exterior, *geom.interiors)]
    noded = union_all([LineString(r) for r in rings if len(r) >= 2])
    if SHAPELY2:
        faces = list(_shapely.get_parts(_shapely.polygonize([noded])))
    else:
        from shapely.ops import polygonize

        faces = list(polygonize(noded))
    if not faces:
        return []
    inner = [f.representative_point() for f in faces]
    px = np.array([p.x for p in inner])
    py = np.array([p.y for p in inner])
    inside = _winding_number(rings[0], px, py) != 0
    for hole in rings[1:]:
        inside &= _winding_number(hole, px, py) == 0
    kept = [f for f, k in zip(faces, inside.tolist(), strict=True) if k]
    if not kept:
        return []
    merged = union_all(kept)
    parts = [merged] if merged.geom_type == "Polygon" else list(getattr(merged, "geoms", []))
    return [p for p in parts if p.geom_type == "Polygon" and not p.is_empty]


def repaired(geom: Any) -> Any:
    """A polygon whose rings touch, cross or run along themselves, made valid: the area its rings wind
    around (:func:`winding_polygons`).

    Where GEOS's ``make_valid`` gives that same area (rings that only touch or cross themselves) its
    result is returned as it is, a Polygon, MultiPolygon or GeometryCollection; where it does not (a
    ring run along once each way: ``make_valid``'s "linework" method takes the run as an edge and may
    fill the area beside it) the winding-number polygons, as a MultiPolygon.

    >>> ring = [(0, 0), (4, 0), (4, 4), (2, 4), (2, 2), (2, 4), (0, 4), (0, 0)]  # a spike down x = 2
    >>> repaired(Polygon(ring)).area
    16.0
    """
    fixed = make_valid(geom)
    area = winding_polygons(geom)
    parts = _polygon_parts(fixed)
    if (not parts and not area) or (parts and area and union_all(parts).equals(union_all(area))):
        return fixed
    return MultiPolygon(area)


def _polygon_parts(geom: Any) -> list[Polygon]:
    if geom.geom_type == "Polygon":
        return [] if geom.is_empty else [geom]
    return [p for g in getattr(geom, "geoms", []) for p in _polygon_parts(g)]


def _winding_number(ring: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """How often the closed ring winds counter-clockwise about each point ``(px, py)``: its edges crossing the
    ray rightwards from the point, upwards less downwards, for a point left (right) of the edge."""
    x0, y0, x1, y1 = ring[:-1, 0], ring[:-1, 1], ring[1:, 0], ring[1:, 1]
    out = np.zeros(len(px))
    step = max(1, 1_000_000 // max(len(x0), 1))  # points per pass: about a million point-edge pairs at a time
    for i in range(0, len(px), step):
        qx, qy = px[i:i + step, None], py[i:i + step, None]
        side = (x1 - x0) * (qy - y0) - (qx - x0) * (y1 - y0)  # > 0: the point left of the edge
        up = (y0 <= qy) & (y1 > qy) & (side > 0)
        down = (y0 > qy) & (y1 <= qy) & (side < 0)
        out[i:i + step] = np.count_nonzero(up, axis=1) - np.count_nonzero(down, axis=1)
    return out


def contains_xy(geom: Any, x: Any, y: Any) -> np.ndarray:
    """Whether each point ``(x, y)`` lies in the interior of ``geom``; the shape of ``x``."""
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if SHAPELY2:
        return np.asarray(_shapely.contains_xy(geom, xa, ya), dtype=bool)
    from shapely import vectorized

    flat = vectorized.contains(geom, xa.ravel(), ya.ravel())
    return np.asarray(flat, dtype=bool).reshape(xa.shape)


def points(x: Any, y: Any) -> np.ndarray:
    """An object array of Points, the shape of ``x``."""
    xa, ya = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    if SHAPELY2:
        return np.asarray(_shapely.points(xa, ya))
    out = np.empty(xa.shape, dtype=object)
    for idx in np.ndindex(xa.shape):
        out[idx] = Point(float(xa[idx]), float(ya[idx]))
    return out


def distance(geom: Any, others: Any) -> Any:
    """Distance from ``geom`` to each geometry of ``others`` (an array or one geometry)."""
    if SHAPELY2:
        return _shapely.distance(geom, others)
    arr = np.asarray(others, dtype=object)
    if arr.ndim == 0:
        return float(geom.distance(arr.item()))
    out = np.empty(arr.shape, dtype=float)
    for idx in np.ndindex(arr.shape):
        out[idx] = geom.distance(arr[idx])
    return out


def buffer(geom: Any, dist: float) -> Any:
    """``geom`` grown by ``dist``; arcs of 8 segments a quarter circle on both paths."""
    return _shapely.buffer(geom, dist, quad_segs=8) if SHAPELY2 else geom.buffer(dist, 8)


def intersects(a: Any, b: Any) -> bool:
    """Whether two geometries share a point."""
    return bool(_shapely.intersects(a, b)) if SHAPELY2 else bool(a.intersects(b))


def prepare(geom: Any) -> None:
    """Prepare ``geom`` in place for repeated predicates (shapely 1.8: nothing to do)."""
    if SHAPELY2:
        _shapely.prepare(geom)


def ring_polygon_areas(coords: np.ndarray, ring_offsets: np.ndarray, polygon_offsets: np.ndarray) -> np.ndarray:
    """The area of each polygon of :func:`ring_polygons`'s ragged arrays (shapely's ``area``)."""
    coords = np.ascontiguousarray(coords, dtype=float)
    if SHAPELY2:
        return np.asarray(_shapely.area(_shapely.from_ragged_array(
            _shapely.GeometryType.POLYGON, coords,
            (np.asarray(ring_offsets, np.int64), np.asarray(polygon_offsets, np.int64)))), dtype=float)
    return np.array([Polygon(coords[ring_offsets[p0]:ring_offsets[p0 + 1]],
                             [coords[ring_offsets[k]:ring_offsets[k + 1]] for k in range(p0 + 1, p1)]).area
                     for p0, p1 in zip(polygon_offsets[:-1], polygon_offsets[1:], strict=True)])


def ring_polygons(coords: np.ndarray, ring_offsets: np.ndarray, polygon_offsets: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Polygons given as closed rings in ragged arrays, checked and oriented in one pass.

    Polygon ``i`` has the rings ``polygon_offsets[i]:polygon_offsets[i + 1]`` (the first its
    exterior), ring ``k`` the positions ``coords[ring_offsets[k]:ring_offsets[k + 1]]`` (closed, at
    least four).  Returns ``(area, valid, oriented, positions)``: each polygon's area and whether
    it is valid (shapely's ``area`` and ``is_valid``), which polygons were oriented (the valid ones
    with an area), and the positions of those, in the layout of ``coords`` (their rings one after
    another, each of its length), with exteriors counter-clockwise and holes clockwise as
    ``shapely.geometry.polygon.orient(polygon, sign=1.0)`` gives them.

    With shapely 2.1 on GEOS 3.12 or later this is one vectorised call of each (``orient``
    itself calls GEOS's ring orientation there); otherwise polygon by polygon with the same functions.
    """
    coords = np.ascontiguousarray(coords, dtype=float)
    if SHAPELY2 and hasattr(_shapely, "orient_polygons") and _shapely.geos_version >= (3, 12, 0):
        geoms = _shapely.from_ragged_array(_shapely.GeometryType.POLYGON, coords,
                                           (np.asarray(ring_offsets, np.int64), np.asarray(polygon_offsets, np.int64)))
        area = np.asarray(_shapely.area(geoms), dtype=float)
        valid = np.asarray(_shapely.is_valid(geoms), dtype=bool)
        oriented = valid & (area > 0)
        pos = _shapely.get_coordinates(_shapely.orient_polygons(geoms[oriented], exterior_cw=False))
        return area, valid, oriented, pos.reshape(-1, 2)
    from shapely.geometry.polygon import orient

    n = len(polygon_offsets) - 1
    area, valid = np.zeros(n), np.zeros(n, bool)
    parts: list[np.ndarray] = []
    for i in range(n):
        rings = [coords[ring_offsets[k]:ring_offsets[k + 1]] for k in range(polygon_offsets[i], polygon_offsets[i + 1])]
        poly = Polygon(rings[0], rings[1:])
        area[i], valid[i] = poly.area, poly.is_valid
        if valid[i] and area[i] > 0:
            p = orient(poly, sign=1.0)
            parts.extend(np.asarray(r.coords, dtype=float)[:, :2] for r in (p.exterior, *p.interiors))
    pos = np.concatenate(parts) if parts else np.zeros((0, 2))
    return area, valid, valid & (area > 0), pos


def from_wkb(data: bytes) -> Any:
    """The geometry of well-known binary ``data``."""
    return _wkb.loads(bytes(data))


def transform(geom: Any, fn: Callable[[np.ndarray], np.ndarray]) -> Any:
    """``geom`` with its coordinates mapped by ``fn`` (an ``(N, 2)`` array to an ``(N, 2)`` array)."""
    if SHAPELY2:
        return _shapely.transform(geom, fn)
    from shapely.ops import transform as ops_transform

    def xy(x: Any, y: Any, z: Any = None) -> tuple[np.ndarray, np.ndarray]:
        out = np.asarray(fn(np.column_stack([np.asarray(x, dtype=float), np.asarray(y, dtype=float)])))
        return out[:, 0], out[:, 1]

    return ops_transform(xy, geom)


def set_precision(geom: Any, grid_size: float) -> Any:
    """``geom`` with coordinates snapped to multiples of ``grid_size``.

    shapely 1.8 has no ``set_precision``: the coordinates are rounded, repeated points
    dropped, lines that collapse to a point become empty and polygons are repaired with
    ``make_valid`` (shapely 2 does the same in one step).
    """
    if SHAPELY2:
        return _shapely.set_precision(geom, grid_size)
    return _snap(geom, float(grid_size))


def _snap_coords(coords: Any, g: float) -> np.ndarray:
    c = np.round(np.asarray(coords, dtype=float)[:, :2] / g) * g
    if len(c) > 1:
        keep = np.concatenate([[True], np.any(np.diff(c, axis=0) != 0.0, axis=1)])
        c = c[keep]
    return c


def _snap(geom: Any, g: float) -> Any:
    kind = geom.geom_type
    if geom.is_empty:
        return geom
    if kind == "Point":
        return Point(*_snap_coords(geom.coords, g)[0])
    if kind == "LineString":
        c = _snap_coords(geom.coords, g)
        return LineString(c) if len(c) >= 2 else LineString()
    if kind == "Polygon":
        rings = [_snap_coords(r.coords, g) for r in (geom.exterior, *geom.interiors)]
        if len(rings[0]) < 4:
            return Polygon()
        poly = Polygon(rings[0], [r for r in rings[1:] if len(r) >= 4])
        return poly if poly.is_valid else repaired(poly)
    if kind == "MultiLineString":
        return MultiLineString([p for p in (_snap(part, g) for part in geom.geoms) if not p.is_empty])
    if kind == "MultiPolygon":
        parts: list[Polygon] = []
        for part in geom.geoms:
            q = _snap(part, g)
            parts.extend([q] if q.geom_type == "Polygon" else [p for p in getattr(q, "geoms", [])
                                                               if p.geom_type == "Polygon"])
        return MultiPolygon([p for p in parts if not p.is_empty])
    if kind == "GeometryCollection":
        return GeometryCollection([p for p in (_snap(part, g) for part in geom.geoms) if not p.is_empty])
    raise TypeError(f"set_precision: no shapely 1.8 path for a {kind}")
