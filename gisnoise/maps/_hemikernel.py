"""The numba window kernel of the fast engine for flights with measured hemispheres (float32, vectorized).

:func:`_hemi_window_kernel` is the parametric window kernel of :mod:`gisnoise.maps._numba`
(same receivers' lattice, incremental body vectors, audibility skipping, accumulators and
time above) with a second kind of instant: a hemisphere card.  Per cell and instant it
evaluates the card's stated scheme (:class:`~gisnoise.model.HemisphereCard`: bilinear in the
table angles of the nodes' A-weighted levels at the receiver's distance) from tables prepared
in NumPy by :mod:`gisnoise.maps.hemisource`.

Four vectorized passes over the cells of a run (:func:`_hemi_cells`, called once per instant
and row segment, so that no per-cell call passes arrays); short loops measured faster than one
fused loop, whose long chains (angles, index, reads) leave the table reads' latency exposed:

* **Distance and angles without libm.**  ``s = log2(d^2)`` (the kernel's polynomial ``log2``),
  ``phi_t = atan2(-x_b, |z_b|)`` and ``theta_t = atan2(y_b, |z_b|)`` by its polynomial ``atan``
  (5e-7 rad).
* **Fractional node indices without search.**  ``(a - g_0) / spacing`` on a uniform axis, else
  ``u = K + sum_k c_k max(a, g_k)`` over the axis' intervals, ``c_k`` the step of the slope
  ``1 / (g_k+1 - g_k)`` at node ``k`` and ``K = -sum_k c_k g_k`` (``a`` is clamped to the
  axis): piecewise linear through ``(g_k, k)``, so bilinear interpolation in ``u`` on the
  integers is bilinear interpolation in the angles.  Two operations per interval, eight
  intervals per sweep over the cells (the axes are padded to a multiple of :data:`HINGES`).
  A bin table (one read per cell from uniform bins with every node on a bin edge) measured
  slower than these sums on the M300's 20 intervals.
* **Entries and weights.**  The table entry of each cell (unsigned, so that no negative-index
  code is generated), the two angle weights and the distance fraction.
* **Two reads per cell.**  Per node, the A-weighted level without spherical spreading,
  ``T_q(d) = 10 lg sum_b 10^((L_b,q + A_b - alpha_b (d - r0)) / 10)``, is tabulated on a grid
  uniform in ``s`` as 16-bit codes (``T = base + step * code``, ``step`` the card table's range
  over :data:`Q_MAX`; the lowest bit of a code the node's filled flag).  Each int64 entry holds
  the codes of two neighbouring theta nodes at both ends of a distance step (node-major, so
  neighbouring cells read neighbouring entries).  The level is the trilinear interpolation
  (4 nodes x 2 distances) minus the spreading ``-20 lg(d / r0)``, exact from ``s``; the filled
  flags weighted like the nodes give the weight on filled nodes, whose energy is summed
  separately (``efill``) for the map's metadata.

The loops read tables at computed indices (gathers); LLVM vectorizes them only when the array
arguments are known not to overlap (:func:`_vectorize_gathers`).  The two reads are most of
what separates this kernel's speed from the parametric one's (``docs/performance.md``).
"""

from __future__ import annotations

import math

import numpy as np

from gisnoise.maps import _numba as _k

numba = _k.numba

#: Columns of the per-card rows ``hs`` (float64) the kernel reads.
(H_TAB, H_NN, H_NJ, H_SI, H_QB, H_IMAX, H_JMAX, H_AMIN, H_AMAX, H_BMIN, H_BMAX, H_PA0, H_PINV, H_PNB, H_PBO,
 H_TA0, H_TINV, H_TNB, H_TBO, H_K0, H_QS, H_PK, H_TK) = range(23)
N_HS = 23

#: A non-uniform axis' intervals are padded to a multiple of this (the kernel sums 8, then 4 at a time).
HINGES = 4

#: Largest code of the table's 16-bit levels (``level = base + step * code``).
Q_MAX = 65532

_CSP = 10.0 / math.log2(10.0)
"""``20 lg d = _CSP log2(d^2)``, dB."""


if numba is not None:
    _F0 = np.float32(0.0)
    _F1 = np.float32(1.0)
    _F32_CSP = np.float32(_CSP)
    _K10 = _k._K10
    _DB_PER_LOG2 = _k._DB_PER_LOG2
    _FLUSH = _k._FLUSH
    _M16 = np.int64(0xFFFF)

    @_k._intrinsic
    def _vectorize_gathers(typingctx):
        """Mark the calling function's array arguments ``noalias`` and prefer 512-bit vectors.

        LLVM vectorizes a loop that reads tables at computed indices (gathers) only when it
        knows the stores cannot touch the tables; every caller passes distinct arrays and
        writes only to its output arrays.  Speed only: with or without it the results are
        the same.
        """

        def codegen(context, builder, sig, args):
            for arg in builder.function.args[2:]:  # after the return and exception pointers
                if isinstance(arg.type, _k._ir.PointerType):
                    arg.add_attribute("noalias")
            try:  # see gisnoise.maps._numba._prefer_512bit_vectors
                set.add(builder.function.attributes, '"prefer-vector-width"="512"')
            except Exception:  # pragma: no cover
                pass
            return context.get_dummy_value()

        return _k._nbt.none(), codegen

    @_k.jit(fastmath=True, error_model="numpy", inline="always")
    def _atan_s(y, x):
        """``atan2(y, x)`` for ``x >= 0`` (float32), in [-pi/2, pi/2]."""
        r = _k._atan2_pos(abs(y), x)
        return -r if y < _F0 else r

    @_k.jit(fastmath=True, error_model="numpy", nogil=True)
    def _hemi_cells(xb, yb, zb, m, dmin2, hrow, tab, axg, axinv, s0, inv_hs, nd, sc, lev, fwo, wt, em, eacc, facc):
        """Level and weight on filled nodes of ``m`` body vectors of one hemisphere card (row ``hrow``).

        Four vectorized passes over the cells (short loops keep the table reads' latency
        hidden): distance and table angles; fractional node indices (one product on a uniform
        axis, else ``u = sum_k c_k max(a - g_k, 0)`` over the axis' intervals, eight at a time); table entries, weights and distance fraction; the table reads, the level and
        the energies.  ``sc``: scratch ``(6, >= m)``.  Writes the level to ``lev`` and the weight
        on filled nodes to ``fwo``, and adds the energies to the accumulators ``em``
        (maximum), ``eacc`` (``wt e``) and ``facc`` (``wt e fw``).
        """
        _vectorize_gathers()
        tb = np.int32(hrow[H_TAB])
        nn = np.int32(hrow[H_NN])
        nj = np.int32(hrow[H_NJ])
        si = np.uint32(hrow[H_SI])
        qb = np.float32(hrow[H_QB])
        qs = np.float32(hrow[H_QS])
        imax = np.int32(hrow[H_IMAX])
        jmax = np.int32(hrow[H_JMAX])
        amin = np.float32(hrow[H_AMIN])
        amax = np.float32(hrow[H_AMAX])
        bmin = np.float32(hrow[H_BMIN])
        bmax = np.float32(hrow[H_BMAX])
        k0 = np.float32(hrow[H_K0])
        d2min = np.float32(dmin2)
        s032 = np.float32(s0)
        ihs = np.float32(inv_hs)
        ndm2 = np.int32(nd - 2)
        w32 = np.float32(wt)
        S = sc[0]
        A = sc[1]
        B = sc[2]
        OUT = sc[3]
        V = sc[4]
        RO = sc[5].view(np.uint32)
        for q in range(m):
            x = xb[q]
            y = yb[q]
            z = zb[q]
            S[q] = _k._log2(max(x * x + y * y + z * z, d2min))
            zc = abs(z)
            ap = _atan_s(-x, zc)
            bt = _atan_s(y, zc)
            out = (z < _F0) or (ap < amin) or (ap > amax) or (bt < bmin) or (bt > bmax)
            OUT[q] = _F1 if out else _F0
            A[q] = min(max(ap, amin), amax)
            B[q] = min(max(bt, bmin), bmax)
        for ax in range(2):
            X = A if ax == 0 else B
            Uo = lev if ax == 0 else V  # lev holds u until the last pass
            g0 = np.float32(hrow[H_PA0 if ax == 0 else H_TA0])
            uinv = np.float32(hrow[H_PINV if ax == 0 else H_TINV])
            off = np.int32(hrow[H_PBO if ax == 0 else H_TBO])
            nint = np.int32(hrow[H_PNB if ax == 0 else H_TNB])
            if uinv > _F0 or nint == 0:
                for q in range(m):
                    Uo[q] = (X[q] - g0) * uinv
            else:  # u = K + sum_k c_k max(a, g_k), K = -sum_k c_k g_k; the axes are padded with c_k = 0
                kc = np.float32(hrow[H_PK if ax == 0 else H_TK])
                for q in range(m):
                    Uo[q] = kc
                kk = off
                while kk + 8 <= off + nint:
                    g_0, g_1, g_2, g_3 = axg[kk], axg[kk + 1], axg[kk + 2], axg[kk + 3]
                    g_4, g_5, g_6, g_7 = axg[kk + 4], axg[kk + 5], axg[kk + 6], axg[kk + 7]
                    c_0, c_1, c_2, c_3 = axinv[kk], axinv[kk + 1], axinv[kk + 2], axinv[kk + 3]
                    c_4, c_5, c_6, c_7 = axinv[kk + 4], axinv[kk + 5], axinv[kk + 6], axinv[kk + 7]
                    for q in range(m):
                        a = X[q]
                        Uo[q] += (((max(a, g_0) * c_0 + max(a, g_1) * c_1) + (max(a, g_2) * c_2 + max(a, g_3) * c_3))
                                  + ((max(a, g_4) * c_4 + max(a, g_5) * c_5) + (max(a, g_6) * c_6 + max(a, g_7) * c_7)))
                    kk += 8
                if kk < off + nint:
                    g_0, g_1, g_2, g_3 = axg[kk], axg[kk + 1], axg[kk + 2], axg[kk + 3]
                    c_0, c_1, c_2, c_3 = axinv[kk], axinv[kk + 1], axinv[kk + 2], axinv[kk + 3]
                    for q in range(m):
                        a = X[q]
                        Uo[q] += (max(a, g_0) * c_0 + max(a, g_1) * c_1) + (max(a, g_2) * c_2 + max(a, g_3) * c_3)
        for q in range(m):  # entries (unsigned: no negative-index wraparound), weights, distance fraction
            u = lev[q]
            v = V[q]
            ii = min(max(np.int32(u), np.int32(0)), imax)
            jj = min(max(np.int32(v), np.int32(0)), jmax)
            A[q] = min(max(u - np.float32(ii), _F0), _F1)
            B[q] = min(max(v - np.float32(jj), _F0), _F1)
            x = (S[q] - s032) * ihs
            kd = min(max(np.int32(x), np.int32(0)), ndm2)
            V[q] = x - np.float32(kd)
            RO[q] = np.uint32(tb + (ii * nj + jj) * nn + kd)
        for q in range(m):
            wa = A[q]
            wb = B[q]
            fd = V[q]
            s = S[q]
            ro = RO[q]
            p0 = tab[ro]  # node (ii, jj) and (ii, jj + 1)
            p1 = tab[ro + si]  # node (ii + 1, jj) and (ii + 1, jj + 1)
            c00 = np.int32(p0 & _M16)
            c01 = np.int32((p0 >> 32) & _M16)
            c10 = np.int32(p1 & _M16)
            c11 = np.int32((p1 >> 32) & _M16)
            a00 = np.float32(c00)
            a01 = np.float32(c01)
            a10 = np.float32(c10)
            a11 = np.float32(c11)
            t00 = a00 + fd * (np.float32(np.int32((p0 >> 16) & _M16)) - a00)
            t01 = a01 + fd * (np.float32(np.int32((p0 >> 48) & _M16)) - a01)
            t10 = a10 + fd * (np.float32(np.int32((p1 >> 16) & _M16)) - a10)
            t11 = a11 + fd * (np.float32(np.int32((p1 >> 48) & _M16)) - a11)
            w00 = (_F1 - wa) * (_F1 - wb)
            w01 = (_F1 - wa) * wb
            w10 = wa * (_F1 - wb)
            w11 = wa * wb
            lv = qb + qs * (w00 * t00 + w01 * t01 + w10 * t10 + w11 * t11) - _F32_CSP * s + k0
            fw = (w00 * np.float32(c00 & 1) + w01 * np.float32(c01 & 1) + w10 * np.float32(c10 & 1)
                  + w11 * np.float32(c11 & 1))
            fw = max(fw, OUT[q])
            lev[q] = lv
            fwo[q] = fw
            e = _k._exp2(lv * _K10)
            em[q] = max(em[q], e)
            eacc[q] += w32 * e
            facc[q] += w32 * e * fw
        return 0

    @_k.jit(fastmath=True, error_model="numpy", nogil=True)
    def _hemi_points(xq, yq, zq, dmin2, tab, hs, axg, axinv, s0, inv_hs, nd, h):
        """The kernel's level and filled weight for arrays of body vectors, hemisphere card ``h`` (tests)."""
        n = xq.size
        levo = np.empty(n, np.float32)
        fwo = np.empty(n, np.float32)
        acc = np.zeros((3, n), np.float32)
        sc = np.empty((6, n), np.float32)
        _hemi_cells(xq.astype(np.float32), yq.astype(np.float32), zq.astype(np.float32), n, dmin2, hs[h], tab, axg,
                    axinv, s0, inv_hs, nd, sc, levo, fwo, 1.0, acc[0], acc[1], acc[2])
        return levo, fwo

    @_k.jit(fastmath=True, error_model="numpy", nogil=True)
    def _hemi_window_kernel(P, U, dh, has_dem, k, m0, c0, ncw, src, C, gain, cidx, coef, w, dt, radius, thr,
                            kind, hs, tab, axg, axinv, s0, inv_hs, nd,
                            emax, energy, ta, computed, efill):  # pragma: no cover - compiled
        """:func:`gisnoise.maps._numba._window_kernel` with hemisphere instants (``kind[i] >= 0``: row of ``hs``).

        Extra output ``efill``: ``sum w_i 10^(L_i/10) f_i`` with ``f_i`` the weight on filled nodes.
        """
        _vectorize_gathers()
        nr = P.shape[0]
        ns = (P.shape[1] - 1) // 2
        n = src.shape[0]
        nt = thr.shape[0]
        thr32, lcur, lprev, eacc, tacc, e0, e1, e2, n0, n1, lo_b, hi_b = _k._window_buffers(k, thr)
        facc = np.zeros(k, np.float32)
        xs = np.empty(k, np.float32)
        ys = np.empty(k, np.float32)
        zs = np.empty(k, np.float32)
        fcur = np.empty(k, np.float32)
        sc = np.empty((6, k), np.float32)
        half_k = 0.5 * k
        half_k32 = np.float32(half_k)
        for r in range(nr):
            for sg in range(ns):
                m, q0, jl = _k._segment(P, U, dh, has_dem, r, sg, k, m0, c0, ncw, src, radius, e0, e1, e2, n0, n1,
                                        lo_b, hi_b, computed)
                if m == 0:
                    continue
                em = emax[r, jl:jl + m]
                en = energy[r, jl:jl + m]
                ef = efill[r, jl:jl + m]
                dhr = dh[r, jl:jl + m] if has_dem else dh[0, 0:1]
                for i in range(n):
                    ci = cidx[i]
                    # body frame: A + u (B + u D) (+ dh (N + u T)), u = q - k/2
                    (ax, ay, az, bx, by, bz, dx, dy, dz,
                     nx, ny, nz, tx, ty, tz) = _k._lattice(C, i, src, e0, e1, e2, n0, n1, has_dem)
                    wt = np.float32(w[i])
                    hk = kind[i]
                    if hk >= 0:
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            hh = dhr[q] if has_dem else _F0
                            xs[q] = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                            ys[q] = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                            zs[q] = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                        _hemi_cells(xs, ys, zs, m, coef[ci, 9], hs[hk], tab, axg, axinv, s0, inv_hs, nd, sc, lcur,
                                    fcur, wt, em, eacc, facc)
                    else:
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
                        for q in range(m):
                            qf = np.float32(q0 + q) - half_k32
                            hh = dhr[q] if has_dem else _F0
                            xb = ax + qf * (bx + qf * dx) + hh * (nx + qf * tx)
                            yb = ay + qf * (by + qf * dy) + hh * (ny + qf * ty)
                            zb = az + qf * (bz + qf * dz) + hh * (nz + qf * tz)
                            lev, e = _k._cell(xb, yb, zb, g, p2, cp3, sp3, p4, cp5, sp5, c6, kk, e7, dmin2)
                            em[q] = max(em[q], e)
                            eacc[q] += wt * e
                            lcur[q] = lev
                        if nt > 0 and e7 != _F0:
                            for q in range(m):
                                lcur[q] = _k._log2(_k._exp2(lcur[q] * _K10) + e7) * _DB_PER_LOG2
                    if nt > 0:
                        if i > 0:
                            _k._time_above(lprev, lcur, thr32, tacc, np.float32(dt[i]), m)
                        for q in range(m):
                            lprev[q] = lcur[q]
                    if (i + 1) % _FLUSH == 0 or i == n - 1:
                        _k._flush(en, eacc, ta, tacc, r, jl, m)
                        for q in range(m):
                            ef[q] += facc[q]
                            facc[q] = _F0
        return 0
