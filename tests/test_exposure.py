"""Exposure of a map against closed-form strip, annulus and façade values; real layer formats."""

import math

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.errors import InputError
from gisnoise.exposure import (
    LevelsRaster,
    Population,
    facade_levels,
    fraction_above,
    map_exposure,
    read_buildings,
    read_levels,
    read_population,
    write_exposure,
)
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, LocalFrame, transformer
from gisnoise.maps import evaluate_grid, write_geotiff
from gisnoise.model import ModelCard

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0 = 70.0  # level at 40 m, P_el = 1
HEIGHT = 60.0  # flight height above flat ground at 0 m
HR = 1.5  # map receiver height
EDGES = [45.0, 50.0, 55.0, 60.0, 65.0]


def omni_card(phase="horizontal"):
    p = dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)
    return ModelCard(id=f"omni-{phase}", vehicle="test", phase=phase, ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0)


def flight(e, n, t, phase):
    lat, lon, h = FRAME.to_wgs84(e, n, np.full_like(t, HEIGHT))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, phase), source=phase)


def flyover():
    t = np.arange(0.0, 3000.0 / 20.0 + 1e-9, 0.2)  # 20 m/s, 4 m between samples, n = -1500 ... 1500 m
    return flight(0 * t, -1500.0 + 20.0 * t, t, "horizontal")


def radius_at(level_db, dz):
    """Horizontal distance at which LAmax = level: G0 - 20 log10(sqrt(r^2 + dz^2) / 40)."""
    d = 40.0 * 10 ** ((G0 - level_db) / 20.0)
    return math.sqrt(max(d * d - dz * dz, 0.0))


def grid(res, half_x, half_y):
    nx, ny = int(2 * half_x / res), int(2 * half_y / res)
    return GridSpec(TMERC, Affine(res, 0.0, -half_x, 0.0, -res, half_y), nx, ny)


def as_levels(res):
    return LevelsRaster(dict(res.bands), res.grid, res.units, dict(res.metadata))


def uniform_population(path, crs, res, half_x, half_y, per_cell):
    """A GeoTIFF of ``per_cell`` people in every cell, centred on the origin, in ``crs``."""
    c = CRS.from_user_input(crs)
    x0, y0 = transformer(CRS.from_user_input("EPSG:4326"), c).transform(LON0, LAT0)
    nx, ny = int(2 * half_x / res), int(2 * half_y / res)
    t = Affine(res, 0.0, x0 - half_x, 0.0, -res, y0 + half_y)
    with rasterio.open(path, "w", driver="GTiff", width=nx, height=ny, count=1, dtype="float32", crs=c.to_wkt(),
                       transform=t, nodata=-1.0) as dst:
        dst.write(np.full((ny, nx), per_cell, dtype=np.float32), 1)
    return path


@pytest.fixture(scope="module")
def flyover_map():
    traj = flyover()
    res = evaluate_grid(traj, [omni_card()], grid(10.0, 1000.0, 350.0), ground_h=0.0, metrics=("LAmax",))
    return traj, res


@pytest.mark.parametrize("crs", [TMERC, "EPSG:32632", "EPSG:3035"])
def test_uniform_density_under_flyover_equals_strip_areas(flyover_map, tmp_path, crs):
    """People in each LAmax class = density x 2 (r_hi - r_lo) x along-track length, within 1 %.

    The population raster (10 m cells, 0.25 people each: 2500 per km^2) covers |x| <= 900 m,
    |y| <= 300 m around the middle of a 3 km track, so every point's closest approach lies
    on the track; it is written in the map's CRS, in UTM 32N and in ETRS89-LAEA.
    """
    traj, res = flyover_map
    density = 0.25 / 100.0  # people per m^2
    pop = read_population(uniform_population(tmp_path / "pop.tif", crs, 10.0, 900.0, 300.0, 0.25))
    doc = map_exposure(as_levels(res), population=pop, edges=EDGES)
    m = doc["population"]["metrics"]["LAmax"]
    assert m["people_without_level"] == 0.0
    for j, c in enumerate(m["classes"]):
        r_lo = radius_at(c["from_db"], HEIGHT - HR)
        r_hi = radius_at(c["to_db"], HEIGHT - HR) if c["to_db"] is not None else 0.0
        expect = density * 2 * (r_lo - r_hi) * 600.0
        assert c["people"] == pytest.approx(expect, rel=0.01), (j, c)
    # people above each level: the cumulative sum; total preserved
    assert doc["population"]["total_people"] == pytest.approx(density * 1800 * 600, rel=1e-6)
    above = m["above"]
    assert above[0]["people"] == pytest.approx(density * 2 * radius_at(45.0, HEIGHT - HR) * 600.0, rel=0.01)


def test_area_above_each_level_is_strip_width_times_map_length(flyover_map):
    traj, res = flyover_map
    nobody = Population(np.zeros((1, 1)), Affine(1.0, 0.0, 0.0, 0.0, -1.0, 0.0), CRS.from_user_input(TMERC))
    doc = map_exposure(as_levels(res), population=nobody, edges=EDGES)
    # the map is 700 m along track; the ends of the 3 km track are far outside it
    for a in doc["area_above"]["LAmax"]:
        expect = 2 * radius_at(a["level_db"], HEIGHT - HR) * 700.0
        assert a["area_m2"] == pytest.approx(expect, rel=0.01)


def test_hover_over_uniform_density_gives_annulus_areas(tmp_path):
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    traj = flight(0 * t, 0 * t, t, "hover")
    res = evaluate_grid(traj, [omni_card("hover")], grid(10.0, 800.0, 800.0), ground_h=0.0, metrics=("LAmax",))
    pop = read_population(uniform_population(tmp_path / "pop.tif", "EPSG:32632", 10.0, 760.0, 760.0, 0.25))
    doc = map_exposure(as_levels(res), population=pop, edges=EDGES)
    density = 0.25 / 100.0
    for c in doc["population"]["metrics"]["LAmax"]["classes"]:
        r_lo = radius_at(c["from_db"], HEIGHT - HR)
        r_hi = radius_at(c["to_db"], HEIGHT - HR) if c["to_db"] is not None else 0.0
        assert r_lo < 760.0
        assert c["people"] == pytest.approx(density * math.pi * (r_lo ** 2 - r_hi ** 2), rel=0.01), c


def test_fraction_above_is_exact_for_a_linear_level():
    # gradient along x only: the fraction is linear in the offset
    assert fraction_above(60.0, 0.1, 0.0, 10.0, 60.25) == pytest.approx(0.25)
    # along the diagonal (equal gradients): the corner triangle z^2 / (2ab)
    assert fraction_above(60.0, 0.1, 0.1, 10.0, 61.0) == pytest.approx(0.0)
    assert fraction_above(60.0, 0.1, 0.1, 10.0, 60.5) == pytest.approx(0.5 ** 2 / 2)
    # Monte Carlo check of an oblique gradient
    rng = np.random.default_rng(1)
    u = rng.uniform(-5, 5, (200_000, 2))
    lv = 60.0 + 0.3 * u[:, 0] - 0.1 * u[:, 1]
    assert fraction_above(60.0, 0.3, -0.1, 10.0, 61.0) == pytest.approx(np.mean(lv > 61.0), abs=0.005)


def box(cx, cy, w, d):
    import shapely

    return shapely.box(cx - w / 2, cy - d / 2, cx + w / 2, cy + d / 2)


def buildings_layer(path, crs, polys, residents, dwellings, heights, driver=None):
    import geopandas as gpd

    df = gpd.GeoDataFrame({"residents": residents, "Dwellings": dwellings, "height": heights},
                          geometry=list(polys), crs=crs)
    df.to_file(path, driver=driver, engine="pyogrio")
    return path


@pytest.mark.parametrize("suffix,driver", [(".gpkg", "GPKG"), (".shp", "ESRI Shapefile")])
def test_box_building_facade_level_equals_closed_form(tmp_path, suffix, driver):
    """A 20 m x 20 m building with its near wall 50 m east of a straight flyover: LAmax at the
    most exposed façade = G0 - 20 log10(d / 40), d from the nearest façade point (0.1 m in
    front of the wall, 4 m above ground) to the track, within 0.1 dB."""
    traj = flyover()
    # the building in UTM 32N (another CRS than the local frame of the flight)
    utm = CRS.from_user_input("EPSG:32632")
    x0, y0 = transformer(CRS.from_user_input("EPSG:4326"), utm).transform(LON0, LAT0)
    far = box(x0 - 300.0, y0 + 100.0, 12.0, 12.0)
    path = buildings_layer(tmp_path / f"b{suffix}", utm, [box(x0 + 60.0, y0, 20.0, 20.0), far],
                           [12, 3], [5, 1], [10.0, 7.0], driver=driver)
    b = read_buildings(path)
    assert b.n == 2 and b.fields == {"residents": "residents", "dwellings": "Dwellings", "height": "height"}
    fl = facade_levels(b, traj, [omni_card()], ground_h=0.0)
    pts = fl["points"]
    # closed form: the track is the local meridian e = 0; each façade point's east offset
    e, _, _ = FRAME.to_enu(pts.lat, pts.lon, np.zeros_like(pts.lat))
    for k in range(2):
        sel = pts.building == k
        emin = np.min(np.abs(e[sel]))
        closed = G0 - 20 * math.log10(math.hypot(emin, HEIGHT - 4.0) / 40.0)
        assert fl["buildings"]["LAmax"]["level"][k] == pytest.approx(closed, abs=0.1)
    # the near building's most exposed wall faces the track (west), 49.9 m from it in UTM metres
    p = fl["buildings"]["LAmax"]["point"][0]
    assert abs(e[p]) == pytest.approx(np.min(np.abs(e[pts.building == 0])), abs=1e-9)
    assert 49.0 < abs(e[p]) < 51.0
    # 4 walls of 20 m cut into 5 m segments
    assert int(np.sum(pts.building == 0)) == 16


def test_exposure_document_with_buildings_and_population(flyover_map, tmp_path):
    traj, res = flyover_map
    utm = CRS.from_user_input("EPSG:32632")
    x0, y0 = transformer(CRS.from_user_input("EPSG:4326"), utm).transform(LON0, LAT0)
    path = buildings_layer(tmp_path / "b.geojson", "EPSG:4326",
                           [box(*transformer(utm, CRS.from_user_input("EPSG:4326")).transform(x0 + 60, y0), 2e-4, 2e-4)],
                           [10], [4], [9.0], driver="GeoJSON")
    pop = read_population(uniform_population(tmp_path / "pop.tif", "EPSG:32632", 10.0, 900.0, 300.0, 0.25))
    write_geotiff(res, tmp_path / "map" / "levels.tif")
    levels = read_levels(tmp_path / "map" / "levels.tif")
    doc = map_exposure(levels, population=pop, buildings=read_buildings(path), trajectory=traj,
                       cards=[omni_card()], edges=EDGES)
    paths = write_exposure(doc, tmp_path / "map")
    text = paths["table"].read_text()
    assert "| 60-65 * |" in text and "peak façade level" in text  # the track crosses the map's edge: a lower bound
    b = doc["buildings"]["metrics"]["LAmax"]
    assert sum(c["residents"] for c in b["classes"]) == 10
    assert b["peak_db_at_dwellings"] == b["peak_facade_db"]


def test_bad_layers_are_refused_in_one_line(tmp_path):
    import geopandas as gpd
    import shapely

    with pytest.raises(InputError, match="population"):
        read_population(tmp_path / "none.tif")
    p = tmp_path / "pts.gpkg"
    gpd.GeoDataFrame({"residents": [1]}, geometry=[shapely.Point(LON0, LAT0)], crs="EPSG:4326").to_file(p)
    with pytest.raises(InputError, match="not a polygon"):
        read_buildings(p)
    q = tmp_path / "neg.gpkg"
    gpd.GeoDataFrame({"residents": [-3]}, geometry=[box(LON0, LAT0, 1e-4, 1e-4)], crs="EPSG:4326").to_file(q)
    with pytest.raises(InputError, match="residents"):
        read_buildings(q)
    with pytest.raises(InputError, match="dwellings"):
        read_buildings(q.with_name("neg.gpkg"), dwellings="flats")


def _population_tif(path, values, nodata=None):
    """A 2 x 3 population raster in UTM 32N holding ``values`` (people per 10 m cell)."""
    with rasterio.open(path, "w", driver="GTiff", width=3, height=2, count=1, dtype="float32", crs="EPSG:32632",
                       transform=Affine(10.0, 0, 600000.0, 0, -10.0, 5790000.0), nodata=nodata) as dst:
        dst.write(np.asarray(values, dtype=np.float32), 1)
    return path


@pytest.mark.parametrize(("bad", "shown"), [(np.inf, "inf"), (-np.inf, "-inf"), (np.nan, "nan"), (-2.0, "-2")])
def test_population_cells_that_are_not_counts_are_refused_naming_the_layer(tmp_path, bad, shown):
    """A cell that is not a finite count >= 0 (and not nodata) refuses the raster in one line naming the file,
    the cell and its value; before, +inf, -inf and NaN were counted as 0 people without a word."""
    p = _population_tif(tmp_path / "people.tif", [[1.0, 2.0, 3.0], [4.0, bad, 6.0]])
    with pytest.raises(InputError) as err:
        read_population(p)
    msg = str(err.value)
    assert err.value.field == "population"
    assert "\n" not in msg and "people.tif" in msg and str(tmp_path) not in msg
    assert f"first {shown} at row 1, column 1" in msg


def test_population_nodata_cells_hold_no_data(tmp_path):
    """Cells holding the raster's nodata value (a negative number or NaN) count no people and are not covered
    (people there are unknown, not none: tests/test_exposure_coverage.py); the others are summed."""
    p = _population_tif(tmp_path / "neg_nodata.tif", [[1.0, -9999.0, 3.0], [4.0, 5.0, -9999.0]], nodata=-9999.0)
    pop = read_population(p)
    assert pop.total == 13.0 and pop.covered.tolist() == [[True, False, True], [True, True, False]]
    q = _population_tif(tmp_path / "nan_nodata.tif", [[1.0, np.nan, 3.0], [4.0, 5.0, 6.0]], nodata=np.nan)
    pop = read_population(q)
    assert pop.total == 19.0 and pop.covered.tolist() == [[True, False, True], [True, True, True]]
    assert read_population(_population_tif(tmp_path / "full.tif", [[1.0, 0.0, 3.0], [4.0, 5.0, 6.0]])).covered is None


def test_unreadable_population_names_the_file_not_its_folder(tmp_path):
    p = tmp_path / "garbage.tif"
    p.write_bytes(b"not a tiff at all")
    with pytest.raises(InputError) as err:
        read_population(p)
    assert "garbage.tif" in str(err.value) and str(tmp_path) not in str(err.value)


def test_facade_levels_leave_out_samples_on_the_ground():
    """Façade levels follow the map's rule: a flight's samples on the ground (landed flag) make no noise.  60 s parked
    at the pad, then 60 s hovering 60 m above it: at a point 4 m above ground 80 m away LAmax is the hover's level
    and SEL that level plus 10 lg 60 s (the parked minute, 80 m off at 4 m height, was louder)."""
    from gisnoise.exposure.facades import point_levels

    t = np.arange(0.0, 121.0)
    parked = t < 60.0
    lat, lon, h = FRAME.to_wgs84(0 * t, 0 * t, np.where(parked, 0.0, HEIGHT))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=np.full(t.size, 3000.0),
                      phase=np.full(t.size, "hover"), on_ground=parked, source="pad")
    plat, plon, _ = FRAME.to_wgs84(80.0, 0.0, 0.0)
    lv = point_levels(traj, [omni_card("hover")], plon, plat, 4.0)
    la = G0 - 20 * math.log10(math.hypot(80.0, HEIGHT - 4.0) / 40.0)
    assert lv["LAmax"][0] == pytest.approx(la, abs=1e-3)  # the frames differ by the curvature over 80 m
    assert lv["SEL"][0] == pytest.approx(la + 10 * math.log10(60.0), abs=1e-3)


def test_classes_the_map_edge_reaches_are_lower_bounds(flyover_map, tmp_path):
    """The flyover's 3 km track crosses the 700 m map's north and south edges, so the edge reaches LAmax under the
    track, G0 - 20 lg((HEIGHT - HR) / 40) = 66.7 dB(A): the strips above 45 ... 65 dB(A) go on beyond the map and
    their areas and people are lower bounds; 70 dB(A) is never reached.  The hover map closes 44 dB(A) inside its
    edge (800 m away): nothing is a lower bound, until a hole of cells without a level (100 m about the hover)
    ends the values at 70 - 10 lg((100^2 + 58.5^2) / 40^2) = 61.3 dB(A): 45 ... 60 dB(A) then are."""
    edges = [45.0, 50.0, 55.0, 60.0, 65.0, 70.0]
    top = G0 - 20 * math.log10((HEIGHT - HR) / 40.0)
    assert 65.0 < top < 70.0
    pop = read_population(uniform_population(tmp_path / "pop.tif", TMERC, 10.0, 900.0, 300.0, 0.25))
    _, res = flyover_map
    doc = map_exposure(as_levels(res), population=pop, edges=edges)
    assert [a["lower_bound"] for a in doc["area_above"]["LAmax"]] == [e < top for e in edges]
    m = doc["population"]["metrics"]["LAmax"]
    assert [c["lower_bound"] for c in m["classes"]] == [e < top for e in edges]
    assert [a["lower_bound"] for a in m["above"]] == [e < top for e in edges]
    # the raster covers |y| <= 300 m of the map's 350: 10 of its 70 rows of strip lie outside it (1/7, the people
    # there unknown): said as well, the classes already lower bounds
    assert len(doc["warnings"]) == 2 and doc["warnings"][0].startswith("LAmax: the map's edge")
    assert "45, 50, 55, 60, 65 dB(A) are lower bounds" in doc["warnings"][0]
    assert doc["population"]["coverage"]["uncovered_share"]["LAmax"] == pytest.approx(1 / 7, abs=1e-12)
    assert "LAmax 14.3 % of the area at or above 45 dB(A)" in doc["warnings"][1]
    paths = write_exposure(doc, tmp_path / "out")
    md = paths["table"].read_text()
    assert "| 65-70 * |" in md and "| >= 70 |" in md and f"**Warning:** {doc['warnings'][0]}" in md
    import json

    assert json.loads(paths["exposure"].read_text())["warnings"] == doc["warnings"]

    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    hover = evaluate_grid(flight(0 * t, 0 * t, t, "hover"), [omni_card("hover")], grid(10.0, 800.0, 800.0),
                          ground_h=0.0, metrics=("LAmax",))
    pop = read_population(uniform_population(tmp_path / "whole.tif", TMERC, 10.0, 800.0, 800.0, 0.25))
    doc = map_exposure(as_levels(hover), population=pop, edges=edges)
    assert doc["warnings"] == [] and not any(a["lower_bound"] for a in doc["area_above"]["LAmax"])
    band = hover.bands["LAmax"].copy()
    x, y = np.meshgrid(hover.grid.xs, hover.grid.ys)
    band[np.hypot(x, y) < 100.0] = np.nan
    holed = LevelsRaster({"LAmax": band}, hover.grid, hover.units, dict(hover.metadata))
    doc = map_exposure(holed, population=pop, edges=edges)
    hole_top = G0 - 10 * math.log10((100.0 ** 2 + (HEIGHT - HR) ** 2) / 40.0 ** 2)
    assert 60.0 < hole_top < 65.0
    assert [a["lower_bound"] for a in doc["area_above"]["LAmax"]] == [e < hole_top for e in edges]
    assert "45, 50, 55, 60 dB(A) are lower bounds" in doc["warnings"][0]


def test_a_population_raster_covering_half_the_map_leaves_half_its_area_unknown(tmp_path):
    """A hover 58.5 m above the receivers in the middle of an 800 m map: LAmax reaches 46.9 dB(A) at the corners,
    so the whole map lies at or above the lowest class (35 dB(A)).  A raster covering exactly its east half (its
    west edge on the map's middle cell edge) leaves half of that area uncovered: people there are unknown, not none.
    The share is the geometric 1/2; the classes the map reaches (35 ... 65 dB(A)) are lower bounds, the people
    above 55 dB(A) are the density times half the disc; a raster beside the map leaves all of it uncovered."""
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    hover = evaluate_grid(flight(0 * t, 0 * t, t, "hover"), [omni_card("hover")], grid(10.0, 400.0, 400.0),
                          ground_h=0.0, metrics=("LAmax",))
    assert np.nanmin(hover.bands["LAmax"]) > 35.0
    crs = CRS.from_user_input(TMERC)
    east = tmp_path / "east.tif"
    with rasterio.open(east, "w", driver="GTiff", width=50, height=100, count=1, dtype="float32", crs=crs.to_wkt(),
                       transform=Affine(10.0, 0.0, 0.0, 0.0, -10.0, 500.0)) as dst:  # x 0 ... 500, y -500 ... 500 m
        dst.write(np.full((100, 50), 0.25, dtype=np.float32), 1)
    doc = map_exposure(as_levels(hover), population=read_population(east))
    assert doc["population"]["coverage"]["uncovered_share"]["LAmax"] == 0.5
    (said,) = [w for w in doc["warnings"] if w.startswith("population:")]
    assert said.startswith("population: east.tif does not cover the map where its levels reach the classes: LAmax "
                           "50.0 % of the area at or above 35 dB(A)")
    assert said.endswith("lower bounds (lower_bound: true): LAmax from 35, 40, 45, 50, 55, 60, 65 dB(A)")
    m = doc["population"]["metrics"]["LAmax"]
    assert [c["lower_bound"] for c in m["classes"]] == [True] * 7 + [False] * 4  # 66.7 dB(A) under the hover
    above55 = next(a["people"] for a in m["above"] if a["level_db"] == 55.0)
    assert above55 == pytest.approx(0.25 / 100.0 * math.pi * radius_at(55.0, HEIGHT - HR) ** 2 / 2, rel=0.01)
    md = write_exposure(doc, tmp_path / "out")["table"].read_text()
    assert f"**Warning:** {said}" in md and "| 55-60 | ≥ " in md
    beside = tmp_path / "beside.tif"
    with rasterio.open(beside, "w", driver="GTiff", width=10, height=10, count=1, dtype="float32", crs=crs.to_wkt(),
                       transform=Affine(10.0, 0.0, 2000.0, 0.0, -10.0, 50.0)) as dst:
        dst.write(np.full((10, 10), 5.0, dtype=np.float32), 1)
    doc = map_exposure(as_levels(hover), population=read_population(beside))
    assert doc["population"]["coverage"]["uncovered_share"]["LAmax"] == 1.0
    assert any("LAmax 100.0 % of the area" in w for w in doc["warnings"])


def test_buildings_with_a_null_or_another_residents_field_are_said(flyover_map, tmp_path):
    """A null residents value is unknown for that building, not 0 and not a reason to refuse the layer: its façade
    is classed, its residents are not counted, its class says so (residents_unknown) and a warning names it.  Bad
    values are shown as the layer holds them (-5, not np.int32(-5)).  A layer whose residents attribute has another
    name is read with a warning naming the names looked for and --residents-field."""
    import geopandas as gpd

    traj, res = flyover_map
    utm = CRS.from_user_input("EPSG:32632")
    x0, y0 = transformer(CRS.from_user_input("EPSG:4326"), utm).transform(LON0, LAT0)
    polys = [box(x0 + 60.0, y0, 20.0, 20.0), box(x0 + 200.0, y0, 20.0, 20.0)]
    p = tmp_path / "null.gpkg"
    gpd.GeoDataFrame({"residents": [12, None]}, geometry=polys, crs=utm).to_file(p, engine="pyogrio")
    b = read_buildings(p)
    assert b.residents.tolist() == [12.0, 0.0] and b.unknown["residents"].tolist() == [False, True]
    (said,) = b.warnings
    assert said.startswith("buildings: null.gpkg: 1 of 2 buildings have no value of 'residents' (residents; first "
                           "feature 1): unknown, not 0")
    doc = map_exposure(as_levels(res), buildings=b, trajectory=traj, cards=[omni_card()], edges=EDGES)
    assert said in doc["warnings"]
    lm = doc["buildings"]["metrics"]["LAmax"]
    far = lm["per_building_db"][1]
    (cls,) = [c for c in lm["classes"] if c["from_db"] <= far < (c["to_db"] or np.inf)]
    assert cls["residents_unknown"] == 1 and sum(c.get("residents_unknown", 0) for c in lm["classes"]) == 1
    assert sum(c["residents"] for c in lm["classes"]) == 12 and sum(c["buildings"] for c in lm["classes"]) == 2
    q = tmp_path / "neg.gpkg"
    gpd.GeoDataFrame({"residents": np.array([-5], dtype=np.int32)}, geometry=polys[:1], crs=utm).to_file(q)
    with pytest.raises(InputError) as err:
        read_buildings(q)
    assert str(err.value) == "buildings: attribute 'residents' (residents) of feature 0 is -5, not a number >= 0"
    r = tmp_path / "de.gpkg"
    gpd.GeoDataFrame({"Einwohner": [12, 3]}, geometry=polys, crs=utm).to_file(r, engine="pyogrio")
    b = read_buildings(r)
    assert b.residents is None and b.warnings == [
        "buildings: de.gpkg has no residents attribute (looked for residents, population, pop, inhabitants, persons, "
        "people; its attributes: Einwohner): no residents are counted; name the attribute with --residents-field"]
    b = read_buildings(r, residents="Einwohner")
    assert b.residents.tolist() == [12.0, 3.0] and b.warnings == []
