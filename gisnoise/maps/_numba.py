"""The numba kernels of the fast engine: one compiled unit, float32, vectorized by LLVM.

:func:`_window_kernel` accumulates the metrics of one window of grid rows over every
instant of a flight; :func:`_level_points` gives the kernel's level for arrays of body
vectors (for the tests against the ansatz).  Everything else of the engine (the cards'
coefficients, the flight's instants, the receivers' lattice, threads) is prepared in
plain NumPy by :mod:`gisnoise.maps.fastkernel` and its inputs.

How the kernel is fast (all in float32, where the level keeps about 1e-5 dB):

* **No angles.**  The emission angles enter Eq. 9 only as ``sin(phi - p3)``,
  ``sin(theta - p5)`` and ``theta + pi/2``.  With the body vector ``r_b = (x, y, z)``,
  ``h = hypot(x, y)`` and ``d = |r_b|``: ``sin(phi - p3) = (y cos p3 - x sin p3) / h``,
  ``sin(theta - p5) = (-z cos p5 - h sin p5) / d`` and ``theta + pi/2 = atan2(h, z)``,
  so the azimuth needs no ``atan2`` and the polar angle one polynomial ``atan``.
* **Polynomials that vectorize.**  ``exp2``, ``log2`` and ``atan`` are Chebyshev
  interpolants (:mod:`gisnoise.maps._poly`) evaluated by Horner's rule, with the exponent
  handled by bit operations; LLVM vectorizes them, which library calls would prevent.
* **Incremental body vector.**  Receivers of a grid row are taken in segments of at
  most :data:`~gisnoise.maps.receivers.SEGMENT_M` metres.  Positions (local ENU) are
  exact (pyproj) at the segment's ends and middle and quadratic in the column in between
  (the residual, from the third derivative of the projection and the Earth's curvature,
  is below 5e-7 m for 1 km segments 10 km from the frame's origin); the body vector of
  the cell ``u`` columns from the segment's middle is ``A + u (B + u D)`` with ``A, B, D``
  rotated once per instant (plus ``dh (N + u T)`` for heights from a DEM: ENU is exactly
  linear in the ellipsoidal height along the normal).  In float32 the body vector
  carries about 6e-8 times the distance from the segment's middle (at most 3e-5 m):
  0.01 dB holds down to about 0.1 m from the UAV.
* **Cells beyond audibility are skipped, provably.**  A segment is skipped when, at every
  instant, its cells' distance to the UAV is beyond the instant's audibility radius
  (:mod:`gisnoise.maps.instants`).
* **Coefficients folded per instant.**  ``p2 cos p3``, ``p4 sin p5``, ``gain log2(10)/10``
  and the like are formed once per instant, and the kernel works in ``log2`` of the energy
  (levels in dB are formed only where time above needs them).
* **Accumulators.**  The maximum and the trapezoid energy ``sum w_i 10^(L_i/10)`` per
  cell; float32 partial sums over at most 32 instants are added to the float64 outputs.

The kernels run without the GIL and are compiled on first use and cached on disk (numba's
cache: beside the module, else in the user's cache directory, or ``NUMBA_CACHE_DIR``);
the set-up (``scripts/_env.sh``) compiles them once with
:func:`~gisnoise.maps.fastkernel.warm_up`, so no run waits for the compiler.  A stale
cache (other numba, changed source) is recompiled by numba itself; when no cache
directory is writable the kernels are compiled in memory on every first use, with a
one-line notice.  When numba is not installed :data:`numba` is None and no kernel is
defined.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from typing import Any

import numpy as np

try:
    import numba
    from llvmlite import ir as _ir
    from numba.core import types as _nbt
    from numba.extending import intrinsic as _intrinsic
except ImportError:  # pragma: no cover - numba is the optional extra "fast"
    numba = None  # type: ignore[assignment]

from gisnoise.maps._poly import _ATAN_C, _EXP2_C, _LOG2_C

log = logging.getLogger(__name__)
CACHE_NOTICE = "numba: no writable cache directory (set NUMBA_CACHE_DIR); compiling the kernels in memory"
"""The one-line notice when the kernels cannot be cached on disk."""
cache_used = True
"""Whether the kernels are cached on disk (False after :data:`CACHE_NOTICE`)."""


def _jit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(cache=True, **options)``, or without the disk cache when no cache directory is writable."""

    def decorate(fn: Callable[..., Any]) -> Any:
        global cache_used
        if cache_used:
            try:
                return numba.njit(cache=True, **options)(fn)
            except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available"
                if "cannot cache" not in str(exc):
                    raise
                cache_used = False
                log.warning(CACHE_NOTICE)
        return numba.njit(cache=False, **options)(fn)

    return decorate


jit = _jit
"""The cache-aware ``numba.njit`` of this module, for the kernels of other modules of the engine."""


_LOG2_10 = math.log2(10.0)
_FM = True  # fastmath: contraction, reassociation; the kernel never sees NaN or inf


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
    _K10_64 = _LOG2_10 / 10.0
    _DB_PER_LOG2 = np.float32(10.0 / _LOG2_10)  # L = log2(e) * _DB_PER_LOG2
    _DB_PER_K10 = _DB_PER_LOG2
    _F127 = np.float32(127.0)
    _TWO23 = np.float32(2.0 ** 23)
    _BIAS_BITS = np.float32(127.0 * 2.0 ** 23)
    _I23 = np.int32(23)
    _MANT = np.int32(0x7FFFFF)
    _ONE_BITS = np.int32(0x3F800000)
    _FLUSH = 32

    @_intrinsic
    def _f32_as_i32(typingctx, x):
        if x != _nbt.float32:
            return None

        def codegen(context, builder, sig, args):
            return builder.bitcast(args[0], _ir.IntType(32))

        return _nbt.int32(_nbt.float32), codegen

    @_intrinsic
    def _i32_as_f32(typingctx, x):
        if x != _nbt.int32:
            return None

        def codegen(context, builder, sig, args):
            return builder.bitcast(args[0], _ir.FloatType())

        return _nbt.float32(_nbt.int32), codegen

    @_intrinsic
    def _prefer_512bit_vectors(typingctx):
        """Mark the calling function for 512-bit vectors where the CPU has them.

        LLVM tunes AVX-512 CPUs to prefer 256-bit vectors (clang's ``-mprefer-vector-width``
        sets the same function attribute); for this arithmetic-bound kernel 512 bits measure
        about twice the throughput.  A no-op on CPUs without AVX-512.
        """

        def codegen(context, builder, sig, args):
            try:  # a string attribute: llvmlite's add() only takes enum ones.  Speed only, never results.
                set.add(builder.function.attributes, '"prefer-vector-width"="512"')
            except Exception:  # pragma: no cover - a future llvmlite without set-based attributes
                pass
            return context.get_dummy_value()

        return _nbt.none(), codegen

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _exp2(y):
        """``2^y`` for float32 ``y`` (clamped to [-126, 126])."""
        y = min(max(y, _EXP_LO), _EXP_HI)
        n = np.floor(y + _HALF)
        f = y - n
        p = ((((_E5 * f + _E4) * f + _E3) * f + _E2) * f + _E1) * f + _E0
        # 2^n from its bit pattern (n + 127) 2^23, formed exactly in float32
        return p * _i32_as_f32(np.int32(n * _TWO23 + _BIAS_BITS))

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _log2(x):
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

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _atan2_pos(y, x):
        """``atan2(y, x)`` in [0, pi] for ``y >= 0`` (float32)."""
        ax = abs(x)
        mn = min(y, ax)
        mx = max(max(y, ax), _TINY)
        a = mn / mx
        s = a * a
        r = a * ((((((_T6 * s + _T5) * s + _T4) * s + _T3) * s + _T2) * s + _T1) * s + _T0)
        r = _HALF_PI - r if y > ax else r
        return _PI - r if x < _ZERO else r

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _cell(xb, yb, zb, g, p2, cp3, sp3, p4, cp5, sp5, c6, kk, e7, dmin2):
        """Level ``L_UAV`` (dB) and energy ``10^(L/10)`` (+ background) from the body vector."""
        y = _cell_log2(xb, yb, zb, g * _K10, p2 * cp3, p2 * sp3, p4 * cp5, p4 * sp5, c6 * _K10, kk * _K10, dmin2)
        return y * _DB_PER_K10, _exp2(y) + e7

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _cell_log2(xb, yb, zb, gk, a3, b3, a5, b5, c6k, kkk, dmin2):
        """``log2`` of the energy ``10^(L/10)`` from the body vector, with the card's row pre-scaled per instant.

        ``gk = g K``, ``a3, b3 = p2 (cos p3, sin p3)``, ``a5, b5 = p4 (cos p5, sin p5)``,
        ``c6k = c6 K``, ``kkk = kk K`` with ``K = log2(10) / 10``: Eq. 9's products folded
        into the coefficients once per instant instead of once per cell.
        """
        h2 = xb * xb + yb * yb
        d2 = h2 + zb * zb
        ih = _ONE / np.sqrt(max(h2, _TINY))
        idd = _ONE / np.sqrt(max(d2, _TINY))
        h = h2 * ih
        s_az = (yb * a3 - xb * b3) * ih
        s_po = -(zb * a5 + h * b5) * idd
        th = _atan2_pos(h, zb)
        return gk * (_ONE + s_az * th) * (_ONE + s_po) - c6k * _log2(max(d2, dmin2)) + kkk

    @_jit(fastmath=_FM, error_model="numpy", nogil=True)
    def _level_points(xb, yb, zb, g, coef):
        """The kernel's level for arrays of body vectors (for tests against the ansatz)."""
        n = xb.size
        out = np.empty(n, np.float32)
        for i in range(n):
            lev, e = _cell(xb[i], yb[i], zb[i], np.float32(g[i]), np.float32(coef[0]), np.float32(coef[1]),
                           np.float32(coef[2]), np.float32(coef[3]), np.float32(coef[4]), np.float32(coef[5]),
                           np.float32(coef[6]), np.float32(coef[7]), np.float32(0.0), np.float32(coef[9]))
            out[i] = lev
        return out

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _segment(P, U, dh, has_dem, r, s, k, m0, c0, ncw, src, radius, e0, e1, e2, n0, n1, lo_b, hi_b, computed):
        """The cells of segment ``s`` of window row ``r`` of :func:`_window_kernel` (every window kernel's) in the
        window, and their lattice: ``(m, q0, jl)``, the segment's cells ``q0 .. q0 + m`` at window columns from
        ``jl``; ``m = 0`` when none is in the window or no instant can reach them.

        Segment ``m0 + s`` holds the global columns ``(m0 + s) k`` to ``(m0 + s + 1) k``, the window the
        global columns ``c0 .. c0 + ncw``.  The position of the cell ``u = q - k/2`` columns from the
        segment's middle is ``e0 + u e1 + u^2 e2`` (``+ dh (n0 + u n1)`` with a DEM); counting from the
        middle halves the float32 rounding of the body vector.  The cells are unreachable when every
        instant's distance to their bounding sphere lies beyond its audibility radius; reachable ones are
        marked in ``computed`` (window row ``r``).
        """
        a = (m0 + s) * k
        lo = max(a, c0)
        hi = min(a + k, c0 + ncw)
        if hi <= lo:
            return 0, 0, 0
        m = hi - lo
        q0 = lo - a
        jl = lo - c0
        inv_k = 1.0 / k
        half_k = 0.5 * k
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
        for i in range(src.shape[0]):
            if radius[i] < 0.0:
                continue
            dist = math.sqrt((src[i, 0] - cx) ** 2 + (src[i, 1] - cy) ** 2 + (src[i, 2] - cz) ** 2)
            if dist - rad <= radius[i]:
                audible = True
                break
        if not audible:
            return 0, 0, 0
        for q in range(m):
            computed[r, jl + q] = 1
        return m, q0, jl

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _lattice(C, i, src, e0, e1, e2, n0, n1, has_dem):
        """The segment's lattice seen from instant ``i`` in body axes (float32): ``A, B, D, N, T`` (fifteen
        numbers) of the body vector ``A + u (B + u D) + dh (N + u T)`` to the cell ``u`` columns from the
        segment's middle, ``dh`` its height above the reference (``N = T = 0`` without a DEM)."""
        ax, ay, az = _rot32(C, i, e0[0] - src[i, 0], e0[1] - src[i, 1], e0[2] - src[i, 2])
        bx, by, bz = _rot32(C, i, e1[0], e1[1], e1[2])
        dx, dy, dz = _rot32(C, i, e2[0], e2[1], e2[2])
        nx = ny = nz = tx = ty = tz = _ZERO
        if has_dem:
            nx, ny, nz = _rot32(C, i, n0[0], n0[1], n0[2])
            tx, ty, tz = _rot32(C, i, n1[0], n1[1], n1[2])
        return ax, ay, az, bx, by, bz, dx, dy, dz, nx, ny, nz, tx, ty, tz

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _folded_row(gain, coef, i, ci):
        """Instant ``i``'s gain and card row ``ci`` folded for :func:`_cell_log2` (float32): ``gk, a3, b3, a5, b5,
        c6k, kkk``, then the background energy ``e7`` and the squared near-field distance ``dmin2``."""
        return (np.float32(gain[i] * _K10_64), np.float32(coef[ci, 0] * coef[ci, 1]),
                np.float32(coef[ci, 0] * coef[ci, 2]), np.float32(coef[ci, 3] * coef[ci, 4]),
                np.float32(coef[ci, 3] * coef[ci, 5]), np.float32(coef[ci, 6] * _K10_64),
                np.float32(coef[ci, 7] * _K10_64), np.float32(coef[ci, 8]), np.float32(coef[ci, 9]))

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _rot32(C, i, v0, v1, v2):
        """The ENU vector ``(v0, v1, v2)`` in body axes, ``C[i] v``, in float32."""
        return (np.float32(C[i, 0, 0] * v0 + C[i, 0, 1] * v1 + C[i, 0, 2] * v2),
                np.float32(C[i, 1, 0] * v0 + C[i, 1, 1] * v1 + C[i, 1, 2] * v2),
                np.float32(C[i, 2, 0] * v0 + C[i, 2, 1] * v1 + C[i, 2, 2] * v2))

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _time_above(lprev, lcur, thr32, tacc, dti, m):
        """Add to ``tacc[t, q]`` the time (s) of an interval ``dti`` the level of cell ``q`` spends at or above
        ``thr32[t]``, the level linear from ``lprev`` to ``lcur`` (dB) within the interval."""
        for t in range(thr32.shape[0]):
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
        return 0

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _window_buffers(k, thr):
        """The work arrays of a window kernel: thresholds in float32, per-cell levels now and at the previous
        instant, float32 partial sums of energy and time above (zero), and the segment lattice's seven 3-vectors."""
        nt = thr.shape[0]
        thr32 = np.empty(nt, np.float32)
        for t in range(nt):
            thr32[t] = np.float32(thr[t])
        return (thr32, np.empty(k, np.float32), np.empty(k, np.float32), np.zeros(k, np.float32),
                np.zeros((nt, k), np.float32), np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3),
                np.empty(3), np.empty(3))

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _level_step(lprev, lcur, thr32, tacc, e7, dti, m):
        """Time above after an instant: ``lcur`` (``log2`` of the UAV's energy) becomes the level with the
        background ``e7`` in dB; with ``dti > 0`` the interval from the previous instant adds to ``tacc``
        (:func:`_time_above`); ``lprev`` takes ``lcur``."""
        if e7 != _ZERO:
            for q in range(m):
                lcur[q] = _log2(_exp2(lcur[q]) + e7) * _DB_PER_LOG2
        else:
            for q in range(m):
                lcur[q] = lcur[q] * _DB_PER_LOG2
        if dti > _ZERO:
            _time_above(lprev, lcur, thr32, tacc, dti, m)
        for q in range(m):
            lprev[q] = lcur[q]
        return 0

    @_jit(fastmath=_FM, error_model="numpy", inline="always")
    def _flush(en, eacc, ta, tacc, r, jl, m):
        """Add the float32 partial sums ``eacc`` and ``tacc`` to the outputs (window row ``r``, columns from ``jl``)
        and zero them."""
        for q in range(m):
            en[q] += eacc[q]
            eacc[q] = _ZERO
        for t in range(tacc.shape[0]):
            tat = ta[t, r, jl:jl + m]
            tac = tacc[t]
            for q in range(m):
                tat[q] += tac[q]
                tac[q] = _ZERO
        return 0

    @_jit(fastmath=_FM, error_model="numpy", nogil=True)
    def _window_kernel(P, U, dh, has_dem, k, m0, c0, ncw, src, C, gain, cidx, coef, w, dt, radius, thr,
                       emax, energy, ta, computed):
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
        # float32 partial sums over at most _FLUSH instants, added to the float64 outputs
        # (a float64 accumulator in the cell loop stops LLVM from vectorizing it)
        thr32, lcur, lprev, eacc, tacc, e0, e1, e2, n0, n1, lo_b, hi_b = _window_buffers(k, thr)
        half_k = 0.5 * k
        half_k32 = np.float32(half_k)
        for r in range(nr):
            for s in range(ns):
                m, q0, jl = _segment(P, U, dh, has_dem, r, s, k, m0, c0, ncw, src, radius, e0, e1, e2, n0, n1,
                                     lo_b, hi_b, computed)
                if m == 0:
                    continue
                # 1-D views indexed from 0: LLVM then sees consecutive addresses and vectorizes
                em = emax[r, jl:jl + m]
                en = energy[r, jl:jl + m]
                dhr = dh[r, jl:jl + m] if has_dem else dh[0, 0:1]
                for i in range(n):
                    ci = cidx[i]
                    # body frame: A + u (B + u D) (+ dh (N + u T)), u = q - k/2; written out here rather than
                    # through _lattice and _folded_row (as the other window kernels): the set-up runs once per
                    # instant and segment, and written out the kernel measured about 4 % faster
                    v0 = e0[0] - src[i, 0]
                    v1 = e0[1] - src[i, 1]
                    v2 = e0[2] - src[i, 2]
                    ax, ay, az = _rot32(C, i, v0, v1, v2)
                    bx, by, bz = _rot32(C, i, e1[0], e1[1], e1[2])
                    dx, dy, dz = _rot32(C, i, e2[0], e2[1], e2[2])
                    # the card's row folded per instant (see _cell_log2)
                    gk = np.float32(gain[i] * _K10_64)
                    a3 = np.float32(coef[ci, 0] * coef[ci, 1])
                    b3 = np.float32(coef[ci, 0] * coef[ci, 2])
                    a5 = np.float32(coef[ci, 3] * coef[ci, 4])
                    b5 = np.float32(coef[ci, 3] * coef[ci, 5])
                    c6k = np.float32(coef[ci, 6] * _K10_64)
                    kkk = np.float32(coef[ci, 7] * _K10_64)
                    e7 = np.float32(coef[ci, 8])
                    dmin2 = np.float32(coef[ci, 9])
                    wi = np.float32(w[i])
                    if has_dem:
                        nx, ny, nz = _rot32(C, i, n0[0], n0[1], n0[2])
                        tx, ty, tz = _rot32(C, i, n1[0], n1[1], n1[2])
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            hh = dhr[q]
                            xb = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                            yb = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                            zb = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                            y = _cell_log2(xb, yb, zb, gk, a3, b3, a5, b5, c6k, kkk, dmin2)
                            e = _exp2(y) + e7
                            em[q] = max(em[q], e)
                            eacc[q] += wi * e
                            if nt > 0:
                                lcur[q] = y
                    else:
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            xb = ax + qf * (bx + qf * dx)
                            yb = ay + qf * (by + qf * dy)
                            zb = az + qf * (bz + qf * dz)
                            y = _cell_log2(xb, yb, zb, gk, a3, b3, a5, b5, c6k, kkk, dmin2)
                            e = _exp2(y) + e7
                            em[q] = max(em[q], e)
                            eacc[q] += wi * e
                            if nt > 0:
                                lcur[q] = y
                    if nt > 0:  # lcur: log2 of the UAV's energy -> level with the background, dB; time above
                        _level_step(lprev, lcur, thr32, tacc, e7, np.float32(dt[i]) if i > 0 else _ZERO, m)
                    if (i + 1) % _FLUSH == 0 or i == n - 1:
                        _flush(en, eacc, ta, tacc, r, jl, m)
        return 0
