"""gisnoise.geo.shapes: the shapely 2 names the core uses, on shapely 2 and on the shapely 1.8 path.

QGIS 3.22 brings shapely 1.8; the 1.8 path is run here by setting ``SHAPELY2`` to False (it
uses only API that 1.8 and 2.x share) and checked against analytic truths; the QGIS tests run
it on QGIS's own shapely 1.8.
"""

import ast
import math
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import shape

from gisnoise.geo import LocalFrame, shapes

ROOT = Path(__file__).resolve().parents[1]
#: shapely 2 warns about the 1.8 API the 1.8 path uses (shapely 1.8 itself does not).
pytestmark = pytest.mark.filterwarnings("ignore:.*shapely.*deprecated:DeprecationWarning")


@pytest.fixture(params=[True, False], ids=["shapely2", "shapely1.8-path"])
def path(request, monkeypatch):
    monkeypatch.setattr(shapes, "SHAPELY2", request.param)
    return request.param


def test_predicates_and_distances_of_the_unit_square(path):
    sq = shapes.box(0.0, 0.0, 1.0, 1.0)
    shapes.prepare(sq)
    x = np.array([[0.5, 2.0, -1.0], [0.25, 0.5, 3.0]])
    y = np.array([[0.5, 0.5, 0.5], [0.75, 4.0, 5.0]])
    inside = shapes.contains_xy(sq, x, y)
    assert inside.shape == (2, 3) and inside.tolist() == [[True, False, False], [True, False, False]]
    d = shapes.distance(sq.boundary, shapes.points(x, y))
    # to the nearest edge or corner of the square
    want = [[0.5, 1.0, 1.0], [0.25, 3.0, math.hypot(2.0, 4.0)]]
    np.testing.assert_allclose(d, want, rtol=0, atol=1e-12)
    assert shapes.intersects(shapes.LineString([(-1, 0.5), (2, 0.5)]), sq)
    assert not shapes.intersects(shapes.LineString([(-1, 2), (2, 2)]), sq)


def test_union_buffer_transform_wkb(path):
    a, b = shapes.box(0, 0, 1, 1), shapes.box(0.5, 0.5, 1.5, 1.5)
    assert shapes.union_all([a, b]).area == pytest.approx(2.0 - 0.25, abs=1e-12)
    grown = shapes.buffer(a, 1.0)
    # square + 4 strips + quarter discs, each a quarter of the inscribed 32-gon (8 segments a quarter)
    assert grown.area == pytest.approx(1.0 + 4.0 + 16.0 * math.sin(math.pi / 16.0), rel=1e-12)
    moved = shapes.transform(a, lambda c: c * 2.0 + np.array([10.0, -5.0]))
    assert moved.bounds == (10.0, -5.0, 12.0, -3.0) and moved.area == pytest.approx(4.0)
    assert shapes.from_wkb(a.wkb).equals(a)


def test_set_precision_snaps_and_drops_collapsed_parts(path):
    g = 0.01
    line = shapes.LineString([(0.0012, 0.0), (0.0041, 0.0), (1.004, 0.996)])
    snapped = shapes.set_precision(line, g)
    c = np.asarray(snapped.coords)
    np.testing.assert_allclose(c, np.round(c / g) * g, rtol=0, atol=1e-12)
    assert len(c) == 2  # the first two points fall on the same node
    assert shapes.set_precision(shapes.LineString([(0.001, 0.0), (0.003, 0.001)]), g).is_empty
    ring = shapes.Polygon([(0, 0), (1.0013, 0), (1.0013, 1.0), (0, 1.0)])
    q = shapes.set_precision(ring, g)
    assert q.is_valid and q.area == pytest.approx(1.0, abs=1e-12)
    sliver = shapes.Polygon([(0, 0), (1, 0), (1, 0.001), (0, 0.001)])
    assert shapes.set_precision(sliver, g).area == 0.0


def test_contours_of_a_hover_are_the_same_on_both_paths(monkeypatch):
    """The map's isobands through the 1.8 path: the disc areas of spherical spreading, as on shapely 2."""
    from test_contours import LAT0, LON0, hover_result

    from gisnoise.maps import contours_geojson

    result = hover_result(metrics=("LAmax",))
    f = LocalFrame(LAT0, LON0, 500.0)

    def areas():
        doc = contours_geojson(result, "50,55,60", metrics=["LAmax"])
        out = {}
        for feat in doc["features"]:
            p = feat["properties"]
            g = shape(feat["geometry"])
            assert g.is_valid

            def to_en(c):
                e, n, _ = f.to_enu(c[:, 1], c[:, 0], np.full(len(c), 500.0))
                return np.column_stack([e, n])

            local = shapes.transform(g, to_en)
            out[(p["kind"], p["level"])] = local.area if p["kind"] == "isoband" else local.length
        return out

    monkeypatch.setattr(shapes, "SHAPELY2", True)
    two = areas()
    monkeypatch.setattr(shapes, "SHAPELY2", False)
    old = areas()
    assert old.keys() == two.keys() and len(old) == 6
    for k in two:
        assert old[k] == pytest.approx(two[k], rel=1e-6), k

    def radius(level):
        return math.sqrt((40.0 * 10 ** ((70.0 - level) / 20.0)) ** 2 - 38.5 ** 2)

    assert old[("isoband", 60.0)] == pytest.approx(math.pi * radius(60.0) ** 2, rel=5e-3)
    assert old[("isoline", 55.0)] == pytest.approx(2 * math.pi * radius(55.0), rel=5e-3)


def _shapely_uses(path: Path):
    """(aliases of gisnoise.geo.shapes, attributes used on them, direct imports of the shapely package)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    aliases, direct = set(), []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module == "gisnoise.geo":
            aliases |= {a.asname or a.name for a in node.names if a.name == "shapes"}
        if isinstance(node, ast.Import):
            direct += [a.name for a in node.names if a.name == "shapely"]
        if isinstance(node, ast.ImportFrom) and node.module == "shapely":
            direct.append("from shapely import")
    used = {n.attr for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in aliases}
    return aliases, used, direct


def test_the_core_reaches_shapely_only_through_shapes():
    """The modules QGIS runs: no shapely-2-only name outside gisnoise.geo.shapes (the service runs elsewhere)."""
    bad = []
    files = sorted((ROOT / "gisnoise").rglob("*.py")) + sorted((ROOT / "qgis_plugin").rglob("*.py"))
    for p in files:
        rel = p.relative_to(ROOT).as_posix()
        if rel in ("gisnoise/geo/shapes.py",) or rel.startswith(("gisnoise/service/", "gisnoise/cli/")):
            continue
        _aliases, used, direct = _shapely_uses(p)
        bad += [f"{rel}: {d}" for d in direct]
        bad += [f"{rel}: shapes.{u} is not offered" for u in sorted(used - shapes.NAMES)]
    assert not bad, "\n".join(bad)


def test_ring_polygons_check_and_orient_as_shapely_does(path):
    """Areas, validity and orientation of polygons in ragged arrays: the unit truths of each polygon."""
    cw_square = [(0, 0), (0, 2), (2, 2), (2, 0), (0, 0)]  # exterior clockwise: reversed
    ccw_hole = [(0.5, 0.5), (1, 0.5), (1, 1), (0.5, 1), (0.5, 0.5)]  # hole counter-clockwise: reversed
    bow_tie = [(0, 0), (1, 1), (1, 0), (0, 1), (0, 0)]  # self-crossing: invalid, signed halves cancel
    triangle = [(3, 0), (4, 0), (3, 1), (3, 0)]  # counter-clockwise already
    sliver = [(0, 0), (1, 0), (2, 0), (0, 0)]  # no area: invalid
    rings = [cw_square, ccw_hole, bow_tie, triangle, sliver]
    coords = np.array([p for r in rings for p in r], dtype=float)
    ring_off = np.cumsum([0] + [len(r) for r in rings])
    poly_off = np.array([0, 2, 3, 4, 5])
    area, valid, oriented, pos = shapes.ring_polygons(coords, ring_off, poly_off)
    np.testing.assert_array_equal(area, [3.75, 0.0, 0.5, 0.0])
    np.testing.assert_array_equal(shapes.ring_polygon_areas(coords, ring_off, poly_off), area)
    assert valid.tolist() == [True, False, True, False] and oriented.tolist() == [True, False, True, False]
    want = [cw_square[::-1], ccw_hole[::-1], triangle]
    np.testing.assert_array_equal(pos, np.array([p for r in want for p in r], dtype=float))


def test_winding_polygons_leave_out_a_path_run_there_and_back(path):
    """The square [1, 3] x [0, 2] whose ring first runs round the unit square [0, 1]^2 and back the same way: that
    path winds around nothing, so the area is the square's 4 (GEOS's linework repair takes the path as edges)."""
    ring = [(1, 0), (0, 0), (0, 1), (1, 1), (0, 1), (0, 0), (1, 0), (3, 0), (3, 2), (1, 2), (1, 0)]
    poly = shapes.Polygon(ring)
    assert not poly.is_valid
    parts = shapes.winding_polygons(poly)
    assert len(parts) == 1 and parts[0].is_valid and parts[0].area == pytest.approx(4.0, abs=1e-12)
    assert parts[0].equals(shapes.box(1.0, 0.0, 3.0, 2.0))
    fixed = shapes.repaired(poly)
    assert fixed.is_valid and fixed.area == pytest.approx(4.0, abs=1e-12)
    # a hole run along the same way inside a 4 x 4 square: the square less the 1 x 1 hole
    hole = [(1, 1), (2, 1), (2, 2), (1, 2), (1, 1), (2, 1), (1, 1)]
    with_hole = shapes.Polygon([(0, 0), (4, 0), (4, 4), (0, 4), (0, 0)], [hole])
    assert sum(p.area for p in shapes.winding_polygons(with_hole)) == pytest.approx(15.0, abs=1e-12)


def test_repaired_keeps_make_valid_where_both_give_one_area(path):
    """A bow tie (two triangles of 1/4 each, wound opposite ways): both lobes, as ``make_valid`` gives them."""
    bow_tie = shapes.Polygon([(0, 0), (1, 1), (1, 0), (0, 1), (0, 0)])
    assert sum(p.area for p in shapes.winding_polygons(bow_tie)) == pytest.approx(0.5, abs=1e-12)
    fixed = shapes.repaired(bow_tie)
    assert fixed.equals(shapes.make_valid(bow_tie)) and fixed.area == pytest.approx(0.5, abs=1e-12)
    assert shapes.winding_polygons(shapes.Polygon()) == []
