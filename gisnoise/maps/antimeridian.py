"""Contours across the antimeridian: cut at +-180 deg of longitude (RFC 7946, section 3.1.9).

A map's grid is a projected raster (a UTM zone by default) and may straddle the antimeridian; its contours,
drawn on the grid and transformed to WGS84, then jump between longitudes near +180 and near -180.  Written as
they are, every ring and line crossing there spans more than 180 deg of longitude, and a GeoJSON reader draws
it the other way round the globe (an isoband then holds none of the track under it and is 10^4 times its
area).  RFC 7946 asks that a geometry crossing the antimeridian be cut in two there.

The contours are made in two steps:

1. :class:`ContinuousLongitudes` wraps the grid's transformer to WGS84: where the positions it gives span more
   than 180 deg of longitude, it moves those more than 180 deg from the grid's centre by 360 deg, so a map's
   longitudes run on continuously (179.99 is followed by 180.01, not -179.99).  In those longitudes the contours
   are as valid as in the grid's CRS (the mapping is continuous), and they are snapped, checked, repaired and
   oriented as any other.
2. :func:`split_at_antimeridian` cuts what then lies beyond +-180 deg there and moves it back by 360 deg:
   polygons are intersected with the strips west of -180, between -180 and 180 and east of 180 (GEOS), lines are
   cut where they cross +-180 (the cut's latitude linearly interpolated in longitude and latitude, as a GeoJSON
   reader draws the segment).  Each piece is valid and lies within [-180, 180]; the pieces of a polygon share
   their edge on the antimeridian and together are the polygon.

A map whose contours never span more than 180 deg of longitude goes through neither step: its positions are the
transformer's, bit for bit, and the test costs one ``numpy.ptp`` over the positions already transformed.

Grids containing a pole are refused before a map is made (:func:`gisnoise.geo.grid_for_points`): round a pole,
rings in longitude and latitude are not the area they enclose.

Examples
--------
>>> lines = [np.array([[179.9, 10.0], [180.1, 10.2]])]
>>> _, (cut,) = split_at_antimeridian([], [lines], 1e-8)
>>> [a.tolist() for a in cut]
[[[179.9, 10.0], [180.0, 10.1]], [[-180.0, 10.1], [-179.9, 10.2]]]
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient

from gisnoise.geo import shapes as shapely

__all__ = ["ContinuousLongitudes", "split_at_antimeridian"]

_STRIPS = ((-540.0, -180.0, 360.0), (-180.0, 180.0, 0.0), (180.0, 540.0, -360.0))
"""Longitude strips ``(west, east, shift)``: what lies in a strip is moved by ``shift`` deg into [-180, 180]."""


class ContinuousLongitudes:
    """A transformer to WGS84 whose longitudes run on across the antimeridian (step 1 of the module docstring).

    Parameters
    ----------
    tr : pyproj.Transformer
        From the grid's CRS to WGS84 (``always_xy``: longitude first).
    grid : GridSpec
        The grid; its centre's longitude is the reference the positions are kept within 180 deg of.

    Attributes
    ----------
    crossed : bool
        Whether any positions were moved (then :func:`split_at_antimeridian` has work to do).
    """

    def __init__(self, tr: Any, grid: Any) -> None:
        self._tr = tr
        self._grid = grid
        self._lon0: float | None = None
        self.crossed = False

    def transform(self, x: Any, y: Any) -> tuple[Any, Any]:
        """``(lon, lat)`` of ``x, y`` (m), deg; longitudes within 180 deg of the grid centre's where they span
        more than 180 deg, else the transformer's as they are."""
        lon, lat = self._tr.transform(x, y)
        lon = np.asarray(lon, dtype=float)
        if lon.size < 2 or not float(np.ptp(lon)) > 180.0:  # the fast path: one pass over the positions
            return lon, lat
        if self._lon0 is None:
            self._lon0 = self._grid.centre_wgs84()[0]
        d = lon - self._lon0
        far = np.abs(d) > 180.0
        if far.any():
            lon = lon.copy()
            lon[far] -= np.copysign(360.0, d[far])
            self.crossed = True
        return lon, lat


def split_at_antimeridian(bands: list[Any], lines: list[Any], precision: float) -> tuple[list[Any], list[Any]]:
    """Isobands and isolines cut at +-180 deg and moved into [-180, 180] (step 2 of the module docstring).

    Parameters
    ----------
    bands : list
        Per isoband None or its polygons, each the list of its rings' position arrays ``(n, 2)`` (lon, lat deg;
        exterior first, as :mod:`gisnoise.maps.contours` finishes them).
    lines : list
        Per isoline None or its lines' position arrays.
    precision : float
        The grid positions are snapped to, deg (new positions on the antimeridian are snapped to it too).

    Returns
    -------
    bands, lines
        The same, every position within [-180, 180]; a polygon or line that lies within it is kept as it is
        (the same array), polygons cut are oriented as the others (exterior counter-clockwise, holes clockwise).
    """
    return ([None if b is None else _split_polygons(b, precision) for b in bands],
            [None if ln is None else _split_lines(ln, precision) for ln in lines])


def _inside(a: np.ndarray) -> bool:
    return bool(a.size == 0 or (a[:, 0].min() >= -180.0 and a[:, 0].max() <= 180.0))


def _split_polygons(polys: list[list[np.ndarray]], precision: float) -> list[list[np.ndarray]]:
    out: list[list[np.ndarray]] = []
    for rings in polys:
        if all(_inside(r) for r in rings):
            out.append(rings)
            continue
        poly = Polygon(rings[0], rings[1:])
        for west, east, shift in _STRIPS:
            piece = poly.intersection(shapely.box(west, -90.0, east, 90.0))
            if piece.is_empty or piece.area == 0:
                continue
            piece = shapely.set_precision(shapely.transform(piece, _shifted(shift)), precision)
            for part in getattr(piece, "geoms", [piece]):
                if isinstance(part, Polygon) and not part.is_empty and part.area > 0:
                    o = orient(part, sign=1.0)
                    out.append([_rounded(np.asarray(r.coords, dtype=float)[:, :2]) for r in (o.exterior, *o.interiors)])
    return out


def _shifted(shift: float) -> Callable[[np.ndarray], np.ndarray]:
    """The coordinate function that moves positions ``(n, 2)`` by ``shift`` deg of longitude."""
    def move(c: np.ndarray) -> np.ndarray:
        return c + np.array([shift, 0.0])
    return move


def _split_lines(lines: list[np.ndarray], precision: float) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for a in lines:
        if _inside(a):
            out.append(a)
            continue
        strip = np.floor((a[:, 0] + 180.0) / 360.0)  # 0 within [-180, 180), 1 east of 180, -1 west of -180
        strip[a[:, 0] == 180.0] = 0.0  # on the antimeridian itself: the middle strip's eastern edge
        start, head = 0, np.zeros((0, 2))
        for i in np.flatnonzero(strip[1:] != strip[:-1]).tolist():
            p, q = a[i], a[i + 1]
            edge = 180.0 + 360.0 * min(strip[i], strip[i + 1])  # the meridian between the two strips
            cut = np.array([[edge, p[1] + (q[1] - p[1]) * (edge - p[0]) / (q[0] - p[0])]])
            out.extend(_piece(np.vstack([head, a[start:i + 1], cut]), strip[i], precision))
            start, head = i + 1, cut
        out.extend(_piece(np.vstack([head, a[start:]]), strip[-1], precision))
    return out


def _piece(a: np.ndarray, strip: float, precision: float) -> list[np.ndarray]:
    """One line's piece lying in ``strip``, moved into [-180, 180], snapped, repeats dropped; none if shorter
    than two positions."""
    q = a.copy()
    q[:, 0] -= 360.0 * strip
    q = np.rint(q / precision) * precision
    keep = np.ones(len(q), bool)
    keep[1:] = np.any(q[1:] != q[:-1], axis=1)
    q = _rounded(q[keep])
    return [q] if len(q) >= 2 else []


def _rounded(a: np.ndarray) -> np.ndarray:
    """Positions rounded to 9 decimals, as :mod:`gisnoise.maps.contours` writes them."""
    return np.rint(a * 1e9) / 1e9
