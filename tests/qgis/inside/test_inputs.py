"""Trajectory inputs of the noise map in QGIS: waypoint layers (points, lines) and flight logs.

A waypoint layer is flown by the core's vehicle model exactly as the same waypoints in a
file (``gisnoise contour route.geojson``); a PX4 log goes through the core's one reader, as
on the command line.
"""

import json
import os
import shutil

import numpy as np
import pytest
from conftest import CARDS, H_GROUND, LAT0, LON0, REPO, assert_same_raster

pytestmark = pytest.mark.qgis

DEMO = [str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]
OPTIONS = {"RESOLUTION": 25.0, "MARGIN": 150.0, "LEVELS": "50,55,60,65"}
CLI = ("--resolution", "25", "--margin", "150", "--levels", "50,55,60,65", "--engine", "numpy")
#: Vertical take-off to 40 m, 600 m east at 15 m/s (the last leg at 12 m/s), vertical landing; altitudes AGL.
WAYPOINTS = [(0.0, 0.0, 0.0, None), (0.0, 0.0, 40.0, None), (300.0, 80.0, 40.0, 15.0), (600.0, 0.0, 40.0, 12.0),
             (600.0, 0.0, 0.0, None)]


def _lonlat(e, n):
    from pyproj import Geod

    geod = Geod(ellps="WGS84")
    lon, lat, _ = geod.fwd(LON0, LAT0, 90.0, e)
    lon, lat, _ = geod.fwd(lon, lat, 0.0, n)
    return lon, lat


@pytest.fixture(scope="module")
def waypoints_file(tmp_path_factory):
    feats = []
    for e, n, alt, speed in WAYPOINTS:
        lon, lat = _lonlat(e, n)
        props = {"alt": alt} if speed is None else {"alt": alt, "speed": speed}
        feats.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [lon, lat, alt]},
                      "properties": props})
    path = tmp_path_factory.mktemp("wp") / "route.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "route": {"altitude_reference": "agl",
                                                                       "ground_h_m": H_GROUND},
                                "features": feats}))
    return path


def _run(tmp_path, name, **params):
    import processing

    out = tmp_path / name
    out.mkdir()
    return processing.run("gisnoise:noisemap", {
        "CARDS": DEMO, **OPTIONS, "OUTPUT_RASTER": str(out / "grid.tif"), "OUTPUT_BANDS": str(out / "bands.gpkg"),
        **params})


@pytest.fixture(scope="module")
def file_map(plugin, waypoints_file, tmp_path_factory):
    return _run(tmp_path_factory.mktemp("wpfile"), "map", TRAJECTORY_FILE=str(waypoints_file),
                GROUND_HEIGHT=H_GROUND)


def test_waypoints_file_gives_the_command_line_map(file_map, waypoints_file, cli, tmp_path):
    cli("contour", waypoints_file, *sum((["--card", c] for c in DEMO), []), "--out", tmp_path / "cli", *CLI)
    assert_same_raster(file_map["OUTPUT_RASTER"], tmp_path / "cli" / "levels.tif", atol=1e-4)


def test_point_layer_of_waypoints_is_flown_like_the_file(plugin, file_map, tmp_path):
    """Points in Web Mercator, fields alt and speed, in a shuffled feature order put right by a seq field."""
    from qgis.core import (
        QgsCoordinateReferenceSystem,
        QgsCoordinateTransform,
        QgsFeature,
        QgsField,
        QgsGeometry,
        QgsPointXY,
        QgsProject,
        QgsVectorLayer,
    )
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("Point?crs=EPSG:3857", "waypoints", "memory")
    layer.dataProvider().addAttributes([QgsField("seq", QVariant.Int), QgsField("alt", QVariant.Double),
                                        QgsField("speed", QVariant.Double)])
    layer.updateFields()
    xform = QgsCoordinateTransform(QgsCoordinateReferenceSystem("EPSG:4326"), layer.crs(), QgsProject.instance())
    feats = []
    for i in (3, 0, 4, 1, 2):
        e, n, alt, speed = WAYPOINTS[i]
        f = QgsFeature(layer.fields())
        f.setGeometry(QgsGeometry.fromPointXY(xform.transform(QgsPointXY(*_lonlat(e, n)))))
        f.setAttributes([i, alt, speed])  # a NULL speed: the cruise speed, as a waypoint without one
        feats.append(f)
    assert layer.dataProvider().addFeatures(feats)[0]
    res = _run(tmp_path, "points", TRAJECTORY=layer, GROUND_HEIGHT=H_GROUND)
    # lon/lat through Web Mercator and back: sub-millimetre, far below a hundredth of a decibel
    assert_same_raster(res["OUTPUT_RASTER"], file_map["OUTPUT_RASTER"], atol=1e-3)


def test_line_layer_of_waypoints_with_z_is_flown_like_the_points(plugin, tmp_path, waypoints_file):
    """A LineString Z without M: its vertices are the waypoints, the feature's speed every leg's."""
    from qgis.core import QgsFeature, QgsField, QgsGeometry, QgsLineString, QgsPoint, QgsVectorLayer
    from qgis.PyQt.QtCore import QVariant

    layer = QgsVectorLayer("LineStringZ?crs=EPSG:4326", "plan", "memory")
    layer.dataProvider().addAttributes([QgsField("speed", QVariant.Double)])
    layer.updateFields()
    f = QgsFeature(layer.fields())
    f.setGeometry(QgsGeometry(QgsLineString([QgsPoint(*_lonlat(e, n), alt) for e, n, alt, _ in WAYPOINTS])))
    f.setAttributes([15.0])
    assert layer.dataProvider().addFeatures([f])[0]
    res = _run(tmp_path, "line", TRAJECTORY=layer, GROUND_HEIGHT=H_GROUND)
    doc = json.loads(waypoints_file.read_text())
    for feat in doc["features"]:
        feat["properties"]["speed"] = 15.0
    same = tmp_path / "same.geojson"
    same.write_text(json.dumps(doc))
    ref = _run(tmp_path, "ref", TRAJECTORY_FILE=str(same), GROUND_HEIGHT=H_GROUND)
    assert_same_raster(res["OUTPUT_RASTER"], ref["OUTPUT_RASTER"], atol=1e-6)


def test_a_waypoint_layer_without_altitude_names_the_field(plugin, tmp_path):
    from qgis.core import QgsFeature, QgsGeometry, QgsPointXY, QgsProcessingException, QgsVectorLayer

    layer = QgsVectorLayer("Point?crs=EPSG:4326", "flat", "memory")
    f = QgsFeature(layer.fields())
    f.setGeometry(QgsGeometry.fromPointXY(QgsPointXY(LON0, LAT0)))
    layer.dataProvider().addFeatures([f])
    with pytest.raises(QgsProcessingException, match="WAYPOINT_ALT_FIELD"):
        _run(tmp_path, "noalt", TRAJECTORY=layer, GROUND_HEIGHT=H_GROUND)


LOGS = REPO / "tests" / "data"


@pytest.fixture(scope="module")
def omni_card(tmp_path_factory):
    """An omnidirectional card: 65 dB(A) at 40 m and 300 W, +10 dB per decade of power (as the CLI's log tests)."""
    from gisnoise.model import ModelCard, save

    card = ModelCard(id="omni", vehicle="test", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=65.0, p1=10.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=300.0, phases=("horizontal", "climb", "sink", "transition"))
    return str(save(card, tmp_path_factory.mktemp("card") / "omni.json"))


def test_px4_log_file_gives_the_command_line_map(plugin, omni_card, cli, tmp_path):
    log = tmp_path / "vtol.ULG"  # any letter case, as some autopilots write it
    shutil.copy(LOGS / "pyulog_sample_log_small_vtol.ulg", log)
    res = _run(tmp_path, "log", TRAJECTORY_FILE=str(log), CARDS=[omni_card], RESOLUTION=20.0, MARGIN=100.0)
    cli("contour", log, "--card", omni_card, "--out", tmp_path / "cli", "--resolution", "20", "--margin", "100",
        "--levels", OPTIONS["LEVELS"], "--engine", "numpy")
    assert_same_raster(res["OUTPUT_RASTER"], tmp_path / "cli" / "levels.tif", atol=1e-4)


def test_quad_log_maps_from_its_battery_charge_and_power_w_overrides_it(plugin, omni_card, cli, tmp_path):
    """The quad's power comes from the battery's charge count, as on the command line; POWER_W replaces it."""
    log = str(LOGS / "robologs_test_quad_fmuv5.ulg")
    common = ["--card", omni_card, "--resolution", "20", "--margin", "100", "--levels", OPTIONS["LEVELS"],
              "--engine", "numpy"]
    res = _run(tmp_path, "own", TRAJECTORY_FILE=log, CARDS=[omni_card], RESOLUTION=20.0, MARGIN=100.0)
    cli("contour", log, *common, "--out", tmp_path / "cli-own")
    assert_same_raster(res["OUTPUT_RASTER"], tmp_path / "cli-own" / "levels.tif", atol=1e-4)
    res = _run(tmp_path, "power", TRAJECTORY_FILE=log, CARDS=[omni_card], RESOLUTION=20.0, MARGIN=100.0,
               POWER_W=150.0)
    cli("contour", log, *common, "--power-w", "150", "--out", tmp_path / "cli-power")
    assert_same_raster(res["OUTPUT_RASTER"], tmp_path / "cli-power" / "levels.tif", atol=1e-4)


def test_a_track_without_current_in_flight_needs_the_constant_power(plugin, omni_card, tmp_path):
    from qgis.core import QgsProcessingException

    from gisnoise.flight import read_route

    tr = read_route(LOGS / "pyulog_sample_log_small_vtol.ulg").trajectory
    csv = tmp_path / "no_current.csv"
    tr.with_(power_w=np.zeros(len(tr))).to_csv(csv)
    with pytest.raises(QgsProcessingException, match="power[_-]w"):
        _run(tmp_path, "nopower", TRAJECTORY_FILE=str(csv), CARDS=[omni_card], RESOLUTION=20.0, MARGIN=100.0,
             GROUND_HEIGHT=float(tr.h.min()))


def test_an_ardupilot_log_without_pymavlink_says_how_to_install_it(plugin, omni_card, tmp_path):
    """Per platform; on Linux a pip command this Python's pip accepts: Debian 12 marks its Python as managed by
    the system (PEP 668), where pip refuses even --user without --break-system-packages (and apt has no
    python3-pymavlink).  The advised command is run by pip with --dry-run --no-index: refused or not, nothing
    is installed."""
    import importlib.util
    import re
    import sysconfig

    from conftest import pip_output
    from qgis.core import QgsProcessingException

    params = {"TRAJECTORY_FILE": str(LOGS / "dronekit_la_testdata_log171_copter.bin"), "CARDS": [omni_card],
              "GEOID_UNDULATION": 22.0, "RESOLUTION": 20.0, "MARGIN": 100.0}
    if importlib.util.find_spec("pymavlink") is not None:  # this QGIS has it: the log maps
        assert _run(tmp_path, "bin", **params)["OUTPUT_RASTER"]
        return
    with pytest.raises(QgsProcessingException) as err:
        _run(tmp_path, "bin", **params)
    msg = str(err.value)
    assert msg.startswith("reading an ArduPilot .bin log needs pymavlink in QGIS's Python")
    assert "OSGeo4W Shell" in msg and "QGIS.app" in msg and "TRAJECTORY_FILE" in msg
    assert "apt install" not in msg
    linux = re.search(r"Linux: (python3 -m pip install [^(;]*?)(?: \(|;)", msg).group(1)
    managed = os.path.isfile(os.path.join(sysconfig.get_path("stdlib"), "EXTERNALLY-MANAGED"))
    assert ("--break-system-packages" in linux) == managed and "--user" in linux
    if importlib.util.find_spec("pip") is not None:
        said = pip_output(linux)
        assert "externally-managed-environment" not in said
        assert "pymavlink" in said  # pip went on to look for it
