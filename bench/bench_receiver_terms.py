"""Receiver-dependent effect extensions on the fast engine, against the plain kernel and the NumPy engine.

One run, one process, rounds interleaved: the bench scenario of ``bench_default.py`` (a circle
of 2552 m radius at 80 m, 27 m/s, 600 samples at 1 Hz, the bundled demonstration horizontal
card, 611 x 611 cells of 10 m) mapped by the fast engine (``LAmax``, ``LAeq``, ``SEL``, one
thread and all threads, no floor) with

* the card itself (the plain kernel, ``gisnoise/maps/_numba.py``);
* the card extended by each receiver-dependent effect and by the chain
  ``+bank_angle+ground_reflection+doppler`` and all four (the kernel of
  ``gisnoise/maps/_numba_receiver.py``);

and, on a band of 20 rows scaled to the grid (linear in the cells), the NumPy engine with the
chain.  Printed: cell-samples per second, each as a ratio to the plain kernel measured in the
same round (medians over the rounds), the largest level difference to the NumPy engine on the
band, and the load average before and after.

    python bench/bench_receiver_terms.py [--quick] [--rounds N]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_default import CARD_PATH, circle, load_avg, rows  # noqa: E402
from bench_evaluator import timed  # noqa: E402

from gisnoise.maps import evaluate_grid, grid_for_trajectory  # noqa: E402
from gisnoise.model import ModelCard, load  # noqa: E402

EXTRA = {
    "atmospheric_absorption": dict(a_abs=6.0),
    "wind": dict(w_east=0.5, w_north=-0.3),
    "doppler": dict(q_doppler=2.0),
    "ground_reflection": dict(r_ground=0.7, f_ground=400.0),
    "bank_angle": dict(k_bank=3.0),
}
CHAINS = ["+atmospheric_absorption", "+wind", "+doppler", "+ground_reflection",
          "+bank_angle+ground_reflection+doppler", "+atmospheric_absorption+wind+doppler+ground_reflection"]


def extended(card: ModelCard, chain: str) -> ModelCard:
    p = dict(card.parameters)
    for e in chain.strip("+").split("+"):
        p.update(EXTRA[e])
    return ModelCard(id=card.id + chain, vehicle=card.vehicle, phase=card.phase, phases=card.phases,
                     ansatz=card.ansatz + chain, parameters=p, reference_power_w=card.reference_power_w)


def main(quick: bool = False, rounds: int = 3) -> None:
    traj = circle(200, radius=900.0) if quick else circle()
    grid = grid_for_trajectory(traj, 10.0, 500.0)
    card = load(CARD_PATH)
    cells = grid.n_cells * len(traj)
    print(f"grid {grid.width} x {grid.height}, {len(traj)} samples: {cells:.3g} cell-samples; load {load_avg()}")
    kw = dict(ground_h=0.0, metrics=("LAmax", "LAeq", "SEL"), check_cards=False)
    variants = {"plain": card, **{c: extended(card, c) for c in CHAINS}}
    for c in variants.values():  # compile (or load) both kernels before timing
        evaluate_grid(traj, [c], rows(grid, 0, 2), **kw)
    ratios: dict[tuple[str, int], list[float]] = {}
    rates: dict[tuple[str, int], list[float]] = {}
    for r in range(rounds):
        for threads in (1, None):
            plain = None
            for name, c in variants.items():
                wall = timed(lambda c=c, threads=threads: evaluate_grid(traj, [c], grid, threads=threads, **kw),
                             trace=False)[0]
                plain = wall if name == "plain" else plain
                assert plain is not None
                rates.setdefault((name, threads or 0), []).append(cells / wall)
                ratios.setdefault((name, threads or 0), []).append(plain / wall)
        print(f"round {r + 1}: load {load_avg()}")
    print("\n| card | threads | M cell-samples/s (median) | x the plain kernel, same round (median) |")
    print("| --- | ---: | ---: | ---: |")
    for (name, th), v in rates.items():
        print(f"| {name} | {th or 'all'} | {np.median(v) / 1e6:.0f} | {np.median(ratios[(name, th)]):.2f} |")
    # the NumPy engine on a band of rows, scaled to the grid
    chain = variants["+bank_angle+ground_reflection+doppler"]
    band = rows(grid, grid.height // 2 - 10, grid.height // 2 + 10)
    t_np, ref, _ = timed(lambda: evaluate_grid(traj, [chain], band, engine="numpy", **kw), repeat=1, trace=False)
    t_fast, fast, _ = timed(lambda: evaluate_grid(traj, [chain], band, **kw), trace=False)
    diff = max(float(np.max(np.abs(ref.bands[k] - fast.bands[k]))) for k in ("LAmax", "LAeq", "SEL"))
    scale = grid.height / band.height
    print(f"\nNumPy engine, +bank_angle+ground_reflection+doppler, scaled to the grid: {t_np * scale:.1f} s "
          f"({cells / (t_np * scale) / 1e6:.1f} M cell-samples/s); the fast engine on the same band "
          f"{t_np / t_fast:.0f}x faster; largest level difference {diff:.1e} dB; load {load_avg()}")


if __name__ == "__main__":
    args = sys.argv[1:]
    n = int(args[args.index("--rounds") + 1]) if "--rounds" in args else 3
    main(quick="--quick" in args, rounds=n)
