"""Contours of fields with nodes exactly at a level, on QGIS's own shapely (1.8 on QGIS 3.22 LTR).

The bands' definition ``level <= L < level_max``: a plateau exactly at a level lies in the band
from that level up, with the area of the plateau, and a band's polygons hold no node of another
band where a row of nodes lies exactly at a level (the rings contourpy draws along such a row run
there and back, and the repair by winding number leaves that run out).
"""

import pytest

pytestmark = pytest.mark.qgis

LEVELS = [45.0, 50.0, 55.0, 60.0, 65.0]
CELL = 10.0


def _grid():
    from affine import Affine

    from gisnoise.geo import GridSpec, utm_crs

    return GridSpec(utm_crs(10.52, 52.26), Affine(CELL, 0.0, 603_000.0, 0.0, -CELL, 5_792_000.0), 41, 31)


def _bands(z):
    """Level -> the written isoband in the grid's CRS (shapely geometry); ``z`` with rows northwards."""
    import numpy as np
    from shapely.geometry import shape
    from shapely.ops import transform

    from gisnoise.geo import WGS84, transformer
    from gisnoise.maps import contours_geojson
    from gisnoise.maps.result import MapResult

    grid = _grid()
    result = MapResult({"LAmax": z[::-1].copy()}, grid, {"units": {"LAmax": "dB(A)"}})
    to_grid = transformer(WGS84, grid.crs)
    out = {}
    for feat in contours_geojson(result, LEVELS, metrics=["LAmax"])["features"]:
        if feat["properties"]["kind"] == "isoband":
            geom = shape(feat["geometry"])
            assert geom.is_valid
            out[feat["properties"]["level"]] = transform(lambda x, y: to_grid.transform(np.asarray(x), np.asarray(y)),
                                                         geom)
    return out


def test_a_plateau_at_a_level_lies_in_the_band_above(plugin):
    """40 dB with 5 x 5 nodes at exactly 50 dB (side 4 cells): 50 dB band 4^2 cells; 45-50 dB the rim, 2 * 4 + 1/2
    cells (half-cell strips along the sides, 1/8 cell at each corner)."""
    import numpy as np

    grid = _grid()
    z = np.full((grid.height, grid.width), 40.0)
    z[10:15, 12:17] = 50.0
    areas = {lo: g.area for lo, g in _bands(z).items()}
    assert areas.keys() == {45.0, 50.0}
    assert areas[50.0] == pytest.approx(16.0 * CELL * CELL, rel=1e-4)
    assert areas[45.0] == pytest.approx(8.5 * CELL * CELL, rel=1e-4)


def test_rows_at_a_level_leave_every_node_in_its_band(plugin):
    """Saddles whose first row and column lie exactly at 55 dB: each node off the levels lies in the band of its
    level and in no other."""
    import numpy as np
    from shapely.geometry import Point

    grid = _grid()
    v, u = np.mgrid[0:grid.height, 0:grid.width].astype(float)
    z = 55.0 + 12.0 * np.sin(u / 2.5) * np.sin(v / 2.5)
    bands = _bands(z)
    x0, y0 = grid.xs[0], grid.ys[::-1][0]
    for lo, geom in bands.items():
        hi = LEVELS[LEVELS.index(lo) + 1] if lo != LEVELS[-1] else np.inf
        edge = geom.boundary
        for zi, uu, vv in zip(z.ravel(), u.ravel(), v.ravel(), strict=True):
            pt = Point(x0 + CELL * uu, y0 + CELL * vv)
            if min(abs(zi - lo), abs(zi - hi)) < 1e-9 or edge.distance(pt) < 1e-3:
                continue  # a node at a level, or on the band's edge
            assert geom.contains(pt) == bool(lo <= zi < hi), f"band {lo}: node at {zi} dB"
