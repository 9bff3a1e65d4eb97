"""The noise map's extent in QGIS: the default margin closes the lowest level; a small one flags the cut."""

import pytest
from conftest import read_raster, run_map

pytestmark = pytest.mark.qgis

LEVELS = [50.0, 55.0, 60.0, 65.0]


def _edge_max(band):
    import numpy as np

    return float(np.concatenate([band[0], band[-1], band[:, 0], band[:, -1]]).max())


def _clipped(path):
    from qgis.core import QgsVectorLayer

    layer = QgsVectorLayer(str(path), "contours", "ogr")
    assert layer.isValid(), path
    assert layer.fields().indexOf("clipped") >= 0
    return {(f["metric"], f["level"]): bool(f["clipped"]) for f in layer.getFeatures()}


def test_default_margin_closes_the_lowest_level(plugin, flight_csv, tmp_path):
    res = run_map(tmp_path, "auto", TRAJECTORY_FILE=str(flight_csv), MARGIN=None)
    grid, names, *_ = read_raster(res["OUTPUT_RASTER"])
    assert grid[names.index("LAmax")].max() > 60.0
    assert _edge_max(grid[names.index("LAmax")]) < 50.0
    flags = _clipped(res["OUTPUT_BANDS"])
    assert flags and not any(flags.values())


def test_a_small_margin_flags_the_cut_contours(plugin, flight_csv, tmp_path):
    res = run_map(tmp_path, "small", TRAJECTORY_FILE=str(flight_csv), MARGIN=40.0)
    grid, names, *_ = read_raster(res["OUTPUT_RASTER"])
    top = _edge_max(grid[names.index("LAmax")])
    flags = _clipped(res["OUTPUT_BANDS"])
    assert flags == {("LAmax", lv): top >= lv for lv in LEVELS if ("LAmax", lv) in flags}
    assert top >= 50.0 and any(flags.values())
