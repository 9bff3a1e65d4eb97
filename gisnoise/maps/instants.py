"""A flight in the fast kernel's form: the cards' coefficients and the flight's instants.

:func:`card_coefficients` turns a card of the ansatz ``paper`` or ``paper-offset`` of
:mod:`gisnoise.model.ansatz` (Eq. 8-11; the only ones the kernel implements,
:data:`FAST_ANSATZES`) into the kernel's coefficient row.  :func:`prepare_flight` forms a
trajectory's evaluation instants as the NumPy engine does (instants, substeps, trapezoid
weights, cards by phase) with the UAV's position in the receivers' local frame, the
rotation into body axes, the gain of each instant and its audibility radius.

**Audibility radius.**  With an audibility floor ``floor_db``, the radius of an instant
is the distance beyond which an upper bound of the card's level over *all* emission
angles (:func:`directivity_range`, with spreading at the distance) lies below the
floor; cells beyond it at every instant are certainly below the floor and the kernel
skips them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.acoustics import speed_of_sound
from gisnoise.flight import Trajectory
from gisnoise.geo import LocalFrame, dcm_ned_to_body
from gisnoise.maps.cardset import as_cardset
from gisnoise.maps.fast_effects import NotOnFastEngine, base_card, instant_card, instant_offsets
from gisnoise.maps.prepare import eval_states, snapshot_state, trapezoid_weights
from gisnoise.maps.receiver_terms import ReceiverTerms, instant_receiver_terms, receiver_terms
from gisnoise.maps.reference import _SampleExtras
from gisnoise.model import ModelCard, get_ansatz

__all__ = [
    "FAST_ANSATZES",
    "FlightInstants",
    "card_coefficients",
    "directivity_range",
    "prepare_flight",
    "snapshot_instant",
]

FAST_ANSATZES = ("paper", "paper-offset")
"""Ansatzes the kernel implements (:mod:`gisnoise.model.ansatz` registry names)."""

_KERNEL_ANSATZES = {name: get_ansatz(name) for name in FAST_ANSATZES}
"""The registered ansatzes the kernel's algebra reproduces (a replacement registered later is refused)."""


# --------------------------------------------------------------------------- cards


_ENU_TO_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _fast_ansatz(card: ModelCard) -> str:
    """The card's ansatz name if the kernel implements it; :class:`CardError` otherwise."""
    model = card.model
    if card.ansatz not in _KERNEL_ANSATZES or model is not _KERNEL_ANSATZES[card.ansatz]:
        raise NotOnFastEngine(f"card {card.id!r}: engine 'fast' implements the ansatzes {', '.join(FAST_ANSATZES)} of "
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
    rx : ndarray (n, 9) or None
        Coefficients of the receiver-dependent effect terms
        (:func:`~gisnoise.maps.receiver_terms.instant_receiver_terms`); None when no card has one.
    lg_power : ndarray (n,) or None
        ``log10(P_el)`` of each instant (``-inf`` without power), for the uncertainty bands
        (:mod:`gisnoise.maps.fast_uncertainty`).
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
    rx: np.ndarray | None = None
    lg_power: np.ndarray | None = None

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
                       background: bool, offset: np.ndarray | None = None, absorption: np.ndarray | None = None,
                       unbounded: np.ndarray | None = None) -> np.ndarray:
    """Distance beyond which an upper bound of the level over all emission angles is below the floor, m.

    The bound is ``g hi`` for ``g >= 0`` and ``g lo`` for ``g < 0`` with
    :func:`directivity_range`; spreading decreases with distance when ``p6 > 0`` (else
    no radius: ``inf``).  Negative: below the floor even at the near-field clamp.
    ``offset``: per-instant terms (or upper bounds of terms) added to the level (dB, effect
    extensions); ``absorption``: a further ``-absorption max(d, d_min)`` (dB per m, >= 0; the
    radius is found by bisection: the bound still decreases with distance); ``unbounded``:
    instants with a term that grows without bound with distance (no radius: ``inf``).
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
    if offset is not None:
        bound = bound + offset
    target = np.full(n, float(floor_db))
    if background:
        # 10 log10(10^(Lu/10) + 10^(p7/10)) < floor  <=>  Lu < 10 log10(10^(floor/10) - 10^(p7/10))
        with np.errstate(divide="ignore", invalid="ignore"):
            target = np.where(floor_db > p7, 10.0 * np.log10(10.0 ** (floor_db / 10.0) - 10.0 ** (p7 / 10.0)),
                              np.nan)
    with np.errstate(over="ignore", invalid="ignore"):
        dist = d_ref * 10.0 ** ((bound - target) / (20.0 * np.where(p6 > 0, p6, 1.0)))
    if absorption is not None:
        dist = _absorbed_radius(dist, bound - target, p6, d_ref, d_min, absorption)
    r = np.where(dist <= d_min, -1.0, dist * (1.0 + 1e-9) + 1e-3)
    r = np.where((p6 > 0) & np.isfinite(target), r, np.inf)
    if unbounded is not None:
        r = np.where(unbounded, np.inf, r)
    return np.where(np.isnan(r), np.inf, r)


def _absorbed_radius(dist: np.ndarray, excess: np.ndarray, p6: np.ndarray, d_ref: np.ndarray, d_min: float,
                     absorption: np.ndarray) -> np.ndarray:
    """The distance where ``excess - 20 p6 lg(d / d_ref) - absorption d`` falls to 0 (m), by bisection.

    ``dist`` is the root without absorption (an upper end: absorption >= 0 only lowers the
    level); returned is an upper end of the root within 1e-9 of it, ``dist`` where nothing to refine.
    """
    sel = (absorption > 0) & (p6 > 0) & np.isfinite(dist) & (dist > d_min)
    if not sel.any():
        return dist
    ex, pp, dr, a = excess[sel], p6[sel], d_ref[sel], absorption[sel]

    def f(d: np.ndarray) -> np.ndarray:
        return ex - 20.0 * pp * np.log10(d / dr) - a * d

    lo = np.full(ex.size, float(d_min))
    hi = dist[sel].copy()
    below = f(lo) < 0  # below the floor already at the near-field clamp
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        neg = f(mid) < 0
        hi = np.where(neg, mid, hi)
        lo = np.where(neg, lo, mid)
        if np.all(hi - lo <= 1e-9 * hi):
            break
    out = dist.copy()
    out[sel] = np.where(below, float(d_min), hi)
    return out


def _instants(t: np.ndarray, state: dict[str, np.ndarray], card_idx: np.ndarray, cards: Sequence[ModelCard],
              frame: LocalFrame, *, background: bool, min_distance_m: float, floor_db: float | None,
              source: str, receiver: bool = False, temperature_c: float = 15.0,
              velocity: Callable[[np.ndarray], np.ndarray] | None = None) -> FlightInstants:
    """The instants in the kernel's form.

    ``receiver``: cards may have receiver-dependent terms (``rx``, the speed of sound of
    ``temperature_c``; ``velocity(src)``: the UAV's ENU velocity at the instants, for
    Doppler); without it such a card is refused (:class:`NotOnFastEngine`).
    """
    n = t.size
    used = sorted(set(card_idx.tolist()))
    src = np.ascontiguousarray(np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1))
    coef = np.zeros((len(cards), 10))
    p0 = np.zeros(len(cards))
    p1 = np.zeros(len(cards))
    ref_w = np.ones(len(cards))
    raw = np.zeros((len(cards), 5))  # p2, p4, p5, p6, p7 for the audibility bound
    d_ref = np.full(len(cards), 40.0)
    ci = card_idx.astype(np.int64)
    offset: np.ndarray | None = None
    terms: list[ReceiverTerms | None] = [None] * len(cards)
    for k in used:
        c, extended = base_card(cards[k])
        p0[k], p1[k], coef[k] = card_coefficients(c, background=background, min_distance_m=min_distance_m)
        terms[k] = receiver_terms(cards[k]) if extended else None
        if terms[k] is not None and not receiver:
            raise NotOnFastEngine(f"card {cards[k].id!r}: the receiver-dependent terms of {cards[k].ansatz!r} are "
                                  "not combined with measured hemisphere cards on the fast engine; use "
                                  "engine='numpy'", field="ansatz")
        inst = instant_card(cards[k]) if extended else None  # base and per-instant effects only
        if inst is not None:  # per-instant terms of effect extensions (gisnoise.maps.fast_effects)
            sel = ci == k
            if offset is None:
                offset = np.zeros(n)
            offset[sel] = instant_offsets(inst, c, t, state, src, sel)[sel]
        pp = dict(zip(c.model.params, c.p, strict=True))
        raw[k] = (pp["p2"], pp["p4"], pp["p5"], pp["p6"], pp["p7"])
        ref_w[k] = c.reference_power_w
        d_ref[k] = c.reference_distance_m
    p_el = np.asarray(state["power_w"], dtype=float) / ref_w[ci]
    with np.errstate(divide="ignore", invalid="ignore"):  # no power: lg P_el = -inf, a silent instant
        lg_power = np.log10(p_el)
    gain = p0[ci] + p1[ci] * lg_power
    C = dcm_ned_to_body(np.radians(state["yaw"]), np.radians(state["pitch"]), np.radians(state["roll"]))
    C = np.ascontiguousarray(np.broadcast_to(C, (n, 3, 3)) @ _ENU_TO_NED)
    w = trapezoid_weights(t)
    dt = np.concatenate([[0.0], np.diff(t)])
    p2, p4, p5, p6, p7 = raw[ci].T
    rx = None
    if any(tm is not None for tm in terms):  # receiver-dependent terms (gisnoise.maps.receiver_terms)
        need_v = any(tm is not None and tm.doppler for tm in terms)
        vel = velocity(src) if (need_v and velocity is not None) else None
        it = instant_receiver_terms(terms, ci, d_ref, vel, float(speed_of_sound(temperature_c)), cards)
        offset = it.offset_db if offset is None else offset + it.offset_db
        radius = _audibility_radius(gain, p2, p4, p5, p6, p7, d_ref[ci], min_distance_m, floor_db, background,
                                    offset + it.bound_db, it.absorption_db_per_m, it.unbounded)
        rx = np.ascontiguousarray(it.rx)
    else:
        radius = _audibility_radius(gain, p2, p4, p5, p6, p7, d_ref[ci], min_distance_m, floor_db, background,
                                    offset)
    if offset is not None:  # one coefficient row per instant, its kk shifted by the term
        coef = coef[ci].copy()
        coef[:, 7] += offset
        ci = np.arange(n, dtype=np.int64)
    return FlightInstants(t=np.asarray(t, dtype=float), src=src, C=C, gain=gain, cidx=ci, coef=coef, w=w, dt=dt,
                          radius=radius, source=source, rx=rx, lg_power=lg_power)


def _gradient_velocity(t: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """The UAV velocity as the NumPy engine forms it (``np.gradient`` of the positions over the instants ``t``)."""
    def vel(src: np.ndarray) -> np.ndarray:
        return _SampleExtras(np.asarray(t, dtype=float), {}, src).vel()
    return vel


def prepare_flight(traj: Trajectory, cards: Any, frame: LocalFrame, *, substeps: int = 1, background: bool = False,
                   min_distance_m: float = 1.0, floor_db: float | None = None,
                   temperature_c: float = 15.0) -> FlightInstants:
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
    temperature_c : float
        Air temperature (C): the speed of sound of the receiver-dependent terms (Doppler,
        ground reflection).
    """
    cardset = as_cardset(cards)
    idx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    t_eval, state, src_sample = eval_states(traj, int(substeps))
    return _instants(t_eval, state, idx_samples[src_sample], cardset.cards, frame, background=background,
                     min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source, receiver=True,
                     temperature_c=temperature_c, velocity=_gradient_velocity(t_eval))


def snapshot_instant(traj: Trajectory, cards: Any, frame: LocalFrame, t_s: float, *, background: bool = False,
                     min_distance_m: float = 1.0, floor_db: float | None = None, substeps: int = 1,
                     temperature_c: float = 15.0) -> FlightInstants:
    """The single instant ``t_s`` (state interpolated as the NumPy evaluator does).

    Its UAV velocity (Doppler) is the NumPy engine's: that of the first evaluation instant
    (with ``substeps``) at or after ``t_s``.
    """
    cardset = as_cardset(cards)
    state, idx = snapshot_state(traj, cardset, t_s)

    def velocity(src: np.ndarray) -> np.ndarray:
        t_eval, st, _ = eval_states(traj, int(substeps))
        full = np.stack(frame.to_enu(st["lat"], st["lon"], st["h"]), axis=-1)
        i = int(np.clip(np.searchsorted(t_eval, float(t_s)), 0, t_eval.size - 1))
        return _gradient_velocity(t_eval)(full)[[i]]

    return _instants(np.array([float(t_s)]), state, idx, cardset.cards, frame, background=background,
                     min_distance_m=min_distance_m, floor_db=floor_db, source=traj.source, receiver=True,
                     temperature_c=temperature_c, velocity=velocity)
