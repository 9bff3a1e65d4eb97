"""Effect extensions whose term depends on the receiver, in the fast engine's form.

Four effects of :mod:`gisnoise.model.effects` read the receiver's position (input
``mic_enu``): ``atmospheric_absorption``, ``wind``, ``doppler`` and ``ground_reflection``.
On a map the NumPy engine (:mod:`gisnoise.maps.reference`) evaluates them with the
receiver as the microphone: ``mic_enu`` the receiver, ``uav_enu`` the UAV, ``vel_enu``
the UAV's velocity (``np.gradient`` of its positions over the evaluation instants),
``mic_agl`` the receiver height above ground and the speed of sound of the map's
temperature.  The fast engine's kernel (:mod:`gisnoise.maps._numba_receiver`) adds the
same closed forms per cell and instant, in float32, with ``r = receiver - UAV`` (ENU, m),
``d = |r|`` and ``d_c = max(d, d_min)``:

* absorption ``-a_abs (d_c - d_ref) / 1000``;
* wind ``(d_c / 100) (w_east r_E + w_north r_N) / max(hypot(r_E, r_N), 1)``;
* Doppler ``-q_doppler 10 lg(1 - M_r)``, ``M_r = v . r / (d c)``;
* ground reflection ``10 lg(1 + R^2 + 2 R C(2 pi f_g tau))`` with the band-averaged cosine
  ``C`` (:func:`gisnoise.model.band_cos`) and ``tau`` the delay of the path reflected by flat
  ground under the receiver (:func:`gisnoise.model.reflection_delay`), none for receivers
  lower than :data:`gisnoise.model.MIN_REFLECTION_HEIGHT_M`.

The parameters are the card's (the effects' own parameter names); the per-instant
coefficients are formed here (:func:`instant_receiver_terms`).  The tests compare the
kernel with the NumPy engine, which evaluates the model's own definition.

**Audibility floor.**  Each term is bounded over all receivers at a distance ``d``: the
Doppler term by its value at ``M_r = -+|v|/c``, the ground reflection by ``20 lg(1 + R)``
(``|C| <= 1``), absorption exactly (``a_abs >= 0`` lowers the level with distance: the radius
shrinks), wind by ``|w| d_c / 100``: a term that grows without bound with distance (wind,
negative absorption) leaves no radius, so such instants skip no cell.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.maps.fast_effects import RECEIVER_EFFECTS, NotOnFastEngine
from gisnoise.model import (
    ATMOSPHERIC_ABSORPTION,
    DOPPLER,
    GROUND_REFLECTION,
    MIN_REFLECTION_HEIGHT_M,
    WIND,
    ModelCard,
    get_effect,
)

__all__ = ["RECEIVER_EFFECTS", "RX_COLUMNS", "InstantTerms", "ReceiverTerms", "instant_receiver_terms",
           "doppler_bound_db", "ground_bound_db", "kernel_flags", "receiver_terms"]

_LIBRARY = {e.name: e for e in (ATMOSPHERIC_ABSORPTION, WIND, DOPPLER, GROUND_REFLECTION)}
assert tuple(_LIBRARY) == RECEIVER_EFFECTS

RX_COLUMNS = ("k_abs", "k_east", "k_north", "q_doppler", "mach_e", "mach_n", "mach_u", "r_ground", "k_ground")
"""Columns of the kernel's per-instant coefficients (:func:`instant_receiver_terms`): ``-K a_abs / 1000``,
``K w_east / 100``, ``K w_north / 100`` (``K = log2(10) / 10``: dB to ``log2`` of the energy), ``q_doppler``,
the UAV velocity over the speed of sound (east, north, up), ``r_ground`` and ``2 pi f_g / c``."""

_K = math.log2(10.0) / 10.0  # dB -> log2 of the energy


@dataclass(frozen=True)
class ReceiverTerms:
    """A card's receiver-dependent effect parameters (zero: the effect is absent)."""

    a_abs: float = 0.0
    w_east: float = 0.0
    w_north: float = 0.0
    q_doppler: float = 0.0
    r_ground: float = 0.0
    f_ground: float = 0.0
    effects: tuple[str, ...] = ()

    @property
    def doppler(self) -> bool:
        return "doppler" in self.effects

    @property
    def ground(self) -> bool:
        return "ground_reflection" in self.effects


def doppler_bound_db(q_doppler: float, mach: Any) -> Any:
    """The largest Doppler term ``-q 10 lg(1 - M_r)`` over every direction at the speed ``mach`` (|v| / c < 1)."""
    with np.errstate(divide="ignore"):
        return np.maximum(-10.0 * q_doppler * np.log10(1.0 - mach), -10.0 * q_doppler * np.log10(1.0 + mach))


def ground_bound_db(r_ground: float) -> float:
    """The largest ground reflection term ``10 lg(1 + R^2 + 2 R C)`` over every delay (``|C| <= 1``): ``20 lg(1 + |R|)``."""
    return 20.0 * math.log10(1.0 + abs(r_ground))


def receiver_terms(card: ModelCard) -> ReceiverTerms | None:
    """The receiver-dependent terms of ``card`` (None when its ansatz has none).

    Raises :class:`~gisnoise.maps.fast_effects.NotOnFastEngine` (field ``ansatz``) when an
    effect of that name is not the library's own (re-registered) or a ground reflection
    coefficient lies outside the effect's bounds [0, 1] (the NumPy engine maps both).
    """
    names = [e for e in card.ansatz.split("+")[1:] if e in _LIBRARY]
    if not names:
        return None
    p = {k: float(v) for k, v in card.parameters.items()}
    for name in names:
        if get_effect(name) is not _LIBRARY[name]:
            raise NotOnFastEngine(f"card {card.id!r}: effect {name!r} is not the library's own; engine 'fast' "
                                  "implements the library's receiver-dependent terms; use engine='numpy'",
                                  field="ansatz")
    r = p.get("r_ground", 0.0) if "ground_reflection" in names else 0.0
    lo, hi = GROUND_REFLECTION.bounds[0]
    if not lo <= r <= hi:
        raise NotOnFastEngine(f"card {card.id!r}: r_ground = {r:g} lies outside [{lo:g}, {hi:g}]; engine 'fast' "
                              "evaluates the ground reflection within the effect's bounds; use engine='numpy'",
                              field="ansatz")
    return ReceiverTerms(
        a_abs=p["a_abs"] if "atmospheric_absorption" in names else 0.0,
        w_east=p["w_east"] if "wind" in names else 0.0,
        w_north=p["w_north"] if "wind" in names else 0.0,
        q_doppler=p["q_doppler"] if "doppler" in names else 0.0,
        r_ground=r,
        f_ground=p["f_ground"] if "ground_reflection" in names else 0.0,
        effects=tuple(names),
    )


@dataclass(frozen=True, eq=False)
class InstantTerms:
    """Per-instant coefficients and bounds of the receiver terms (see :func:`instant_receiver_terms`)."""

    rx: np.ndarray
    offset_db: np.ndarray
    bound_db: np.ndarray
    absorption_db_per_m: np.ndarray
    unbounded: np.ndarray


def instant_receiver_terms(terms: Sequence[ReceiverTerms | None], ci: np.ndarray, d_ref: np.ndarray,
                           velocity: np.ndarray | None, c_sound: float, cards: Sequence[ModelCard]) -> InstantTerms:
    """The kernel's coefficients ``rx (n, 9)`` (:data:`RX_COLUMNS`) for the instants with card rows ``ci``.

    ``terms[k]``: card ``k``'s :func:`receiver_terms`; ``d_ref[k]`` its reference distance (m);
    ``velocity (n, 3)``: the UAV's ENU velocity at the instants (m/s; needed with Doppler);
    ``c_sound``: speed of sound, m/s.  Returns also, per instant, the constant part of the
    terms (``offset_db``: ``a_abs d_ref / 1000``), an upper bound of the remaining terms over
    all receivers (``bound_db``: Doppler and ground reflection), the absorption per metre of
    distance (``absorption_db_per_m``, ``a_abs / 1000``) and whether a term grows without
    bound with distance (``unbounded``: wind, negative absorption).

    Raises :class:`~gisnoise.errors.InputError` (field ``trajectory``) when a Doppler card
    serves an instant at which the UAV is as fast as sound (the term is undefined there).
    """
    n = ci.size
    rx = np.zeros((n, len(RX_COLUMNS)))
    offset = np.zeros(n)
    bound = np.zeros(n)
    absorb = np.zeros(n)
    unbounded = np.zeros(n, bool)
    for k, tm in enumerate(terms):
        if tm is None:
            continue
        sel = ci == k
        if not sel.any():
            continue
        a = tm.a_abs / 1000.0
        rx[sel, 0] = -a * _K
        offset[sel] = a * float(d_ref[k])
        absorb[sel] = a
        unbounded[sel] |= a < 0.0
        rx[sel, 1] = tm.w_east / 100.0 * _K
        rx[sel, 2] = tm.w_north / 100.0 * _K
        unbounded[sel] |= (tm.w_east != 0.0) | (tm.w_north != 0.0)
        if tm.doppler:
            assert velocity is not None
            m = velocity[sel] / c_sound
            speed = np.linalg.norm(m, axis=1)
            if not np.all(speed < 1.0):
                vmax = float(np.max(speed)) * c_sound
                raise InputError(f"trajectory: the UAV moves at {vmax:.4g} m/s, not below the speed of sound "
                                 f"({c_sound:.4g} m/s): the Doppler term of card {cards[k].id!r} is undefined",
                                 field="trajectory")
            q = tm.q_doppler
            rx[sel, 3] = q
            rx[sel, 4:7] = m
            bound[sel] += doppler_bound_db(q, speed)
        if tm.ground:
            rx[sel, 7] = tm.r_ground
            rx[sel, 8] = 2.0 * math.pi * tm.f_ground / c_sound
            bound[sel] += ground_bound_db(tm.r_ground)
    return InstantTerms(rx, offset, bound, absorb, unbounded)


def kernel_flags(rx: np.ndarray, receiver_height_m: float) -> int:
    """Which terms the kernel computes: bit 0 absorption, 1 wind, 2 Doppler, 3 ground reflection.

    The ground reflection only for receivers at least :data:`~gisnoise.model.MIN_REFLECTION_HEIGHT_M`
    above the ground (lower ones count as on the ground: no term, as in the model).
    """
    flags = 0
    if np.any(rx[:, 0] != 0.0):
        flags |= 1
    if np.any(rx[:, 1:3] != 0.0):
        flags |= 2
    if np.any(rx[:, 3] != 0.0):
        flags |= 4
    if np.any(rx[:, 7] != 0.0) and float(receiver_height_m) >= MIN_REFLECTION_HEIGHT_M:
        flags |= 8
    return flags
