"""Effect extensions on the fast engine: per-instant level terms from the model's own evaluation.

A card ``"<base>+<effect>[+...]"`` whose base is one of the kernel's ansatzes
(``paper``, ``paper-offset``) maps on the fast engine when each extension term depends
on the instant only (``bank_angle``: the roll angle; ``rpm``: the propeller speed) or is
one of the library's receiver-dependent terms (:data:`RECEIVER_EFFECTS`, computed per
cell by the kernel: :mod:`gisnoise.maps.receiver_terms`).  The kernel evaluates the base
and adds, per instant, the per-instant effects' term ``dL``.

``dL`` is not re-implemented here: it is the card's own ansatz
(:mod:`gisnoise.model.effects`, the definition fitting and diagnosis use) minus its base,
both evaluated by the model on the instant's inputs.  To refuse a term that depends on
the receiver (``doppler``, ``wind``, ``ground_reflection``, ``atmospheric_absorption``:
distance or direction to the receiver), the difference is taken at several receiver
geometries and must agree to :data:`INSTANT_TERM_TOL_DB`; else the card is refused with
a :class:`~gisnoise.errors.CardError` naming ``ansatz`` (the NumPy engine maps it).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from gisnoise.errors import CardError, InputError
from gisnoise.maps.reference import _BASE_INPUTS, _SampleExtras
from gisnoise.model import ModelCard, get_ansatz

__all__ = ["INSTANT_TERM_TOL_DB", "KERNEL_BASES", "RECEIVER_EFFECTS", "NotOnFastEngine", "base_card", "instant_card",
           "instant_offsets"]


class NotOnFastEngine(CardError):
    """A card the fast engine does not evaluate (field ``ansatz``); the NumPy engine does."""

KERNEL_BASES = ("paper", "paper-offset")
"""The base ansatzes the kernel implements."""

INSTANT_TERM_TOL_DB = 1e-9
"""Largest spread of an extension term over receiver geometries for it to count as per-instant, dB."""

_PROBES = ((3.0, -2.6, -1.3), (40.0, 0.4, -0.2), (750.0, 2.1, 1.1))
"""Receiver geometries ``(d m, phi rad, theta rad)`` at which the extension term is compared."""

_RECEIVER_INPUTS = ("mic_enu",)

RECEIVER_EFFECTS = ("atmospheric_absorption", "wind", "doppler", "ground_reflection")
"""The library's effects whose term depends on the receiver; the kernel computes them per cell."""


def instant_card(card: ModelCard) -> ModelCard | None:
    """``card`` without its receiver-dependent effects (:data:`RECEIVER_EFFECTS`): its base and per-instant effects.

    ``card`` itself when it has no receiver-dependent effect; None when it has no per-instant one.
    """
    base, *chain = card.ansatz.split("+")
    inst = [e for e in chain if e not in RECEIVER_EFFECTS]
    if len(inst) == len(chain):
        return card
    if not inst:
        return None
    name = "+".join([base, *inst])
    params = {k: float(card.parameters[k]) for k in get_ansatz(name).params}
    return dataclasses.replace(card, ansatz=name, parameters=params, covariance=None)


def base_card(card: ModelCard) -> tuple[ModelCard, bool]:
    """The card of the kernel's base ansatz (the base's parameters) and whether ``card`` extends it.

    Raises :class:`NotOnFastEngine` (a :class:`CardError`) (field ``ansatz``) when the base is not a kernel ansatz or an
    extension other than :data:`RECEIVER_EFFECTS` reads the receiver's position.
    """
    name = card.ansatz
    base_name = name.split("+", 1)[0]
    if base_name not in KERNEL_BASES:
        raise NotOnFastEngine(f"card {card.id!r}: engine 'fast' implements the ansatzes {', '.join(KERNEL_BASES)} of "
                        f"gisnoise.model.ansatz and their per-instant extensions, not {name!r}; use engine='numpy'",
                        field="ansatz")
    if base_name == name:
        return card, False
    inst = instant_card(card)
    receiver = [] if inst is None else [k for k in inst.model.inputs if k in _RECEIVER_INPUTS]
    if receiver:
        raise NotOnFastEngine(f"card {card.id!r}: ansatz {name!r} has a term that depends on the receiver "
                        f"({receiver[0]}) beyond the effects {', '.join(RECEIVER_EFFECTS)}; engine 'fast' adds "
                        "per-instant terms and those; use engine='numpy'", field="ansatz")
    base = get_ansatz(base_name)
    params = {k: float(card.parameters[k]) for k in base.params}
    return dataclasses.replace(card, ansatz=base_name, parameters=params, covariance=None), True


def instant_offsets(card: ModelCard, base: ModelCard, t: np.ndarray, state: Mapping[str, np.ndarray],
                    src_enu: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """Per-instant term ``L_UAV(card) - L_UAV(base)`` (dB) at the instants ``t`` with flight ``state``.

    ``src_enu``: the UAV's positions (m); ``where``: the instants the card serves (default
    all), where the term is checked.

    Raises :class:`NotOnFastEngine` (field ``ansatz``) when the term changes with the
    receiver's geometry, :class:`InputError` naming the input when the trajectory lacks one the card reads.
    """
    n = np.asarray(t).size
    extras = _SampleExtras(np.asarray(t, dtype=float), state, src_enu)
    x_extra: dict[str, np.ndarray] = {}
    for name in card.model.inputs:
        if name in _BASE_INPUTS or name == "meta":
            continue
        v = extras.get(name)
        if v is None:
            raise InputError(f"card {card.id!r} (ansatz {card.ansatz!r}) needs input {name!r}, "
                             "which the trajectory does not provide", field=name)
        x_extra[name] = np.asarray(v, dtype=float)
    power = np.asarray(state["power_w"], dtype=float)
    diffs = []
    for d, phi, theta in _PROBES:
        x = card.inputs(np.full(n, d), np.full(n, phi), np.full(n, theta), power, **x_extra)
        with np.errstate(all="ignore"):
            diffs.append(np.broadcast_to(card.level_uav(x) - base.level_uav(x), (n,)).astype(float))
    sel = np.ones(n, bool) if where is None else np.asarray(where, bool)
    spread = max(float(np.max(np.abs(dl - diffs[0])[sel], initial=0.0)) for dl in diffs)
    if not np.isfinite(diffs[0][sel]).all() or not spread <= INSTANT_TERM_TOL_DB:
        raise NotOnFastEngine(f"card {card.id!r}: the extension term of {card.ansatz!r} depends on the receiver's "
                        f"geometry (spread {spread:.3g} dB) or is not finite on this flight; engine 'fast' adds "
                        "per-instant terms only; use engine='numpy'", field="ansatz")
    return diffs[0]
