"""Fit time: gisnoise.fit (analytic Jacobian, Gauss-Newton/LM) vs scipy least_squares (finite differences).

100 000 samples x 7 parameters (the paper's ansatz Eq. 8-11, P_el 5-10), three
microphones with different noise.  Both solvers start from the same values and
minimise the same weighted cost; scipy gets the weights gisnoise estimated (it
cannot estimate them itself).  Prints times and the ratio measured in this run.

    python bench/bench_fit.py [n_samples]
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.optimize import least_squares

from gisnoise.fit import fit_arrays
from gisnoise.model import get_ansatz


def data(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = {"d": rng.uniform(25.0, 600.0, n), "phi": rng.uniform(-np.pi, np.pi, n),
         "theta": rng.uniform(-1.5, 0.3, n), "p_el": rng.uniform(5.0, 10.0, n)}
    truth = np.array([60.0, 0.08, -0.28, -0.2, 1.05, 1.0, 40.0])
    mic = np.array(["m1", "m2", "m3"])[rng.integers(0, 3, n)]
    sd = {"m1": 0.8, "m2": 1.2, "m3": 1.6}
    y = get_ansatz("paper").level(truth, x) + rng.normal(0.0, 1.0, n) * np.vectorize(sd.get)(mic)
    return x, y, mic, truth


def main(n: int = 100_000) -> None:
    x, y, mic, truth = data(n)
    model = get_ansatz("paper")
    t0 = time.perf_counter()
    res = fit_arrays(y, x, "paper", mic=mic)
    t_ours = time.perf_counter() - t0

    sig = np.array([res.noise_std[m] for m in mic])

    def wres(p):
        return (model.level(p, x) - y) / sig

    t0 = time.perf_counter()
    ref = least_squares(wres, res.start, jac="2-point", method="trf")
    t_fd = time.perf_counter() - t0

    t0 = time.perf_counter()
    fixed_w = fit_arrays(y, x, "paper", mic=mic, per_mic_noise=False)
    t_one = time.perf_counter() - t0

    ours_cost = 0.5 * float(np.sum(wres(res.p) ** 2))
    print(f"samples {n}, parameters {model.n_params}")
    print(f"gisnoise.fit (ML, per-mic noise by relaxation): {t_ours:7.3f} s  {res.iterations} GN iterations, "
          f"{res.nfev} model evaluations, {res.cycles} cycles")
    print(f"gisnoise.fit (one noise variance):              {t_one:7.3f} s  {fixed_w.iterations} GN iterations")
    print(f"scipy least_squares trf, 2-point Jacobian:      {t_fd:7.3f} s  {ref.nfev} evaluations + "
          f"{ref.njev} Jacobians (x{model.n_params + 1} residual calls each)")
    print(f"ratio scipy / gisnoise (ML fit):                {t_fd / t_ours:7.2f}")
    print(f"weighted cost: gisnoise {ours_cost:.6f}, scipy {ref.cost:.6f}, relative difference "
          f"{abs(ours_cost - ref.cost) / ref.cost:.1e}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
