"""The uncertainty bands on the fast engine: the delta method of the NumPy engine, accumulated in numba.

The NumPy engine (:mod:`gisnoise.maps.reference`) propagates each card's parameter covariance
``C`` through the ansatz's analytic Jacobian: ``LAmax_std = sqrt(J^T C J)`` with ``J = dL/dp`` at
the instant of the maximum, ``LAeq_std = SEL_std = sqrt(g^T C g)`` with ``g = sum_i w_i
10^(L_i/10) dL_i/dp / sum_i w_i 10^(L_i/10)``, ``*_p95 = level - 1.645 std``; cards are
independent (block-diagonal covariance).  Where instants tie for the maximum, ``LAmax_std`` is the
largest ``tie_std(sqrt(J_i^T C J_i), LAmax - L_i)`` over the instants less than ``TIE_DB`` below
LAmax (:func:`~gisnoise.maps.prepare.tie_std`), in both engines.  Here the kernel of
:mod:`gisnoise.maps._numba_jac` runs after the level kernel, whose LAmax sets each cell's bar
``LAmax - TIE_DB``; over the same lattice, instants and audibility skipping it keeps per cell that
largest value over the instants above the bar and the sums of ``g``, window by window, and each
window is reduced to its standard deviations at once, so memory stays that of a window (``8``
columns per card).

It serves the ``paper`` and ``paper-offset`` ansatzes (Eq. 8-11, whose Jacobian the kernel
writes out; the tests check it against the ansatz's); effect extensions and measured
hemispheres keep their uncertainty on the NumPy engine (:func:`uncertainty_refusal`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled
from gisnoise.maps import _numba_jac as _jk
from gisnoise.maps.fast_effects import KERNEL_BASES
from gisnoise.maps.instants import FlightInstants, card_coefficients
from gisnoise.maps.prepare import TIE_DB, Z95
from gisnoise.maps.receivers import Receivers
from gisnoise.maps.threads import default_threads, map_threads, row_blocks
from gisnoise.model import HemisphereCard, ModelCard

__all__ = ["uncertainty_bands", "uncertainty_refusal"]

_SILENT_GAIN_DB = -1.0e4
"""Gain of an instant without power in the Jacobian kernel: its energy underflows to the kernel's floor (2^-126)."""


def uncertainty_refusal(cards: Sequence[ModelCard]) -> str | None:
    """Why the fast engine cannot give the uncertainty bands of ``cards`` (one line), or None when it can."""
    for c in cards:
        if isinstance(c, HemisphereCard):
            return f"card {c.id!r}: a measured hemisphere has no parameters to propagate"
        if c.ansatz not in KERNEL_BASES:  # the kernel's base ansatzes, without effect extensions
            return f"card {c.id!r}: the uncertainty bands of ansatz {c.ansatz!r} need the NumPy engine"
    return None


def _card_rows(cards: Sequence[ModelCard], used: Sequence[int], *, background: bool,
               min_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's per-card rows ``jc`` (:data:`~gisnoise.maps._numba_jac.JC_COLUMNS`) and each used card's
    covariance in the columns ``p0 .. p7`` (``(len(used), 8, 8)``; ``paper``'s ``p0`` row and column zero)."""
    jc = np.zeros((len(cards), len(_jk.JC_COLUMNS)))
    cov = np.zeros((len(used), _jk.N_JAC, _jk.N_JAC))
    for u, k in enumerate(used):
        c = cards[k]
        _p0, _p1, row = card_coefficients(c, background=background, min_distance_m=min_distance_m)
        p = dict(zip(c.model.params, c.p, strict=True))
        jc[k] = row
        jc[k, 6] = p["p6"]
        jc[k, 7] = 20.0 * math.log10(c.reference_distance_m)
        cols = [_jk.N_JAC - len(c.model.params) + i for i in range(len(c.model.params))]  # paper: p1 .. p7
        cov[u][np.ix_(cols, cols)] = np.asarray(c.cov, dtype=float)
    return jc, cov


def uncertainty_bands(cards: Sequence[ModelCard], fl: FlightInstants, rc: Receivers, metrics: Sequence[str],
                      levels: dict[str, np.ndarray], *, background: bool, min_distance_m: float,
                      threads: int | None = None, chunk_cells: int = 1 << 17,
                      cancel: Callable[[], bool] | None = None,
                      progress: Callable[[float], Any] | None = None) -> dict[str, np.ndarray]:
    """The bands ``LAmax_std``, ``LAmax_p95``, ``LAeq_std``, ``LAeq_p95``, ``SEL_std`` of the requested metrics.

    ``fl``: the flight as the level kernel ran it (:func:`~gisnoise.maps.instants.prepare_flight`
    with ``background`` and ``min_distance_m``: its instants, weights, rotations, ``lg P_el`` and
    audibility radii); its cards pass :func:`uncertainty_refusal` and
    :func:`~gisnoise.maps.prepare.require_covariances` (the caller checks, before the levels);
    ``levels``: the level bands already computed (LAmax sets the instants that tie for it; the ``*_p95``
    bands subtract from them).  NaN where a level band is NaN.
    """
    want_max = "LAmax" in metrics
    want_int = "LAeq" in metrics or "SEL" in metrics
    if not (want_max or want_int) or fl.lg_power is None:
        return {}
    used = sorted(set(fl.cidx.tolist()))
    jc, cov = _card_rows(cards, used, background=background, min_distance_m=min_distance_m)
    slot = {k: u for u, k in enumerate(used)}
    jo = np.array([_jk.N_JAC * slot[int(k)] for k in fl.cidx], dtype=np.int64)
    # a silent instant (no power: gain and lg P_el -inf) adds no energy and no Jacobian of its own, only the
    # background's (dL/dp7 = 1): a finite gain far below any level and lg P_el = 0 give exactly that
    silent = ~(np.isfinite(fl.gain) & np.isfinite(fl.lg_power))
    gain = np.where(silent, _SILENT_GAIN_DB, fl.gain)
    lgp = np.where(silent, 0.0, fl.lg_power)
    nj = _jk.N_JAC * len(used)
    H, W = rc.grid.shape
    bar = np.full((H, W), np.finfo(np.float32).max, np.float32)  # the energy an instant reaches to tie for LAmax
    if want_max:
        lamax = levels["LAmax"]
        ok = np.isfinite(lamax)
        # (at least the smallest normal float32: a cell of silent instants only sits at the kernel's floor)
        bar[ok] = np.maximum(np.power(10.0, (lamax[ok] - TIE_DB) / 10.0), np.finfo(np.float32).tiny)
    s_max = np.full((H, W), np.nan)
    s_int = np.full((H, W), np.nan)
    k = rc.seg
    done = 0

    def window(b: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        r0, r1 = b
        dh = rc.window_heights(r0, r1, 0, W)
        P, U = rc.lattice(r0, r1, 0, -(-W // k))
        nr = r1 - r0
        thr = bar[r0:r1]
        std_max = np.full((nr, W), -1.0)
        energy = np.zeros((nr, W))
        gsum = np.zeros((nj, nr, W))
        computed = np.zeros((nr, W), np.uint8)
        _jk._jac_window_kernel(P, U, dh, rc.dh is not None, k, 0, 0, W, fl.src, fl.C, gain, lgp, fl.cidx, jc, jo,
                               fl.w, fl.radius, thr, TIE_DB, cov, std_max, energy, gsum, computed)
        missed = (computed == 1) & (thr < np.finfo(np.float32).max) & (std_max < 0.0)
        if missed.any():  # the level kernel's loudest instant reaches the bar: never
            raise RuntimeError(f"uncertainty: {int(missed.sum())} cells without an instant at their LAmax")
        with np.errstate(invalid="ignore", divide="ignore"):
            g = gsum.reshape(len(used), _jk.N_JAC, nr, W) / energy
        var_int = np.einsum("uprc,upq,uqrc->rc", g, cov, g)
        out_max = std_max
        out_int = np.sqrt(np.maximum(var_int, 0.0))
        off = computed == 0
        out_max[off] = np.nan
        out_int[off] = np.nan
        return out_max, out_int
    def put(b: tuple[int, int], res: tuple[np.ndarray, np.ndarray]) -> None:
        nonlocal done
        s_max[b[0]:b[1]], s_int[b[0]:b[1]] = res
        done += b[1] - b[0]
        if progress is not None:
            progress(done / H)

    def check() -> None:
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")

    nthreads = default_threads() if threads is None else max(1, int(threads))
    map_threads(window, row_blocks(H, W, max(1, int(chunk_cells) // max(1, nj // 4)), nthreads), put, nthreads,
                poll=check)
    out: dict[str, np.ndarray] = {}
    if want_max:
        s = np.where(np.isfinite(levels["LAmax"]), s_max, np.nan)
        out["LAmax_std"], out["LAmax_p95"] = s, levels["LAmax"] - Z95 * s
    if want_int:
        for name in ("LAeq", "SEL"):
            if name in metrics:
                s = np.where(np.isfinite(levels[name]), s_int, np.nan)
                out[f"{name}_std"] = s
                if name == "LAeq":
                    out["LAeq_p95"] = levels["LAeq"] - Z95 * s
    return out
