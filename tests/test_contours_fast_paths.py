"""The shortcuts of the contour writer give what their definitions give.

* each distinct point transformed once = every point transformed by pyproj on its own;
* snapping all pieces in one pass = snapping each piece (repeats dropped inside a piece, never
  across two pieces);
* a map on a grid the caller built = the map on the grid ``make_map`` builds from the same
  resolution and margin (the service checks the grid's size first and passes it on).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gisnoise.geo import WGS84, transformer, utm_crs
from gisnoise.maps import contours, grid_for_trajectory, make_map
from gisnoise.model import cards as gcards

REPO = Path(__file__).resolve().parents[1]


def _per_point(pts: np.ndarray, tr) -> np.ndarray:
    return np.array([tr.transform(float(x), float(y)) for x, y in pts])


@pytest.mark.parametrize("zero", [False, True])
def test_distinct_points_transformed_once_equal_every_point_transformed(zero):
    crs = utm_crs(10.52, 52.26)
    tr = transformer(crs, WGS84)
    rng = np.random.default_rng(3)
    a = rng.uniform([600_000, 5_790_000], [610_000, 5_800_000], (50, 2))
    b = np.vstack([a[10:20], rng.uniform([600_000, 5_790_000], [610_000, 5_800_000], (7, 2)), a[:3]])  # shared points
    if zero:  # -0.0 and 0.0 are one number to a sort: the points are then transformed one by one
        b[0] = [0.0, 5_795_000.0]
        b[1] = [-0.0, 5_795_000.0]
    out = contours._bulk_wgs84([a, b], tr)
    assert out.shape == (len(a) + len(b), 2)
    np.testing.assert_array_equal(out, _per_point(np.vstack([a, b]), tr))  # bit for bit
    assert contours._bulk_wgs84([], tr).shape == (0, 2)


def _snapped_pieces(pts, ends):
    """The one-pass snapping's buffer split into its pieces."""
    q, starts = contours._snapped_buffer(pts, ends)
    return np.split(q, starts[1:-1]) if len(ends) else []


def test_snapping_in_one_pass_equals_snapping_each_piece():
    p = contours.PRECISION_DEG
    ring = np.array([[0.0, 0.0], [1.0, 0.0], [1.0 + 0.2 * p, 0.0], [1.0, 1.0], [0.0, 0.0]])  # a repeat once snapped
    line = np.array([[0.0, 0.0], [0.3 * p, 0.0], [2.0, 2.0]])  # starts where the ring ends: kept, it is another piece
    pieces = _snapped_pieces(np.vstack([ring, line]), np.array([5, 8]))
    np.testing.assert_array_equal(pieces[0], [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(pieces[1], [[0.0, 0.0], [2.0, 2.0]])
    rng = np.random.default_rng(5)
    # points within a few grid steps of each other: many snap onto the same node as their neighbour
    pts = 0.5 + rng.integers(-1, 2, (300, 2)) * p + rng.uniform(-0.4, 0.4, (300, 2)) * p
    ends = np.array([4, 9, 60, 61, 200, 300])
    one_pass = _snapped_pieces(pts, ends)
    repeats = 0
    for x, (s, e) in zip(one_pass, zip(np.r_[0, ends[:-1]], ends, strict=True), strict=True):
        q = np.rint(pts[s:e] / p) * p  # the rule, piece by piece: on the grid, no two equal positions in a row
        keep = np.r_[True, np.any(q[1:] != q[:-1], axis=1)]
        repeats += int((~keep).sum())
        np.testing.assert_array_equal(x, q[keep])
    assert repeats > 10  # the data exercise the dropping
    assert _snapped_pieces(np.zeros((0, 2)), np.zeros(0, np.intp)) == []


def test_a_map_on_the_callers_grid_is_the_map_on_the_grid_make_map_builds():
    route = json.loads((REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson").read_text())
    cards = [gcards.load(REPO / "gisnoise" / "data" / "cards" / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]
    kw = dict(levels=(45, 55, 65), outputs=("contours",))
    own = make_map(route, cards, None, resolution_m=40, margin_m=200, **kw)
    grid = grid_for_trajectory(own["trajectory"], 40, 200)
    given = make_map(own["trajectory"], cards, None, resolution_m=1, margin_m=5, grid=grid, **kw)  # not used
    assert given["result"].grid == own["result"].grid
    assert given["contours_text"] == own["contours_text"]
