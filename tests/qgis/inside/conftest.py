"""A headless QGIS with the plugin installed from the built zip into a fresh profile.

Runs in QGIS's own Python (started by tests/qgis/test_qgis_plugin.py).  The
session builds the zip with scripts/build-plugin, unzips it into a new profile
folder, starts QGIS offscreen with that profile, initialises Processing and
registers the provider through the plugin's own ``classFactory``.
"""

import csv
import math
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(os.environ.get("GISNOISE_REPO") or Path(__file__).resolve().parents[3])
CARDS = REPO / "gisnoise" / "data" / "cards"
PLUGIN = "gisnoise_qgis"

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


@pytest.fixture(scope="session")
def plugin_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "build-plugin"), "--out", str(out)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    return Path(r.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def profile(tmp_path_factory, plugin_zip):
    """A fresh QGIS settings folder whose default profile has the plugin installed from the zip."""
    root = tmp_path_factory.mktemp("qgis_settings")
    plugins = root / "profiles" / "default" / "python" / "plugins"
    plugins.mkdir(parents=True)
    with zipfile.ZipFile(plugin_zip) as zf:
        zf.extractall(plugins)
    return root


@pytest.fixture(scope="session")
def qgis_app(profile):
    from qgis.core import QgsApplication

    QgsApplication.setPrefixPath("/usr", True)
    app = QgsApplication([], False, str(profile / "profiles" / "default"))
    app.initQgis()
    plugins = os.path.join(QgsApplication.pkgDataPath(), "python", "plugins")
    if plugins not in sys.path:
        sys.path.append(plugins)
    from processing.core.Processing import Processing

    Processing.initialize()
    yield app


@pytest.fixture(scope="session")
def plugin(qgis_app, profile):
    """The plugin loaded from the installed zip, its provider registered."""
    folder = str(profile / "profiles" / "default" / "python" / "plugins")
    sys.path.insert(0, folder)
    import gisnoise_qgis

    assert Path(gisnoise_qgis.__file__).resolve().parent == (Path(folder) / PLUGIN).resolve()
    instance = gisnoise_qgis.classFactory(None)
    instance.initProcessing()
    from gisnoise_qgis._core import ensure_core

    ensure_core()  # the tests import the core the plugin bundles
    yield instance
    instance.unload()


@pytest.fixture(scope="session")
def cli():
    """Runs the gisnoise command line of the project's environment."""
    exe = os.environ.get("GISNOISE_CLI") or str(REPO / ".venv" / "bin" / "gisnoise")

    def run(*args):
        r = subprocess.run([exe, "-q", *map(str, args)], capture_output=True, text=True, timeout=300)
        assert r.returncode == 0, f"gisnoise {' '.join(map(str, args))}: {r.stdout}{r.stderr}"
        return r

    return run


# ---------------------------------------------------------------------- a flight
LAT0, LON0, H_GROUND = 52.3130, 10.5600, 80.0
ALT_M = 60.0
SPEED = 20.0
POWER_W = 3000.0


def straight_flight(n=31, dt=1.0):
    """A level flight due east at 60 m over flat ground, 20 m/s, 3 kW, phase horizontal.

    Returns the flight-CSV columns (positions from the local ENU frame of the core).
    """
    from pyproj import Geod

    geod = Geod(ellps="WGS84")
    t = [i * dt for i in range(n)]
    lons, lats, _ = geod.fwd([LON0] * n, [LAT0] * n, [90.0] * n, [SPEED * ti for ti in t])
    return {"t": t, "lat": list(lats), "lon": list(lons), "h": [H_GROUND + ALT_M] * n, "roll": [0.0] * n,
            "pitch": [2.0] * n, "yaw": [90.0] * n, "power_w": [POWER_W] * n, "phase": ["horizontal"] * n}


def write_csv(path, cols):
    keys = list(cols)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for i in range(len(cols["t"])):
            w.writerow([cols[k][i] if k == "phase" else repr(float(cols[k][i])) for k in keys])
    return path


@pytest.fixture(scope="session")
def flight():
    return straight_flight()


@pytest.fixture(scope="session")
def flight_csv(tmp_path_factory, flight):
    return write_csv(tmp_path_factory.mktemp("flight") / "flight.csv", flight)


CARD = str(CARDS / "demo_horizontal.json")
MAP_OPTIONS = {"RESOLUTION": 20.0, "MARGIN": 200.0, "LEVELS": "50,55,60,65", "GROUND_HEIGHT": H_GROUND}
CLI_OPTIONS = ("--resolution", "20", "--margin", "200", "--levels", "50,55,60,65", "--ground-height", str(H_GROUND))


def run_map(tmp_path, name, **params):
    """processing.run of the noise map with the options above, outputs in ``tmp_path/name``."""
    import processing

    out = tmp_path / name
    out.mkdir()
    return processing.run("gisnoise:noisemap", {
        "CARDS": [CARD], **MAP_OPTIONS,
        "OUTPUT_RASTER": str(out / "grid.tif"), "OUTPUT_BANDS": str(out / "bands.gpkg"),
        "OUTPUT_LINES": str(out / "lines.geojson"), **params})


@pytest.fixture(scope="session")
def csv_map(plugin, flight_csv, tmp_path_factory):
    """The map of the flight CSV made by processing.run, contours of every metric."""
    return run_map(tmp_path_factory.mktemp("csv_map"), "map", TRAJECTORY_FILE=str(flight_csv),
                   CONTOUR_METRICS=[0, 1, 2])


def assert_same_raster(a_path, b_path, atol):
    """Same bands, grid, CRS and nodata; values within ``atol`` dB."""
    import numpy as np
    from osgeo import osr

    a, names_a, gt_a, wkt_a, nd_a = read_raster(a_path)
    b, names_b, gt_b, wkt_b, nd_b = read_raster(b_path)
    assert names_a == names_b == ["LAmax", "LAeq", "SEL"]
    assert a.shape == b.shape
    np.testing.assert_allclose(gt_a, gt_b, rtol=0, atol=1e-6)
    assert osr.SpatialReference(wkt=wkt_a).IsSame(osr.SpatialReference(wkt=wkt_b))
    assert nd_a == nd_b
    valid = a != nd_a
    assert np.array_equal(valid, b != nd_b)
    assert valid.mean() > 0.9
    np.testing.assert_allclose(a[valid], b[valid], rtol=0, atol=atol)


def read_raster(path):
    """(bands as a float64 array, band descriptions, geotransform, WKT, nodata) through GDAL."""
    import numpy as np
    from osgeo import gdal

    ds = gdal.Open(str(path))
    assert ds is not None, path
    bands = np.stack([ds.GetRasterBand(i + 1).ReadAsArray().astype(float) for i in range(ds.RasterCount)])
    names = [ds.GetRasterBand(i + 1).GetDescription() for i in range(ds.RasterCount)]
    nodata = ds.GetRasterBand(1).GetNoDataValue()
    out = bands, names, ds.GetGeoTransform(), ds.GetProjection(), nodata
    ds = None
    return out


def bilinear(array, geotransform, x, y):
    """Value of a north-up raster at map coordinates, interpolated between cell centres."""
    x0, dx, _, y0, _, dy = geotransform
    c = (x - x0) / dx - 0.5
    r = (y - y0) / dy - 0.5
    c0, r0 = math.floor(c), math.floor(r)
    fc, fr = c - c0, r - r0
    c1, r1 = min(c0 + 1, array.shape[1] - 1), min(r0 + 1, array.shape[0] - 1)
    top = array[r0, c0] * (1 - fc) + array[r0, c1] * fc
    bottom = array[r1, c0] * (1 - fc) + array[r1, c1] * fc
    return top * (1 - fr) + bottom * fr


def recording_feedback():
    """A Processing feedback that keeps what the algorithm says: ``.warnings`` (pushWarning), ``.errors``
    (reportError), ``.infos`` (pushInfo) and ``.progress`` (each setProgress)."""
    from qgis.core import QgsProcessingFeedback

    class Recording(QgsProcessingFeedback):
        def __init__(self):
            super().__init__()
            self.errors, self.warnings, self.infos, self.progress = [], [], [], []
            self.progressChanged.connect(self.progress.append)

        def reportError(self, error, fatalError=False):  # noqa: N802, N803 (QGIS's names)
            self.errors.append(error)
            super().reportError(error, fatalError)

        def pushWarning(self, warning):  # noqa: N802 (QGIS's name)
            self.warnings.append(warning)
            super().pushWarning(warning)

        def pushInfo(self, info):  # noqa: N802 (QGIS's name)
            self.infos.append(info)
            super().pushInfo(info)

    return Recording()


def pip_output(command):
    """What pip says to an advised command line (``python3 -m pip install ...``) run by this Python with
    ``--dry-run --no-index``: it installs and fetches nothing, but refuses as pip would for real."""
    import shlex

    args = shlex.split(command)
    assert args[:4] == ["python3", "-m", "pip", "install"], command
    r = subprocess.run([sys.executable, "-m", "pip", "install", *args[4:], "--dry-run", "--no-index"],
                       capture_output=True, text=True, timeout=120)
    return r.stdout + r.stderr
