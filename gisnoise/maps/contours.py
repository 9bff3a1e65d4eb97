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
    open: ``level_max`` is null).  A node exactly at a level belongs to the band from
    that level up, so a plateau at 50 dB is drawn in the 50 dB band.  What has no area
    is not drawn apart: a node or a row of nodes exactly at ``level_max`` with the band
    on both sides (a peak, a ridge) lies inside the band's polygon.
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
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from shapely.geometry import LineString, Polygon
from shapely.geometry.polygon import orient

from gisnoise.geo import WGS84, transformer
from gisnoise.geo import shapes as shapely
from gisnoise.maps.antimeridian import ContinuousLongitudes, split_at_antimeridian
from gisnoise.maps.clipping import clip_warnings, clipped_levels, edge_max, geojson_warnings, parse_levels
from gisnoise.maps.sel import metric_levels

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.maps.result import MapResult

__all__ = ["isobands", "isolines", "contour_features", "contours_geojson", "write_geojson", "contours_text", "geojson_text", "parse_levels",
           "clipped_levels", "clip_warnings"]

PRECISION_DEG = 1e-8
"""Coordinates are snapped to this grid (deg, about 1 mm)."""


def _generator(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> Any:
    import contourpy

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    z = np.asarray(z, dtype=float)
    if x.size > 1 and x[1] < x[0]:
        x, z = x[::-1], z[:, ::-1]
    if y.size > 1 and y[1] < y[0]:  # north-up rasters: rows run southwards
        y, z = y[::-1], z[::-1, :]
    finite = np.isfinite(z)
    # contourpy.contour_generator(x, y, np.ma.masked_invalid(z), line_type="Separate", fill_type="OuterOffset")
    # builds this generator, after a pass of numpy.ma over z that costs more than a band's contours
    xx, yy = np.meshgrid(x, y)
    return contourpy.SerialContourGenerator(
        xx, yy, np.ascontiguousarray(z), cast(Any, None) if finite.all() else ~finite, corner_mask=True,
        line_type=contourpy.LineType.Separate, fill_type=contourpy.FillType.OuterOffset, quad_as_tri=False,
        z_interp=contourpy.ZInterp.Linear, x_chunk_size=0, y_chunk_size=0)


def _exact_nodes(z: np.ndarray, levels: Sequence[float]) -> list[np.ndarray]:
    """For each level, the flat indices of the nodes of ``z`` exactly at it."""
    return [np.flatnonzero(z == lv) for lv in levels]


def _filled_levels(levels: Sequence[float], nodes: Sequence[np.ndarray]) -> list[float]:
    """The levels to give contourpy's ``filled`` so that its bands hold the nodes of this module's bands.

    contourpy fills ``lower < z <= upper``, a band here is ``level <= z < level_max``: a node exactly at
    a level (a plateau) would fall in the band below.  Where some node equals a level (``nodes``, from
    :func:`_exact_nodes`), ``numpy.nextafter(level, -inf)`` is given instead: for float64 values
    ``z > nextafter(level, -inf)`` exactly when ``z >= level``; the band's edge moves by a rounding
    error.  A level no node equals is given as it is (same nodes, same text written).  Where a band
    has no width along a row at the level, its ring runs along both sides of the row on the same
    coordinates: :func:`gisnoise.geo.shapes.repaired` reads its area by winding number, and
    :func:`_merged` joins a band a ridge parts.

    >>> z = np.array([[45.0, 50.0], [50.0, 55.0]])
    >>> _filled_levels([50.0, 52.0], _exact_nodes(z, [50.0, 52.0])) == [np.nextafter(50.0, -np.inf), 52.0]
    True
    """
    return [float(np.nextafter(lv, -np.inf)) if len(k) else float(lv) for lv, k in zip(levels, nodes, strict=True)]


def _parted_at(z: np.ndarray, level: float, nodes: np.ndarray) -> bool:
    """Whether a band whose ``level_max`` is ``level`` may lie on both sides of a cell edge whose two nodes are
    exactly at ``level`` (a ridge): the cells on both sides hold a node below ``level`` and none above (NaN
    corners aside).  contourpy then draws the band as two polygons sharing that edge (:func:`_merged`).
    ``nodes``: the flat indices of the nodes exactly at ``level``."""
    ny, nx = z.shape
    flat = z.ravel()
    v, u = np.divmod(nodes, nx)

    def reach(cell: np.ndarray) -> np.ndarray:  # cells by the flat index of their first corner
        c = flat[np.stack([cell, cell + 1, cell + nx, cell + nx + 1])]
        return np.any(c < level, axis=0) & ~np.any(c > level, axis=0)

    k = nodes[(u < nx - 1) & (v >= 1) & (v < ny - 1)]
    k = k[flat[k + 1] == level]  # edges along a row: the cells below and above
    if k.size and np.any(reach(k - nx) & reach(k)):
        return True
    k = nodes[(v < ny - 1) & (u >= 1) & (u < nx - 1)]
    k = k[flat[k + nx] == level]  # edges along a column: the cells left and right
    return bool(k.size and np.any(reach(k - 1) & reach(k)))


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
        geom = shapely.repaired(geom)
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
    nodes = _exact_nodes(z, [lo, hi])
    polys = _polygons(*_generator(x, y, z).filled(*_filled_levels([lo, hi], nodes)))
    if len(polys) > 1 and _parted_at(z, hi, nodes[1]):  # a ridge at hi parts the band (:func:`_merged`)
        polys = _valid_polygons(shapely.union_all(polys))
    return polys


def isolines(x: Any, y: Any, z: Any, level: float) -> list[LineString]:
    """Lines where ``z == level`` (closed lines repeat their first point).  See :func:`isobands`."""
    z = np.asarray(z, dtype=float)
    if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2 or not np.isfinite(z).any():
        return []
    return [LineString(seg) for seg in _generator(x, y, z).lines(float(level)) if len(seg) >= 2]


def _bulk_wgs84(arrays: list[np.ndarray], tr: Any) -> np.ndarray:
    """The (n, 2) point arrays, concatenated, in WGS84 longitude/latitude, in one call of the transformer.

    Each distinct point is transformed once (an isoline's points are also the edges of the two
    isobands beside it); a point is transformed by itself, so this gives the same numbers as
    transforming every point.
    """
    if not arrays:
        return np.zeros((0, 2))
    allpts = np.ascontiguousarray(np.concatenate(arrays), dtype=float)
    if allpts.size and not (allpts == 0.0).any():  # as complex numbers -0.0 == 0.0: no zeros, no merging
        uniq, inverse = np.unique(allpts.view(np.complex128).ravel(), return_inverse=True)
        lon, lat = tr.transform(uniq.real.copy(), uniq.imag.copy())
        return np.column_stack([lon, lat])[inverse.ravel()]
    lon, lat = tr.transform(allpts[:, 0], allpts[:, 1])
    return np.column_stack([lon, lat])


def _band_geometries(x: np.ndarray, y: np.ndarray, z: np.ndarray, bounds: list[tuple[float, float | None]],
                     lv: list[float], tr: Any) -> tuple[list[list[list[np.ndarray]] | None], list[list[np.ndarray] | None]]:
    """Isobands (one per bound) and isolines (one per level) of one band, in WGS84, finished and rounded.

    An isoband is a list of polygons, each the list of its rings' position arrays (exterior
    first); an isoline the list of its lines' position arrays; positions rounded as they are
    written (:func:`_rounded`).  One contour generator serves every level; the points of all
    levels are transformed to WGS84 in one call and snapped to :data:`PRECISION_DEG` together
    (:func:`_snapped_buffer`).  Repair and orientation as :func:`isobands` and :func:`isolines`
    define them (exterior rings counter-clockwise, holes clockwise): a polygon whose snapped rings
    are closed is checked, and oriented when valid, by GEOS for all such polygons at once
    (:func:`gisnoise.geo.shapes.ring_polygons`); any other is repaired (by winding number,
    :func:`gisnoise.geo.shapes.repaired`) and reduced to the precision by GEOS on its own
    (:func:`_repaired`).  Levels exactly at nodes: :func:`_filled_levels`.
    """
    nb, nl = len(bounds), len(lv)
    if z.ndim != 2 or z.shape[0] < 2 or z.shape[1] < 2 or not np.isfinite(z).any():
        return [None] * nb, [None] * nl
    gen = _generator(x, y, z)
    top = float(np.nanmax(z)) + 1.0
    rings: list[np.ndarray] = []  # every ring of every polygon of every bound, projected
    polys: list[tuple[int, int, int]] = []  # (bound, first ring, ring count)
    exact = _exact_nodes(z, lv)
    at = dict(zip(lv, _filled_levels(lv, exact), strict=True))
    nodes_at = dict(zip(lv, exact, strict=True))
    for b, (lo, hi) in enumerate(bounds):
        up = top if hi is None else float(hi)
        if up <= lo:
            continue
        pts, offs = gen.filled(at.get(lo, float(lo)), up if hi is None else at.get(hi, up))
        for pt, off in zip(pts, offs, strict=True):
            rr = [pt[off[i]:off[i + 1]] for i in range(len(off) - 1)]
            rr = [r for r in rr if len(r) >= 4]
            if rr:
                polys.append((b, len(rings), len(rr)))
                rings.extend(rr)
    segs: list[np.ndarray] = []
    seg_level: list[int] = []
    for j, lo in enumerate(lv):
        for seg in gen.lines(float(lo)):
            if len(seg) >= 2:
                segs.append(seg)
                seg_level.append(j)
    nr = len(rings)
    pieces = rings + segs
    wgs = _bulk_wgs84(pieces, tr)
    ends = np.cumsum([len(p) for p in pieces], dtype=np.intp)
    q, starts = _snapped_buffer(wgs, ends)  # piece k: q[starts[k]:starts[k + 1]]
    out = _rounded(q[starts[nr]:], True)  # the lines' positions as written
    bands = _finished_polygons(polys, nb, rings, wgs, ends, q, starts)
    for b, (_, hi) in enumerate(bounds):  # a band a ridge exactly at its level_max parts (:func:`_merged`)
        if len(bands[b]) > 1 and hi is not None and _parted_at(z, hi, nodes_at[hi]):
            bands[b] = _merged(bands[b])
    lines: list[list[np.ndarray]] = [[] for _ in range(nl)]
    bl = starts[nr:].tolist()
    for i, j in enumerate(seg_level):
        if bl[i + 1] - bl[i] >= 2:
            lines[j].append(out[bl[i] - bl[0]:bl[i + 1] - bl[0]])
    return [p if p else None for p in bands], [ln if ln else None for ln in lines]


def _finished_polygons(polys: list[tuple[int, int, int]], nb: int, rings: list[np.ndarray], wgs: np.ndarray,
                       ends: np.ndarray, q: np.ndarray, starts: np.ndarray) -> list[list[list[np.ndarray]]]:
    """The isobands' polygons (``polys``: bound, first ring, ring count) as lists of rounded ring position arrays.

    ``wgs``: every piece's projected positions (piece ``k`` ends at ``ends[k]``); ``q``: the snapped ones (piece
    ``k`` is ``q[starts[k]:starts[k + 1]]``).  As :func:`isobands` and the old one-polygon-at-a-time code define
    it: a polygon without area before snapping is left out; one whose snapped rings stay closed and make a valid
    polygon is kept as snapped, oriented; any other is repaired (:func:`_repaired`).  The checks and the
    orientation are GEOS's, for all polygons at once (:func:`gisnoise.geo.shapes.ring_polygons`).
    """
    bands: list[list[list[np.ndarray]]] = [[] for _ in range(nb)]
    if not polys:
        return bands
    nr = len(rings)
    wstarts = np.zeros(nr + 1, np.intp)
    wstarts[1:] = ends[:nr]
    n_pos = np.diff(starts[:nr + 1])
    # snapped rings that stay closed (a ring that collapses is left to the repair)
    closed = ((n_pos >= 4) & ~np.any(q[starts[:nr]] != q[starts[1:nr + 1] - 1], axis=1)).tolist()
    ok = [all(closed[i0:i0 + n]) for _, i0, n in polys]
    fast = [p for p, k in zip(polys, ok, strict=True) if k]
    ring_ids = np.array([i for _, i0, n in fast for i in range(i0, i0 + n)], np.intp)
    poly_off = np.cumsum([0] + [n for _, _, n in fast], dtype=np.intp)
    if np.any(wgs[wstarts[:-1]] != wgs[wstarts[1:] - 1]):  # contourpy closes its rings: never met, but exact
        raw_area = np.array([Polygon(w[0], w[1:]).area for w in
                             ([wgs[wstarts[k]:wstarts[k + 1]] for k in range(i0, i0 + n)] for _, i0, n in fast)])
    else:
        raw_area = shapely.ring_polygon_areas(*_ragged(wgs, wstarts, ring_ids), poly_off)
    _, valid, oriented, pos = shapely.ring_polygons(*_ragged(q, starts, ring_ids), poly_off)
    pos = _rounded(pos, True)
    lens = n_pos.tolist()
    at = 0  # where the next oriented polygon's positions start
    k = 0  # the next polygon of ``fast``
    for (b, i0, n), fine in zip(polys, ok, strict=True):
        if not fine:
            bands[b].extend(_repaired(rings, wgs, ends, i0, n))
            continue
        if raw_area[k] == 0:
            pass
        elif oriented[k]:
            poly = []
            for m in range(i0, i0 + n):
                poly.append(pos[at:at + lens[m]])
                at += lens[m]
            bands[b].append(poly)
        elif not valid[k]:
            bands[b].extend(_repaired(rings, wgs, ends, i0, n))
        k += 1
    return bands


def _ragged(pts: np.ndarray, starts: np.ndarray, ring_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The rings ``ring_ids`` (pieces ``pts[starts[k]:starts[k + 1]]``) as one position array and its ring offsets."""
    off = np.zeros(len(ring_ids) + 1, np.intp)
    np.cumsum(starts[ring_ids + 1] - starts[ring_ids], out=off[1:])
    if len(ring_ids) == 0 or ring_ids[-1] == len(ring_ids) - 1:  # increasing: rings 0 .. n - 1, one slice
        return pts[starts[0]:starts[0] + off[-1]], off
    idx = np.concatenate([np.arange(starts[k], starts[k + 1]) for k in ring_ids]) if len(ring_ids) else \
        np.zeros(0, np.intp)
    return pts[idx], off


def _repaired(rings: list[np.ndarray], wgs: np.ndarray, ends: np.ndarray, i0: int, n: int) -> list[list[np.ndarray]]:
    """One polygon (rings ``i0 .. i0 + n - 1`` of ``rings``, projected in ``wgs``) made valid
    (:func:`gisnoise.geo.shapes.repaired`) and snapped to :data:`PRECISION_DEG`, oriented, as the lists of its
    parts' ring position arrays (rounded)."""
    wr = [wgs[(ends[k - 1] if k else 0):ends[k]] for k in range(i0, i0 + n)]
    geom = Polygon(wr[0], wr[1:])
    if geom.is_empty or geom.area == 0:
        return []
    return _snapped_parts(shapely.repaired(geom))


def _merged(polys: list[list[np.ndarray]]) -> list[list[np.ndarray]]:
    """A band's polygons (lists of ring position arrays) merged where they share an edge, snapped and oriented.

    For bands :func:`_parted_at` names: a ridge of nodes exactly at ``level_max`` belongs to the band above
    (a set without area), the band runs along it on each side, and its two polygons share that edge (no valid
    MultiPolygon holds both).  Their union is the band's area."""
    return _snapped_parts(shapely.union_all([Polygon(p[0], p[1:]) for p in polys]))


def _snapped_parts(geom: Any) -> list[list[np.ndarray]]:
    """The polygons of a valid ``geom`` snapped to :data:`PRECISION_DEG`, oriented, as lists of their rings'
    position arrays (rounded)."""
    g = shapely.set_precision(geom, PRECISION_DEG)
    return [[_rounded(np.asarray(ring.coords, dtype=float)[:, :2], True) for ring in (o.exterior, *o.interiors)]
            for o in (orient(part, sign=1.0) for part in _valid_polygons(g) if part.area > 0)]


def _snapped_buffer(pts: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each piece ``pts[ends[i - 1]:ends[i]]`` (rings and lines) on the :data:`PRECISION_DEG` grid, consecutive
    repeats within a piece dropped (as GEOS's snapping does), in one pass of NumPy: the kept positions and where
    each piece starts among them (one more: the end)."""
    if not len(ends):
        return np.zeros((0, 2)), np.zeros(1, np.intp)
    q = np.rint(pts / PRECISION_DEG) * PRECISION_DEG
    keep = np.ones(len(q), bool)
    if len(q) > 1:
        np.any(q[1:] != q[:-1], axis=1, out=keep[1:])
    keep[ends[:-1]] = True  # the first position of every piece
    starts = np.zeros(len(ends) + 1, np.intp)
    starts[1:] = np.cumsum(keep)[ends - 1]  # positions kept up to the end of each piece (pieces are not empty)
    return q[keep], starts


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
    return _features(result, levels, metrics, arrays=False)


def _features(result: MapResult, levels: Any, metrics: Sequence[str] | None, *, arrays: bool) -> list[dict]:
    """:func:`contour_features`; with ``arrays`` the positions stay numpy arrays (for :func:`geojson_text`)."""
    lv = parse_levels(levels)
    names = result.level_bands() if metrics is None else list(metrics)
    for n in names:
        result.band(n)
    grid = result.grid
    x, y = grid.xs, grid.ys
    tr = ContinuousLongitudes(transformer(grid.crs, WGS84), grid)  # across the antimeridian: :mod:`.antimeridian`
    units = result.units
    features: list[dict] = []
    for name in names:
        z = np.asarray(result.band(name), dtype=float)
        unit = units.get(name, "dB(A)")
        top = edge_max(z)
        mlv = metric_levels(name, lv)
        bounds = [(mlv[i], mlv[i + 1] if i + 1 < len(mlv) else None) for i in range(len(mlv))]
        bands, lines = _band_geometries(x, y, z, bounds, mlv, tr)
        if tr.crossed:  # RFC 7946 section 3.1.9: cut at +-180 deg
            bands, lines = split_at_antimeridian(bands, lines, PRECISION_DEG)
        for (lo, hi), geom in zip(bounds, bands, strict=True):
            if geom is None:
                continue
            label = f"{name} >= {lo:g} {unit}" if hi is None else f"{name} {lo:g}-{hi:g} {unit}"
            coords = geom if arrays else [[ring.tolist() for ring in poly] for poly in geom]
            features.append({"type": "Feature", "geometry": {"type": "MultiPolygon", "coordinates": coords},
                             "properties": {"metric": name, "level": lo, "level_max": hi, "kind": "isoband",
                                            "unit": unit, "name": label, "clipped": bool(top >= lo)}})
        for lo, ml in zip(mlv, lines, strict=True):
            if ml is None:
                continue
            features.append({"type": "Feature", "geometry": {
                "type": "MultiLineString", "coordinates": ml if arrays else [a.tolist() for a in ml]}, "properties": {
                "metric": name, "level": lo, "level_max": None, "kind": "isoline", "unit": unit,
                "name": f"{name} {lo:g} {unit}", "clipped": bool(top >= lo)}})
    return features


def _rounded(a: np.ndarray, arrays: bool) -> Any:
    """Positions rounded to 9 decimals (as :func:`round` does): an array, or lists."""
    a = np.rint(a * 1e9) / 1e9
    return a if arrays else a.tolist()


def contours_geojson(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> dict:
    """A GeoJSON FeatureCollection (RFC 7946) of :func:`contour_features`."""
    return _collection(result, levels, metrics, contour_features(result, levels, metrics=metrics))


def _collection(result: MapResult, levels: Any, metrics: Sequence[str] | None, feats: list[dict]) -> dict:
    """The FeatureCollection of ``feats``; its ``gisnoise`` member: the levels drawn, the map's warnings, the
    bands contoured (``metrics``: in the order of the features, the order of the map's bands and so of the
    GeoTIFF's unless ``metrics`` says otherwise, each listed even when none of its levels is reached) and the
    grid."""
    return {"type": "FeatureCollection", "features": feats,
            "gisnoise": {"levels": parse_levels(levels),
                         "warnings": geojson_warnings(result, levels, metrics),
                         "metrics": _contoured(result, metrics),
                         "grid": result.grid.to_dict()}}


def _contoured(result: MapResult, metrics: Sequence[str] | None) -> list[str]:
    """The bands :func:`contour_features` contours, in its order."""
    return result.level_bands() if metrics is None else list(dict.fromkeys(metrics))


def write_geojson(result: MapResult, path: str | os.PathLike[str], levels: Any, *,
                  metrics: Sequence[str] | None = None) -> Path:
    """Write :func:`contours_geojson` to ``path`` (temporary file, then rename).

    The positions are written by :func:`geojson_text` from the coordinate arrays (the same
    numbers as ``json.dumps`` of :func:`contours_geojson`, several times faster).
    """
    text = contours_text(result, levels, metrics=metrics)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, p)
    return p


def contours_text(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> str:
    """The text :func:`write_geojson` writes, in memory (a service answering without a file)."""
    feats = _features(result, levels, metrics, arrays=True)
    return geojson_text(_collection(result, levels, metrics, feats))


_TOKEN = "\x00gisnoise-positions-"


def geojson_text(doc: dict) -> str:
    """Compact JSON text of a GeoJSON document whose positions may be numpy arrays of shape (n, 2).

    Arrays are written by :func:`_positions_texts` (fixed 8 decimals: positions lie on the
    :data:`PRECISION_DEG` grid); everything else by ``json.dumps`` (``allow_nan=False``).

    >>> geojson_text({"name": "a", "coordinates": np.array([[10.5, -52.25], [-170.125, 0.0]])})
    '{"name":"a","coordinates":[[10.50000000,-52.25000000],[-170.12500000,0.00000000]]}'
    """
    arrays: list[np.ndarray] = []

    def token(o: Any) -> str:  # json.dumps asks for each object it cannot write itself: the arrays
        if isinstance(o, np.ndarray):
            arrays.append(o)
            return f"{_TOKEN}{len(arrays) - 1}"
        raise TypeError(f"Object of type {type(o).__name__} is not JSON serializable")

    text = json.dumps(doc, allow_nan=False, separators=(",", ":"), default=token)
    if not arrays:
        return text
    bodies = _positions_texts(arrays)
    quoted = json.dumps(_TOKEN)[:-1]  # as json.dumps writes the token: opening quote, escaped NUL, name
    pieces = text.split(quoted)
    out = [pieces[0]]
    for piece in pieces[1:]:
        end = piece.index('"')
        out.append(bodies[int(piece[:end])])
        out.append(piece[end + 1:])
    return "".join(out)


def _positions_texts(arrays: list[np.ndarray]) -> list[str]:
    """``[[x,y],...]`` of each (n, 2) array (|values| < 1000, 8 decimals), all formatted together (one pass of NumPy).

    A position is a row of eleven 4-byte words (``"   ["``, the integer part of x right-aligned with
    its sign, ``".   "``, two words of four decimals, ``"   ,"``, the same for y, ``"],  "``), each
    word taken from a table; the blanks of all rows are dropped in one step and each array's text is
    a slice of the packed text, without its last comma.
    """
    flat = [np.asarray(a, dtype=float).reshape(-1, 2) for a in arrays]
    sizes = [len(a) for a in flat]
    a = np.concatenate(flat) if flat else np.zeros((0, 2))
    if a.size and (not np.isfinite(a).all() or np.abs(a).max() >= 999.5):
        raise ValueError("positions must be finite and below 1000 in magnitude")
    k = np.rint(a * 1e8).astype(np.int64)
    n = len(k)
    words = np.empty((n, 11), np.uint32)
    words[:, 0], words[:, 5], words[:, 10] = _WORDS["   ["], _WORDS["   ,"], _WORDS["],  "]
    length = np.full(n, 4, np.intp)  # "[", "," and "]," of the row, then its numbers' characters
    for j, col in ((0, 1), (1, 6)):
        m = np.abs(k[:, j])
        ip = (m // 10 ** 8 + 1000 * (k[:, j] < 0)).astype(np.intp)  # integer part, negatives after 999
        fp = m % 10 ** 8
        words[:, col] = _INTEGERS[ip]
        words[:, col + 1] = _WORDS[".   "]
        words[:, col + 2] = _DIGITS4[fp // 10 ** 4]
        words[:, col + 3] = _DIGITS4[fp % 10 ** 4]
        length += _INTEGER_CHARS[ip] + 9  # the point and eight decimals
    text = words.tobytes().translate(None, b" ").decode("ascii")
    ends = np.zeros(n + 1, np.intp)  # where each row's packed text ends
    np.cumsum(length, out=ends[1:])
    first = np.zeros(len(sizes) + 1, np.intp)  # each array's first row
    np.cumsum(sizes, out=first[1:])
    bounds = ends[first].tolist()
    return ["[" + text[bounds[i]:bounds[i + 1] - 1] + "]" for i in range(len(sizes))]


def _as_words(texts: list[str]) -> np.ndarray:
    """Texts of four ASCII characters as 4-byte words (in the machine's byte order, as the rows are read)."""
    return np.frombuffer("".join(texts).encode("ascii"), np.uint32).copy()


_WORDS = {t: _as_words([t])[0] for t in ("   [", "   ,", "],  ", ".   ")}
_DIGITS4 = _as_words([f"{i:04d}" for i in range(10 ** 4)])
"""Four decimals ``0000 .. 9999`` as words."""
_INTEGERS = _as_words([f"{i:>4d}" for i in range(1000)] + [f"{-i:>4d}" if i else "  -0" for i in range(1000)])
"""Integer parts with their sign, right-aligned in four characters: ``0 .. 999``, then ``-0 .. -999``."""
_INTEGER_CHARS = np.array([len(str(i)) for i in range(1000)] + [len(str(i)) + 1 for i in range(1000)], np.intp)
