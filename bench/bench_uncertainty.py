"""The uncertainty bands (delta method) on the fast engine vs the NumPy engine, same map, same run.

The flight and grid of ``bench_evaluator.py`` with its card given a covariance (fitted-card
scale); both engines compute LAmax, LAeq, SEL and their ``*_std`` / ``*_p95`` bands.  Prints the
machine's load, the wall time of each (best of 3; the NumPy engine once when slow), the ratio
NumPy / fast, the fast engine's time without the bands (their extra cost) and the largest
difference of each band between the engines over all cells, those where instants tie for the
maximum included (the circle's centre: every instant at the same distance; both engines take
``LAmax_std`` by the rule of :func:`gisnoise.maps.tie_std`), with the share of cells over 1e-3 dB.

    python bench/bench_uncertainty.py [n_cells] [n_instants]
"""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
from bench_default import load_avg
from bench_evaluator import CARD, case, timed

from gisnoise.maps import evaluate_grid

STD = np.array([0.4, 1.5, 0.01, 0.05, 0.02, 0.05, 0.01, 0.3])


def main(n_cells: int = 40_000, n_inst: int = 300) -> None:
    traj, grid = case(n_cells, n_inst)
    card = dataclasses.replace(CARD, covariance=tuple(map(tuple, np.diag(STD ** 2))))
    kw = dict(metrics=("LAmax", "LAeq", "SEL"), ground_h=0.0, uncertainty=True)
    print(f"load {load_avg()}; grid {grid.width} x {grid.height}, {len(traj)} instants")
    evaluate_grid(traj, [card], grid, engine="fast", **kw)  # compiled outside the timing
    t_fast, fast, _ = timed(lambda: evaluate_grid(traj, [card], grid, engine="fast", **kw), trace=False)
    t_lev, _, _ = timed(lambda: evaluate_grid(traj, [card], grid, engine="fast",
                                              **{**kw, "uncertainty": False}), trace=False)
    t_np, ref, _ = timed(lambda: evaluate_grid(traj, [card], grid, engine="numpy", **kw), repeat=1, trace=False)
    print(f"fast engine with the bands   : {t_fast:8.3f} s  (levels only {t_lev:.3f} s: the bands x{t_fast / t_lev:.2f})")
    print(f"NumPy engine with the bands  : {t_np:8.3f} s")
    print(f"ratio NumPy / fast           : {t_np / t_fast:8.1f}")
    for name in ref.bands:
        diff = np.abs(ref.bands[name] - fast.bands[name])
        print(f"  {name:10s} largest difference {np.nanmax(diff):.2e} dB, {np.mean(diff > 1e-3):.2%} of cells over "
              "1e-3 dB")
    print(f"load {load_avg()}")


if __name__ == "__main__":
    main(*(int(x) for x in sys.argv[1:3]))
