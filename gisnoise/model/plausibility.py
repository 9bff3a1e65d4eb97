"""The plausibility guard: a card whose levels leave the physically plausible range is never used.

A model card states a level at the reference distance (40 m) for every emission
direction and every power it is meant for.  :func:`card_problems` evaluates the card's
ansatz (the base ansatz for ``<base>+<effect>`` cards, with the effect at rest) there:

* over the whole emission sphere (azimuth -180..180 deg, polar angle -90..90 deg, 5 deg
  steps) at the reference distance,
* at the electric powers the card states it holds for (``statistics.power_range_w``,
  ``[lo, hi]`` in W), else from half to twice its reference power,

and refuses a card when

* any level lies outside :data:`LEVEL_RANGE_DB` (-20 to 160 dB(A): quieter than any
  audible UAV at 40 m, or louder than a jet engine at that distance), or is not finite;
* its covariance gives a parameter a non-finite standard deviation or a level standard
  deviation over the sphere above :data:`MAX_LEVEL_STD_DB` (20 dB: the card says
  nothing about the level).

The messages name the parameters that drive the level out of range (largest
contribution ``|dL/dp_k| |p_k|`` at the worst direction) or carry the largest
uncertainty.  The guard runs when a card is loaded (:func:`gisnoise.model.load`;
``force=True`` for inspection only), before ``fit`` writes a card, and when a map is
made (:func:`gisnoise.maps.make_map`, so the command line, the service and QGIS) and by the
evaluator itself (:func:`gisnoise.maps.evaluate_grid`, given card files or card objects).
"""

from __future__ import annotations

import pickle
import threading
from collections import OrderedDict
from typing import Any

import numpy as np

from gisnoise.errors import CardError
from gisnoise.model.effects import get_ansatz
from gisnoise.model.power_range import stated_power_range_w

__all__ = ["LEVEL_RANGE_DB", "MAX_LEVEL_STD_DB", "ImplausibleCardError", "card_problems", "check_card",
           "card_level_range", "power_range_w"]

LEVEL_RANGE_DB = (-20.0, 160.0)
"""Plausible A-weighted UAV level at the reference distance, dB(A)."""
MAX_LEVEL_STD_DB = 20.0
"""Largest plausible standard deviation of the level over the emission sphere, dB."""
DEFAULT_POWER_FACTORS = (0.5, 2.0)
"""Powers checked for a card that states no range, as factors of its reference power."""

_PHI = np.radians(np.arange(-180.0, 180.1, 5.0))
_THETA = np.radians(np.arange(-90.0, 90.1, 5.0))


class ImplausibleCardError(CardError):
    """A model card whose levels or uncertainties leave the plausible range."""


def power_range_w(card: Any) -> tuple[float, float]:
    """The electric power range (W) a card holds for: ``statistics.power_range_w`` or 0.5-2 x reference."""
    rng = stated_power_range_w(card)
    if rng is not None:
        return rng
    ref = float(card.reference_power_w)
    return ref * DEFAULT_POWER_FACTORS[0], ref * DEFAULT_POWER_FACTORS[1]


def _is_table(card: Any) -> bool:
    """A card whose source is a measured table (a hemisphere card), not an ansatz with parameters."""
    return hasattr(card, "overall_a_db") and hasattr(card, "node_levels")


def _base(card: Any) -> tuple[Any, np.ndarray, list[str], np.ndarray | None]:
    """The base ansatz, its parameter values and names, and their covariance block."""
    name = str(card.ansatz).split("+", 1)[0]
    base = get_ansatz(name)
    names = list(base.params)
    p = np.array([float(card.parameters[k]) for k in names])
    cov = None
    if card.covariance is not None:
        full = np.array(card.covariance, dtype=float)
        order = list(get_ansatz(card.ansatz).params)
        idx = [order.index(k) for k in names]
        cov = full[np.ix_(idx, idx)]
    return base, p, names, cov


def _sphere_inputs(card: Any) -> dict[str, np.ndarray]:
    lo, hi = power_range_w(card)
    p_el = np.geomspace(lo, hi, 5) / float(card.reference_power_w)
    phi, theta, pe = np.meshgrid(_PHI, _THETA, p_el, indexing="ij")
    return {"d": np.full(phi.shape, float(card.reference_distance_m)), "phi": phi, "theta": theta, "p_el": pe}


def card_level_range(card: Any) -> tuple[float, float]:
    """Lowest and highest UAV level (dB(A)) of a card at the reference distance over the emission
    sphere and its power range (see the module docstring)."""
    if _is_table(card):
        lv = np.asarray(card.overall_a_db, dtype=float)
        if not np.all(np.isfinite(lv)):
            return float("nan"), float("nan")
        return float(np.min(lv)), float(np.max(lv))
    base, p, _, _ = _base(card)
    x = _sphere_inputs(card)
    with np.errstate(all="ignore"):
        lv = base.level_uav(p, x, d_ref=float(card.reference_distance_m))
    if not np.all(np.isfinite(lv)):
        return float("nan"), float("nan")
    return float(np.min(lv)), float(np.max(lv))


def card_problems(card: Any) -> list[str]:
    """What makes a card implausible (empty when it is plausible); each message names the parameters.

    A measured table (a hemisphere card) has no parameters: its A-weighted levels at its
    reference radius must be finite and within the plausible range.
    """
    if _is_table(card):
        lo, hi = card_level_range(card)
        lo_ok, hi_ok = LEVEL_RANGE_DB
        if not (np.isfinite(lo) and lo >= lo_ok and hi <= hi_ok):
            return [f"table levels at {float(card.reference_distance_m):g} m range {lo:.4g} to {hi:.4g} dB(A), "
                    f"outside the plausible {lo_ok:g} to {hi_ok:g} dB(A)"]
        return []
    base, p, names, cov = _base(card)
    x = _sphere_inputs(card)
    bg = base.background
    with np.errstate(all="ignore"):
        lv, jac = base.level_and_jacobian(p, x, d_ref=float(card.reference_distance_m), background=False)
    out: list[str] = []
    lo_ok, hi_ok = LEVEL_RANGE_DB
    flat = np.asarray(lv).reshape(-1)
    j = None if jac is None else np.asarray(jac).reshape(flat.size, -1)
    if not np.all(np.isfinite(flat)) or flat.min() < lo_ok or flat.max() > hi_ok:
        bad = ~np.isfinite(flat) | (flat < lo_ok) | (flat > hi_ok)
        worst = int(np.flatnonzero(bad)[np.argmax(np.abs(np.nan_to_num(flat[bad], nan=1e300)))])
        culprits = names
        if j is not None and np.all(np.isfinite(j[worst])):
            with np.errstate(over="ignore"):  # parameters near the float limit: their contribution is inf
                contrib = np.abs(j[worst] * p)
            if bg is not None:
                contrib[names.index(bg)] = 0.0
            culprits = [names[k] for k in np.argsort(-contrib) if contrib[k] >= 0.5 * contrib.max()]
        lo_w, hi_w = power_range_w(card)
        out.append(f"level at {float(card.reference_distance_m):g} m over the emission sphere at "
                   f"{lo_w:g}-{hi_w:g} W ranges {np.nanmin(flat):.4g} to {np.nanmax(flat):.4g} dB(A), outside "
                   f"the plausible {lo_ok:g} to {hi_ok:g} dB(A); driven by "
                   + ", ".join(f"{k} = {float(card.parameters[k]):.4g}" for k in culprits))
    if cov is not None:
        var = np.diag(cov)
        badvar = [names[k] for k in range(len(names)) if not np.isfinite(var[k])]
        if badvar:
            out.append(f"standard deviation of {', '.join(badvar)} is not finite")
        elif j is not None and np.all(np.isfinite(j)):
            sd = np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", j, cov, j), 0.0))
            if sd.max() > MAX_LEVEL_STD_DB:
                n = int(np.argmax(sd))
                share = np.abs(j[n]) * np.sqrt(np.maximum(var, 0.0))
                culprits = [names[k] for k in np.argsort(-share) if share[k] >= 0.5 * share.max()]
                out.append(f"level standard deviation up to {sd.max():.3g} dB (limit {MAX_LEVEL_STD_DB:g} dB); "
                           "uncertain: " + ", ".join(
                               f"{k} = {float(card.parameters[k]):.4g} +- {np.sqrt(max(var[names.index(k)], 0)):.3g}"
                               for k in culprits))
    return out


_PLAUSIBLE: OrderedDict[bytes, None] = OrderedDict()
"""Contents (pickled) of cards found plausible, most recent last: a card is checked once per process."""
_PLAUSIBLE_MAX = 256
_PLAUSIBLE_LOCK = threading.Lock()


def _content_key(card: Any) -> bytes | None:
    """The card's whole content as bytes (its pickle: every field, arrays included), or None."""
    try:
        return pickle.dumps(card, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # noqa: BLE001 - a card that cannot be pickled is simply checked every time
        return None


def check_card(card: Any, *, source: str | None = None) -> None:
    """Raise :class:`ImplausibleCardError` naming the parameters when :func:`card_problems` finds any.

    The verdict depends on the card's content only; plausible contents are remembered, so a
    card mapped again (a service answering route planners, a map of many phases) is not
    checked again.
    """
    key = _content_key(card)
    if key is not None:
        with _PLAUSIBLE_LOCK:
            if key in _PLAUSIBLE:
                _PLAUSIBLE.move_to_end(key)
                return
    problems = card_problems(card)
    if not problems and key is not None:
        with _PLAUSIBLE_LOCK:
            _PLAUSIBLE[key] = None
            while len(_PLAUSIBLE) > _PLAUSIBLE_MAX:
                _PLAUSIBLE.popitem(last=False)
    if problems:
        src = source or f"model card {card.id!r}"
        raise ImplausibleCardError(f"{src}: implausible card: {'; '.join(problems)}", field="parameters")
