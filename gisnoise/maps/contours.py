"""GeoJSON contours of noise maps: isobands and isolines in WGS84 (RFC 7946).

The levels of a band are contoured on the receiver grid with contourpy (linear
interpolation between cell centres), transformed to WGS84 longitude/latitude and
written as a FeatureCollection following RFC 7946: positions in ``[lon, lat]``
order, polygon exterior rings counter-clockwise and holes clockwise (right-hand
rule), rings closed, geometries checked valid with shapely.

Features
--------
isoband
    ``MultiPolygon`` of the area where ``level <= L < level_max`` (the last band is
    open: ``level_max`` is null).
isoline
    ``MultiLineString`` where ``L == level``; ``level_max`` is null.

Each feature has the properties ``metric``, ``level``, ``level_max``, ``kind``,
``unit``, a display ``name`` and ``clipped``: true when the area at or above the
feature's ``level`` reaches the grid's outer cells, so the feature is cut by the grid's
edge rather than closed by the levels (:func:`clipped_levels`, :func:`clip_warnings`).

Examples
--------
>>> import numpy as np
>>> x = y = np.linspace(-2.0, 2.0, 81)
>>> z = 60.0 - 5.0 * np.hypot(*np.meshgrid(x, y))  # 55 dB on the unit circle
>>> [round(p.area, 2) for p in isobands(x, y, z, [55.0])]
[3.14]
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from shapely.geometry import LineString, MultiLineString, MultiPolygon, Polygon, mapping
from shapely.geometry.polygon import orient

from gisnoise.errors import InputError
from gisnoise.geo import WGS84, transformer
from gisnoise.geo import shapes as shapely
from gisnoise.maps._checks import as_float
from gisnoise.maps.sel import metric_levels

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.maps.result import MapResult

__all__ = ["isobands", "isolines", "contour_features", "contours_geojson", "write_geojson", "parse_levels",
           "clipped_levels", "clip_warnings"]

PRECISION_DEG = 1e-8
"""Coordinates are snapped to this grid (deg, about 1 mm)."""


def parse_levels(levels: Any, *, field: str = "levels") -> list[float]:
    """Sorted unique finite levels from a sequence or a comma-separated string (dB).

    >>> parse_levels("60, 45,50")
    [45.0, 50.0, 60.0]
    """
    if isinstance(levels, str):
        parts = [p.strip() for p in levels.split(",") if p.strip()]
    elif np.ndim(levels) == 0:
        parts = [levels]
    else:
        parts = list(levels)
    out = [as_float(p, field) for p in parts]
    if not out:
        raise InputError(f"{field}: give at least one level", field=field)
    return sorted(set(out))


def _edge_max(z: np.ndarray) -> float:
    a = np.asarray(z, dtype=float)
    if a.ndim != 2 or a.size == 0:
        return float("nan")
    edge = np.concatenate([a[0], a[-1], a[:, 0], a[:, -1]])
    edge = edge[np.isfinite(edge)]
    return float(edge.max()) if edge.size else float("nan")


def clipped_levels(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> dict[str, list[float]]:
    """Metric -> the levels whose contours the grid's edge cuts (some outer cell at or above them).

    Only metrics with at least one such level are listed; ``metrics`` defaults to the level bands.
    """
    lv = parse_levels(levels)
    names = result.level_bands() if metrics is None else list(metrics)
    out: dict[str, list[float]] = {}
    for name in names:
        top = _edge_max(result.band(name))
        cut = [lo for lo in metric_levels(name, lv) if top >= lo]
        if cut:
            out[name] = cut
    return out


def clip_warnings(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> list[str]:
    """One line per metric whose contours the grid's edge cuts, naming the metric, levels and edge maximum."""
    out = []
    units = result.units
    for name, cut in clipped_levels(result, levels, metrics=metrics).items():
        unit = units.get(name, "dB(A)")
        top = _edge_max(result.band(name))
        lv = ", ".join(f"{v:g}" for v in cut)
        out.append(f"{name} {lv} {unit} contours are clipped: the grid's edge reaches {top:.1f} {unit}; "
                   "they carry \"clipped\": true (a wider margin shows them whole)")
    return out


def _generator(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> Any:
    import contourpy

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    z = np.asarray(z, dtype=float)
    if x.size > 1 and x[1] < x[0]:
        x, z = x[::-1], z[:, ::-1]
    if y.size > 1 and y[1] < y[0]:  # north-up rasters: rows run southwards
        y, z = y[::-1], z[::-1, :]
    return contourpy.contour_generator(x, y, np.ma.masked_invalid(z),
                                       line_type="Separate", fill_type="OuterOffset")


def _polygons(points: Sequence[np.ndarray], offsets: Sequence[np.ndarray]) -> list[Polygon]:
    out: list[Polygon] = []
    for pts, off in zip(points, offsets, strict=True):
        rings = [pts[off[i]:off[i + 1]] for i in range(len(off) - 1)]
        rings = [r for r in rings if len(r) >= 4]
        if not rings:
            continue
        poly = Polygon(rings[0], rings[1:])
        if poly.is_empty or poly.area == 0:
            continue
        out.extend(_valid_polygons(poly))
    return out


def _valid_polygons(geom: Any) -> list[Polygon]:
    if not geom.is_valid:
        geom = shapely.make_valid(geom)
    if isinstance(geom, Polygon):
        return [] if geom.is_empty else [geom]
    parts = getattr(geom, "geoms", [])
    out: list[Polygon] = []
    for g in parts:
        out.extend(_valid_polygons(g))
    return out


def isobands(x: Any, y: Any, z: Any, levels: Sequence[float]) -> list[Polygon]:
    """Polygons where ``levels[0] <= z < levels[1]`` (or ``z >= levels[0]`` for one level).

    Parameters
    ----------
    x, y : array_like
        Coordinates of the columns (``x``, shape ``(nx,)``) and rows (``y``, ``(ny,)``).
    z : array_like, shape (ny, nx)
        Values at the nodes; NaN is left out.
    levels : sequence of one or two floats
        Lower (and upper) bound.

    Returns
    -------
    list of shapely Polygon
        In the coordinates of ``x, y``; valid, not yet oriented.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2 or not np.isfinite(z).any():
        return []
    lo = float(levels[0])
    hi = float(levels[1]) if len(levels) > 1 else float(np.nanmax(z)) + 1.0
    if hi <= lo:
        return []
    pts, offs = _generator(x, y, z).filled(lo, hi)
    return _polygons(pts, offs)


def isolines(x: Any, y: Any, z: Any, level: float) -> list[LineString]:
    """Lines where ``z == level`` (closed lines repeat their first point).  See :func:`isobands`."""
    z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2 or not np.isfinite(z).any():
        return []
    return [LineString(seg) for seg in _generator(x, y, z).lines(float(level)) if len(seg) >= 2]


def _to_wgs84(geom: Any, tr: Any) -> Any:
    def fn(xy: np.ndarray) -> np.ndarray:
        lon, lat = tr.transform(xy[:, 0], xy[:, 1])
        return np.column_stack([lon, lat])

    return shapely.transform(geom, fn)


def contour_features(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> list[dict]:
    """GeoJSON features (dicts) of isobands and isolines of ``result``'s level bands.

    Parameters
    ----------
    result : MapResult
    levels : sequence of float or str
        Contour levels, dB(A); ``SEL`` is contoured :data:`gisnoise.maps.sel.SEL_OFFSET_DB` higher
        (:func:`gisnoise.maps.sel.metric_levels`).
    metrics : sequence of str, optional
        Bands to contour; default every band in dB(A) (``LAmax``, ``LAeq``, ``SEL``,
        snapshot and ``*_p95``), not time above or standard deviations.
    """
    lv = parse_levels(levels)
    names = result.level_bands() if metrics is None else list(metrics)
    for n in names:
        result.band(n)
    grid = result.grid
    x, y = grid.xs, grid.ys
    tr = transformer(grid.crs, WGS84)
    units = result.units
    features: list[dict] = []
    for name in names:
        z = result.band(name)
        unit = units.get(name, "dB(A)")
        top = _edge_max(z)
        mlv = metric_levels(name, lv)
        bounds = [(mlv[i], mlv[i + 1] if i + 1 < len(mlv) else None) for i in range(len(mlv))]
        for lo, hi in bounds:
            polys = isobands(x, y, z, [lo] if hi is None else [lo, hi])
            geom = _finish_polygons([_to_wgs84(p, tr) for p in polys])
            if geom is None:
                continue
            label = f"{name} >= {lo:g} {unit}" if hi is None else f"{name} {lo:g}-{hi:g} {unit}"
            features.append(_feature(geom, {"metric": name, "level": lo, "level_max": hi, "kind": "isoband",
                                            "unit": unit, "name": label, "clipped": bool(top >= lo)}))
        for lo in mlv:
            lines = [_to_wgs84(g, tr) for g in isolines(x, y, z, lo)]
            lines = [shapely.set_precision(g, PRECISION_DEG) for g in lines]
            lines = [g for g in lines if isinstance(g, LineString) and not g.is_empty and len(g.coords) >= 2]
            if not lines:
                continue
            features.append(_feature(MultiLineString(lines), {
                "metric": name, "level": lo, "level_max": None, "kind": "isoline", "unit": unit,
                "name": f"{name} {lo:g} {unit}", "clipped": bool(top >= lo)}))
    return features


def _finish_polygons(polys: list[Polygon]) -> MultiPolygon | None:
    """Snap to :data:`PRECISION_DEG`, repair, orient (exterior CCW, holes CW)."""
    out: list[Polygon] = []
    for p in polys:
        q = shapely.set_precision(p, PRECISION_DEG)
        for part in _valid_polygons(q):
            if part.area > 0:
                out.append(orient(part, sign=1.0))
    if not out:
        return None
    return MultiPolygon(out)


def _feature(geom: Any, props: dict) -> dict:
    return {"type": "Feature", "geometry": _plain(mapping(geom)), "properties": props}


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, float):
        return round(obj, 9)
    return obj


def contours_geojson(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> dict:
    """A GeoJSON FeatureCollection (RFC 7946) of :func:`contour_features`."""
    feats = contour_features(result, levels, metrics=metrics)
    return {"type": "FeatureCollection", "features": feats,
            "gisnoise": {"levels": parse_levels(levels),
                         "warnings": clip_warnings(result, levels, metrics=metrics),
                         "metrics": sorted({f["properties"]["metric"] for f in feats}),
                         "grid": result.grid.to_dict()}}


def write_geojson(result: MapResult, path: str | os.PathLike[str], levels: Any, *,
                  metrics: Sequence[str] | None = None) -> Path:
    """Write :func:`contours_geojson` to ``path`` (temporary file, then rename)."""
    doc = contours_geojson(result, levels, metrics=metrics)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps(doc, allow_nan=False, separators=(",", ":")), encoding="utf-8")
    os.replace(tmp, p)
    return p
