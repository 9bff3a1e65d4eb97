"""The written contours against their definition, on fields made to break a contour writer.

Fields: plateaus exactly at the levels, nodes a hair off a level, saddles, a checkerboard,
single loud cells, NaN cells (scattered, a block, a whole column), levels reaching the
grid's edge, noise.  For every isoband and isoline of ``contours_geojson``, with the
positions taken back to the grid's CRS:

* each vertex lies on its level by linear interpolation along the cell edge it sits on
  (or, where NaN cells cut a cell corner off, along that corner's diagonal), or is a grid
  node inside the band (the grid's edge, a NaN border, a plateau);
* grid nodes clearly inside a band lie in its polygons, nodes clearly outside do not;
* polygons are valid, exteriors counter-clockwise, holes clockwise, positions on the
  1e-8 deg grid; ``clipped`` says whether the band's level reaches the grid's outer nodes or a node next
  to a NaN node (where the contour stops as at the grid's edge);
* the polygons checked and oriented all at once (:func:`gisnoise.geo.shapes.ring_polygons`)
  equal those done one by one with shapely's ``orient`` (the shapely 1.8 path).
"""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from affine import Affine
from shapely.geometry import LinearRing, Point, shape

from gisnoise.geo import WGS84, GridSpec, shapes, transformer, utm_crs
from gisnoise.maps import contours, contours_geojson
from gisnoise.maps.result import MapResult

LEVELS = [45.0, 50.0, 55.0, 60.0, 65.0]
CELL = 10.0
TOL_CELLS = 2e-4  # snapping to 1e-8 deg and rounding move a vertex by under 1 mm: 1e-4 of a 10 m cell
GRID = GridSpec(utm_crs(10.52, 52.26), Affine(CELL, 0.0, 603_000.0, 0.0, -CELL, 5_792_000.0), 41, 31)


def _fields() -> dict[str, np.ndarray]:
    ny, nx = GRID.height, GRID.width
    v, u = np.mgrid[0:ny, 0:nx].astype(float)
    rng = np.random.default_rng(11)
    cone = 72.0 - 1.1 * np.hypot(u - 17.3, v - 13.6)
    out = {"cone": cone, "plateaus_at_levels": np.round(cone), "plateaus_5db": np.round(cone / 5.0) * 5.0}
    near = cone.copy()
    near[np.abs(near - 55.0) < 0.6] = 55.0 + 1e-12  # nodes a hair above a level
    near[np.abs(near - 50.0) < 0.6] = 50.0 - 1e-12  # and a hair below one
    out["hair_off_levels"] = near
    out["saddles"] = 55.0 + 12.0 * np.sin(u / 2.5) * np.sin(v / 2.5)
    out["saddles_at_levels"] = 55.0 + 10.0 * np.round(np.sin(u * np.pi / 2) * np.sin(v * np.pi / 2))
    out["checkerboard"] = 50.0 + 10.0 * ((u + v) % 2)
    single = np.full((ny, nx), 40.0)
    single[15, 20], single[1, 1], single[0, nx - 1], single[ny - 1, 7] = 70.0, 55.0, 66.0, 50.0
    out["single_cells"] = single
    scattered = cone.copy()
    scattered[rng.random((ny, nx)) < 0.06] = np.nan
    out["nan_scattered"] = scattered
    block = out["saddles"].copy()
    block[8:14, 10:19] = np.nan
    block[:, 0] = np.nan
    out["nan_block_and_column"] = block
    out["ramp_to_the_edge"] = 68.0 - 0.6 * u
    out["noise"] = np.round(55.0 + rng.normal(0.0, 6.0, (ny, nx)), 1)
    return out


FIELDS = _fields()


def _grid_coords(ring: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """WGS84 positions -> column and row of the contour grid (cell centres at integers, rows northwards)."""
    x, y = transformer(WGS84, GRID.crs).transform(ring[:, 0], ring[:, 1])
    xs, ys = GRID.xs, GRID.ys[::-1]  # contourpy's rows run northwards
    return (np.asarray(x) - xs[0]) / CELL, (np.asarray(y) - ys[0]) / CELL


def _on_level(z: np.ndarray, u: float, v: float, levels: list[float], lo: float, hi: float | None) -> str | None:
    """None when the vertex ``(u, v)`` lies on one of ``levels`` by linear interpolation along its cell's edge or
    diagonal, or is a node whose value lies in the band ``[lo, hi]``; else what is wrong."""
    ny, nx = z.shape
    iu, iv = round(u), round(v)
    du, dv = abs(u - iu), abs(v - iv)
    top = np.inf if hi is None else hi
    if du < TOL_CELLS and dv < TOL_CELLS and lo - 1e-9 <= z[iv, iu] <= top + 1e-9:
        return None  # a node in the band
    u0, v0 = min(int(np.floor(u)), nx - 2), min(int(np.floor(v)), ny - 2)
    fu, fv = u - u0, v - v0
    edges = []  # the cell edges (and cut-off corners' diagonals) the vertex may lie on: their ends and its fraction
    if dv < TOL_CELLS:  # on a row: between columns u0 and u0 + 1
        edges.append((z[iv, u0], z[iv, u0 + 1], fu))
    if du < TOL_CELLS:  # on a column
        edges.append((z[v0, iu], z[v0 + 1, iu], fv))
    if abs(fu - fv) < TOL_CELLS:
        edges.append((z[v0, u0], z[v0 + 1, u0 + 1], fu))
    if abs(fu + fv - 1.0) < TOL_CELLS:
        edges.append((z[v0, u0 + 1], z[v0 + 1, u0], fv))
    for za, zb, t in edges:
        level = za + t * (zb - za)
        if any(abs(level - lv) <= abs(zb - za) * 2 * TOL_CELLS + 1e-9 for lv in levels):
            return None
    return f"({u:.5f}, {v:.5f}) on no level along {len(edges)} edges near it"


def _plateau_cells(z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Columns and rows of the centres of cells whose four corners hold one value, and that value: the
    level is that value all over such a cell (a plateau has area)."""
    c = z[:-1, :-1]
    same = np.isfinite(c) & (z[1:, :-1] == c) & (z[:-1, 1:] == c) & (z[1:, 1:] == c)
    vv, uu = np.nonzero(same)
    return uu + 0.5, vv + 0.5, c[vv, uu]


@pytest.fixture(params=[True, False], ids=["shapely2", "shapely1.8-path"])
def shapely_path(request, monkeypatch):
    """The core on shapely 2's functions, and on the calls it makes with shapely 1.8 (QGIS)."""
    monkeypatch.setattr(shapes, "SHAPELY2", request.param)
    return request.param


@pytest.mark.filterwarnings("ignore:.*shapely.*deprecated:DeprecationWarning")  # the 1.8 calls on shapely 2
@pytest.mark.parametrize("name", sorted(FIELDS))
def test_contours_lie_on_their_levels_and_bound_their_bands(name, shapely_path):
    z = FIELDS[name]  # rows northwards (contour rows); the map holds them southwards
    result = MapResult({"LAmax": z[::-1].copy()}, GRID, {"units": {"LAmax": "dB(A)"}})
    doc = contours_geojson(result, LEVELS, metrics=["LAmax"])
    zc = z  # rows northwards: row v of zc is contour row v
    finite = np.isfinite(zc)
    # where the values end: the outer nodes and the nodes next to (of 8 neighbours) a NaN node
    from scipy.ndimage import binary_dilation

    by_nan = binary_dilation(np.isnan(zc), structure=np.ones((3, 3), bool)) & finite
    edge_max = np.nanmax(np.concatenate([zc[0], zc[-1], zc[:, 0], zc[:, -1], zc[by_nan]]))
    # the contoured domain: nodes of a cell with at least three finite corners (a cell with one NaN corner
    # keeps the triangle of the other three)
    corners = finite[:-1, :-1].astype(int) + finite[1:, :-1] + finite[:-1, 1:] + finite[1:, 1:]
    full = np.zeros_like(finite)
    for dv in (0, 1):
        for du in (0, 1):
            full[dv:dv + corners.shape[0], du:du + corners.shape[1]] |= corners >= 3
    domain = finite & full
    pu, pv, pz = _plateau_cells(zc)
    plon, plat = GRID.to_wgs84(GRID.xs[0] + CELL * pu, GRID.ys[::-1][0] + CELL * pv)
    bands = 0
    present = set()
    for feat in doc["features"]:
        p = feat["properties"]
        lo, hi = p["level"], p["level_max"]
        assert p["clipped"] == bool(edge_max >= lo)
        if p["kind"] == "isoline":
            for line in feat["geometry"]["coordinates"]:
                a = np.asarray(line)
                assert np.all(np.abs(a * 1e8 - np.rint(a * 1e8)) < 1e-4)
                for u, v in zip(*_grid_coords(a), strict=True):
                    bad = _on_level(zc, u, v, [lo], lo, lo)
                    assert bad is None, f"{name} isoline {lo}: {bad}"
            continue
        bands += 1
        present.add(lo)
        geom = shape(feat["geometry"])
        assert geom.is_valid, f"{name} band {lo}: {shapely.is_valid_reason(geom)}"
        for poly, rings in zip(geom.geoms, feat["geometry"]["coordinates"], strict=True):
            assert LinearRing(rings[0]).is_ccw and not any(LinearRing(h).is_ccw for h in rings[1:])
            for ring in rings:
                a = np.asarray(ring)
                assert np.all(np.abs(a * 1e8 - np.rint(a * 1e8)) < 1e-4)  # on the 1e-8 deg grid
                for u, v in zip(*_grid_coords(a), strict=True):
                    bad = _on_level(zc, u, v, [lo] if hi is None else [lo, hi], lo, hi)
                    assert bad is None, f"{name} band {lo}-{hi}: {bad}"
            assert poly.area > 0
        # point sampling: nodes clearly in the band are covered, nodes clearly outside are not
        top = np.inf if hi is None else hi
        vv, uu = np.nonzero(domain)
        lon, lat = GRID.to_wgs84(GRID.xs[0] + CELL * uu, GRID.ys[::-1][0] + CELL * vv)
        near = geom.boundary
        for zi, x, y in zip(zc[vv, uu], lon, lat, strict=True):
            pt = Point(x, y)
            if min(abs(zi - lo), abs(zi - top)) < 1e-9 or near.distance(pt) < 3e-8:
                continue  # a node at a level (its set may have no area) or on the boundary (a cut corner)
            assert geom.contains(pt) == bool(lo <= zi < top), f"{name} band {lo}-{hi}: node at {zi} dB"
        # a plateau exactly at a level lies in the band from that level up, and in no other
        for zi, x, y in zip(pz, plon, plat, strict=True):
            assert geom.contains(Point(x, y)) == bool(lo <= zi < top), f"{name} band {lo}-{hi}: plateau at {zi} dB"
    assert bands or not np.nanmax(zc) >= LEVELS[0]
    # every band that holds a node inside it or a plateau has a feature
    for lo, hi in zip(LEVELS, LEVELS[1:] + [np.inf], strict=True):
        if np.any(domain & (zc > lo) & (zc < hi)) or np.any((pz >= lo) & (pz < hi)):
            assert lo in present, f"{name}: no band {lo}-{hi}"


@pytest.mark.parametrize("name", sorted(FIELDS))
def test_polygons_checked_at_once_equal_polygons_checked_one_by_one(name, monkeypatch):
    """``ring_polygons`` on a band's snapped rings: shapely 2's vectorised calls give what ``orient`` gives per
    polygon (the shapely 1.8 path), bit for bit, valid or not."""
    z = FIELDS[name]
    gen = contours._generator(GRID.xs, GRID.ys[::-1], z)
    tr = transformer(GRID.crs, WGS84)
    rings, counts = [], []
    for lo, hi in zip(LEVELS, LEVELS[1:] + [float(np.nanmax(z)) + 1.0], strict=True):
        if hi <= lo:
            continue
        pts, offs = gen.filled(lo, hi)
        for pt, off in zip(pts, offs, strict=True):
            rr = [pt[off[i]:off[i + 1]] for i in range(len(off) - 1)]
            counts.append(len(rr))
            rings += rr
    if not rings:
        pytest.skip("no band on this field")
    wgs = contours._bulk_wgs84(rings, tr)
    q, starts = contours._snapped_buffer(wgs, np.cumsum([len(r) for r in rings]))
    closed = [e - s >= 4 and np.array_equal(q[s], q[e - 1]) for s, e in zip(starts[:-1], starts[1:], strict=True)]
    keep, at = [], 0
    for n in counts:
        if all(closed[at:at + n]):
            keep.append(range(at, at + n))
        at += n
    ids = np.array([k for r in keep for k in r])
    coords = np.concatenate([q[starts[k]:starts[k + 1]] for k in ids])
    ring_off = np.cumsum([0] + [starts[k + 1] - starts[k] for k in ids])
    poly_off = np.cumsum([0] + [len(r) for r in keep])
    monkeypatch.setattr(shapes, "SHAPELY2", True)
    at_once = shapes.ring_polygons(coords, ring_off, poly_off)
    monkeypatch.setattr(shapes, "SHAPELY2", False)
    one_by_one = shapes.ring_polygons(coords, ring_off, poly_off)
    for a, b in zip(at_once, one_by_one, strict=True):
        np.testing.assert_array_equal(a, b)
    assert at_once[2].sum() > 0


def _band_areas(z: np.ndarray) -> dict[float, float]:
    """Level -> area (m^2, in the grid's CRS) of the written isoband from that level; ``z`` with rows northwards."""
    result = MapResult({"LAmax": z[::-1].copy()}, GRID, {"units": {"LAmax": "dB(A)"}})
    to_grid = transformer(WGS84, GRID.crs)
    out = {}
    for feat in contours_geojson(result, LEVELS, metrics=["LAmax"])["features"]:
        if feat["properties"]["kind"] == "isoband":
            geom = shapely.transform(shape(feat["geometry"]), lambda c: np.column_stack(to_grid.transform(c[:, 0], c[:, 1])))
            assert geom.is_valid
            out[feat["properties"]["level"]] = geom.area
    return out


def test_a_plateau_exactly_at_a_level_lies_in_the_band_above_it():
    """40 dB with a square of 5 x 5 nodes at exactly 50 dB (side s = 4 cells of 10 m): the 50 dB band is the
    square, s^2 cells; 45-50 dB is the rim where the edges from 50 to 40 dB pass 45 dB at their middles, a strip
    half a cell wide along each side and a corner triangle of 1/8 cell at each corner: 2 s + 1/2 cells."""
    z = np.full((GRID.height, GRID.width), 40.0)
    z[10:15, 12:17] = 50.0
    s, cell_area = 4.0, CELL * CELL
    areas = _band_areas(z)
    assert areas.keys() == {45.0, 50.0}
    assert areas[50.0] == pytest.approx(s * s * cell_area, rel=1e-4)  # snapping moves a vertex by under 1 mm
    assert areas[45.0] == pytest.approx((2 * s + 0.5) * cell_area, rel=1e-4)
    x, y = GRID.xs, GRID.ys[::-1]
    assert sum(p.area for p in contours.isobands(x, y, z, [50.0, 55.0])) == pytest.approx(s * s * cell_area)
    assert sum(p.area for p in contours.isobands(x, y, z, [45.0, 50.0])) == pytest.approx((2 * s + 0.5) * cell_area)


@pytest.mark.parametrize("sign", [1.0, -1.0], ids=["trough", "ridge"])
def test_a_row_exactly_at_a_level_between_rising_rows(sign):
    """z = 50 + sign 5 |v - 15| dB (row 15 exactly at 50 dB, 40 cells wide).  Trough: 50-55 dB is |v - 15| < 1,
    two rows of cells; 55-60 dB the two strips 1 <= |v - 15| < 2; nothing lies below 50 dB.  Ridge: 45-50 dB is
    0 < |v - 15| <= 1 (the row at 50 dB has no area); no band from 50 dB."""
    v = np.arange(GRID.height, dtype=float)[:, None] * np.ones(GRID.width)
    z = 50.0 + sign * 5.0 * np.abs(v - 15.0)
    strip = (GRID.width - 1) * CELL * CELL  # one row of cells
    areas = _band_areas(z)
    expected = {50.0: 2 * strip, 55.0: 2 * strip, 60.0: 2 * strip} if sign > 0 else {45.0: 2 * strip}
    for lo, area in expected.items():
        assert areas.get(lo) == pytest.approx(area, rel=1e-4)
    assert 45.0 not in areas if sign > 0 else 50.0 not in areas
