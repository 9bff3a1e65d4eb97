"""Geoid undulation: heights above mean sea level become ellipsoidal heights with EGM96.

The reference values are NGA's published EGM96 test values: the file OUTINTPT.DAT that the
National Geospatial-Intelligence Agency distributes with its EGM96 geoid program (F477.F,
"EGM96 geoid undulations at test points", NGA Office of Geomatics, earth-info.nga.mil),
computed from the full spherical-harmonic model to degree 360 (latitude, east longitude
in deg, N in m).  The map uses the 15' grid of the same model interpolated bilinearly
(PROJ's vgridshift), which departs from the harmonic series by interpolation error: below
a decimetre everywhere but the steepest geoid slopes (we measure at most 0.056 m at these
six points).  Tolerance 0.1 m: a tenth of the grid's worst-case interpolation error in
mountains and a hundredth of a GNSS receiver's vertical error; at 40 m it moves a level
by 0.02 dB.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner

from gisnoise.cli.main import cli
from gisnoise.errors import InputError
from gisnoise.flight import read_flight, read_route
from gisnoise.geo import find_geoid_grid, geoid_undulation
from gisnoise.model import ModelCard, save

DATA = Path(__file__).parent / "data"
COPTER = DATA / "dronekit_la_testdata_log171_copter.bin"

# NGA EGM96 OUTINTPT.DAT: (lat deg, east lon deg, N m)
NGA_EGM96 = [
    (38.6281550, 269.7791550, -31.628),
    (-14.6212170, 305.0211140, -2.969),
    (46.8743190, 102.4487290, -43.575),
    (-23.6174460, 133.8747120, 15.871),
    (38.6254730, 359.9995000, 50.066),     # across the grid's 0/360 deg seam
    (-0.4667440, 0.0023000, 17.329),
]
TOL_M = 0.1


@pytest.fixture(scope="module")
def grid():
    g = find_geoid_grid()
    if g is None:
        if os.environ.get("CI") == "true":   # scripts/install-system-deps installs proj-data on CI
            pytest.fail("no EGM96 geoid grid: install proj-data (scripts/install-system-deps)")
        pytest.skip("no EGM96 geoid grid (apt-get install proj-data)")
    return g


@pytest.mark.parametrize("lat,lon,n_nga", NGA_EGM96)
def test_egm96_undulation_at_nga_test_points(grid, lat, lon, n_nga):
    n, used = geoid_undulation(lat, lon)
    assert used.model == "EGM96"
    assert float(n) == pytest.approx(n_nga, abs=TOL_M)


def test_undulation_broadcasts_and_wraps_longitude(grid):
    lat = np.array([r[0] for r in NGA_EGM96])
    lon = np.array([r[1] for r in NGA_EGM96])
    n, _ = geoid_undulation(lat, lon)
    n_west, _ = geoid_undulation(lat, lon - 360.0)             # same meridians, western longitudes
    np.testing.assert_allclose(n, [r[2] for r in NGA_EGM96], atol=TOL_M)
    np.testing.assert_allclose(n_west, n, atol=1e-9)


def test_grid_named_by_the_environment_variable(grid, monkeypatch, tmp_path):
    copy = tmp_path / "my geoid" / grid.path.name                # a folder with a blank in its name
    copy.parent.mkdir()
    shutil.copy(grid.path, copy)
    monkeypatch.setenv("GISNOISE_GEOID_GRID", str(copy))
    g = find_geoid_grid()
    assert g is not None and g.path == copy.resolve()
    assert float(g.undulation(38.6281550, 269.7791550)) == pytest.approx(-31.628, abs=TOL_M)
    monkeypatch.setenv("GISNOISE_GEOID_GRID", str(tmp_path / "missing.gtx"))
    with pytest.raises(InputError, match="GISNOISE_GEOID_GRID=.*missing.gtx: no such geoid grid file"):
        find_geoid_grid()


def test_no_grid_is_an_error_naming_the_way_out(no_geoid_grid):
    with pytest.raises(InputError, match="--geoid-undulation") as e:
        geoid_undulation(50.0, 10.0)
    assert e.value.field == "geoid_undulation_m"
    assert "proj-data" in str(e.value) and "GISNOISE_GEOID_GRID" in str(e.value)


def _gps_alt_msl():
    """(boot s, lat, lon, Alt) of the log's 3D fixes, as pymavlink reads them."""
    DFReader = pytest.importorskip("pymavlink.DFReader")
    r = DFReader.DFReader_binary(str(COPTER), zero_time_base=True)
    rows = []
    while (m := r.recv_match(type=["GPS"])) is not None:
        if m.Status >= 3:
            rows.append((m.T / 1e3, m.Lat, m.Lng, m.Alt))
    r.close()
    a = np.array(rows)
    keep = np.concatenate([[True], np.diff(a[:, 0]) > 0])
    return a[keep]


def test_ardupilot_log_heights_are_msl_plus_egm96(grid):
    pytest.importorskip("pymavlink")
    import pyproj

    tr = read_flight(COPTER)                                        # no undulation given: the geoid model
    g = _gps_alt_msl()
    # the expectation from pymavlink and PROJ directly: N of the 15' EGM96 grid at each fix
    shift = pyproj.Transformer.from_pipeline(f"+proj=vgridshift +grids={grid.path} +multiplier=1")
    n = np.asarray(shift.transform(g[:, 2], g[:, 1], np.zeros(len(g)))[2])
    # the trajectory's samples are the fixes inside the span all sources cover: match them by position
    i0 = int(np.argmin(np.abs(g[:, 1] - tr.lat[0]) + np.abs(g[:, 2] - tr.lon[0]) + np.abs(g[:, 3] + n - tr.h[0])))
    k = np.arange(i0, i0 + len(tr))
    np.testing.assert_allclose(tr.lat, g[k, 1], atol=1e-9)
    np.testing.assert_allclose(tr.h, g[k, 3] + n[k], atol=1e-6)
    assert tr.metadata["geoid_model"] == f"EGM96 ({grid.path.name})"
    assert tr.metadata["geoid_undulation_m"] == pytest.approx(float(np.mean(n[k])), abs=1e-6)
    assert "mean sea level (GPS.Alt)" in tr.metadata["height_datum"]
    # the override wins and is stated as given
    tr22 = read_flight(COPTER, geoid_undulation_m=22.0)
    np.testing.assert_allclose(tr22.h, g[k, 3] + 22.0, atol=1e-6)
    assert tr22.metadata["geoid_model"] == "given by the user" and tr22.metadata["geoid_undulation_m"] == 22.0


def test_map_of_an_ardupilot_log_states_the_datum(grid, tmp_path):
    pytest.importorskip("pymavlink")
    card = ModelCard(id="omni", vehicle="test", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=65.0, p1=10.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=300.0, phases=("horizontal", "climb", "sink", "transition"))
    log = tmp_path / "F1.BIN"
    shutil.copy(COPTER, log)
    r = CliRunner().invoke(cli, ["-q", "contour", str(log), "--card", str(save(card, tmp_path / "c.json")),
                                 "--out", str(tmp_path / "m"), "--resolution", "20", "--margin", "100"],
                           catch_exceptions=False)
    assert r.exit_code == 0, r.output
    with rasterio.open(tmp_path / "m" / "levels.tif") as ds:
        meta = json.loads(ds.tags()["gisnoise"])
    n = float(np.mean(geoid_undulation(read_route(log).trajectory.lat, read_route(log).trajectory.lon)[0]))
    assert meta["trajectory"]["geoid_model"].startswith("EGM96")
    assert meta["trajectory"]["geoid_undulation_m"] == pytest.approx(n, abs=0.01)
    assert "mean sea level" in meta["trajectory"]["height_datum"]


def test_ardupilot_map_without_grid_exits_2_naming_the_option(no_geoid_grid, tmp_path):
    pytest.importorskip("pymavlink")
    r = CliRunner().invoke(cli, ["-q", "contour", str(COPTER), "--card", "demo-horizontal",
                                 "--out", str(tmp_path / "m")], catch_exceptions=False)
    assert r.exit_code == 2 and "--geoid-undulation" in r.output
    assert len(r.output.strip().splitlines()) == 1 and not (tmp_path / "m").exists()


def test_msl_waypoints_take_the_undulation_from_the_grid(grid):
    doc = {"schema": "gisnoise/waypoints/1", "altitude_reference": "msl",
           "waypoints": [{"lon": 269.7791550 - 360.0, "lat": 38.6281550, "alt": 300.0, "speed": 15.0},
                         {"lon": 269.7791550 - 360.0, "lat": 38.6381550, "alt": 300.0, "speed": 15.0}]}
    tr = read_route(doc).trajectory
    # N changes by centimetres over the 1.1 km route: within the tolerance of the test point's value
    np.testing.assert_allclose(tr.h, 300.0 - 31.628, atol=TOL_M + 0.05)
    assert tr.metadata["geoid_model"].startswith("EGM96") or "egm96" in tr.metadata["geoid_model"].lower()
    assert tr.metadata["geoid_undulation_m"] == pytest.approx(-31.628, abs=TOL_M + 0.05)
    # a given undulation is checked as for logs: the geoid departs less than 110 m from the ellipsoid
    with pytest.raises(InputError) as e:
        read_route(dict(doc, geoid_undulation_m=1000.0))
    assert e.value.field == "geoid_undulation_m"
    assert read_route(dict(doc, geoid_undulation_m=-30.0)).trajectory.metadata["geoid_model"] == "given by the user"
