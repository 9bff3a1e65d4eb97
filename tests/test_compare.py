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
    # both tracks and the 45 dB(A) reach around them (40 m 10^(25/20) = 711 m slant, 708 m across); the 200 m
    # block of people covers a small part of these zones, which its own warning names
    wide = GridSpec(TMERC, Affine(20.0, 0, -800.0, 0, -20.0, 1800.0), 100, 180)
    cmp = compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=wide)
    assert not [w for w in cmp.doc["warnings"] if "grid's edge" in w]
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


def _parked(wait_s):
    """``northwards(0)`` after ``wait_s`` seconds on its pad (landed flag, motors running): the same flight in a
    longer file."""
    fly = northwards(0.0)
    wait = np.arange(-float(wait_s), 0.0)
    lat0, lon0, h0 = FRAME.to_wgs84(0.0, -1000.0, 0.0)
    n, m = wait.size, wait.size + len(fly)
    return Trajectory(t=np.concatenate([wait, fly.t]), lat=np.concatenate([np.full(n, lat0), fly.lat]),
                      lon=np.concatenate([np.full(n, lon0), fly.lon]), h=np.concatenate([np.full(n, h0), fly.h]),
                      roll=np.zeros(m), pitch=np.zeros(m), yaw=np.zeros(m), power_w=np.full(m, 3000.0),
                      phase=np.full(m, "horizontal"), on_ground=np.arange(m) < n, source="parked")


def test_laeq_routes_share_one_period_so_a_longer_file_ranks_no_better(tmp_path):
    """The same flight, once with 60 s on its pad before it: its SEL is the same, so over one period T its LAeq is
    too (LAeq,T = SEL - 10 lg(T / 1 s)).  T defaults to the longest route's duration, 100 + 60 = 160 s; the two tie.
    Each file's own duration (100 s against 160 s) made the longer one 10 lg(160/100) = 2.04 dB quieter."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    grid = GridSpec(TMERC, Affine(20.0, 0, -400.0, 0, -20.0, 400.0), 40, 40)
    routes = [northwards(0.0), _parked(60)]
    laeq = compare_routes(routes, [omni()], population=pop, names=["plain", "parked"], metric="LAeq", ground_h=0.0,
                          grid=grid)
    sel = compare_routes(routes, [omni()], population=pop, names=["plain", "parked"], metric="SEL", ground_h=0.0,
                         grid=grid)
    rows = {r["route"]: r for r in laeq.doc["ranking"]}
    assert rows["plain"]["people_above"] == pytest.approx(rows["parked"]["people_above"], abs=1e-6)
    assert laeq.doc["period_s"] == pytest.approx(160.0)
    assert "160 s" in laeq.doc["ranking_rule"] and sel.doc["period_s"] is None
    assert rows["plain"]["rank"] == rows["parked"]["rank"] == 1 and rows["plain"]["tie"] and rows["parked"]["tie"]
    assert rows["plain"]["people_above"]["45"] == pytest.approx(DENSITY * 200 * 200)  # the whole block: no tie of zeros
    for n in ("plain", "parked"):
        ok = np.isfinite(sel.bands[n])
        assert ok.sum() > 1000
        np.testing.assert_allclose(laeq.bands[n][ok], sel.bands[n][ok] - 10 * math.log10(160.0), atol=1e-6)
    given = compare_routes(routes, [omni()], population=pop, metric="LAeq", ground_h=0.0, grid=grid, period_s=3600.0)
    ok = np.isfinite(sel.bands["plain"])
    np.testing.assert_allclose(given.bands["route1"][ok], sel.bands["plain"][ok] - 10 * math.log10(3600.0), atol=1e-6)
    with pytest.raises(InputError, match=r"period_s: 120 s is shorter than route route2's duration 160.0 s") as e:
        compare_routes(routes, [omni()], population=pop, metric="LAeq", ground_h=0.0, grid=grid, period_s=120.0)
    assert e.value.field == "period_s"
    with pytest.raises(InputError, match="period_s: an averaging period applies to the metric LAeq only"):
        compare_routes(routes, [omni()], population=pop, metric="LAmax", ground_h=0.0, grid=grid, period_s=200.0)


def test_cli_compare_states_the_laeq_period(tmp_path):
    cp = str(save(omni(), tmp_path / "omni.json"))
    block_population(tmp_path / "pop.tif")
    files = []
    for name, tr in (("plain", northwards(0.0)), ("parked", _parked(60))):
        tr.to_csv(tmp_path / f"{name}.csv")
        files.append(str(tmp_path / f"{name}.csv"))
    r = CliRunner().invoke(cli, ["-q", "compare", *files, "--card", cp, "--population", str(tmp_path / "pop.tif"),
                                 "--out", str(tmp_path / "out"), "--metric", "LAeq", "--period", "200",
                                 "--margin", "300", "--ground-height", "0"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "out" / "comparison.json").read_text())
    assert doc["period_s"] == 200.0 and [x["rank"] for x in doc["ranking"]] == [1, 1]
    md = (tmp_path / "out" / "comparison.md").read_text()
    assert "(LAeq, over T = 200 s)" in md and "| 1 (tie) | parked |" in md and "| 1 (tie) | plain |" in md
    r = CliRunner().invoke(cli, ["compare", "--help"])
    text = " ".join(r.output.split())  # as wrapped to the terminal's width
    assert "--period" in text and "longest route's duration" in text


def _waypoints(e, ground):
    """A waypoints route northwards at x = ``e``: vertical take-off from ground at ``ground`` m, 60 m above it."""
    lat, lon, _ = FRAME.to_wgs84(np.array([e, e]), np.array([-1000.0, 1000.0]), np.zeros(2))
    wps = [{"lon": float(lon[0]), "lat": float(lat[0]), "alt": 0.0}]
    wps += [{"lon": float(x), "lat": float(y), "alt": 60.0} for x, y in zip(lon, lat, strict=True)]
    wps.append({"lon": float(lon[1]), "lat": float(lat[1]), "alt": 0.0})
    return {"schema": "gisnoise/waypoints/1", "altitude_reference": "agl", "ground_h_m": ground, "sample_dt_s": 1.0,
            "waypoints": wps}


def omni_all():
    return ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=0.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, phases=("climb", "sink", "hover", "transition"))


def test_a_given_ground_is_checked_against_every_route_as_a_map_checks_it(tmp_path):
    """Routes 60 m high (ground 0): a ground given at 100 m would put the receivers above the track.  ``contour``
    refuses it with the shared rule (gisnoise.limits.check_receivers); the comparison refuses it in the same words,
    naming the route."""
    from gisnoise.limits import check_receivers

    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [northwards(400.0), northwards(0.0)]
    with pytest.raises(InputError) as rule:
        check_receivers(1.5, 100.0, routes[0].h)
    with pytest.raises(InputError) as e:
        compare_routes(routes, [omni()], population=pop, names=["east", "over"], ground_h=100.0)
    assert str(e.value) == f"east: {rule.value}" and e.value.field == rule.value.field == "ground_h"
    assert "ground at 100 m lies above the track's lowest point 60" in str(e.value)
    csvs = [tmp_path / f"r{k}.csv" for k in range(2)]
    for tr, p in zip(routes, csvs, strict=True):
        tr.to_csv(p)
    r = CliRunner().invoke(cli, ["-q", "compare", *map(str, csvs), "--card", str(save(omni(), tmp_path / "o.json")),
                                 "--population", str(tmp_path / "pop.tif"), "--out", str(tmp_path / "c"),
                                 "--ground-height", "100"])
    assert r.exit_code == 2 and "r0: ground_h: ground at 100 m lies above" in r.output
    assert not (tmp_path / "c" / "comparison.json").exists()


def test_routes_that_state_different_grounds_are_refused_unless_one_ground_is_given(tmp_path):
    """Two routes 60 m above grounds they state at 0 m and 32 m: over one flat ground at 0 m the second would fly
    92 m above the receivers, 32 m higher than it does, and win by that alone.  Refused without a ground; with the
    ground given, the route whose own ground differs is named with both grounds."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [_waypoints(0.0, 0.0), _waypoints(400.0, 32.0)]
    with pytest.raises(InputError) as e:
        compare_routes(routes, [omni_all()], population=pop, names=["low", "high"], margin_m=300.0)
    assert e.value.field == "ground_h_m"
    assert "the routes state different grounds (low 0 m, high 32 m)" in str(e.value)
    assert "up to 32.0 m higher" in str(e.value) and "--dem" in str(e.value) and "--ground-height" in str(e.value)
    cmp = compare_routes(routes, [omni_all()], population=pop, names=["low", "high"], margin_m=300.0, ground_h=0.0)
    (w,) = [w for w in cmp.doc["warnings"] if w.startswith("grounds differ")]
    assert w.startswith("grounds differ: high states 32 m; every route is evaluated over one flat ground at 0 m")
    with pytest.raises(InputError, match=r"low: ground_h: ground at 32 m lies above the track's lowest point"):
        compare_routes(routes, [omni_all()], population=pop, names=["low", "high"], margin_m=300.0, ground_h=32.0)
    same = compare_routes([_waypoints(0.0, 0.0), _waypoints(400.0, 0.5)], [omni_all()], population=pop,
                          margin_m=300.0)  # within the ground tolerance (1 m): one ground, the lower
    assert same.doc["ground_h_m"] == 0.0 and not [w for w in same.doc["warnings"] if w.startswith("grounds differ")]


def test_a_population_raster_that_covers_part_of_a_zone_makes_its_counts_lower_bounds(tmp_path):
    """A raster of 0.01 people per m^2 that ends 200 m east of a route's track.  The route's zone above a level is
    the stadium of half-width r around its 2 km track (r from LAmax = 70 - 20 lg(sqrt(r^2 + 58.5^2) / 40)); the part
    east of x = 200 m is L (r - 200) plus the circle's segment beyond 200 m, r^2 acos(200/r) - 200 sqrt(r^2 - 200^2).
    The warning's share is that part over the stadium 2 r L + pi r^2 (34.6 % above 45 dB(A), 3.6 % above 55), to
    within the cell-centre rule's resolution (half a 20 m cell along the zone's uncovered boundary, L + 2 r acos(200/r);
    the raster's edge lies on cell edges); the people above 45 dB(A) are the density times the rest, flagged lower
    bounds, as those above 50 and 55; a route 1 km west lies inside the raster: no flag."""
    d, length, dens, cell = 200.0, 2000.0, 0.01, 20.0
    w = int((d + 2500.0) / 50.0)
    with rasterio.open(tmp_path / "half.tif", "w", driver="GTiff", width=w, height=80, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(), transform=Affine(50.0, 0, -2500.0, 0, -50.0, 2000.0)) as f:
        f.write(np.full((80, w), dens * 2500.0, np.float32), 1)
    pop = read_population(tmp_path / "half.tif")
    grid = GridSpec(TMERC, Affine(cell, 0, -1800.0, 0, -cell, 1800.0), 130, 180)  # holds both 45 dB(A) zones
    cmp = compare_routes([northwards(0.0), northwards(-1000.0)], [omni()], population=pop, names=["over", "west"],
                         ground_h=0.0, grid=grid)
    rows = {r["route"]: r for r in cmp.doc["ranking"]}

    def uncovered(level):
        r = math.sqrt((40.0 * 10 ** ((G0 - level) / 20)) ** 2 - (HEIGHT - HR) ** 2)
        area = 2 * r * length + math.pi * r * r
        part = length * (r - d) + r * r * math.acos(d / r) - d * math.sqrt(r * r - d * d)
        return part / area, area, 0.5 * cell * (length + 2 * r * math.acos(d / r)) / area

    share45, area45, tol45 = uncovered(45.0)
    share55, _, tol55 = uncovered(55.0)
    over = rows["over"]
    assert over["population_uncovered_share"] == over["uncovered_share"]["45"]
    assert over["uncovered_share"]["45"] == pytest.approx(share45, abs=tol45)  # 0.3460 +- 0.0087
    assert over["uncovered_share"]["55"] == pytest.approx(share55, abs=tol55)  # 0.0357 +- 0.0214
    assert over["people_above"]["45"] == pytest.approx(dens * area45 * (1 - share45), rel=2e-3)
    assert over["lower_bound"] == {"45": True, "50": True, "55": True, "60": False, "65": False}
    assert rows["west"]["population_uncovered_share"] == 0.0 and not any(rows["west"]["lower_bound"].values())
    (msg,) = [m for m in cmp.doc["warnings"] if "population raster" in m]
    got = 100 * over["population_uncovered_share"]
    assert msg.startswith(f"over: the population raster (half.tif) does not cover {got:.1f} % of its area above 45 "
                          "dB(A) LAmax") and "people above 45, 50, 55 dB(A) are lower bounds" in msg


def test_lower_bounds_are_flagged_per_route_and_level_and_starred_in_the_table(tmp_path):
    """A grid 600 m wide around a track at x = 0 and one at x = 150 m, the raster around all of it: the edge cells'
    centres lie 290 m (and 140 m) from the nearest track, where LAmax = 70 - 20 lg(sqrt(290^2 + 58.5^2) / 40) =
    52.6 dB(A) (58.4 dB(A)): the counts above 45 and 50 (and 55) dB(A) are lower bounds, the others are not."""
    with rasterio.open(tmp_path / "pop.tif", "w", driver="GTiff", width=60, height=60, count=1, dtype="float32",
                       crs=CRS.from_user_input(TMERC).to_wkt(), transform=Affine(100.0, 0, -3000.0, 0, -100.0, 3000.0)) as f:
        f.write(np.full((60, 60), 100.0, np.float32), 1)
    pop = read_population(tmp_path / "pop.tif")
    grid = GridSpec(TMERC, Affine(20.0, 0, -300.0, 0, -20.0, 1300.0), 30, 130)
    cmp = compare_routes([northwards(0.0), northwards(150.0)], [omni()], population=pop, names=["mid", "side"],
                         ground_h=0.0, grid=grid)
    rows = {r["route"]: r for r in cmp.doc["ranking"]}
    for name, x in (("mid", 290.0), ("side", 140.0)):
        edge = G0 - 20 * math.log10(math.hypot(x, HEIGHT - HR) / 40.0)
        assert rows[name]["lower_bound"] == {f"{v:g}": edge >= v for v in (45.0, 50.0, 55.0, 60.0, 65.0)}
    assert rows["side"]["lower_bound"]["55"] and not rows["mid"]["lower_bound"]["55"]
    paths = write_comparison(cmp, tmp_path / "out")
    assert json.loads(paths["comparison"].read_text())["ranking"][0]["lower_bound"] == cmp.doc["ranking"][0][
        "lower_bound"]
    md = paths["table"].read_text()
    (mid,) = [line for line in md.splitlines() if "| mid |" in line]
    cells = [c.strip() for c in mid.strip("|").split("|")]
    assert [c.endswith(" *") for c in cells[2:7]] == [True, True, False, False, False]
    assert "\\* lower bound: the zone above this level reaches the grid's edge" in md and "## Warnings" in md


def test_equal_routes_share_a_rank_whatever_the_order_of_the_arguments(tmp_path):
    """The same route twice: equal numbers, so rank 1 both, said a tie, in the same order either way; the tie
    tolerance (0.5 person, 0.5 person-dB, 0.05 dB) and the next rank skipping (1, 1, 3) by the rule alone."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    grid = GridSpec(TMERC, Affine(20.0, 0, -400.0, 0, -20.0, 400.0), 40, 40)
    orders = []
    for names in (["a", "a_copy"], ["a_copy", "a"]):
        cmp = compare_routes([northwards(0.0), northwards(0.0)], [omni()], population=pop, names=names,
                             ground_h=0.0, grid=grid)
        orders.append([(r["route"], r["rank"], r.get("tie")) for r in cmp.doc["ranking"]])
        assert "| 1 (tie) | a |" in write_comparison(cmp, tmp_path / names[0])["table"].read_text()
    assert orders[0] == orders[1] == [("a", 1, True), ("a_copy", 1, True)]
    from gisnoise.planning._rules import rank_rows

    def row(name, people, pdb, peak=None):
        return {"route": name, "people_above": {"55": people}, "person_db": pdb, "peak_dwelling_db": peak}

    ranked = rank_rows([row("c", 100.6, 0.0), row("b", 100.3, 400.0), row("a", 100.0, 500.0)], "55")
    assert [(r["route"], r["rank"], r["tie"]) for r in ranked] == [("b", 1, False), ("a", 2, False), ("c", 3, False)]
    ranked = rank_rows([row("z", 10.0, 5.0, 60.0), row("y", 10.4, 5.4, 60.04), row("x", 12.0, 0.0, 50.0)], "55")
    assert [(r["route"], r["rank"], r["tie"]) for r in ranked] == [("y", 1, True), ("z", 1, True), ("x", 3, False)]


def test_progress_counts_the_routes_and_a_cancel_stops_the_comparison(tmp_path):
    """The fraction done follows the routes (half after the first of two, 1 at the end) and a cancel raises
    Cancelled while a route is evaluated."""
    from gisnoise.errors import Cancelled

    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [northwards(0.0), northwards(400.0)]
    grid = GridSpec(TMERC, Affine(20.0, 0, -800.0, 0, -20.0, 1800.0), 100, 180)
    seen: list[float] = []
    compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=grid, progress=seen.append)
    assert seen == sorted(seen) and seen[-1] == pytest.approx(1.0) and any(abs(f - 0.5) < 1e-9 for f in seen)
    with pytest.raises(Cancelled):
        compare_routes(routes, [omni()], population=pop, ground_h=0.0, grid=grid, cancel=lambda: True)


def test_the_default_margin_comes_from_the_cards_and_cuts_no_zone(tmp_path):
    """Without a margin the common grid holds every route's zone above the lowest level (a fixed 500 m cut the
    bundled route's 45-55 dB(A) zones): no edge warning, and the people above each level equal those counted on
    a grid 3 km wider on every side."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [northwards(0.0), northwards(400.0)]
    cmp = compare_routes(routes, [omni()], population=pop, ground_h=0.0)
    assert not [w for w in cmp.doc["warnings"] if "grid's edge" in w]
    wide = compare_routes(routes, [omni()], population=pop, ground_h=0.0, margin_m=3000.0)
    for a, b in zip(cmp.doc["ranking"], wide.doc["ranking"], strict=True):
        assert a["route"] == b["route"]  # (lower bounds here: the block raster covers little of the zones)
        assert a["people_above"] == pytest.approx(b["people_above"], rel=1e-6)
    assert cmp.grid.n_cells < wide.grid.n_cells
