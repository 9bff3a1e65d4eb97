"""Trajectories from flight CSV, GeoJSON LineStrings with times and waypoints (SPEC section 7)."""

import json
import math

import numpy as np
import pytest

from gisnoise.errors import InputError, TrajectoryError
from gisnoise.flight import (
    GRAVITY,
    Trajectory,
    VehicleModel,
    read_route,
    read_trajectory,
    route_from_waypoints,
    trajectory_to_geojson,
)
from gisnoise.geo import LocalFrame

LAT0, LON0 = 52.27, 10.52
FRAME = LocalFrame(LAT0, LON0, 0.0)


def wp(e, n, alt, **kw):
    lat, lon, _ = FRAME.to_wgs84(e, n, 0.0)
    return {"lon": float(lon), "lat": float(lat), "alt": alt, **kw}


def enu(traj):
    return FRAME.to_enu(traj.lat, traj.lon, traj.h)


def delivery(**settings):
    """Vertical take-off to 80 m, 0.8 km east, a 90 deg left turn, 1 km north, vertical landing."""
    wps = [wp(0, 0, 0), wp(0, 0, 80), wp(800, 0, 80), wp(800, 1000, 80), wp(800, 1000, 0)]
    return route_from_waypoints(wps, {"sample_dt_s": 0.2, **settings}).trajectory


def test_flight_csv_is_read_as_is(tmp_path):
    t = np.arange(5.0)
    traj = Trajectory(t=t, lat=np.full(5, LAT0), lon=LON0 + 1e-4 * t, h=np.full(5, 50.0), roll=t, pitch=-t,
                      yaw=10 * t, power_w=np.full(5, 2000.0), phase=np.full(5, "hover"))
    traj.to_csv(tmp_path / "f.csv")
    back = read_trajectory(tmp_path / "f.csv")
    for k in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w"):  # every column, as written
        np.testing.assert_allclose(getattr(back, k), getattr(traj, k), rtol=0, atol=1e-9, err_msg=k)
    assert list(back.phase) == ["hover"] * 5


def test_vertical_take_off_follows_the_trapezoid_profile():
    traj = delivery()
    v = VehicleModel()
    # 80 m at 3 m/s with 1 m/s^2: 80/3 + 3/1 = 29.67 s of climb
    climb = traj.t[traj.phase == "climb"]
    assert climb[0] == 0.0 and climb[-1] == pytest.approx(80 / v.climb_rate_m_s + v.climb_rate_m_s, abs=0.21)
    e, n, u = enu(traj)
    assert np.all(np.hypot(e[traj.phase == "climb"], n[traj.phase == "climb"]) < 0.01)  # straight up
    assert traj.h[0] == pytest.approx(0.0, abs=0.01) and traj.h[-1] == pytest.approx(0.0, abs=0.01)
    i = int(np.argmin(np.abs(traj.t - 11.5)))
    assert traj.power_w[i] == pytest.approx(float(v.rotor_power_w(v.weight_n, 3.0)) + v.systems_power_w, rel=1e-6)


def test_phases_in_order_take_off_to_landing():
    traj = delivery()
    runs = [p for i, p in enumerate(traj.phase) if i == 0 or p != traj.phase[i - 1]]
    assert runs == ["climb", "transition", "horizontal", "transition", "sink"]
    v = VehicleModel()
    assert np.all(traj.airspeed_m_s[traj.phase == "horizontal"] >= v.transition_speed_m_s - 1e-6)
    assert np.all(traj.airspeed_m_s[traj.phase == "transition"] <= v.transition_speed_m_s + 1e-6)
    # transition from rest to 18 m/s at 1.5 m/s^2 takes 12 s
    tr = traj.t[traj.phase == "transition"]
    first = tr[tr < traj.duration_s / 2]
    assert first[-1] - first[0] == pytest.approx(18.0 / 1.5, abs=0.5)


def test_coordinated_turn_bank_is_atan_v2_over_gR():
    traj = delivery()
    v = VehicleModel()
    cruise = v.cruise_speed_m_s
    radius = cruise ** 2 / (GRAVITY * math.tan(math.radians(v.max_bank_deg)))
    turning = np.abs(traj.roll) > 1.0
    assert np.degrees(np.arctan(cruise ** 2 / (GRAVITY * radius))) == pytest.approx(v.max_bank_deg)
    np.testing.assert_allclose(traj.roll[turning], -v.max_bank_deg, atol=1e-6)  # a left turn: roll negative
    # the turn takes a quarter circle at cruise speed: (pi/2) R / v
    dt = traj.t[1] - traj.t[0]
    assert turning.sum() * dt == pytest.approx(0.5 * np.pi * radius / cruise, abs=2 * dt)
    # heading from east (90 deg) to north (0 deg); the track on the arc stays at distance R from the centre
    assert traj.yaw[turning][0] == pytest.approx(90.0, abs=3.0) and traj.yaw[turning][-1] == pytest.approx(0.0, abs=3)
    e, n, _ = enu(traj)
    centre = np.array([800.0 - radius, 0.0 + radius])
    r = np.hypot(e[turning] - centre[0], n[turning] - centre[1])
    np.testing.assert_allclose(r, radius, atol=0.05)
    # power in the turn: induced drag grows with the load factor n = 1/cos(bank)
    level = (traj.phase == "horizontal") & ~turning & (np.abs(traj.pitch) < 0.01) & (traj.airspeed_m_s > 24.99)
    p_level = np.median(traj.power_w[level])
    p_turn = np.median(traj.power_w[turning])
    expected = float(v.power_w(cruise, 0.0, math.radians(v.max_bank_deg), 0.0) - v.power_w(cruise, 0.0, 0.0, 0.0))
    assert p_turn - p_level == pytest.approx(expected, abs=1.0)  # W; earth curvature tilts the legs by 0.005 deg


def test_short_legs_tighten_the_turn_and_slow_down():
    # legs of 60 m: the fillet radius shrinks to fit and the speed drops to keep the bank at 30 deg
    wps = [wp(0, 0, 80), wp(200, 0, 80), wp(200, 60, 80), wp(260, 60, 80), wp(460, 60, 80)]
    traj = route_from_waypoints(wps, {"sample_dt_s": 0.1}).trajectory
    # 90 deg turns between 60 m legs: each fillet's tangent length R tan(45 deg) = R is at most half a
    # leg, R = 30 m; at 30 deg bank the coordinated turn allows v = sqrt(g R tan 30 deg) = 13.03 m/s
    radius = 30.0
    v_turn = math.sqrt(GRAVITY * radius * math.tan(math.radians(30.0)))
    assert np.max(np.abs(traj.roll)) == pytest.approx(30.0, abs=1e-6)
    assert traj.airspeed_m_s.min() == pytest.approx(v_turn, abs=0.01)
    assert traj.airspeed_m_s[0] == pytest.approx(25.0)  # the route starts in flight
    # the first (left) turn at (200, 0): centre (170, 30), the track on the arc 30 m from it
    e, n, _ = enu(traj)
    first = (np.abs(traj.roll) > 1.0) & (n < 15.0)
    assert first.sum() > 10
    np.testing.assert_allclose(np.hypot(e[first] - 170.0, n[first] - 30.0), radius, atol=0.05)


def test_hold_hovers_for_its_duration():
    wps = [wp(0, 0, 0), wp(0, 0, 30, hold_s=20.0), wp(0, 0, 0)]
    traj = route_from_waypoints(wps, {"sample_dt_s": 0.5}).trajectory
    hover = traj.t[traj.phase == "hover"]
    assert hover[-1] - hover[0] == pytest.approx(20.0, abs=0.51)
    assert np.all(traj.power_w[traj.phase == "hover"] == pytest.approx(VehicleModel().hover_power_w()))


def test_hover_power_is_momentum_theory():
    v = VehicleModel(mass_kg=20.0, rotor_disk_area_m2=1.0, figure_of_merit=1.0, motor_efficiency=1.0,
                     systems_power_w=1.0)
    t = 20.0 * GRAVITY
    assert v.hover_power_w() == pytest.approx(t ** 1.5 / math.sqrt(2 * 1.225 * 1.0) + 1.0, rel=1e-12)


def test_altitude_references(tmp_path):
    base = [wp(0, 0, 0), wp(0, 0, 50)]
    agl = read_route({"schema": "gisnoise/waypoints/1", "ground_h_m": 120.0, "waypoints": base})
    assert agl.ground_h_m == 120.0 and agl.trajectory.h.max() == pytest.approx(170.0, abs=1e-6)
    msl = read_route({"schema": "gisnoise/waypoints/1", "altitude_reference": "msl", "geoid_undulation_m": 44.0,
                      "waypoints": [wp(0, 0, 100), wp(0, 0, 150)]})
    assert msl.ground_h_m is None and msl.trajectory.h.max() == pytest.approx(194.0, abs=1e-6)


def test_geojson_points_equal_the_waypoints_document(tmp_path):
    wps = [wp(0, 0, 0), wp(0, 0, 40), wp(500, 300, 60, speed=20.0), wp(500, 300, 0)]
    doc = {"schema": "gisnoise/waypoints/1", "sample_dt_s": 1.0, "waypoints": wps}
    fc = {"type": "FeatureCollection", "route": {"sample_dt_s": 1.0}, "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [w["lon"], w["lat"], w["alt"]]},
         "properties": {k: v for k, v in w.items() if k == "speed"}} for w in wps]}
    (tmp_path / "r.geojson").write_text(json.dumps(fc))
    a = read_trajectory(doc)
    b = read_trajectory(tmp_path / "r.geojson")
    np.testing.assert_allclose(a.t, b.t)
    np.testing.assert_allclose(a.lat, b.lat)
    np.testing.assert_allclose(a.power_w, b.power_w)
    assert a.airspeed_m_s.max() == pytest.approx(20.0)


def test_linestring_with_times_round_trips_and_derives_the_bank():
    # a circle of radius 200 m at 20 m/s, 60 m up: bank = atan(v^2 / (g R)) to the right (clockwise)
    r, v = 200.0, 20.0
    t = np.arange(0.0, 60.0, 0.5)
    ang = v * t / r
    e, n = r * np.sin(ang), r * np.cos(ang)  # clockwise from north
    lat, lon, h = FRAME.to_wgs84(e, n, np.full_like(t, 60.0))
    feat = {"type": "Feature", "geometry": {"type": "LineString",
                                            "coordinates": np.column_stack([lon, lat, h]).tolist()},
            "properties": {"times": t.tolist()}}
    traj = read_trajectory(feat)
    np.testing.assert_allclose(traj.h, h, atol=1e-9)
    mid = slice(5, -5)
    np.testing.assert_allclose(traj.roll[mid], np.degrees(np.arctan(v ** 2 / (GRAVITY * r))), atol=0.05)
    np.testing.assert_allclose(traj.airspeed_m_s[mid], v, rtol=1e-3)
    assert set(traj.phase) == {"horizontal"}
    course = np.degrees(ang + np.pi / 2)  # tangent of a clockwise circle
    np.testing.assert_allclose(((traj.yaw - course + 180) % 360 - 180)[mid], 0.0, atol=0.3)
    # [lon, lat, z, t] positions and an exported trajectory read back the same
    feat4 = {"type": "Feature", "geometry": {"type": "LineString",
                                             "coordinates": np.column_stack([lon, lat, h, t]).tolist()}}
    np.testing.assert_allclose(read_trajectory(feat4).roll, traj.roll)
    back = read_trajectory(trajectory_to_geojson(traj))
    for k in ("t", "lat", "lon", "h", "roll", "pitch", "yaw", "power_w"):
        np.testing.assert_allclose(getattr(back, k), getattr(traj, k), atol=1e-9)


def test_linestring_without_times_is_flown_as_waypoints():
    coords = [[w["lon"], w["lat"], w["alt"]] for w in (wp(0, 0, 80), wp(1000, 0, 80))]
    traj = read_trajectory({"type": "LineString", "coordinates": coords})
    assert traj.duration_s == pytest.approx(1000.0 / 25.0, rel=1e-4)  # 80 m up: the arc is 1.2 cm longer


@pytest.mark.parametrize("doc, field", [
    ({"schema": "gisnoise/waypoints/1", "waypoints": [{"lat": 52.0, "alt": 0}, {"lon": 10, "lat": 52, "alt": 9}]},
     "lon"),
    ({"schema": "gisnoise/waypoints/1", "waypoints": [{"lon": 10, "lat": 52, "alt": 0}]}, "waypoints"),
    ({"schema": "gisnoise/waypoints/2", "waypoints": []}, "schema"),
    ({"schema": "gisnoise/waypoints/1", "altitude_reference": "sea", "waypoints": []}, "altitude_reference"),
    ({"schema": "gisnoise/waypoints/1", "waypoints": [{"lon": 10, "lat": 52, "alt": 0},
                                                      {"lon": 10, "lat": 52, "alt": 9, "phase": "loiter"}]}, "phase"),
    ({"schema": "gisnoise/waypoints/1", "vehicle": {"mass_kg": -1}, "waypoints": [
        {"lon": 10, "lat": 52, "alt": 0}, {"lon": 10, "lat": 52, "alt": 9}]}, "vehicle.mass_kg"),
    ({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[10, 52, 5], [10.1, 52, 5]]},
      "properties": {"times": [0.0]}}, "times"),
    ({"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[10, 52, 5], [10.1, 52, 5]]},
      "properties": {"times": [1.0, 1.0]}}, "times"),
    ({"type": "Polygon", "coordinates": []}, "trajectory"),
])
def test_bad_documents_name_the_field(doc, field):
    with pytest.raises(InputError) as exc:
        read_trajectory(doc)
    assert exc.value.field == field


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(TrajectoryError, match="no such trajectory file"):
        read_trajectory(tmp_path / "none.csv")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(TrajectoryError, match="malformed JSON at line 1") as exc:
        read_trajectory(tmp_path / "bad.json")
    assert exc.value.field == "json"


def test_sample_route_is_a_delivery_flight():
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
    route = read_route(path)
    traj = route.trajectory
    runs = [p for i, p in enumerate(traj.phase) if i == 0 or p != traj.phase[i - 1]]
    assert runs[0] == "climb" and runs[-1] == "sink" and "horizontal" in runs and "transition" in runs
    assert np.abs(traj.roll).max() > 10.0  # it turns
    e, n, u = FRAME.to_enu(traj.lat, traj.lon, traj.h)
    assert np.hypot(e[-1] - e[0], n[-1] - n[0]) > 1000.0  # a real distance
    # the file's own waypoints: lift-off at the first pad, landing on the last, altitudes above the
    # document's flat ground (agl, ground_h_m), the highest cruise altitude 100 m
    doc = json.loads(path.read_text())
    pts = [f["geometry"]["coordinates"] for f in doc["features"]]
    alts = [f["properties"]["alt"] for f in doc["features"]]
    ground = doc["route"]["ground_h_m"]
    assert route.ground_h_m == ground
    assert (traj.lon[0], traj.lat[0]) == pytest.approx(tuple(pts[0][:2]), abs=1e-9)
    assert (traj.lon[-1], traj.lat[-1]) == pytest.approx(tuple(pts[-1][:2]), abs=1e-9)
    assert traj.h[0] == pytest.approx(ground + alts[0], abs=0.01)
    assert traj.h[-1] == pytest.approx(ground + alts[-1], abs=0.01)
    assert traj.h.max() == pytest.approx(ground + max(alts), abs=0.01)
    climb = traj.phase == "climb"
    np.testing.assert_allclose(traj.lon[climb], pts[0][0], atol=1e-9)  # straight up from the pad
    assert traj.h[climb].max() == pytest.approx(ground + alts[1], abs=0.01)


def test_agl_altitudes_stand_on_the_dem(tmp_path):
    import rasterio
    from affine import Affine

    from gisnoise.geo import apply_affine

    x0, y0 = 634000.0, 5794500.0  # UTM 32N near the test origin
    tr = Affine(10.0, 0, x0, 0, -10.0, y0)
    rows, cols = np.mgrid[0:150, 0:150]
    xs, ys = apply_affine(tr, cols + 0.5, rows + 0.5)
    with rasterio.open(tmp_path / "dem.tif", "w", driver="GTiff", width=150, height=150, count=1,
                       dtype="float64", crs="EPSG:32632", transform=tr) as ds:
        ds.write(100.0 + 0.02 * (xs - x0), 1)  # a slope rising eastwards, 2 %
    from gisnoise.geo import WGS84, parse_crs, transformer

    lon, lat = transformer(parse_crs("EPSG:32632"), WGS84).transform([x0 + 300.0, x0 + 1200.0],
                                                                       [y0 - 700.0, y0 - 700.0])
    wps = [{"lon": lon[0], "lat": lat[0], "alt": 0}, {"lon": lon[0], "lat": lat[0], "alt": 50},
           {"lon": lon[1], "lat": lat[1], "alt": 50}]
    route = read_route({"schema": "gisnoise/waypoints/1", "waypoints": wps}, dem=tmp_path / "dem.tif",
                       dem_offset_m=40.0)
    assert route.ground_h_m is None
    h = route.trajectory.h
    assert h[0] == pytest.approx(100.0 + 0.02 * 300.0 + 40.0, abs=0.01)
    assert h[-1] == pytest.approx(100.0 + 0.02 * 1200.0 + 40.0 + 50.0, abs=0.01)


def _timed(coords, **doc):
    return {"type": "FeatureCollection", **doc, "features": [
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords},
         "properties": {"times": [0.0, 60.0], "altitude_reference": "agl"}}]}


def test_a_route_in_a_projected_crs_is_refused_naming_the_positions():
    # RFC 7946 positions are WGS84 longitude, latitude: UTM metres are not degrees (before: "origin lat0 must be
    # within [-90, 90] deg, got 5789919.97", naming a field the user never wrote)
    utm = [[602398.3, 5789904.5, 50.0], [603898.3, 5789904.5, 50.0]]
    with pytest.raises(TrajectoryError, match=r"coordinates: vertex 0 is \(602398.30, 5789904.50\), not WGS84") as e:
        read_trajectory(_timed(utm))
    assert e.value.field == "coordinates"
    # the pre-RFC 7946 crs member naming it is refused, not ignored; one naming WGS84 longitude, latitude is read
    named = {"crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:EPSG::25832"}}}
    with pytest.raises(TrajectoryError, match="crs: GeoJSON positions are WGS84 .*EPSG::25832") as e:
        read_trajectory(_timed(utm, **named))
    assert e.value.field == "crs"
    deg = [[LON0, LAT0, 50.0], [LON0 + 0.02, LAT0, 50.0]]
    crs84 = {"crs": {"type": "name", "properties": {"name": "urn:ogc:def:crs:OGC:1.3:CRS84"}}}
    np.testing.assert_array_equal(read_trajectory(_timed(deg, **crs84)).lon, read_trajectory(_timed(deg)).lon)
