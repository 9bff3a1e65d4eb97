"""Exposure of a day of operations: people by class of Lden and N-above, a building's façade Lden,
against closed form (one hovering flight of an omnidirectional card, flown many times a day)."""

import json
import math

import numpy as np
import pytest
import rasterio
from affine import Affine
from click.testing import CliRunner
from pyproj import CRS

pytest.importorskip("numba")

from gisnoise.cli.main import cli  # noqa: E402
from gisnoise.errors import InputError  # noqa: E402
from gisnoise.exposure import operations_exposure, read_buildings, read_population  # noqa: E402
from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import WGS84, GridSpec, LocalFrame, transformer  # noqa: E402
from gisnoise.model import ModelCard, save  # noqa: E402
from gisnoise.ops import Flight, Schedule, evaluate_operations  # noqa: E402

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, UP, HR, SECONDS = 70.0, 31.5, 1.5, 60.0  # dB at 40 m; hover height, receiver height, m; hover duration, s
COUNTS = {"day": 40, "evening": 8, "night": 4}
DENSITY = 0.01  # people per m^2
BOX = (110.0, -10.0, 130.0, 10.0)  # a building east of the hover: its west wall at x = 110 m
EDGES = [40.0, 45.0, 50.0, 55.0]


def omni():
    return ModelCard(id="omni-hover", vehicle="test", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)


def hover():
    t = np.array([0.0, SECONDS])
    lat, lon, h = FRAME.to_wgs84(np.zeros(2), np.zeros(2), np.full(2, UP))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2), yaw=np.zeros(2),
                      power_w=np.full(2, 3000.0), phase=np.full(2, "hover"), source="hover")


def lden_offset_db():
    """Lden - L of a receiver where the hover's level is L (EU Directive 2002/49/EC, Annex I, by hand)."""
    e = {p: COUNTS[p] * SECONDS / (h * 3600.0) for p, h in (("day", 12), ("evening", 4), ("night", 8))}
    return 10 * math.log10((12 * e["day"] + 4 * e["evening"] * 10 ** 0.5 + 8 * e["night"] * 10) / 24)


def disc_area(level_db, offset_db=0.0):
    """Area (m^2) at receiver height where G0 - 20 log10(d / 40) + offset >= level."""
    d = 40.0 * 10 ** ((G0 + offset_db - level_db) / 20.0)
    return math.pi * max(d * d - (UP - HR) ** 2, 0.0)


def write_population(path):
    """Uniform density on 20 m cells of UTM 32N (another CRS than the map's)."""
    utm = CRS.from_epsg(32632)
    x0, y0 = transformer(WGS84, utm).transform(LON0, LAT0)
    n = 50
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32", crs=utm.to_wkt(),
                       transform=Affine(20.0, 0, x0 - 500.0, 0, -20.0, y0 + 500.0)) as d:
        d.write(np.full((n, n), DENSITY * 400.0, dtype=np.float32), 1)
    return path


def write_buildings(path):
    import geopandas as gpd
    from shapely.geometry import box

    etrs = CRS.from_epsg(25832)
    x0, y0 = transformer(WGS84, etrs).transform(LON0, LAT0)
    poly = box(x0 + BOX[0], y0 + BOX[1], x0 + BOX[2], y0 + BOX[3])
    gpd.GeoDataFrame({"residents": [12], "dwellings": [5]}, geometry=[poly], crs=etrs).to_file(
        path, driver="GPKG", engine="pyogrio")
    return path


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    d = tmp_path_factory.mktemp("opsexp")
    grid = GridSpec(TMERC, Affine(10.0, 0, -400.0, 0, -10.0, 400.0), 80, 80)
    sched = Schedule(flights=(Flight("A", hover(), COUNTS),), cards=[omni()], grid=grid, ground_h_m=0.0,
                     thresholds_db=(60.0,))
    res = evaluate_operations(sched, threads=1)
    pop = read_population(write_population(d / "pop.tif"))
    b = read_buildings(write_buildings(d / "b.gpkg"))
    doc = operations_exposure(res, sched, population=pop, buildings=b, edges=EDGES)
    return doc, d


def test_people_above_each_lden_level_are_density_times_the_disc(day):
    doc, _ = day
    off = lden_offset_db()
    got = doc["population"]["metrics"]["Lden"]["above"]
    for a in got:
        want = DENSITY * disc_area(a["level_db"], off)
        assert want > 1000 * DENSITY  # every disc holds people and lies inside the map
        assert a["people"] == pytest.approx(want, rel=0.01), a
    area = {a["level_db"]: a["area_m2"] for a in doc["area_above"]["Lden"]}
    for e in EDGES:
        assert area[e] == pytest.approx(disc_area(e, off), rel=0.01)


def test_people_by_events_above_60_db_are_density_times_the_lamax_disc(day):
    doc, _ = day
    na = doc["population"]["metrics"]["NA60"]
    flights = sum(COUNTS.values())  # 52: every flight of the day is above 60 dB inside the disc
    want = DENSITY * disc_area(60.0)
    above = {a["level"]: a["people"] for a in na["above"]}
    for edge in (1.0, 2.0, 5.0, 10.0, 20.0, 50.0):
        assert above[edge] == pytest.approx(want, rel=0.02)  # whole 10 m cells against a circle of 122 m
    assert above[100.0] == 0.0 and flights < 100
    assert doc["units"]["NA60"] == "events" and doc["units"]["Lden"] == "dB(A)"


def test_facade_lden_and_events_of_the_box_building_equal_closed_form(day):
    doc, _ = day
    bm = doc["buildings"]["metrics"]
    # nearest façade receiver: middle of the west wall's segment next to y = 0 (4 segments of 5 m), 0.1 m out, 4 m up
    d = math.sqrt((BOX[0] - 0.1) ** 2 + 2.5 ** 2 + (UP - 4.0) ** 2)
    la = G0 - 20 * math.log10(d / 40.0)
    assert bm["Lden"]["peak_facade_db"] == pytest.approx(la + lden_offset_db(), abs=0.1)
    assert bm["LAmax"]["peak_facade_db"] == pytest.approx(la, abs=0.1)
    assert la > 60.0 and bm["NA60"]["peak_facade_db"] == sum(COUNTS.values())
    cls = [c for c in bm["Lden"]["classes"] if c["residents"] > 0]
    assert len(cls) == 1 and cls[0]["dwellings"] == 5 and cls[0]["from_db"] <= la + lden_offset_db() < cls[0]["to_db"]
    assert bm["Lden"]["most_exposed"]["wall"] >= 0


def test_cli_operations_writes_exposure_and_refuses_a_bad_layer_before_evaluating(day, tmp_path):
    _, d = day
    hover().to_csv(tmp_path / "a.csv")
    save(omni(), tmp_path / "hover.json")
    doc = {"schema": "gisnoise/operations/1", "cards": ["hover.json"],
           "grid": {"crs": TMERC, "bounds": [-400, -400, 400, 400], "resolution_m": 10},
           "ground_h_m": 0.0, "thresholds_db": [60], "levels_db": [45, 50],
           "flights": [{"id": "A", "trajectory": "a.csv", "counts": COUNTS}]}
    (tmp_path / "day.json").write_text(json.dumps(doc))
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["-q", "operations", str(tmp_path / "day.json"), "--out", str(out),
                                 "--population", str(d / "pop.tif"), "--buildings", str(d / "b.gpkg")])
    assert r.exit_code == 0, r.output
    ex = json.loads((out / "exposure.json").read_text())
    assert set(ex["population"]["metrics"]) == {"Lden", "Lday", "Levening", "Lnight", "LAmax", "NA60"}
    table = (out / "exposure.md").read_text()
    assert "## Lden" in table and "## NA60" in table and "| class events |" in table
    ld = {a["level_db"]: a["people"] for a in ex["population"]["metrics"]["Lden"]["above"]}
    assert ld[50.0] == pytest.approx(DENSITY * disc_area(50.0, lden_offset_db()), rel=0.01)
    # the folder read back by `gisnoise exposure` (float32 GeoTIFF): the same document
    again = tmp_path / "again"
    args = ["-q", "exposure", str(out), "--population", str(d / "pop.tif"), "--buildings", str(d / "b.gpkg"),
            "--out", str(again)]
    r = CliRunner().invoke(cli, [*args, "--schedule", str(tmp_path / "day.json")])
    assert r.exit_code == 0, r.output
    ex2 = json.loads((again / "exposure.json").read_text())
    for m in ("Lden", "Lnight", "LAmax", "NA60"):
        a1 = [a["people"] for a in ex["population"]["metrics"][m]["above"]]
        a2 = [a["people"] for a in ex2["population"]["metrics"][m]["above"]]
        assert a2 == pytest.approx(a1, rel=1e-4, abs=1e-6), m
        assert ex2["buildings"]["metrics"][m]["peak_facade_db"] == pytest.approx(
            ex["buildings"]["metrics"][m]["peak_facade_db"], abs=1e-9)
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 2 and "--schedule" in r.output
    bad = tmp_path / "bad"
    r = CliRunner().invoke(cli, ["operations", str(tmp_path / "day.json"), "--out", str(bad),
                                 "--buildings", str(tmp_path / "missing.gpkg")])
    assert r.exit_code == 2 and r.output.strip().count("\n") == 0 and "buildings" in r.output
    assert not (bad / "operations.tif").exists()


def test_facade_levels_of_a_day_equal_the_maps_cells_at_the_same_points_empty_evening_included(tmp_path):
    """The façades and the map combine one day by one rule (gisnoise.ops.period_bands): at a façade
    point the façade bands equal the map's cell centred there; an empty period is NaN in both."""
    from gisnoise.exposure import exposure_table, operations_facade_levels

    counts = {"day": 40, "evening": 0, "night": 4}
    b = read_buildings(write_buildings(tmp_path / "b.gpkg"))
    flat = dict(cards=[omni()], ground_h_m=0.0, thresholds_db=(50.0, 60.0), receiver_height_m=4.0)
    fl = operations_facade_levels(b, Schedule(flights=(Flight("A", hover(), counts),), **flat), ground_h=0.0,
                                  height_m=4.0)
    pts = fl["points"]
    x, y = transformer(WGS84, TMERC).transform(pts.lon, pts.lat)
    d = np.hypot(x, y)
    for i in (int(np.argmin(d)), int(np.argmax(d))):  # the nearest and the farthest façade point
        grid = GridSpec(TMERC, Affine(1.0, 0, x[i] - 1.5, 0, -1.0, y[i] + 1.5), 3, 3)  # cell (1, 1) centred on it
        res = evaluate_operations(Schedule(flights=(Flight("A", hover(), counts),), grid=grid, **flat), threads=1)
        for n in ("Lden", "Lday", "Lnight", "LAmax"):
            assert np.isfinite(fl["levels"][n][i])
            assert fl["levels"][n][i] == pytest.approx(res.bands[n][1, 1], abs=1e-3), n
        assert np.isnan(fl["levels"]["Levening"][i]) and np.isnan(res.bands["Levening"][1, 1])
        for n in ("NA50", "NA60"):
            assert fl["levels"][n][i] == res.bands[n][1, 1], n
    # LAmax 59.5-61 dB along the façades: every flight of the day above 50 dB, above 60 dB at the near wall only
    assert set(fl["levels"]["NA50"]) == {44.0} and set(fl["levels"]["NA60"]) == {0.0, 44.0}
    sched = Schedule(flights=(Flight("A", hover(), counts),), **flat)
    doc = operations_exposure(res, sched, buildings=b)
    assert doc["operations"]["empty_periods"] == ["evening"]
    assert math.isnan(doc["buildings"]["metrics"]["Levening"]["peak_facade_db"])
    assert doc["buildings"]["metrics"]["Lden"]["peak_facade_db"] == pytest.approx(np.max(fl["levels"]["Lden"]))
    assert "peak façade level: none (no flight in the period)" in exposure_table(doc)


def test_exposure_of_a_day_refuses_a_schedule_that_is_not_the_folders(day, tmp_path):
    """`gisnoise exposure OPS_DIR --schedule OTHER.json` took the façade levels from the other schedule and the areas
    from the folder's map, and exposure.json named the other schedule beside the folder's flights.  The folder records
    its schedule's path and SHA-256: another schedule (other counts, or other contents) is refused in one line naming
    both, field schedule, before anything is written; the same file elsewhere is the same day."""
    from gisnoise.exposure import read_levels
    from gisnoise.ops import load_schedule

    _, d = day
    hover().to_csv(tmp_path / "a.csv")
    save(omni(), tmp_path / "hover.json")
    doc = {"schema": "gisnoise/operations/1", "cards": ["hover.json"],
           "grid": {"crs": TMERC, "bounds": [-400, -400, 400, 400], "resolution_m": 10},
           "ground_h_m": 0.0, "thresholds_db": [60], "flights": [{"id": "A", "trajectory": "a.csv", "counts": COUNTS}]}
    (tmp_path / "day.json").write_text(json.dumps(doc))
    (tmp_path / "other.json").write_text(json.dumps({**doc, "flights": [{**doc["flights"][0], "counts": {"day": 1}}]}))
    (tmp_path / "relevelled.json").write_text(json.dumps({**doc, "levels_db": [45]}))  # same flights, other file
    (tmp_path / "copy").mkdir()
    (tmp_path / "copy" / "day.json").write_text((tmp_path / "day.json").read_text())
    for f in ("a.csv", "hover.json"):
        (tmp_path / "copy" / f).write_bytes((tmp_path / f).read_bytes())
    out = tmp_path / "ops"
    r = CliRunner().invoke(cli, ["-q", "operations", str(tmp_path / "day.json"), "--out", str(out)])
    assert r.exit_code == 0, r.output
    summary = json.loads((out / "summary.json").read_text())["metadata"]
    assert summary["schedule"] == str(tmp_path / "day.json")
    args = ["-q", "exposure", str(out), "--population", str(d / "pop.tif"), "--buildings", str(d / "b.gpkg")]
    for other, why in (("other.json", "its contents differ"), ("relevelled.json", "its contents differ")):
        r = CliRunner().invoke(cli, [*args, "--schedule", str(tmp_path / other)])
        assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1, r.output
        assert r.output.startswith(f"Error: schedule: {tmp_path / other} is not the schedule the day was made from "
                                   f"({tmp_path / 'day.json'}): {why}")
        assert not (out / "exposure.json").exists()
    r = CliRunner().invoke(cli, [*args, "--schedule", str(tmp_path / "copy" / "day.json")])
    assert r.exit_code == 0, r.output
    assert json.loads((out / "exposure.json").read_text())["operations"]["schedule"] == str(tmp_path / "day.json")
    # a schedule built in Python has no file to compare: its flights and counts are
    sched = load_schedule(tmp_path / "other.json")
    sched = Schedule(flights=sched.flights, cards=[omni()], ground_h_m=0.0, thresholds_db=(60.0,))
    with pytest.raises(InputError) as err:
        operations_exposure(read_levels(out / "operations.tif"), sched, population=read_population(d / "pop.tif"))
    assert err.value.field == "schedule" and "its flights or their counts differ (flight A)" in str(err.value)
