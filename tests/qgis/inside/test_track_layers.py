"""Flown-track layers whose fields are not named as the flight CSV's, read with the field parameters' defaults.

The flight of conftest (31 samples, 30 s, level at 140 m ellipsoidal) as a layer: the map must be the
flight CSV's map, or the algorithm must say which field parameters to set, all at once; a layer with
the fields of a flown track is never flown as a waypoint plan (the vehicle model's own speed and
timing) without being asked.
"""

import pytest
from conftest import assert_same_raster, recording_feedback, run_map, write_csv

pytestmark = pytest.mark.qgis

#: The analyst's names of the flight CSV's columns.
RENAMED = {"t": "time", "h": "altitude", "roll": "roll", "pitch": "pitch", "yaw": "yaw", "power_w": "power",
           "phase": "phase"}


def _point_layer(flight, columns, *, z=True, name="flight log"):
    """Points in EPSG:4326 (Z = the height when ``z``), one field per entry of ``columns`` (CSV column -> field)."""
    from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsPoint, QgsVectorLayer
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer(f"{'PointZ' if z else 'Point'}?crs=EPSG:4326", name, "memory")
    layer.dataProvider().addAttributes([QgsField(f, QVariant.String if c == "phase" else QVariant.Double)
                                        for c, f in columns.items()])
    layer.updateFields()
    feats = []
    for i in range(len(flight["t"])):
        f = QgsFeature(layer.fields())
        point = QgsPoint(flight["lon"][i], flight["lat"][i], flight["h"][i]) if z else QgsPoint(
            flight["lon"][i], flight["lat"][i])
        f.setGeometry(QgsGeometry(point))
        f.setAttributes([flight[c][i] for c in columns])
        feats.append(f)
    assert layer.dataProvider().addFeatures(feats)[0]
    return layer


def _line_layer(flight, columns):
    """One LineStringZM (Z = height, M = time) with the feature fields ``columns`` (CSV column -> field)."""
    from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsLineString, QgsPoint, QgsVectorLayer, QgsWkbTypes
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("LineStringZM?crs=EPSG:4326", "route", "memory")
    layer.dataProvider().addAttributes([QgsField(f, QVariant.String if c == "phase" else QVariant.Double)
                                        for c, f in columns.items()])
    layer.updateFields()
    line = QgsLineString([QgsPoint(flight["lon"][i], flight["lat"][i], flight["h"][i], flight["t"][i],
                                   QgsWkbTypes.PointZM) for i in range(len(flight["t"]))])
    f = QgsFeature(layer.fields())
    f.setGeometry(QgsGeometry(line))
    f.setAttributes([flight[c][0] for c in columns])
    assert layer.dataProvider().addFeatures([f])[0]
    return layer


@pytest.mark.parametrize("z", [True, False])
def test_a_track_layer_with_a_time_field_of_another_name_is_not_flown_as_waypoints(plugin, flight, tmp_path, z):
    """Defaults everywhere ("auto", TIME_FIELD t): refused in one message naming each field parameter to set and
    the layer's field that looks like it, and TRAJECTORY_KIND; nothing written."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY=_point_layer(flight, RENAMED, z=z))
    msg = str(err.value)
    assert "\n" not in msg
    assert "no time field 't' (parameter TIME_FIELD; the layer has 'time'" in msg
    assert "no electric power field 'power_w' (parameter POWER_FIELD; the layer has 'power'" in msg
    assert "the layer has 'altitude'" in msg and "ALTITUDE_FIELD" in msg
    assert "TRAJECTORY_KIND" in msg and "WAYPOINT_ALT_FIELD" not in msg
    assert not (tmp_path / "map" / "grid.tif").exists()


def test_the_track_layer_with_its_fields_named_gives_the_csv_map(csv_map, flight, tmp_path):
    said = recording_feedback()
    import processing
    from conftest import CARD, MAP_OPTIONS

    (tmp_path / "named").mkdir()
    res = processing.run("gisnoise:noisemap", {
        "TRAJECTORY": _point_layer(flight, RENAMED), "TIME_FIELD": "time", "ALTITUDE_FIELD": "altitude",
        "POWER_FIELD": "power", "CARDS": [CARD], **MAP_OPTIONS, "CONTOUR_METRICS": [0, 1, 2],
        "OUTPUT_RASTER": str(tmp_path / "named" / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "named" / "b.gpkg")},
        feedback=said)
    assert "trajectory: 31 samples over 30.0 s; cards: demo-horizontal" in said.infos
    assert_same_raster(res["OUTPUT_RASTER"], csv_map["OUTPUT_RASTER"], atol=1e-6)


def test_a_line_layer_with_z_and_m_maps_with_the_default_field_names(csv_map, flight, tmp_path):
    """Time from M, height from Z, yaw along the line: the parameters' default names (t, h, yaw), which the layer
    lacks, need not be cleared; the log says what was taken instead."""
    said = recording_feedback()
    import processing
    from conftest import CARD, MAP_OPTIONS

    (tmp_path / "line").mkdir()
    res = processing.run("gisnoise:noisemap", {
        "TRAJECTORY": _line_layer(flight, {c: c for c in ("roll", "pitch", "power_w", "phase")}), "CARDS": [CARD],
        **MAP_OPTIONS, "CONTOUR_METRICS": [0, 1, 2], "OUTPUT_RASTER": str(tmp_path / "line" / "grid.tif"),
        "OUTPUT_BANDS": str(tmp_path / "line" / "b.gpkg")}, feedback=said)
    # yaw from the track: the geodesic due east turns by 0.007 deg over 600 m at 52 N
    assert_same_raster(res["OUTPUT_RASTER"], csv_map["OUTPUT_RASTER"], atol=0.01)
    assert any("ALTITUDE_FIELD" in i and "Z" in i for i in said.infos)
    assert any("YAW_FIELD" in i and "along the line" in i for i in said.infos)


def test_a_line_layer_without_attitude_fields_flies_level(plugin, flight, tmp_path):
    """No roll or pitch field and the defaults roll, pitch: 0 deg, said; the map of the same flight with pitch 0."""
    said = recording_feedback()
    import processing
    from conftest import CARD, MAP_OPTIONS

    level = {**flight, "pitch": [0.0] * len(flight["t"])}
    ref = run_map(tmp_path, "ref", TRAJECTORY_FILE=str(write_csv(tmp_path / "level.csv", level)))
    (tmp_path / "line").mkdir()
    res = processing.run("gisnoise:noisemap", {
        "TRAJECTORY": _line_layer(flight, {"power_w": "power_w"}), "CARDS": [CARD], **MAP_OPTIONS,
        "OUTPUT_RASTER": str(tmp_path / "line" / "grid.tif"), "OUTPUT_BANDS": str(tmp_path / "line" / "b.gpkg")},
        feedback=said)
    assert_same_raster(res["OUTPUT_RASTER"], ref["OUTPUT_RASTER"], atol=0.01)
    for param in ("ROLL_FIELD", "PITCH_FIELD"):
        assert any(param in i and "0 deg" in i for i in said.infos), param


def test_every_field_parameter_that_does_not_fit_is_named_at_once(plugin, flight, tmp_path):
    """A flown track (TRAJECTORY_KIND 1) with its time field named: power and yaw fields of other names are
    both named, with the layer's fields that look like them."""
    from qgis.core import QgsProcessingException

    layer = _point_layer(flight, {"t": "time_s", "yaw": "heading", "power_w": "watts"})
    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY=layer, TRAJECTORY_KIND=1, TIME_FIELD="time_s")
    msg = str(err.value)
    assert "no yaw field 'yaw' (parameter YAW_FIELD; the layer has 'heading'" in msg
    assert "no electric power field 'power_w' (parameter POWER_FIELD; the layer has 'watts'" in msg


def test_a_time_field_with_a_repeated_time_is_named_as_the_users(plugin, flight, tmp_path):
    """The core's check of the times names its own column 't'; the message names the layer's field, its parameter
    and the feature."""
    from qgis.core import QgsProcessingException

    repeated = {**flight, "t": [5.0 if i == 6 else t for i, t in enumerate(flight["t"])]}  # samples 5 and 6 at 5 s
    layer = _point_layer(repeated, RENAMED)
    with pytest.raises(QgsProcessingException) as err:
        run_map(tmp_path, "map", TRAJECTORY=layer, TIME_FIELD="time", ALTITUDE_FIELD="altitude",
                POWER_FIELD="power")
    msg = str(err.value)
    assert "field 'time' (parameter TIME_FIELD) is not strictly increasing" in msg
    assert "field 't'" not in msg
    fids = sorted(f.id() for f in layer.getFeatures() if f["time"] == 5.0)
    assert any(f"(feature {fid})" in msg for fid in fids)
