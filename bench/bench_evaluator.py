"""Evaluator throughput: gisnoise.maps.evaluate.evaluate_grid vs a plain NumPy broadcast, same run.

The baseline forms the whole cells x instants arrays at once (receivers, emission
angles, the ansatz, max and trapezoid energy) with no chunking: the simplest
vectorised code, limited by memory.  The evaluator works in bounded blocks and also
does the bookkeeping a product needs (phases -> cards, progress, cancel, bands).
Both compute LAmax and LAeq of the same directional card on the same grid.  Prints
cell-instants per second, the ratio evaluator / baseline, and peak memory of each
(tracemalloc, which numpy reports to).

    python bench/bench_evaluator.py [n_cells] [n_instants]
"""

from __future__ import annotations

import sys
import time
import tracemalloc

import numpy as np
from affine import Affine

from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, emission_angles, transformer
from gisnoise.maps import evaluate_grid
from gisnoise.model import ModelCard

LAT0, LON0 = 52.27, 10.52
CARD = ModelCard(id="bench", vehicle="bench", phase="horizontal", ansatz="paper-offset",
                 parameters=dict(p0=64.0, p1=20.0, p2=0.03, p3=-0.28, p4=-0.05, p5=1.05, p6=1.0, p7=40.0),
                 reference_power_w=3000.0)


def case(n_cells: int, n_inst: int) -> tuple[Trajectory, GridSpec]:
    frame = LocalFrame(LAT0, LON0, 0.0)
    t = np.linspace(0.0, n_inst / 2.0, n_inst)  # 2 Hz, a 25 m/s circle of 400 m radius, 80 m up
    ang = 25.0 * t / 400.0
    lat, lon, h = frame.to_wgs84(400 * np.sin(ang), 400 * np.cos(ang), np.full(n_inst, 80.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(n_inst, 9.0), pitch=np.zeros(n_inst),
                      yaw=np.degrees(ang) + 90.0, power_w=3000.0 * (1 + 0.2 * np.sin(t / 9)),
                      phase=np.full(n_inst, "horizontal"))
    side = int(round(np.sqrt(n_cells)))
    res = 2000.0 / side
    crs = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
    return traj, GridSpec(crs, Affine(res, 0, -1000.0, 0, -res, 1000.0), side, side)


def baseline(traj: Trajectory, grid: GridSpec) -> dict[str, np.ndarray]:
    """Everything at once: (cells, instants) arrays, no blocks."""
    frame = LocalFrame(*reversed(grid.centre_wgs84()), 0.0)
    x, y = grid.centres()
    lon, lat = transformer(grid.crs, WGS84).transform(x.ravel(), y.ravel())
    rx, ry, rz = frame.to_enu(lat, lon, np.full(lat.shape, 1.5))  # flat ground at h = 0
    sx, sy, sz = frame.to_enu(traj.lat, traj.lon, traj.h)
    d, phi, theta = emission_angles(rx[:, None] - sx, ry[:, None] - sy, rz[:, None] - sz,
                                    np.radians(traj.yaw), np.radians(traj.pitch), np.radians(traj.roll))
    L = CARD.level_uav(CARD.inputs(d, phi, theta, traj.power_w[None, :]))
    w = np.zeros(len(traj))
    dt = np.diff(traj.t)
    w[:-1] += dt / 2
    w[1:] += dt / 2
    energy = np.power(10.0, L / 10.0) @ w
    return {"LAmax": L.max(axis=1).reshape(grid.shape),
            "LAeq": (10 * np.log10(energy / traj.duration_s)).reshape(grid.shape)}


def timed(fn, repeat: int = 3, trace: bool = True):
    """Smallest wall time of ``repeat`` runs (the machine may be shared), the result and peak MB.

    ``trace``: the first run measures the peak memory (tracemalloc, which slows it); without,
    every run is timed alike and the peak is 0.
    """
    best, out, peak = float("inf"), None, 0.0
    for i in range(repeat):
        if i == 0 and trace:
            tracemalloc.start()
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        if i == 0 and trace:
            peak = tracemalloc.get_traced_memory()[1] / 1e6
            tracemalloc.stop()
    return best, out, peak


def main(n_cells: int = 10_000, n_inst: int = 600) -> None:
    traj, grid = case(n_cells, n_inst)
    work = grid.n_cells * len(traj)
    print(f"grid {grid.width} x {grid.height} = {grid.n_cells} cells, {len(traj)} instants: {work / 1e6:.1f} M "
          "cell-instants")
    t_base, ref, m_base = timed(lambda: baseline(traj, grid))
    t_eval, res, m_eval = timed(lambda: evaluate_grid(traj, [CARD], grid, metrics=("LAmax", "LAeq"),
                                                           ground_h=0.0))
    for k in ref:
        diff = float(np.max(np.abs(res.bands[k] - ref[k])))
        assert diff < 1e-6, f"{k} differs from the baseline by {diff} dB"
    print(f"numpy broadcast : {work / t_base / 1e6:8.2f} M cell-instants/s  ({t_base:.3f} s, peak {m_base:.0f} MB)")
    print(f"evaluate_grid   : {work / t_eval / 1e6:8.2f} M cell-instants/s  ({t_eval:.3f} s, peak {m_eval:.0f} MB)")
    print(f"ratio evaluator / broadcast: {t_base / t_eval:.2f} (throughput), memory {m_eval / m_base:.2f}")
    t_unc, _, m_unc = timed(lambda: evaluate_grid(
        traj, [ModelCard(**{**CARD.__dict__, "covariance": tuple(map(tuple, np.eye(8) * 1e-4))})], grid,
        metrics=("LAmax", "LAeq"), uncertainty=True, ground_h=0.0), repeat=1)
    print(f"with uncertainty: {work / t_unc / 1e6:8.2f} M cell-instants/s  ({t_unc:.3f} s, peak {m_unc:.0f} MB)")


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:3]]
    main(*args)
