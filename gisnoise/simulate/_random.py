"""Seeded randomness of the simulator: one generator per (seed, keys) and slow random processes.

Every random draw of a simulation derives from the scenario's ``seed`` through
:func:`seeded_rng` with keys naming the flight, the microphone and the purpose, so one
draw does not shift another when a scenario changes.
"""

from __future__ import annotations

import math

import numpy as np


def seeded_rng(seed: int, *keys: int) -> np.random.Generator:
    """The random generator of one purpose: seeded by the scenario's ``seed`` and the integer ``keys``."""
    return np.random.default_rng(np.random.SeedSequence([seed, *keys]))


def ou_process(rng: np.random.Generator, t: np.ndarray, std: float, tau: float) -> np.ndarray:
    """Slow random process sampled at times ``t`` (s): a stationary Ornstein-Uhlenbeck
    process (standard deviation ``std``, correlation time ``tau`` s) drawn every ``tau / 10``
    and interpolated linearly, so it is smooth at the scale a 10 Hz log resolves."""
    if std == 0 or len(t) == 0:
        return np.zeros(len(t))
    step = tau / 10.0
    tk = np.arange(t[0], t[-1] + step, step)
    x = np.empty(len(tk))
    x[0] = rng.normal(0.0, std)
    a = math.exp(-step / tau)
    w = rng.normal(0.0, std * math.sqrt(1.0 - a * a), len(tk))
    for i in range(1, len(tk)):
        x[i] = a * x[i - 1] + w[i]
    return np.interp(t, tk, x)

