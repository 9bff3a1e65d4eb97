"""The fast evaluator engine: a numba kernel in float32 for the ``paper`` ansatzes.

:func:`evaluate_grid_fast` computes the same bands as the reference NumPy evaluator
(:func:`gisnoise.maps.evaluate.evaluate_grid`, which calls it for ``engine="fast"``)
within 0.01 dB, much faster.  It evaluates the ansatzes ``paper`` and
``paper-offset`` of :mod:`gisnoise.model.ansatz` (Eq. 8-11; the tests check the kernel
against the registry's definition) and refuses every other ansatz.

How the kernel is fast (all in float32, where the level keeps about 1e-5 dB):

* **No angles.**  The emission angles enter Eq. 9 only as ``sin(phi - p3)``,
  ``sin(theta - p5)`` and ``theta + pi/2``.  With the body vector ``r_b = (x, y, z)``,
  ``h = hypot(x, y)`` and ``d = |r_b|``: ``sin(phi - p3) = (y cos p3 - x sin p3) / h``,
  ``sin(theta - p5) = (-z cos p5 - h sin p5) / d`` and ``theta + pi/2 = atan2(h, z)``,
  so the azimuth needs no ``atan2`` and the polar angle one polynomial ``atan``.
* **Polynomials that vectorize.**  ``exp2``, ``log2`` and ``atan`` are Chebyshev
  interpolants (near-minimax) evaluated by Horner's rule, with the exponent handled by
  bit operations; LLVM vectorizes them, which library calls would prevent.  Their
  errors (relative 3e-7, absolute 2e-7, 5e-7 rad) are checked by the tests.
* **Incremental body vector.**  Receivers of a grid row are taken in segments of at
  most :data:`SEGMENT_M` metres.  Positions (local ENU) are exact (pyproj) at the
  segment's ends and middle and quadratic in the column in between (the residual,
  from the third derivative of the projection and the Earth's curvature, is below
  5e-7 m for 1 km segments 10 km from the frame's origin); the body vector of the cell
  ``u`` columns from the segment's middle is ``A + u (B + u D)`` with ``A, B, D``
  rotated once per instant (plus ``dh (N + u T)`` for heights from a DEM: ENU is exactly
  linear in the ellipsoidal height along the normal).  In float32 the body vector
  carries about 6e-8 times the distance from the segment's middle (at most 3e-5 m):
  0.01 dB holds down to about 0.1 m from the UAV.
* **Cells beyond audibility are skipped, provably.**  With ``floor_db``, a segment is
  skipped when, at every instant, its cells' distance to the UAV is beyond the radius
  at which an upper bound of the card's level over *all* emission angles
  (:func:`directivity_range`, with spreading at the distance) drops below the floor.  Its cells get NaN (LAmax certainly below
  ``floor_db``); every other cell is computed over all instants, exactly.

Accumulation: the maximum and the trapezoid energy ``sum w_i 10^(L_i/10)`` per cell
(energy in float64), time above levels linear between instants as the NumPy path.

The kernel runs without the GIL on blocks of rows; :func:`run_grid` spreads the blocks
over a thread pool.  One compiled function serves a whole grid, a tile of it (the Dask
path of :mod:`gisnoise.ops.scale`) and a single instant, so tiles aligned to segments give
bitwise the same cells as the whole grid.
"""

from __future__ import annotations

import logging
import math
import os
import threading
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

try:
    import numba
    from llvmlite import ir as _ir
    from numba.core import types as _nbt
    from numba.extending import intrinsic as _intrinsic
except ImportError:  # pragma: no cover - numba is the optional extra "fast"
    numba = None

from gisnoise.errors import CardError, InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, dcm_ned_to_body, transformer
from gisnoise.model import ModelCard
from gisnoise.model import ansatz as _model

__all__ = [
    "FAST_ANSATZES",
    "SEGMENT_M",
    "FlightInstants",
    "Receivers",
    "card_coefficients",
    "directivity_range",
    "evaluate_grid_fast",
    "level_from_body",
    "prepare_flight",
    "receivers_for",
    "run_grid",
    "run_window",
]

log = logging.getLogger(__name__)

FAST_ANSATZES = ("paper", "paper-offset")
"""Ansatzes the kernel implements (:mod:`gisnoise.model.ansatz` registry names)."""

SEGMENT_M = 1024.0
"""Longest run of receivers (m) along a grid row between exact positions (ends and middle)."""

DEFAULT_CHUNK_CELLS = 1 << 17
"""Cells per kernel call (whole rows); the unit of progress, cancel and threading."""

_LOG2_10 = math.log2(10.0)
_FM = True  # fastmath: contraction, reassociation; the kernel never sees NaN or inf


def _require_numba() -> None:
    if numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")


# --------------------------------------------------------------------------- polynomials


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


if numba is not None:
    _E0, _E1, _E2, _E3, _E4, _E5 = (np.float32(c) for c in _EXP2_C)
    _G0, _G1, _G2, _G3, _G4, _G5, _G6, _G7, _G8 = (np.float32(c) for c in _LOG2_C)
    _T0, _T1, _T2, _T3, _T4, _T5, _T6 = (np.float32(c) for c in _ATAN_C)
    _ONE = np.float32(1.0)
    _HALF = np.float32(0.5)
    _ZERO = np.float32(0.0)
    _TINY = np.float32(1e-30)
    _SQRT2 = np.float32(math.sqrt(2.0))
    _HALF_PI = np.float32(math.pi / 2.0)
    _PI = np.float32(math.pi)
    _EXP_LO = np.float32(-126.0)
    _EXP_HI = np.float32(126.0)
    _K10 = np.float32(_LOG2_10 / 10.0)  # 10^(L/10) = 2^(L * _K10)
    _DB_PER_LOG2 = np.float32(10.0 / _LOG2_10)  # L = log2(e) * _DB_PER_LOG2
    _F127 = np.float32(127.0)
    _TWO23 = np.float32(2.0 ** 23)
    _BIAS_BITS = np.float32(127.0 * 2.0 ** 23)
    _I23 = np.int32(23)
    _MANT = np.int32(0x7FFFFF)
    _ONE_BITS = np.int32(0x3F800000)
    _FLUSH = 32

    @_intrinsic
    def _f32_as_i32(typingctx, x):  # type: ignore[no-untyped-def]
        if x != _nbt.float32:
            return None

        def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
            return builder.bitcast(args[0], _ir.IntType(32))

        return _nbt.int32(_nbt.float32), codegen

    @_intrinsic
    def _i32_as_f32(typingctx, x):  # type: ignore[no-untyped-def]
        if x != _nbt.int32:
            return None

        def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
            return builder.bitcast(args[0], _ir.FloatType())

        return _nbt.float32(_nbt.int32), codegen

    @_intrinsic
    def _prefer_512bit_vectors(typingctx):  # type: ignore[no-untyped-def]
        """Mark the calling function for 512-bit vectors where the CPU has them.

        LLVM tunes AVX-512 CPUs to prefer 256-bit vectors (clang's ``-mprefer-vector-width``
        sets the same function attribute); for this arithmetic-bound kernel 512 bits measure
        about twice the throughput.  A no-op on CPUs without AVX-512.
        """

        def codegen(context, builder, sig, args):  # type: ignore[no-untyped-def]
            try:  # a string attribute: llvmlite's add() only takes enum ones.  Speed only, never results.
                set.add(builder.function.attributes, '"prefer-vector-width"="512"')
            except Exception:  # pragma: no cover - a future llvmlite without set-based attributes
                pass
            return context.get_dummy_value()

        return _nbt.none(), codegen

    @numba.njit(fastmath=_FM, error_model="numpy", inline="always", cache=True)
    def _exp2(y):  # type: ignore[no-untyped-def]
        """``2^y`` for float32 ``y`` (clamped to [-126, 126])."""
        y = min(max(y, _EXP_LO), _EXP_HI)
        n = np.floor(y + _HALF)
        f = y - n
        p = ((((_E5 * f + _E4) * f + _E3) * f + _E2) * f + _E1) * f + _E0
        # 2^n from its bit pattern (n + 127) 2^23, formed exactly in float32
        return p * _i32_as_f32(np.int32(n * _TWO23 + _BIAS_BITS))

    @numba.njit(fastmath=_FM, error_model="numpy", inline="always", cache=True)
    def _log2(x):  # type: ignore[no-untyped-def]
        """``log2(x)`` for positive normal float32 ``x``."""
        bits = _f32_as_i32(x)
        e = np.float32(np.int32(bits >> _I23)) - _F127  # x > 0: the sign bit is clear
        m = _i32_as_f32(np.int32((bits & _MANT) | _ONE_BITS))
        big = m > _SQRT2
        m = m * _HALF if big else m
        ef = e + (_ONE if big else _ZERO)
        u = m - _ONE
        p = (((((((_G8 * u + _G7) * u + _G6) * u + _G5) * u + _G4) * u + _G3) * u + _G2) * u + _G1) * u + _G0
        return ef + p

    @numba.njit(fastmath=_FM, error_model="numpy", inline="always", cache=True)
    def _atan2_pos(y, x):  # type: ignore[no-untyped-def]
        """``atan2(y, x)`` in [0, pi] for ``y >= 0`` (float32)."""
        ax = abs(x)
        mn = min(y, ax)
        mx = max(max(y, ax), _TINY)
        a = mn / mx
        s = a * a
        r = a * ((((((_T6 * s + _T5) * s + _T4) * s + _T3) * s + _T2) * s + _T1) * s + _T0)
        r = _HALF_PI - r if y > ax else r
        return _PI - r if x < _ZERO else r

    @numba.njit(fastmath=_FM, error_model="numpy", inline="always", cache=True)
    def _cell(xb, yb, zb, g, p2, cp3, sp3, p4, cp5, sp5, c6, kk, e7, dmin2):  # type: ignore[no-untyped-def]
        """Level ``L_UAV`` (dB) and energy ``10^(L/10)`` (+ background) from the body vector."""
        h2 = xb * xb + yb * yb
        d2 = h2 + zb * zb
        ih = _ONE / np.sqrt(max(h2, _TINY))
        idd = _ONE / np.sqrt(max(d2, _TINY))
        h = h2 * ih
        s_az = (yb * cp3 - xb * sp3) * ih
        s_po = -(zb * cp5 + h * sp5) * idd
        th = _atan2_pos(h, zb)
        a = _ONE + p2 * s_az * th
        b = _ONE + p4 * s_po
        lev = g * a * b - c6 * _log2(max(d2, dmin2)) + kk
        return lev, _exp2(lev * _K10) + e7

    @numba.njit(fastmath=_FM, error_model="numpy", nogil=True, cache=True)
    def _level_points(xb, yb, zb, g, coef):  # type: ignore[no-untyped-def]
        """The kernel's level for arrays of body vectors (for tests against the ansatz)."""
        n = xb.size
        out = np.empty(n, np.float32)
        for i in range(n):
            lev, e = _cell(xb[i], yb[i], zb[i], np.float32(g[i]), np.float32(coef[0]), np.float32(coef[1]),
                           np.float32(coef[2]), np.float32(coef[3]), np.float32(coef[4]), np.float32(coef[5]),
                           np.float32(coef[6]), np.float32(coef[7]), np.float32(0.0), np.float32(coef[9]))
            out[i] = lev
        return out

    @numba.njit(fastmath=_FM, error_model="numpy", nogil=True, cache=True)
    def _window_kernel(P, U, dh, has_dem, k, m0, c0, ncw, src, C, gain, cidx, coef, w, dt, radius, thr,
                       emax, energy, ta, computed):  # type: ignore[no-untyped-def]
        """Accumulate the metrics of one window of rows.

        ``P[r, 2 s]``, ``P[r, 2 s + 1]``, ``P[r, 2 s + 2]`` (f64, ENU m) are the receiver
        positions at the reference height at the start, middle and end of segment ``m0 + s``
        (global columns ``(m0 + s) k`` to ``(m0 + s + 1) k``) of window row ``r``; in between
        they are quadratic in the column.  ``U`` holds the unit normals there (DEM only) and
        ``dh[r, j]`` (f32) the receiver heights above the reference.  Window columns are the
        global columns ``c0 .. c0 + ncw``.  Per instant ``i``: UAV position ``src``, ENU->body
        matrix ``C``, gain, card row ``cidx`` of ``coef``, trapezoid weight ``w``, interval to
        the previous instant ``dt`` and audibility radius (m; +inf always audible, negative
        never).  Outputs are zero on entry.
        """
        _prefer_512bit_vectors()
        nr = P.shape[0]
        ns = (P.shape[1] - 1) // 2
        n = src.shape[0]
        nt = thr.shape[0]
        thr32 = np.empty(nt, np.float32)
        for t in range(nt):
            thr32[t] = np.float32(thr[t])
        lcur = np.empty(k, np.float32)
        lprev = np.empty(k, np.float32)
        # float32 partial sums over at most _FLUSH instants, added to the float64 outputs
        # (a float64 accumulator in the cell loop stops LLVM from vectorizing it)
        eacc = np.zeros(k, np.float32)
        tacc = np.zeros((nt, k), np.float32)
        e0 = np.empty(3)
        e1 = np.empty(3)
        e2 = np.empty(3)
        n0 = np.empty(3)
        n1 = np.empty(3)
        lo_b = np.empty(3)
        hi_b = np.empty(3)
        inv_k = 1.0 / k
        half_k = 0.5 * k
        half_k32 = np.float32(half_k)
        for r in range(nr):
            for s in range(ns):
                a = (m0 + s) * k
                lo = max(a, c0)
                hi = min(a + k, c0 + ncw)
                if hi <= lo:
                    continue
                m = hi - lo
                q0 = lo - a
                jl = lo - c0
                # position of the cell u = q - k/2 from the middle: e0 + u e1 + u^2 e2 (+ dh (n0 + u n1));
                # counting from the middle halves the float32 rounding of the body vector
                for c in range(3):
                    pa = P[r, 2 * s, c]
                    pm = P[r, 2 * s + 1, c]
                    pb = P[r, 2 * s + 2, c]
                    e0[c] = pm
                    e1[c] = (pb - pa) * inv_k
                    e2[c] = 2.0 * (pa - 2.0 * pm + pb) * inv_k * inv_k
                    n0[c] = 0.5 * (U[r, 2 * s, c] + U[r, 2 * s + 2, c]) if has_dem else 0.0
                    n1[c] = (U[r, 2 * s + 2, c] - U[r, 2 * s, c]) * inv_k if has_dem else 0.0
                    lo_b[c] = np.inf
                    hi_b[c] = -np.inf
                for q in range(q0, q0 + m):
                    u = q - half_k
                    for c in range(3):
                        v = e0[c] + u * (e1[c] + u * e2[c])
                        if has_dem:
                            v += dh[r, jl + q - q0] * (n0[c] + u * n1[c])
                        lo_b[c] = min(lo_b[c], v)
                        hi_b[c] = max(hi_b[c], v)
                cx = 0.5 * (lo_b[0] + hi_b[0])
                cy = 0.5 * (lo_b[1] + hi_b[1])
                cz = 0.5 * (lo_b[2] + hi_b[2])
                rad = 0.5 * math.sqrt((hi_b[0] - lo_b[0]) ** 2 + (hi_b[1] - lo_b[1]) ** 2
                                      + (hi_b[2] - lo_b[2]) ** 2) + 0.01
                audible = False
                for i in range(n):
                    if radius[i] < 0.0:
                        continue
                    dist = math.sqrt((src[i, 0] - cx) ** 2 + (src[i, 1] - cy) ** 2 + (src[i, 2] - cz) ** 2)
                    if dist - rad <= radius[i]:
                        audible = True
                        break
                if not audible:
                    continue
                # 1-D views indexed from 0: LLVM then sees consecutive addresses and vectorizes
                em = emax[r, jl:jl + m]
                en = energy[r, jl:jl + m]
                dhr = dh[r, jl:jl + m] if has_dem else dh[0, 0:1]
                for q in range(m):
                    computed[r, jl + q] = 1
                for i in range(n):
                    ci = cidx[i]
                    v0 = e0[0] - src[i, 0]
                    v1 = e0[1] - src[i, 1]
                    v2 = e0[2] - src[i, 2]
                    # body frame: A + u (B + u D) (+ dh (N + u T)), u = q - k/2
                    ax = np.float32(C[i, 0, 0] * v0 + C[i, 0, 1] * v1 + C[i, 0, 2] * v2)
                    ay = np.float32(C[i, 1, 0] * v0 + C[i, 1, 1] * v1 + C[i, 1, 2] * v2)
                    az = np.float32(C[i, 2, 0] * v0 + C[i, 2, 1] * v1 + C[i, 2, 2] * v2)
                    bx = np.float32(C[i, 0, 0] * e1[0] + C[i, 0, 1] * e1[1] + C[i, 0, 2] * e1[2])
                    by = np.float32(C[i, 1, 0] * e1[0] + C[i, 1, 1] * e1[1] + C[i, 1, 2] * e1[2])
                    bz = np.float32(C[i, 2, 0] * e1[0] + C[i, 2, 1] * e1[1] + C[i, 2, 2] * e1[2])
                    dx = np.float32(C[i, 0, 0] * e2[0] + C[i, 0, 1] * e2[1] + C[i, 0, 2] * e2[2])
                    dy = np.float32(C[i, 1, 0] * e2[0] + C[i, 1, 1] * e2[1] + C[i, 1, 2] * e2[2])
                    dz = np.float32(C[i, 2, 0] * e2[0] + C[i, 2, 1] * e2[1] + C[i, 2, 2] * e2[2])
                    g = np.float32(gain[i])
                    p2 = np.float32(coef[ci, 0])
                    cp3 = np.float32(coef[ci, 1])
                    sp3 = np.float32(coef[ci, 2])
                    p4 = np.float32(coef[ci, 3])
                    cp5 = np.float32(coef[ci, 4])
                    sp5 = np.float32(coef[ci, 5])
                    c6 = np.float32(coef[ci, 6])
                    kk = np.float32(coef[ci, 7])
                    e7 = np.float32(coef[ci, 8])
                    dmin2 = np.float32(coef[ci, 9])
                    wi = np.float32(w[i])
                    if has_dem:
                        nx = np.float32(C[i, 0, 0] * n0[0] + C[i, 0, 1] * n0[1] + C[i, 0, 2] * n0[2])
                        ny = np.float32(C[i, 1, 0] * n0[0] + C[i, 1, 1] * n0[1] + C[i, 1, 2] * n0[2])
                        nz = np.float32(C[i, 2, 0] * n0[0] + C[i, 2, 1] * n0[1] + C[i, 2, 2] * n0[2])
                        tx = np.float32(C[i, 0, 0] * n1[0] + C[i, 0, 1] * n1[1] + C[i, 0, 2] * n1[2])
                        ty = np.float32(C[i, 1, 0] * n1[0] + C[i, 1, 1] * n1[1] + C[i, 1, 2] * n1[2])
                        tz = np.float32(C[i, 2, 0] * n1[0] + C[i, 2, 1] * n1[1] + C[i, 2, 2] * n1[2])
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            hh = dhr[q]
                            xb = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                            yb = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                            zb = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                            lev, e = _cell(xb, yb, zb, g, p2, cp3, sp3, p4, cp5, sp5, c6, kk, e7, dmin2)
                            em[q] = max(em[q], e)
                            eacc[q] += wi * e
                            lcur[q] = lev
                    else:
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            xb = ax + qf * (bx + qf * dx)
                            yb = ay + qf * (by + qf * dy)
                            zb = az + qf * (bz + qf * dz)
                            lev, e = _cell(xb, yb, zb, g, p2, cp3, sp3, p4, cp5, sp5, c6, kk, e7, dmin2)
                            em[q] = max(em[q], e)
                            eacc[q] += wi * e
                            lcur[q] = lev
                    if nt > 0:
                        if e7 != _ZERO:
                            for q in range(m):
                                lcur[q] = _log2(_exp2(lcur[q] * _K10) + e7) * _DB_PER_LOG2
                        if i > 0:
                            dti = np.float32(dt[i])
                            for t in range(nt):
                                tv = thr32[t]
                                tac = tacc[t]
                                for q in range(m):
                                    x0 = lprev[q] - tv
                                    x1 = lcur[q] - tv
                                    up0 = x0 >= _ZERO
                                    up1 = x1 >= _ZERO
                                    fr = _ZERO
                                    if up0 and up1:
                                        fr = _ONE
                                    elif up0 != up1:
                                        fr = max(x0, x1) / abs(x0 - x1)
                                    tac[q] += dti * fr
                        for q in range(m):
                            lprev[q] = lcur[q]
                    if (i + 1) % _FLUSH == 0 or i == n - 1:
                        for q in range(m):
                            en[q] += eacc[q]
                            eacc[q] = _ZERO
                        for t in range(nt):
                            tat = ta[t, r, jl:jl + m]
                            tac = tacc[t]
                            for q in range(m):
                                tat[q] += tac[q]
                                tac[q] = _ZERO
        return 0


# --------------------------------------------------------------------------- cards


_ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _fast_ansatz(card: ModelCard) -> str:
    """The card's ansatz name if the kernel implements it; :class:`CardError` otherwise."""
    registered = {"paper": _model.PAPER, "paper-offset": _model.PAPER_OFFSET}
    model = card.model
    if card.ansatz not in registered or model is not registered[card.ansatz]:
        raise CardError(f"card {card.id!r}: engine 'fast' implements the ansatzes {', '.join(FAST_ANSATZES)} of "
                        f"gisnoise.model.ansatz, not {card.ansatz!r}; use engine='numpy'", field="ansatz")
    return card.ansatz


def card_coefficients(card: ModelCard, *, background: bool = False,
                      min_distance_m: float = 1.0) -> tuple[float, float, np.ndarray]:
    """The kernel's form of a card: ``p0, p1`` and the per-card coefficient row.

    ``L_UAV = (p0 + p1 log10 P_el) (1 + p2 sin(phi - p3)(theta + pi/2))(1 + p4 sin(theta - p5))
    - c6 log2(max(d^2, d_min^2)) + kk`` with ``c6 = 10 log10(2) p6`` and
    ``kk = c6 log2(d_ref^2)`` (Eq. 9-10 with ``20 log10(d/d_ref) = 10 log10(2) log2(d^2/d_ref^2)``).

    Returns
    -------
    p0, p1 : float
        Gain ``g = p0 + p1 log10(P_el)`` (``p0 = 0`` for ``paper``), dB.
    row : ndarray, shape (10,)
        ``p2, cos p3, sin p3, p4, cos p5, sin p5, c6, kk, e7, d_min^2`` with ``e7 = 10^(p7/10)``
        when the background is included, else 0.

    Raises
    ------
    CardError
        The card's ansatz is not one the kernel implements (field ``ansatz``).
    """
    name = _fast_ansatz(card)
    p = card.p
    if name == "paper":
        p0, (p1, p2, p3, p4, p5, p6, p7) = 0.0, p
    else:
        p0, p1, p2, p3, p4, p5, p6, p7 = p
    c6 = 10.0 * math.log10(2.0) * p6
    kk = c6 * math.log2(card.reference_distance_m ** 2)
    e7 = 10.0 ** (p7 / 10.0) if background else 0.0
    row = np.array([p2, math.cos(p3), math.sin(p3), p4, math.cos(p5), math.sin(p5), c6, kk, e7,
                    float(min_distance_m) ** 2])
    return float(p0), float(p1), row


def level_from_body(card: ModelCard, xb: Any, yb: Any, zb: Any, power_w: Any, *,
                    min_distance_m: float = 1.0) -> np.ndarray:
    """The kernel's ``L_UAV`` (dB, float32) for body vectors ``(xb, yb, zb)`` (m) and power (W).

    Arrays broadcast.  The tests compare it with the ansatz of :mod:`gisnoise.model.ansatz` at
    the emission angles of the same vectors.
    """
    _require_numba()
    p0, p1, row = card_coefficients(card, min_distance_m=min_distance_m)
    xb, yb, zb, pw = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (xb, yb, zb, power_w)))
    g = p0 + p1 * np.log10(pw.ravel() / card.reference_power_w)
    out = _level_points(xb.astype(np.float32).ravel(), yb.astype(np.float32).ravel(),
                        zb.astype(np.float32).ravel(), g, row)
    return out.reshape(xb.shape)


# --------------------------------------------------------------------------- instants of a flight


@dataclass(frozen=True, eq=False)
class FlightInstants:
    """One flight's evaluation instants, ready for the kernel (a local frame's ENU, m).

    Attributes
    ----------
    t : ndarray (n,)
        Instants, s.
    src : ndarray (n, 3)
        UAV position, ENU m.
    C : ndarray (n, 3, 3)
        Rotation ENU -> body axes.
    gain : ndarray (n,)
        ``p0 + p1 log10(P_el)`` of each instant's card, dB.
    cidx : ndarray of int64 (n,)
        Row of ``coef`` per instant.
    coef : ndarray (n_cards, 10)
        :func:`card_coefficients` rows.
    w : ndarray (n,)
        Trapezoid weights, s.
    dt : ndarray (n,)
        Interval to the previous instant, s (0 first).
    radius : ndarray (n,)
        Audibility radius, m: beyond it the level is below the floor at every emission
        angle (``inf`` without a floor, negative when never audible).
    """

    t: np.ndarray
    src: np.ndarray
    C: np.ndarray
    gain: np.ndarray
    cidx: np.ndarray
    coef: np.ndarray
    w: np.ndarray
    dt: np.ndarray
    radius: np.ndarray
    source: str = "trajectory"

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def n(self) -> int:
        return int(self.t.size)


def directivity_range(p2: float, p4: float, p5: float, *, n: int = 2049) -> tuple[float, float]:
    """Bounds ``(lo, hi)`` of ``a b = (1 + p2 sin(phi - p3)(theta + pi/2))(1 + p4 sin(theta - p5))`` over all angles.

    For a fixed polar angle the azimuth only moves ``a`` within ``1 -+ |p2| (theta + pi/2)``;
    the remaining function of ``theta`` is maximised (minimised) on ``n`` points of
    [-pi/2, pi/2] and widened by its Lipschitz constant times half the spacing, so the
    bounds are safe, not estimates.

    >>> [round(v, 3) for v in directivity_range(0.0, 0.3, 0.0)]  # 1 + 0.3 sin(theta)
    [0.7, 1.3]
    """
    th = np.linspace(-np.pi / 2, np.pi / 2, n)
    span = np.abs(p2) * (th + np.pi / 2)
    b = 1.0 + p4 * np.sin(th - p5)
    prods = np.stack([(1.0 + span) * b, (1.0 - span) * b])
    lip = abs(p2) * (1.0 + abs(p4)) + (1.0 + abs(p2) * np.pi) * abs(p4)
    slack = lip * (th[1] - th[0]) / 2.0 + 1e-12
    return float(prods.min() - slack), float(prods.max() + slack)


def _audibility_radius(gain: np.ndarray, p2: np.ndarray, p4: np.ndarray, p5: np.ndarray, p6: np.ndarray,
                       p7: np.ndarray, d_ref: np.ndarray, d_min: float, floor_db: float | None,
                       background: bool) -> np.ndarray:
    """Distance beyond which an upper bound of the level over all emission angles is below the floor, m.

    The bound is ``g hi`` for ``g >= 0`` and ``g lo`` for ``g < 0`` with
    :func:`directivity_range`; spreading decreases with distance when ``p6 > 0`` (else
    no radius: ``inf``).  Negative: below the floor even at the near-field clamp.
    """
    n = gain.size
    if floor_db is None:
        return np.full(n, np.inf)
    bound = np.empty(n)
    keys = np.stack([p2, p4, p5], axis=-1)
    for key in np.unique(keys, axis=0):
        sel = np.all(keys == key, axis=-1)
        lo, hi = directivity_range(*key)
        g = gain[sel]
        bound[sel] = np.where(g >= 0, g * hi, g * lo)  # dB at d_ref over all angles
    target = np.full(n, float(floor_db))
    if background:
        # 10 log10(10^(Lu/10) + 10^(p7/10)) < floor  <=>  Lu < 10 log10(10^(floor/10) - 10^(p7/10))
        with np.errstate(divide="ignore", invalid="ignore"):
            target = np.where(floor_db > p7, 10.0 * np.log10(10.0 ** (floor_db / 10.0) - 10.0 ** (p7 / 10.0)),
                              np.nan)
    with np.errstate(over="ignore", invalid="ignore"):
        dist = d_ref * 10.0 ** ((bound - target) / (20.0 * np.where(p6 > 0, p6, 1.0)))
    r = np.where(dist <= d_min, -1.0, dist * (1.0 + 1e-9) + 1e-3)
    r = np.where((p6 > 0) & np.isfinite(target), r, np.inf)
    return np.where(np.isnan(r), np.inf, r)


def _instants(t: np.ndarray, state: dict[str, np.ndarray], card_idx: np.ndarray, cards: Sequence[ModelCard],
              frame: LocalFrame, *, background: bool, min_distance_m: float, floor_db: float | None,
              source: str) -> FlightInstants:
    n = t.size
    used = sorted(set(card_idx.tolist()))
    coef = np.zeros((len(cards), 10))
    p0 = np.zeros(len(cards))
    p1 = np.zeros(len(cards))
    ref_w = np.ones(len(cards))
    raw = np.zeros((len(cards), 5))  # p2, p4, p5, p6, p7 for the audibility bound
    d_ref = np.full(len(cards), 40.0)
    for k in used:
        c = cards[k]
        p0[k], p1[k], coef[k] = card_coefficients(c, background=background, min_distance_m=min_distance_m)
        pp = dict(zip(c.model.params, c.p, strict=True))
        raw[k] = (pp["p2"], pp["p4"], pp["p5"], pp["p6"], pp["p7"])
        ref_w[k] = c.reference_power_w
        d_ref[k] = c.reference_distance_m
    ci = card_idx.astype(np.int64)
    p_el = np.asarray(state["power_w"], dtype=float) / ref_w[ci]
    gain = p0[ci] + p1[ci] * np.log10(p_el)
    src = np.ascontiguousarray(np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1))
    C = dcm_ned_to_body(np.radians(state["yaw"]), np.radians(state["pitch"]), np.radians(state["roll"]))
    C = np.ascontiguousarray(np.broadcast_to(C, (n, 3, 3)) @ _ENU_TO_NED)
    from gisnoise.maps.evaluate import _trapezoid_weights

    w = _trapezoid_weights(t)
    dt = np.concatenate([[0.0], np.diff(t)])
    radius = _audibility_radius(gain, *raw[ci].T, d_ref[ci], min_distance_m, floor_db, background)
    return FlightInstants(t=np.asarray(t, dtype=float), src=src, C=C, gain=gain, cidx=ci, coef=coef, w=w, dt=dt,
                          radius=radius, source=source)


def prepare_flight(traj: Trajectory, cards: Any, frame: LocalFrame, *, substeps: int = 1, background: bool = False,
                   min_distance_m: float = 1.0, floor_db: float | None = None) -> FlightInstants:
    """A trajectory's evaluation instants in ``frame`` (as the NumPy evaluator forms them).

    Parameters
    ----------
    traj : Trajectory
    cards : CardSet or sequence of ModelCard
        Cards by phase; every card serving an instant must have a :data:`FAST_ANSATZES` ansatz.
    frame : LocalFrame
        The receivers' local frame.
    substeps : int
        Sub-intervals per sample interval (>= 1).
    background : bool
        Include the cards' background level.
    min_distance_m : float
        Near-field clamp of the distance, m.
    floor_db : float, optional
        Audibility floor, dB(A), for the per-instant radius.
    """
    from gisnoise.maps.evaluate import CardSet, _eval_states

    cardset = cards if isinstance(cards, CardSet) else CardSet(cards)
    idx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    t_eval, state, src_sample = _eval_states(traj, int(substeps))
    return _instants(t_eval, state, idx_samples[src_sample], cardset.cards, frame, background=background,
                     min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source)


def snapshot_instant(traj: Trajectory, cards: Any, frame: LocalFrame, t_s: float, *, background: bool = False,
                     min_distance_m: float = 1.0, floor_db: float | None = None) -> FlightInstants:
    """The single instant ``t_s`` (state interpolated as the NumPy evaluator does)."""
    from gisnoise.maps.evaluate import CardSet

    cardset = cards if isinstance(cards, CardSet) else CardSet(cards)
    state = traj.interpolate(np.array([float(t_s)]))
    idx = cardset.assign(state.pop("phase"), [t_s], source=traj.source)
    return _instants(np.array([float(t_s)]), state, idx, cardset.cards, frame, background=background,
                     min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source)


# --------------------------------------------------------------------------- receivers


@dataclass(frozen=True, eq=False)
class Receivers:
    """The receivers of a grid in a local frame, as the kernel reads them.

    Attributes
    ----------
    grid : GridSpec
    origin : tuple of float
        ``(lat0, lon0, h0)`` of the local ENU frame (deg, deg, m ellipsoidal).
    h_ref : float
        Ellipsoidal height of the lattice positions, m (flat ground: the receivers' height).
    dh : ndarray of float32, shape ``grid.shape``, or None
        Receiver height above ``h_ref`` from a DEM, m (0 where the DEM has no value).
    valid : ndarray of bool, shape ``grid.shape``, or None
        Receivers on the DEM (the others get NaN).
    seg : int
        Cells per segment (exact positions every ``seg`` columns).
    ground : dict
        How the ground was chosen (for the result's metadata).
    dh_origin : tuple of int
        Grid row and column of ``dh[0, 0]`` and ``valid[0, 0]`` (a window's copy, see
        :meth:`for_window`).
    """

    grid: GridSpec
    origin: tuple[float, float, float]
    h_ref: float
    dh: np.ndarray | None = None
    valid: np.ndarray | None = None
    seg: int = 1
    ground: dict | None = None
    dh_origin: tuple[int, int] = (0, 0)

    def for_window(self, r0: int, r1: int, c0: int, c1: int) -> Receivers:
        """The same receivers holding only the DEM heights of rows ``r0:r1``, columns ``c0:c1``
        (what a worker needs for one tile)."""
        if self.dh is None:
            return self
        o_r, o_c = self.dh_origin
        sl = (slice(r0 - o_r, r1 - o_r), slice(c0 - o_c, c1 - o_c))
        return replace(self, dh=np.ascontiguousarray(self.dh[sl]),
                       valid=None if self.valid is None else np.ascontiguousarray(self.valid[sl]),
                       dh_origin=(r0, c0))

    @property
    def frame(self) -> LocalFrame:
        """The local frame (a per-thread instance: pyproj transformers are not shared)."""
        from gisnoise.maps.evaluate import _local_frame

        return _local_frame(*self.origin)

    @property
    def n_segments(self) -> int:
        return -(-self.grid.width // self.seg)

    def lattice(self, r0: int, r1: int, m0: int, m1: int) -> tuple[np.ndarray, np.ndarray]:
        """Exact ENU positions ``P`` (and unit normals ``U``) of rows ``r0:r1`` at the ends and middles of segments ``m0:m1``.

        Shape ``(r1 - r0, 2 (m1 - m0) + 1, 3)``, m; column ``c`` (fractional in the middles)
        has its centre at ``x = transform.c + transform.a (c + 0.5)``.
        """
        t = self.grid.transform
        cols = np.arange(2 * m0, 2 * m1 + 1) * (0.5 * self.seg)  # segment ends and middles
        rows = np.arange(r0, r1)
        x = np.broadcast_to(t.c + t.a * (cols + 0.5), (rows.size, cols.size))
        y = np.broadcast_to((t.f + t.e * (rows + 0.5))[:, None], (rows.size, cols.size))
        lon, lat = transformer(self.grid.crs, WGS84).transform(np.ascontiguousarray(x), np.ascontiguousarray(y))
        fr = self.frame
        P = np.stack(fr.to_enu(lat, lon, np.full(lat.shape, self.h_ref)), axis=-1)
        if self.dh is None:
            return np.ascontiguousarray(P), np.zeros((1, 1, 3))
        up = np.stack(fr.to_enu(lat, lon, np.full(lat.shape, self.h_ref + 1.0)), axis=-1)
        return np.ascontiguousarray(P), np.ascontiguousarray(up - P)


def segment_cells(resolution_m: float) -> int:
    """Cells per segment for a cell size (m): the longest run within :data:`SEGMENT_M`, 1 to 2048."""
    return int(min(2048, max(1, math.floor(SEGMENT_M / float(resolution_m)))))


def receivers_for(grid: GridSpec, trajectories: Iterable[Trajectory] = (), *, receiver_height: float = 1.5,
                  dem: Any = None, ground_h: float | None = None, dem_offset_m: float = 0.0) -> Receivers:
    """Receivers of ``grid`` with the NumPy evaluator's ground rules.

    With a DEM the ground comes from it (frame height: the mean ground); else flat at
    ``ground_h``, by default the lowest height of the trajectories.
    """
    from gisnoise.maps.evaluate import _as_float, _dem_on_grid

    hr = _as_float(receiver_height, "receiver_height")
    lon_c, lat_c = grid.centre_wgs84()
    seg = segment_cells(min(grid.resolution))
    if dem is not None:
        ground = _dem_on_grid(dem, grid) + _as_float(dem_offset_m, "dem_offset_m")
        valid = np.isfinite(ground)
        if not valid.any():
            raise InputError("dem: the DEM does not cover the grid", field="dem")
        if not valid.all():
            log.warning("dem: %d of %d receivers lie outside the DEM or on nodata; they get nodata",
                        int((~valid).sum()), valid.size)
        h0 = float(np.nanmean(ground))
        dh = np.where(valid, ground - h0, 0.0).astype(np.float32)
        return Receivers(grid, (lat_c, lon_c, h0), h0 + hr, dh, valid, seg,
                         {"ground": "dem", "dem_offset_m": float(dem_offset_m)})
    trajs = list(trajectories)
    if ground_h is None:
        if not trajs:
            raise InputError("ground_h: give the ground height (no DEM and no trajectory)", field="ground_h")
        lows = [(float(np.min(tr.h)), tr) for tr in trajs]
        g, tr = min(lows, key=lambda v: v[0])
        if tr.phase[int(np.argmin(tr.h))] == "horizontal":
            log.warning("ground height taken as the trajectory's lowest point (%.1f m) although it is in "
                        "horizontal flight there; state the ground height", g)
        desc = {"ground": "flat", "ground_h_m": g, "ground_h_source": "lowest trajectory point"}
    else:
        g = _as_float(ground_h, "ground_h")
        desc = {"ground": "flat", "ground_h_m": g, "ground_h_source": "given"}
    return Receivers(grid, (lat_c, lon_c, g), g + hr, None, None, seg, desc)


# --------------------------------------------------------------------------- running the kernel


@dataclass(frozen=True, eq=False)
class WindowResult:
    """Kernel output on a window of rows ``r0:r1`` and columns ``c0:c1``.

    ``emax`` (float32) the largest ``10^(L/10)``; ``energy`` (float64) ``sum w_i 10^(L_i/10)``, s;
    ``ta`` (float64, one plane per threshold) time above, s; ``computed`` (bool) the cells
    within audibility (the others are zero and certainly below the floor).
    """

    emax: np.ndarray
    energy: np.ndarray
    ta: np.ndarray
    computed: np.ndarray


def window_lattice(rc: Receivers, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
    """The lattice (:meth:`Receivers.lattice`) a window needs; compute it once for many flights."""
    return rc.lattice(r0, r1, c0 // rc.seg, -(-c1 // rc.seg))


def run_window(fl: FlightInstants, rc: Receivers, r0: int, r1: int, c0: int, c1: int,
               thresholds: Sequence[float] = (), *, lattice: tuple[np.ndarray, np.ndarray] | None = None
               ) -> WindowResult:
    """Run the kernel on rows ``r0:r1`` and columns ``c0:c1`` of the grid (releases the GIL).

    ``c0`` and ``c1`` should be multiples of ``rc.seg`` (or ``c1`` the grid's width) so that
    the window's cells equal the whole grid's bit for bit.  ``lattice``: the window's
    :func:`window_lattice`, when already computed.
    """
    _require_numba()
    W = rc.grid.width
    if not (0 <= r0 < r1 <= rc.grid.height and 0 <= c0 < c1 <= W):
        raise InputError(f"window rows {r0}:{r1}, columns {c0}:{c1} outside the grid {rc.grid.shape}",
                         field="window")
    k = rc.seg
    m0 = c0 // k
    P, U = window_lattice(rc, r0, r1, c0, c1) if lattice is None else lattice
    nr, ncw = r1 - r0, c1 - c0
    if rc.dh is not None:
        o_r, o_c = rc.dh_origin
        if r0 < o_r or c0 < o_c or r1 - o_r > rc.dh.shape[0] or c1 - o_c > rc.dh.shape[1]:
            raise InputError(f"window rows {r0}:{r1}, columns {c0}:{c1} outside the receivers' DEM heights",
                             field="window")
        dh = np.ascontiguousarray(rc.dh[r0 - o_r:r1 - o_r, c0 - o_c:c1 - o_c])
    else:
        dh = np.zeros((1, 1), np.float32)
    thr = np.asarray(list(thresholds), dtype=np.float64)
    emax = np.zeros((nr, ncw), np.float32)
    energy = np.zeros((nr, ncw), np.float64)
    ta = np.zeros((thr.size, nr, ncw), np.float64)
    computed = np.zeros((nr, ncw), np.uint8)
    _window_kernel(P, U, dh, rc.dh is not None, k, m0, c0, ncw, fl.src, fl.C, fl.gain, fl.cidx, fl.coef, fl.w,
                   fl.dt, fl.radius, thr, emax, energy, ta, computed)
    return WindowResult(emax, energy, ta, computed.astype(bool))


_POOLS: dict[int, ThreadPoolExecutor] = {}
_POOLS_LOCK = threading.Lock()


def thread_pool(n: int) -> ThreadPoolExecutor:
    """A process-wide pool of ``n`` threads, kept for reuse (its threads keep their pyproj transformers)."""
    with _POOLS_LOCK:
        pool = _POOLS.get(n)
        if pool is None:
            pool = _POOLS[n] = ThreadPoolExecutor(max_workers=n, thread_name_prefix=f"gisnoise-fast{n}")
        return pool


def default_threads() -> int:
    """Kernel threads: ``GISNOISE_THREADS`` if set, else the CPUs this process may use."""
    raw = os.environ.get("GISNOISE_THREADS", "").strip()
    if raw:
        try:
            n = int(raw)
        except ValueError:
            raise InputError(f"GISNOISE_THREADS must be a positive integer, got {raw!r}",
                             field="GISNOISE_THREADS") from None
        if n < 1:
            raise InputError(f"GISNOISE_THREADS must be a positive integer, got {raw!r}", field="GISNOISE_THREADS")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _map_threads(fn: Callable[[Any], Any], items: Sequence[Any], put: Callable[[Any, Any], None], threads: int,
                 *, poll: Callable[[], None] | None = None) -> None:
    """``put(item, fn(item))`` for every item, ``put`` in the calling thread as results come.

    With ``threads > 1`` (and more than one item) ``fn`` runs on :func:`thread_pool`, at most
    ``2 threads`` items pending; ``poll`` (which may raise to stop) is called after every batch
    of finished items, and on the way out the pending items are cancelled or waited for.
    Otherwise the items run in order here, ``poll`` before each.
    """
    if threads == 1 or len(items) == 1:
        for x in items:
            if poll is not None:
                poll()
            put(x, fn(x))
        return
    pool = thread_pool(threads)
    pending: dict[Any, Any] = {}
    it = iter(items)
    try:
        for x in it:
            pending[pool.submit(fn, x)] = x
            if len(pending) >= 2 * threads:
                break
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                put(pending.pop(f), f.result())
            if poll is not None:
                poll()
            for x in it:
                pending[pool.submit(fn, x)] = x
                if len(pending) >= 2 * threads:
                    break
    finally:
        for f in pending:
            f.cancel()
        wait(pending)


def run_grid(fl: FlightInstants, rc: Receivers, thresholds: Sequence[float] = (), *, threads: int | None = None,
             chunk_cells: int = DEFAULT_CHUNK_CELLS, progress: Callable[[float], Any] | None = None,
             cancel: Callable[[], bool] | None = None) -> WindowResult:
    """The kernel on the whole grid, in blocks of rows spread over ``threads`` threads.

    ``progress`` gets the fraction of rows done after every block; ``cancel`` is polled
    between blocks and, returning true, raises :class:`~gisnoise.errors.Cancelled`.
    """
    from gisnoise.errors import Cancelled

    H, W = rc.grid.shape
    nthreads = default_threads() if threads is None else max(1, int(threads))
    rows = max(1, min(int(chunk_cells) // W, -(-H // (4 * nthreads))))  # >= 4 blocks a thread when it can
    blocks = [(r, min(r + rows, H)) for r in range(0, H, rows)]
    nt = len(list(thresholds))
    emax = np.zeros((H, W), np.float32)
    energy = np.zeros((H, W), np.float64)
    ta = np.zeros((nt, H, W), np.float64)
    computed = np.zeros((H, W), bool)
    done = 0

    def put(b: tuple[int, int], res: WindowResult) -> None:
        nonlocal done
        r0, r1 = b
        emax[r0:r1] = res.emax
        energy[r0:r1] = res.energy
        ta[:, r0:r1] = res.ta
        computed[r0:r1] = res.computed
        done += r1 - r0
        if progress is not None:
            progress(done / H)

    def check() -> None:
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")

    _map_threads(lambda b: run_window(fl, rc, b[0], b[1], 0, W, thresholds), blocks, put, nthreads, poll=check)
    return WindowResult(emax, energy, ta, computed)


def db(x: np.ndarray) -> np.ndarray:
    """``10 log10(x)`` with 0 -> -inf and no warning."""
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(x)


# --------------------------------------------------------------------------- the evaluator


def evaluate_grid_fast(
    traj: Trajectory,
    cards: Any,
    grid: GridSpec,
    *,
    metrics: Sequence[str] | str = ("LAmax", "LAeq", "SEL"),
    receiver_height: float = 1.5,
    dem: Any = None,
    ground_h: float | None = None,
    dem_offset_m: float = 0.0,
    period_s: float | None = None,
    threshold_db: float | Sequence[float] | None = None,
    snapshot_t: float | None = None,
    background: bool = False,
    substeps: int = 1,
    uncertainty: bool = False,
    chunk_cells: int | None = None,
    block_size: int | None = None,
    min_distance_m: float = 1.0,
    progress: Callable[[float], Any] | None = None,
    cancel: Callable[[], bool] | None = None,
    floor_db: float | None = None,
    threads: int | None = None,
    engine: str = "fast",
    kernel: Any = None,
    temperature_c: float = 15.0,
) -> Any:
    """:func:`gisnoise.maps.evaluate.evaluate_grid` with the fast kernel (same parameters and bands).

    Differences: ``uncertainty`` is refused (the Jacobian stays with the NumPy engine);
    ``chunk_cells`` is the number of cells per kernel call (whole rows, default
    :data:`DEFAULT_CHUNK_CELLS`) and ``block_size`` is not used (the kernel keeps no
    cells x instants arrays).  Further parameters:

    floor_db : float, optional
        Audibility floor, dB(A).  Cells whose level is, by a bound over all emission angles,
        below it at every instant are not computed: NaN in the level bands, 0 in time-above
        bands of levels >= ``floor_db``.  Default: every cell is computed.
    threads : int, optional
        Kernel threads (default :func:`default_threads`).
    engine : str
        ``"fast"`` (the value :func:`~gisnoise.maps.evaluate.evaluate_grid` forwards).
    kernel : None
        The NumPy engine's block replacement; refused here.
    temperature_c : float
        Not used: the ``paper`` ansatzes do not need the speed of sound.

    Returns
    -------
    MapResult
        The bands of the NumPy engine within 0.01 dB; ``metadata["engine"] == "fast"``,
        ``metadata["cells_below_floor"]``.
    """
    from gisnoise.maps.evaluate import (
        MapResult,
        _as_float,
        _band_order,
        _check_flight_and_grid,
        _map_metadata,
        _period_and_snapshot,
        _requested,
        _substeps_and_min_distance,
        snapshot_name,
        threshold_name,
    )

    if engine != "fast":
        raise InputError(f"engine must be 'numpy' or 'fast', got {engine!r}", field="engine")
    if kernel is not None:
        raise InputError("kernel: a replacement block function belongs to engine='numpy'", field="kernel")
    _require_numba()
    _check_flight_and_grid(traj, grid)
    if uncertainty:
        raise InputError("uncertainty: engine 'fast' computes levels only; use engine='numpy' for the "
                         "uncertainty bands", field="engine")
    cardset, metrics, thresholds = _requested(cards, metrics, threshold_db, snapshot_t)
    substeps, min_d = _substeps_and_min_distance(substeps, min_distance_m)
    floor = None if floor_db is None else _as_float(floor_db, "floor_db")
    if chunk_cells is not None and (isinstance(chunk_cells, bool) or int(chunk_cells) < 1):
        raise InputError(f"chunk_cells must be >= 1, got {chunk_cells!r}", field="chunk_cells")
    chunk = DEFAULT_CHUNK_CELLS if chunk_cells is None else int(chunk_cells)
    _, period, snap = _period_and_snapshot(traj, metrics, thresholds, period_s, snapshot_t)

    rc = receivers_for(grid, [traj], receiver_height=receiver_height, dem=dem, ground_h=ground_h,
                       dem_offset_m=dem_offset_m)
    frame = rc.frame
    fl = prepare_flight(traj, cardset, frame, substeps=substeps, background=background, min_distance_m=min_d,
                        floor_db=floor)
    share = 1.0 if snap is None else fl.n / (fl.n + 1.0)

    def prog(f: float) -> None:
        if progress is not None:
            progress(share * f)

    res = run_grid(fl, rc, thresholds, threads=threads, chunk_cells=chunk, progress=prog, cancel=cancel)
    bands: dict[str, np.ndarray] = {}
    below = ~res.computed
    for name in _band_order(metrics, thresholds, snap, False):
        bands[name] = np.full(grid.shape, np.nan)
    if "LAmax" in metrics:
        bands["LAmax"] = db(res.emax.astype(np.float64))
    if "SEL" in metrics:
        bands["SEL"] = db(res.energy)
    if "LAeq" in metrics:
        assert period is not None
        bands["LAeq"] = db(res.energy / period)
    for i, thr in enumerate(thresholds):
        a = res.ta[i].copy()
        if floor is None or thr < floor:
            a[below] = np.nan
        bands[threshold_name(thr)] = a
    for name in ("LAmax", "SEL", "LAeq"):
        if name in bands:
            bands[name][below] = np.nan
    if snap is not None:
        s_fl = snapshot_instant(traj, cardset, frame, snap, background=background, min_distance_m=min_d,
                                floor_db=floor)
        s = run_grid(s_fl, rc, (), threads=threads, chunk_cells=chunk, cancel=cancel,
                     progress=None if progress is None else (lambda f: progress(share + (1 - share) * f)))
        a = db(s.emax.astype(np.float64))
        a[~s.computed] = np.nan
        bands[snapshot_name(snap)] = a
    if rc.valid is not None and not rc.valid.all():
        for a in bands.values():
            a[~rc.valid] = np.nan
    used = sorted(set(fl.cidx.tolist()))
    meta = _map_metadata(grid, bands, traj, fl.n, substeps, period, float(receiver_height), rc.ground or {},
                         background, min_d, thresholds, snap, cardset, used)
    meta.update({"engine": "fast", "floor_db": floor, "cells_below_floor": int(below.sum())})
    return MapResult(bands=bands, grid=grid, metadata=meta)
