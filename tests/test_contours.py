"""GeoJSON contours: RFC 7946 structure and analytic isobands."""

import json

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LinearRing, shape

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame
from gisnoise.maps import (
    contours_geojson,
    evaluate_grid,
    grid_for_trajectory,
    isobands,
    isolines,
    parse_levels,
    write_geojson,
)
from gisnoise.model import ModelCard

LAT0, LON0 = 48.137, 11.575  # lat and lon far apart: a swapped order cannot pass


def hover_result(metrics=("LAmax", "LAeq")):
    """A 30 s hover of an omnidirectional card 40 m above flat ground at 500 m: levels of spherical spreading."""
    f = LocalFrame(LAT0, LON0, 500.0)
    lat, lon, h = f.to_wgs84(np.zeros(2), np.zeros(2), np.full(2, 40.0))
    traj = Trajectory(t=np.array([0.0, 30.0]), lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2),
                      yaw=np.zeros(2), power_w=np.full(2, 3000.0), phase=np.full(2, "hover"))
    card = ModelCard(id="omni", vehicle="t", phase="hover", ansatz="paper-offset",
                     parameters=dict(p0=70.0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    grid = grid_for_trajectory(traj, 10.0, 400.0)
    return evaluate_grid(traj, [card], grid, ground_h=500.0, metrics=metrics)


@pytest.fixture(scope="module")
def hover_map():
    return hover_result()


def test_geojson_is_rfc7946(hover_map, tmp_path):
    path = write_geojson(hover_map, tmp_path / "c.geojson", [45, 50, 55, 60])
    doc = json.loads(path.read_text())
    assert doc["type"] == "FeatureCollection" and "crs" not in doc
    assert doc["features"]
    holes = 0
    for feat in doc["features"]:
        props = feat["properties"]
        assert props["metric"] in ("LAmax", "LAeq") and props["kind"] in ("isoband", "isoline")
        assert isinstance(props["level"], float) and "level_max" in props
        geom = feat["geometry"]
        if props["kind"] == "isoband":
            assert geom["type"] == "MultiPolygon"
            for poly in geom["coordinates"]:
                for k, ring in enumerate(poly):
                    assert ring[0] == ring[-1] and len(ring) >= 4  # closed
                    lon, lat = np.array(ring).T
                    assert np.all(np.abs(lon - LON0) < 0.01) and np.all(np.abs(lat - LAT0) < 0.01)  # lon, lat
                    ccw = LinearRing(ring).is_ccw
                    assert ccw if k == 0 else not ccw  # right-hand rule: exterior CCW, holes CW
                    holes += k > 0
            assert shape(geom).is_valid
        else:
            assert geom["type"] == "MultiLineString"
            for line in geom["coordinates"]:
                lon, lat = np.array(line).T
                assert np.all(np.abs(lon - LON0) < 0.01) and np.all(np.abs(lat - LAT0) < 0.01)
    assert holes > 0  # bands around a loud centre have holes; their orientation was checked


def test_bands_are_nested_and_open_at_the_top(hover_map):
    doc = contours_geojson(hover_map, "50,55,60", metrics=["LAmax"])
    bands = {f["properties"]["level"]: f for f in doc["features"] if f["properties"]["kind"] == "isoband"}
    assert bands[60.0]["properties"]["level_max"] is None
    assert bands[55.0]["properties"]["level_max"] == 60.0
    outer55 = shapely.union_all([shape(bands[55.0]["geometry"]), shape(bands[60.0]["geometry"])])
    # bands tile the plane without overlap: the union of [55,60) and [60,inf) is the disc L >= 55
    assert shape(bands[55.0]["geometry"]).intersection(shape(bands[60.0]["geometry"])).area < 1e-12
    assert len(outer55.geoms if hasattr(outer55, "geoms") else [outer55]) == 1
    # the omnidirectional hover 38.5 m above the receivers: L >= L_c on the disc of horizontal radius
    # r_c = sqrt(D_c^2 - 38.5^2), D_c = 40 m * 10^((70 - L_c) / 20) (spherical spreading); areas in the
    # local east/north plane of the hover point
    frame = LocalFrame(LAT0, LON0, 500.0)

    def local_area(geom):
        def to_en(lonlat):
            e, n, _ = frame.to_enu(lonlat[:, 1], lonlat[:, 0], np.full(len(lonlat), 500.0))
            return np.column_stack([e, n])

        return shapely.transform(geom, to_en).area

    def radius(level):
        return np.sqrt((40.0 * 10 ** ((70.0 - level) / 20.0)) ** 2 - 38.5 ** 2)

    assert local_area(shape(bands[60.0]["geometry"])) == pytest.approx(np.pi * radius(60.0) ** 2, rel=5e-3)
    assert local_area(shape(bands[55.0]["geometry"])) == pytest.approx(
        np.pi * (radius(55.0) ** 2 - radius(60.0) ** 2), rel=5e-3)
    assert local_area(outer55) == pytest.approx(np.pi * radius(55.0) ** 2, rel=5e-3)


def test_isoband_area_of_a_cone_is_the_disc():
    x = y = np.linspace(-100.0, 100.0, 201)
    z = 70.0 - 0.1 * np.hypot(*np.meshgrid(x, y))  # L = 65 at r = 50, L = 62 at r = 80
    (band,) = isobands(x, y, z, [62.0, 65.0])  # annulus 50 <= r <= 80
    assert band.area == pytest.approx(np.pi * (80 ** 2 - 50 ** 2), rel=2e-3)
    assert len(band.interiors) == 1
    (ring,) = isolines(x, y, z, 65.0)
    assert ring.is_closed and shapely.Polygon(ring).area == pytest.approx(np.pi * 50 ** 2, rel=2e-3)


def test_nan_cells_are_left_out():
    x = y = np.linspace(0.0, 10.0, 11)
    z = np.full((11, 11), 60.0)
    z[:, :5] = np.nan
    polys = isobands(x, y, z, [55.0, 65.0])
    assert sum(p.area for p in polys) == pytest.approx(50.0)  # x from 5 to 10, y from 0 to 10


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(20, 120, allow_nan=False), min_size=1, max_size=6))
def test_parse_levels_sorts_and_dedups(levels):
    out = parse_levels(",".join(repr(v) for v in levels))
    assert out == sorted(set(levels))


@pytest.mark.parametrize("metrics", [("LAeq", "LAmax"), ("SEL", "LAeq"), ("SEL", "LAmax", "LAeq")])
def test_geojson_lists_the_contoured_metrics_in_band_order_even_without_contours(metrics, tmp_path):
    """gisnoise.metrics of contours.geojson is the GeoTIFF's band descriptions in their order (SPEC 5: LAmax, LAeq,
    SEL), also when no level is reached (199 dB(A): no feature); it was sorted (LAeq before LAmax), and empty
    without a contour."""
    import rasterio

    from gisnoise.maps import contours_text, write_geotiff

    res = hover_result(metrics)
    with rasterio.open(write_geotiff(res, tmp_path / "levels.tif")) as ds:
        bands = list(ds.descriptions)
    assert bands == [m for m in ("LAmax", "LAeq", "SEL") if m in metrics]
    for levels, no_feature in (([45.0, 60.0], False), ([199.0], True)):
        doc = contours_geojson(res, levels)
        assert doc["gisnoise"]["metrics"] == bands
        assert json.loads(contours_text(res, levels))["gisnoise"]["metrics"] == bands
        written = json.loads(write_geojson(res, tmp_path / "c.geojson", levels).read_text())
        assert written["gisnoise"]["metrics"] == bands
        if no_feature:
            assert doc["features"] == []
        else:  # the features follow the same order
            assert list(dict.fromkeys(f["properties"]["metric"] for f in doc["features"])) == bands


def test_parse_levels_errors():
    for bad in ("", "55,abc", "inf"):
        with pytest.raises(InputError) as exc:
            parse_levels(bad)
        assert exc.value.field == "levels"


@pytest.mark.parametrize("bad", [-1000.0, -50.5, 200.5, 1e308])
def test_parse_levels_refuses_levels_no_microphone_records(bad):
    """A contour level outside [-50, 200] dB(A) (gisnoise.limits.MEASURED_LEVEL_RANGE_DB) is refused in one line
    naming the field, the value, the range and why; before, -1000 drew a band 'LAmax -1000-45 dB(A)'."""
    with pytest.raises(InputError) as exc:
        parse_levels([60, 45, bad])
    msg = str(exc.value)
    assert exc.value.field == "levels" and "\n" not in msg
    assert msg.startswith(f"levels: {bad:g} dB(A) is outside [-50, 200] dB(A)")
    assert "microphone" in msg


def test_parse_levels_keeps_the_ends_of_the_range_and_merges_duplicates():
    assert parse_levels([200, -50, 45, 45.0, "45"]) == [-50.0, 45.0, 200.0]
    assert parse_levels("60,45,45") == [45.0, 60.0]
