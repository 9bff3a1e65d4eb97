"""``qgis_process run`` with the plugin installed from the built zip into a fresh profile."""

import json
import os
import shutil
import subprocess
import zipfile

import pytest
from conftest import CARD, MAP_OPTIONS, assert_same_raster

pytestmark = pytest.mark.qgis


def qgis_process():
    # Debian's /usr/bin/qgis_process wrapper passes --noversioncheck, which qgis_process 3.22 rejects;
    # the binary next to it is the real command.
    for name in ("qgis_process.bin", "qgis_process"):
        exe = shutil.which(name)
        if exe:
            return exe
    pytest.fail("no qgis_process command")


@pytest.fixture(scope="module")
def fresh_settings(tmp_path_factory, plugin_zip):
    """A QGIS settings folder that has never seen the plugin, then the plugin unzipped and enabled."""
    root = tmp_path_factory.mktemp("qgis_process_settings")
    plugins = root / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    runtime = root / "xdg"
    runtime.mkdir(mode=0o700)
    env = {**os.environ, "QGIS_CUSTOM_CONFIG_PATH": str(root), "QT_QPA_PLATFORM": "offscreen",
           "XDG_RUNTIME_DIR": str(runtime)}
    with zipfile.ZipFile(plugin_zip) as zf:
        zf.extractall(plugins)
    r = subprocess.run([qgis_process(), "plugins", "enable", "gisnoise_qgis"], env=env, capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return env


def test_qgis_process_runs_the_noise_map(fresh_settings, flight_csv, csv_map, tmp_path):
    out = tmp_path / "out"
    args = [f"TRAJECTORY_FILE={flight_csv}", f"CARDS={CARD}"]
    args += [f"{k}={v}" for k, v in MAP_OPTIONS.items()]
    args += [f"OUTPUT_RASTER={out / 'grid.tif'}", f"OUTPUT_BANDS={out / 'bands.gpkg'}"]
    r = subprocess.run([qgis_process(), "--json", "run", "gisnoise:noisemap", "--", *args], env=fresh_settings,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    results = json.loads(r.stdout)["results"]
    assert results["OUTPUT_RASTER"] == str(out / "grid.tif")
    # the same map as processing.run in this QGIS (and so as the command line)
    assert_same_raster(results["OUTPUT_RASTER"], csv_map["OUTPUT_RASTER"], atol=1e-9)
    assert (out / "bands.gpkg").is_file()


def test_qgis_process_outputs_open_styled_in_a_fresh_project(plugin, fresh_settings, flight_csv, tmp_path):
    """Loaded from files alone (no post-processor ran): the noise palette, labels, grid CRS, track."""
    from qgis.core import QgsProject, QgsRasterLayer, QgsVectorLayer

    out = tmp_path / "out"
    args = [f"TRAJECTORY_FILE={flight_csv}", f"CARDS={CARD}"]
    args += [f"{k}={v}" for k, v in MAP_OPTIONS.items()]
    args += [f"OUTPUT_RASTER={out / 'grid.tif'}", f"OUTPUT_BANDS={out / 'bands.gpkg'}",
             f"OUTPUT_LINES={out / 'lines.gpkg'}", f"OUTPUT_TRACK={out / 'track.gpkg'}"]
    r = subprocess.run([qgis_process(), "--json", "run", "gisnoise:noisemap", "--", *args], env=fresh_settings,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    from gisnoise.maps import class_colours

    levels = [float(v) for v in MAP_OPTIONS["LEVELS"].split(",")]
    colours = class_colours(levels)
    project = QgsProject.instance()
    project.clear()
    raster = QgsRasterLayer(str(out / "grid.tif"), "grid", "gdal")
    project.addMapLayer(raster)
    assert raster.renderer().type() == "singlebandpseudocolor"
    items = raster.renderer().shader().rasterShaderFunction().colorRampItemList()
    assert [i.color.name().upper() for i in items[1:]] == colours
    assert items[1].label == f"LAmax {levels[0]:g}-{levels[1]:g} dB(A)"
    bands = QgsVectorLayer(str(out / "bands.gpkg"), "bands", "ogr")
    lines = QgsVectorLayer(str(out / "lines.gpkg"), "lines", "ogr")
    track = QgsVectorLayer(str(out / "track.gpkg"), "track", "ogr")
    for lyr in (bands, lines, track):
        assert lyr.isValid()
        project.addMapLayer(lyr)
        assert lyr.crs() == raster.crs()  # everything in the grid's CRS
    assert bands.renderer().type() == "graduatedSymbol"
    assert [rg.symbol().color().name().upper() for rg in bands.renderer().ranges()] == colours
    assert [rg.label() for rg in bands.renderer().ranges()][-1] == f"LAmax >= {levels[-1]:g} dB(A)"
    assert lines.labelsEnabled() and "level" in lines.labeling().settings().fieldName
    assert track.renderer().type() == "categorizedSymbol" and track.featureCount() == 1
    project.clear()


def test_qgis_process_prints_the_warnings_as_warnings(fresh_settings, cli, tmp_path):
    """The command line's three warnings for the delivery route on a 500 m margin, printed by qgis_process as
    WARNING lines; no ERROR line for a run that succeeds."""
    import re

    from conftest import CARDS, REPO

    route = REPO / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
    demo = [str(CARDS / f"demo_{p}.json") for p in ("horizontal", "climb", "sink")]
    r = cli("contour", route, *sum((["--card", c] for c in demo), []), "--resolution", "20", "--margin", "500",
            "--out", tmp_path / "cli")
    expected = [line[len("warning: "):] for line in r.stderr.splitlines() if line.startswith("warning: ")]
    assert len(expected) == 3
    args = [f"TRAJECTORY_FILE={route}", *(f"CARDS={c}" for c in demo), "RESOLUTION=20", "MARGIN=500",
            f"OUTPUT_RASTER={tmp_path / 'grid.tif'}", f"OUTPUT_BANDS={tmp_path / 'bands.gpkg'}"]
    r = subprocess.run([qgis_process(), "run", "gisnoise:noisemap", "--", *args], env=fresh_settings,
                       capture_output=True, text=True, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 0, out[-3000:]
    assert "ERROR" not in out
    warned = re.findall(r"WARNING:\s*(.*)", out)
    assert [w.replace(" (parameter MARGIN)", "") for w in warned] == expected
