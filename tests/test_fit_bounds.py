"""Physically meaningful parameter bounds of the fit: Eq. 9's directivity factors stay positive over the
whole emission sphere, the spreading exponent between cylindrical and twice spherical spreading."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _fit_synth import REF_W, TRUTH, synthetic_samples

from gisnoise.identify import DEFAULT_BOUNDS, MIN_DIRECTIVITY_FACTOR, fit

PHI = np.radians(np.arange(-180.0, 180.1, 1.0))
THETA = np.radians(np.arange(-90.0, 90.1, 1.0))


def _factor_minima(p):
    """Smallest value over the sphere of 1 + p2 sin(phi - p3)(theta + pi/2) and of 1 + p4 sin(theta - p5)."""
    phi, theta = np.meshgrid(PHI, THETA, indexing="ij")
    f2 = 1.0 + p["p2"] * np.sin(phi - p["p3"]) * (theta + np.pi / 2)
    f4 = 1.0 + p["p4"] * np.sin(theta - p["p5"])
    return float(f2.min()), float(f4.min())


def test_default_bounds_are_the_positive_factor_limits():
    lo2, hi2 = DEFAULT_BOUNDS["p2"]
    lo4, hi4 = DEFAULT_BOUNDS["p4"]
    assert hi2 == -lo2 == pytest.approx(0.95 / math.pi) and hi4 == -lo4 == pytest.approx(0.95)
    # at the bounds, the worst direction of the sphere leaves exactly the minimum factor (1 deg grid)
    f2, f4 = _factor_minima({"p2": hi2, "p3": 0.0, "p4": hi4, "p5": math.pi / 2})
    assert f2 == pytest.approx(MIN_DIRECTIVITY_FACTOR, abs=1e-3) and f4 == pytest.approx(MIN_DIRECTIVITY_FACTOR)
    assert DEFAULT_BOUNDS["p6"] == (0.5, 2.0)


def test_a_directivity_beyond_the_bound_ends_on_it_and_is_reported():
    """Data whose lateral directivity p2 = 0.35 would turn Eq. 9's factor negative (1 - 0.35 pi = -0.10):
    the fit stops at |p2| = 0.95 / pi, says so, and its card keeps every factor >= 0.05 over the sphere."""
    samples, _ = synthetic_samples(seed=5, truth=dict(TRUTH, p2=0.35), noise={"m1": 0.5, "m2": 0.5, "m3": 0.5})
    res = fit(samples, reference_power_w=REF_W)
    assert abs(res.params["p2"]) == pytest.approx(0.95 / math.pi, abs=1e-9)
    assert "p2" in res.at_bounds and "p2 on a bound" in res.message
    f2, f4 = _factor_minima(res.params)
    assert f2 >= MIN_DIRECTIVITY_FACTOR - 1e-3 and f4 >= MIN_DIRECTIVITY_FACTOR


def test_truth_inside_the_bounds_is_recovered_in_either_sign_convention():
    samples, _ = synthetic_samples(seed=7)
    start = dict(TRUTH, p2=-TRUTH["p2"], p3=TRUTH["p3"] + math.pi, p4=-TRUTH["p4"], p5=TRUTH["p5"] - math.pi)
    res = fit(samples, reference_power_w=REF_W, p0=start)
    for k in ("p2", "p3", "p4", "p5"):       # the canonical convention: p3, p5 in (-pi/2, pi/2]
        assert abs(res.params[k] - TRUTH[k]) < 3.0 * res.std[k]
    assert not res.at_bounds
