"""No data is not nobody: a population raster's nodata cells leave the map uncovered, exactly as where it ends.

Known truth by construction: a raster whose cells beyond a line hold nodata (a national raster beyond a border)
and the same raster clipped at that line hold the same data, so exposure, comparison and route search give the same
counts, uncovered shares, warnings (but for the file's name) and lower-bound flags; the same raster with zeros there
holds data everywhere (nobody lives there) and covers the whole map.
"""

import math

import numpy as np
import pytest
import rasterio
from affine import Affine
from pyproj import CRS

from gisnoise.errors import InputError
from gisnoise.exposure import LevelsRaster, map_exposure, read_population
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, LocalFrame, transformer
from gisnoise.maps import evaluate_grid
from gisnoise.model import ModelCard
from gisnoise.planning import compare_routes, optimize_route

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)
G0, HEIGHT, HR = 70.0, 60.0, 1.5
NODATA = -99999.0  # WorldPop's
ARCSEC3 = 3.0 / 3600.0
BORDER_LON = LON0 + 0.001  # columns whose centre lies east of it: "beyond the border"


def omni(p1=20.0):
    return ModelCard(id="omni", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=G0, p1=p1, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0),
                     reference_power_w=3000.0, phases=("climb", "sink", "hover", "transition"))


def radius_at(level):
    return math.sqrt((40.0 * 10 ** ((G0 - level) / 20.0)) ** 2 - (HEIGHT - HR) ** 2)


def write(path, values, transform, crs, nodata):
    with rasterio.open(path, "w", driver="GTiff", width=values.shape[1], height=values.shape[0], count=1,
                       dtype="float32", crs=CRS.from_user_input(crs).to_wkt(), transform=transform,
                       nodata=nodata) as d:
        d.write(values.astype(np.float32), 1)
    return path


def worldpop_trio(folder):
    """A WorldPop-like raster (EPSG:4326, 3 arc-seconds, 5 people per cell) around the origin, three ways: nodata
    beyond BORDER_LON, clipped there, and zeros there."""
    t = Affine(ARCSEC3, 0.0, LON0 - 0.012, 0.0, -ARCSEC3, LAT0 + 0.007)
    w, h = int(round(0.024 / ARCSEC3)), int(round(0.014 / ARCSEC3))
    lon = t.c + t.a * (np.arange(w) + 0.5)
    beyond = lon > BORDER_LON
    full = np.full((h, w), 5.0)
    nod = write(folder / "border_nodata.tif", np.where(beyond[None, :], NODATA, full), t, "EPSG:4326", NODATA)
    keep = int(np.argmax(beyond))  # the first column beyond: all later ones are too
    clip = write(folder / "border_clipped.tif", full[:, :keep], t, "EPSG:4326", NODATA)
    zero = write(folder / "border_zeros.tif", np.where(beyond[None, :], 0.0, full), t, "EPSG:4326", NODATA)
    return nod, clip, zero, t.c + t.a * keep  # the border: the first nodata column's west edge, deg


@pytest.fixture(scope="module")
def hover_map():
    """A hover 58.5 m above the receivers in the middle of an 800 m map (LAmax above 46.9 dB(A) everywhere)."""
    t = np.arange(0.0, 60.0 + 1e-9, 1.0)
    lat, lon, h = FRAME.to_wgs84(0 * t, 0 * t, np.full_like(t, HEIGHT))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "hover"), source="hover")
    res = evaluate_grid(traj, [omni()], GridSpec(TMERC, Affine(10.0, 0, -400.0, 0, -10.0, 400.0), 80, 80),
                        ground_h=0.0, metrics=("LAmax",))
    return LevelsRaster(dict(res.bands), res.grid, res.units, dict(res.metadata))


def test_nodata_beyond_a_border_is_uncovered_as_the_raster_clipped_there(hover_map, tmp_path):
    nod, clip, zero, border = worldpop_trio(tmp_path)
    pops = {k: read_population(p) for k, p in (("nodata", nod), ("clipped", clip), ("zeros", zero))}
    assert not pops["nodata"].covered.all() and pops["clipped"].covered is None
    docs = {k: map_exposure(hover_map, population=p) for k, p in pops.items()}
    a, b = docs["nodata"]["population"], docs["clipped"]["population"]
    assert a["coverage"] == b["coverage"]
    # the share: the map's part east of the border (the whole map lies above 35 dB(A)), to half a 10 m cell
    x_border = float(transformer(CRS.from_epsg(4326), CRS.from_user_input(TMERC)).transform(border, LAT0)[0])
    assert a["coverage"]["uncovered_share"]["LAmax"] == pytest.approx((400.0 - x_border) / 800.0, abs=5.0 / 800.0)
    assert a["coverage"]["uncovered_share"]["LAmax"] > 0.3
    ma, mb = a["metrics"]["LAmax"], b["metrics"]["LAmax"]
    for key in ("classes", "above"):
        assert [c["lower_bound"] for c in ma[key]] == [c["lower_bound"] for c in mb[key]]
        assert [c["people"] for c in ma[key]] == pytest.approx([c["people"] for c in mb[key]], rel=1e-12)
    # the border lies 91 m east of the hover: the zones above 35 ... 60 dB(A) (r(60) = 112 m) reach beyond it, the
    # one above 65 dB(A) (r = 40 m) does not; the map's own edge (its cells 395 m from the hover: 50.0 dB(A)) makes
    # 35 ... 50 lower bounds anyway
    edge = G0 - 20 * math.log10(math.hypot(395.0, HEIGHT - HR) / 40.0)
    assert 50.0 < edge < 55.0
    assert radius_at(65.0) < x_border < radius_at(60.0)
    assert [c["lower_bound"] for c in ma["above"]] == [e < 65.0 for e in docs["nodata"]["class_edges_db"]]
    said = [w.replace("border_nodata.tif", "X") for w in docs["nodata"]["warnings"]]
    assert said == [w.replace("border_clipped.tif", "X") for w in docs["clipped"]["warnings"]]
    assert any(w.startswith("population: X does not cover the map") for w in said)
    # zeros: data everywhere, nobody beyond the border; the same people, no coverage warning, only the map's edge
    z = docs["zeros"]["population"]
    assert z["coverage"]["uncovered_share"]["LAmax"] == 0.0
    assert not any(w.startswith("population:") for w in docs["zeros"]["warnings"])
    assert [c["people"] for c in z["metrics"]["LAmax"]["above"]] == pytest.approx(
        [c["people"] for c in ma["above"]], rel=1e-12)
    assert [c["lower_bound"] for c in z["metrics"]["LAmax"]["above"]] == [
        e <= edge for e in docs["zeros"]["class_edges_db"]]


def northwards(e):
    t = np.arange(0.0, 2000.0 / 20.0 + 1e-9, 0.5)
    lat, lon, h = FRAME.to_wgs84(np.full_like(t, e), -1000.0 + 20.0 * t, np.full_like(t, HEIGHT))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=0 * t,
                      power_w=np.full_like(t, 3000.0), phase=np.full(t.size, "horizontal"), source=f"e{e:g}")


def test_compare_flags_a_route_over_nodata_as_over_the_raster_clipped_there(tmp_path):
    """0.01 people per m^2 on 50 m cells (TMERC); beyond x = 200 m nodata, or the raster ends there.  The route over
    x = 0 has a third of its zone above 45 dB(A) beyond it: the same shares, flags, counts and warnings both ways."""
    t = Affine(50.0, 0, -2500.0, 0, -50.0, 2000.0)
    full = np.full((80, 100), 25.0)
    x = t.c + t.a * (np.arange(100) + 0.5)
    nod = read_population(write(tmp_path / "nod.tif", np.where(x[None, :] > 200.0, NODATA, full), t, TMERC, NODATA))
    clip = read_population(write(tmp_path / "clip.tif", full[:, :54], t, TMERC, NODATA))  # ends at x = 200 m
    grid = GridSpec(TMERC, Affine(20.0, 0, -1800.0, 0, -20.0, 1800.0), 130, 180)
    docs = {}
    for name, pop in (("nod", nod), ("clip", clip)):
        docs[name] = compare_routes([northwards(0.0), northwards(-1000.0)], [omni()], population=pop,
                                    names=["over", "west"], ground_h=0.0, grid=grid).doc
    for a, b in zip(docs["nod"]["ranking"], docs["clip"]["ranking"], strict=True):
        assert a["route"] == b["route"]
        for key in ("uncovered_share", "population_uncovered_share", "lower_bound", "rank"):
            assert a[key] == b[key], key
        assert list(a["people_above"].values()) == pytest.approx(list(b["people_above"].values()), rel=1e-12)
    over = next(r for r in docs["nod"]["ranking"] if r["route"] == "over")
    assert over["population_uncovered_share"] > 0.3 and over["lower_bound"]["45"]
    assert [w.replace("nod.tif", "X") for w in docs["nod"]["warnings"]] == \
        [w.replace("clip.tif", "X") for w in docs["clip"]["warnings"]]
    assert any("over: the population raster (nod.tif) does not cover" in w for w in docs["nod"]["warnings"])


def pad(e):
    lat, lon, _ = FRAME.to_wgs84(e, 0.0, 0.0)
    return (float(lon), float(lat))


def test_route_search_over_nodata_is_said_as_over_the_raster_clipped_there(tmp_path):
    """The raster ends, or holds nodata, 100 m south of the pads' line: the search ellipse (semi-axes 1875 m and
    1125 m) lies 44.3 % beyond, by its segment; both ways the same share, warnings and route.  A pad on a nodata cell
    is refused as a pad outside the raster; with zeros south of the line the raster covers the whole ellipse."""
    t = Affine(20.0, 0, -2500.0, 0, -20.0, 2000.0)
    full = np.full((200, 250), 0.2)
    south = (np.arange(200) >= 105)[:, None]
    nod = read_population(write(tmp_path / "nod.tif", np.where(south, NODATA, full), t, TMERC, NODATA))
    clip = read_population(write(tmp_path / "clip.tif", full[:105], t, TMERC, NODATA))
    out = {}
    for name, pop in (("nod", nod), ("clip", clip)):
        out[name] = optimize_route(pad(-1500.0), pad(1500.0), [omni(0.0)], population=pop, max_detour_pct=25.0,
                                   resolution_m=25.0, eval_resolution_m=25.0)
    b = 100.0 / math.sqrt(1875.0 ** 2 - 1500.0 ** 2)
    share = (math.acos(b) - b * math.sqrt(1 - b * b)) / math.pi
    s_nod, s_clip = out["nod"].summary, out["clip"].summary
    assert s_nod["search_area_uncovered_share"] == s_clip["search_area_uncovered_share"]
    assert s_nod["search_area_uncovered_share"] == pytest.approx(share, abs=0.01)
    assert [w.replace("nod.tif", "X") for w in s_nod["warnings"]] == \
        [w.replace("clip.tif", "X") for w in s_clip["warnings"]]
    assert np.array_equal(out["nod"].lonlat, out["clip"].lonlat)
    for k in ("people_above_55_direct", "people_above_55_optimized"):
        assert s_nod[k] == pytest.approx(s_clip[k], rel=1e-12), k
    assert s_nod["lower_bound_55_direct"] == s_clip["lower_bound_55_direct"]
    assert s_nod["lower_bound_55_optimized"] == s_clip["lower_bound_55_optimized"]
    lat, lon, _ = FRAME.to_wgs84(0.0, -500.0, 0.0)  # 400 m into the nodata rows
    with pytest.raises(InputError) as e:
        optimize_route(pad(-1500.0), (float(lon), float(lat)), [omni(0.0)], population=nod)
    assert e.value.field == "to" and "cells without data" in str(e.value)
    zeros = read_population(write(tmp_path / "zeros.tif", np.where(south, 0.0, full), t, TMERC, NODATA))
    from gisnoise.exposure import population_coverage

    grid = GridSpec(TMERC, Affine(25.0, 0, -2000.0, 0, -25.0, 1200.0), 160, 96)
    rows, cols = np.nonzero(np.ones(grid.shape, dtype=bool))
    assert population_coverage(zeros, grid, rows, cols).all()
    assert not population_coverage(nod, grid, rows, cols).all()
