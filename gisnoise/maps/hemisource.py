"""Measured hemispheres (:class:`~gisnoise.model.HemisphereCard`) in the fast engine.

When a map's cards include a hemisphere card, ``engine="fast"`` runs this numba kernel (float64)
in place of the parametric one: it evaluates the hemisphere instants and, mixed in by phase,
the ``paper`` / ``paper-offset`` instants (the same Eq. 8-10 as :mod:`gisnoise.model.ansatz`).

The hemisphere's level follows the card's stated scheme (bilinear interpolation in the table
angles of the nodes' A-weighted levels at the receiver's distance).  The kernel reads the
nodes' levels from a table over ``ln d`` (:func:`distance_table`, built by
:meth:`HemisphereCard.node_levels`, the model's definition) with linear interpolation; the
step keeps the difference to the exact per-band sum below 0.001 dB (tested against the NumPy
engine).  The metadata states ``hemisphere_filled_energy_share``: the share of the map's
energy (sum over cells of the SEL energy) from hemisphere instants that came from filled
cells of the table.

Refused here (use ``engine="numpy"``): time-above thresholds, snapshots, the audibility floor.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, InputError
from gisnoise.geo import WGS84, body_vector, transformer
from gisnoise.maps import _numba as _kernels
from gisnoise.maps._checks import as_float
from gisnoise.maps.instants import card_coefficients
from gisnoise.maps.prepare import (
    MapOptions,
    MapRequest,
    band_order,
    eval_states,
    ground_on_grid,
    local_frame,
    map_metadata,
    trapezoid_weights,
)
from gisnoise.maps.result import MapResult
from gisnoise.maps.threads import default_threads, map_threads
from gisnoise.model import HemisphereCard

__all__ = ["N_DISTANCES", "distance_table", "evaluate_hemisphere_fast"]

N_DISTANCES = 2048
"""Distances of the kernel's table, log-spaced from the nearest to the farthest receiver."""

numba = _kernels.numba

_LUT_PER_DEG = 10
_NLUT = 180 * _LUT_PER_DEG + 1
_LN10_10 = math.log(10.0) / 10.0
"""Bins per degree of the table-angle lookup (the lower node of each bin's start)."""


def _lut(grid: np.ndarray) -> np.ndarray:
    """Index of the last node at or below the start of every bin over -90..90 deg."""
    edges = -90.0 + np.arange(180 * _LUT_PER_DEG + 1) / _LUT_PER_DEG
    return np.clip(np.searchsorted(grid, edges, side="right") - 1, 0, max(grid.size - 2, 0)).astype(np.int64)


def distance_table(card: HemisphereCard, d_lo: float, d_hi: float, n: int = N_DISTANCES
                   ) -> tuple[np.ndarray, float, float]:
    """Nodes' A-weighted levels at ``n`` distances log-spaced over ``[d_lo, d_hi]``: ``(nodes, n)``, ``ln d_lo``, step."""
    u0, u1 = math.log(d_lo), math.log(max(d_hi, d_lo * 1.001))
    du = (u1 - u0) / (n - 1)
    d = np.exp(u0 + du * np.arange(n))
    nodes = card.phi_deg.size * card.theta_deg.size
    tab = np.empty((nodes, n))
    for k0 in range(0, n, 64):
        lv = card.node_levels(d[k0:k0 + 64])
        tab[:, k0:k0 + lv.shape[0]] = lv.reshape(lv.shape[0], nodes).T
    return tab, u0, du


if numba is not None:
    @_kernels.jit(inline="always")
    def _locate(grid: np.ndarray, off: int, n: int, lut: np.ndarray, loff: int, a: float) -> tuple[int, float]:
        if n == 1:
            return 0, 0.0
        if a <= grid[off]:
            return 0, 0.0
        if a >= grid[off + n - 1]:
            return n - 2, 1.0
        i = lut[loff + int((a + 90.0) * _LUT_PER_DEG)]
        while i < n - 2 and grid[off + i + 1] <= a:
            i += 1
        g0 = grid[off + i]
        return i, (a - g0) / (grid[off + i + 1] - g0)

    @_kernels.jit(nogil=True, error_model="numpy")
    def _hemi_kernel(rcv, src, R, kind, gain, coef, w, dmin2,
                     phig, phio, phin, thg, tho, thn, tab, tabo, meas, measo, u0, du, nd, plut, tlut,
                     emax, energy, efill):  # pragma: no cover - compiled
        nc = rcv.shape[0]
        ns = src.shape[0]
        rad = 180.0 / math.pi
        half_pi = 0.5 * math.pi
        for c in range(nc):
            em = 0.0
            en = 0.0
            ef = 0.0
            for s in range(ns):
                de = rcv[c, 0] - src[s, 0]
                dn = rcv[c, 1] - src[s, 1]
                du_ = rcv[c, 2] - src[s, 2]
                xb = R[s, 0, 0] * de + R[s, 0, 1] * dn + R[s, 0, 2] * du_
                yb = R[s, 1, 0] * de + R[s, 1, 1] * dn + R[s, 1, 2] * du_
                zb = R[s, 2, 0] * de + R[s, 2, 1] * dn + R[s, 2, 2] * du_
                d2 = xb * xb + yb * yb + zb * zb
                k = kind[s]
                if k < 0:
                    d2c = max(d2, coef[s, 9])
                    h = math.sqrt(xb * xb + yb * yb)
                    phi = math.atan2(yb, xb)
                    theta = math.atan2(-zb, h)
                    sp = math.sin(phi) * coef[s, 1] - math.cos(phi) * coef[s, 2]
                    st = math.sin(theta) * coef[s, 4] - math.cos(theta) * coef[s, 5]
                    lv = (gain[s] * (1.0 + coef[s, 0] * sp * (theta + half_pi)) * (1.0 + coef[s, 3] * st)
                          - coef[s, 6] * math.log2(d2c) + coef[s, 7])
                    e = math.exp(lv * _LN10_10) + coef[s, 8]
                    fw = 0.0
                else:
                    d = math.sqrt(max(d2, dmin2))
                    zc = abs(zb)
                    a = math.atan2(-xb, zc) * rad
                    b = math.atan2(yb, zc) * rad
                    ni = phin[k]
                    nj = thn[k]
                    i, wi = _locate(phig, phio[k], ni, plut, k * _NLUT, a)
                    j, wj = _locate(thg, tho[k], nj, tlut, k * _NLUT, b)
                    i1 = min(i + 1, ni - 1)
                    j1 = min(j + 1, nj - 1)
                    x = (math.log(d) - u0) / du
                    kd = min(max(int(x), 0), nd - 2)
                    fd = min(max(x - kd, 0.0), 1.0)
                    base = tabo[k]
                    lv = 0.0
                    fw = 0.0
                    for q in range(4):
                        ii = i if q < 2 else i1
                        jj = j if q % 2 == 0 else j1
                        ww = (1.0 - wi if q < 2 else wi) * (1.0 - wj if q % 2 == 0 else wj)
                        node = ii * nj + jj
                        r = base + node * nd + kd
                        lv += ww * (tab[r] * (1.0 - fd) + tab[r + 1] * fd)
                        if meas[measo[k] + node] == 0:
                            fw += ww
                    if zb < 0.0 or a < phig[phio[k]] or a > phig[phio[k] + ni - 1] \
                            or b < thg[tho[k]] or b > thg[tho[k] + nj - 1]:
                        fw = 1.0
                    e = math.exp(lv * _LN10_10)
                if e > em:
                    em = e
                en += w[s] * e
                ef += w[s] * e * fw
            emax[c] = em
            energy[c] = en
            efill[c] = ef


def _rotations(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """ENU -> body rotation matrices ``(n, 3, 3)``, columns the images of east, north, up."""
    n = yaw.size
    R = np.empty((n, 3, 3))
    for col, v in enumerate(np.eye(3)):
        xb, yb, zb = body_vector(v[0], v[1], v[2], yaw, pitch, roll)
        R[:, 0, col], R[:, 1, col], R[:, 2, col] = xb, yb, zb
    return R


def evaluate_hemisphere_fast(req: MapRequest, opts: MapOptions) -> MapResult:
    """The fast engine for card sets with hemisphere cards (module docstring); ``req`` from ``check_request``."""
    if numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")
    if req.thresholds or req.snap is not None:
        raise InputError("engine 'fast' computes LAmax, LAeq and SEL of hemisphere cards; use engine='numpy' "
                         "for time above and snapshots", field="engine")
    if opts.floor_db is not None:
        raise InputError("floor_db: the audibility floor does not apply to hemisphere cards; leave it out",
                         field="floor_db")
    traj, grid, cardset = req.traj, req.grid, req.cardset
    hr = as_float(opts.receiver_height, "receiver_height")
    cidx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    used = sorted(set(cidx_samples.tolist()))
    t_eval, state, src_sample = eval_states(traj, req.substeps)
    cidx = cidx_samples[src_sample]
    ns = t_eval.size
    w = trapezoid_weights(t_eval)

    ground = ground_on_grid(grid, [traj], dem=opts.dem, ground_h=opts.ground_h, dem_offset_m=opts.dem_offset_m)
    lon_c, lat_c = grid.centre_wgs84()
    frame = local_frame(lat_c, lon_c, ground.h0)
    src = np.ascontiguousarray(np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1))
    R = _rotations(np.radians(state["yaw"]), np.radians(state["pitch"]), np.radians(state["roll"]))
    x, y = grid.flat_centres(0, grid.n_cells)
    lon, lat = transformer(grid.crs, WGS84).transform(x, y)
    ground_flat = None if ground.heights is None else ground.heights.ravel()
    hgt = (np.full(grid.n_cells, ground.h0) if ground_flat is None else ground_flat) + hr
    valid = np.isfinite(hgt)
    hgt = np.where(valid, hgt, ground.h0 + hr)
    rcv = np.ascontiguousarray(np.stack(frame.to_enu(lat, lon, hgt), axis=-1))

    # distances the table must span
    lo_b, hi_b = rcv.min(axis=0), rcv.max(axis=0)
    far = np.sqrt(np.sum(np.maximum(np.abs(src - lo_b), np.abs(src - hi_b)) ** 2, axis=1)).max()
    dmin = float(req.min_distance_m)
    # per-instant card description
    kind = np.full(ns, -1, np.int64)
    gain = np.zeros(ns)
    coef = np.zeros((ns, 10))
    phig, phio, phin, thg, tho, thn, tabs, tabo, meas, measo = [], [], [], [], [], [], [], [], [], []
    hemi_no: dict[int, int] = {}
    u0 = du = 0.0
    off_p = off_t = off_tab = off_m = 0
    for k in used:
        card = cardset.cards[k]
        sel = cidx == k
        if isinstance(card, HemisphereCard):
            h = hemi_no.setdefault(k, len(hemi_no))
            kind[sel] = h
            d_lo = min(dmin, float(card.reference_distance_m)) * 0.999
            tab, u0, du = distance_table(card, d_lo, max(far, 2.0 * d_lo) * 1.001)
            phig.append(card.phi_deg)
            phio.append(off_p)
            phin.append(card.phi_deg.size)
            off_p += card.phi_deg.size
            thg.append(card.theta_deg)
            tho.append(off_t)
            thn.append(card.theta_deg.size)
            off_t += card.theta_deg.size
            tabs.append(tab.ravel())
            tabo.append(off_tab)
            off_tab += tab.size
            meas.append(card.measured.ravel().astype(np.uint8))
            measo.append(off_m)
            off_m += card.measured.size
        else:
            p0, p1, row = card_coefficients(card, background=opts.background, min_distance_m=dmin)
            gain[sel] = p0 + p1 * np.log10(np.asarray(state["power_w"], dtype=float)[sel] / card.reference_power_w)
            coef[sel] = row
    # all hemisphere cards share one distance grid: rebuild them on the widest span if there are several
    if len(hemi_no) > 1:
        d_lo = min(min(dmin, float(cardset.cards[k].reference_distance_m)) for k in hemi_no) * 0.999
        d_hi = max(far, 2.0 * d_lo) * 1.001
        tabs = []
        for k in hemi_no:
            tab, u0, du = distance_table(cardset.cards[k], d_lo, d_hi)  # type: ignore[arg-type]
            tabs.append(tab.ravel())

    def cat(parts: list[Any], dtype: Any) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate(parts).astype(dtype)) if parts else np.zeros(1, dtype)

    args = (src, R, kind, gain, coef, w, dmin * dmin,
            cat(phig, float), np.array(phio or [0], np.int64), np.array(phin or [1], np.int64),
            cat(thg, float), np.array(tho or [0], np.int64), np.array(thn or [1], np.int64),
            cat(tabs, float), np.array(tabo or [0], np.int64), cat(meas, np.uint8),
            np.array(measo or [0], np.int64), float(u0), float(du) or 1.0, N_DISTANCES,
            cat([_lut(g) for g in phig], np.int64), cat([_lut(g) for g in thg], np.int64))

    n = grid.n_cells
    emax, energy, efill = np.zeros(n), np.zeros(n), np.zeros(n)
    nthreads = default_threads() if opts.threads is None else max(1, int(opts.threads))
    step = max(1, min(1 << 14, -(-n // (4 * nthreads))))
    blocks = [(c0, min(c0 + step, n)) for c0 in range(0, n, step)]
    done = 0

    def run(b: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        c0, c1 = b
        m = c1 - c0
        out = np.zeros(m), np.zeros(m), np.zeros(m)
        _hemi_kernel(rcv[c0:c1], *args, *out)
        return out

    def put(b: tuple[int, int], res: tuple[np.ndarray, np.ndarray, np.ndarray]) -> None:
        nonlocal done
        emax[b[0]:b[1]], energy[b[0]:b[1]], efill[b[0]:b[1]] = res
        done += b[1] - b[0]
        if opts.progress is not None:
            opts.progress(done / n)

    def poll() -> None:
        if opts.cancel is not None and opts.cancel():
            raise Cancelled("cancelled", field="cancel")

    map_threads(run, blocks, put, nthreads, poll=poll)

    metrics = req.metrics
    bands: dict[str, np.ndarray] = {name: np.full(n, np.nan) for name in band_order(metrics, [], None, False)}
    with np.errstate(divide="ignore"):
        if "LAmax" in metrics:
            bands["LAmax"] = 10.0 * np.log10(emax)
        if "SEL" in metrics:
            bands["SEL"] = 10.0 * np.log10(energy)
        if "LAeq" in metrics:
            assert req.period is not None
            bands["LAeq"] = 10.0 * np.log10(energy / req.period)
    for a in bands.values():
        a[~valid] = np.nan
    shaped = {k: v.reshape(grid.shape) for k, v in bands.items()}
    meta = map_metadata(req, shaped, ns, hr, ground.description, opts.background, used)
    tot = float(energy[valid].sum())
    meta.update({"engine": "fast", "floor_db": None, "cells_below_floor": 0,
                 "hemisphere_filled_energy_share": float(efill[valid].sum()) / tot if tot > 0 else 0.0,
                 "hemisphere_interpolation": "bilinear in the table angles of the nodes' A-weighted levels at the "
                                             "receiver's distance (ISO 9613-1 absorption in the card's atmosphere)"})
    return MapResult(bands=shaped, grid=grid, metadata=meta)
