"""Exposure on the ground: areas in square metres of ground whatever the map's CRS, population rasters that are
densities refused, and only the part of a large raster under the map expanded."""

import math
import re

import numpy as np
import pytest
import rasterio
from affine import Affine
from click.testing import CliRunner
from pyproj import CRS, Geod, Proj

from gisnoise.errors import InputError
from gisnoise.exposure import (
    DENSEST_BLOCK_PER_KM2,
    LevelsRaster,
    area_above,
    events_area_above,
    map_exposure,
    population_points,
    read_population,
)
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, LocalFrame, transformer
from gisnoise.maps import evaluate_grid
from gisnoise.model import ModelCard

LAT0, LON0 = 52.27, 10.52
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, HEIGHT, HR = 70.0, 60.0, 1.5
WGS84 = CRS.from_epsg(4326)
MOLLWEIDE = CRS.from_user_input("ESRI:54009")
LEVELS = [50.0, 55.0, 60.0, 65.0]


def omni():
    return ModelCard(id="omni", vehicle="test", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)


def hover():
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    lat, lon, h = FRAME.to_wgs84(0 * t, 0 * t, np.full_like(t, HEIGHT))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "hover"), source="hover")


def radius_at(level):
    return math.sqrt((40.0 * 10 ** ((G0 - level) / 20.0)) ** 2 - (HEIGHT - HR) ** 2)


def map_about_the_hover(crs, ground_cell_m, half_m):
    """A map of the hover in ``crs`` with cells of about ``ground_cell_m`` on the ground, ``half_m`` each way."""
    c = CRS.from_user_input(crs)
    x0, y0 = transformer(WGS84, c).transform(LON0, LAT0)
    k = Proj(c).get_factors(LON0, LAT0).meridional_scale  # CRS units per ground metre (conformal CRSs)
    res, half = ground_cell_m * k, half_m * k
    n = int(round(2 * half / res))
    grid = GridSpec(c, Affine(res, 0, x0 - half, 0, -res, y0 + half), n, n)
    r = evaluate_grid(hover(), [omni()], grid, ground_h=0.0, metrics=("LAmax",))
    return LevelsRaster(dict(r.bands), r.grid, r.units, dict(r.metadata))


def test_areas_above_each_level_are_ground_areas_in_utm_and_in_web_mercator():
    """The hover's zone above a level is the disc of radius r(L) on the ground.  In UTM and in Web Mercator
    (EPSG:3857, whose square metres are 1 / cos^2(52.27 deg) = 2.67 ground square metres here) the area above each
    level is pi r^2 within 2 %, and the two maps agree within 2 %; the map-unit areas were 2.67 times too large."""
    utm = map_about_the_hover("EPSG:32632", 10.0, 500.0)
    web = map_about_the_hover("EPSG:3857", 10.0, 500.0)
    a_utm = area_above(utm.bands["LAmax"], utm.grid, LEVELS)
    a_web = area_above(web.bands["LAmax"], web.grid, LEVELS)
    for level, u, w in zip(LEVELS, a_utm, a_web, strict=True):
        disc = math.pi * radius_at(level) ** 2
        assert u == pytest.approx(disc, rel=0.02), level
        assert w == pytest.approx(disc, rel=0.02), level
        assert w == pytest.approx(u, rel=0.02), level
    assert web.grid.resolution[0] > 1.6 * utm.grid.resolution[0]  # the CRS units are not ground metres
    doc = map_exposure(web, population=read_population_none(web))
    assert [a["area_m2"] for a in doc["area_above"]["LAmax"] if a["level_db"] in LEVELS] == pytest.approx(a_web)
    assert "areas on the ground" in doc["area_rule"]


def read_population_none(levels):
    """A population raster of one empty cell (the document needs a layer), north-up as every population raster."""
    from gisnoise.exposure import Population

    return Population(np.zeros((1, 1)), Affine(1.0, 0.0, 0.0, 0.0, -1.0, 0.0), levels.grid.crs)


@pytest.mark.parametrize(("crs", "lon"), [("EPSG:32632", 12.6), ("EPSG:32632", 10.52), ("EPSG:3857", 10.52)])
def test_area_of_cells_above_a_level_is_their_count_times_the_cell_area_over_the_areal_scale(crs, lon):
    """A band of 70 dB(A) everywhere: every cell lies whole above 60 dB(A), so the area above it is the geodesic area
    of the grid's outline on the WGS84 ellipsoid, and in UTM the sum over the cells of the cell's area over PROJ's
    areal scale at its centre (245 km east of the zone's central meridian: 1.0007; on it: 0.9992); in Web Mercator
    100 m^2 of map hold cos^2(52.27 deg) x 1.0017 of it on the ellipsoid (PROJ's factor there is the sphere's).  The
    N-above rule (whole cells) gives the same."""
    c = CRS.from_user_input(crs)
    x0, y0 = transformer(WGS84, c).transform(lon, LAT0)
    grid = GridSpec(c, Affine(10.0, 0, x0, 0, -10.0, y0), 200, 150)  # 30 000 cells: the scale's lattice
    band = np.full(grid.shape, 70.0)
    got = area_above(band, grid, [60.0])[0]
    assert events_area_above(band, grid, [60.0]) == pytest.approx([got], rel=1e-12)
    assert abs(got / (grid.n_cells * 100.0) - 1.0) > 5e-4  # the nominal area is off by more than that
    if c.to_epsg() == 32632:
        p = Proj(c)
        x, y = grid.centres()
        scale = np.asarray(p.get_factors(*p(x, y, inverse=True)).areal_scale)
        assert got == pytest.approx(float(np.sum(100.0 / scale)), rel=1e-8)
    left, bottom, right, top = grid.bounds
    s = np.linspace(0.0, 1.0, 2001)
    ox = np.concatenate([left + (right - left) * s, np.full(s.size, right), right - (right - left) * s,
                         np.full(s.size, left)])
    oy = np.concatenate([np.full(s.size, top), top - (top - bottom) * s, np.full(s.size, bottom),
                         bottom + (top - bottom) * s])
    olon, olat = transformer(c, WGS84).transform(ox, oy)
    outline = abs(Geod(ellps="WGS84").polygon_area_perimeter(olon, olat)[0])
    assert got == pytest.approx(outline, rel=1e-6)


def write(path, values, transform, crs, nodata=-200.0):
    with rasterio.open(path, "w", driver="GTiff", width=values.shape[1], height=values.shape[0], count=1,
                       dtype="float32", crs=CRS.from_user_input(crs).to_wkt(), transform=transform, nodata=nodata,
                       compress="deflate") as d:
        d.write(values.astype(np.float32), 1)
    return path


def city_density(lon, lat):
    """People per km^2: 2 000 with a block of 12 000 and a +-50 % ripple (a city's centre, up to 18 000)."""
    d = np.where((np.abs(lon - LON0) < 0.01) & (np.abs(lat - LAT0) < 0.01), 12000.0, 2000.0)
    return d * (1 + 0.5 * np.sin(lon * 300) * np.cos(lat * 200))


def test_a_density_raster_is_refused_and_its_counts_raster_is_read(tmp_path):
    """One density field (people per km^2, up to 18 000) written as people per cell of 100 m Mollweide (an
    equal-area CRS: 1 ha per cell) and of 3 arc-second WGS84 cells (their ellipsoidal areas), and as the density
    itself: the counts are read without a word, the densities refused in one line naming the file and asking for
    people per cell: taken as people per cell, 18 000 people on a hectare (the 0.53 ha cells judged over a hectare,
    as a tower may fill a small cell), 1.8 million per km^2."""
    x0, y0 = transformer(WGS84, MOLLWEIDE).transform(LON0, LAT0)
    t = Affine(100.0, 0, x0 - 3000.0, 0, -100.0, y0 + 3000.0)
    cx, cy = np.meshgrid(t.c + 100.0 * (np.arange(60) + 0.5), t.f - 100.0 * (np.arange(60) + 0.5))
    d = city_density(*transformer(MOLLWEIDE, WGS84).transform(cx, cy))
    counts = read_population(write(tmp_path / "ghsl_counts.tif", d * 0.01, t, MOLLWEIDE))
    assert counts.warnings == [] and counts.total == pytest.approx(float(np.sum(d * 0.01)), rel=1e-6)
    r = 3.0 / 3600.0
    tw = Affine(r, 0, LON0 - 0.05, 0, -r, LAT0 + 0.03)
    lon, lat = np.meshgrid(tw.c + r * (np.arange(120) + 0.5), tw.f - r * (np.arange(72) + 0.5))
    g = Geod(ellps="WGS84")
    km2 = np.array([abs(g.polygon_area_perimeter([0, r, r, 0], [la - r / 2, la - r / 2, la + r / 2, la + r / 2])[0])
                    for la in lat[:, 0]])[:, None] / 1e6
    dw = city_density(lon, lat)
    assert read_population(write(tmp_path / "worldpop_counts.tif", dw * km2, tw, WGS84)).warnings == []
    for name, values, trans, crs, per_km2 in (("ghsl_density.tif", d, t, MOLLWEIDE, d.max() / 0.01),
                                              ("worldpop_density.tif", dw, tw, WGS84, dw.max() / 0.01)):
        with pytest.raises(InputError) as e:
            read_population(write(tmp_path / name, values, trans, crs))
        msg = str(e.value)
        assert e.value.field == "population" and "\n" not in msg and str(tmp_path) not in msg
        assert msg.startswith(f"population: {name} holds ") and "looks like a density" in msg
        assert msg.endswith("give people per cell")
        said = float(re.search(r"([0-9]+) per km², more than any city block", msg).group(1))
        assert said == pytest.approx(per_km2, rel=2e-3) and per_km2 > DENSEST_BLOCK_PER_KM2


def test_a_thin_density_raster_is_said_and_a_tower_in_a_small_cell_is_not(tmp_path):
    """A density of 4 000 per km^2 on 100 m cells read as people per cell is 400 000 per km^2: denser than the
    densest districts on record, said in a warning that reaches the exposure document; 2 000 people in one 20 m cell
    (a tower) are judged over a hectare (200 000 per km^2): no word."""
    x0, y0 = transformer(WGS84, MOLLWEIDE).transform(LON0, LAT0)
    thin = read_population(write(tmp_path / "thin.tif", np.full((20, 20), 4000.0),
                                 Affine(100.0, 0, x0 - 1000.0, 0, -100.0, y0 + 1000.0), MOLLWEIDE))
    (said,) = thin.warnings
    assert said.startswith("population: thin.tif holds up to ") and "give people per cell" in said
    top = float(re.search(r"holds up to ([0-9]+) people per km² of ground", said).group(1))
    assert top == pytest.approx(400000.0, rel=2e-3)  # Mollweide's square metres are the sphere's: 0.17 % here
    levels = map_about_the_hover("EPSG:32632", 20.0, 300.0)
    assert said in map_exposure(levels, population=thin)["warnings"]
    tower = np.zeros((10, 10))
    tower[4, 4] = 2000.0
    utm = CRS.from_epsg(32632)
    u0, v0 = transformer(WGS84, utm).transform(LON0, LAT0)
    assert read_population(write(tmp_path / "tower.tif", tower, Affine(20.0, 0, u0, 0, -20.0, v0), utm)).warnings == []


def test_the_command_refuses_a_density_raster_in_one_line(tmp_path):
    from gisnoise.cli.main import cli
    from gisnoise.maps import write_geotiff

    levels = map_about_the_hover("EPSG:32632", 20.0, 300.0)
    from gisnoise.maps import MapResult

    write_geotiff(MapResult(levels.bands, levels.grid, levels.metadata), tmp_path / "levels.tif")
    x0, y0 = transformer(WGS84, MOLLWEIDE).transform(LON0, LAT0)
    write(tmp_path / "density.tif", np.full((20, 20), 18000.0), Affine(100.0, 0, x0 - 1000.0, 0, -100.0, y0 + 1000.0),
          MOLLWEIDE)
    r = CliRunner().invoke(cli, ["-q", "exposure", str(tmp_path / "levels.tif"), "--population",
                                 str(tmp_path / "density.tif"), "--out", str(tmp_path / "out")])
    assert r.exit_code == 2
    (line,) = [x for x in r.output.splitlines() if "density.tif" in x]
    assert "looks like a density" in line and "population" in line
    assert not (tmp_path / "out" / "exposure.json").exists()


def test_a_large_raster_counts_as_its_window_about_the_map(tmp_path):
    """A 1 x 1 deg WorldPop-like raster (3 arc-seconds, 1.44 million populated cells) under an 800 m map: 1.44
    million cells x 225 sub-cells exceeded the 50 million points and were refused; only the window about the map is
    expanded now, and the counts equal those of the raster clipped to a small window about the map, read whole or
    read through ``within``.  The people are those on the map: 1 000 per km^2 times its 0.64 km^2 within the
    sub-cells' half-width along its outline, none without a level."""
    r = 3.0 / 3600.0
    t = Affine(r, 0, LON0 - 0.5, 0, -r, LAT0 + 0.5)
    lat = t.f - r * (np.arange(1200) + 0.5)
    g = Geod(ellps="WGS84")
    km2 = np.array([abs(g.polygon_area_perimeter([0, r, r, 0], [la - r / 2, la - r / 2, la + r / 2, la + r / 2])[0])
                    for la in lat]) / 1e6
    big = np.repeat(1000.0 * km2[:, None], 1200, axis=1)  # 1 000 people per km^2
    write(tmp_path / "region.tif", big, t, WGS84, nodata=-99999.0)
    i0, j0 = 576, 576  # 0.02 deg about the map's centre
    small_t = Affine(r, 0, t.c + r * j0, 0, -r, t.f - r * i0)
    write(tmp_path / "window.tif", big[i0:i0 + 48, j0:j0 + 48], small_t, WGS84, nodata=-99999.0)
    levels = map_about_the_hover("EPSG:32632", 10.0, 400.0)
    region = read_population(tmp_path / "region.tif")
    assert (region.counts > 0).sum() * 225 > 50_000_000
    pts = population_points(region, levels.grid)
    assert pts[0].size < 1_000_000
    docs = [map_exposure(levels, population=p) for p in (
        region, read_population(tmp_path / "window.tif"), read_population(tmp_path / "region.tif", within=levels.grid))]
    assert read_population(tmp_path / "region.tif", within=levels.grid).counts.size < 10_000
    first = docs[0]["population"]
    for other in docs[1:]:
        o = other["population"]
        assert o["coverage"] == first["coverage"] and o["coverage"]["uncovered_share"]["LAmax"] == 0.0
        assert o["total_people"] == pytest.approx(first["total_people"], rel=1e-9)
        for key in ("classes", "above"):
            assert [c["people"] for c in o["metrics"]["LAmax"][key]] == pytest.approx(
                [c["people"] for c in first["metrics"]["LAmax"][key]], rel=1e-9)
    side = pts[3]
    assert first["total_people"] == pytest.approx(1000.0 * 0.64, abs=1000.0 * 3200.0 * side / 2 / 1e6)
    assert first["metrics"]["LAmax"]["people_without_level"] == 0.0
