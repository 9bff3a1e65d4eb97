"""The default engine, from the first run: start-up, kernel and whole process against a plain NumPy broadcast.

Everything is measured in one run and given as ratios against baselines measured in
the same run; the load average is printed before and after (the machine may be shared).

1. Start-up: ``gisnoise --help`` and ``gisnoise contour --help`` against ``python -c pass``.
2. Kernel, in-process and warm: ``evaluate_grid`` with default options (the fast engine)
   on the bench scenario, with and without an audibility floor, against a plain NumPy
   broadcast of the same model (whole cells x instants arrays of a block of rows; its
   time scales with the cells, so it is measured on 3 blocks of rows and scaled to the
   grid).  The largest level difference to the broadcast is printed.
3. Whole process: ``gisnoise contour`` with default options (GeoTIFF and contours
   included) in a fresh process, three ways: without set-up (an empty kernel cache: the
   kernels compile), the first run after the set-up's warm-up (``warm_up``), and a later
   run; against the broadcast's time for the whole grid.
4. Memory: peak resident memory of a process mapping a 2000 x 2000 grid for a 10-minute
   flight at 1 Hz with the default engine.

    python bench/bench_default.py [--quick] [--kernel]

The bench scenario: a circle of 2552 m radius at 80 m, 27 m/s, 600 samples at 1 Hz, the
bundled demonstration horizontal card; the command's default 10 m cells and 500 m margin
give 611 x 611 cells: 2.2e8 cell-samples.  ``--quick``: a smaller circle; ``--kernel``:
parts 1 and 2 only.  CPU times (all threads) are printed beside wall times.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, emission_angles, transformer
from gisnoise.maps import evaluate_grid, grid_for_trajectory
from gisnoise.model import load

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CARD_PATH = ROOT / "gisnoise" / "data" / "cards" / "demo_horizontal.json"
LAT0, LON0 = 52.27, 10.52


def load_avg() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def circle(n: int = 600, radius: float = 2552.0, speed: float = 27.0) -> Trajectory:
    frame = LocalFrame(LAT0, LON0, 0.0)
    t = np.arange(n, dtype=float)
    ang = speed * t / radius
    lat, lon, h = frame.to_wgs84(radius * np.sin(ang), radius * np.cos(ang), np.full(n, 80.0))
    return Trajectory(t=t, lat=lat, lon=lon, h=h, roll=np.full(n, 6.0), pitch=np.full(n, 2.0),
                      yaw=np.degrees(ang) + 90.0, power_w=3000.0 * (1 + 0.2 * np.sin(t / 9)),
                      phase=np.full(n, "horizontal"), source="circle")


def broadcast(traj: Trajectory, grid: GridSpec, card, ground_h: float) -> dict[str, np.ndarray]:
    """The plain broadcast: (cells, instants) arrays at once, the model from gisnoise.model."""
    frame = LocalFrame(*reversed(grid.centre_wgs84()), ground_h)
    x, y = grid.centres()
    lon, lat = transformer(grid.crs, WGS84).transform(x.ravel(), y.ravel())
    rx, ry, rz = frame.to_enu(lat, lon, np.full(lat.shape, ground_h + 1.5))
    sx, sy, sz = frame.to_enu(traj.lat, traj.lon, traj.h)
    d, phi, theta = emission_angles(rx[:, None] - sx, ry[:, None] - sy, rz[:, None] - sz,
                                    np.radians(traj.yaw), np.radians(traj.pitch), np.radians(traj.roll))
    L = card.level_uav(card.inputs(np.maximum(d, 1.0), phi, theta, traj.power_w[None, :]))
    w = np.zeros(len(traj))
    dt = np.diff(traj.t)
    w[:-1] += dt / 2
    w[1:] += dt / 2
    energy = np.power(10.0, L / 10.0) @ w
    return {"LAmax": L.max(axis=1).reshape(grid.shape),
            "LAeq": (10 * np.log10(energy / traj.duration_s)).reshape(grid.shape)}


def rows(grid: GridSpec, r0: int, r1: int) -> GridSpec:
    t = grid.transform
    from affine import Affine

    return GridSpec(grid.crs, Affine(t.a, 0.0, t.c, 0.0, t.e, t.f + r0 * t.e), grid.width, r1 - r0)


CPU: dict[str, float] = {}


def best_of(fn, repeat: int = 3, key: str = "") -> tuple[float, object]:
    """Smallest wall time of ``repeat`` runs and the result; the smallest CPU time (all threads) in ``CPU[key]``."""
    best, out, cpu = float("inf"), None, float("inf")
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    if key:
        CPU[key] = cpu
    return best, out


def run(cmd: list[str], env: dict[str, str] | None = None) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


FLOOR = 45.0
"""Audibility floor of the kernel's second measurement, dB(A)."""


def main(quick: bool = False, kernel_only: bool = False) -> None:
    py = sys.executable
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
          f"{platform.python_version()}; load average before: {load_avg()}")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    gis = [py, "-c", "from gisnoise.cli.main import main; main()"]

    # 1. start-up
    base = min(run([py, "-c", "pass"], env) for _ in range(5))
    h1 = min(run(gis + ["--help"], env) for _ in range(5))
    h2 = min(run(gis + ["contour", "--help"], env) for _ in range(5))
    print(f"\n1. start-up (best of 5): python -c pass {base:.3f} s; gisnoise --help {h1:.3f} s "
          f"(+{h1 - base:.3f}); gisnoise contour --help {h2:.3f} s (+{h2 - base:.3f})")

    # 2. kernel, in-process, warm
    card = load(CARD_PATH)
    traj = circle(300, 1200.0, 25.0) if quick else circle()
    grid = grid_for_trajectory(traj, resolution_m=10.0, margin_m=500.0)
    H, W = grid.shape
    work = grid.n_cells * len(traj)
    print(f"\n2. kernel: {W} x {H} cells x {len(traj)} samples = {work:.3g} cell-samples")
    block = 10
    t_blocks: list[float] = []
    cpu_blocks: list[float] = []
    diffs: list[float] = []
    for r0 in (H // 4, H // 2, 3 * H // 4):
        sub = rows(grid, r0, r0 + block)
        t_b, ref = best_of(lambda sub=sub: broadcast(traj, sub, card, 0.0), repeat=1, key="base")
        t_blocks.append(t_b)
        cpu_blocks.append(CPU["base"])
        fast_sub = evaluate_grid(traj, card, sub, ground_h=0.0, metrics=("LAmax", "LAeq"))
        diffs += [float(np.nanmax(np.abs(fast_sub.bands[k] - ref[k]))) for k in ref]
    t_base = min(t_blocks) * H / block
    print(f"   plain broadcast: {min(t_blocks):.3f} s per {block} rows -> {t_base:.1f} s for the grid "
          f"({work / t_base / 1e6:.2f} M cell-samples/s)")
    evaluate_grid(traj, card, grid, ground_h=0.0)  # compile or load the kernels
    t_fast, res = best_of(lambda: evaluate_grid(traj, card, grid, ground_h=0.0), key="fast")
    t_floor, res_f = best_of(lambda: evaluate_grid(traj, card, grid, ground_h=0.0, floor_db=FLOOR), key="floor")
    cpu_base = min(cpu_blocks) * H / block
    print(f"   default engine ({res.metadata['engine']}), no floor: {t_fast:.3f} s, "
          f"{work / t_fast / 1e6:.0f} M cell-samples/s, {t_base / t_fast:.0f}x the broadcast "
          f"(CPU time: {cpu_base / CPU['fast']:.0f}x)")
    print(f"   default engine, floor {FLOOR:g} dB(A): {t_floor:.3f} s, {work / t_floor / 1e6:.0f} M cell-samples/s, "
          f"{t_base / t_floor:.0f}x the broadcast (CPU time: {cpu_base / CPU['floor']:.0f}x; "
          f"{res_f.metadata['cells_below_floor']} of {grid.n_cells} cells below the floor)")
    if kernel_only:
        print(f"\nload average after: {load_avg()}")
        return
    print(f"   largest difference to the broadcast: {max(diffs):.2g} dB")

    # 3. whole process
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "circle.csv"
        traj.to_csv(csv)
        cache = Path(tmp) / "numba-cache"
        cenv = dict(env, NUMBA_CACHE_DIR=str(cache), NUMBA_CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator")
        contour = gis + ["contour", str(csv), "--card", str(CARD_PATH), "--ground-height", "0"]
        t_cold = run(contour + ["--out", str(Path(tmp) / "cold")], cenv)
        cache2 = Path(tmp) / "numba-cache-2"
        cenv2 = dict(cenv, NUMBA_CACHE_DIR=str(cache2))
        t_setup = run([py, "-c", "from gisnoise.maps import warm_up; warm_up()"], cenv2)
        t_first = run(contour + ["--out", str(Path(tmp) / "first")], cenv2)
        t_later = min(run(contour + ["--out", str(Path(tmp) / f"later{i}")], cenv2) for i in range(2))
    print(f"\n3. whole process, gisnoise contour with default options ({W} x {H} cells, {len(traj)} samples):")
    print(f"   no set-up (kernels compile): {t_cold:.2f} s, {t_base / t_cold:.1f}x the broadcast")
    print(f"   set-up warm-up {t_setup:.2f} s; first run after it: {t_first:.2f} s, "
          f"{t_base / t_first:.1f}x the broadcast")
    print(f"   later run (best of 2): {t_later:.2f} s, {t_base / t_later:.1f}x the broadcast")

    # 4. memory
    side = 500 if quick else 2000
    code = (
        "import resource, numpy as np\n"
        "from affine import Affine\n"
        "from gisnoise.geo import GridSpec\n"
        "from gisnoise.maps import evaluate_grid\n"
        "from gisnoise.model import load\n"
        f"import sys; sys.path.insert(0, {str(HERE)!r})\n"
        "from bench_default import circle, LAT0, LON0\n"
        "crs = f'+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs'\n"
        f"g = GridSpec(crs, Affine(1.0, 0, -1000.0, 0, -1.0, 1000.0) * Affine.scale(2000.0 / {side}), {side}, {side})\n"
        f"res = evaluate_grid(circle(601, 600.0, 25.0), load({str(CARD_PATH)!r}), g, ground_h=0.0, "
        "threshold_db=55.0)\n"
        "print(res.metadata['engine'], resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n")
    t0 = time.perf_counter()
    out = subprocess.run([py, "-c", code], check=True, env=env, capture_output=True, text=True).stdout.split()
    print(f"\n4. memory: {side} x {side} cells, 10-minute flight at 1 Hz, engine {out[0]}: peak resident "
          f"{float(out[1]):.0f} MB, {time.perf_counter() - t0:.1f} s wall (fresh process)")
    print(f"\nload average after: {load_avg()}")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:], kernel_only="--kernel" in sys.argv[1:])
