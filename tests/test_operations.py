"""A day of operations against hand-computed period levels, Lden, N-above and time above."""

import json

import numpy as np
import pytest
from affine import Affine
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("numba")

from gisnoise.errors import InputError  # noqa: E402
from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import (
    GridSpec,  # noqa: E402
    LocalFrame,  # noqa: E402
)
from gisnoise.model import ModelCard, save  # noqa: E402
from gisnoise.ops import (  # noqa: E402
    Flight,
    Schedule,
    evaluate_operations,
    lden,
    load_schedule,
    period_of,
    schedule_from_dict,
    tile_windows,
)

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0 = 70.0  # dB at 40 m
HOUR = 3600.0


def omni(phase="hover"):
    p = dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)
    return ModelCard(id=f"omni-{phase}", vehicle="test", phase=phase, ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0)


def hover(e, n, up, seconds, source):
    t = np.array([0.0, seconds])
    lat, lon, h = FRAME.to_wgs84(np.full(2, e), np.full(2, n), np.full(2, up))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2), yaw=np.zeros(2),
                      power_w=np.full(2, 3000.0), phase=np.full(2, "hover"), source=source)


def grid():
    # 50 m cells centred on x, y = 0 (tmerc: x, y = local east, north within millimetres)
    return GridSpec(TMERC, Affine(50.0, 0.0, -425.0, 0.0, -50.0, 425.0), 17, 17)


def cell(g, x, y):
    return int(np.argmin(np.abs(g.ys - y))), int(np.argmin(np.abs(g.xs - x)))


def level(x, y, e, n, up):
    return G0 - 20 * np.log10(np.sqrt((x - e) ** 2 + (y - n) ** 2 + (up - 1.5) ** 2) / 40.0)


A = dict(e=0.0, n=0.0, up=31.5, seconds=60.0, counts={"day": 10, "evening": 2, "night": 1})
B = dict(e=300.0, n=-100.0, up=51.5, seconds=120.0, counts={"day": 5, "night": 3})


@pytest.fixture(scope="module")
def day():
    flights = tuple(Flight(name, hover(f["e"], f["n"], f["up"], f["seconds"], name), f["counts"])
                    for name, f in (("A", A), ("B", B)))
    sched = Schedule(flights=flights, cards=[omni()], grid=grid(), ground_h_m=0.0, thresholds_db=(60.0, 70.0))
    return sched, evaluate_operations(sched, threads=1)


def test_lden_formula_of_the_directive():
    # the penalties make 60 / 55 / 50 dB in day / evening / night all count as 60 dB
    assert float(lden(60.0, 55.0, 50.0)) == pytest.approx(60.0, abs=1e-12)
    expected = 10 * np.log10((12 * 10 ** 6.5 + 4 * 10 ** 6.5 + 8 * 10 ** 6.0) / 24)
    assert float(lden(65.0, 60.0, 50.0)) == pytest.approx(expected, abs=1e-12)
    assert float(lden(50.0, -np.inf, -np.inf)) == pytest.approx(50.0 + 10 * np.log10(12 / 24), abs=1e-12)


def test_periods_of_clock_times():
    assert [period_of(t) for t in ("00:00", "06:59:59", "07:00", "18:59", "19:00", "22:59", "23:00")] == \
        ["night", "night", "day", "day", "evening", "evening", "night"]
    for bad in ("24:00", "7", "07:60", "noon"):
        with pytest.raises(InputError):
            period_of(bad)


@pytest.mark.parametrize("where", [(0.0, 0.0), (300.0, -100.0), (-200.0, 150.0), (400.0, 400.0)])
def test_period_levels_lden_and_counts_equal_hand_computation(day, where):
    sched, res = day
    g = sched.grid
    r, c = cell(g, *where)
    x, y = g.xs[c], g.ys[r]
    la = level(x, y, A["e"], A["n"], A["up"])  # constant during each hover
    lb = level(x, y, B["e"], B["n"], B["up"])
    ea = A["seconds"] * 10 ** (la / 10)  # single-event exposure, s
    eb = B["seconds"] * 10 ** (lb / 10)
    l_day = 10 * np.log10((10 * ea + 5 * eb) / (12 * HOUR))
    l_eve = 10 * np.log10(2 * ea / (4 * HOUR))
    l_night = 10 * np.log10((1 * ea + 3 * eb) / (8 * HOUR))
    l_den = 10 * np.log10((12 * 10 ** (l_day / 10) + 4 * 10 ** ((l_eve + 5) / 10)
                           + 8 * 10 ** ((l_night + 10) / 10)) / 24)
    b = res.bands
    for name, want in (("Lday", l_day), ("Levening", l_eve), ("Lnight", l_night), ("Lden", l_den),
                       ("LAmax", max(la, lb))):
        assert b[name][r, c] == pytest.approx(want, abs=0.01), name
    for thr in (60.0, 70.0):
        na, nb = la > thr, lb > thr
        assert b[f"NA{thr:g}_day"][r, c] == 10 * na + 5 * nb
        assert b[f"NA{thr:g}_evening"][r, c] == 2 * na
        assert b[f"NA{thr:g}_night"][r, c] == 1 * na + 3 * nb
        assert b[f"NA{thr:g}"][r, c] == 13 * na + 8 * nb
        assert b[f"TA{thr:g}_day"][r, c] == pytest.approx(10 * 60 * na + 5 * 120 * nb, abs=1e-3)
        assert b[f"TA{thr:g}_night"][r, c] == pytest.approx(60 * na + 3 * 120 * nb, abs=1e-3)
        assert b[f"TA{thr:g}"][r, c] == pytest.approx(13 * 60 * na + 8 * 120 * nb, abs=1e-3)


def test_the_cases_above_cover_both_sides_of_the_thresholds(day):
    sched, res = day
    # A (13 flights) reaches 72.5 dB under it, B (8 flights) 68.1 dB; their 60 dB areas are apart
    assert set(np.unique(res.bands["NA70"])) == {0.0, 13.0}
    assert set(np.unique(res.bands["NA60"])) == {0.0, 8.0, 13.0}
    assert res.units["Lden"] == "dB(A)" and res.units["NA60"] == "events" and res.units["TA60_day"] == "s"
    assert res.metadata["periods"]["night"] == {"start_h": 23.0, "hours": 8.0, "penalty_db": 10.0}


def test_a_period_without_flights_is_nodata_and_lden_still_counts_the_others():
    f = Flight("A", hover(0.0, 0.0, 31.5, 60.0, "A"), {"day": 4})
    res = evaluate_operations(Schedule(flights=(f,), cards=[omni()], grid=grid(), ground_h_m=0.0), threads=1)
    assert np.isnan(res.bands["Lnight"]).all() and np.isnan(res.bands["Levening"]).all()
    np.testing.assert_allclose(res.bands["Lden"], res.bands["Lday"] + 10 * np.log10(12 / 24), atol=1e-9)


def test_schedule_checks_its_input():
    tr = hover(0.0, 0.0, 31.5, 60.0, "A")
    with pytest.raises(InputError, match="unknown period"):
        Flight("A", tr, {"morning": 3})
    with pytest.raises(InputError, match=">= 0"):
        Flight("A", tr, {"day": -1})
    with pytest.raises(InputError, match="below floor_db"):
        Schedule(flights=(Flight("A", tr, {"day": 1}),), cards=[omni()], thresholds_db=(50.0,), floor_db=55.0)
    with pytest.raises(InputError, match="used twice"):
        Schedule(flights=(Flight("A", tr, {"day": 1}), Flight("A", tr, {"day": 1})), cards=[omni()])
    with pytest.raises(InputError, match="give 'cards'"):
        Schedule(flights=(Flight("A", tr, {"day": 1}),))
    with pytest.raises(InputError, match="schema"):
        schedule_from_dict({"schema": "gisnoise/operations/9", "flights": []})


def write_case(tmp_path):
    (tmp_path / "routes").mkdir()
    hover(0.0, 0.0, 31.5, 60.0, "A").to_csv(tmp_path / "routes" / "a.csv")
    hover(300.0, -100.0, 51.5, 120.0, "B").to_csv(tmp_path / "routes" / "b.csv")
    save(omni(), tmp_path / "hover.json")
    doc = {"schema": "gisnoise/operations/1", "cards": ["hover.json"],
           "grid": {"crs": TMERC, "bounds": [-425, -425, 425, 425], "resolution_m": 50},
           "ground_h_m": 0.0, "thresholds_db": [60, 70], "levels_db": [40, 50],
           "flights": [{"id": "A", "trajectory": "routes/a.csv", "counts": {"day": 10, "evening": 2, "night": 1}},
                       {"id": "B", "trajectory": "routes/b.csv",
                        "departures": ["07:00", "09:30", "12:00", "15:00", "18:59", "23:10", "02:00", "06:00"]}]}
    path = tmp_path / "day.json"
    path.write_text(json.dumps(doc))
    return path


def test_schedule_file_with_departure_times(tmp_path, day):
    sched = load_schedule(write_case(tmp_path))
    assert [dict(f.counts) for f in sched.flights] == [{"day": 10, "evening": 2, "night": 1},
                                                        {"day": 5, "evening": 0, "night": 3}]
    res = evaluate_operations(sched)
    for name, band in day[1].bands.items():  # the same day as the fixture, from files
        np.testing.assert_allclose(res.bands[name], band, atol=1e-3, err_msg=name)  # CSV rounds positions


def test_cli_writes_bands_contours_and_summary(tmp_path, day):
    import rasterio

    from gisnoise.cli.main import cli

    path = write_case(tmp_path)
    out = tmp_path / "out"
    # a local Dask cluster when asked for; its bands equal the single-process reference
    r = CliRunner().invoke(cli, ["operations", str(path), "--out", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert "Dask (1 workers" in r.output
    r = CliRunner().invoke(cli, ["operations", str(path), "--out", str(tmp_path / "one"), "--single-process",
                                 "--threads", "2"])
    assert r.exit_code == 0, r.output
    assert "2 threads" in r.output
    assert "Lden: max" in r.output and "NA60_night: max 3.0 events" in r.output
    with rasterio.open(out / "operations.tif") as ds:
        names = list(ds.descriptions)
        lden_band = ds.read(names.index("Lden") + 1)
    np.testing.assert_allclose(lden_band, day[1].bands["Lden"].astype(np.float32), atol=1e-4)
    feats = json.loads((out / "contours.geojson").read_text())["features"]
    assert {f["properties"]["metric"] for f in feats} == {"Lden", "Lnight"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["metadata"]["flights"][1]["counts"] == {"day": 5.0, "evening": 0.0, "night": 3.0}
    r = CliRunner().invoke(cli, ["operations", str(tmp_path / "missing.json"), "--out", str(out)])
    assert r.exit_code == 2 and "no such schedule file" in r.output


@settings(deadline=None)
@given(h=st.integers(1, 300), w=st.integers(1, 300), seg=st.integers(1, 80), cells=st.integers(1, 5000))
def test_tiles_cover_the_grid_once_with_segment_aligned_columns(h, w, seg, cells):
    cover = np.zeros((h, w), int)
    tiles = tile_windows((h, w), seg, cells)
    assert len(tiles) <= 4 * -(-h * w // min(cells, h * w)) + h + w  # about `cells` per tile
    for r0, r1, c0, c1 in tiles:
        cover[r0:r1, c0:c1] += 1
        assert c0 % seg == 0 and (c1 % seg == 0 or c1 == w)
    assert (cover == 1).all()


def test_cli_runs_in_one_process_by_default(tmp_path, day, monkeypatch):
    from gisnoise.cli.main import cli

    path = write_case(tmp_path)
    r = CliRunner().invoke(cli, ["operations", str(path), "--out", str(tmp_path / "a"), "--plot"])
    assert r.exit_code == 0, r.output
    assert "threads" in r.output and "Dask" not in r.output
    png = tmp_path / "a" / "map.png"
    assert f"wrote {png}" in r.output and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # --single-process wins over a scheduler named in the environment (none runs at this address)
    monkeypatch.setenv("GISNOISE_DASK_SCHEDULER", "tcp://127.0.0.1:9")
    r = CliRunner().invoke(cli, ["operations", str(path), "--out", str(tmp_path / "b"), "--single-process"])
    assert r.exit_code == 0, r.output
    assert "threads" in r.output
    r = CliRunner().invoke(cli, ["-q", "operations", str(path), "--out", str(tmp_path / "c"), "--single-process",
                                 "--workers", "2"])
    assert r.exit_code == 2 and "excludes" in r.output


def test_thresholds_are_optional_in_a_schedule(tmp_path):
    """thresholds_db may be left out (no N-above or time-above bands), as the schedule's documentation says."""
    path = write_case(tmp_path)
    doc = json.loads(path.read_text())
    del doc["thresholds_db"]
    sched = schedule_from_dict(doc, base_dir=tmp_path)
    assert sched.thresholds_db == ()
    res = evaluate_operations(sched, threads=1)
    assert not [b for b in res.bands if b.startswith(("NA", "TA"))] and "Lden" in res.bands


def test_schedule_without_ground_takes_the_take_off_point_and_refuses_a_track_in_the_air(tmp_path):
    """The ground rule of the maps holds for a day of operations: without ground_h_m or a DEM the ground is a flight's
    take-off or landing point (not the lowest logged height), and flights that are in the air throughout are refused
    (the receivers would stand at flight altitude)."""
    from gisnoise.cli.main import cli

    (tmp_path / "routes").mkdir()
    t = np.arange(0.0, 61.0)
    lat, lon, h = FRAME.to_wgs84(10.0 * t - 300.0, np.zeros_like(t), np.full(t.size, 31.5))  # a flyover at 10 m/s
    Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full(t.size, 90.0),
               power_w=np.full(t.size, 3000.0), phase=np.full(t.size, "horizontal"),
               source="air").to_csv(tmp_path / "routes" / "air.csv")
    up = np.interp(t, [0.0, 10.0, 50.0, 60.0], [2.0, 31.5, 31.5, 0.5])  # lands 1.5 m below its take-off point
    lat, lon, h = FRAME.to_wgs84(np.zeros_like(t), np.zeros_like(t), up)
    power = np.where(t == 0.0, 0.0, 3000.0)  # on the ground, motors off, at the first sample
    Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=power,
               phase=np.full(t.size, "hover"), source="hop").to_csv(tmp_path / "routes" / "hop.csv")
    save(omni(), tmp_path / "hover.json")
    save(omni("horizontal"), tmp_path / "horizontal.json")

    def write(*routes):
        doc = {"schema": "gisnoise/operations/1", "cards": ["hover.json", "horizontal.json"],
               "grid": {"crs": TMERC, "bounds": [-425, -425, 425, 425], "resolution_m": 50},
               "flights": [{"id": r, "trajectory": f"routes/{r}.csv", "counts": {"day": 1}} for r in routes]}
        path = tmp_path / f"{'-'.join(routes)}.json"
        path.write_text(json.dumps(doc))
        return path

    with pytest.raises(InputError) as err:
        load_schedule(write("air"))
    assert err.value.field == "ground_h_m" and "ground_h_m" in str(err.value)
    r = CliRunner().invoke(cli, ["-q", "operations", str(write("air")), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and len(r.output.strip().splitlines()) == 1 and "ground_h_m" in r.output
    assert not (tmp_path / "o" / "operations.tif").exists()
    for routes in (("hop",), ("air", "hop")):
        res = evaluate_operations(load_schedule(write(*routes)), threads=1)
        assert res.metadata["ground_h_m"] == pytest.approx(float(h[0]), abs=1e-6)
        assert res.metadata["ground_h_source"] == "take-off or landing point of a flight, or a route's stated ground"


def test_samples_on_the_ground_make_no_noise_in_a_day_of_operations():
    """As on a map, a flight's samples on the ground (landed flag) are silent: 60 s parked at the pad, then a hover
    of 60 s at 31.5 m above it.  Lday is the hover alone (its constant level over 60 s, times the count, over the
    12 h day), LAmax the hover's level, and N-above counts the flight once; the parked minute was loud at the pad."""
    t = np.concatenate([np.arange(0.0, 60.0), np.arange(60.0, 121.0)])
    parked = t < 60.0
    up = np.where(parked, 0.0, 31.5)
    lat, lon, h = FRAME.to_wgs84(np.zeros_like(t), np.zeros_like(t), up)
    tr = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=np.full(t.size, 3000.0),
                    phase=np.full(t.size, "hover"), on_ground=parked, source="pad")
    counts = {"day": 10, "evening": 0, "night": 0}
    sched = Schedule(flights=(Flight("pad", tr, counts),), cards=[omni()], grid=grid(), ground_h_m=0.0,
                     thresholds_db=(40.0,))
    res = evaluate_operations(sched, threads=1)
    g = sched.grid
    for where in ((0.0, 0.0), (200.0, -150.0), (-400.0, 400.0)):
        r, c = cell(g, *where)
        la = level(g.xs[c], g.ys[r], 0.0, 0.0, 31.5)
        assert res.bands["LAmax"][r, c] == pytest.approx(la, abs=1e-3)
        assert res.bands["Lday"][r, c] == pytest.approx(la + 10 * np.log10(10 * 60.0 / (12 * HOUR)), abs=1e-3)
        assert res.bands["NA40_day"][r, c] == 10


def test_a_day_on_cells_coarse_for_its_flights_says_so(day):
    """A day's LAmax and N-above need the footprint under each flight: cells whose centres can lie half a diagonal
    beside the track lose up to 10 lg(1 + (res / sqrt 2 / H)^2) dB under it, as a map of one flight warns.
    Flight A hovers 30 m above the receivers, B 50 m: on 50 m cells 3.78 and 1.76 dB."""
    from gisnoise.ops.operations import schedule_findings

    sched, res = day
    coarse = [w for w in res.metadata["warnings"] if "resolution:" in w]
    assert len(coarse) == 1 and coarse[0].startswith("flights A, B: resolution: cells of 50 m are coarse for a "
                                                     "flight 30.0 m above the receivers")
    assert "up to 3.8 dB" in coarse[0]
    fine = GridSpec(TMERC, Affine(20.0, 0.0, -425.0, 0.0, -20.0, 425.0), 43, 43)  # 20 m: 0.87 dB at 30 m
    assert not [w for w in schedule_findings(sched, fine)[0] if "resolution:" in w]
    only_a = GridSpec(TMERC, Affine(30.0, 0.0, -425.0, 0.0, -30.0, 425.0), 29, 29)  # 30 m: 1.76 and 0.72 dB
    (w,) = [w for w in schedule_findings(sched, only_a)[0] if "resolution:" in w]
    assert w.startswith("flight A: resolution: cells of 30 m")


def pad_hover(e, ground, up, source):
    """On a pad at ``ground`` m (motors off at t = 0), then 60 s hovering ``up`` m above it at east ``e``."""
    t = np.array([0.0, 1.0, 61.0])
    lat, lon, h = FRAME.to_wgs84(np.full(3, e), np.zeros(3), np.array([ground, ground + up, ground + up]))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(3), pitch=np.zeros(3), yaw=np.zeros(3),
                      power_w=np.array([0.0, 3000.0, 3000.0]), phase=np.full(3, "hover"), source=source)


def test_a_schedules_ground_above_a_flight_is_refused_as_contour_refuses_it(tmp_path, monkeypatch):
    """A ground_h_m above a flight's lowest flying point would put the receivers above the UAV: `contour
    --ground-height` refuses it, and so does a schedule, in the same words, naming the flight, before any
    evaluation.  Flight A hovers at 31.5 m: a ground at 40 m is refused; one within the ground tolerance of
    gisnoise.limits (1 m) above it is not."""
    import gisnoise.ops.operations as ops
    from gisnoise.cli.main import cli
    from gisnoise.limits import GROUND_TOLERANCE_M
    from gisnoise.maps import make_map
    from gisnoise.ops.operations import schedule_findings

    path = write_case(tmp_path)
    doc = json.loads(path.read_text())
    doc["ground_h_m"] = 40.0
    path.write_text(json.dumps(doc))
    monkeypatch.setattr(ops, "make_plan", lambda *a, **k: pytest.fail("evaluated before the refusal"))
    with pytest.raises(InputError) as err:
        evaluate_operations(load_schedule(path), threads=1)
    with pytest.raises(InputError) as map_err:
        make_map(tmp_path / "routes" / "a.csv", [tmp_path / "hover.json"], None, ground_h=40.0, outputs=("contours",))
    assert err.value.field == "ground_h_m"
    assert str(err.value) == (f"{path}: flight 'A': ground_h_m: ground at 40 m lies above the track's lowest point "
                              f"31.5 m")
    assert str(map_err.value) == "ground_h: ground at 40 m lies above the track's lowest point 31.5 m"
    r = CliRunner().invoke(cli, ["operations", str(path), "--out", str(tmp_path / "o")])
    assert r.exit_code == 2 and r.output.strip() == f"Error: {err.value}"
    assert not (tmp_path / "o").exists()
    sched = load_schedule(path)
    for g, refused in ((31.5 + GROUND_TOLERANCE_M - 0.01, False), (31.5 + GROUND_TOLERANCE_M + 0.01, True)):
        sched = Schedule(flights=sched.flights, cards=[omni()], grid=grid(), ground_h_m=g)
        if refused:
            with pytest.raises(InputError, match="flight 'A': ground_h_m"):
                schedule_findings(sched, grid())
        else:
            schedule_findings(sched, grid())


def test_a_flight_taking_off_far_above_the_schedules_ground_is_named():
    """A flight taking off from a pad 60 m above the schedule's ground (a log on another height datum, say) and
    hovering 30 m above it is mapped 88.5 m above the receivers instead of 28.5 m: by spherical spreading its
    LAmax under it is 20 lg(88.5 / 28.5) = 9.84 dB lower than over its own ground, which the warning says and the
    two maps show.  A pad 3 m up (a roof) moves it by 20 lg(31.5 / 28.5) = 0.87 dB, within 1 dB: not named."""
    far = Flight("far", pad_hover(0.0, 60.0, 30.0, "far"), {"day": 1}, ground_h_m=60.0)
    roof = Flight("roof", pad_hover(300.0, 3.0, 30.0, "roof"), {"day": 1}, ground_h_m=3.0)
    low = evaluate_operations(Schedule(flights=(far, roof), cards=[omni()], grid=grid(), ground_h_m=0.0), threads=1)
    shift = 20 * np.log10(88.5 / 28.5)
    named = [w for w in low.metadata["warnings"] if "own ground" in w]
    assert named == [f"flight far: its own ground (stated by its route, or its take-off or landing point) lies at "
                     f"60.0 m, 60.0 m above the schedule's ground_h_m 0.0 m: mapped over that ground, its levels under "
                     f"the track {shift:.1f} dB lower (it flies 88.5 m above the receivers instead of 28.5 m, median "
                     f"while flying; more where it flies lower, at take-off and landing); check the flight's heights (a log's geoid_undulation_m) and the ground, or give "
                     f"a dem, which maps each flight over its own ground"]
    own = evaluate_operations(Schedule(flights=(far,), cards=[omni()], grid=grid(), ground_h_m=60.0), threads=1)
    assert not [w for w in own.metadata["warnings"] if "own ground" in w]
    r, c = cell(grid(), 0.0, 0.0)
    assert low.bands["LAmax"][r, c] == pytest.approx(G0 - 20 * np.log10(88.5 / 40.0), abs=1e-3)
    assert own.bands["LAmax"][r, c] == pytest.approx(G0 - 20 * np.log10(28.5 / 40.0), abs=1e-3)
    assert own.bands["LAmax"][r, c] - low.bands["LAmax"][r, c] == pytest.approx(shift, abs=2e-3)


def test_flights_on_different_grounds_are_named_with_the_ground_they_share():
    """Without the schedule's ground the day lies on the lowest of the flights' grounds.  Flight b, 30 m above its
    pad at 20 m, is then 48.5 m above the receivers instead of 28.5 m: its LAmax under it drops by
    20 lg(48.5 / 28.5) = 4.62 dB because flight a, 400 m away, takes off at 0 m.  Said, naming every flight's
    ground and the one used; alone, b is mapped over its own ground and nothing is said."""
    a = Flight("a", pad_hover(-200.0, 0.0, 30.0, "a"), {"day": 1}, ground_h_m=0.0)
    b = Flight("b", pad_hover(200.0, 20.0, 30.0, "b"), {"day": 1}, ground_h_m=20.0)
    both = evaluate_operations(Schedule(flights=(a, b), cards=[omni()], grid=grid()), threads=1)
    alone = evaluate_operations(Schedule(flights=(b,), cards=[omni()], grid=grid()), threads=1)
    assert both.metadata["ground_h_m"] == 0.0 and alone.metadata["ground_h_m"] == 20.0
    shift = 20 * np.log10(48.5 / 28.5)
    (said,) = [w for w in both.metadata["warnings"] if w.startswith("ground:")]
    assert said == ("ground: the flights' own grounds (stated by their routes, or their take-off or landing points) "
                    "differ (a 0.0 m; b 20.0 m); the day is mapped over the lowest, 0.0 m, as one flat ground: flight "
                    f"b: its levels under the track {shift:.1f} dB lower (it flies 48.5 m above the receivers instead "
                    "of 28.5 m, median while flying; more where it flies lower, at take-off and landing); give a dem, which maps each flight over its own ground, or the "
                    "schedule's ground_h_m")
    assert not [w for w in alone.metadata["warnings"] if w.startswith("ground:")]
    r, c = cell(grid(), 200.0, 0.0)
    assert both.bands["LAmax"][r, c] == pytest.approx(G0 - 20 * np.log10(48.5 / 40.0), abs=1e-3)
    assert alone.bands["LAmax"][r, c] - both.bands["LAmax"][r, c] == pytest.approx(shift, abs=2e-3)


def test_departures_and_counts_are_clock_times_and_numbers_only(tmp_path):
    """JSON true is no departure (it was 01:00, a night flight) and no count (it was 1), nor is the string "5" a
    count; a bad clock time names its flight.  A plain number is hours after midnight (documented): 7.5 is day,
    23.5 night, 24 is refused."""
    path = write_case(tmp_path)
    base = json.loads(path.read_text())

    def load(**flight_b):
        doc = json.loads(json.dumps(base))
        doc["flights"][1] = {"id": "B", "trajectory": "routes/b.csv", **flight_b}
        path.write_text(json.dumps(doc))
        return load_schedule(path)

    for fb, field, said in (({"departures": [True]}, "departures", "flight 'B': departures: True is not a clock time"),
                            ({"departures": ["25:00"]}, "departures", "flight 'B': departures: '25:00' is not a clock"),
                            ({"departures": [24]}, "departures", "flight 'B': departures: 24 h is not within 0-24 h"),
                            ({"counts": {"day": True}}, "counts", "flight 'B': count of 'day' must be a number, got True"),
                            ({"counts": {"day": "5"}}, "counts", "flight 'B': count of 'day' must be a number, got '5'"),
                            # one timetable written both ways was two (the day's count doubled, Lden +3 dB)
                            ({"counts": {"day": 1, "night": 2}, "departures": [7.5, 23.5, "06:59"]}, "departures",
                             "flight 'B' gives both 'counts' and 'departures'")):
        with pytest.raises(InputError) as err:
            load(**fb)
        assert err.value.field == field and said in str(err.value), str(err.value)
    assert dict(load(departures=[7.5, 23.5, "06:59"]).flights[1].counts) == {"day": 1.0, "evening": 0.0, "night": 2.0}


def test_quiet_keeps_the_warnings_and_leaves_out_the_summary(tmp_path):
    """-q: the warnings about the answers (here the day's coarse cells) still reach stderr; the grid line, the
    bands' maxima and the files written (all in the files) are left out."""
    from gisnoise.cli.main import cli

    path = write_case(tmp_path)
    loud = CliRunner().invoke(cli, ["operations", str(path), "--out", str(tmp_path / "a")])
    quiet = CliRunner().invoke(cli, ["-q", "operations", str(path), "--out", str(tmp_path / "b")])
    assert loud.exit_code == quiet.exit_code == 0
    warned = [ln for ln in loud.stderr.splitlines() if ln.startswith("warning: ")]
    assert warned and "resolution: cells of 50 m" in "".join(warned)
    assert quiet.stderr.splitlines() == warned and quiet.stdout == ""
    assert "Lden: max" in loud.stdout and "wrote" in loud.stdout


def test_an_n_above_area_cut_by_the_grid_edge_is_named(tmp_path):
    # the omnidirectional hover B (8 departures, 50 m above the receivers at x = 300, y = -100) exceeds 60 dB(A)
    # within d < 40 m * 10^((G0 - 60) / 20) = 126.5 m: 116 m around it on the ground, past the cells at x = 400
    # (the grid ends at 425 m); hover A (13 flights, 30 m up at the centre) stays inside, and 70 dB(A) (d < 40 m)
    # is exceeded only next to A.  So the day names NA60 with B's 8 flights, and not NA70
    res = evaluate_operations(load_schedule(write_case(tmp_path)))
    said = [w for w in res.metadata["warnings"] if "at the grid's edge" in w]
    assert said == ["NA60: up to 8 flights a day exceed 60 dB(A) at the grid's edge: the area where they do reaches "
                    "beyond the map (a wider margin shows it whole)"]
    assert float(res.bands["NA60"][:, -1].max()) == 8.0
