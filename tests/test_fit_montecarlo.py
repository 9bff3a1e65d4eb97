"""Monte Carlo study of the fit's uncertainty (slow; run with ``scripts/study -k montecarlo``).

Many seeded synthetic campaigns with a known truth are fitted.  For every
parameter the study measures the coverage of the 95 % intervals
``p_hat +- 1.96 std`` and the ratio of the mean Cramer-Rao standard deviation to
the empirical standard deviation of the estimates, with white measurement noise
(where the Cramer-Rao bound is the right answer) and with AR(1)-coloured noise
(where it is too optimistic and the autocorrelation correction is needed).  The
numbers are written into ``docs/fit.md`` between the ``montecarlo`` markers.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest
from _fit_synth import NOISE, REF_W, TRUTH, synthetic_samples

from gisnoise.identify.fit import fit
from gisnoise.model import get_ansatz

pytestmark = pytest.mark.slow

DOC = Path(__file__).resolve().parents[1] / "docs" / "fit.md"
NAMES = get_ansatz("paper-offset").params
P_TRUE = np.array([TRUTH[k] for k in NAMES])
Z95 = 1.959963984540054
GEOMETRY = {"altitudes": (40.0, 120.0), "speeds": (22.0, 30.0)}


def _study(seeds: int, ar: float) -> dict:
    est, cr, corr, noise = [], [], [], []
    t0 = time.perf_counter()
    for seed in range(seeds):
        samples, _ = synthetic_samples(seed=1000 + seed, ar=ar, **GEOMETRY)
        res = fit(samples, reference_power_w=REF_W)
        est.append(res.p)
        cr.append(res.std_array)
        corr.append(res.std_corrected_array)
        noise.append([res.noise_std[m] for m in NOISE])
    est, cr, corr, noise = map(np.array, (est, cr, corr, noise))
    err = np.abs(est - P_TRUE)
    emp = est.std(axis=0, ddof=1)
    return {
        "seeds": seeds, "ar": ar, "n": len(samples), "seconds": time.perf_counter() - t0,
        "coverage_cr": (err <= Z95 * cr).mean(axis=0), "coverage_corr": (err <= Z95 * corr).mean(axis=0),
        "ratio_cr": cr.mean(axis=0) / emp, "ratio_corr": corr.mean(axis=0) / emp,
        "bias_in_std": (est.mean(axis=0) - P_TRUE) / emp,
        "noise_ratio": noise.mean(axis=0) / np.array(list(NOISE.values())),
    }


def _table(r: dict) -> str:
    lines = ["| parameter | truth | coverage 95 % (CR) | coverage 95 % (corrected) | mean CR std / empirical std "
             "| mean corrected std / empirical std | bias / empirical std |",
             "|---|---|---|---|---|---|---|"]
    for i, k in enumerate(NAMES):
        lines.append(f"| {k} | {P_TRUE[i]:g} | {r['coverage_cr'][i]:.1%} | {r['coverage_corr'][i]:.1%} | "
                     f"{r['ratio_cr'][i]:.2f} | {r['ratio_corr'][i]:.2f} | {r['bias_in_std'][i]:+.2f} |")
    lines.append(f"| all | | {r['coverage_cr'].mean():.1%} | {r['coverage_corr'].mean():.1%} | "
                 f"{r['ratio_cr'].mean():.2f} | {r['ratio_corr'].mean():.2f} | |")
    noise = ", ".join(f"{m} {v:.3f}" for m, v in zip(NOISE, r["noise_ratio"], strict=True))
    lines.append("")
    lines.append(f"{r['seeds']} seeds, {r['n']} samples each, {r['seconds']:.0f} s.  Estimated / simulated noise "
                 f"standard deviation (mean over seeds): {noise}.")
    return "\n".join(lines)


def _write_doc(white: dict, coloured: dict) -> None:
    text = DOC.read_text(encoding="utf-8")
    block = (
        "<!-- montecarlo:begin (written by tests/test_fit_montecarlo.py; do not edit by hand) -->\n"
        f"### White measurement noise\n\n{_table(white)}\n\n"
        f"### AR(1) measurement noise, coefficient {coloured['ar']:g}\n\n"
        f"The variance of a mean of AR(1) noise is {(1 + coloured['ar']) / (1 - coloured['ar']):.0f} times that "
        f"of white noise of the same level, so the Cramer-Rao deviation is about "
        f"{np.sqrt((1 - coloured['ar']) / (1 + coloured['ar'])):.2f} of the true one.\n\n{_table(coloured)}\n"
        "<!-- montecarlo:end -->"
    )
    new, k = re.subn(r"<!-- montecarlo:begin.*?<!-- montecarlo:end -->", lambda _: block, text, flags=re.S)
    assert k == 1, "docs/fit.md lacks the montecarlo markers"
    DOC.write_text(new, encoding="utf-8")


@pytest.fixture(scope="module")
def studies():
    white = _study(200, 0.0)
    coloured = _study(100, 0.8)
    _write_doc(white, coloured)
    return white, coloured


def test_montecarlo_white_noise_coverage_and_deviation_ratio(studies):
    white, _ = studies
    # 95 % intervals from the Cramer-Rao bound cover the truth 90-99 % of the time
    assert 0.90 <= white["coverage_cr"].mean() <= 0.99
    assert np.all(white["coverage_cr"] >= 0.88)
    # the bound is attained: mean CR std equals the empirical spread (200 seeds: +-10 %)
    assert np.all((white["ratio_cr"] > 0.85) & (white["ratio_cr"] < 1.15)), white["ratio_cr"]
    # maximum-likelihood noise variances: within 2 % of the simulated ones on average
    assert np.all(np.abs(white["noise_ratio"] - 1.0) < 0.02)


def test_montecarlo_coloured_noise_needs_the_correction(studies):
    _, coloured = studies
    # sqrt((1 - 0.8) / (1 + 0.8)) = 0.33: the Cramer-Rao bound is three times too small
    assert np.all(coloured["ratio_cr"] < 0.5)
    assert coloured["coverage_cr"].mean() < 0.7
    # the corrected deviation restores most of it
    assert np.all(coloured["ratio_corr"] > 0.75)
    assert coloured["coverage_corr"].mean() >= 0.85
