"""The NumPy engine: the reference evaluator, vectorised over blocks of cells x instants.

For every receiver and every evaluation instant the level ``L_UAV`` is computed by the
card's ansatz (:mod:`gisnoise.model.ansatz`: one model definition for evaluation,
fitting and diagnosis), any ansatz including the extensions of :mod:`gisnoise.model.effects`.
The work runs in blocks of cells x instants whose size is bounded (``block_size``
cell-instants), so memory stays bounded for any grid and trajectory length.  The
per-block physics is the pure function :func:`_levels_chunk`, which a faster kernel can
replace (``kernel=``) and be compared against.

Uncertainty (``uncertainty=True``) propagates the cards' parameter covariance by
the delta method through the ansatz's analytic Jacobian:

* ``LAeq_std``: ``sqrt(g^T C g)`` with ``g = sum_i w_i 10^(L_i/10) dL_i/dp / sum_i
  w_i 10^(L_i/10)`` (energy-weighted mean Jacobian; ``w_i`` trapezoid weights);
  the same for ``SEL``, which differs from LAeq by a constant;
* ``LAmax_std``: ``sqrt(J^T C J)`` with ``J = dL/dp`` at the instant of the maximum; where
  instants tie for it (a circle's centre, symmetric passes), the largest of
  ``tie_std(sqrt(J_i^T C J_i), LAmax - L_i)`` over the instants ``i`` less than
  ``TIE_DB`` = 0.1 dB below LAmax (:func:`~gisnoise.maps.prepare.tie_std`: the largest of the
  tied instants' standard deviations; conservative, well defined, the same on the fast engine);
* ``LAmax_p95``, ``LAeq_p95``: ``L - 1.645 std``, the level that the true level
  exceeds with 95 % probability (one-sided, normal approximation of the linearised
  model).  Its contour bounds the area where the level is reached with 95 % confidence.

Parameters of different cards are independent (block-diagonal covariance); a card
that serves several phases is one block.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.acoustics import speed_of_sound
from gisnoise.errors import Cancelled, GisnoiseError, InputError
from gisnoise.geo import WGS84, emission_angles, transformer
from gisnoise.maps._checks import as_float
from gisnoise.maps.hemifill import filled_weights, has_hemisphere, hemisphere_atmospheres
from gisnoise.maps.prepare import (
    TIE_DB,
    UNCERTAINTY_NOTE,
    Z95,
    MapOptions,
    band_order,
    check_request,
    eval_states,
    ground_on_grid,
    local_frame,
    map_metadata,
    require_covariances,
    snapshot_state,
    tie_std,
    trapezoid_weights,
)
from gisnoise.maps.result import MapResult, snapshot_name, threshold_name
from gisnoise.model import ModelCard

__all__ = ["DEFAULT_BLOCK", "evaluate_numpy"]


DEFAULT_BLOCK = 1 << 18
"""Default cell-instants per block (about 2 MB per float64 temporary)."""

_BASE_INPUTS = ("d", "phi", "theta", "p_el")


def _time_above(L: np.ndarray, dt: np.ndarray, thr: float) -> np.ndarray:
    """Time (s) with ``L > thr``, ``L`` linear between columns; ``L (nc, m)``, ``dt (m-1,)``."""
    a = L[:, :-1] - thr
    b = L[:, 1:] - thr
    up_a = a >= 0
    up_b = b >= 0
    mixed = up_a != up_b
    denom = np.where(mixed, np.abs(a - b), 1.0)
    frac = np.where(up_a & up_b, 1.0, np.where(mixed, np.maximum(a, b) / denom, 0.0))
    return frac @ dt


def _tie_std(L: np.ndarray, J: np.ndarray, top: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Per cell the largest :func:`~gisnoise.maps.prepare.tie_std` over the instants less than ``TIE_DB`` below
    ``top`` (``-inf``: none).

    ``L (nc, m)`` levels, ``J (nc, m, n_jac)`` their Jacobians, ``top (nc,)`` the level the
    instants are measured from, ``cov (n_jac, n_jac)``; silent instants (``L = -inf``) are none.
    """
    with np.errstate(invalid="ignore"):  # (-inf - -inf: a cell without sound)
        below = top[:, None] - L
    rows, cols = np.nonzero((below < TIE_DB) & np.isfinite(L))
    jc = J[rows, cols]
    std = np.sqrt(np.maximum(np.einsum("kp,pq,kq->k", jc, cov, jc), 0.0))
    out = np.full(L.shape[0], -np.inf)
    np.maximum.at(out, rows, tie_std(std, below[rows, cols]))
    return out


def _redo_ties(levels_at: Callable[[np.ndarray, slice], tuple[np.ndarray, np.ndarray | None]], rcv: np.ndarray,
               top: np.ndarray, cov: np.ndarray, ns: int, ns_chunk: int,
               cancel: Callable[[], bool] | None) -> np.ndarray:
    """:func:`_tie_std` of receivers ``rcv`` whose LAmax ``top`` is known, over all ``ns`` instants again."""
    out = np.full(top.shape, -np.inf)
    for s0 in range(0, ns, ns_chunk):
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")
        L, J = levels_at(rcv, slice(s0, min(s0 + ns_chunk, ns)))
        assert J is not None
        out = np.maximum(out, _tie_std(L, J, top, cov))
    return out


class _SampleExtras:
    """Per-instant inputs beyond ``d, phi, theta, p_el`` that extended ansatzes read.

    Names and units as :meth:`gisnoise.measure.samples.Samples.inputs`: ``bank`` (rad),
    ``speed`` (ground speed, m/s), ``rpm`` (1/min), ``airspeed`` (m/s), ``roll``,
    ``pitch``, ``yaw`` (deg), ``t_e`` (s), ``uav_enu`` and ``vel_enu`` (m, m/s,
    trailing axis 3), ``mic_enu`` (receiver, m, trailing axis 3), ``meta`` (dict).
    Per-instant arrays are passed with shape ``(1, n)`` (vectors ``(1, n, 3)``) and
    receiver arrays ``(nc, 1, 3)`` so they broadcast against ``d``.
    """

    def __init__(self, t: np.ndarray, state: Mapping[str, np.ndarray], src_enu: np.ndarray) -> None:
        self.t = t
        self.state = state
        self.src = src_enu
        self._vel: np.ndarray | None = None

    def vel(self) -> np.ndarray:
        if self._vel is None:
            if self.t.size > 1:
                self._vel = np.gradient(self.src, self.t, axis=0)
            else:
                self._vel = np.zeros_like(self.src)
        return self._vel

    def get(self, name: str) -> np.ndarray | None:
        s = self.state
        if name == "bank":
            return np.radians(s["roll"])
        if name in ("roll", "pitch", "yaw"):
            return np.asarray(s[name])
        if name == "speed":
            return np.linalg.norm(self.vel(), axis=1)
        if name == "vel_enu":
            return self.vel()
        if name == "uav_enu":
            return self.src
        if name in ("t_e", "t"):
            return self.t
        if name == "rpm":
            return s.get("rpm")
        if name == "airspeed":
            return s.get("airspeed_m_s")
        return None


def _needed_extras(cards: Sequence[ModelCard], extras: _SampleExtras, used: Iterable[int]) -> tuple[dict, list]:
    sample: dict[str, np.ndarray] = {}
    receiver: list[str] = []
    for k in used:
        c = cards[k]
        for name in c.model.inputs:
            if name in _BASE_INPUTS or name in sample or name in receiver:
                continue
            if name == "mic_enu":
                receiver.append(name)
                continue
            if name == "meta":
                continue
            v = extras.get(name)
            if v is None:
                raise InputError(f"card {c.id!r} (ansatz {c.ansatz!r}) needs input {name!r}, "
                                 "which the trajectory does not provide", field=name)
            sample[name] = np.asarray(v, dtype=float)
    return sample, receiver


# --------------------------------------------------------------------------- the per-block kernel


def _levels_chunk(
    rcv: np.ndarray,
    src: np.ndarray,
    att: np.ndarray,
    power_w: np.ndarray,
    card_idx: np.ndarray,
    cards: Sequence[ModelCard],
    *,
    background: bool = False,
    sample_extras: Mapping[str, np.ndarray] | None = None,
    receiver_extras: Sequence[str] = (),
    jac_offsets: Sequence[int] | None = None,
    n_jac: int = 0,
    min_distance_m: float = 1.0,
    receiver_agl_m: float = 1.5,
    meta: Mapping[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Levels of ``nc`` receivers x ``ns`` instants: the evaluator's physics, pure.

    Parameters
    ----------
    rcv : ndarray, shape (nc, 3)
        Receiver positions, local ENU, m.
    src : ndarray, shape (ns, 3)
        UAV positions, same frame, m.
    att : ndarray, shape (ns, 3)
        UAV yaw, pitch, roll, rad (Z-Y-X).
    power_w : ndarray, shape (ns,)
        Electric power, W.
    card_idx : ndarray of int, shape (ns,)
        Index into ``cards`` of each instant's card.
    cards : sequence of ModelCard
    background : bool
        Add each card's background level (Eq. 8).
    sample_extras : dict, optional
        Further per-instant inputs (arrays with leading axis ``ns``).
    receiver_extras : sequence of str
        Names of receiver inputs to pass (only ``mic_enu``: ``rcv``).
    jac_offsets : sequence of int, optional
        When given, also return ``J (nc, ns, n_jac)`` with card ``k``'s
        ``dL/dp`` in columns ``jac_offsets[k]:jac_offsets[k] + n_params``, zero elsewhere.
    n_jac : int
        Total Jacobian columns.
    min_distance_m : float
        Distances are clamped to at least this (the point-source model's near-field limit), m.
    receiver_agl_m : float
        Receiver height above ground (input ``mic_agl`` of extensions such as ground reflection), m.
    meta : dict, optional
        Facts for extensions (``speed_of_sound_m_s``), passed as input ``meta``.

    Returns
    -------
    L : ndarray, shape (nc, ns)
        Level, dB(A).
    J : ndarray, shape (nc, ns, n_jac), or None
    """
    de = rcv[:, 0, None] - src[None, :, 0]
    dn = rcv[:, 1, None] - src[None, :, 1]
    du = rcv[:, 2, None] - src[None, :, 2]
    d, phi, theta = emission_angles(de, dn, du, att[:, 0], att[:, 1], att[:, 2])
    del de, dn, du
    np.maximum(d, min_distance_m, out=d)
    nc, ns = d.shape
    L = np.empty((nc, ns))
    J = np.zeros((nc, ns, n_jac)) if jac_offsets is not None else None
    sample_extras = sample_extras or {}
    ks = np.unique(card_idx)
    for k in ks:
        card = cards[int(k)]
        sel: Any = slice(None) if ks.size == 1 else np.flatnonzero(card_idx == k)
        x = card.inputs(d[:, sel], phi[:, sel], theta[:, sel], power_w[None, sel])
        for name, v in sample_extras.items():
            x[name] = v[None, sel]
        for name in receiver_extras:
            x[name] = rcv[:, None, :]
        x["mic_agl"] = receiver_agl_m
        x["meta"] = dict(meta or {})
        try:
            if J is None:
                L[:, sel] = card.level(x, background=background)
                continue
            lv, jk = card.model.level_and_jacobian(card.p, x, background=background,
                                                   d_ref=card.reference_distance_m)
        except (ValueError, IndexError, KeyError, TypeError) as exc:
            if isinstance(exc, GisnoiseError):
                raise
            raise InputError(f"card {card.id!r}: ansatz {card.ansatz!r} cannot be evaluated on a map "
                             f"({type(exc).__name__}: {exc})", field="ansatz") from None
        assert jac_offsets is not None
        L[:, sel] = lv
        o = jac_offsets[int(k)]
        if ks.size == 1:
            J[:, :, o:o + jk.shape[-1]] = jk
        else:
            J[:, sel, o:o + jk.shape[-1]] = jk
    return L, J


# --------------------------------------------------------------------------- the engine


def evaluate_numpy(traj: Any, cards: Any, grid: Any, opts: MapOptions) -> MapResult:
    """The NumPy engine behind :func:`~gisnoise.maps.evaluate.evaluate_grid` (``engine="numpy"``)."""
    if opts.floor_db is not None:
        raise InputError("floor_db: the audibility floor is an option of engine='fast'", field="floor_db")
    if opts.threads is not None:
        raise InputError("threads: kernel threads are an option of engine='fast'", field="threads")
    req = check_request(traj, cards, grid, opts)
    traj, grid, cardset, metrics, thresholds = req.traj, req.grid, req.cardset, req.metrics, req.thresholds
    hr = as_float(opts.receiver_height, "receiver_height")
    temp = as_float(opts.temperature_c, "temperature_c", minimum=-273.15, strict=True)
    c_sound = float(speed_of_sound(temp))
    block = int(opts.block_size)
    if block < 1:
        raise InputError(f"block_size must be >= 1, got {opts.block_size!r}", field="block_size")
    uncertainty, progress, cancel = opts.uncertainty, opts.progress, opts.cancel
    integral, period, snap = req.integral, req.period, req.snap

    card_idx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    used = sorted(set(card_idx_samples.tolist()))
    t_eval, state, src_sample = eval_states(traj, req.substeps)
    card_idx = card_idx_samples[src_sample]
    ns = t_eval.size
    weights = trapezoid_weights(t_eval)

    # jacobian layout: one block of columns per card (cards are independent)
    want_jac = bool(uncertainty) and bool({"LAmax", "LAeq", "SEL"} & set(metrics))
    offsets: list[int] = []
    n_jac = 0
    cov = np.zeros((0, 0))
    if uncertainty:
        for c in cardset.cards:
            offsets.append(n_jac)
            n_jac += c.model.n_params
        cov = np.zeros((n_jac, n_jac))
        require_covariances([cardset.cards[k] for k in used])
        for k in used:
            c = cardset.cards[k]
            o = offsets[k]
            cov[o:o + c.model.n_params, o:o + c.model.n_params] = c.cov

    # ground and frame
    ground = ground_on_grid(grid, dem=opts.dem, ground_h=req.ground, dem_offset_m=opts.dem_offset_m)
    h0 = ground.h0
    lon_c, lat_c = grid.centre_wgs84()
    frame = local_frame(lat_c, lon_c, h0)
    src_enu = np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1)
    att = np.stack([np.radians(state["yaw"]), np.radians(state["pitch"]), np.radians(state["roll"])], axis=-1)
    power = np.asarray(state["power_w"], dtype=float)
    extras = _SampleExtras(t_eval, state, src_enu)
    sample_extras, receiver_extras = _needed_extras(cardset.cards, extras, used)

    snap_args = None
    if snap is not None:
        s_state, s_idx = snapshot_state(traj, cardset, snap)
        s_src = np.stack(frame.to_enu(s_state["lat"], s_state["lon"], s_state["h"]), axis=-1)
        s_att = np.stack([np.radians(s_state["yaw"]), np.radians(s_state["pitch"]),
                          np.radians(s_state["roll"])], axis=-1)
        s_extras = _SampleExtras(np.array([snap]), s_state, s_src)
        s_extras._vel = extras.vel()[[int(np.clip(np.searchsorted(t_eval, snap), 0, ns - 1))]]
        s_sample_extras, _ = _needed_extras(cardset.cards, s_extras, sorted(set(s_idx.tolist())))
        snap_args = (s_src, s_att, np.asarray(s_state["power_w"], dtype=float), s_idx, s_sample_extras)

    # blocks
    per_elem = 1 + (n_jac if want_jac else 0)
    budget = max(1, block // per_elem)
    chunk_cells = opts.chunk_cells
    if chunk_cells is not None:
        if isinstance(chunk_cells, bool) or int(chunk_cells) < 1:
            raise InputError(f"chunk_cells must be >= 1, got {chunk_cells!r}", field="chunk_cells")
        nc_chunk = int(chunk_cells)
        ns_chunk = max(1, min(ns, budget // nc_chunk))
    else:
        ns_chunk = max(2, min(ns, budget // 64))
        nc_chunk = max(1, budget // ns_chunk)
    n_cells = grid.n_cells
    nc_chunk = min(nc_chunk, n_cells)
    total_work = float(n_cells) * (ns + (1 if snap is not None else 0))

    out = {name: np.full(n_cells, np.nan) for name in band_order(metrics, thresholds, snap, uncertainty)}
    levels_fn = _levels_chunk if opts.kernel is None else opts.kernel
    to_wgs = transformer(grid.crs, WGS84)
    ground_flat = None if ground.heights is None else ground.heights.ravel()
    done = 0.0
    hemi = has_hemisphere(cardset.cards) and integral  # energy share of filled hemisphere nodes
    e_fill = e_all = 0.0
    kw: dict[str, Any] = dict(background=opts.background, receiver_extras=receiver_extras,
                              min_distance_m=req.min_distance_m, receiver_agl_m=hr,
                              meta={"speed_of_sound_m_s": c_sound, "temperature_c": temp})

    def levels_at(rcv: np.ndarray, sl: slice) -> tuple[np.ndarray, np.ndarray | None]:
        """Levels (and Jacobians) of receivers ``rcv`` at the instants ``sl``."""
        return levels_fn(rcv, src_enu[sl], att[sl], power[sl], card_idx[sl], cardset.cards,
                         sample_extras={k: v[sl] for k, v in sample_extras.items()},
                         jac_offsets=offsets if want_jac else None, n_jac=n_jac, **kw)

    for c0 in range(0, n_cells, nc_chunk):
        c1 = min(c0 + nc_chunk, n_cells)
        nc = c1 - c0
        x, y = grid.flat_centres(c0, c1)
        lon, lat = to_wgs.transform(x, y)
        hgt = (np.full(nc, h0) if ground_flat is None else ground_flat[c0:c1]) + hr
        valid = np.isfinite(hgt)
        hgt = np.where(valid, hgt, h0 + hr)
        rcv = np.stack(frame.to_enu(lat, lon, hgt), axis=-1)

        lmax = np.full(nc, -np.inf)
        # LAmax_std: the largest tie_std of the instants within TIE_DB of the running maximum; a cell whose maximum
        # rises by less than TIE_DB from one block of instants to the next (their tie_std changes): redone
        smax = np.full(nc, -np.inf) if want_jac and "LAmax" in metrics else None
        redo = np.zeros(nc, bool)
        energy = np.zeros(nc)
        gsum = np.zeros((nc, n_jac)) if want_jac else None
        tabove = [np.zeros(nc) for _ in thresholds]
        for s0 in range(0, ns, ns_chunk):
            if cancel is not None and cancel():
                raise Cancelled("cancelled", field="cancel")
            s1 = min(s0 + ns_chunk, ns)
            e1 = min(s1 + 1, ns)  # one more instant for the intervals
            sl = slice(s0, e1)
            L, J = levels_at(rcv, sl)
            m = s1 - s0
            Lm = L[:, :m]
            if "LAmax" in metrics:
                top = np.maximum(lmax, Lm.max(axis=1))
                if smax is not None and J is not None:
                    drop = top - TIE_DB >= lmax  # every earlier instant falls out of the new maximum's band
                    redo |= ~drop & (top > lmax)
                    smax = np.maximum(np.where(drop, -np.inf, smax), _tie_std(Lm, J[:, :m], top, cov))
                lmax = top
            if integral:
                e = np.power(10.0, Lm / 10.0)
                ew = e * weights[s0:s1]
                energy += ew.sum(axis=1)
                if gsum is not None and J is not None:
                    # a silent instant (no power: L = -inf) adds nothing, though its dL/dp1 is -inf
                    gsum += np.einsum("cs,csp->cp", ew, np.where(ew[..., None] > 0, J[:, :m, :], 0.0))
                if hemi:
                    fw = filled_weights(rcv, src_enu[s0:s1], att[s0:s1], card_idx[s0:s1], cardset.cards)
                    e_fill += float(np.sum(ew[valid] * fw[valid]))
                    e_all += float(np.sum(ew[valid]))
                if thresholds and L.shape[1] > 1:
                    dt = np.diff(t_eval[s0:e1])
                    for i, thr in enumerate(thresholds):
                        tabove[i] += _time_above(L, dt, thr)
            done += nc * m
            if progress is not None:
                progress(min(done / total_work, 1.0))

        sl_c = slice(c0, c1)
        if "LAmax" in metrics:
            out["LAmax"][sl_c] = lmax
        if "SEL" in metrics:
            out["SEL"][sl_c] = 10.0 * np.log10(energy)
        if "LAeq" in metrics:
            assert period is not None
            out["LAeq"][sl_c] = 10.0 * np.log10(energy / period)
        for i, thr in enumerate(thresholds):
            out[threshold_name(thr)][sl_c] = tabove[i]
        if snap_args is not None:
            s_src, s_att, s_pow, s_idx, s_sx = snap_args
            Ls, _ = levels_fn(rcv, s_src, s_att, s_pow, s_idx, cardset.cards, sample_extras=s_sx, **kw)
            out[snapshot_name(snap)][sl_c] = Ls[:, 0]  # type: ignore[arg-type]
            done += nc
            if progress is not None:
                progress(min(done / total_work, 1.0))
        if uncertainty:
            if smax is not None:
                if redo.any():
                    smax[redo] = _redo_ties(levels_at, rcv[redo], lmax[redo], cov, ns,
                                            max(1, budget // int(redo.sum())), cancel)
                s = np.maximum(smax, 0.0)  # (no audible instant, LAmax -inf: 0)
                out["LAmax_std"][sl_c] = s
                out["LAmax_p95"][sl_c] = lmax - Z95 * s
            if ("LAeq" in metrics or "SEL" in metrics) and gsum is not None:
                g = gsum / energy[:, None]
                s = np.sqrt(np.maximum(np.einsum("cp,pq,cq->c", g, cov, g), 0.0))
                if "LAeq" in metrics:
                    out["LAeq_std"][sl_c] = s
                    out["LAeq_p95"][sl_c] = out["LAeq"][sl_c] - Z95 * s
                if "SEL" in metrics:
                    out["SEL_std"][sl_c] = s
        if not valid.all():
            for a in out.values():
                a[sl_c][~valid] = np.nan

    bands = {k: v.reshape(grid.shape) for k, v in out.items()}
    meta = map_metadata(req, bands, ns, hr, ground.description, opts.background, used, speed_of_sound_m_s=c_sound)
    if hemi:
        meta["hemisphere_filled_energy_share"] = e_fill / e_all if e_all > 0 else 0.0
    if has_hemisphere(cardset.cards):
        meta["hemisphere_atmospheres"] = hemisphere_atmospheres([cardset.cards[k] for k in used])
    if uncertainty:
        meta["uncertainty"] = UNCERTAINTY_NOTE
    return MapResult(bands=bands, grid=grid, metadata=meta)
