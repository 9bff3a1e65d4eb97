"""Scoring a route counts only where the level can reach the lowest level: the sums equal those of
every population sub-cell and every map sub-cell through ``fraction_above`` (the definition)."""

import math

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.exposure import (
    LevelsRaster,
    area_above,
    fraction_above,
    level_field,
    person_db_above,
    population_exposure,
    population_points,
    population_scores,
    read_population,
)
from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, transformer
from gisnoise.maps import CardSet, evaluate_grid
from gisnoise.model import ModelCard
from gisnoise.planning import score_route

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
EDGES = [45.0, 50.0, 55.0, 60.0, 65.0]


def card():
    # the paper's ansatz with directivity, so the level field is not a plain function of distance
    return ModelCard(id="dir", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=56.0, p1=20.0, p2=0.2, p3=-0.3, p4=-0.15, p5=1.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)


def diagonal_flight():
    t = np.arange(0.0, 100.0 + 1e-9, 0.5)
    e, n = -700.0 + 14.0 * t, -500.0 + 10.0 * t
    lat, lon, h = FRAME.to_wgs84(e, n, 50.0 + 0.2 * t)
    yaw = np.full_like(t, math.degrees(math.atan2(14.0, 10.0)))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=np.full_like(t, -5.0), yaw=yaw,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"), source="diagonal")


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A 4 km map at 40 m; people on 50 m cells of a UTM raster (another CRS), a third of them empty."""
    grid = GridSpec(TMERC, Affine(40.0, 0, -2000.0, 0, -40.0, 2000.0), 100, 100)
    utm = CRS.from_epsg(32632)
    x0, y0 = transformer(WGS84, utm).transform(LON0, LAT0)
    rng = np.random.default_rng(7)
    people = rng.gamma(0.7, 20.0, (44, 44)) * (rng.random((44, 44)) > 0.33)
    path = tmp_path_factory.mktemp("score") / "pop.tif"
    with rasterio.open(path, "w", driver="GTiff", width=44, height=44, count=1, dtype="float64", crs=utm.to_wkt(),
                       transform=Affine(50.0, 0, x0 - 1100.0, 0, -50.0, y0 + 1100.0)) as d:
        d.write(people, 1)
    pop = read_population(path)
    traj = diagonal_flight()
    band = evaluate_grid(traj, CardSet([card()]), grid, metrics=("LAmax",), ground_h=0.0,
                         engine="numpy").bands["LAmax"]
    return grid, pop, traj, band


def plain_people(band, grid, pts, edges, floor):
    """Every sub-cell through level_field and fraction_above, no pruning."""
    x, y, people, side = pts
    L, gx, gy = level_field(band, grid, x, y)
    ok = np.isfinite(L) & np.isfinite(gx) & np.isfinite(gy)
    above = [float(np.sum(people[ok] * fraction_above(L[ok], gx[ok], gy[ok], side, e))) for e in edges]
    dose = float(np.sum(people[ok] * np.maximum(L[ok] - floor, 0.0)))
    return above, dose, float(people[~ok].sum())


def ground_areas(grid):
    """Each cell's area on the ground: its area in the map's CRS over PROJ's areal scale at its centre."""
    from pyproj import Proj

    p = Proj(grid.crs)
    lon, lat = p(*grid.centres(), inverse=True)
    return grid.resolution[0] * grid.resolution[1] / np.asarray(p.get_factors(lon, lat).areal_scale)


def plain_area(band, grid, edges):
    """Every map sub-cell through level_field and fraction_above, each a quarter of its cell's ground area."""
    rx, ry = grid.resolution
    t = grid.transform
    cc, rr = np.meshgrid(np.arange(grid.width), np.arange(grid.height))
    xs, ys = [], []
    for oc in (0.25, 0.75):
        for orr in (0.25, 0.75):
            xs.append(t.c + t.a * (cc + oc))
            ys.append(t.f + t.e * (rr + orr))
    L, gx, gy = level_field(band, grid, np.concatenate(xs).ravel(), np.concatenate(ys).ravel())
    w = np.tile(ground_areas(grid).ravel() / 4, 4)
    ok = np.isfinite(L) & np.isfinite(gx) & np.isfinite(gy)
    side = 0.5 * math.sqrt(rx * ry)
    return [float(np.sum(w[ok] * fraction_above(L[ok], gx[ok], gy[ok], side, e))) for e in edges]


def test_the_map_spans_the_levels_and_most_cells_lie_below_the_lowest(case):
    grid, pop, traj, band = case
    assert np.nanmax(band) > EDGES[-1] + 5  # every class is crossed
    assert np.mean(band < EDGES[0]) > 0.5  # and most of the map is skipped by the bound


def test_people_person_db_and_area_equal_the_plain_sums(case):
    grid, pop, traj, band = case
    pts = population_points(pop, grid)
    above, dose, without = plain_people(band, grid, pts, EDGES, EDGES[0])
    got = population_scores(band, grid, pts, EDGES)
    assert got["above"] == pytest.approx(above, rel=1e-9, abs=1e-9)
    assert got["person_db"] == pytest.approx(dose, rel=1e-9)
    assert got["people_without_level"] == pytest.approx(without, abs=1e-9)
    assert above[0] > 50 and above[-1] > 1  # people in every class: the comparison is not of zeros
    assert person_db_above(band, grid, pts, 40.0) == pytest.approx(plain_people(band, grid, pts, [], 40.0)[1],
                                                                   rel=1e-9)
    assert area_above(band, grid, EDGES) == pytest.approx(plain_area(band, grid, EDGES), rel=1e-9)
    lr = LevelsRaster({"LAmax": band}, grid, {"LAmax": "dB(A)"}, {})
    pe = population_exposure(lr, pop, edges=EDGES, points=pts)["metrics"]["LAmax"]
    assert [a["people"] for a in pe["above"]] == pytest.approx(above, rel=1e-9, abs=1e-9)


def test_cells_without_value_keep_their_people_out_of_every_class(case):
    grid, pop, traj, band = case
    holed = band.copy()
    holed[40:45, 40:60] = np.nan  # near the track
    pts = population_points(pop, grid)
    above, dose, without = plain_people(holed, grid, pts, EDGES, EDGES[0])
    got = population_scores(holed, grid, pts, EDGES)
    assert without > 0
    assert got["people_without_level"] == pytest.approx(without, rel=1e-12)
    assert got["above"] == pytest.approx(above, rel=1e-9, abs=1e-9)
    assert area_above(holed, grid, EDGES) == pytest.approx(plain_area(holed, grid, EDGES), rel=1e-9)


def test_score_route_equals_the_class_counts_of_its_full_map(case):
    grid, pop, traj, band = case
    row, got_band = score_route(traj, CardSet([card()]), grid, population=pop, levels=EDGES, ground_h=0.0,
                                engine="numpy")
    np.testing.assert_array_equal(got_band, band)
    pts = population_points(pop, grid)
    above, dose, _ = plain_people(band, grid, pts, EDGES, EDGES[0])
    assert [row["people_above"][f"{e:g}"] for e in EDGES] == pytest.approx(above, rel=1e-9, abs=1e-9)
    assert row["person_db"] == pytest.approx(dose, rel=1e-9)
    assert [row["area_above_m2"][f"{e:g}"] for e in EDGES] == pytest.approx(plain_area(band, grid, EDGES), rel=1e-9)
