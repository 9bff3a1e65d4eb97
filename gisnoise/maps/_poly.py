"""The fast kernel's polynomial approximations: Chebyshev interpolants of ``exp2``, ``log2`` and ``atan``.

The kernel (:mod:`gisnoise.maps._numba`) evaluates them by Horner's rule in float32,
which LLVM vectorizes (library calls would stay scalar); :func:`_poly_eval` does the
same in NumPy, so the tests can check their errors (relative 3e-7, absolute 2e-7,
5e-7 rad).

>>> len(_EXP2_C), len(_LOG2_C), len(_ATAN_C)  # degrees 5, 8 and 6
(6, 9, 7)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np


def _cheb_monomial(f: Callable[[np.ndarray], np.ndarray], a: float, b: float, deg: int) -> tuple[float, ...]:
    """Monomial coefficients (ascending) of the Chebyshev interpolant of ``f`` on ``[a, b]``."""
    from numpy.polynomial import chebyshev, polynomial

    ch = chebyshev.Chebyshev.interpolate(f, deg, domain=[a, b])
    return tuple(float(c) for c in ch.convert(kind=polynomial.Polynomial, domain=[a, b], window=[a, b]).coef)


_EXP2_C = _cheb_monomial(lambda x: 2.0 ** x, -0.5, 0.5, 5)
"""``2^f`` on ``[-0.5, 0.5]``."""
_LOG2_C = _cheb_monomial(lambda u: np.log2(1.0 + u), math.sqrt(0.5) - 1.0, math.sqrt(2.0) - 1.0, 8)
"""``log2(1 + u)`` on ``[sqrt(1/2) - 1, sqrt(2) - 1]``."""
_ATAN_C = _cheb_monomial(
    lambda s: np.arctan(np.sqrt(np.maximum(s, 1e-300))) / np.sqrt(np.maximum(s, 1e-300)), 0.0, 1.0, 6)
"""``atan(a) / a`` as a polynomial in ``s = a^2`` on ``[0, 1]``."""


def _poly_eval(c: Sequence[float], x: np.ndarray) -> np.ndarray:
    """Horner evaluation in float32 exactly as the kernel does (for the accuracy tests)."""
    x = np.asarray(x, dtype=np.float32)
    r = np.full(x.shape, np.float32(c[-1]), dtype=np.float32)
    for k in c[-2::-1]:
        r = r * x + np.float32(k)
    return r
