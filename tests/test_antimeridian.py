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
from shapely.geometry import Point, Polygon, shape

from gisnoise.cli.main import cli
from gisnoise.flight import Trajectory
from gisnoise.geo import centre_lon, grid_for_points, scale_factor
from gisnoise.maps import crs_scale_warning
from gisnoise.model import ModelCard, save

G0, HEIGHT, SPEED, HALF = 70.0, 60.0, 10.0, 600.0
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
    c = ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                  parameters=dict(p0=G0, p1=20.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                  reference_power_w=3000.0)
    return str(save(c, tmp_path / "omni.json"))


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
