"""The noise grid written to a path that held an earlier grid, and to a format of one band."""

import numpy as np
import pytest
from conftest import CARDS, MAP_OPTIONS, REPO, read_raster, run_map

pytestmark = pytest.mark.qgis

ROUTE = REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
DEMO = [str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]


def _statistics(path):
    """min, max of band 1 as GDAL (and so QGIS) reports them: from the .aux.xml beside the file when there is one."""
    from osgeo import gdal

    ds = gdal.Open(str(path))
    lo, hi, _, _ = ds.GetRasterBand(1).GetStatistics(False, True)
    ds = None
    return lo, hi


def _lamax(path):
    bands, _, _, _, nodata = read_raster(path)
    return bands[0][bands[0] != nodata]


def test_a_grid_written_over_an_earlier_one_reports_its_own_statistics(plugin, flight_csv, tmp_path):
    """The first grid's statistics are cached beside it (as gdalinfo -stats or QGIS's layer properties do);
    the second run to the same path must not leave them to describe the new grid."""
    import processing

    grid = tmp_path / "grid.tif"
    # the delivery route (its ground stated in the file), then a quieter flight
    for n, (trajectory, ground) in enumerate(((ROUTE, None), (flight_csv, MAP_OPTIONS["GROUND_HEIGHT"]))):
        processing.run("gisnoise:noisemap", {
            "TRAJECTORY_FILE": str(trajectory), "CARDS": DEMO, **MAP_OPTIONS, "GROUND_HEIGHT": ground,
            "OUTPUT_RASTER": str(grid), "OUTPUT_BANDS": str(tmp_path / f"bands{n}.gpkg")})
        if n == 0:
            first = _lamax(grid)
            _statistics(grid)
            assert (tmp_path / "grid.tif.aux.xml").is_file()
    second = _lamax(grid)
    assert second.max() < first.max() - 10.0  # another map
    assert _statistics(grid) == pytest.approx((float(second.min()), float(second.max())), abs=1e-4)


def test_a_one_band_format_takes_one_metric_and_says_so_for_three(plugin, flight_csv, tmp_path):
    """An Arc/Info ASCII grid holds one band: with the three metrics the refusal says so and names METRICS; with
    METRICS LAmax alone the grid is written, equal to the GeoTIFF's LAmax band."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "three", TRAJECTORY_FILE=str(flight_csv), OUTPUT_RASTER=str(tmp_path / "three" / "g.asc"))
    msg = str(err.value)
    assert "1 band" in msg and "3 bands (LAmax, LAeq, SEL)" in msg and "METRICS" in msg and "OUTPUT_RASTER" in msg
    res = run_map(tmp_path, "one", TRAJECTORY_FILE=str(flight_csv), METRICS=[0], CONTOUR_METRICS=[0],
                  OUTPUT_RASTER=str(tmp_path / "one" / "g.asc"))
    tif = run_map(tmp_path, "tif", TRAJECTORY_FILE=str(flight_csv), METRICS=[0])["OUTPUT_RASTER"]
    asc, _, gt_asc, _, nd_asc = read_raster(res["OUTPUT_RASTER"])
    ref, _, gt_ref, _, nd_ref = read_raster(tif)
    assert asc.shape == ref.shape == (1, *ref.shape[1:])
    np.testing.assert_allclose(gt_asc, gt_ref, atol=1e-6)
    valid = ref[0] != nd_ref
    assert np.array_equal(asc[0] != nd_asc, valid)
    np.testing.assert_allclose(asc[0][valid], ref[0][valid], atol=1e-3)  # text with the precision AAIGrid writes
