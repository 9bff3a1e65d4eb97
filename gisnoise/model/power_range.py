"""The electric powers a model card holds for, and what a map does with powers outside them.

A fitted card states the powers of the data it was fitted on (``statistics.power_range_w``,
``[lo, hi]`` in W).  Two kinds of card use it differently:

* a card **without a power term** (the fit held ``p1`` at 0 because the campaign flew at one
  steady power, ``provenance.held_parameters.p1``; or any card stating a range with ``p1 = 0``)
  is a level offset valid only at the power flown.  Used at another power, its level would
  be silently wrong by ``p1_true log10(P / P_flown)`` (about 2 dB for 25 % more power at a
  typical ``p1`` of 20): a map with flying samples of its phases outside its range, widened by
  :data:`POWER_RANGE_DEX` either side, is **refused** naming ``power_w``;
* a card **with a power term** extrapolates outside its range by the model's own power law:
  normal use (a route's power model differs from the powers of a campaign), so the map is made,
  and a warning plus the map's metadata (``power_outside_card_range``) say which card, how many
  samples and which powers.

:data:`POWER_RANGE_DEX` is the spread of ``log10 P`` below which the fitter calls a campaign's
power steady (:data:`gisnoise.identify.STEADY_POWER_DEX` is this value): powers that close to
the range are the power the card was fitted at.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["POWER_RANGE_DEX", "PowerRangeFinding", "stated_power_range_w", "holds_at_power_flown", "power_range_finding",
           "power_range_findings"]

POWER_RANGE_DEX = 0.02
"""Tolerance of a stated power range, in log10 of the power (0.02: about 4.7 %)."""


def stated_power_range_w(card: Any) -> tuple[float, float] | None:
    """The power range (W) a card states (``statistics.power_range_w``), or None when it states none."""
    rng = (getattr(card, "statistics", None) or {}).get("power_range_w")
    if isinstance(rng, Sequence) and not isinstance(rng, str) and len(rng) == 2:
        try:
            lo, hi = (float(v) for v in rng)
        except (TypeError, ValueError):
            return None
        if 0 < lo <= hi and np.isfinite(hi):
            return lo, hi
    return None


def holds_at_power_flown(card: Any) -> bool:
    """True for a card without a power term: ``p1`` held by the fit, or ``p1 = 0`` with a stated power range."""
    params = getattr(card, "parameters", None) or {}
    if "p1" not in params:
        return False
    held = (getattr(card, "provenance", None) or {}).get("held_parameters") or {}
    if "p1" in held:
        return True
    return float(params["p1"]) == 0.0 and stated_power_range_w(card) is not None


@dataclass(frozen=True)
class PowerRangeFinding:
    """A card used outside its stated power range: the range (W), the powers used (W, the finite positive ones),
    how many of them lie outside, and the refusal (a card without power term) or else the warning."""

    range_w: tuple[float, float]
    used_w: tuple[float, float]
    samples: int
    refusal: str | None
    warning: str | None


def power_range_finding(card: Any, power_w: Any) -> PowerRangeFinding | None:
    """What using ``card`` at electric powers ``power_w`` (W, array_like) means (see the module docstring).

    None when the powers lie within the stated range (widened by :data:`POWER_RANGE_DEX`) or the
    card states no range.
    """
    rng = stated_power_range_w(card)
    pw = np.asarray(power_w, dtype=float)
    pw = pw[np.isfinite(pw) & (pw > 0)]
    if rng is None or pw.size == 0:
        return None
    lo, hi = rng
    f = 10.0 ** POWER_RANGE_DEX
    out = (pw < lo / f) | (pw > hi * f)
    if not out.any():
        return None
    n, p_lo, p_hi = int(out.sum()), float(pw.min()), float(pw.max())
    if holds_at_power_flown(card):
        refusal = (f"card {card.id!r} holds only at the power flown in its campaign ({lo:.4g}-{hi:.4g} W; no power "
                   f"term, p1 held at 0), but the track uses it at {p_lo:.4g}-{p_hi:.4g} W ({n} flying sample(s) "
                   f"outside); give the power it holds for (a log: --power-w W, field power_w) or fit a card over "
                   f"several powers")
        return PowerRangeFinding(rng, (p_lo, p_hi), n, refusal, None)
    return PowerRangeFinding(rng, (p_lo, p_hi), n, None,
                             f"card {card.id!r} is used at {p_lo:.4g}-{p_hi:.4g} W: {n} flying sample(s) outside "
                             f"the {lo:.4g}-{hi:.4g} W it was fitted at, where its power term extrapolates")


def power_range_findings(card: Any, power_w: Any) -> tuple[str | None, str | None]:
    """(refusal, warning) of :func:`power_range_finding`: both None when the powers lie within the range.

    Examples
    --------
    >>> from gisnoise.model import ModelCard
    >>> p = dict(p0=64.0, p1=0.0, p2=0.0, p3=0.0, p4=0.0, p5=0.0, p6=1.0, p7=40.0)
    >>> c = ModelCard(id="steady", vehicle="v", phase="horizontal", ansatz="paper-offset", parameters=p,
    ...               reference_power_w=3000.0, statistics={"power_range_w": [2400.0, 2400.0]})
    >>> power_range_findings(c, [2400.0, 2500.0])      # 2500 W is within 0.02 dex of 2400 W
    (None, None)
    >>> refuse, _ = power_range_findings(c, [2400.0, 3000.0])
    >>> refuse.split(";")[0]
    "card 'steady' holds only at the power flown in its campaign (2400-2400 W"
    """
    f = power_range_finding(card, power_w)
    return (None, None) if f is None else (f.refusal, f.warning)
