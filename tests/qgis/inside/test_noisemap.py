"""Noise grid and contours through processing.run: the same map as the command line."""

import pytest
from conftest import CARD, CLI_OPTIONS, MAP_OPTIONS, assert_same_raster, bilinear, read_raster, run_map

pytestmark = pytest.mark.qgis

LEVELS = [50.0, 55.0, 60.0, 65.0]



def test_raster_equals_the_command_line(csv_map, cli, flight_csv, tmp_path):
    cli("contour", flight_csv, "--card", CARD, "--out", tmp_path / "cli", *CLI_OPTIONS)
    # same input, same core; only numpy/scipy versions differ between QGIS's Python and the project's
    assert_same_raster(csv_map["OUTPUT_RASTER"], tmp_path / "cli" / "levels.tif", atol=1e-4)


def test_point_layer_in_another_crs_gives_the_csv_map(csv_map, flight, tmp_path):
    from qgis.core import (
        QgsCoordinateReferenceSystem,
        QgsCoordinateTransform,
        QgsFeature,
        QgsField,
        QgsGeometry,
        QgsPoint,
        QgsProject,
        QgsVectorLayer,
    )
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("PointZ?crs=EPSG:3857", "flight", "memory")
    fields = [QgsField(k, QVariant.Double) for k in ("time_s", "roll", "pitch", "yaw", "power_w")]
    layer.dataProvider().addAttributes(fields + [QgsField("phase", QVariant.String)])
    layer.updateFields()
    xform = QgsCoordinateTransform(QgsCoordinateReferenceSystem("EPSG:4326"), layer.crs(), QgsProject.instance())
    feats = []
    for i in reversed(range(len(flight["t"]))):  # any feature order: the algorithm sorts by time
        p = xform.transform(flight["lon"][i], flight["lat"][i])
        f = QgsFeature(layer.fields())
        f.setGeometry(QgsGeometry(QgsPoint(p.x(), p.y(), flight["h"][i])))
        f.setAttributes([flight["t"][i], flight["roll"][i], flight["pitch"][i], flight["yaw"][i],
                         flight["power_w"][i], flight["phase"][i]])
        feats.append(f)
    assert layer.dataProvider().addFeatures(feats)[0]
    res = run_map(tmp_path, "points", TRAJECTORY=layer, TIME_FIELD="time_s", ALTITUDE_FIELD="")
    # lon/lat through Web Mercator and back: sub-millimetre, far below a hundredth of a decibel
    assert_same_raster(res["OUTPUT_RASTER"], csv_map["OUTPUT_RASTER"], atol=1e-3)


def test_line_layer_with_time_in_m_gives_the_csv_map(csv_map, flight, tmp_path):
    from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsLineString, QgsPoint, QgsVectorLayer, QgsWkbTypes
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("LineStringZM?crs=EPSG:4326", "route", "memory")
    layer.dataProvider().addAttributes([QgsField("roll", QVariant.Double), QgsField("pitch", QVariant.Double),
                                        QgsField("power_w", QVariant.Double), QgsField("phase", QVariant.String)])
    layer.updateFields()
    line = QgsLineString([QgsPoint(flight["lon"][i], flight["lat"][i], flight["h"][i], flight["t"][i],
                                   QgsWkbTypes.PointZM) for i in range(len(flight["t"]))])
    f = QgsFeature(layer.fields())
    f.setGeometry(QgsGeometry(line))
    f.setAttributes([0.0, 2.0, 3000.0, "horizontal"])
    assert layer.dataProvider().addFeatures([f])[0]
    res = run_map(tmp_path, "line", TRAJECTORY=layer, TIME_FIELD="", ALTITUDE_FIELD="", YAW_FIELD="",
                  ROLL_FIELD="roll", PITCH_FIELD="pitch")
    # yaw from the track: the geodesic due east turns by 0.007 deg over 600 m at 52 N
    assert_same_raster(res["OUTPUT_RASTER"], csv_map["OUTPUT_RASTER"], atol=0.01)


def _features(path):
    from qgis.core import QgsVectorLayer

    layer = QgsVectorLayer(str(path), "c", "ogr")
    assert layer.isValid(), path
    return layer, list(layer.getFeatures())


def test_contours_carry_metric_and_level_and_follow_the_raster(csv_map):
    from qgis.core import QgsCoordinateReferenceSystem, QgsCoordinateTransform, QgsProject

    grid, names, gt, wkt, nodata = read_raster(csv_map["OUTPUT_RASTER"])
    bands_layer, bands = _features(csv_map["OUTPUT_BANDS"])
    lines_layer, lines = _features(csv_map["OUTPUT_LINES"])
    # contours in the grid's CRS (the GeoJSON of the web stays in WGS84)
    assert bands_layer.crs() == lines_layer.crs() == QgsCoordinateReferenceSystem.fromWkt(wkt)
    assert bands_layer.crs().authid() == "EPSG:32632"
    assert {f["metric"] for f in bands} == set(names)
    from gisnoise.maps import metric_levels

    for f in bands + lines:  # SEL's contours lie 10 dB above the map's levels
        assert f["metric"] in names and f["level"] in metric_levels(f["metric"], LEVELS)
    assert {f["kind"] for f in bands} == {"isoband"} and {f["kind"] for f in lines} == {"isoline"}
    xform = QgsCoordinateTransform(lines_layer.crs(), QgsCoordinateReferenceSystem.fromWkt(wkt),
                                   QgsProject.instance())
    for metric_i, metric in enumerate(names):
        band = grid[metric_i]
        valid = band[band != nodata]
        # an isoline of level L exists exactly when the map spans L
        expected = {lv for lv in metric_levels(metric, LEVELS) if valid.min() < lv < valid.max()}
        got = {f["level"] for f in lines if f["metric"] == metric}
        assert got == expected, metric
        for f in lines:
            if f["metric"] != metric:
                continue
            for v in f.geometry().vertices():
                p = xform.transform(v.x(), v.y())
                # vertices lie on cell-centre edges, where the grid interpolates linearly
                assert bilinear(band, gt, p.x(), p.y()) == pytest.approx(f["level"], abs=0.02)


def test_loaded_outputs_are_styled_by_level(plugin, flight_csv, tmp_path):
    import processing
    from qgis.core import QgsProject

    res = processing.runAndLoadResults("gisnoise:noisemap", {
        "TRAJECTORY_FILE": str(flight_csv), "CARDS": [CARD], **MAP_OPTIONS,
        "OUTPUT_RASTER": str(tmp_path / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "bands.gpkg"),
        "OUTPUT_LINES": str(tmp_path / "lines.gpkg"), "OUTPUT_TRACK": str(tmp_path / "track.gpkg")})
    project = QgsProject.instance()
    raster = project.mapLayer(res["OUTPUT_RASTER"]) or project.mapLayersByName("noise grid (LAmax)")[0]
    assert raster.renderer().type() == "singlebandpseudocolor"
    shader = raster.renderer().shader().rasterShaderFunction()
    assert [round(i.value, 6) for i in shader.colorRampItemList()] == [50.0, 55.0, 60.0, 65.0, float("inf")]
    vectors = [lyr for lyr in project.mapLayers().values() if lyr.type() == lyr.VectorLayer]
    tracks = [lyr for lyr in vectors if lyr.fields().indexOf("phase") >= 0]
    assert len(tracks) == 1 and tracks[0].renderer().type() == "categorizedSymbol"
    assert [f["phase"] for f in tracks[0].getFeatures()] == ["horizontal"]
    vectors = [lyr for lyr in vectors if lyr.id() != tracks[0].id()]
    assert len(vectors) == 2
    for lyr in vectors:
        assert {f["metric"] for f in lyr.getFeatures()} == {"LAmax"}  # the default: LAmax contours only
        renderer = lyr.renderer()
        assert renderer.type() == "graduatedSymbol"
        assert renderer.classAttribute() == "level"
        assert [r.lowerValue() for r in renderer.ranges()] == LEVELS
    project.removeAllMapLayers()


def test_progress_reaches_the_end_and_cancel_stops(plugin, flight_csv, tmp_path):
    import processing
    from qgis.core import QgsProcessingException, QgsProcessingFeedback

    feedback = QgsProcessingFeedback()
    seen = []
    feedback.progressChanged.connect(seen.append)
    processing.run("gisnoise:noisemap", {
        "TRAJECTORY_FILE": str(flight_csv), "CARDS": [CARD], **MAP_OPTIONS,
        "OUTPUT_RASTER": str(tmp_path / "p.tif"), "OUTPUT_BANDS": str(tmp_path / "p.gpkg")}, feedback=feedback)
    assert seen and seen == sorted(seen) and seen[-1] == pytest.approx(100.0)

    cancelled = QgsProcessingFeedback()
    cancelled.cancel()
    with pytest.raises(QgsProcessingException, match="cancelled"):
        processing.run("gisnoise:noisemap", {
            "TRAJECTORY_FILE": str(flight_csv), "CARDS": [CARD], **MAP_OPTIONS,
            "OUTPUT_RASTER": str(tmp_path / "c.tif"), "OUTPUT_BANDS": str(tmp_path / "c.gpkg")}, feedback=cancelled)
    assert not (tmp_path / "c.tif").exists()


def test_uncertainty_bands_equal_the_command_line(plugin, cli, flight_csv, tmp_path):
    # the delta-method bands in QGIS (the bundled core, no numba: the NumPy engine) and on the command line
    # (the fast engine by default): the same bands, the same values
    import numpy as np

    cli("contour", flight_csv, "--card", CARD, "--out", tmp_path / "cli", "--uncertainty", *CLI_OPTIONS)
    res = run_map(tmp_path, "qgis", TRAJECTORY_FILE=str(flight_csv), UNCERTAINTY=True)
    a, names_a, *_, nd_a = read_raster(res["OUTPUT_RASTER"])
    b, names_b, *_, nd_b = read_raster(tmp_path / "cli" / "levels.tif")
    assert names_a == names_b and {"LAmax_std", "LAeq_std", "LAmax_p95"} <= set(names_a)
    valid = (a != nd_a) & (b != nd_b)
    assert valid.mean() > 0.9
    for i, name in enumerate(names_a):  # LAmax_std too: where instants tie both take the rule of tie_std
        np.testing.assert_allclose(a[i][valid[i]], b[i][valid[i]], rtol=0, atol=1e-3, err_msg=name)
    std = a[names_a.index("LAeq_std")][valid[0]]
    assert std.max() > 0.05  # a map where the uncertainty shows (the demo card: up to 0.085 dB here)
