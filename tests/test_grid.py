"""Receiver grids, UTM choice, cell limit, DEM resampling and the GeoTIFF writer."""

import numpy as np
import pytest
import rasterio
from affine import Affine
from hypothesis import given, settings
from hypothesis import strategies as st

from gisnoise.errors import CRSError, GridTooLargeError, InvalidGridError
from gisnoise.flight import Trajectory
from gisnoise.geo import (
    GridSpec,
    apply_affine,
    parse_crs,
    read_dem,
    resample_dem,
    sample_dem,
    utm_crs,
)
from gisnoise.maps import NODATA, MapResult, grid_for_trajectory, write_geotiff


def track(lon, lat):
    lon = np.asarray(lon, float)
    lat = np.asarray(lat, float)
    n = lon.size
    return Trajectory(t=np.arange(n, dtype=float), lat=lat, lon=lon, h=np.full(n, 100.0), roll=np.zeros(n),
                      pitch=np.zeros(n), yaw=np.zeros(n), power_w=np.full(n, 3000.0), phase=np.full(n, "horizontal"))


@pytest.mark.parametrize("lon, lat, epsg", [(10.52, 52.27, 32632), (13.4, 52.5, 32633), (-0.12, 51.5, 32630),
                                            (151.2, -33.9, 32756), (-179.9, 0.0, 32601), (179.9, 0.0, 32660)])
def test_utm_zone(lon, lat, epsg):
    assert utm_crs(lon, lat).to_epsg() == epsg


def test_grid_covers_track_plus_margin_snapped_to_resolution():
    traj = track([10.50, 10.53], [52.26, 52.28])
    g = grid_for_trajectory(traj, 10.0, 250.0)
    x, y = g.from_wgs84(traj.lon, traj.lat)
    left, bottom, right, top = g.bounds
    assert left <= x.min() - 250 and right >= x.max() + 250 and bottom <= y.min() - 250 and top >= y.max() + 250
    assert left > x.min() - 260 and top < y.max() + 260  # not more than one cell extra
    for v in (left, bottom, right, top):
        assert v % 10.0 == pytest.approx(0.0, abs=1e-6)
    assert g.n_cells == g.width * g.height


def test_given_crs_and_crs_errors():
    traj = track([10.50, 10.51], [52.26, 52.27])
    assert grid_for_trajectory(traj, 20, 100, crs="EPSG:25832").crs.to_epsg() == 25832
    for bad in ("EPSG:999999", "not a crs", "EPSG:4326", "+proj=longlat +datum=WGS84", "EPSG:2263"):
        with pytest.raises(CRSError) as exc:
            grid_for_trajectory(traj, 20, 100, crs=bad)
        assert exc.value.field == "crs"


def test_cell_limit_from_environment(monkeypatch):
    traj = track([10.50, 10.51], [52.26, 52.27])
    monkeypatch.setenv("GISNOISE_MAX_CELLS", "1000")
    with pytest.raises(GridTooLargeError, match="exceeds the limit of 1,000 cells") as exc:
        grid_for_trajectory(traj, 10, 100)
    assert exc.value.field == "resolution_m"
    monkeypatch.setenv("GISNOISE_MAX_CELLS", "lots")
    with pytest.raises(InvalidGridError) as exc:
        grid_for_trajectory(traj, 10, 100)
    assert exc.value.field == "GISNOISE_MAX_CELLS"
    monkeypatch.delenv("GISNOISE_MAX_CELLS")
    assert grid_for_trajectory(traj, 10, 100).n_cells < 25_000_000


@pytest.mark.parametrize("kw, field", [({"resolution_m": 0}, "resolution_m"), ({"resolution_m": float("nan")},
                                       "resolution_m"), ({"margin_m": -1}, "margin_m")])
def test_bad_resolution_or_margin(kw, field):
    traj = track([10.50, 10.50], [52.26, 52.26])  # a hover: two samples, one place
    args = {"resolution_m": 10.0, "margin_m": 100.0, **kw}
    with pytest.raises(InvalidGridError) as exc:
        grid_for_trajectory(traj, **args)
    assert exc.value.field == field


@settings(max_examples=40, deadline=None)
@given(res=st.floats(0.5, 50), w=st.integers(1, 40), h=st.integers(1, 40), x0=st.floats(-1e5, 1e5),
       y0=st.floats(-1e5, 1e5))
def test_cell_centres_are_transform_of_half_pixels(res, w, h, x0, y0):
    g = GridSpec("EPSG:32632", Affine(res, 0, 500000 + x0, 0, -res, 5.8e6 + y0), w, h)
    x, y = g.centres()
    rows, cols = np.mgrid[0:h, 0:w]
    ex, ey = apply_affine(g.transform, cols + 0.5, rows + 0.5)
    np.testing.assert_allclose(x, ex, atol=1e-6)
    np.testing.assert_allclose(y, ey, atol=1e-6)
    fx, fy = g.flat_centres(0, g.n_cells)
    np.testing.assert_allclose(fx, x.ravel())
    np.testing.assert_allclose(fy, y.ravel())


def test_rotated_or_south_up_transforms_are_refused():
    with pytest.raises(InvalidGridError):
        GridSpec("EPSG:32632", Affine(10, 1, 0, 0, -10, 0), 3, 3)
    with pytest.raises(InvalidGridError):
        GridSpec("EPSG:32632", Affine(10, 0, 0, 0, 10, 0), 3, 3)


def write_plane_dem(path, crs="EPSG:32632", res=30.0, x0=600000.0, y0=5795000.0, n=60):
    """h = 0.01 x' + 0.02 y' + 100 (x', y' from the DEM's corner): a plane, so bilinear is exact."""
    tr = Affine(res, 0, x0, 0, -res, y0)
    rows, cols = np.mgrid[0:n, 0:n]
    xs, ys = apply_affine(tr, cols + 0.5, rows + 0.5)
    z = 0.01 * (xs - x0) + 0.02 * (ys - y0) + 100.0
    z[0, 0] = -32768.0
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32", crs=crs,
                       transform=tr, nodata=-32768.0) as ds:
        ds.write(z.astype(np.float32), 1)
    return lambda x, y: 0.01 * (x - x0) + 0.02 * (y - y0) + 100.0


def test_dem_resampled_bilinear_to_the_grid(tmp_path):
    plane = write_plane_dem(tmp_path / "dem.tif")
    dem = read_dem(tmp_path / "dem.tif")
    assert np.isnan(dem.heights[0, 0])  # nodata -> NaN
    g = GridSpec("EPSG:32632", Affine(10.0, 0, 600300.0, 0, -10.0, 5794700.0), 50, 40)
    z = resample_dem(dem, g)
    x, y = g.centres()
    np.testing.assert_allclose(z, plane(x, y), atol=2e-3)  # float32 storage
    outside = GridSpec("EPSG:32632", Affine(10.0, 0, 590000.0, 0, -10.0, 5794700.0), 5, 5)
    assert np.isnan(resample_dem(dem, outside)).all()
    lon, lat = g.to_wgs84(x[5, 7], y[5, 7])
    assert float(sample_dem(dem, lon, lat)) == pytest.approx(plane(x[5, 7], y[5, 7]), abs=2e-3)


def test_geotiff_bands_crs_transform_nodata(tmp_path):
    g = GridSpec("EPSG:25832", Affine(5.0, 0, 604000.0, 0, -5.0, 5793000.0), 7, 4)
    a = np.arange(28, dtype=float).reshape(4, 7)
    b = a * 0.5
    b[1, 2] = np.nan
    res = MapResult(bands={"LAmax": a, "TA55": b}, grid=g, metadata={"units": {"LAmax": "dB(A)", "TA55": "s"}})
    p = write_geotiff(res, tmp_path / "levels.tif")
    with rasterio.open(p) as ds:
        assert ds.crs.to_epsg() == 25832
        assert ds.transform == g.transform
        assert ds.descriptions == ("LAmax", "TA55")
        assert ds.nodata == NODATA and ds.dtypes == ("float32", "float32")
        assert ds.tags(2)["unit"] == "s"
        np.testing.assert_array_equal(ds.read(1), a.astype(np.float32))
        m = ds.read(2, masked=True)
        assert m.mask[1, 2] and m.mask.sum() == 1
        # pixel (row 1, col 2) centre: the receiver of that cell
        assert ds.xy(1, 2) == pytest.approx(tuple(v[1, 2] for v in g.centres()))


def test_parse_crs_accepts_projected_metre_crs():
    assert parse_crs("EPSG:3035").to_epsg() == 3035


def test_transformer_is_cached_per_thread_by_the_identity_of_its_crss():
    """One cache rule with crs_label: the same CRS objects give the same transformer in one thread, another
    thread builds its own (transformers are not shared), and an equal CRS object transforms the same."""
    import threading

    from pyproj import CRS

    from gisnoise.geo import WGS84, transformer

    utm = CRS.from_epsg(32632)
    tr = transformer(WGS84, utm)
    assert transformer(WGS84, utm) is tr
    other: list = []
    t = threading.Thread(target=lambda: other.append(transformer(WGS84, utm)))
    t.start()
    t.join()
    assert other[0] is not tr
    x, y = transformer(WGS84, CRS.from_epsg(32632)).transform(9.0, 0.0)  # zone 32's central meridian, equator
    assert (x, y) == pytest.approx((500000.0, 0.0), abs=1e-6) and tr.transform(9.0, 0.0) == (x, y)
    for k in range(70):  # more pairs than the cache holds: each pair still gets its own transformer
        code = 32633 + k % 2
        assert transformer(WGS84, CRS.from_epsg(code)).transform(6.0 * (code - 32600) - 183.0, 0.0) == \
            pytest.approx((500000.0, 0.0), abs=1e-6)


def test_crs_label_is_the_authority_code_else_the_wkt_cached_by_identity():
    from pyproj import CRS

    from gisnoise.geo import crs_label

    utm = CRS.from_epsg(32632)
    assert crs_label(utm) == "EPSG:32632" and crs_label(utm) == "EPSG:32632"  # the second call: the cache
    assert crs_label(CRS.from_epsg(32632)) == "EPSG:32632"  # an equal CRS, another object
    local = CRS.from_proj4("+proj=tmerc +lat_0=52 +lon_0=10.5 +k=1 +x_0=0 +y_0=0 +ellps=GRS80 +units=m")
    assert local.to_authority() is None
    assert crs_label(local) == local.to_wkt()
    for k in range(70):  # more objects than the cache holds, of two CRSs in turn: each gets its own label
        code = 32633 + k % 2
        assert crs_label(CRS.from_epsg(code)) == f"EPSG:{code}"


def test_scale_factor_is_projs_cached_by_crs_object_and_point():
    """Transverse Mercator keeps k0 = 0.9996 along a UTM zone's central meridian; Web Mercator scales by
    sec(latitude) (2 at 60 deg, 1 on the equator).  The cache answers each CRS object and point with its own
    value, also when asked in turn, from another thread, and past its size."""
    import math
    import threading

    from pyproj import CRS

    from gisnoise.geo import scale_factor

    utm, web = CRS.from_epsg(32632), CRS.from_epsg(3857)
    for _ in range(2):  # the second round: from the cache
        assert scale_factor(utm, 9.0, 52.0) == pytest.approx(0.9996, abs=1e-9)
        assert scale_factor(web, 9.0, 60.0) == pytest.approx(2.0, abs=1e-8)
        assert scale_factor(web, 9.0, 0.0) == pytest.approx(1.0, abs=1e-8)
        assert scale_factor(CRS.from_epsg(3857), 9.0, 60.0) == pytest.approx(2.0, abs=1e-8)  # an equal CRS
    other: list = []
    t = threading.Thread(target=lambda: other.append(scale_factor(web, 9.0, 45.0)))
    t.start()
    t.join()
    assert other[0] == pytest.approx(math.sqrt(2.0), abs=1e-8)
    for k in range(300):  # more points than a CRS's table holds
        lat = -60.0 + 0.4 * k
        assert scale_factor(web, 9.0, lat) == pytest.approx(1.0 / math.cos(math.radians(lat)), rel=1e-8)


def test_grid_for_points_keeps_the_projected_extent_of_the_same_points(monkeypatch):
    """Zone 32's central meridian on the equator projects to (500 000 m, 0 m): the grid around it is the
    margin snapped to the cells, for each resolution and margin asked again; other points get their own extent,
    the cell limit holds for a kept extent too, and a CRS given as text is one object for the same points (so the
    transformer cache hits)."""
    from gisnoise.geo import grid_for_points

    for _ in range(2):
        g = grid_for_points([9.0], [0.0], 10.0, 100.0)
        assert g.crs.to_epsg() == 32632 and tuple(g.transform)[:6] == (10.0, 0.0, 499900.0, 0.0, -10.0, 100.0)
        assert (g.width, g.height) == (20, 20)
        g = grid_for_points([9.0], [0.0], 25.0, 60.0)
        assert tuple(g.transform)[:6] == (25.0, 0.0, 499925.0, 0.0, -25.0, 75.0) and (g.width, g.height) == (6, 6)
    g = grid_for_points([9.0, 9.0], [0.0, 0.01], 10.0, 100.0)  # 0.9996 x 1105.74 m of meridian arc further north
    assert (g.width, g.height) == (20, 131) and g.transform.f == 1210.0  # top edge: 1105.30 + 100 m snapped up
    text = grid_for_points([9.0], [0.0], 10.0, 100.0, crs="EPSG:32632")
    assert grid_for_points([9.0], [0.0], 10.0, 100.0, crs="EPSG:32632").crs is text.crs
    monkeypatch.setenv("GISNOISE_MAX_CELLS", "399")
    with pytest.raises(GridTooLargeError):
        grid_for_points([9.0], [0.0], 10.0, 100.0)


def test_coarse_cells_are_a_map_warning_and_the_loss_they_name_holds(omni_card):
    """A straight level flight 50 m above the receivers (ground 0 m, receivers 1.5 m, track 51.5 m), 2 m between
    samples: right under it LAmax is 65 - 20 lg(50 / 40) = 63.06 dB(A) (the omni card: 65 dB(A) at 40 m,
    spherical spreading).  The nearest cell centre lies at most res / sqrt(2) beside the track, so the map's
    maximum falls short by at most 10 lg(1 + (res / sqrt(2) / 50)^2); that exceeds 1 dB above
    sqrt(2) 50 sqrt(10^0.1 - 1) = 35.98 m: 30 m cells pass silently, 100 m and 5000 m cells are named with
    their loss bound and 35 m cells to use instead."""
    from gisnoise.geo import LocalFrame
    from gisnoise.maps import make_map
    from gisnoise.maps.grids import coarse_cell_loss_db

    frame = LocalFrame(52.27, 10.52, 0.0)
    t = np.arange(0.0, 60.0 + 1e-9, 0.1)  # 20 m/s eastwards: 2 m between samples, e = -600 ... 600 m
    lat, lon, h = frame.to_wgs84(-600.0 + 20.0 * t, np.zeros_like(t), np.full_like(t, 51.5))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full_like(t, 90.0),
                      power_w=np.full_like(t, 300.0), phase=np.full(t.size, "horizontal"))
    truth = 65.0 - 20.0 * np.log10(50.0 / 40.0)
    for res, warned in ((30.0, False), (100.0, True), (5000.0, True)):
        paths = make_map(traj, [omni_card], None, resolution_m=res, margin_m=100.0, ground_h=0.0,
                         metrics=("LAmax",), levels=(60.0,), outputs=("contours",))
        loss = float(coarse_cell_loss_db(res, 50.0))
        top = float(np.nanmax(paths["result"].bands["LAmax"]))
        assert truth - loss - 0.01 <= top <= truth + 0.01, (res, top, truth, loss)
        said = [w for w in paths["warnings"] if w.startswith("resolution:")]
        assert paths["result"].metadata["warnings"] == paths["warnings"]
        if not warned:
            assert loss < 1.0 and said == []
            continue
        assert loss > 1.0 and len(said) == 1, paths["warnings"]
        assert f"cells of {res:g} m are coarse for a flight 50.0 m above the receivers" in said[0]
        assert f"low by up to {loss:.1f} dB" in said[0] and "cells of 35 m or finer keep that within 1 dB" in said[0]
    assert coarse_cell_loss_db(35.0, 50.0) <= 1.0 < coarse_cell_loss_db(36.0, 50.0)
