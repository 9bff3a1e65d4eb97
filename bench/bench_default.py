"""The default engine, from the first run: start-up, kernel and whole process against a plain NumPy broadcast.

Everything is measured in one run and given as ratios against baselines measured in
the same run; the load average is printed before and after (the machine may be shared).

1. Start-up: ``gisnoise --help`` and ``gisnoise contour --help`` against ``python -c pass``.
2. Kernel, in-process and warm: ``evaluate_grid`` with default options (the fast engine)
   on the bench scenario, with and without an audibility floor, against a plain NumPy
   broadcast of the same model measured in the same round.  Two baselines, both the
   plain broadcast (whole cells x instants arrays, float64, the model from
   ``gisnoise.model``), measured on a band of rows in the middle and scaled to the grid
   (their time is linear in the cells): blocks of 10 rows (30 MB arrays, cache-friendly:
   NumPy at its best) and blocks of 100 rows (300 MB arrays, as broadcasting whole grids
   makes them; the baseline of the issue's figures).  The largest level difference to
   the broadcast is printed.
3. Whole process: ``gisnoise contour`` with default options (its own extent; GeoTIFF and
   contours included) in a fresh process: the first run after the set-up's warm-up
   (``warm_up``), later runs (one a round), and without set-up (an empty kernel cache:
   the kernels compile); against the broadcast scaled to the command's cells.
   Rounds of (baselines, kernel, whole process) are interleaved; medians of the rounds'
   ratios are printed with the load of each round.
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


CHILD_CPU: list[float] = []
"""CPU seconds (user + system, all threads) of each process :func:`run` started, in order."""


def run(cmd: list[str], env: dict[str, str] | None = None) -> float:
    """Wall seconds of a fresh process; its CPU seconds are appended to :data:`CHILD_CPU`."""
    import resource

    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    CHILD_CPU.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return wall


FLOOR = 45.0
"""Audibility floor of the kernel's second measurement, dB(A)."""
BLOCK_ROWS = 10
"""Rows of the cache-friendly broadcast's blocks (arrays of about 30 MB: NumPy at its best)."""
WHOLE_ROWS = 100
"""Rows of the whole-array broadcast's blocks (arrays of about 300 MB, as broadcasting whole grids makes them)."""


def per_cell_sample(traj: Trajectory, grid: GridSpec, card, rows_n: int) -> tuple[float, float, dict, GridSpec]:
    """Wall and CPU seconds per cell-sample of the broadcast on ``rows_n`` rows in the middle of the grid."""
    H = grid.shape[0]
    r0 = max(0, H // 2 - rows_n // 2)
    sub = rows(grid, r0, min(H, r0 + rows_n))
    t0, c0 = time.perf_counter(), time.process_time()
    ref = broadcast(traj, sub, card, 0.0)
    work = sub.n_cells * len(traj)
    return (time.perf_counter() - t0) / work, (time.process_time() - c0) / work, ref, sub


def median(v: list[float]) -> float:
    return float(np.median(np.asarray(v, dtype=float)))


def main(quick: bool = False, kernel_only: bool = False, rounds: int = 3) -> None:
    py = sys.executable
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
          f"{platform.python_version()}; load average before: {load_avg()}")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    gis = [py, "-c", "from gisnoise.cli.main import main; main()"]

    # 1. start-up, interleaved (bytecode written on the first run, as an installation has it)
    tmp = tempfile.TemporaryDirectory()
    env1 = dict(env, PYTHONPYCACHEPREFIX=str(Path(tmp.name) / "pycache-1"))
    env1.pop("PYTHONDONTWRITEBYTECODE", None)
    t_pass, t_h1, t_h2 = [], [], []
    for _ in range(5):
        t_pass.append(run([py, "-c", "pass"], env1))
        t_h1.append(run(gis + ["--help"], env1))
        t_h2.append(run(gis + ["contour", "--help"], env1))
    base, h1, h2 = min(t_pass), min(t_h1), min(t_h2)
    print(f"\n1. start-up (best of 5, interleaved): python -c pass {base:.3f} s; gisnoise --help {h1:.3f} s "
          f"(+{h1 - base:.3f}); gisnoise contour --help {h2:.3f} s (+{h2 - base:.3f})")

    card = load(CARD_PATH)
    traj = circle(300, 1200.0, 25.0) if quick else circle()
    grid = grid_for_trajectory(traj, resolution_m=10.0, margin_m=500.0)
    H, W = grid.shape
    work = grid.n_cells * len(traj)
    print(f"\n2. kernel: {W} x {H} cells x {len(traj)} samples = {work:.3g} cell-samples; baselines: the plain "
          f"NumPy broadcast (gisnoise.model, float64) on blocks of {BLOCK_ROWS} rows (cache-friendly) and of "
          f"{WHOLE_ROWS} rows (whole arrays), scaled to the grid; {rounds} interleaved rounds, medians")
    evaluate_grid(traj, card, grid, ground_h=0.0)  # compile or load the kernels

    csv = Path(tmp.name) / "circle.csv"
    traj.to_csv(csv)
    cache2 = Path(tmp.name) / "numba-cache-2"
    # a set-up as an installation has it: compiled kernels (numba's cache) and the package's bytecode (pip writes
    # it on install; here the warm-up's imports write it, into a throw-away folder)
    cenv2 = dict(env, NUMBA_CACHE_DIR=str(cache2), NUMBA_CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator",
                 PYTHONPYCACHEPREFIX=str(Path(tmp.name) / "pycache-2"))
    cenv2.pop("PYTHONDONTWRITEBYTECODE", None)
    contour = gis + ["contour", str(csv), "--card", str(CARD_PATH), "--ground-height", "0"]
    if not kernel_only:
        t_setup = run([py, "-c", "from gisnoise.maps import warm_up; warm_up()"], cenv2)
        t_first = run(contour + ["--out", str(Path(tmp.name) / "first")], cenv2)
        cpu_first = CHILD_CPU[-1]
        import rasterio

        with rasterio.open(Path(tmp.name) / "first" / "levels.tif") as src:
            cmd_cells = src.width * src.height
            cmd_shape = (src.width, src.height)

    R: dict[str, list[float]] = {k: [] for k in ("blk", "whole", "blk_cpu", "fast", "fast_cpu", "floor", "floor_cpu",
                                                 "proc", "r_fast_blk", "r_fast_whole", "r_floor_blk",
                                                 "r_floor_whole", "r_cpu_blk", "r_proc_blk", "r_proc_whole",
                                                 "proc_cpu", "r_proc_cpu", "load")}
    diffs: list[float] = []
    skipped = 0
    for rnd in range(rounds):
        R["load"].append(os.getloadavg()[0])
        blk, blk_cpu, ref, sub = per_cell_sample(traj, grid, card, BLOCK_ROWS)
        fast_sub = evaluate_grid(traj, card, sub, ground_h=0.0, metrics=("LAmax", "LAeq"))
        diffs += [float(np.nanmax(np.abs(fast_sub.bands[k] - ref[k]))) for k in ref]
        whole = per_cell_sample(traj, grid, card, WHOLE_ROWS if not quick else 40)[0]
        t_fast, res = best_of(lambda: evaluate_grid(traj, card, grid, ground_h=0.0), repeat=2, key="fast")
        t_floor, res_f = best_of(lambda: evaluate_grid(traj, card, grid, ground_h=0.0, floor_db=FLOOR), repeat=2,
                                 key="floor")
        skipped = int(res_f.metadata["cells_below_floor"])
        R["blk"].append(blk * work)
        R["whole"].append(whole * work)
        R["blk_cpu"].append(blk_cpu * work)
        R["fast"].append(t_fast)
        R["fast_cpu"].append(CPU["fast"])
        R["floor"].append(t_floor)
        R["floor_cpu"].append(CPU["floor"])
        R["r_fast_blk"].append(blk * work / t_fast)
        R["r_fast_whole"].append(whole * work / t_fast)
        R["r_floor_blk"].append(blk * work / t_floor)
        R["r_floor_whole"].append(whole * work / t_floor)
        R["r_cpu_blk"].append(blk_cpu * work / CPU["fast"])
        line = (f"   round {rnd + 1} (load {R['load'][-1]:.1f}): broadcast {blk * work:.1f} s (blocks) / "
                f"{whole * work:.1f} s (whole arrays); kernel {t_fast:.3f} s, with floor {t_floor:.3f} s")
        if not kernel_only:
            t_proc = run(contour + ["--out", str(Path(tmp.name) / f"later{rnd}")], cenv2)
            n_cmd = cmd_cells * len(traj)
            R["proc"].append(t_proc)
            R["proc_cpu"].append(CHILD_CPU[-1])
            R["r_proc_cpu"].append(blk_cpu * n_cmd / CHILD_CPU[-1])
            R["r_proc_blk"].append(blk * n_cmd / t_proc)
            R["r_proc_whole"].append(whole * n_cmd / t_proc)
            line += f"; gisnoise contour {t_proc:.2f} s"
        print(line, flush=True)
    m = {k: median(v) for k, v in R.items() if v}
    print(f"   plain broadcast: {m['blk']:.1f} s for the grid on blocks of {BLOCK_ROWS} rows "
          f"({work / m['blk'] / 1e6:.1f} M cell-samples/s), {m['whole']:.1f} s on blocks of {WHOLE_ROWS} rows "
          f"({work / m['whole'] / 1e6:.1f} M cell-samples/s)")
    print(f"   default engine ({res.metadata['engine']}), no floor: {m['fast']:.3f} s, "
          f"{work / m['fast'] / 1e6:.0f} M cell-samples/s; {m['r_fast_blk']:.0f}x the broadcast on blocks, "
          f"{m['r_fast_whole']:.0f}x on whole arrays (CPU time against the blocks: {m['r_cpu_blk']:.0f}x; "
          f"{work / m['fast_cpu'] / 1e6:.0f} M cell-samples per CPU-second)")
    print(f"   default engine, floor {FLOOR:g} dB(A): {m['floor']:.3f} s, {work / m['floor'] / 1e6:.0f} M "
          f"cell-samples/s; {m['r_floor_blk']:.0f}x on blocks, {m['r_floor_whole']:.0f}x on whole arrays "
          f"({skipped} of {grid.n_cells} cells below the floor)")
    print(f"   largest difference to the broadcast: {max(diffs):.2g} dB")
    if kernel_only:
        tmp.cleanup()
        print(f"\nload average after: {load_avg()}")
        return

    # 3. whole process
    cache = Path(tmp.name) / "numba-cache"
    cenv = dict(env, NUMBA_CACHE_DIR=str(cache), NUMBA_CACHE_LOCATOR_CLASSES="UserProvidedCacheLocator",
                PYTHONPYCACHEPREFIX=str(Path(tmp.name) / "pycache"))
    cenv.pop("PYTHONDONTWRITEBYTECODE", None)
    t_cold = run(contour + ["--out", str(Path(tmp.name) / "cold")], cenv)
    tmp.cleanup()
    n_cmd = cmd_cells * len(traj)
    print(f"\n3. whole process, gisnoise contour with default options ({cmd_shape[0]} x {cmd_shape[1]} cells: "
          f"its own extent; {len(traj)} samples; the broadcast scaled to these cells):")
    print(f"   no set-up (kernels compile): {t_cold:.2f} s, {m['blk'] / work * n_cmd / t_cold:.1f}x the broadcast "
          f"on blocks, {m['whole'] / work * n_cmd / t_cold:.1f}x on whole arrays")
    print(f"   set-up warm-up {t_setup:.2f} s; first run after it: {t_first:.2f} s, "
          f"{m['blk'] / work * n_cmd / t_first:.1f}x on blocks, {m['whole'] / work * n_cmd / t_first:.1f}x on "
          "whole arrays")
    print(f"   first run's CPU time {cpu_first:.2f} s: {m['blk_cpu'] / work * n_cmd / cpu_first:.1f}x the broadcast's "
          "CPU time on blocks")
    print(f"   later runs (median of {rounds}, each against its round's broadcast): {m['proc']:.2f} s, "
          f"{m['r_proc_blk']:.1f}x on blocks, {m['r_proc_whole']:.1f}x on whole arrays; CPU time "
          f"{m['proc_cpu']:.2f} s (all threads): {m['r_proc_cpu']:.1f}x the broadcast's CPU time on blocks")

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
        "hwm = [ln for ln in open('/proc/self/status') if ln.startswith('VmHWM')]\n"
        "peak = float(hwm[0].split()[1]) / 1024 if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024\n"
        "print(res.metadata['engine'], peak)\n")
    t0 = time.perf_counter()
    out = subprocess.run([py, "-c", code], check=True, env=env, capture_output=True, text=True).stdout.split()
    # VmHWM of the child: ru_maxrss would carry the forked copy of this process (the broadcast's arrays) over exec
    print(f"\n4. memory: {side} x {side} cells, 10-minute flight at 1 Hz, engine {out[0]}: peak resident "
          f"{float(out[1]):.0f} MB, {time.perf_counter() - t0:.1f} s wall (fresh process)")
    print(f"\nload average after: {load_avg()}")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:], kernel_only="--kernel" in sys.argv[1:])
