"""The plausibility guard: a card whose levels leave the physically plausible range is never used.

A model card states its level at its reference distance for every emission direction and
every power it is meant for.  :func:`card_problems` judges it by two rules.

**The reference distance** (``reference_distance_m``) must lie in
:data:`REFERENCE_DISTANCE_RANGE_M`, 1 m to 1 km.  It is where the card's level is stated,
so it must be a distance at which a level says something about the source: no sound power
measurement puts its microphones nearer than 1 m (ISO 3744's smallest hemisphere radius, the
radius measured UAV hemispheres are back-propagated to), and nearer than that a UAV's rotors
are no point source; farther than 1 km the level is decided by absorption, ground and weather
rather than by the source (ISO 9613-2 states its accuracy up to 1 km).  Outside this range the
card is refused naming ``reference_distance_m`` alone: its levels anywhere else follow from a
level stated where none can be measured (a card stated at 1e-9 m maps at -150 dB(A)).

**The level at 40 m** (:data:`RULE_DISTANCE_M`, the paper's and the specification's reference
distance; the distance :data:`LEVEL_RANGE_DB` is stated for) is evaluated from the card's
ansatz (the base ansatz for ``<base>+<effect>`` cards, with the effect at rest) with its own
reference distance and spreading, whatever that distance is:

* over the whole emission sphere (azimuth -180..180 deg, polar angle -90..90 deg, 5 deg
  steps),
* at the electric powers the card states it holds for (``statistics.power_range_w``,
  ``[lo, hi]`` in W), else from half to twice its reference power,

and the card is refused when

* any level lies outside :data:`LEVEL_RANGE_DB` (-20 to 160 dB(A): quieter than any
  audible UAV at 40 m, or louder than a jet engine at that distance), or is not finite;
* its level at twice that distance (80 m) is not below its level at 40 m in some direction and
  power: a point source's sound spreads, so its level falls with distance (6 dB per doubling
  in free field; a card with spreading ``p6 <= 0`` is as loud or louder far away and would put
  its loudest levels at the edge of every map);
* its covariance gives a parameter a non-finite standard deviation or a level standard
  deviation over the sphere above :data:`MAX_LEVEL_STD_DB` (20 dB: the card says
  nothing about the level).

The messages name the parameters that drive the level out of range (largest
contribution ``|dL/dp_k| |p_k|`` at the worst direction) or carry the largest
uncertainty; the error's ``field`` is ``parameters``.  A measured table (a hemisphere card)
has no parameters: its A-weighted node levels at 40 m (spherical spreading and absorption
from its radius, as the map computes them) must lie in the range, else it is refused naming
its table, ``levels_db``.  The guard runs when a card is loaded (:func:`gisnoise.model.load`,
either kind; ``force=True`` for inspection only), before ``fit`` writes a card, and when a
map is made (:func:`gisnoise.maps.make_map`, so the command line, the service and QGIS) and by
the evaluator itself (:func:`gisnoise.maps.evaluate_grid`, given card files or card objects).
"""

from __future__ import annotations

import pickle
import threading
from collections import OrderedDict
from typing import Any

import numpy as np

from gisnoise.errors import CardError
from gisnoise.model.ansatz import REFERENCE_DISTANCE_M
from gisnoise.model.effects import get_ansatz
from gisnoise.model.power_range import stated_power_range_w

__all__ = ["LEVEL_RANGE_DB", "MAX_LEVEL_STD_DB", "REFERENCE_DISTANCE_RANGE_M", "RULE_DISTANCE_M",
           "ImplausibleCardError", "card_problems", "check_card", "card_level_range", "power_range_w"]

LEVEL_RANGE_DB = (-20.0, 160.0)
"""Plausible A-weighted UAV level at :data:`RULE_DISTANCE_M` (40 m), dB(A)."""
RULE_DISTANCE_M = REFERENCE_DISTANCE_M
"""Distance (m) at which the level must lie in :data:`LEVEL_RANGE_DB`: 40 m, whatever the card's reference distance."""
REFERENCE_DISTANCE_RANGE_M = (1.0, 1000.0)
"""Plausible reference distance of a card (the radius of a hemisphere), m (see the module docstring)."""
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
    """The emission sphere at :data:`RULE_DISTANCE_M` and the card's powers (module docstring)."""
    lo, hi = power_range_w(card)
    p_el = np.geomspace(lo, hi, 5) / float(card.reference_power_w)
    phi, theta, pe = np.meshgrid(_PHI, _THETA, p_el, indexing="ij")
    return {"d": np.full(phi.shape, RULE_DISTANCE_M), "phi": phi, "theta": theta, "p_el": pe}


def _table_levels(card: Any) -> np.ndarray:
    """A hemisphere card's A-weighted node levels at :data:`RULE_DISTANCE_M`, dB(A) (NaN where not finite)."""
    with np.errstate(all="ignore"):
        return np.asarray(card.node_levels(RULE_DISTANCE_M), dtype=float)


def card_level_range(card: Any) -> tuple[float, float]:
    """Lowest and highest UAV level (dB(A)) of a card at :data:`RULE_DISTANCE_M` (40 m) over the emission
    sphere and its power range (a hemisphere card: over its nodes); NaN when a level is not finite."""
    if _is_table(card):
        lv = _table_levels(card)
    else:
        base, p, _, _ = _base(card)
        x = _sphere_inputs(card)
        with np.errstate(all="ignore"):
            lv = base.level_uav(p, x, d_ref=float(card.reference_distance_m))
    if not np.all(np.isfinite(lv)):
        return float("nan"), float("nan")
    return float(np.min(lv)), float(np.max(lv))


def _reference_distance_problem(card: Any) -> str | None:
    lo, hi = REFERENCE_DISTANCE_RANGE_M
    r = float(card.reference_distance_m)
    if lo <= r <= hi:
        return None
    what = "the radius of its table" if _is_table(card) else "where its levels are stated"
    return (f"reference_distance_m = {r:g} m ({what}) lies outside the plausible {lo:g} to {hi:g} m: no source "
            f"level is measured nearer than {lo:g} m, none farther than {hi:g} m is the source's alone")


PHASE_ANGLES = ("p3", "p5")
"""The directivity's phase angles (rad, Eq. 9): ``sin(phi - p3)``, ``sin(theta - p5)``.  A fit puts them within
+-pi/2 (flipping the sign of ``p2``, ``p4``); beyond +-pi they are given in degrees (Table 1's -0.28 and 1.049 rad
are -16 and 60.1 deg), which ``sin`` would take silently for other directions."""


def _phase_angle_problem(card: Any, names: list[str]) -> str | None:
    """The message for a phase angle beyond +-pi (given in degrees), or None."""
    for k in PHASE_ANGLES:
        if k in names:
            v = float(card.parameters[k])
            if np.isfinite(v) and abs(v) > np.pi:
                return (f"{k} = {v:.4g} is no angle in radians (within +-pi; a fit gives +-pi/2): given in degrees? "
                        f"{v:.4g} deg is {np.radians(v):.4g} rad")
    return None


def _problems(card: Any) -> list[tuple[str, str]]:
    """``(field, message)`` of every problem :func:`card_problems` finds."""
    bad_ref = _reference_distance_problem(card)
    if bad_ref is not None:  # the levels follow from it: nothing else to say
        return [("reference_distance_m", bad_ref)]
    lo_ok, hi_ok = LEVEL_RANGE_DB
    if _is_table(card):
        lo, hi = card_level_range(card)
        if not (np.isfinite(lo) and lo >= lo_ok and hi <= hi_ok):
            top = np.asarray(card.overall_a_db, dtype=float)
            return [("levels_db", f"levels_db: table levels at {RULE_DISTANCE_M:g} m range {lo:.4g} to {hi:.4g} "
                                  f"dB(A) ({np.nanmin(top):.4g} to {np.nanmax(top):.4g} dB(A) at its radius "
                                  f"{float(card.reference_distance_m):g} m), outside the plausible {lo_ok:g} to "
                                  f"{hi_ok:g} dB(A) at {RULE_DISTANCE_M:g} m")]
        return []
    base, p, names, cov = _base(card)
    x = _sphere_inputs(card)
    bg = base.background
    with np.errstate(all="ignore"):
        lv, jac = base.level_and_jacobian(p, x, d_ref=float(card.reference_distance_m), background=False)
    out: list[tuple[str, str]] = []
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
        ref = float(card.reference_distance_m)
        stated = "" if ref == RULE_DISTANCE_M else f" (stated at {ref:g} m)"
        out.append(("parameters", f"level at {RULE_DISTANCE_M:g} m{stated} over the emission sphere at "
                    f"{lo_w:g}-{hi_w:g} W ranges {np.nanmin(flat):.4g} to {np.nanmax(flat):.4g} dB(A), outside "
                    f"the plausible {lo_ok:g} to {hi_ok:g} dB(A); driven by "
                    + ", ".join(f"{k} = {float(card.parameters[k]):.4g}" for k in culprits)))
    far = dict(x, d=np.full(x["d"].shape, 2 * RULE_DISTANCE_M))
    with np.errstate(all="ignore"):
        lv_far, jac_far = base.level_and_jacobian(p, far, d_ref=float(card.reference_distance_m), background=False)
    rise = np.asarray(lv_far).reshape(-1) - flat
    if not out and np.all(np.isfinite(rise)) and rise.max() >= 0:  # (levels out of range: that says enough)
        worst = int(np.argmax(rise))
        culprits = names
        if j is not None and jac_far is not None:
            with np.errstate(all="ignore"):
                # parameters that shape the fall with distance; at 0 (p6 = 0) a parameter still counts
                contrib = np.abs(np.asarray(jac_far).reshape(flat.size, -1)[worst] - j[worst]) * np.maximum(np.abs(p),
                                                                                                             1.0)
            if np.all(np.isfinite(contrib)) and contrib.max() > 0:
                culprits = [names[k] for k in np.argsort(-contrib) if contrib[k] >= 0.5 * contrib.max()]
        out.append(("parameters", f"level at {2 * RULE_DISTANCE_M:g} m is {rise.max():+.3g} dB against "
                    f"{RULE_DISTANCE_M:g} m in its worst direction: a source's level falls with distance "
                    "(spherical spreading -6 dB per doubling); driven by "
                    + ", ".join(f"{k} = {float(card.parameters[k]):.4g}" for k in culprits)))
    if cov is not None:
        var = np.diag(cov)
        badvar = [names[k] for k in range(len(names)) if not np.isfinite(var[k])]
        if badvar:
            out.append(("parameters", f"standard deviation of {', '.join(badvar)} is not finite"))
        elif j is not None and np.all(np.isfinite(j)):
            sd = np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", j, cov, j), 0.0))
            if sd.max() > MAX_LEVEL_STD_DB:
                n = int(np.argmax(sd))
                share = np.abs(j[n]) * np.sqrt(np.maximum(var, 0.0))
                culprits = [names[k] for k in np.argsort(-share) if share[k] >= 0.5 * share.max()]
                out.append(("parameters", f"level standard deviation up to {sd.max():.3g} dB (limit "
                            f"{MAX_LEVEL_STD_DB:g} dB); uncertain: " + ", ".join(
                                f"{k} = {float(card.parameters[k]):.4g} +- "
                                f"{np.sqrt(max(var[names.index(k)], 0)):.3g}" for k in culprits)))
    phase = None if out else _phase_angle_problem(card, names)  # levels out of range say enough
    return out + ([("parameters", phase)] if phase is not None else [])


def card_problems(card: Any) -> list[str]:
    """What makes a card implausible (empty when it is plausible); each message names the field or parameters.

    The rules are the module docstring's: the reference distance within :data:`REFERENCE_DISTANCE_RANGE_M`,
    the levels at :data:`RULE_DISTANCE_M` within :data:`LEVEL_RANGE_DB` (a hemisphere card: its node
    levels there), levels falling with distance, a bounded level uncertainty.
    """
    return [msg for _, msg in _problems(card)]


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
    """Raise :class:`ImplausibleCardError` when :func:`card_problems` finds anything.

    The error's ``field`` is the first problem's: ``reference_distance_m``, ``parameters``, or
    ``levels_db`` (a hemisphere card's table).  The verdict depends on the card's content only; plausible contents are remembered, so a
    card mapped again (a service answering route planners, a map of many phases) is not
    checked again.
    """
    key = _content_key(card)
    if key is not None:
        with _PLAUSIBLE_LOCK:
            if key in _PLAUSIBLE:
                _PLAUSIBLE.move_to_end(key)
                return
    problems = _problems(card)
    if not problems and key is not None:
        with _PLAUSIBLE_LOCK:
            _PLAUSIBLE[key] = None
            while len(_PLAUSIBLE) > _PLAUSIBLE_MAX:
                _PLAUSIBLE.popitem(last=False)
    if problems:
        src = source or f"model card {card.id!r}"
        raise ImplausibleCardError(f"{src}: implausible card: {'; '.join(m for _, m in problems)}",
                                   field=problems[0][0])
