"""Hemisphere cards in a card set: which sets hold one, and the weight of filled table nodes per cell.

Shared by both engines (the NumPy reference and the numba hemisphere kernel) for the map's
metadata on the energy that came from filled (not measured) cells of a hemisphere.

A map whose energy came for more than :data:`FILLED_SHARE_WARNING` (half) from filled nodes,
directions outside the table's angles or above the horizon says so in its warnings
(:func:`filled_share_warning`): more of it then repeats the table's fill than its measurement.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.geo import emission_angles
from gisnoise.model import HemisphereCard

__all__ = ["FILLED_SHARE_WARNING", "filled_share_warning", "filled_weights", "has_hemisphere", "hemisphere_atmospheres"]

FILLED_SHARE_WARNING = 0.5
"""Share of a map's energy from filled hemisphere directions above which the map warns: more than half of it is then
fill, not measurement (the M300 flyover at 10 m: 0.32)."""


def has_hemisphere(cards: Any) -> bool:
    """True when any card of the set is a hemisphere card."""
    return any(isinstance(c, HemisphereCard) for c in cards)


def hemisphere_atmospheres(cards: Any) -> dict[str, dict[str, float]]:
    """The atmosphere of each hemisphere card's absorption on the map, by card id (for the metadata)."""
    return {c.id: c.propagation_atmosphere for c in cards if isinstance(c, HemisphereCard)}


def filled_weights(rcv: np.ndarray, src: np.ndarray, att: np.ndarray, card_idx: np.ndarray, cards: Any
                   ) -> np.ndarray:
    """Interpolation weight on filled table nodes, ``(cells, instants)``; 0 for parametric cards' instants.

    Arguments as the NumPy engine's block function (ENU receivers and sources, yaw/pitch/roll in rad).
    """
    d, phi, theta = emission_angles(rcv[:, 0, None] - src[None, :, 0], rcv[:, 1, None] - src[None, :, 1],
                                    rcv[:, 2, None] - src[None, :, 2], att[:, 0], att[:, 1], att[:, 2])
    fw = np.zeros(d.shape)
    for k in np.unique(card_idx):
        c = cards[int(k)]
        if isinstance(c, HemisphereCard):
            sel = np.flatnonzero(card_idx == k)
            fw[:, sel] = c.interpolation(phi[:, sel], theta[:, sel])[1]
    return fw


def filled_share_warning(metadata: dict[str, Any]) -> str | None:
    """The map's warning when ``metadata["hemisphere_filled_energy_share"]`` exceeds :data:`FILLED_SHARE_WARNING`
    (module docstring); None otherwise or when the map has no share (no hemisphere card, or neither LAeq nor SEL)."""
    share = metadata.get("hemisphere_filled_energy_share")
    if share is None or not share > FILLED_SHARE_WARNING:
        return None
    return (f"hemisphere: {100.0 * share:.0f} % of the map's sound energy came from table directions that were not "
            "measured (filled nodes, directions beyond the table's angles, which take its edge values, or above the "
            "horizon, mirrored): the map shows the table's fill more than its measurement "
            "(metadata hemisphere_filled_energy_share)")
