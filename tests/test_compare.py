"""Candidate routes on one grid: people above each level, person-dB and the ranking against closed form."""

import json
import math

import numpy as np
import pytest
import rasterio
from affine import Affine
from click.testing import CliRunner
from pyproj import CRS
from scipy.integrate import quad

from gisnoise.cli.main import cli
from gisnoise.errors import InputError
from gisnoise.exposure import read_population
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, LocalFrame
from gisnoise.model import ModelCard, save
from gisnoise.planning import compare_routes, write_comparison

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, HEIGHT, HR = 70.0, 60.0, 1.5
DENSITY = 0.01  # people per m^2 in the block (1 per 10 m x 10 m cell)
BLOCK = 100.0  # half width of the square block at the origin, m


def omni():
    return ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)


def northwards(e):
    t = np.arange(0.0, 2000.0 / 20.0 + 1e-9, 0.2)
    lat, lon, h = FRAME.to_wgs84(np.full_like(t, e), -1000.0 + 20.0 * t, np.full_like(t, HEIGHT))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"), source=f"e{e:g}")


def lamax(x):
    return G0 - 20 * math.log10(math.hypot(x, HEIGHT - HR) / 40.0)


def block_population(path):
    n = int(2 * BLOCK / 10.0)
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(),
                       transform=Affine(10.0, 0, -BLOCK, 0, -10.0, BLOCK)) as dst:
        dst.write(np.full((n, n), DENSITY * 100.0, dtype=np.float32), 1)
    return path


@pytest.fixture(scope="module")
def comparison(tmp_path_factory):
    d = tmp_path_factory.mktemp("cmp")
    pop = read_population(block_population(d / "pop.tif"))
    grid = GridSpec(TMERC, Affine(10.0, 0, -300.0, 0, -10.0, 150.0), 100, 30)  # x -300..700, y -150..150
    cmp = compare_routes([northwards(0.0), northwards(400.0)], [omni()], population=pop, names=["over", "beside"],
                         levels=(45.0, 50.0, 55.0, 60.0, 65.0), ground_h=0.0, grid=grid)
    return cmp, d


def test_people_above_each_level_and_person_db_equal_closed_form(comparison):
    cmp, _ = comparison
    rows = {r["route"]: r for r in cmp.doc["ranking"]}
    side = 2 * BLOCK
    for level in (45.0, 50.0, 55.0, 60.0, 65.0):
        # over the block: the strip |x| < r(level), clipped to the block
        r = math.sqrt(max((40.0 * 10 ** ((G0 - level) / 20)) ** 2 - (HEIGHT - HR) ** 2, 0.0))
        over = DENSITY * side * 2 * min(r, BLOCK)
        # 400 m east: the block spans x = 300 ... 500 m from the track
        beside = DENSITY * side * max(0.0, min(r, 500.0) - 300.0)
        assert rows["over"]["people_above"][f"{level:g}"] == pytest.approx(over, rel=0.01, abs=2.0)
        assert rows["beside"]["people_above"][f"{level:g}"] == pytest.approx(beside, rel=0.01, abs=2.0)
    dose_over = DENSITY * side * quad(lambda x: max(lamax(x) - 45.0, 0.0), -BLOCK, BLOCK)[0]
    dose_beside = DENSITY * side * quad(lambda x: max(lamax(x) - 45.0, 0.0), 300.0, 500.0, points=[394.0])[0]
    assert rows["over"]["person_db"] == pytest.approx(dose_over, rel=0.01)
    assert rows["beside"]["person_db"] == pytest.approx(dose_beside, rel=0.02, abs=5.0)
    assert cmp.best == "beside" and rows["beside"]["rank"] == 1 and rows["over"]["rank"] == 2


def test_difference_map_is_the_other_route_minus_the_best(comparison):
    cmp, d = comparison
    paths = write_comparison(cmp, d / "out")
    with rasterio.open(paths["difference"]) as src:
        assert src.descriptions == ("over - beside",)
        a = src.read(1)
        row, col = src.index(0.0 + 1e-6, 0.0 - 1e-6)  # the cell at the block centre, x = 5, y = -5
        x, y = src.xy(row, col)
    expect = (G0 - 20 * math.log10(math.hypot(x, HEIGHT - HR) / 40)) - lamax(x - 400.0)
    assert a[row, col] == pytest.approx(expect, abs=0.05)
    doc = json.loads(paths["comparison"].read_text())
    assert doc["ranking"][0]["route"] == "beside"
    assert "| 1 | beside |" in paths["table"].read_text()


def test_compare_refuses_bad_requests(comparison):
    cmp, d = comparison
    pop = read_population(d / "pop.tif")
    with pytest.raises(InputError, match="at least two"):
        compare_routes([northwards(0.0)], [omni()], population=pop)
    with pytest.raises(InputError, match="rank_level"):
        compare_routes([northwards(0.0), northwards(50.0)], [omni()], population=pop, rank_level_db=52.0)
    with pytest.raises(InputError, match="population"):
        compare_routes([northwards(0.0), northwards(50.0)], [omni()])
    with pytest.raises(InputError, match=r"levels: -1000 dB\(A\) is outside \[-50, 200\] dB\(A\)"):
        compare_routes([northwards(0.0), northwards(50.0)], [omni()], population=pop, levels=(-1000.0, 55.0))


def test_cli_compare(tmp_path):
    cp = str(save(omni(), tmp_path / "omni.json"))
    files = []
    for e in (0.0, 400.0):
        p = tmp_path / f"route{e:g}.csv"
        northwards(e).to_csv(p)
        files.append(str(p))
    block_population(tmp_path / "pop.tif")
    r = CliRunner().invoke(cli, ["-q", "compare", *files, "--card", cp, "--population", str(tmp_path / "pop.tif"),
                                 "--out", str(tmp_path / "out"), "--resolution", "20", "--margin", "200",
                                 "--ground-height", "0"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "out" / "comparison.json").read_text())
    assert [x["route"] for x in doc["ranking"]] == ["route400", "route0"]
    assert doc["ranking"][1]["people_above"]["55"] == pytest.approx(DENSITY * 200 * 200, rel=0.01)
    r = CliRunner().invoke(cli, ["-q", "compare", files[0], "--card", cp, "--out", str(tmp_path / "o2")])
    assert r.exit_code == 2 and "population" in r.output


def test_samples_on_the_ground_make_no_noise_in_a_comparison():
    """As on a map: a route that waits 60 s on its pad (landed flag) before flying north is scored by its flight
    alone; LAmax and SEL at a cell beside the track equal those of the same flight without the wait."""
    from gisnoise.planning import score_route

    fly = northwards(0.0)
    wait = np.arange(-60.0, 0.0)
    lat0, lon0, h0 = FRAME.to_wgs84(0.0, -1000.0, 0.0)  # the pad under the start of the track
    n = wait.size
    parked = Trajectory(t=np.concatenate([wait, fly.t]), lat=np.concatenate([np.full(n, lat0), fly.lat]),
                        lon=np.concatenate([np.full(n, lon0), fly.lon]), h=np.concatenate([np.full(n, h0), fly.h]),
                        roll=np.zeros(n + len(fly)), pitch=np.zeros(n + len(fly)), yaw=np.zeros(n + len(fly)),
                        power_w=np.full(n + len(fly), 3000.0), phase=np.full(n + len(fly), "horizontal"),
                        on_ground=np.arange(n + len(fly)) < n, source="parked")
    grid = GridSpec(TMERC, Affine(10.0, 0, -300.0, 0, -10.0, -900.0), 60, 20)  # around the pad
    for metric in ("LAmax", "SEL"):
        _, a = score_route(fly, [omni()], grid, metric=metric, ground_h=0.0)
        _, b = score_route(parked, [omni()], grid, metric=metric, ground_h=0.0)
        np.testing.assert_allclose(b, a, atol=1e-9, err_msg=metric)


def test_without_a_ground_the_routes_take_off_point_is_the_ground_and_routes_in_the_air_are_refused(tmp_path):
    """The ground rule of the maps: without --ground-height the ground is a route's take-off or landing point (not
    its lowest logged height), and candidates that are all in the air throughout are refused: the receivers would
    stand at flight altitude."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    with pytest.raises(InputError) as err:
        compare_routes([northwards(0.0), northwards(400.0)], [omni()], population=pop)
    assert err.value.field == "ground_h_m" and "ground_h_m" in str(err.value)
    csvs = [tmp_path / f"r{e:g}.csv" for e in (0.0, 400.0)]
    for e, p in zip((0.0, 400.0), csvs, strict=True):
        northwards(e).to_csv(p)
    r = CliRunner().invoke(cli, ["-q", "compare", *map(str, csvs), "--card", str(save(omni(), tmp_path / "o.json")),
                                 "--population", str(tmp_path / "pop.tif"), "--out", str(tmp_path / "c")])
    assert r.exit_code == 2 and "ground_h_m" in r.output and not (tmp_path / "c" / "comparison.json").exists()
    fly = northwards(0.0)
    up = fly.h.copy()
    up[:25] = np.linspace(2.0, HEIGHT, 25)  # takes off at 2 m; its lowest logged height comes later (GPS drift)
    up[-1] = 1.0
    power = np.where(np.arange(up.size) == 0, 0.0, 3000.0)  # motors off on the pad at the first sample
    hop = fly.with_(h=up, power_w=power)
    cmp = compare_routes([hop, northwards(400.0)], [omni()], population=pop, grid=GridSpec(
        TMERC, Affine(20.0, 0, -300.0, 0, -20.0, 150.0), 50, 15))
    assert cmp.doc["ground_h_m"] == pytest.approx(2.0, abs=1e-6)


def test_a_grid_that_cuts_a_level_flags_the_counts_above_it(tmp_path):
    """People above a level whose zone the grid's edge cuts are undercounted (the people beyond the edge have no
    level): the comparison says which route and levels, as a map flags clipped contours; a grid that holds every
    level's zone says nothing."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [northwards(0.0), northwards(400.0)]
    # 60 m high at 20 m/s: LAmax reaches 65 dB(A) out to 46 m from the track; a grid 300 m north-south cuts it
    small = GridSpec(TMERC, Affine(10.0, 0, -300.0, 0, -10.0, 150.0), 100, 30)
    cmp = compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=small)
    flagged = {w.split(":")[0] for w in cmp.doc["warnings"]}
    assert flagged == {"route1", "route2"}
    assert all("45, 50, 55, 60, 65" in w for w in cmp.doc["warnings"])
    # both tracks and the 45 dB(A) reach around them (40 m 10^(25/20) = 711 m slant, 708 m across)
    wide = GridSpec(TMERC, Affine(20.0, 0, -800.0, 0, -20.0, 1800.0), 100, 180)
    cmp = compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=wide)
    assert cmp.doc["warnings"] == []
    csvs = [tmp_path / f"r{k}.csv" for k in range(2)]
    for r, p in zip(routes, csvs, strict=True):
        r.to_csv(p)
    r = CliRunner().invoke(cli, ["-q", "compare", *map(str, csvs), "--card", str(save(omni(), tmp_path / "o.json")),
                                 "--population", str(tmp_path / "pop.tif"), "--out", str(tmp_path / "c"),
                                 "--ground-height", "0", "--margin", "100"])
    assert r.exit_code == 0 and "warning: r0: LAmax reaches" in r.output


def test_a_band_cut_by_cells_without_a_level_is_flagged_as_at_the_grid_edge():
    """Counts above a level that reaches cells without a level (a DEM's gap) are lower bounds, as at the
    outer edge: the edge rule is the maps' (``gisnoise.maps.clipping.edge_max``)."""
    from gisnoise.planning.compare import _clipped

    band = np.full((5, 5), 40.0)
    band[2, 2] = 60.0
    assert _clipped("r", band, [45.0, 55.0], "LAmax") is None  # closed inside the grid
    band[2, 3] = np.nan
    msg = _clipped("r", band, [45.0, 55.0, 65.0], "LAmax")
    assert msg is not None and "60.0 dB(A)" in msg and "45, 55 dB(A)" in msg


def test_coarse_cells_for_the_routes_are_named(tmp_path):
    """Routes 58.5 m above the receivers on 200 m cells: LAmax under a track may be low by
    10 lg(1 + (200 / sqrt 2 / 58.5)^2) = 8.35 dB, and the counts with it; the comparison says so as a map does."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [northwards(0.0), northwards(400.0)]
    coarse = GridSpec(TMERC, Affine(200.0, 0, -1400.0, 0, -200.0, 1800.0), 15, 19)
    cmp = compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=coarse)
    (w,) = [w for w in cmp.doc["warnings"] if "resolution:" in w]
    assert w.startswith("routes route1, route2: resolution: cells of 200 m are coarse for a flight 58.5 m above "
                        "the receivers") and "up to 8.4 dB" in w
