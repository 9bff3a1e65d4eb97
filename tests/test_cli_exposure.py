"""``gisnoise exposure``: a written map, a population raster and buildings in other CRSs -> exposure.json."""

import json
import math

import geopandas as gpd
import numpy as np
import rasterio
import shapely
from affine import Affine
from click.testing import CliRunner
from pyproj import CRS

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame, transformer
from gisnoise.model import ModelCard, save

LAT0, LON0 = 52.27, 10.52
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, HEIGHT = 70.0, 60.0
UTM = CRS.from_epsg(32632)


def run(*args):
    return CliRunner().invoke(cli, ["-q", *args], catch_exceptions=False)


def setup(tmp_path):
    card = ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    cp = str(save(card, tmp_path / "omni.json"))
    t = np.arange(0.0, 100.0 + 1e-9, 0.25)  # northwards at 20 m/s, n = -1000 ... 1000 m
    lat, lon, h = FRAME.to_wgs84(0 * t, -1000.0 + 20.0 * t, np.full_like(t, HEIGHT))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"))
    tp = tmp_path / "flight.csv"
    traj.to_csv(tp)
    x0, y0 = transformer(CRS.from_epsg(4326), UTM).transform(LON0, LAT0)
    with rasterio.open(tmp_path / "pop.tif", "w", driver="GTiff", width=20, height=10, count=1, dtype="float32",
                       crs=UTM.to_wkt(), transform=Affine(20.0, 0, x0 - 200.0, 0, -20.0, y0 + 100.0)) as dst:
        dst.write(np.full((10, 20), 2.0, dtype=np.float32), 1)
    gpd.GeoDataFrame({"residents": [20], "dwellings": [8], "height": [12.0]},
                     geometry=[shapely.box(x0 + 50.0, y0 - 10.0, x0 + 70.0, y0 + 10.0)], crs=UTM
                     ).to_file(tmp_path / "b.shp", engine="pyogrio")
    r = run("contour", str(tp), "--card", cp, "--out", str(tmp_path / "map"), "--resolution", "20",
            "--margin", "300", "--ground-height", "0", "--metrics", "LAmax,SEL")
    assert r.exit_code == 0, r.output
    return cp, str(tp)


def test_exposure_of_a_written_map(tmp_path):
    cp, tp = setup(tmp_path)
    r = run("exposure", str(tmp_path / "map"), "--population", str(tmp_path / "pop.tif"),
            "--buildings", str(tmp_path / "b.shp"), "--trajectory", tp, "--card", cp)
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "map" / "exposure.json").read_text())
    assert doc["schema"] == "gisnoise/exposure/1"
    assert set(doc["population"]["metrics"]) == {"LAmax", "SEL"}
    assert doc["population"]["total_people"] == 400.0
    assert doc["population"]["metrics"]["LAmax"]["people_without_level"] == 0.0
    # the wall facing the track: 0.1 m in front of it, 4 m up; the track is 1 km long each way
    b = doc["buildings"]["metrics"]["LAmax"]
    lon, lat = b["most_exposed"]["lon"], b["most_exposed"]["lat"]
    e, _, _ = FRAME.to_enu(lat, lon, 0.0)
    assert 49.0 < float(e) < 51.0
    assert b["peak_db_at_residents"] == b["peak_facade_db"]
    assert abs(b["peak_facade_db"] - (G0 - 20 * math.log10(math.hypot(float(e), HEIGHT - 4.0) / 40.0))) < 0.1
    assert (tmp_path / "map" / "exposure.md").read_text().startswith("# Exposure")
    # the grid's edge lies 300 m beside and beyond the track (+- a 20 m cell): LAmax there is about
    # 70 - 20 lg(sqrt(300^2 + 58.5^2) / 40) = 52.3 dB(A), so the 35 ... 50 dB(A) classes go on beyond the map
    lamax = [w for w in doc["warnings"] if w.startswith("LAmax:")]
    assert len(lamax) == 1 and "35, 40, 45, 50 dB(A) are lower bounds" in lamax[0], doc["warnings"]
    assert f"warning: {lamax[0]}" in r.stderr.splitlines()
    assert [a["lower_bound"] for a in doc["area_above"]["LAmax"]][:6] == [True] * 4 + [False] * 2
    # the population raster (400 x 200 m) covers a sliver of the map along the 2 km track: the people of every
    # class the map reaches (up to 66.7 dB(A) under the track) are lower bounds, and said
    assert [c["lower_bound"] for c in doc["population"]["metrics"]["LAmax"]["classes"]] == [True] * 7 + [False] * 4
    (cover,) = [w for w in doc["warnings"] if w.startswith("population: pop.tif does not cover the map")]
    assert f"warning: {cover}" in r.stderr.splitlines()


def test_bad_input_is_one_line_and_keeps_what_is_stored(tmp_path):
    cp, tp = setup(tmp_path)
    r = run("exposure", str(tmp_path / "map"), "--population", str(tmp_path / "pop.tif"))
    assert r.exit_code == 0
    before = (tmp_path / "map" / "exposure.json").read_text()
    for args, field in (
        (["--buildings", str(tmp_path / "b.shp")], "trajectory"),
        (["--population", str(tmp_path / "missing.tif")], "population"),
        (["--population", str(tmp_path / "pop.tif"), "--classes", "50"], "--classes"),
        (["--population", str(tmp_path / "pop.tif"), "--metrics", "Lden"], "Lden"),
        ([], "population"),
    ):
        r = CliRunner().invoke(cli, ["-q", "exposure", str(tmp_path / "map"), *args])
        assert r.exit_code == 2, (args, r.output)
        assert field in r.output
        assert (tmp_path / "map" / "exposure.json").read_text() == before


def test_population_with_an_infinite_cell_is_refused_by_the_command(tmp_path):
    """``gisnoise exposure`` refuses a population raster holding +inf in one line naming the file (it counted the
    cell as 0 people before), and writes nothing."""
    setup(tmp_path)
    a = np.full((10, 20), 2.0, dtype=np.float32)
    a[3, 4] = np.inf
    with rasterio.open(tmp_path / "pop.tif") as src:
        profile = src.profile
    with rasterio.open(tmp_path / "pop_inf.tif", "w", **profile) as dst:
        dst.write(a, 1)
    r = CliRunner().invoke(cli, ["-q", "exposure", str(tmp_path / "map"), "--population", str(tmp_path / "pop_inf.tif")])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    said = [ln for ln in lines if "pop_inf.tif" in ln]
    assert len(said) == 1 and "first inf at row 3, column 4" in said[0], r.output
    assert not (tmp_path / "map" / "exposure.json").exists()


def test_contour_writes_exposure_with_population_and_buildings(tmp_path):
    cp, tp = setup(tmp_path)
    r = run("contour", tp, "--card", cp, "--out", str(tmp_path / "m2"), "--resolution", "20", "--margin", "300",
            "--ground-height", "0", "--metrics", "LAmax,SEL", "--population", str(tmp_path / "pop.tif"),
            "--buildings", str(tmp_path / "b.shp"))
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "m2" / "exposure.json").read_text())
    assert doc["population"]["total_people"] == 400.0
    b = doc["buildings"]["metrics"]["LAmax"]
    lon, lat = b["most_exposed"]["lon"], b["most_exposed"]["lat"]
    e, _, _ = FRAME.to_enu(lat, lon, 0.0)
    assert abs(b["peak_facade_db"] - (G0 - 20 * math.log10(math.hypot(float(e), HEIGHT - 4.0) / 40.0))) < 0.1


def test_a_residents_field_of_another_name_is_said_and_named_with_the_option(tmp_path):
    """A buildings layer whose residents attribute is 'Einwohner' gave '-' in every residents cell without a word:
    the command says which names it looked for and the option that names another; with the option the residents
    are counted.  -q leaves out the table and the files written, never the warnings."""
    cp, tp = setup(tmp_path)
    x0, y0 = transformer(CRS.from_epsg(4326), UTM).transform(LON0, LAT0)
    gpd.GeoDataFrame({"Einwohner": [20]}, geometry=[shapely.box(x0 + 50.0, y0 - 10.0, x0 + 70.0, y0 + 10.0)],
                     crs=UTM).to_file(tmp_path / "de.gpkg", engine="pyogrio")
    args = ["exposure", str(tmp_path / "map"), "--buildings", str(tmp_path / "de.gpkg"), "--trajectory", tp,
            "--card", cp]
    r = run(*args)
    assert r.exit_code == 0, r.output
    said = ("warning: buildings: de.gpkg has no residents attribute (looked for residents, population, pop, "
            "inhabitants, persons, people; its attributes: Einwohner): no residents are counted; name the attribute "
            "with --residents-field")
    assert said in r.stderr.splitlines() and r.stdout == ""
    doc = json.loads((tmp_path / "map" / "exposure.json").read_text())
    assert "residents" not in doc["buildings"]["metrics"]["LAmax"]["classes"][0]
    r = CliRunner().invoke(cli, [*args, "--residents-field", "Einwohner"])
    assert r.exit_code == 0 and "warning: buildings" not in r.stderr and "# Exposure" in r.stdout
    doc = json.loads((tmp_path / "map" / "exposure.json").read_text())
    assert sum(c["residents"] for c in doc["buildings"]["metrics"]["LAmax"]["classes"]) == 20
