"""A flight is judged alike on every map of it: a day of operations and route comparison check it as a map does.

The known truths: the count of samples a real crash log has lying upside down (read from the trajectory's own
attitude, as the map's test does), the number of samples flown outside a card's fitted power range (every sample of
a track built at one power), and the refusal of a card valid only at the power it was fitted at.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_compare import FRAME, TMERC, block_population  # noqa: E402

from gisnoise.cli.main import cli
from gisnoise.errors import InputError
from gisnoise.exposure import read_population
from gisnoise.flight import Trajectory, read_route
from gisnoise.maps import make_map
from gisnoise.model import ModelCard, save
from gisnoise.ops import evaluate_operations, load_schedule
from gisnoise.planning import compare_routes

COPTER = Path(__file__).parent / "data" / "dronekit_la_testdata_log171_copter.bin"
PARAMS = dict(p0=70.0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)


def _track(power_w, e=0.0):
    """A 40 s level flight northwards at 60 m and 15 m/s, every one of its 81 samples at ``power_w``, from and to
    nowhere near the ground (the ground is given)."""
    t = np.arange(0.0, 40.0 + 1e-9, 0.5)
    lat, lon, h = FRAME.to_wgs84(0 * t + e, 15.0 * t - 300.0, 0 * t + 60.0)
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full(t.size, float(power_w)), phase=np.full(t.size, "horizontal"),
                      source=f"track{e:g}")


def _fitted(tmp_path):
    """Fitted at 2000-2600 W, with a power term: extrapolating beyond is a warning."""
    c = ModelCard(id="fitted", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=PARAMS,
                  reference_power_w=3000.0, statistics={"power_range_w": [2000.0, 2600.0]})
    return str(save(c, tmp_path / "fitted.json"))


def _steady(tmp_path):
    """Fitted at 2400 W only, the power term held at 0: valid at that power alone."""
    c = ModelCard(id="steady", vehicle="v", phase="horizontal", ansatz="paper-offset",
                  parameters=dict(PARAMS, p1=0.0), reference_power_w=3000.0,
                  statistics={"power_range_w": [2400.0, 2400.0]},
                  provenance={"held_parameters": {"p1": "steady power: held at 0"}})
    return str(save(c, tmp_path / "steady.json"))


def _schedule(tmp_path, card, flights, **extra):
    doc = {"schema": "gisnoise/operations/1", "cards": [card],
           "grid": {"crs": TMERC, "bounds": [-400, -400, 400, 400], "resolution_m": 50},
           "levels_db": [50], "flights": flights, **extra}
    path = tmp_path / "day.json"
    path.write_text(json.dumps(doc))
    return path


def test_a_day_of_operations_names_a_crashed_log_as_its_map_does(tmp_path, omni_card):
    """log171 ends with the copter upside down and drawing power: the day's result, its summary and the command
    say it, naming the flight, in the words of the flight's own map."""
    tr = read_route(COPTER).trajectory
    lie = tr.lying & (tr.power_w > 0) & ~tr.on_ground
    named = f"{int(lie.sum())} samples from t = {tr.t[lie][0]:.1f} s to {tr.t[lie][-1]:.1f} s lie upside down at rest"
    assert lie.sum() >= 110
    path = tmp_path / "day.json"
    path.write_text(json.dumps({"schema": "gisnoise/operations/1", "cards": [omni_card], "levels_db": [50],
                                "grid": {"resolution_m": 20, "margin_m": 100},
                                "flights": [{"id": "crash", "trajectory": str(COPTER), "counts": {"day": 2}}]}))
    res = evaluate_operations(load_schedule(path), threads=1)
    said = [w for w in res.metadata["warnings"] if "lie upside down" in w]
    assert len(said) == 1 and said[0].startswith(f"flight crash: {COPTER}: {named}")
    m = make_map(COPTER, [omni_card], tmp_path / "map", resolution_m=20, margin_m=100, outputs=("contours",))
    assert said[0] == "flight crash: " + next(w for w in m["warnings"] if "lie upside down" in w)
    r = CliRunner().invoke(cli, ["-q", "operations", str(path), "--out", str(tmp_path / "ops")])
    assert r.exit_code == 0, r.output
    assert f"warning: flight crash: {COPTER}: {named}" in r.stderr  # -q: a warning still says it
    assert r.stdout == ""  # -q: no grid line, no bands' maxima, no files written
    summary = json.loads((tmp_path / "ops" / "summary.json").read_text())
    assert said[0] in summary["metadata"]["warnings"]
    geo = json.loads((tmp_path / "ops" / "contours.geojson").read_text())
    assert said[0] in geo["gisnoise"]["warnings"]


def test_a_day_of_operations_says_powers_outside_a_cards_range_once_for_the_flights_sharing_it(tmp_path):
    """Two flights of one track at 3000 W on a card fitted at 2000-2600 W: one line naming both, and all 81
    samples of each counted in the metadata; a track inside the range says nothing."""
    _track(3000.0).to_csv(tmp_path / "fast.csv")
    _track(2400.0, e=100.0).to_csv(tmp_path / "inside.csv")
    path = _schedule(tmp_path, _fitted(tmp_path), [
        {"id": "a", "trajectory": "fast.csv", "counts": {"day": 1}},
        {"id": "b", "trajectory": "fast.csv", "counts": {"night": 1}},
        {"id": "c", "trajectory": "inside.csv", "counts": {"day": 3}}], ground_h_m=0.0)
    res = evaluate_operations(load_schedule(path), threads=1)
    power = [w for w in res.metadata["warnings"] if "outside" in w]
    assert len(power) == 1 and power[0].startswith("flights a, b: ")
    assert "used at 3000-3000 W: 81 flying sample(s) outside" in power[0]
    expect = {"fitted": {"range_w": [2000.0, 2600.0], "used_w": [3000.0, 3000.0], "samples": 81}}
    assert res.metadata["power_outside_card_range"] == {"a": expect, "b": expect}


def test_a_day_of_operations_refuses_a_card_valid_only_at_the_power_flown_before_it_evaluates(tmp_path, monkeypatch):
    import gisnoise.ops.operations as ops

    _track(3000.0).to_csv(tmp_path / "fast.csv")
    path = _schedule(tmp_path, _steady(tmp_path), [{"id": "a", "trajectory": "fast.csv", "counts": {"day": 1}}],
                     ground_h_m=0.0)

    def no_plan(*a, **k):
        raise AssertionError("evaluated before the refusal")

    monkeypatch.setattr(ops, "make_plan", no_plan)
    with pytest.raises(InputError) as e:
        evaluate_operations(load_schedule(path), threads=1)
    assert e.value.field == "power_w" and "(2400-2400 W" in str(e.value) and "at 3000-3000 W" in str(e.value)


def test_route_comparison_checks_each_route_as_its_map_does(tmp_path):
    """A route flown above a card's fitted powers is named, with its samples counted; the other is not; a card
    valid only at the power flown is refused before any route is evaluated."""
    pop = read_population(block_population(tmp_path / "pop.tif"))
    routes = [_track(3000.0), _track(2400.0, e=100.0)]
    cmp = compare_routes(routes, [_fitted(tmp_path)], population=pop, names=["fast", "inside"], ground_h=0.0,
                         margin_m=300.0)
    power = [w for w in cmp.doc["warnings"] if "outside" in w]
    assert len(power) == 1 and power[0].startswith("fast: track0: ")
    assert cmp.doc["power_outside_card_range"] == {
        "fast": {"fitted": {"range_w": [2000.0, 2600.0], "used_w": [3000.0, 3000.0], "samples": 81}}}
    with pytest.raises(InputError) as e:
        compare_routes(routes, [_steady(tmp_path)], population=pop, ground_h=0.0, margin_m=300.0)
    assert e.value.field == "power_w" and "(2400-2400 W" in str(e.value)


def test_route_optimize_says_the_routes_fly_outside_the_cards_powers(tmp_path):
    """A card fitted at 1-2 W: both the direct and the optimized route fly every sample above it; the command
    says so for each route, and comparison.json counts each route's flying samples."""
    from test_route_optimize import pad, town

    card = ModelCard(id="tiny", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(PARAMS, p1=10.0), reference_power_w=3000.0,
                     phases=("climb", "sink", "hover", "transition"), statistics={"power_range_w": [1.0, 2.0]})
    cp = str(save(card, tmp_path / "tiny.json"))
    town(tmp_path / "pop.tif")
    (s_lon, s_lat), (g_lon, g_lat) = pad(-1500.0), pad(1500.0)
    r = CliRunner().invoke(cli, ["-q", "route", "optimize", "--from", f"{s_lon},{s_lat}", "--to", f"{g_lon},{g_lat}",
                                 "--card", cp, "--population", str(tmp_path / "pop.tif"), "--out",
                                 str(tmp_path / "out"), "--max-detour", "25", "--resolution", "50"])
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "out" / "comparison.json").read_text())
    for name, file in (("direct", "direct.geojson"), ("optimized", "route.geojson")):
        tr = read_route(tmp_path / "out" / file).trajectory
        assert doc["power_outside_card_range"][name]["tiny"]["samples"] == int(tr.flying.sum())
        assert sum(line.startswith(f"warning: {name}: ") and "outside" in line for line in r.stderr.splitlines()) == 1


def test_a_schedule_gives_a_logs_geoid_undulation_and_constant_power(tmp_path, omni_card):
    """A flight log in a schedule takes what `contour --geoid-undulation N --power-w W` gives a map of it: the
    same heights and powers, bit for bit; a flight CSV, which states its power, refuses power_w."""
    flights = [{"id": "c", "trajectory": str(COPTER), "counts": {"day": 1}, "geoid_undulation_m": 22.0,
                "power_w": 250.0}]
    path = tmp_path / "day.json"
    path.write_text(json.dumps({"schema": "gisnoise/operations/1", "cards": [omni_card], "flights": flights}))
    got = load_schedule(path).flights[0].trajectory
    want = read_route(COPTER, geoid_undulation_m=22.0, power_w=250.0).trajectory
    assert np.array_equal(got.h, want.h) and np.array_equal(got.power_w, want.power_w)
    assert np.all(got.power_w == 250.0)
    assert not np.array_equal(got.h, read_route(COPTER, geoid_undulation_m=0.0, power_w=250.0).trajectory.h)
    _track(3000.0).to_csv(tmp_path / "fast.csv")
    flights = [{"id": "a", "trajectory": "fast.csv", "counts": {"day": 1}, "power_w": 250.0}]
    path = _schedule(tmp_path, omni_card, flights, ground_h_m=0.0)
    with pytest.raises(InputError) as e:
        load_schedule(path)
    assert e.value.field == "power_w"


def test_a_schedule_refuses_a_field_it_does_not_know(tmp_path, omni_card):
    """A misspelt field (geoid_undulaton_m) would be left out without a word, the log's heights then taken from
    the geoid grid: refused, naming it and the fields a flight knows."""
    flights = [{"id": "c", "trajectory": str(COPTER), "counts": {"day": 1}, "geoid_undulaton_m": 22.0}]
    path = tmp_path / "day.json"
    path.write_text(json.dumps({"schema": "gisnoise/operations/1", "cards": [omni_card], "flights": flights}))
    with pytest.raises(InputError) as e:
        load_schedule(path)
    assert e.value.field == "geoid_undulaton_m"
    assert "flight 'c': unknown field 'geoid_undulaton_m' (known: id, trajectory, counts" in str(e.value)
    path.write_text(json.dumps({"schema": "gisnoise/operations/1", "cards": [omni_card], "flights": flights[:0],
                                "grid": {"resolution": 10}}))
    with pytest.raises(InputError) as e:
        load_schedule(path)
    assert e.value.field == "resolution" and "grid: unknown field 'resolution'" in str(e.value)


def test_real_logs_under_a_schedules_ground_are_refused_or_named(tmp_path, omni_card):
    """The PX4 VTOL log flies at 103-104.5 m and the robologs quad at about 5 m: a schedule's ground at 118 m lies
    above them, refused as `contour --ground-height 118` refuses it, naming the flight.  The ArduPilot log (heights
    above mean sea level, made ellipsoidal with the flight's geoid_undulation_m) takes off from its own ground
    (gisnoise.flight.ground_from_track, the maps' ground rule) about 490 m above 118 m: named, with both grounds."""
    from gisnoise.flight import ground_from_track
    from gisnoise.ops.operations import schedule_findings

    data = Path(__file__).parent / "data"

    def day(log, **flight):
        path = tmp_path / "day.json"
        path.write_text(json.dumps({"schema": "gisnoise/operations/1", "cards": [omni_card], "ground_h_m": 118.0,
                                    "grid": {"resolution_m": 20, "margin_m": 100},
                                    "flights": [{"id": "log", "trajectory": str(log), "counts": {"day": 1},
                                                 **flight}]}))
        return load_schedule(path)

    for log in ("pyulog_sample_log_small_vtol.ulg", "robologs_test_quad_fmuv5.ulg"):
        sched = day(data / log)
        tr = sched.flights[0].trajectory
        lowest = float(np.min(tr.h[tr.flying]))
        assert lowest < 117.0
        with pytest.raises(InputError) as err:
            schedule_findings(sched, sched.receiver_grid())
        with pytest.raises(InputError) as map_err:
            make_map(data / log, [omni_card], None, ground_h=118.0, outputs=("contours",))
        assert err.value.field == "ground_h_m"
        assert str(err.value) == f"{tmp_path / 'day.json'}: flight 'log': ground_h_m: " + \
            str(map_err.value).removeprefix("ground_h: ")
    sched = day(COPTER, geoid_undulation_m=22.0)
    own = ground_from_track(read_route(COPTER, geoid_undulation_m=22.0).trajectory)
    assert own is not None and 480.0 < own - 118.0 < 500.0
    said = [w for w in schedule_findings(sched, sched.receiver_grid())[0] if "own ground" in w]
    assert len(said) == 1 and said[0].startswith(
        f"flight log: its own ground (stated by its route, or its take-off or landing point) lies at {own:.1f} m, "
        f"{own - 118.0:.1f} m above the schedule's ground_h_m 118.0 m: mapped over that ground, its levels under the "
        f"track ")
    assert "dB lower" in said[0] and "give a dem, which maps each flight over its own ground" in said[0]
