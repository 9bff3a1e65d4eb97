"""The powers a map flies each card at, against the powers the card holds for (:mod:`gisnoise.model.power_range`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory
from gisnoise.maps.cardset import CardSet, flying_cards
from gisnoise.model import power_range_finding

__all__ = ["check_power_ranges"]


def check_power_ranges(traj: Trajectory, cardset: CardSet, *, cards_flying: np.ndarray | None = None
                       ) -> tuple[list[str], dict[str, Any]]:
    """Refuse a card without power term used outside its power range; warn about extrapolating ones.

    ``cards_flying``: the card of each flying sample (:func:`~gisnoise.maps.cardset.flying_cards`), if known.

    Returns the warnings and, per card used outside its range, ``{"range_w": [lo, hi], "used_w":
    [min, max], "samples": n}`` for the map's metadata.

    Raises
    ------
    InputError
        (field ``power_w``) a card valid only at the power flown meets other powers.
    """
    fly = traj.flying
    if not fly.any():
        return [], {}
    idx = cards_flying if cards_flying is not None else flying_cards(traj, cardset)
    pw = traj.power_w[fly]
    warnings: list[str] = []
    meta: dict[str, Any] = {}
    for k, card in enumerate(cardset.cards):
        f = power_range_finding(card, pw[idx == k])
        if f is None:
            continue
        if f.refusal is not None:
            raise InputError(f"{traj.source}: {f.refusal}", field="power_w")
        warnings.append(f"{traj.source}: {f.warning}")
        meta[card.id] = {"range_w": list(f.range_w), "used_w": list(f.used_w), "samples": f.samples}
    return warnings, meta
