"""Measured hemispheres (:class:`~gisnoise.model.HemisphereCard`) in the fast engine.

When a flight's cards include a hemisphere card, the fast engine runs the window kernel of
:mod:`gisnoise.maps._hemikernel` (float32, vectorized; how it is fast is told there) in place
of the parametric one: it evaluates the hemisphere instants and, mixed in by phase, the
``paper`` / ``paper-offset`` instants exactly as the parametric kernel does.  It computes
everything the parametric fast path computes: LAmax, LAeq, SEL, time above levels, snapshots
and the audibility floor; the operations of :mod:`gisnoise.ops` run it per tile through
:func:`prepare_flight` and :func:`~gisnoise.maps.fastkernel.run_window`.

The hemisphere's level follows the card's stated scheme (bilinear interpolation in the table
angles of the nodes' A-weighted levels at the receiver's distance).  Per node, the level
without spherical spreading is tabulated (:func:`distance_table`, from
:meth:`HemisphereCard.node_levels`, the model's definition) on distances log-spaced by
:data:`DIST_STEP` (in ``ln d``) and read linearly; the difference to the exact per-band sum
stays below 0.001 dB (tested).  The table reaches :data:`DEFAULT_REACH_M` from the UAV, or
the map's farthest cell; a window farther out is refused (field ``grid``).

**Audibility floor.**  The bound of a hemisphere instant is the largest node level at the
distance (bilinear interpolation never exceeds its nodes), plus the table's largest step in
spreading: beyond the distance where it falls below the floor, cells are skipped.

The metadata states ``hemisphere_filled_energy_share``: the share of the map's energy (sum
over cells of the SEL energy) from hemisphere instants that came from filled table nodes.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, InputError
from gisnoise.flight import Trajectory
from gisnoise.maps import _hemikernel as _hk
from gisnoise.maps._checks import as_float
from gisnoise.maps.cardset import as_cardset
from gisnoise.maps.hemifill import has_hemisphere, hemisphere_atmospheres
from gisnoise.maps.instants import FlightInstants, _instants
from gisnoise.maps.instants import prepare_flight as _prepare_parametric
from gisnoise.maps.instants import snapshot_instant as _snapshot_parametric
from gisnoise.maps.kernelbands import chunk_cells_of, kernel_bands
from gisnoise.maps.prepare import (
    MapOptions,
    MapRequest,
    eval_states,
    map_metadata,
    snapshot_state,
)
from gisnoise.maps.receivers import Receivers, receivers_for
from gisnoise.maps.result import MapResult
from gisnoise.maps.threads import default_threads, map_threads, row_blocks
from gisnoise.model import HemisphereCard, ModelCard

__all__ = [
    "DEFAULT_REACH_M",
    "DIST_STEP",
    "HemiFlight",
    "HemiTables",
    "HemiWindowResult",
    "distance_table",
    "evaluate_hemisphere_fast",
    "hemisphere_level_points",
    "prepare_flight",
    "run_hemi_window",
    "snapshot_instant",
]

DIST_STEP = 0.02
"""Step of the kernel's distance table in ``ln d`` (about 2 % of the distance)."""
DEFAULT_REACH_M = 200_000.0
"""Farthest distance from the UAV the table covers when no map is given (operations), m."""

_PLACEHOLDER = ModelCard(id="hemisphere", vehicle="hemisphere", phase="horizontal", ansatz="paper-offset",
                         parameters=dict(p0=0.0, p1=0.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=0.0, p7=0.0),
                         reference_power_w=1.0, reference_distance_m=1.0)
"""Stands for a hemisphere card in the parametric preparation (its rows are replaced)."""


# --------------------------------------------------------------------------- tables


def _axis(grid_deg: np.ndarray) -> tuple[float, float, np.ndarray, np.ndarray, float]:
    """A table axis as the kernel reads it: ``(g0, 1 / spacing or 0, nodes, slope steps, K)`` in radians.

    On a uniform axis the fractional node index is ``(a - g0) / spacing`` (no nodes, no steps);
    otherwise the kernel sums ``K + sum_k c_k max(a, g_k)`` over the intervals ``k`` with
    ``c_k = 1 / w_k - 1 / w_k-1`` (``w_k`` the width of interval ``k``, ``1 / w_-1 = 0``) and
    ``K = -sum_k c_k g_k``, that is ``sum_k c_k max(a - g_k, 0)``: for ``g_0 <= a <= g_n`` the
    piecewise linear function through ``(g_k, k)``, so bilinear interpolation in it is
    bilinear interpolation in the angles.  Nodes and steps are padded with ``c_k = 0`` to a
    multiple of :data:`~gisnoise.maps._hemikernel.HINGES`.
    """
    g = np.radians(np.asarray(grid_deg, dtype=float))
    none = np.zeros(0, np.float32)
    if g.size == 1:
        return float(g[0]), 0.0, none, none, 0.0
    sp = np.diff(g)
    if np.ptp(sp) <= 1e-9 * sp.max():
        return float(g[0]), 1.0 / float(sp.mean()), none, none, 0.0
    pad = -(g.size - 1) % _hk.HINGES
    gk = np.pad(g[:-1], (0, pad)).astype(np.float32)
    ck = np.pad(np.diff(1.0 / sp, prepend=0.0), (0, pad)).astype(np.float32)
    return float(g[0]), 0.0, gk, ck, -float(np.dot(ck.astype(float), gk.astype(float)))


def distance_table(card: HemisphereCard, d_lo: float, d_hi: float, step: float = DIST_STEP
                   ) -> tuple[np.ndarray, float, float]:
    """Nodes' A-weighted levels without spherical spreading on distances log-spaced over ``[d_lo, d_hi]``.

    Returns ``(table, s0, hs)``: ``table[k, node]`` (float64, nodes row-major ``phi, theta``) at
    ``d_k`` with ``log2(d_k^2) = s0 + k hs``; the level at ``d_k`` is ``table - 20 lg(d_k / r0)``.
    """
    hs = 2.0 * step / math.log(2.0)
    s0 = 2.0 * math.log2(d_lo)
    nd = max(2, int(math.ceil((2.0 * math.log2(max(d_hi, d_lo * 1.001)) - s0) / hs)) + 2)
    d = 2.0 ** ((s0 + hs * np.arange(nd)) / 2.0)
    lv = card.node_levels(d).reshape(nd, -1)
    return lv + 20.0 * np.log10(d / float(card.reference_distance_m))[:, None], s0, hs


@dataclass(frozen=True, eq=False)
class HemiTables:
    """The hemisphere cards of a flight as the kernel reads them (:mod:`gisnoise.maps._hemikernel`).

    ``kind[i]``: row of ``hs`` of instant ``i``'s hemisphere card, -1 for a parametric card;
    ``hs``: per card the offsets and scalars (columns ``H_*``); ``tab``: the distance tables
    (float32, one shared distance grid ``s0 + k hs_step`` in ``log2(d^2)``, ``nd`` points);
    ``axg``, ``axinv``: the axes' nodes and inverse interval widths (rad, float32);
    ``reach_m``: the farthest distance the tables cover; ``bound``: per card, the largest node
    level at each table distance (dB, for the audibility radius).
    """

    kind: np.ndarray
    hs: np.ndarray
    tab: np.ndarray
    axg: np.ndarray
    axinv: np.ndarray
    s0: float
    hs_step: float
    nd: int
    reach_m: float
    bound: np.ndarray


def _tables(cards: Sequence[HemisphereCard], d_min: float, reach_m: float) -> HemiTables:
    """Kernel tables of ``cards`` (kind left empty); placeholders when there is none."""
    if not cards:
        return HemiTables(kind=np.zeros(0, np.int64), hs=np.zeros((1, _hk.N_HS)), tab=np.zeros(2, np.int64),
                          axg=np.zeros(1, np.float32), axinv=np.zeros(1, np.float32), s0=0.0, hs_step=1.0, nd=2, reach_m=math.inf,
                          bound=np.zeros((0, 2)))
    d_lo = d_min * 0.999
    rows, tabs, axg, axinv, bounds = [], [], [], [], []
    off_t = off_a = 0
    s0 = hs = 0.0
    for card in cards:
        tab, s0, hs = distance_table(card, d_lo, reach_m)
        nd = tab.shape[0]
        ni, nj = card.phi_deg.size, card.theta_deg.size
        si = nj if ni > 1 else 0
        pa0, pinv, pg, pi_, pk = _axis(card.phi_deg)
        ta0, tinv, tg, ti_, tk = _axis(card.theta_deg)
        r0 = float(card.reference_distance_m)
        row = np.zeros(_hk.N_HS)
        codes, base, step = _quads(tab, ~card.measured.ravel(), nj)
        row[[_hk.H_TAB, _hk.H_NN, _hk.H_NJ, _hk.H_SI, _hk.H_IMAX, _hk.H_JMAX, _hk.H_QB, _hk.H_QS]] = (
            off_t, nd - 1, nj, si * (nd - 1), max(ni - 2, 0), max(nj - 2, 0), base, step)
        gp, gt = np.radians(card.phi_deg), np.radians(card.theta_deg)
        row[[_hk.H_AMIN, _hk.H_AMAX, _hk.H_BMIN, _hk.H_BMAX]] = gp[0], gp[-1], gt[0], gt[-1]
        row[[_hk.H_PA0, _hk.H_PINV, _hk.H_PNB, _hk.H_PBO]] = pa0, pinv, pg.size, off_a
        row[[_hk.H_TA0, _hk.H_TINV, _hk.H_TNB, _hk.H_TBO]] = ta0, tinv, tg.size, off_a + pg.size
        row[[_hk.H_PK, _hk.H_TK]] = pk, tk
        row[_hk.H_K0] = 20.0 * math.log10(r0)
        rows.append(row)
        tabs.append(codes)
        axg += [pg, tg]
        axinv += [pi_, ti_]
        s = s0 + hs * np.arange(nd)
        bounds.append(tab.max(axis=1) - _hk._CSP * s + 20.0 * math.log10(r0))
        off_t += (nd - 1) * ni * nj
        off_a += pg.size + tg.size
    return HemiTables(kind=np.zeros(0, np.int64), hs=np.array(rows), tab=np.concatenate(tabs),
                      axg=np.concatenate(axg), axinv=np.concatenate(axinv),
                      s0=float(s0), hs_step=float(hs), nd=nd, reach_m=float(reach_m), bound=np.array(bounds))


def _quads(tab: np.ndarray, filled: np.ndarray, nj: int) -> tuple[np.ndarray, float, float]:
    """The kernel's table of one card: per node and distance step four 16-bit level codes in one int64.

    ``tab[k, node]`` (nodes row-major ``phi, theta``, ``nj`` theta nodes).  The entry of node
    ``(i, j)`` and step ``k`` holds, from the lowest 16 bits up, the codes of ``(i, j)`` at
    ``d_k`` and ``d_k+1`` and of ``(i, j + 1)`` (``j`` on the last theta node) at ``d_k`` and
    ``d_k+1``: one read gives both theta nodes of a cell at both distances, two reads all
    eight values.  Node-major (the steps of a node adjacent): neighbouring cells read
    neighbouring entries.

    Returns ``(codes, base, step)``: level ``= base + step * code`` (dB) with ``step`` the
    table's level range over :data:`~gisnoise.maps._hemikernel.Q_MAX`; the lowest bit of a code
    is its node's filled flag (1 filled, 0 measured), the code the nearest of that parity, so
    that a level is off by at most ``step`` (about 0.002 dB for a 130 dB range).
    """
    if not np.isfinite(tab).all():
        raise InputError("cards: a hemisphere card has node levels that are not finite numbers", field="cards")
    lo, hi = float(tab.min()), float(tab.max())
    step = max(hi - lo, 1e-6) / _hk.Q_MAX
    f = filled.astype(np.float64)[None, :]
    near = 2.0 * np.floor(((tab - lo) / step - f) / 2.0 + 0.5) + f
    code = np.clip(near, 0, _hk.Q_MAX + 1).astype(np.uint64)
    nn = code.shape[1]
    right = np.arange(nn) + 1
    right[nj - 1::nj] -= 1  # the last theta node pairs with itself
    q = (code[:-1] | (code[1:] << np.uint64(16)) | (code[:-1, right] << np.uint64(32))
         | (code[1:, right] << np.uint64(48)))
    return np.ascontiguousarray(q.view(np.int64).T).ravel(), lo, step


def _radius(bound: np.ndarray, s0: float, hs: float, floor_db: float | None) -> float:
    """Distance beyond which the level bound of a card is below ``floor_db`` (inf: none; -1: never above)."""
    if floor_db is None:
        return math.inf
    seg = np.maximum(bound[:-1], bound[1:]) + _hk._CSP * hs  # bound over each step of the table
    above = np.flatnonzero(seg >= floor_db)
    if above.size == 0:
        return -1.0
    k = int(above[-1]) + 1
    if k >= bound.size - 1:
        return math.inf
    return 2.0 ** ((s0 + hs * k) / 2.0) * (1.0 + 1e-9) + 1e-3


# --------------------------------------------------------------------------- flights


@dataclass(frozen=True, eq=False)
class HemiFlight(FlightInstants):
    """A flight's instants (:class:`~gisnoise.maps.instants.FlightInstants`) with hemisphere cards' tables."""

    hemi: HemiTables | None = None


def _with_hemispheres(t: np.ndarray, state: dict[str, np.ndarray], idx: np.ndarray, cards: Sequence[ModelCard],
                      frame: Any, *, background: bool, min_distance_m: float, floor_db: float | None,
                      source: str, reach_m: float) -> HemiFlight:
    hemi_k = [k for k in sorted(set(idx.tolist())) if isinstance(cards[k], HemisphereCard)]
    stand_in = [(_PLACEHOLDER if isinstance(c, HemisphereCard) else c) for c in cards]
    with np.errstate(divide="ignore", invalid="ignore"):
        fl = _instants(t, state, idx, stand_in, frame, background=background, min_distance_m=min_distance_m,
                       floor_db=floor_db, source=source)
    tables = _tables([cards[k] for k in hemi_k], float(min_distance_m), float(reach_m))
    kind = np.full(t.size, -1, np.int64)
    gain, radius = fl.gain.copy(), fl.radius.copy()
    for h, k in enumerate(hemi_k):
        sel = idx == k
        kind[sel] = h
        gain[sel] = 0.0
        radius[sel] = _radius(tables.bound[h], tables.s0, tables.hs_step, floor_db)
    tables = dataclasses.replace(tables, kind=kind)
    return HemiFlight(t=fl.t, src=fl.src, C=fl.C, gain=gain, cidx=fl.cidx, coef=fl.coef, w=fl.w, dt=fl.dt,
                      radius=radius, source=fl.source, hemi=tables)


def prepare_flight(traj: Trajectory, cards: Any, frame: Any, *, substeps: int = 1, background: bool = False,
                   min_distance_m: float = 1.0, floor_db: float | None = None,
                   reach_m: float | None = None, temperature_c: float = 15.0) -> FlightInstants:
    """:func:`gisnoise.maps.instants.prepare_flight` for card sets that may hold hemisphere cards.

    Without a hemisphere card it is the parametric preparation (``temperature_c``: the speed of
    sound of receiver-dependent terms); with one, a :class:`HemiFlight` whose tables reach
    ``reach_m`` from the UAV (default :data:`DEFAULT_REACH_M`).
    """
    cardset = as_cardset(cards)
    if not has_hemisphere(cardset.cards):
        return _prepare_parametric(traj, cardset, frame, substeps=substeps, background=background,
                                   min_distance_m=min_distance_m, floor_db=floor_db, temperature_c=temperature_c)
    idx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    t_eval, state, src_sample = eval_states(traj, int(substeps))
    return _with_hemispheres(t_eval, state, idx_samples[src_sample], cardset.cards, frame, background=background,
                             min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source,
                             reach_m=DEFAULT_REACH_M if reach_m is None else reach_m)


def snapshot_instant(traj: Trajectory, cards: Any, frame: Any, t_s: float, *, background: bool = False,
                     min_distance_m: float = 1.0, floor_db: float | None = None,
                     reach_m: float | None = None, temperature_c: float = 15.0) -> FlightInstants:
    """:func:`gisnoise.maps.instants.snapshot_instant` for card sets that may hold hemisphere cards."""
    cardset = as_cardset(cards)
    if not has_hemisphere(cardset.cards):
        return _snapshot_parametric(traj, cardset, frame, t_s, background=background,
                                    min_distance_m=min_distance_m, floor_db=floor_db, temperature_c=temperature_c)
    state, idx = snapshot_state(traj, cardset, t_s)
    return _with_hemispheres(np.array([float(t_s)]), state, idx, cardset.cards, frame, background=background,
                             min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source,
                             reach_m=DEFAULT_REACH_M if reach_m is None else reach_m)


# --------------------------------------------------------------------------- running the kernel


@dataclass(frozen=True, eq=False)
class HemiWindowResult:
    """:class:`~gisnoise.maps.fastkernel.WindowResult` plus ``efill``: the energy from filled nodes."""

    emax: np.ndarray
    energy: np.ndarray
    ta: np.ndarray
    computed: np.ndarray
    efill: np.ndarray


def run_hemi_window(fl: HemiFlight, rc: Receivers, r0: int, r1: int, c0: int, c1: int,
                    thresholds: Sequence[float] = (), *, lattice: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> HemiWindowResult:
    """The hemisphere kernel on rows ``r0:r1``, columns ``c0:c1`` (as :func:`~gisnoise.maps.fastkernel.run_window`)."""
    if _hk.numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")
    ht = fl.hemi
    assert ht is not None
    dh = rc.window_heights(r0, r1, c0, c1)
    k = rc.seg
    P, U = rc.lattice(r0, r1, c0 // k, -(-c1 // k)) if lattice is None else lattice
    nr, ncw = r1 - r0, c1 - c0
    # the tables must reach every cell of the window from every hemisphere instant
    hsel = ht.kind >= 0
    if hsel.any():
        far = _farthest(rc, fl.src[hsel], r0, r1, c0, c1)
        if far > ht.reach_m:
            raise InputError(f"grid: cells lie up to {far:.0f} m from the UAV, beyond the hemisphere tables' reach "
                             f"of {ht.reach_m:.0f} m", field="grid")
    thr = np.asarray(list(thresholds), dtype=np.float64)
    emax = np.zeros((nr, ncw), np.float32)
    energy = np.zeros((nr, ncw), np.float64)
    efill = np.zeros((nr, ncw), np.float64)
    ta = np.zeros((thr.size, nr, ncw), np.float64)
    computed = np.zeros((nr, ncw), np.uint8)
    _hk._hemi_window_kernel(P, U, dh, rc.dh is not None, k, c0 // k, c0, ncw, fl.src, fl.C, fl.gain, fl.cidx,
                            fl.coef, fl.w, fl.dt, fl.radius, thr, ht.kind, ht.hs, ht.tab, ht.axg, ht.axinv, ht.s0, 1.0 / ht.hs_step, ht.nd, emax, energy, ta, computed, efill)
    return HemiWindowResult(emax, energy, ta, computed.astype(bool), efill)


def _run_grid(fl: HemiFlight, rc: Receivers, thresholds: Sequence[float], threads: int | None, chunk: int,
              progress: Callable[[float], Any] | None, cancel: Callable[[], bool] | None) -> HemiWindowResult:
    H, W = rc.grid.shape
    nthreads = default_threads() if threads is None else max(1, int(threads))
    blocks = row_blocks(H, W, chunk, nthreads)
    nt = len(list(thresholds))
    out = HemiWindowResult(np.zeros((H, W), np.float32), np.zeros((H, W)), np.zeros((nt, H, W)),
                           np.zeros((H, W), bool), np.zeros((H, W)))
    done = 0

    def put(b: tuple[int, int], res: HemiWindowResult) -> None:
        nonlocal done
        r0, r1 = b
        out.emax[r0:r1], out.energy[r0:r1], out.ta[:, r0:r1] = res.emax, res.energy, res.ta
        out.computed[r0:r1], out.efill[r0:r1] = res.computed, res.efill
        done += r1 - r0
        if progress is not None:
            progress(done / H)

    def check() -> None:
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")

    map_threads(lambda b: run_hemi_window(fl, rc, b[0], b[1], 0, W, thresholds), blocks, put, nthreads, poll=check)
    return out


def _farthest(rc: Receivers, src: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> float:
    """Largest distance from the points ``src`` (ENU) to the cells of a window (a box around its edges), m."""
    t = rc.grid.transform
    f = np.linspace(0.0, 1.0, 9)
    cols = np.concatenate([c0 + f * (c1 - c0), c0 + f * (c1 - c0), np.full(9, c0), np.full(9, c1)])
    rows = np.concatenate([np.full(9, r0), np.full(9, r1), r0 + f * (r1 - r0), r0 + f * (r1 - r0)])
    lon, lat = rc.grid.to_wgs84(t.c + t.a * cols, t.f + t.e * rows)
    p = np.stack(rc.frame.to_enu(lat, lon, np.full(lat.shape, rc.h_ref)), axis=-1)
    dz = 0.0 if rc.dh is None else float(np.abs(rc.dh).max())
    lo_b, hi_b = p.min(axis=0) - dz - 1.0, p.max(axis=0) + dz + 1.0
    return float(np.sqrt(np.sum(np.maximum(np.abs(src - lo_b), np.abs(src - hi_b)) ** 2, axis=1)).max())


def evaluate_hemisphere_fast(req: MapRequest, opts: MapOptions) -> MapResult:
    """The fast engine for card sets with hemisphere cards (module docstring); ``req`` from ``check_request``."""
    if _hk.numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")
    traj, grid, metrics, thresholds, period, snap = req.traj, req.grid, req.metrics, req.thresholds, req.period, req.snap
    floor = None if opts.floor_db is None else as_float(opts.floor_db, "floor_db")
    chunk = chunk_cells_of(opts.chunk_cells, 1 << 17)
    rc = receivers_for(grid, [traj], receiver_height=opts.receiver_height, dem=opts.dem, ground_h=req.ground,
                       dem_offset_m=opts.dem_offset_m)
    frame = rc.frame
    s_enu = np.stack(frame.to_enu(traj.lat, traj.lon, traj.h), axis=-1)
    reach = _farthest(rc, s_enu, 0, grid.height, 0, grid.width) * 1.05 + 10.0
    kw = dict(background=opts.background, min_distance_m=req.min_distance_m, floor_db=floor, reach_m=reach)
    fl = prepare_flight(traj, req.cardset, frame, substeps=req.substeps, **kw)  # type: ignore[arg-type]
    share = 1.0 if snap is None else fl.n / (fl.n + 1.0)
    progress = opts.progress

    def prog(f: float) -> None:
        if progress is not None:
            progress(share * f)

    res = _run_grid(fl, rc, thresholds, opts.threads, chunk, prog, opts.cancel)  # type: ignore[arg-type]
    s = None
    if snap is not None:
        s_fl = snapshot_instant(traj, req.cardset, frame, snap, **kw)  # type: ignore[arg-type]
        assert isinstance(s_fl, HemiFlight)  # the card set holds a hemisphere card
        s = _run_grid(s_fl, rc, (), opts.threads, chunk, None if progress is None else
                      (lambda f: progress(share + (1 - share) * f)), opts.cancel)
    bands, below = kernel_bands(res, grid.shape, metrics, thresholds, snap, period, floor, s, rc.valid)
    used = sorted(set(req.cardset.assign(traj.phase, traj.t, source=traj.source).tolist()))
    meta = map_metadata(req, bands, fl.n, float(opts.receiver_height), rc.ground or {}, opts.background, used)
    ok = np.ones(grid.shape, bool) if rc.valid is None else rc.valid
    tot = float(res.energy[ok].sum())
    meta.update({"engine": "fast", "floor_db": floor, "cells_below_floor": int(below.sum()),
                 "hemisphere_filled_energy_share": float(res.efill[ok].sum()) / tot if tot > 0 else 0.0,
                 "hemisphere_atmospheres": hemisphere_atmospheres([req.cardset.cards[k] for k in used]),
                 "hemisphere_interpolation": "bilinear in the table angles of the nodes' A-weighted levels at the "
                                             "receiver's distance (ISO 9613-1 absorption in the card's map "
                                             "atmosphere)"})
    return MapResult(bands=bands, grid=grid, metadata=meta)


def hemisphere_level_points(card: HemisphereCard, xb: Any, yb: Any, zb: Any, *, min_distance_m: float = 1.0
                            ) -> tuple[np.ndarray, np.ndarray]:
    """The kernel's level (dB(A), float32) and weight on filled nodes for body vectors ``(xb, yb, zb)`` (m).

    For the tests against :meth:`HemisphereCard.level_direction` (the NumPy engine's definition).
    """
    if _hk.numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")
    xb, yb, zb = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (xb, yb, zb)))
    d = np.sqrt(xb ** 2 + yb ** 2 + zb ** 2)
    reach = max(float(d.max()) * 1.05 + 10.0, 10.0) if d.size else 10.0
    ht = _tables([card], float(min_distance_m), reach)
    lev, fw = _hk._hemi_points(xb.ravel(), yb.ravel(), zb.ravel(), float(min_distance_m) ** 2, ht.tab, ht.hs,
                               ht.axg, ht.axinv, ht.s0, 1.0 / ht.hs_step, ht.nd, 0)
    return lev.reshape(xb.shape), fw.reshape(xb.shape)
