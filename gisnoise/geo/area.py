"""Ground areas of raster cells in any CRS.

A cell of a projected raster covers ``|a e|`` square CRS units on the map; on the ground (the
CRS's ellipsoid) it covers that times the ground area of one square unit there,
``|det J| M N cos(lat)`` with ``J`` the Jacobian of the inverse projection (longitude and latitude
in radians per CRS unit, central differences) and ``M``, ``N`` the ellipsoid's radii of curvature.
That is exact for any projection: 1 for an equal-area CRS, about ``1 / k0^2`` in a UTM zone, and in
Web Mercator (EPSG:3857) ``cos^2(lat)`` times the ellipsoid's own factor (PROJ's ``proj_factors``
gives 3857's scale on the sphere it projects from, 0.17 % off the WGS84 ground at 52 deg N).
:func:`areal_scale` is the map's area over the ground's.  A cell of a geographic raster
(longitude, latitude) covers the ellipsoid's zone between its two parallels over its longitude
span, in closed form.

:func:`cell_areas` gives the ground area of cells of a north-up raster; for many cells the
scale is evaluated on a lattice of at most :data:`LATTICE` x :data:`LATTICE` cell centres and
interpolated bilinearly between them (it is smooth: over a 10 km UTM map its bilinear error is
below 1e-10 relative).

Examples
--------
>>> from affine import Affine
>>> from pyproj import CRS
>>> a = cell_areas(CRS.from_epsg(3035), Affine(100.0, 0, 4.3e6, 0, -100.0, 3.3e6), [0], [0])  # LAEA: equal area
>>> round(float(a[0]), 3)
10000.0
>>> wm = cell_areas(CRS.from_epsg(3857), Affine(10.0, 0, 0.0, 0, -10.0, 6621293.7), [0], [0])  # 10 m at 51 deg N
>>> round(float(wm[0]), 1)  # 100 m^2 of Web Mercator: cos^2(51 deg) of it, times the ellipsoid's 1.0016
39.7
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from affine import Affine
from pyproj import CRS

from gisnoise.geo.grid import _IdentityCache, _local

__all__ = ["LATTICE", "areal_scale", "cell_areas"]

LATTICE = 65
"""Lattice points per axis on which :func:`cell_areas` evaluates the ground area of many cells."""

_STEP = 50.0
"""Half the step of the central differences, CRS units: truncation (step / R)^2 ~ 1e-10, round-off ~ 1e-10."""


def _to_geodetic(crs: CRS) -> tuple[Any, float, float]:
    """The CRS's inverse projection to its own geographic CRS (always x, y: longitude, latitude in deg), and that
    CRS's ellipsoid (semi-major axis m, eccentricity squared), cached per thread and CRS object."""
    from pyproj import Transformer

    cache = getattr(_local, "geodetic", None)
    if cache is None:
        cache = _local.geodetic = _IdentityCache()  # one per thread: pyproj objects are not shared

    def make() -> tuple[Any, float, float]:
        geo = crs.geodetic_crs
        if geo is None:
            raise ValueError("no geodetic CRS")
        ell = geo.ellipsoid
        a, b = (6378137.0, 6356752.314245) if ell is None else (float(ell.semi_major_metre),
                                                                 float(ell.semi_minor_metre))
        return Transformer.from_crs(crs, geo, always_xy=True), a, 1.0 - (b / a) ** 2

    return cache.get((crs,), make)


def _ground_per_unit2(crs: CRS, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Ground area (m^2) of one square CRS unit at points ``x, y`` of a projected CRS; NaN where it has none."""
    from pyproj.exceptions import ProjError

    try:
        tr, a, e2 = _to_geodetic(crs)
        h = _STEP
        px = np.concatenate([x + h, x - h, x, x])
        py = np.concatenate([y, y, y + h, y - h])
        lon, lat = (np.radians(np.asarray(v, dtype=float)) for v in tr.transform(px, py, errcheck=False))
    except (ProjError, TypeError, ValueError):
        return np.full(x.shape, np.nan)
    n = x.size
    dlon = (lon[:n] - lon[n:2 * n] + math.pi) % (2 * math.pi) - math.pi  # across the antimeridian
    dlon_y = (lon[2 * n:3 * n] - lon[3 * n:] + math.pi) % (2 * math.pi) - math.pi
    jxx, jyx = dlon / (2 * h), (lat[:n] - lat[n:2 * n]) / (2 * h)  # d lon / dx, d lat / dx
    jxy, jyy = dlon_y / (2 * h), (lat[2 * n:3 * n] - lat[3 * n:]) / (2 * h)  # d lon / dy, d lat / dy
    phi = 0.25 * (lat[:n] + lat[n:2 * n] + lat[2 * n:3 * n] + lat[3 * n:])
    w = 1.0 - e2 * np.sin(phi) ** 2
    m, nn = a * (1.0 - e2) / w ** 1.5, a / np.sqrt(w)  # meridian and prime-vertical radii, m
    g = np.abs(jxx * jyy - jxy * jyx) * m * nn * np.cos(phi)
    return np.where(np.isfinite(g) & (g > 0), g, np.nan)


def areal_scale(crs: CRS, x: Any, y: Any) -> np.ndarray:
    """Map area over ground area of a projected CRS at points ``x, y`` (CRS units; map area in square metres of
    its unit): 1 for an equal-area CRS.  NaN where the CRS has no ground (outside the projection's domain).
    Arrays broadcast.

    >>> from pyproj import CRS
    >>> round(float(areal_scale(CRS.from_epsg(3035), 4321000.0, 3210000.0)), 9)  # Lambert azimuthal equal-area
    1.0
    >>> round(float(areal_scale(CRS.from_epsg(32632), 500000.0, 5790000.0)), 6)  # a UTM zone's middle: k0^2
    0.9992
    """
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    unit = crs.axis_info[0].unit_conversion_factor if crs.axis_info else 1.0  # metres per unit
    g = _ground_per_unit2(crs, x.ravel(), y.ravel())
    return (unit * unit / g).reshape(x.shape)


def _geographic_areas(crs: CRS, t: Affine, rows: np.ndarray) -> np.ndarray:
    """Ellipsoidal area (m^2) of the cells of rows ``rows`` of a geographic raster (x longitude, y latitude)."""
    unit = crs.axis_info[0].unit_conversion_factor if crs.axis_info else math.pi / 180.0  # radians per unit
    ell = crs.ellipsoid
    a, b = (6378137.0, 6356752.314245) if ell is None else (float(ell.semi_major_metre), float(ell.semi_minor_metre))
    e = math.sqrt(max(1.0 - (b / a) ** 2, 0.0))

    def q(lat: np.ndarray) -> np.ndarray:  # twice the authalic zone function: area = b^2 dlon (q2 - q1) / 2
        s = np.sin(np.clip(lat, -0.5 * math.pi, 0.5 * math.pi))
        if e < 1e-12:
            return 2.0 * s
        return s / (1.0 - e * e * s * s) + np.log((1.0 + e * s) / (1.0 - e * s)) / (2.0 * e)

    top = (t.f + t.e * rows) * unit
    bottom = (t.f + t.e * (rows + 1.0)) * unit
    return 0.5 * b * b * abs(t.a * unit) * np.abs(q(top) - q(bottom))


def cell_areas(crs: CRS, transform: Affine, rows: Any, cols: Any) -> np.ndarray:
    """Ground area (m^2) of the cells ``rows, cols`` of a north-up raster in ``crs`` (see the module docstring).

    Parameters
    ----------
    crs : pyproj.CRS
        Projected (any linear unit) or geographic.
    transform : affine.Affine
        Pixel-corner transform of the raster (no rotation).
    rows, cols : array_like of int
        Cells, broadcast.

    Returns
    -------
    ndarray of float
        m^2 per cell; NaN where the CRS has no ground (outside the projection's domain).
    """
    rows, cols = np.broadcast_arrays(np.asarray(rows, dtype=float), np.asarray(cols, dtype=float))
    t = transform
    if rows.size == 0:
        return np.zeros(rows.shape)
    if crs.is_geographic:
        return _geographic_areas(crs, t, rows)
    units2 = abs(t.a * t.e)  # square CRS units per cell
    r0, r1, c0, c1 = rows.min(), rows.max(), cols.min(), cols.max()
    if rows.size <= LATTICE * LATTICE:
        xs, ys = t.c + t.a * (cols + 0.5), t.f + t.e * (rows + 0.5)
        return units2 * _ground_per_unit2(crs, xs.ravel(), ys.ravel()).reshape(rows.shape)
    lr = np.linspace(r0, r1, int(min(LATTICE, r1 - r0 + 1)))
    lc = np.linspace(c0, c1, int(min(LATTICE, c1 - c0 + 1)))
    cc, rr = np.meshgrid(lc, lr)
    s = _ground_per_unit2(crs, (t.c + t.a * (cc + 0.5)).ravel(), (t.f + t.e * (rr + 0.5)).ravel()).reshape(cc.shape)
    # bilinear between the lattice's points (a lattice of one row or column is constant along it)
    fr = (rows - r0) / (r1 - r0) * (lr.size - 1) if lr.size > 1 else np.zeros(rows.shape)
    fc = (cols - c0) / (c1 - c0) * (lc.size - 1) if lc.size > 1 else np.zeros(cols.shape)
    i = np.clip(np.floor(fr).astype(np.int64), 0, max(lr.size - 2, 0))
    j = np.clip(np.floor(fc).astype(np.int64), 0, max(lc.size - 2, 0))
    u, v = fr - i, fc - j
    i1, j1 = np.minimum(i + 1, lr.size - 1), np.minimum(j + 1, lc.size - 1)
    return units2 * (s[i, j] * (1 - u) * (1 - v) + s[i1, j] * u * (1 - v) + s[i, j1] * (1 - u) * v
                     + s[i1, j1] * u * v)
