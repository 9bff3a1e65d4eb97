"""Maps across the antimeridian and near the poles.

Contours crossing +-180 deg are cut there (RFC 7946, section 3.1.9) and stay the area the raster holds; the grid's
scale check takes the track's centre on the circle; grids round a pole, or beyond the UTM zones' latitudes in the
default CRS, are refused naming the field to change."""

import json

import numpy as np
import pytest
import rasterio
from click.testing import CliRunner
from pyproj import Geod
from shapely.geometry import MultiPolygon, Point, Polygon, shape
from test_evaluate import G0 as OMNI_G0
from test_evaluate import omni_card

from gisnoise.cli.main import cli
from gisnoise.errors import CRSError, InvalidGridError
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame, centre_lon, grid_for_points, scale_factor
from gisnoise.maps import crs_scale_warning
from gisnoise.maps.antimeridian import split_at_antimeridian
from gisnoise.model import save

G0, HEIGHT, SPEED, HALF = OMNI_G0, 60.0, 10.0, 600.0
LEVELS = (50.0, 60.0)
GEOD = Geod(ellps="WGS84")


def flyover(frame, dt=1.0):
    """A straight eastward flyover at HEIGHT m, 2 HALF m long, centred on ``frame``'s origin."""
    t = np.arange(0.0, 2 * HALF / SPEED + dt / 2, dt)
    x = -HALF + SPEED * t
    lat, lon, h = frame.to_wgs84(x, np.zeros_like(t), np.full_like(t, HEIGHT))
    lon = (np.asarray(lon) + 180.0) % 360.0 - 180.0
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full_like(t, 90.0),
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"))


@pytest.fixture()
def card(tmp_path):
    return str(save(omni_card(), tmp_path / "omni.json"))   # 70 dB(A) at 40 m (G0), spherical spreading


def contour(tmp_path, card, traj, *extra):
    csv = tmp_path / "track.csv"
    traj.to_csv(csv)
    out = tmp_path / "m"
    r = CliRunner().invoke(cli, ["-q", "contour", str(csv), "--card", card, "--out", str(out), "--ground-height",
                                 "0", "--resolution", "10", "--margin", "200", "--metrics", "LAmax", "--levels",
                                 ",".join(f"{v:g}" for v in LEVELS), *extra], catch_exceptions=False)
    return r, out


def positions(geom):
    parts = getattr(geom, "geoms", [geom])
    rings = [r for p in parts for r in ((p.exterior, *p.interiors) if isinstance(p, Polygon) else (p,))]
    return [np.asarray(r.coords) for r in rings]


def loudest_band_against_raster(out, traj):
    """The loudest isoband of ``out``: every track point lies in it and its geodesic area is the area of the raster
    cells at or above its level (their grid area over the CRS's squared scale) within the cells' discretization;
    returns the band."""
    doc = json.loads((out / "contours.geojson").read_text())
    band = next(f for f in doc["features"] if f["properties"]["kind"] == "isoband"
                and f["properties"]["level"] == LEVELS[-1])
    geom = shape(band["geometry"])
    assert geom.is_valid
    assert all(geom.covers(Point(x, y)) for x, y in zip(traj.lon, traj.lat, strict=True))
    area, perimeter = GEOD.geometry_area_perimeter(geom)
    with rasterio.open(out / "levels.tif") as ds:
        z = ds.read(1)
        res = ds.res[0]
        k = scale_factor(ds.crs, centre_lon(traj.lon), float(np.mean(traj.lat)))
    cells = float((z >= LEVELS[-1]).sum()) * res * res / k ** 2
    assert abs(abs(area) - cells) <= perimeter * res / 2, (area, cells, perimeter)
    return doc, geom


def test_a_map_across_the_antimeridian_is_cut_there_and_keeps_its_area(tmp_path, card):
    """A flyover from 179.994 E to 179.994 W: each feature lies within [-180, 180] deg, in pieces that meet at +-180
    and each span well under a degree; the loudest isoband holds every track point and the raster's area; the default
    UTM zone's scale (1.0009 here) gives no warning (the mean of the track's longitudes, near 0, gave 2.2)."""
    traj = flyover(LocalFrame(-16.5, 180.0, 0.0))
    assert traj.lon.max() > 179.99 and traj.lon.min() < -179.99
    r, out = contour(tmp_path, card, traj)
    assert r.exit_code == 0, r.output
    doc, band = loudest_band_against_raster(out, traj)
    assert isinstance(band, MultiPolygon) and len(band.geoms) == 2
    for f in doc["features"]:
        g = shape(f["geometry"])
        assert g.is_valid
        pts = positions(g)
        assert all(np.abs(p[:, 0]).max() <= 180.0 and np.ptp(p[:, 0]) < 0.1 for p in pts)
        lon = np.concatenate([p[:, 0] for p in pts])
        assert (lon == 180.0).any() and (lon == -180.0).any(), f["properties"]["name"]
    assert not any("scales distances" in w for w in doc["gisnoise"]["warnings"])


def test_a_map_beside_the_antimeridian_is_not_cut(tmp_path, card):
    """The same flyover 2 km west of it: nothing reaches 180 deg, nothing is cut, the band stays one polygon."""
    traj = flyover(LocalFrame(-16.5, 179.97, 0.0))
    r, out = contour(tmp_path, card, traj)
    assert r.exit_code == 0, r.output
    _, band = loudest_band_against_raster(out, traj)
    assert isinstance(band, MultiPolygon) and len(band.geoms) == 1 and band.bounds[2] < 180.0


def test_split_keeps_the_polygons_area_and_holes_and_cuts_lines_at_the_crossing():
    """A square with a hole across 180 deg (in longitudes running on) is cut into two valid pieces whose areas sum to
    the square's (the hole lies in the eastern piece); a polygon within [-180, 180] is kept as the same object."""
    ring = np.array([[179.5, 0.0], [180.5, 0.0], [180.5, 1.0], [179.5, 1.0], [179.5, 0.0]])
    hole = np.array([[180.2, 0.2], [180.2, 0.8], [180.4, 0.8], [180.4, 0.2], [180.2, 0.2]])
    inside = [np.array([[10.0, 0.0], [11.0, 0.0], [11.0, 1.0], [10.0, 0.0]])]
    line = np.array([[179.0, 0.0], [181.0, 2.0], [179.5, 2.5]])
    (polys,), (lines,) = split_at_antimeridian([[[ring, hole], inside]], [[line]], 1e-8)
    assert polys[-1] is inside
    pieces = [Polygon(p[0], p[1:]) for p in polys[:-1]]
    assert len(pieces) == 2 and all(p.is_valid and p.exterior.is_ccw for p in pieces)
    assert sum(p.area for p in pieces) == pytest.approx(1.0 - 0.12, abs=1e-12)
    east = next(p for p in pieces if p.bounds[0] == -180.0)
    assert east.bounds == (-180.0, 0.0, -179.5, 1.0) and len(east.interiors) == 1
    assert [a.tolist() for a in lines] == [[[179.0, 0.0], [180.0, 1.0]],
                                           [[-180.0, 1.0], [-179.0, 2.0], [-180.0, 2.33333333]],
                                           [[180.0, 2.33333333], [179.5, 2.5]]]


def test_crs_scale_is_taken_at_the_tracks_centre_on_the_circle():
    """A track from 179.985 E to 179.996 W (lat 16.5 S): the default zone (60 S, EPSG:32760) and zone 1 S
    (EPSG:32701) both have scale within 0.1 % of 1 there and give no warning (at the mean of the longitudes, near 0 deg
    E, the first said 3.4)."""
    lon = (np.linspace(179.985, 180.004, 20) + 180.0) % 360.0 - 180.0
    lat = np.full(lon.size, -16.5)
    assert centre_lon(lon) == pytest.approx(179.9945, abs=1e-9)
    for crs, epsg in ((None, 32760), ("EPSG:32701", 32701)):
        grid = grid_for_points(lon, lat, 10.0, 500.0, crs)
        assert grid.crs.to_epsg() == epsg and crs_scale_warning(grid, lon, lat) is None
        assert scale_factor(grid.crs, 179.9945, -16.5) == pytest.approx(1.0, abs=1e-3)


def test_grids_round_a_pole_are_refused_naming_the_field():
    """A track over the North Pole: refused naming the trajectory; a track 11 km off it with a margin reaching over
    it: refused naming margin_m and a margin that keeps it out (which then works); UTM beyond 84 N: refused naming
    crs and UPS North."""
    lat = np.array([89.99, 89.995, 89.992])
    lon = np.array([0.0, 0.0, 180.0])
    for crs in (None, "EPSG:32661"):
        with pytest.raises(InvalidGridError, match="trajectory: .* North Pole") as e:
            grid_for_points(lon, lat, 10.0, 100.0, crs)
        assert e.value.field == "trajectory"
    lat, lon = np.array([89.9, 89.9]), np.array([10.0, 10.02])
    with pytest.raises(InvalidGridError, match="margin_m: .* North Pole.* a margin under") as e:
        grid_for_points(lon, lat, 100.0, 12000.0, "EPSG:32661")
    assert e.value.field == "margin_m"
    under = float(str(e.value).split("a margin under ")[1].split(" m")[0])
    grid_for_points(lon, lat, 100.0, under, "EPSG:32661")
    with pytest.raises(InvalidGridError, match="South Pole"):
        grid_for_points([0.0, 90.0], [-89.995, -89.995], 10.0, 100.0, "EPSG:32761")
    with pytest.raises(CRSError, match=r"crs: the map reaches 85\.\d\d deg N.*--crs EPSG:32661") as e:
        grid_for_points(lon, lat - 4.9, 10.0, 500.0)
    assert e.value.field == "crs"
    with pytest.raises(CRSError, match=r"crs: the map reaches 80\.0\d deg S.*--crs EPSG:32761"):
        grid_for_points(lon, -np.array([79.996, 79.996]), 10.0, 500.0)
    assert grid_for_points(lon, lat - 4.9, 10.0, 500.0, "EPSG:32661").crs.to_epsg() == 32661
    assert grid_for_points(lon, lat - 6.0, 10.0, 500.0).crs.to_epsg() == 32632  # 83.9 N: UTM zone 32


def test_a_map_beyond_84_north_in_ups_holds_its_track(tmp_path, card):
    """At 85 N, where the default CRS is refused, --crs EPSG:32661 (UPS North, scale 0.9948 there) maps the
    flyover: its loudest isoband holds every track point and the raster's area."""
    traj = flyover(LocalFrame(85.0, 10.0, 0.0))
    r, _ = contour(tmp_path, card, traj)
    assert r.exit_code == 2 and "EPSG:32661" in r.output and len(r.output.strip().splitlines()) == 1
    r, out = contour(tmp_path, card, traj, "--crs", "EPSG:32661")
    assert r.exit_code == 0, r.output
    loudest_band_against_raster(out, traj)
