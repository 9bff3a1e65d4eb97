"""The fast engine's kernel for cards with receiver-dependent effect terms (float32, numba).

:func:`_receiver_window_kernel` is :func:`gisnoise.maps._numba._window_kernel` (same
arguments, lattice, audibility skipping, accumulation; its level helpers) plus, per cell
and instant, the terms of :mod:`gisnoise.maps.receiver_terms` in ``log2`` of the energy:
absorption, wind, Doppler and the ground reflection.  It needs the receiver-minus-UAV
vector in ENU (not only in body axes): the same incremental lattice, unrotated.  It is a
separate compiled function so that the plain kernel's code does not change.

Per instant ``i`` the coefficients ``rx[i]`` (:data:`~gisnoise.maps.receiver_terms.RX_COLUMNS`)
and, for the whole call, the receiver height above ground ``hr`` and ``flags`` (bit 0
absorption, 1 wind, 2 Doppler, 3 ground reflection; :func:`~gisnoise.maps.receiver_terms.kernel_flags`).

The ground reflection's band-averaged cosine ``C(u) = (sin(a2 u) - sin(a1 u)) / ((a2 - a1) u)``
(``a1, a2`` the one-third-octave's relative edges, :data:`gisnoise.model.THIRD_OCTAVE`) is
evaluated as ``cos(m u) sin(h u) / (h u)`` with ``m = (a1 + a2) / 2``, ``h = (a2 - a1) / 2``
(the same function, no cancellation at small ``u``), with polynomial ``sin``/``cos`` (minimax
on ``[-pi/4, pi/4]``, quadrant by ``pi/2`` in two parts) that LLVM vectorizes.  The delay
is ``tau = 4 h_s h_r / ((l_direct + l_reflected) c)``, the difference of the two path lengths
without cancellation.
"""

from __future__ import annotations

import math

import numpy as np

from gisnoise.maps import _numba as _k
from gisnoise.model import THIRD_OCTAVE

numba = _k.numba

if numba is not None:
    _cell_log2 = _k._cell_log2
    _exp2 = _k._exp2
    _log2 = _k._log2
    _prefer = _k._prefer_512bit_vectors
    _ONE = np.float32(1.0)
    _HALF = np.float32(0.5)
    _ZERO = np.float32(0.0)
    _TINY = np.float32(1e-30)
    _K10_64 = _k._K10_64
    _DB_PER_LOG2 = _k._DB_PER_LOG2
    _FLUSH = _k._FLUSH
    _FOUR = np.float32(4.0)
    _TWO_OVER_PI = np.float32(2.0 / math.pi)
    _PIO2_HI = np.float32(1.5703125)  # pi/2 in two parts: n * _PIO2_HI is exact for n < 2^15
    _PIO2_LO = np.float32(math.pi / 2.0 - 1.5703125)
    _S1, _S2, _S3 = np.float32(-1.6666654611e-1), np.float32(8.3321608736e-3), np.float32(-1.9515295891e-4)
    _C1, _C2, _C3 = np.float32(4.166664568298827e-2), np.float32(-1.388731625493765e-3), np.float32(2.443315711809948e-5)
    _BAND_MID = np.float32(0.5 * (THIRD_OCTAVE[0] + THIRD_OCTAVE[1]))
    _BAND_HALF = np.float32(0.5 * (THIRD_OCTAVE[1] - THIRD_OCTAVE[0]))
    _SMALL = np.float32(1e-4)
    _SIXTH = np.float32(1.0 / 6.0)

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _sin_cos_reduced(x):
        """``sin(r), cos(r)`` and the quadrant ``q`` of ``x = q pi/2 + r`` (float32, |r| <= pi/4)."""
        n = np.floor(x * _TWO_OVER_PI + _HALF)
        r = (x - n * _PIO2_HI) - n * _PIO2_LO
        z = r * r
        s = r + r * z * (_S1 + z * (_S2 + z * _S3))
        c = _ONE - _HALF * z + z * z * (_C1 + z * (_C2 + z * _C3))
        return s, c, np.int32(n) & np.int32(3)

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _band_cos(u):
        """``C(u)``: ``cos(u)`` averaged over a one-third-octave band about ``u`` (even in ``u``)."""
        u = abs(u)
        s1, c1, q1 = _sin_cos_reduced(_BAND_MID * u)
        cm = s1 if (q1 & 1) != 0 else c1
        cm = -cm if ((q1 + 1) & 2) != 0 else cm  # cos(m u)
        x = _BAND_HALF * u
        s2, c2, q2 = _sin_cos_reduced(x)
        sh = c2 if (q2 & 1) != 0 else s2
        sh = -sh if (q2 & 2) != 0 else sh  # sin(h u)
        sinc = sh / max(x, _TINY) if x > _SMALL else _ONE - x * x * _SIXTH
        return cm * sinc

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _dist_c(re, rn, ru, dmin2):
        """``max(d, d_min)`` of the ENU vector ``(re, rn, ru)`` (receiver - UAV)."""
        return np.sqrt(max(re * re + rn * rn + ru * ru, dmin2))

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _wind(re, rn, ru, dmin2, kwe, kwn):
        """Wind term (``log2`` of the energy): ``d_c (kwe r_E + kwn r_N) / max(|r_h|, 1)``."""
        return _dist_c(re, rn, ru, dmin2) * (kwe * re + kwn * rn) / max(np.sqrt(re * re + rn * rn), _ONE)

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _doppler(re, rn, ru, q, me, mn, mu):
        """Doppler term (``log2`` of the energy): ``-q log2(1 - M_r)``, ``(me, mn, mu)`` the velocity over ``c``."""
        mr = (me * re + mn * rn + mu * ru) / np.sqrt(max(re * re + rn * rn + ru * ru, _TINY))
        return -q * _log2(_ONE - mr)

    @_k.jit(fastmath=_k._FM, error_model="numpy", inline="always")
    def _ground(re, rn, ru, g0, g1, uk, hr):
        """Ground reflection term (``log2`` of the energy): ``log2(g0 + g1 C(u))``, ``u = uk h_s / (l_d + l_r)``."""
        rh2 = re * re + rn * rn
        hs = max(hr - ru, _ZERO)
        lm = hs - hr
        lp = hs + hr
        u = uk * hs / (np.sqrt(rh2 + lm * lm) + np.sqrt(rh2 + lp * lp))
        return _log2(g0 + g1 * _band_cos(u))

    @_k.jit(fastmath=_k._FM, error_model="numpy", nogil=True)
    def _receiver_window_kernel(P, U, dh, has_dem, k, m0, c0, ncw, src, C, gain, cidx, coef, w, dt, radius, thr,
                                rx, hr, flags, emax, energy, ta, computed):
        """:func:`gisnoise.maps._numba._window_kernel` with the receiver terms ``rx`` (see the module)."""
        _prefer()
        nr = P.shape[0]
        ns = (P.shape[1] - 1) // 2
        n = src.shape[0]
        nt = thr.shape[0]
        thr32, lcur, lprev, eacc, tacc, e0, e1, e2, n0, n1, lo_b, hi_b = _k._window_buffers(k, thr)
        ybuf = np.empty(k, np.float32)
        rbe = np.empty(k, np.float32)
        rbn = np.empty(k, np.float32)
        rbu = np.empty(k, np.float32)
        half_k = 0.5 * k
        half_k32 = np.float32(half_k)
        hr32 = np.float32(hr)
        fl = np.int64(flags)
        for r in range(nr):
            for s in range(ns):
                m, q0, jl = _k._segment(P, U, dh, has_dem, r, s, k, m0, c0, ncw, src, radius, e0, e1, e2, n0, n1,
                                        lo_b, hi_b, computed)
                if m == 0:
                    continue
                em = emax[r, jl:jl + m]
                en = energy[r, jl:jl + m]
                dhr = dh[r, jl:jl + m] if has_dem else dh[0, 0:1]
                f1e = np.float32(e1[0])
                f1n = np.float32(e1[1])
                f1u = np.float32(e1[2])
                f2e = np.float32(e2[0])
                f2n = np.float32(e2[1])
                f2u = np.float32(e2[2])
                g0e = np.float32(n0[0])
                g0n = np.float32(n0[1])
                g0u = np.float32(n0[2])
                g1e = np.float32(n1[0])
                g1n = np.float32(n1[1])
                g1u = np.float32(n1[2])
                for i in range(n):
                    ci = cidx[i]
                    # body frame: A + u (B + u D) (+ dh (N + u T)), u = q - k/2
                    (ax, ay, az, bx, by, bz, dx, dy, dz,
                     nx, ny, nz, tx, ty, tz) = _k._lattice(C, i, src, e0, e1, e2, n0, n1, has_dem)
                    ve = np.float32(e0[0] - src[i, 0])
                    vn = np.float32(e0[1] - src[i, 1])
                    vu = np.float32(e0[2] - src[i, 2])
                    gk, a3, b3, a5, b5, c6k, kkk, e7, dmin2 = _k._folded_row(gain, coef, i, ci)
                    wi = np.float32(w[i])
                    kab = np.float32(rx[i, 0])
                    kwe = np.float32(rx[i, 1])
                    kwn = np.float32(rx[i, 2])
                    qd = np.float32(rx[i, 3])
                    me = np.float32(rx[i, 4])
                    mn = np.float32(rx[i, 5])
                    mu = np.float32(rx[i, 6])
                    rg = rx[i, 7]
                    g0 = np.float32(1.0 + rg * rg)
                    g1 = np.float32(2.0 * rg)
                    uk = np.float32(rx[i, 8] * 4.0 * hr)
                    # the base level and the ENU vector per cell, then each term in its own loop (a flag
                    # tested outside a loop costs nothing; inside one LLVM would compute every term)
                    if has_dem:
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            hh = dhr[q]
                            xb = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                            yb = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                            zb = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                            ybuf[q] = _cell_log2(xb, yb, zb, gk, a3, b3, a5, b5, c6k, kkk, dmin2)
                            rbe[q] = ve + qf * (f1e + qf * f2e) + hh * (g0e + qf * g1e)
                            rbn[q] = vn + qf * (f1n + qf * f2n) + hh * (g0n + qf * g1n)
                            rbu[q] = vu + qf * (f1u + qf * f2u) + hh * (g0u + qf * g1u)
                    else:
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            xb = ax + qf * (bx + qf * dx)
                            yb = ay + qf * (by + qf * dy)
                            zb = az + qf * (bz + qf * dz)
                            ybuf[q] = _cell_log2(xb, yb, zb, gk, a3, b3, a5, b5, c6k, kkk, dmin2)
                            rbe[q] = ve + qf * (f1e + qf * f2e)
                            rbn[q] = vn + qf * (f1n + qf * f2n)
                            rbu[q] = vu + qf * (f1u + qf * f2u)
                    if (fl & 1) != 0:
                        for q in range(m):
                            ybuf[q] += kab * _dist_c(rbe[q], rbn[q], rbu[q], dmin2)
                    if (fl & 2) != 0:
                        for q in range(m):
                            ybuf[q] += _wind(rbe[q], rbn[q], rbu[q], dmin2, kwe, kwn)
                    if (fl & 4) != 0:
                        for q in range(m):
                            ybuf[q] += _doppler(rbe[q], rbn[q], rbu[q], qd, me, mn, mu)
                    if (fl & 8) != 0:
                        for q in range(m):
                            ybuf[q] += _ground(rbe[q], rbn[q], rbu[q], g0, g1, uk, hr32)
                    for q in range(m):
                        y = ybuf[q]
                        e = _exp2(y) + e7
                        em[q] = max(em[q], e)
                        eacc[q] += wi * e
                        if nt > 0:
                            lcur[q] = y
                    if nt > 0:  # lcur: log2 of the UAV's energy -> level with the background, dB; time above
                        _k._level_step(lprev, lcur, thr32, tacc, e7, np.float32(dt[i]) if i > 0 else _ZERO, m)
                    if (i + 1) % _FLUSH == 0 or i == n - 1:
                        _k._flush(en, eacc, ta, tacc, r, jl, m)
        return 0

    @_k.jit(fastmath=_k._FM, error_model="numpy", nogil=True)
    def _band_cos_points(u):
        """The kernel's ``C(u)`` for an array (for the tests against :func:`gisnoise.model.band_cos`)."""
        out = np.empty(u.size, np.float32)
        for i in range(u.size):
            out[i] = _band_cos(np.float32(u[i]))
        return out
