"""The Dask path equals the single-process path bit for bit."""

import dataclasses

import numpy as np
import pytest
from affine import Affine

pytest.importorskip("numba")
distributed = pytest.importorskip("distributed")

from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import GridSpec, LocalFrame  # noqa: E402
from gisnoise.maps import segment_cells  # noqa: E402
from gisnoise.model import ModelCard  # noqa: E402
from gisnoise.ops import (  # noqa: E402
    Flight,
    Schedule,
    evaluate_operations,
    local_cluster,  # noqa: E402
    tile_windows,
)

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
FRAME = LocalFrame(LAT0, LON0, 0.0)


def card(phase, **p):
    base = dict(p0=64.0, p1=20.0, p2=0.03, p3=-0.29, p4=-0.05, p5=1.06, p6=1.0, p7=40.0)
    base.update(p)
    return ModelCard(id=phase, vehicle="test", phase=phase, ansatz="paper-offset", parameters=base,
                     reference_power_w=3000.0)


def line_flight(e0, n0, e1, n1, up, v, source):
    dist = np.hypot(e1 - e0, n1 - n0)
    t = np.arange(0.0, dist / v, 1.0)
    f = t / t[-1]
    lat, lon, h = FRAME.to_wgs84(e0 + f * (e1 - e0), n0 + f * (n1 - n0), up + 10 * np.sin(t / 9))
    yaw = np.degrees(np.arctan2(e1 - e0, n1 - n0))
    phase = np.where(t < 8, "climb", "horizontal")
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=5 * np.sin(t / 7), pitch=np.full(t.size, 3.0),
                      yaw=np.full(t.size, yaw), power_w=3000 * (1 + 0.2 * np.cos(t / 5)), phase=phase,
                      source=source)


@pytest.fixture(scope="module")
def city():
    # 4 km x 2 km at 10 m over rough ground; three routes in the western half with
    # day / evening / night counts; the eastern edge is beyond audibility
    g = GridSpec(TMERC, Affine(10.0, 0.0, -1500.0, 0.0, -10.0, 1000.0), 400, 200)
    rng = np.random.default_rng(7)
    dem = 60.0 + np.cumsum(rng.normal(0, 0.3, g.shape), axis=1)
    flights = (Flight("a", line_flight(-1400, -900, 200, 800, 160.0, 25.0, "a"), {"day": 30, "evening": 4}),
               Flight("b", line_flight(-1400, 500, 0, -900, 180.0, 22.0, "b"), {"day": 12, "night": 2}),
               Flight("c", line_flight(-300, 900, 200, -900, 140.0, 20.0, "c"), {"evening": 3, "night": 1.5}))
    sched = Schedule(flights=flights, cards=[card("horizontal"), card("climb", p0=70.0)], grid=g, dem=dem,
                     thresholds_db=(55.0, 65.0), floor_db=50.0)
    tile = 9000  # 12 tiles with edges on the kernel's segments (102 cells)
    one = evaluate_operations(sched, threads=2, tile_cells=tile)
    return sched, tile, one


def assert_identical(a, b):
    assert list(a.bands) == list(b.bands)
    for name in a.bands:
        np.testing.assert_array_equal(a.bands[name], b.bands[name], err_msg=name)


def test_the_case_is_tiled_and_crosses_the_floor(city):
    sched, tile, one = city
    assert one.metadata["tiles"] == len(tile_windows(sched.grid.shape, segment_cells(10.0), tile)) >= 6
    assert 0 < one.metadata["cells_below_floor"] < sched.grid.n_cells
    assert np.isfinite(one.bands["Lden"]).sum() > 0.3 * sched.grid.n_cells


def test_local_cluster_equals_single_process(city):
    sched, tile, one = city
    dask = evaluate_operations(sched, workers=2, tile_cells=tile)
    assert dask.metadata["execution"]["executor"] == "dask"
    assert dask.metadata["execution"]["tasks"] == one.metadata["tiles"] * 3
    assert_identical(one, dask)


def test_existing_scheduler_and_the_environment_setting(city, monkeypatch):
    sched, tile, one = city
    with local_cluster(1) as cluster:
        seen = []
        res = evaluate_operations(sched, scheduler=cluster.scheduler_address, tile_cells=tile, progress=seen.append)
        assert res.metadata["execution"]["scheduler"] == cluster.scheduler_address
        assert seen[-1] == pytest.approx(1.0) and len(seen) == one.metadata["tiles"]
        assert_identical(one, res)
        monkeypatch.setenv("GISNOISE_DASK_SCHEDULER", cluster.scheduler_address)
        res = evaluate_operations(sched, tile_cells=4 * tile)  # other tiles, same cells
        assert res.metadata["execution"]["executor"] == "dask"
        assert_identical(one, res)


def test_floor_keeps_levels_within_a_hundredth_of_a_decibel(city):
    # without the floor every flight is computed everywhere; with it, a level is either
    # within 0.01 dB of that or NaN, and N-above / time above (thresholds >= floor) are exact
    sched, tile, one = city
    exact = evaluate_operations(dataclasses.replace(sched, floor_db=None), threads=2, tile_cells=tile)
    for name in ("Lden", "Lday", "Levening", "Lnight", "LAmax"):
        kept = np.isfinite(one.bands[name])
        assert kept.mean() > 0.3, name
        assert np.max(np.abs(one.bands[name][kept] - exact.bands[name][kept])) <= 0.01, name
    assert np.all(exact.bands["LAmax"][np.isnan(one.bands["LAmax"])] < sched.floor_db)
    for name in one.bands:
        if name.startswith(("NA", "TA")):
            np.testing.assert_array_equal(one.bands[name], exact.bands[name], err_msg=name)
