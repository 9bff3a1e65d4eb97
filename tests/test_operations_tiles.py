"""One process by default: tiles small enough for every thread, a progress that moves, the same bands."""

import numpy as np
import pytest
from affine import Affine

pytest.importorskip("numba")

from gisnoise.flight import Trajectory  # noqa: E402
from gisnoise.geo import GridSpec, LocalFrame  # noqa: E402
from gisnoise.model import ModelCard  # noqa: E402
from gisnoise.ops import Flight, Schedule, evaluate_operations  # noqa: E402

LAT0, LON0 = 52.27, 10.52
TMERC = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def test_default_tiling_feeds_every_thread_and_moves_the_progress():
    frame = LocalFrame(LAT0, LON0, 0.0)
    t = np.arange(0.0, 60.0)
    lat, lon, h = frame.to_wgs84(-600 + 20 * t, 0 * t, np.full(t.size, 100.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.zeros(t.size), pitch=np.zeros(t.size),
                      yaw=np.full(t.size, 90.0), power_w=np.full(t.size, 3000.0),
                      phase=np.full(t.size, "horizontal"), source="line")
    card = ModelCard(id="h", vehicle="test", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=64.0, p1=20.0, p2=0.03, p3=-0.29, p4=-0.05, p5=1.06, p6=1.0, p7=40.0),
                     reference_power_w=3000.0)
    grid = GridSpec(TMERC, Affine(10.0, 0.0, -1000.0, 0.0, -10.0, 500.0), 200, 100)  # 20 000 cells < one tile
    sched = Schedule(flights=(Flight("a", traj, {"day": 10, "night": 1}),), cards=[card], grid=grid,
                     ground_h_m=0.0, thresholds_db=(55.0,))  # a flyover 100 m up: the ground is given
    seen: list[float] = []
    auto = evaluate_operations(sched, threads=2, single_process=True, progress=seen.append)
    whole = evaluate_operations(sched, threads=2, single_process=True, tile_cells=10**6)  # one tile
    assert whole.metadata["tiles"] == 1
    assert auto.metadata["tiles"] >= 16  # eight a thread
    assert len(seen) == auto.metadata["tiles"] and seen == sorted(seen) and seen[-1] == pytest.approx(1.0)
    for name, band in whole.bands.items():  # any tiling with edges on the kernel's segments: the same bits
        assert np.array_equal(auto.bands[name], band, equal_nan=True), name
