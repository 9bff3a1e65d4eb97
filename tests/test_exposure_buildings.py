"""Buildings as layers hold them: heights in OpenStreetMap's forms and the most exposed storey, courtyards, and
façade points in ground metres whatever the layer's CRS; against closed-form spherical spreading."""

import math

import numpy as np
import pytest
from affine import Affine
from pyproj import CRS, Geod, Proj

from gisnoise.exposure import (
    LevelsRaster,
    exposure_table,
    facade_levels,
    facade_points,
    map_exposure,
    parse_height,
    read_buildings,
)
from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, transformer
from gisnoise.maps import evaluate_grid
from gisnoise.model import ModelCard

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0 = 70.0  # dB(A) at 40 m in every direction: L = G0 - 20 lg(d / 40 m)
UTM = CRS.from_epsg(32632)
X0, Y0 = transformer(WGS84, UTM).transform(LON0, LAT0)  # the frame's origin in UTM 32N
K_UTM = Proj(UTM).get_factors(LON0, LAT0).meridional_scale  # 0.99974: a UTM metre there is 1/K ground metres


def omni_card(phase="horizontal"):
    p = dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)
    return ModelCard(id=f"omni-{phase}", vehicle="test", phase=phase, ansatz="paper-offset", parameters=p,
                     reference_power_w=3000.0)


def level(d):
    return G0 - 20 * math.log10(d / 40.0)


def hover(up, e=0.0, n=0.0, seconds=60.0):
    """A hover ``up`` m above flat ground at 0 m, over ENU (e, n) of the frame."""
    t = np.arange(0.0, seconds + 1e-9, 1.0)
    lat, lon, h = FRAME.to_wgs84(np.full(t.size, e), np.full(t.size, n), np.full(t.size, up))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t, power_w=np.full(t.size, 3000.0),
                      phase=np.full(t.size, "hover"), source="hover")


def square(cx, cy, w, hole=None):
    """A ``w`` m square footprint in UTM 32N centred ``cx, cy`` m from the frame's origin, with a ``hole`` m square
    courtyard in its middle."""
    from shapely.geometry import Polygon, box

    outer = box(X0 + cx - w / 2, Y0 + cy - w / 2, X0 + cx + w / 2, Y0 + cy + w / 2)
    if hole is None:
        return outer
    inner = box(X0 + cx - hole / 2, Y0 + cy - hole / 2, X0 + cx + hole / 2, Y0 + cy + hole / 2)
    return Polygon(outer.exterior.coords, [inner.exterior.coords[::-1]])


def layer(path, geoms, crs=UTM, **columns):
    import geopandas as gpd

    gpd.GeoDataFrame(columns, geometry=list(geoms), crs=UTM).to_crs(crs).to_file(path, engine="pyogrio")
    return path


def small_map(traj):
    """A 200 m map about the frame's origin (the exposure document needs one)."""
    grid = GridSpec(TMERC, Affine(20.0, 0.0, -100.0, 0.0, -20.0, 100.0), 10, 10)
    res = evaluate_grid(traj, [omni_card("hover")], grid, ground_h=0.0, metrics=("LAmax", "SEL"))
    return LevelsRaster(dict(res.bands), res.grid, res.units, dict(res.metadata))


# --- heights -----------------------------------------------------------------------------------------------------

def test_heights_in_openstreetmaps_forms_are_read_and_others_are_unknown_with_one_warning(tmp_path):
    """'10', '10 m', '10.5m' are metres, '12 ft' and 40'6" feet (0.3048 m); a value that is none of these (text,
    a negative or zero height) is unknown for its building, never a refusal of the layer, and one warning says how
    many and shows the first; a null is unknown without a word.  building:levels the same, as numbers."""
    heights = ["15", "10 m", "10.5m", "12 ft", "about 10", None, "-4", "40'6\"", "0"]
    levels = ["5", "3", None, "1", "3;4", "2", "2", None, None]
    path = layer(tmp_path / "osm.gpkg", [square(30.0 * i, 0.0, 10.0) for i in range(len(heights))],
                 height=heights, **{"building:levels": levels})
    b = read_buildings(path)
    want = [15.0, 10.0, 10.5, 12 * 0.3048, np.nan, np.nan, np.nan, 40.5 * 0.3048, np.nan]
    np.testing.assert_allclose(b.height_m, want, rtol=1e-12)
    np.testing.assert_array_equal(b.levels, [5, 3, np.nan, 1, np.nan, 2, 2, np.nan, np.nan])
    assert b.fields["height"] == "height" and b.fields["levels"] == "building:levels"
    h_said = [w for w in b.warnings if "of 'height'" in w]
    l_said = [w for w in b.warnings if "of 'building:levels'" in w]
    assert len(h_said) == 1 and len(l_said) == 1
    assert h_said[0].startswith("buildings: osm.gpkg: 3 of 9 buildings have a value of 'height' (height) that is "
                                "not a height in m or ft")
    assert "(first feature 4: 'about 10'): unknown, so those buildings take their storeys from 'building:levels'" \
        in h_said[0]
    assert "1 of 9 buildings" in l_said[0] and "first feature 4: '3;4'" in l_said[0]
    assert all("\n" not in w for w in b.warnings)


def test_a_height_in_feet_equals_the_same_height_in_metres():
    assert parse_height("196.85 ft") == pytest.approx(196.85 * 0.3048, rel=1e-12) == pytest.approx(60.0, abs=2e-4)
    assert parse_height("60") == parse_height("60 m") == parse_height(60) == 60.0


# --- the most exposed storey --------------------------------------------------------------------------------------

@pytest.mark.parametrize("attrs", [{"height": ["60 m", None]}, {"height": [60.0, None]},
                                   {"height": ["196.85 ft", None]},
                                   {"height": [None, None], "building:levels": [20, None]}],
                         ids=["60 m", "60.0", "ft", "levels"])
def test_top_storey_under_a_hover_is_louder_than_the_facade_at_4_m_by_spherical_spreading(tmp_path, attrs):
    """A 60 m tower of 20 x 20 m (or 20 storeys x 3 m) with a drone hovering 100 m above its centre, an
    omnidirectional card.  Storeys: round(60 / 3) = 20 of 3 m, receivers at their middles; the loudest is the top
    one at 58.5 m.  The nearest façade points stand at the middles of the 5 m segments next to each wall's middle,
    0.1 m out: r = hypot(10.1, 2.5) m from the centre (in UTM metres; ground metres / 0.99974) for the 4 m receiver
    and the top storey's alike.  So LAmax at the top storey exceeds the 4 m level by 20 lg(d_4m / d_top), d the
    distances to the drone; SEL by the same (a hover at constant distance).  A building without a height (20 m
    away from the tower) gets the 4 m level alone."""
    up, top = 100.0, 60.0 - 3.0 / 2
    path = layer(tmp_path / "tower.gpkg", [square(0.0, 0.0, 20.0), square(40.0, 0.0, 20.0)], residents=[80, 6],
                 **attrs)
    b = read_buildings(path)
    traj = hover(up)
    fl = facade_levels(b, traj, [omni_card("hover")], ground_h=0.0)
    st = fl["storeys"]["buildings"]
    r = math.hypot(10.1, 2.5) / K_UTM
    d4, dtop = math.hypot(r, up - 4.0), math.hypot(r, up - top)
    la = fl["buildings"]["LAmax"]["level"]
    assert la[0] == pytest.approx(level(d4), abs=2e-3)
    assert st["LAmax"]["level"][0] == pytest.approx(level(dtop), abs=2e-3)
    assert st["LAmax"]["level"][0] - la[0] == pytest.approx(20 * math.log10(d4 / dtop), abs=1e-3)
    assert st["SEL"]["level"][0] - fl["buildings"]["SEL"]["level"][0] == pytest.approx(20 * math.log10(d4 / dtop),
                                                                                        abs=1e-3)
    assert st["LAmax"]["storey"][0] == 20 and st["LAmax"]["z_m"][0] == pytest.approx(top, abs=1e-3)
    # the building without a height: its façade at 4 m, no storey
    assert np.isfinite(la[1]) and math.isnan(st["LAmax"]["level"][1]) and st["LAmax"]["point"][1] == -1
    assert fl["storeys"]["points"].storeys.tolist() == [20, 0]

    doc = map_exposure(small_map(traj), buildings=b, trajectory=traj, cards=[omni_card("hover")])
    bm = doc["buildings"]["metrics"]["LAmax"]
    assert bm["per_building_db"][0] == pytest.approx(level(d4), abs=2e-3)  # classed at 4 m, as before
    s = bm["storeys"]
    assert s["per_building_db"][0] == pytest.approx(level(dtop), abs=2e-3) and s["per_building_db"][1] is None
    assert s["per_building_storey"] == [20, None] and s["per_building_receiver_m"][1] is None
    assert s["most_exposed"]["building"] == 0 and s["most_exposed"]["storey"] == 20
    assert doc["buildings"]["facade"]["storeys"]["per_building_storeys"] == [20, 0]
    assert doc["buildings"]["facade"]["storeys"]["buildings_with_height"] == 1
    text = exposure_table(doc)
    assert "most exposed storeys (1 of 2 buildings with a height; the others are judged at 4 m alone):" in text
    assert f"| 0 | 20 of 20 | 58.5 | {level(dtop):.1f} | {level(d4):.1f} |" in text


def test_a_layer_without_heights_gets_no_storeys(tmp_path):
    """No height or storeys attribute: the document is as before, façades at 4 m alone, no storeys key."""
    path = layer(tmp_path / "flat.gpkg", [square(0.0, 0.0, 20.0)], residents=[5])
    b = read_buildings(path)
    traj = hover(50.0)
    fl = facade_levels(b, traj, [omni_card("hover")], ground_h=0.0)
    assert fl["storeys"] is None
    doc = map_exposure(small_map(traj), buildings=b, trajectory=traj, cards=[omni_card("hover")])
    assert "storeys" not in doc["buildings"]["facade"] and "storeys" not in doc["buildings"]["metrics"]["LAmax"]
    assert "most exposed storeys" not in exposure_table(doc)


# --- courtyards ---------------------------------------------------------------------------------------------------

def test_a_courtyard_block_equals_the_same_block_drawn_as_four_wings(tmp_path):
    """A 120 m block around a 100 m courtyard, a drone hovering 30 m above the courtyard's centre.  The courtyard's
    walls face outdoor air: their receivers stand 0.1 m into the courtyard, so the nearest ones are 49.9 m out
    and 2.5 m along a wall (the middles of its 5 m segments) from the centre: LAmax = G0 - 20 lg(d / 40), d from
    that geometry.  The same block drawn as four wings (no hole) gives the same level; dropping the hole left
    the outer walls alone, 60.1 m out (0.5 dB lower)."""
    from shapely.geometry import MultiPolygon, Point, box

    court = square(0.0, 0.0, 120.0, hole=100.0)
    wings = MultiPolygon([box(X0 - 60, Y0 + 50, X0 + 60, Y0 + 60), box(X0 - 60, Y0 - 60, X0 + 60, Y0 - 50),
                          box(X0 - 60, Y0 - 50, X0 - 50, Y0 + 50), box(X0 + 50, Y0 - 50, X0 + 60, Y0 + 50)])
    b = read_buildings(layer(tmp_path / "court.gpkg", [court, wings], residents=[400, 400]))
    up = 30.0
    fl = facade_levels(b, hover(up), [omni_card("hover")], ground_h=0.0, metrics=("LAmax",))
    d = math.hypot(math.hypot(49.9, 2.5) / K_UTM, up - 4.0)
    la = fl["buildings"]["LAmax"]["level"]
    assert la[0] == pytest.approx(level(d), abs=2e-3)
    assert la[0] == pytest.approx(la[1], abs=1e-6)
    assert la[0] - level(math.hypot(math.hypot(60.1, 2.5) / K_UTM, up - 4.0)) > 0.5
    # every receiver of the courtyard block stands in the air, 0.1 m off a wall: 4 x 24 outside, 4 x 20 inside
    pts = fl["points"]
    mine = pts.building == 0
    assert int(mine.sum()) == 96 + 80
    inside = [court.exterior.distance(Point(x, y)) > 1.0 for x, y in zip(pts.x[mine], pts.y[mine], strict=True)]
    assert sum(inside) == 80
    for x, y in zip(pts.x[mine], pts.y[mine], strict=True):
        p = Point(x, y)
        assert not court.contains(p) and court.boundary.distance(p) == pytest.approx(0.1, abs=1e-6)
    p = int(fl["buildings"]["LAmax"]["point"][0])
    assert pts.wall[p] >= 4  # a wall of the courtyard: walls 0-3 are the exterior ring's


# --- ground metres whatever the CRS ---------------------------------------------------------------------------------

def test_facade_points_are_in_ground_metres_in_utm_web_mercator_and_wgs84(tmp_path):
    """The same buildings in UTM 32N, EPSG:3857 and EPSG:4326: the same façade points (5 m segments of ground
    metres: 16 on a 20 m box, 96 + 80 on the courtyard block, 20 on a 25 m tower) and the same levels.  In
    Web Mercator units (1.63 per ground metre at 52.27 N) the spacing was 3.1 m and the box had 28 points."""
    geoms = [square(60.0, 0.0, 20.0), square(-80.0, 40.0, 120.0, hole=100.0), square(0.0, -90.0, 25.0)]
    traj = hover(40.0)
    got = {}
    for crs in ("EPSG:32632", "EPSG:3857", "EPSG:4326"):
        b = read_buildings(layer(tmp_path / f"b{crs[5:]}.gpkg", geoms, crs=crs, height=[12.0, 9.0, 60.0]))
        assert b.crs.to_epsg() == int(crs[5:])
        fl = facade_levels(b, traj, [omni_card("hover")], ground_h=0.0, metrics=("LAmax",))
        pts = fl["points"]
        assert [int(np.sum(pts.building == k)) for k in range(3)] == [16, 176, 20], crs
        # neighbours on the box's first wall: 5 m apart in UTM metres (ground metres x 0.99974)
        on = np.flatnonzero((pts.building == 0) & (pts.wall == 0))
        _, _, step = Geod(ellps="WGS84").inv(pts.lon[on[0]], pts.lat[on[0]], pts.lon[on[1]], pts.lat[on[1]])
        assert step == pytest.approx(5.0 / K_UTM, abs=1e-3), crs
        got[crs] = (fl["buildings"]["LAmax"]["level"], fl["storeys"]["buildings"]["LAmax"]["level"])
    for crs in ("EPSG:3857", "EPSG:4326"):
        np.testing.assert_allclose(got[crs][0], got["EPSG:32632"][0], atol=1e-6)
        np.testing.assert_allclose(got[crs][1], got["EPSG:32632"][1], atol=1e-6)


def test_a_crs_in_feet_places_points_in_ground_metres(tmp_path):
    """A layer in a CRS whose unit is the US survey foot (NAD83 / New York Long Island): 5 m spacing, not 5 ft."""
    import geopandas as gpd
    from shapely.geometry import box

    ny = CRS.from_epsg(2263)
    x, y = transformer(WGS84, ny).transform(-73.98, 40.75)
    w = 20.0 / 0.3048006  # 20 m in US feet
    p = tmp_path / "ny.gpkg"
    gpd.GeoDataFrame({"residents": [10]}, geometry=[box(x, y, x + w, y + w)], crs=ny).to_file(p, engine="pyogrio")
    pts = facade_points(read_buildings(p))
    assert pts.x.size == 16


def test_a_day_of_operations_gives_the_most_exposed_storey_too(tmp_path):
    """A day of one hover 100 m above a 60 m tower (40 flights by day, 8 in the evening, 4 at night): Lden, Lday,
    Lnight and LAmax at the top storey all exceed those at 4 m by 20 lg(d_4m / d_top) (one geometry for every
    flight; the period sums scale alike), and N-above counts the flights there."""
    from gisnoise.exposure import operations_facade_levels
    from gisnoise.ops import Flight, Schedule

    up, top = 100.0, 60.0 - 3.0 / 2
    b = read_buildings(layer(tmp_path / "tower.gpkg", [square(0.0, 0.0, 20.0)], height=["60 m"]))
    sched = Schedule(flights=(Flight("A", hover(up), {"day": 40, "evening": 8, "night": 4}),),
                     cards=[omni_card("hover")], ground_h_m=0.0, thresholds_db=(65.0,), receiver_height_m=4.0)
    fl = operations_facade_levels(b, sched, ground_h=0.0)
    r = math.hypot(10.1, 2.5) / K_UTM
    d4, dtop = math.hypot(r, up - 4.0), math.hypot(r, up - top)
    st = fl["storeys"]["buildings"]
    assert level(d4) < 65.0 < level(dtop)
    for n in ("Lden", "Lday", "Levening", "Lnight", "LAmax"):
        assert st[n]["level"][0] - fl["buildings"][n]["level"][0] == pytest.approx(20 * math.log10(d4 / dtop),
                                                                                    abs=1e-3), n
    assert fl["buildings"]["LAmax"]["level"][0] == pytest.approx(level(d4), abs=2e-3)
    assert fl["buildings"]["NA65"]["level"][0] == 0 and st["NA65"]["level"][0] == 52
    assert st["Lden"]["storey"][0] == 20


def test_the_command_reads_osm_heights_names_the_unreadable_and_takes_the_storey_height(tmp_path):
    """`gisnoise exposure --buildings` with heights as an OSM extract holds them: a value that does not read is
    named in a warning on stderr and the layer is read; --height-field names the attribute; --storey-height 4
    makes a 60 m tower 15 storeys, its top receiver at 60 - 2 = 58 m."""
    import json

    from click.testing import CliRunner

    from gisnoise.cli.main import cli
    from gisnoise.maps import write_geotiff
    from gisnoise.model import save

    up = 100.0
    traj = hover(up)
    traj.to_csv(tmp_path / "hover.csv")
    card = str(save(omni_card("hover"), tmp_path / "omni.json"))
    grid = GridSpec(TMERC, Affine(20.0, 0.0, -100.0, 0.0, -20.0, 100.0), 10, 10)
    write_geotiff(evaluate_grid(traj, [omni_card("hover")], grid, ground_h=0.0, metrics=("LAmax",)),
                  tmp_path / "map" / "levels.tif")
    layer(tmp_path / "osm.gpkg", [square(0.0, 0.0, 20.0), square(40.0, 0.0, 20.0)], residents=[80, 6],
          roof_h=["60 m", "tall"])
    r = CliRunner().invoke(cli, ["-q", "exposure", str(tmp_path / "map"), "--buildings", str(tmp_path / "osm.gpkg"),
                                 "--height-field", "roof_h", "--storey-height", "4", "--trajectory",
                                 str(tmp_path / "hover.csv"), "--card", card], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    said = [w for w in r.stderr.splitlines() if "'roof_h'" in w]
    assert len(said) == 1 and said[0].startswith("warning: buildings: osm.gpkg: 1 of 2 buildings have a value of "
                                                 "'roof_h' (height) that is not a height") and "'tall'" in said[0]
    doc = json.loads((tmp_path / "map" / "exposure.json").read_text())
    assert doc["buildings"]["facade"]["storeys"]["per_building_storeys"] == [15, 0]
    s = doc["buildings"]["metrics"]["LAmax"]["storeys"]
    assert s["per_building_receiver_m"][0] == pytest.approx(58.0, abs=1e-9)
    d4, dtop = (math.hypot(math.hypot(10.1, 2.5) / K_UTM, up - z) for z in (4.0, 58.0))
    assert s["per_building_db"][0] == pytest.approx(level(dtop), abs=2e-3)
    assert doc["buildings"]["metrics"]["LAmax"]["per_building_db"][0] == pytest.approx(level(d4), abs=2e-3)


def test_contour_with_buildings_takes_the_same_height_options(tmp_path):
    """`gisnoise contour --buildings` reads the layer as `exposure` does: --height-field names the attribute and
    --storey-height 4 makes the 60 m tower 15 storeys, its top receiver at 58 m, its level the closed form there."""
    import json

    from click.testing import CliRunner

    from gisnoise.cli.main import cli
    from gisnoise.model import save

    up = 100.0
    hover(up).to_csv(tmp_path / "hover.csv")
    card = str(save(omni_card("hover"), tmp_path / "omni.json"))
    layer(tmp_path / "osm.gpkg", [square(0.0, 0.0, 20.0), square(40.0, 0.0, 20.0)], residents=[80, 6],
          roof_h=["60 m", "tall"])
    r = CliRunner().invoke(cli, ["-q", "contour", str(tmp_path / "hover.csv"), "--card", card, "--out",
                                 str(tmp_path / "map"), "--ground-height", "0", "--resolution", "20", "--metrics",
                                 "LAmax", "--buildings", str(tmp_path / "osm.gpkg"), "--height-field", "roof_h",
                                 "--storey-height", "4"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    doc = json.loads((tmp_path / "map" / "exposure.json").read_text())
    assert doc["buildings"]["facade"]["storeys"]["per_building_storeys"] == [15, 0]
    s = doc["buildings"]["metrics"]["LAmax"]["storeys"]
    assert s["per_building_receiver_m"][0] == pytest.approx(58.0, abs=1e-9)
    dtop = math.hypot(math.hypot(10.1, 2.5) / K_UTM, up - 58.0)
    assert s["per_building_db"][0] == pytest.approx(level(dtop), abs=2e-3)
