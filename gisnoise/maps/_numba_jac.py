"""The fast engine's kernel of the uncertainty bands: the level and its parameter Jacobian (float32, numba).

:func:`_jac_window_kernel` walks the receivers' lattice as :func:`gisnoise.maps._numba._window_kernel`
does (same segments, audibility skipping, rotation, level) and accumulates per cell, besides the
trapezoid energy, the delta method's two results (:mod:`gisnoise.maps.fast_uncertainty`):

* ``smax``: ``LAmax_std``, the largest :func:`~gisnoise.maps.prepare.tie_std` of ``sqrt(J_i C_i J_i^T)``
  (``J_i = dL_i/dp``, ``C_i`` the covariance of instant ``i``'s card) over the instants less than
  :data:`~gisnoise.maps.prepare.TIE_DB` below the cell's LAmax (the level kernel's): those whose
  energy ``10^(L_i/10)`` reaches the cell's ``bar = 10^((LAmax - TIE_DB)/10)``;
* ``gsum[j]``: ``sum_i w_i 10^(L_i/10) dL_i/dp_j`` (LAeq and SEL: divided by the energy).

Columns ``j``: ``p0 .. p7`` of ``paper-offset`` (``paper`` has no ``p0``; its column stays 0); in
``gsum`` eight per card of the flight, the instant's card's from ``jo[i]`` (``8 slot``).  With ``P_el`` the power,
``a = 1 + p2 sin(phi - p3)(theta + pi/2)``, ``b = 1 + p4 sin(theta - p5)``, ``g = p0 + p1 lg P_el``
and ``l_s = -20 lg(d / d_ref)`` (Eq. 9-10, :func:`gisnoise.model.ansatz._paper_terms`):

    dL/dp0 = a b,  dL/dp1 = lg(P_el) a b,  dL/dp2 = g sin(phi - p3)(theta + pi/2) b,
    dL/dp3 = -g p2 cos(phi - p3)(theta + pi/2) b,  dL/dp4 = g a sin(theta - p5),
    dL/dp5 = -g a p4 cos(theta - p5),  dL/dp6 = l_s,

each times ``w = 10^(L_UAV/10) / (10^(L_UAV/10) + 10^(p7/10))`` with the background, and
``dL/dp7 = 1 - w`` (0 without it).  The angles come from the body vector ``(x, y, z)`` with
``h = hypot(x, y)`` and ``d = |r|``: ``sin(phi - p3) = (y cos p3 - x sin p3) / h``,
``cos(phi - p3) = (x cos p3 + y sin p3) / h``, ``sin(theta - p5) = -(z cos p5 + h sin p5) / d``,
``cos(theta - p5) = (h cos p5 - z sin p5) / d`` and ``theta + pi/2 = atan2(h, z)``.

Per-card rows ``jc`` (:data:`JC_COLUMNS`): ``p2, cos p3, sin p3, p4, cos p5, sin p5, p6,
20 lg d_ref, e7, d_min^2`` (``e7 = 10^(p7/10)`` with the background, else 0).
"""

from __future__ import annotations

import math

import numpy as np

from gisnoise.maps import _hemikernel as _hk
from gisnoise.maps import _numba as _k

numba = _k.numba

JC_COLUMNS = ("p2", "cos_p3", "sin_p3", "p4", "cos_p5", "sin_p5", "p6", "dref_db", "e7", "dmin2")
"""Columns of the kernel's per-card rows ``jc``."""
N_JAC = 8
"""Jacobian columns per card (``p0 .. p7``)."""

if numba is not None:
    _vectorize_gathers = _hk._vectorize_gathers
    _ONE = np.float32(1.0)
    _ZERO = np.float32(0.0)
    _TINY = np.float32(1e-30)
    _NONE_LO = np.int32(1 << 30)  # the bounds of no cell
    _NONE_HI = np.int32(-1)
    _C20 = np.float32(10.0 * math.log10(2.0))  # 20 lg d = _C20 log2(d^2)
    _K10 = _k._K10
    _FLUSH = _k._FLUSH

    @_k.jit(fastmath=_k._FM, error_model="numpy", nogil=True)
    def _jac_cells(xb, yb, zb, m, g, lg, p2, c3, s3, p4, c5, s5, p6, drefdb, e7, dmin2, wt, bar, eb, eacc,
                   m0_, m1_, m2_, m3_, m4_, m5_, m6_, m7_, g0_, g1_, g2_, g3_, g4_, g5_, g6_, g7_):
        """Level, energy and Jacobian of ``m`` body vectors of one instant, into the accumulators (module docstring).

        A function of its own, its array arguments distinct (:func:`~gisnoise.maps._hemikernel._vectorize_gathers`
        tells LLVM so), so that the loop over the cells vectorizes.  ``eb``, ``m*_``: this instant's
        energy and Jacobian of each cell (work arrays); ``g*_`` (the card's columns, and ``eacc``) add
        ``wt e`` times the Jacobian (and ``wt e``).  Returns ``lo, hi``: the cells ``lo <= q <= hi`` hold
        every cell whose energy reaches its ``bar`` (``lo > hi``: none).
        """
        _vectorize_gathers()
        lo = _NONE_LO  # int32 reductions, as wide as the cells' float32 lanes
        hi = _NONE_HI
        for q in range(m):
            x = xb[q]
            y = yb[q]
            z = zb[q]
            h2 = x * x + y * y
            d2 = h2 + z * z
            ih = _ONE / np.sqrt(max(h2, _TINY))
            idd = _ONE / np.sqrt(max(d2, _TINY))
            hz = h2 * ih
            s_az = (y * c3 - x * s3) * ih
            c_az = (x * c3 + y * s3) * ih
            s_po = -(z * c5 + hz * s5) * idd
            c_po = (hz * c5 - z * s5) * idd
            th = _k._atan2_pos(hz, z)
            fa = _ONE + p2 * s_az * th
            fb = _ONE + p4 * s_po
            ls = drefdb - _C20 * _k._log2(max(d2, dmin2))
            lu = g * fa * fb + p6 * ls
            eu = _k._exp2(lu * _K10)
            e = eu + e7
            wb = eu / e
            gb = g * wb
            j_0 = fa * fb * wb
            j_1 = lg * j_0
            j_2 = gb * s_az * th * fb
            j_3 = -gb * p2 * c_az * th * fb
            j_4 = gb * fa * s_po
            j_5 = -gb * fa * p4 * c_po
            j_6 = ls * wb
            j_7 = _ONE - wb
            qi = np.int32(q)
            tie = e >= bar[q]
            lo = min(lo, qi if tie else _NONE_LO)
            hi = max(hi, qi if tie else _NONE_HI)
            eb[q] = e
            m0_[q] = j_0
            m1_[q] = j_1
            m2_[q] = j_2
            m3_[q] = j_3
            m4_[q] = j_4
            m5_[q] = j_5
            m6_[q] = j_6
            m7_[q] = j_7
            we = wt * e
            eacc[q] += we
            g0_[q] += we * j_0
            g1_[q] += we * j_1
            g2_[q] += we * j_2
            g3_[q] += we * j_3
            g4_[q] += we * j_4
            g5_[q] += we * j_5
            g6_[q] += we * j_6
            g7_[q] += we * j_7
        return lo, hi

    @_k.jit(error_model="numpy", inline="always")
    def _tie_std(std, below_db, tie_db):
        """:func:`gisnoise.maps.prepare.tie_std` with ``TIE_DB = tie_db`` (written out here, since numba's cache
        knows this file's text only; ``tests/test_fast_uncertainty.py`` checks that the two agree)."""
        return std - below_db * below_db / (tie_db * (tie_db - below_db))

    @_k.jit(fastmath=_k._FM, error_model="numpy", nogil=True)
    def _tie_stds(lo, hi, bar, eb, jb, cv, sm, tie_db):
        """``sm[q] = max(sm[q], tie_std(sqrt(J C J^T), LAmax - L))`` for the cells ``lo <= q <= hi`` whose energy
        ``eb`` reaches ``bar`` and lies less than ``tie_db`` below their LAmax; ``jb (8, k)``: their Jacobians
        (:func:`_jac_cells`), ``cv (8, 8)``: the instant's card's covariance."""
        for q in range(lo, hi + 1):
            if eb[q] >= bar[q]:  # LAmax - L = tie_db - 10 lg(e / bar)
                below = max(tie_db - 10.0 * math.log10(np.float64(eb[q]) / np.float64(bar[q])), 0.0)
                if below < tie_db:
                    v = 0.0
                    for a in range(N_JAC):
                        s = 0.0
                        for b in range(N_JAC):
                            s += cv[a, b] * np.float64(jb[b, q])
                        v += np.float64(jb[a, q]) * s
                    sm[q] = max(sm[q], _tie_std(math.sqrt(max(v, 0.0)), below, tie_db))
        return 0

    @_k.jit(fastmath=_k._FM, error_model="numpy", nogil=True)
    def _jac_window_kernel(P, U, dh, has_dem, k, m0, c0, ncw, src, C, gain, lgp, cidx, jc, jo, w, radius,
                           bar, tie_db, cov, smax, energy, gsum, computed):  # pragma: no cover - compiled
        """Accumulate ``smax``, ``energy`` (as the window kernel) and ``gsum`` (module docstring).

        Arguments as :func:`gisnoise.maps._numba._window_kernel` (no thresholds), plus per instant
        ``lgp`` (``lg P_el``) and ``jo`` (first Jacobian column of its card, ``8 slot``), per card the rows
        ``jc``, per cell ``bar (nr, ncw)`` f32 (``10^((LAmax - tie_db)/10)``; the largest float32: no
        LAmax_std), ``tie_db`` (:data:`~gisnoise.maps.prepare.TIE_DB`), per card slot ``cov (n_used, 8, 8)``
        f64.  Outputs: ``smax (nr, ncw)`` f64 (-1 on entry: a cell no instant reached keeps it), and zero
        on entry ``energy (nr, ncw)`` f64, ``gsum (nj, nr, ncw)`` f64, ``computed (nr, ncw)`` u8.
        """
        _k._prefer_512bit_vectors()
        nr = P.shape[0]
        ns = (P.shape[1] - 1) // 2
        n = src.shape[0]
        nj = gsum.shape[0]
        thr32, lcur, lprev, eacc, tacc, e0, e1, e2, n0, n1, lo_b, hi_b = _k._window_buffers(k, np.zeros(0))
        gacc = np.zeros((nj, k), np.float32)
        jb = np.empty((N_JAC, k), np.float32)
        eb = np.empty(k, np.float32)
        xs = np.empty(k, np.float32)
        ys = np.empty(k, np.float32)
        zs = np.empty(k, np.float32)
        half_k32 = np.float32(0.5 * k)
        for r in range(nr):
            for sg in range(ns):
                m, q0, jl = _k._segment(P, U, dh, has_dem, r, sg, k, m0, c0, ncw, src, radius, e0, e1, e2, n0, n1,
                                        lo_b, hi_b, computed)
                if m == 0:
                    continue
                br = bar[r, jl:jl + m]
                sm = smax[r, jl:jl + m]
                en = energy[r, jl:jl + m]
                dhr = dh[r, jl:jl + m] if has_dem else dh[0, 0:1]
                for i in range(n):
                    ci = cidx[i]
                    # body frame: A + u (B + u D) (+ dh (N + u T)), u = q - k/2
                    (ax, ay, az, bx, by, bz, dx, dy, dz,
                     nx, ny, nz, tx, ty, tz) = _k._lattice(C, i, src, e0, e1, e2, n0, n1, has_dem)
                    g = np.float32(gain[i])
                    lg = np.float32(lgp[i])
                    p2 = np.float32(jc[ci, 0])
                    c3 = np.float32(jc[ci, 1])
                    s3 = np.float32(jc[ci, 2])
                    p4 = np.float32(jc[ci, 3])
                    c5 = np.float32(jc[ci, 4])
                    s5 = np.float32(jc[ci, 5])
                    p6 = np.float32(jc[ci, 6])
                    drefdb = np.float32(jc[ci, 7])
                    e7 = np.float32(jc[ci, 8])
                    dmin2 = np.float32(jc[ci, 9])
                    wt = np.float32(w[i])
                    j0 = jo[i]
                    for q in range(m):
                        qf = np.float32(q0 + q) - half_k32
                        hh = dhr[q] if has_dem else _ZERO
                        xs[q] = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                        ys[q] = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                        zs[q] = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                    lo_t, hi_t = _jac_cells(xs, ys, zs, m, g, lg, p2, c3, s3, p4, c5, s5, p6, drefdb, e7, dmin2,
                                            wt, br, eb, eacc, jb[0], jb[1], jb[2], jb[3], jb[4], jb[5], jb[6], jb[7],
                                            gacc[j0], gacc[j0 + 1], gacc[j0 + 2], gacc[j0 + 3], gacc[j0 + 4],
                                            gacc[j0 + 5], gacc[j0 + 6], gacc[j0 + 7])
                    if lo_t <= hi_t:  # an instant that ties for some cells' LAmax
                        _tie_stds(lo_t, hi_t, br, eb, jb, cov[j0 // N_JAC], sm, tie_db)
                    if (i + 1) % _FLUSH == 0 or i == n - 1:  # float32 partial sums into the float64 outputs
                        for q in range(m):
                            en[q] += eacc[q]
                            eacc[q] = _ZERO
                        for j in range(nj):
                            gs = gsum[j, r, jl:jl + m]
                            ga = gacc[j]
                            for q in range(m):
                                gs[q] += ga[q]
                                ga[q] = _ZERO
        return 0
