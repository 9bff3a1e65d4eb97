"""Speed and scale: the fast engine, the NumPy engine and a plain broadcast baseline, in one run.

Prints, side by side and as ratios against baselines measured in the same run:

1. throughput (cell-instants per second, wall and CPU) of the fast kernel, the NumPy
   engine (``evaluate_grid``) and a plain NumPy broadcast of the whole cells x instants
   arrays, on the same grid and trajectory, with the largest level difference to the
   NumPy engine;
2. how the fast engine's cost grows with grid size and trajectory length (a table);
3. the aim case: a 2000 x 2000 grid and a 10-minute flight at 1 Hz, wall time and the
   peak memory of a process that does only that;
4. a city-scale day of operations (many delivery flights over a 10 km x 8 km grid) on a
   local Dask cluster with 1 and 2 workers, against the single-process path, with the
   workers' peak memory and a bitwise comparison of the bands.

    python bench/bench_speed.py [--quick]

``--quick`` uses smaller cases (a minute).  The machine may be shared: the load average
is printed before and after, and CPU times are printed beside wall times.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import time

import numpy as np
from affine import Affine

from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, emission_angles, transformer
from gisnoise.maps import evaluate_grid, evaluate_grid_fast
from gisnoise.model import ModelCard, load

LAT0, LON0 = 52.27, 10.52
CRS = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
HERE = os.path.dirname(os.path.abspath(__file__))
CARDS = os.path.join(HERE, "..", "gisnoise", "data", "cards")
CARD = ModelCard(id="bench", vehicle="bench", phase="horizontal", ansatz="paper-offset",
                 parameters=dict(p0=64.0, p1=20.0, p2=0.03, p3=-0.29, p4=-0.05, p5=1.06, p6=1.0, p7=40.0),
                 reference_power_w=3000.0)


def flight(n: int, dt: float = 1.0, speed: float = 25.0, radius: float = 600.0) -> Trajectory:
    """A banked circle at 80 m, ``n`` samples every ``dt`` s (a 10-minute flight: n = 601)."""
    frame = LocalFrame(LAT0, LON0, 0.0)
    t = np.arange(n) * dt
    ang = speed * t / radius
    lat, lon, h = frame.to_wgs84(radius * np.sin(ang), radius * np.cos(ang), np.full(n, 80.0))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(n, 6.0), pitch=np.full(n, 2.0),
                      yaw=np.degrees(ang) + 90.0, power_w=3000.0 * (1 + 0.2 * np.sin(t / 9)),
                      phase=np.full(n, "horizontal"), source="circle")


def square_grid(side: int, extent_m: float = 2000.0) -> GridSpec:
    res = extent_m / side
    return GridSpec(CRS, Affine(res, 0, -extent_m / 2, 0, -res, extent_m / 2), side, side)


def baseline(traj: Trajectory, grid: GridSpec) -> dict[str, np.ndarray]:
    """The plain broadcast: whole (cells, instants) arrays at once, float64, no blocks."""
    frame = LocalFrame(*reversed(grid.centre_wgs84()), 0.0)
    x, y = grid.centres()
    lon, lat = transformer(grid.crs, WGS84).transform(x.ravel(), y.ravel())
    rx, ry, rz = frame.to_enu(lat, lon, np.full(lat.shape, 1.5))
    sx, sy, sz = frame.to_enu(traj.lat, traj.lon, traj.h)
    d, phi, theta = emission_angles(rx[:, None] - sx, ry[:, None] - sy, rz[:, None] - sz,
                                    np.radians(traj.yaw), np.radians(traj.pitch), np.radians(traj.roll))
    L = CARD.level_uav(CARD.inputs(np.maximum(d, 1.0), phi, theta, traj.power_w[None, :]))
    w = np.zeros(len(traj))
    dt = np.diff(traj.t)
    w[:-1] += dt / 2
    w[1:] += dt / 2
    energy = np.power(10.0, L / 10.0) @ w
    return {"LAmax": L.max(axis=1).reshape(grid.shape), "LAeq": (10 * np.log10(energy / traj.duration_s)).reshape(grid.shape)}


def timed(fn, repeat: int = 3):
    """Best wall time of ``repeat`` runs, its CPU time and the result."""
    best = (float("inf"), 0.0, None)
    for _ in range(repeat):
        c0, t0 = time.process_time(), time.perf_counter()
        out = fn()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        if wall < best[0]:
            best = (wall, cpu, out)
    return best


def peak_mb() -> float:
    """Peak resident memory of this process, MB (``VmHWM``: unlike ``ru_maxrss`` it starts afresh at exec)."""
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def machine() -> str:
    model = platform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import numba

    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:
        cpus = os.cpu_count()
    mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 ** 30
    return (f"{model}; {cpus} CPUs; {mem:.0f} GiB; Python {platform.python_version()}, numpy {np.__version__}, "
            f"numba {numba.__version__}; load average {os.getloadavg()[0]:.1f}")


# --------------------------------------------------------------------------- 1. throughput


def throughput(side: int, n: int) -> None:
    traj, grid = flight(n), square_grid(side)
    work = grid.n_cells * n
    evaluate_grid(traj, [CARD], grid, ground_h=0.0, engine="fast", metrics=("LAmax",))  # compile / load
    fast_w, fast_c, fast = timed(lambda: evaluate_grid(traj, [CARD], grid, ground_h=0.0, engine="fast",
                                                       metrics=("LAmax", "LAeq")))
    np_w, np_c, ref = timed(lambda: evaluate_grid(traj, [CARD], grid, ground_h=0.0, metrics=("LAmax", "LAeq")),
                            repeat=1)
    base_w, base_c, base = timed(lambda: baseline(traj, grid), repeat=1)
    fast1_w, fast1_c, _ = timed(lambda: evaluate_grid_fast(traj, [CARD], grid, ground_h=0.0, threads=1,
                                                           metrics=("LAmax", "LAeq")))
    diff = max(float(np.nanmax(np.abs(fast.bands[k] - ref.bands[k]))) for k in ("LAmax", "LAeq"))
    diff_b = max(float(np.nanmax(np.abs(base[k] - ref.bands[k]))) for k in ("LAmax", "LAeq"))
    print(f"\n1. throughput: {side} x {side} grid, {n} instants ({work / 1e6:.0f} M cell-instants), LAmax + LAeq")
    print(f"{'':28s}{'wall s':>9s}{'CPU s':>9s}{'M/s wall':>10s}{'M/s CPU':>10s}{'x baseline':>12s}{'x numpy':>9s}")
    rows = [("fast engine, 2 threads", fast_w, fast_c), ("fast engine, 1 thread", fast1_w, fast1_c),
            ("numpy engine", np_w, np_c), ("plain broadcast baseline", base_w, base_c)]
    for name, w, c in rows:
        print(f"{name:28s}{w:9.3f}{c:9.3f}{work / w / 1e6:10.1f}{work / c / 1e6:10.1f}{base_w / w:12.1f}"
              f"{np_w / w:9.1f}")
    print(f"largest difference to the numpy engine: fast {diff:.2e} dB, baseline {diff_b:.2e} dB")
    print(f"aim: fast >= 50x the baseline: {base_w / fast_w:.0f}x wall (1 thread: {base_w / fast1_w:.0f}x; "
          f"per CPU second {base_c / fast_c:.0f}x)")


# --------------------------------------------------------------------------- 2. scaling


def scaling(sides: list[int], lengths: list[int]) -> None:
    print("\n2. fast engine wall time (s) by grid and trajectory length (2000 m x 2000 m grid, circle at 80 m);"
          " last columns: median ns per cell-instant, wall and CPU")
    print(f"{'grid':>12s}" + "".join(f"{n:>10d} inst" for n in lengths) + f"{'ns wall':>10s}{'ns CPU':>9s}")
    for side in sides:
        grid = square_grid(side)
        row, per, per_cpu = [], [], []
        for n in lengths:
            traj = flight(n)
            w, c, _ = timed(lambda traj=traj, grid=grid: evaluate_grid(
                traj, [CARD], grid, ground_h=0.0, engine="fast", metrics=("LAmax", "LAeq", "SEL")), repeat=1)
            row.append(w)
            per.append(w / (grid.n_cells * n) * 1e9)
            per_cpu.append(c / (grid.n_cells * n) * 1e9)
        print(f"{side:>5d} x {side:<5d}" + "".join(f"{w:15.2f}" for w in row)
              + f"{np.median(per):10.2f}{np.median(per_cpu):9.2f}")


# --------------------------------------------------------------------------- 3. the aim case


def aim_case(side: int, n: int) -> dict:
    """Run in a fresh process: wall time and peak memory of the 2000 x 2000, 10-minute case."""
    traj, grid = flight(n), square_grid(side)
    evaluate_grid(flight(3), [CARD], square_grid(4), ground_h=0.0, engine="fast")  # load the compiled kernel
    t0, c0 = time.perf_counter(), time.process_time()
    res = evaluate_grid(traj, [CARD], grid, ground_h=0.0, engine="fast", threshold_db=55.0)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return {"wall_s": wall, "cpu_s": cpu, "peak_mb": peak_mb(),
            "cells": grid.n_cells, "instants": n, "bands": list(res.bands), "lamax_max": float(np.nanmax(res.bands["LAmax"]))}


def run_aim(side: int, n: int) -> None:
    out = subprocess.run([sys.executable, os.path.abspath(__file__), "--aim-case", str(side), str(n)],
                         capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    print(f"\n3. aim case: {side} x {side} grid, {n - 1} s flight at 1 Hz ({n} instants), LAmax, LAeq, SEL, TA55")
    print(f"wall {r['wall_s']:.2f} s (aim < 10 s: {10.0 / r['wall_s']:.1f}x margin), CPU {r['cpu_s']:.2f} s; "
          f"peak memory of the process {r['peak_mb']:.0f} MB (aim < 2048 MB: {2048 / r['peak_mb']:.1f}x margin)")


# --------------------------------------------------------------------------- 4. city scale on Dask


def city(n_flights: int, extent_km: tuple[float, float], res_m: float):
    """Delivery flights between random hubs of a city: take-off, cruise at 100 m, landing."""
    from gisnoise.flight import route_from_waypoints
    from gisnoise.ops import Flight, Schedule

    rng = np.random.default_rng(2024)
    frame = LocalFrame(LAT0, LON0, 100.0)
    w, h = extent_km[0] * 1000, extent_km[1] * 1000
    hubs = np.column_stack([rng.uniform(-0.4 * w, 0.4 * w, 8), rng.uniform(-0.4 * h, 0.4 * h, 8)])
    flights = []
    for k in range(n_flights):
        a, b = rng.choice(len(hubs), 2, replace=False)
        mid = (hubs[a] + hubs[b]) / 2 + rng.normal(0, 300, 2)
        pts = [hubs[a], hubs[a], mid, hubs[b], hubs[b]]
        alts = [0.0, 60.0, 100.0, 60.0, 0.0]
        wps = []
        for (e, nn), alt in zip(pts, alts, strict=True):
            lat, lon, _ = frame.to_wgs84(e, nn, 0.0)
            wps.append({"lon": float(lon), "lat": float(lat), "alt": alt})
        route = route_from_waypoints(wps, {"altitude_reference": "agl", "ground_h_m": 100.0, "sample_dt_s": 1.0})
        day = int(rng.integers(4, 30))
        flights.append(Flight(f"f{k}", route.trajectory, {"day": day, "evening": day // 6, "night": day // 12}))
    cards = [load(os.path.join(CARDS, f"demo_{p}.json")) for p in ("horizontal", "climb", "sink")]
    grid = GridSpec(CRS, Affine(res_m, 0, -w / 2, 0, -res_m, h / 2), int(w / res_m), int(h / res_m))
    return Schedule(flights=tuple(flights), cards=cards, grid=grid, ground_h_m=100.0, thresholds_db=(55.0, 65.0),
                    floor_db=None)


def run_city(n_flights: int, extent_km: tuple[float, float], res_m: float) -> None:
    from gisnoise.ops import evaluate_operations, local_cluster

    sched = city(n_flights, extent_km, res_m)
    g = sched.grid
    inst = sum(len(f.trajectory) for f in sched.flights)
    print(f"\n4. city scale: {n_flights} delivery routes ({sum(f.total for f in sched.flights):.0f} flights a day, "
          f"{inst} instants in all) over {extent_km[0]:g} km x {extent_km[1]:g} km at {res_m:g} m "
          f"({g.width} x {g.height} = {g.n_cells / 1e6:.1f} M cells), tiles of 2^16 cells")
    evaluate_operations(sched, grid=square_grid(8), threads=1)  # load the compiled kernel
    import distributed

    tile = 1 << 16
    w0, c0, one = timed(lambda: evaluate_operations(sched, threads=2, tile_cells=tile), repeat=1)
    w1, c1, _ = timed(lambda: evaluate_operations(sched, threads=1, tile_cells=tile), repeat=1)
    print(f"{'':34s}{'wall s':>9s}{'CPU s':>9s}{'x 1 worker':>12s}{'worker peak MB':>16s}{'bands':>12s}")
    print(f"{'one process, 1 thread':34s}{w1:9.2f}{c1:9.2f}")
    print(f"{'one process, 2 threads':34s}{w0:9.2f}{c0:9.2f}")
    base = None
    for workers in (1, 2):
        with local_cluster(workers) as cluster:
            with distributed.Client(cluster.scheduler_address, set_as_default=False) as client:
                cpu0 = client.run(time.process_time)  # workers started; their CPU clocks
                t0 = time.perf_counter()
                res = evaluate_operations(sched, scheduler=cluster.scheduler_address, tile_cells=tile)
                wall = time.perf_counter() - t0
                cpu = sum(client.run(time.process_time)[k] - cpu0[k] for k in cpu0)
                peaks = client.run(peak_mb)
        same = all(np.array_equal(res.bands[k], one.bands[k], equal_nan=True) for k in one.bands)
        base = wall if base is None else base
        print(f"{f'local Dask cluster, {workers} worker(s)':34s}{wall:9.2f}{cpu:9.2f}{base / wall:12.2f}"
              f"{max(peaks.values()):16.0f}{'identical' if same else 'DIFFERENT':>12s}")
    print(f"Lden max {np.nanmax(one.bands['Lden']):.1f} dB(A); area Lden >= 45 dB(A): "
          f"{(one.bands['Lden'] >= 45).sum() * res_m ** 2 / 1e6:.2f} km2")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--aim-case":
        print(json.dumps(aim_case(int(sys.argv[2]), int(sys.argv[3]))))
        return
    quick = "--quick" in sys.argv
    print("machine:", machine())
    if quick:
        run_aim(1000, 301)
        throughput(120, 120)
        scaling([250, 500], [75, 150])
        run_city(6, (4.0, 3.0), 10.0)
    else:
        run_aim(2000, 601)
        throughput(200, 240)
        scaling([500, 1000, 2000], [150, 300, 600])
        run_city(30, (10.0, 8.0), 10.0)
    print(f"\nload average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
