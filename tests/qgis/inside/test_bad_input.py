"""Bad input raises QgsProcessingException naming the field, and QGIS keeps running."""

import json

import pytest
from conftest import CARDS, MAP_OPTIONS

pytestmark = pytest.mark.qgis

CARD = str(CARDS / "demo_horizontal.json")


def _point_layer(with_time):
    from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsPoint, QgsVectorLayer
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("PointZ?crs=EPSG:4326", "no time", "memory")
    names = (["t"] if with_time else []) + ["yaw", "power_w"]
    layer.dataProvider().addAttributes([QgsField(k, QVariant.Double) for k in names])
    layer.updateFields()
    feats = []
    for i in range(3):
        f = QgsFeature(layer.fields())
        f.setGeometry(QgsGeometry(QgsPoint(10.56 + 0.0003 * i, 52.313, 140.0)))
        f.setAttributes(([float(i)] if with_time else []) + [90.0, 3000.0])
        feats.append(f)
    layer.dataProvider().addFeatures(feats)
    return layer


def _run(tmp_path, **params):
    import processing

    return processing.run("gisnoise:noisemap", {
        "CARDS": [CARD], **MAP_OPTIONS, "ALTITUDE_FIELD": "", "PHASE_FIELD": "", "ROLL_FIELD": "",
        "PITCH_FIELD": "", "OUTPUT_RASTER": str(tmp_path / "grid.tif"),
        "OUTPUT_BANDS": str(tmp_path / "bands.gpkg"), **params})


def test_layer_without_time_field_names_the_field(plugin, tmp_path):
    """Read as a flown track (TRAJECTORY_KIND 1; by default a layer without time is read as waypoints)."""
    from qgis.core import QgsProcessingException

    with pytest.raises(QgsProcessingException) as err:
        _run(tmp_path, TRAJECTORY=_point_layer(with_time=False), TRAJECTORY_KIND=1)
    msg = str(err.value)
    assert "time field" in msg and "'t'" in msg and "TIME_FIELD" in msg


@pytest.mark.parametrize("content, field", [
    (json.dumps({"type": "FeatureCollection", "features": []}), "schema"),
    ("t,lat,lon\n0,52,10\n", "json"),
])
def test_file_that_is_not_a_card_names_the_field(plugin, tmp_path, content, field):
    from qgis.core import QgsProcessingException

    bad = tmp_path / "not_a_card.json"
    bad.write_text(content, encoding="utf-8")
    with pytest.raises(QgsProcessingException) as err:
        _run(tmp_path, TRAJECTORY=_point_layer(with_time=True), CARDS=[str(bad)])
    msg = str(err.value)
    assert "not_a_card.json" in msg and field in msg


def test_qgis_keeps_running_after_bad_input(plugin, tmp_path):
    """After the failures above the same QGIS still runs the algorithm and a native one."""
    import processing
    from qgis.core import QgsApplication, QgsProcessingException

    with pytest.raises(QgsProcessingException):
        _run(tmp_path / "bad", TRAJECTORY=_point_layer(with_time=False), TRAJECTORY_KIND=1)
    res = _run(tmp_path, TRAJECTORY=_point_layer(with_time=True), RESOLUTION=25.0, MARGIN=100.0)
    assert (tmp_path / "grid.tif").is_file() and res["OUTPUT_BANDS"]
    assert QgsApplication.instance() is not None
    buffered = processing.run("native:buffer", {"INPUT": _point_layer(with_time=True), "DISTANCE": 0.001,
                                                "OUTPUT": "memory:"})["OUTPUT"]
    assert buffered.featureCount() == 3


def _card_variant(tmp_path, name, parameters, **fields):
    doc = json.loads((CARDS / "demo_horizontal.json").read_text(encoding="utf-8"))
    doc.update(id=name, **fields)
    doc["parameters"] = {**doc["parameters"], **parameters}
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    return str(path)


def test_implausible_card_is_refused_naming_p2(plugin, tmp_path):
    from qgis.core import QgsProcessingException

    bad = _card_variant(tmp_path, "wild", {"p2": -2958.0, "p6": 2.01})
    with pytest.raises(QgsProcessingException) as err:
        _run(tmp_path, TRAJECTORY=_point_layer(with_time=True), CARDS=[bad])
    assert "p2" in str(err.value) and not (tmp_path / "grid.tif").exists()


def test_card_without_power_term_at_another_power_names_power_w(plugin, tmp_path):
    """A card fitted at one steady power (p1 held at 0, 2400 W) meets a track flown at 3000 W."""
    from qgis.core import QgsProcessingException

    steady = _card_variant(tmp_path, "steady", {"p1": 0.0}, covariance=None,
                           statistics={"power_range_w": [2400.0, 2400.0]},
                           provenance={"held_parameters": {"p1": "steady power"}})
    with pytest.raises(QgsProcessingException) as err:
        _run(tmp_path, TRAJECTORY=_point_layer(with_time=True), CARDS=[steady])
    assert "power_w" in str(err.value) and "2400" in str(err.value)
