"""The speed a map flies each measured hemisphere at, against the speed it was measured at.

A hemisphere card is one flight condition (:class:`~gisnoise.model.HemisphereCard`): its
``condition["speed_m_s"]`` is the speed the vehicle flew while it was measured (the Salford
file name's ``F05``: 5 m/s).  The map evaluates the table at whatever speed the flight flies the
card's phase at; the level there is the measured condition's, not the flight's.

The tolerance is that of a noise certification flight: 14 CFR Part 36, Appendix H (helicopters)
lets the airspeed of a test flight vary from its reference airspeed by at most 5 kt
(:data:`SPEED_TOLERANCE_M_S`, 2.57 m/s) for the measurement to stand for that reference condition.
Samples flown farther from the stated speed are named in one warning per card; the map is made.
Only the samples the map evaluates count: those that fly (:attr:`~gisnoise.flight.Trajectory.flying`; samples
on the ground or lying upside down after a crash are silent on the map) and that the card serves.
The speed is the logged airspeed when the trajectory has one (``airspeed_m_s``; routes from
waypoints carry their speed there), else the speed over the ground from the positions, smoothed
over :data:`~gisnoise.flight.phases.PHASE_SMOOTHING_S` as the phase rule smooths it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.flight import Trajectory, smoothed_speed
from gisnoise.maps.cardset import CardSet, flying_cards
from gisnoise.model import HemisphereCard

__all__ = ["SPEED_TOLERANCE_M_S", "check_hemisphere_speeds"]

SPEED_TOLERANCE_M_S = 5 * 1852 / 3600
"""Largest departure of the flown speed from a hemisphere's stated speed that is still its condition, m/s
(5 kt: 14 CFR Part 36 Appendix H's airspeed tolerance of a helicopter noise test flight)."""


def check_hemisphere_speeds(traj: Trajectory, cardset: CardSet, *, cards_flying: np.ndarray | None = None
                            ) -> tuple[list[str], dict[str, Any]]:
    """Warn about hemisphere cards flown away from their stated speed (module docstring); ``cards_flying`` as
    :func:`~gisnoise.maps.powers.check_power_ranges` takes it.

    Returns the warnings (one per card) and, per such card, ``{"stated_m_s": v, "flown_m_s": [[min, max], ...],
    "samples": n, "of": m, "speed": "airspeed" | "ground speed"}`` for the map's metadata (``n`` of the card's
    ``m`` flying samples are outside the tolerance; ``flown_m_s``: the range of those slower than ``v``, then of
    those faster, each when there are any).
    """
    stated = {k: float(c.condition["speed_m_s"]) for k, c in enumerate(cardset.cards)
              if isinstance(c, HemisphereCard) and isinstance(c.condition.get("speed_m_s"), (int, float))}
    fly = traj.flying
    if not stated or not fly.any():
        return [], {}
    if traj.airspeed_m_s is not None:
        speed, what = traj.airspeed_m_s, "airspeed"
    else:
        speed, what = smoothed_speed(traj.t, np.column_stack(traj.enu(traj.origin()))), "ground speed"
    idx = cards_flying if cards_flying is not None else flying_cards(traj, cardset)
    flown = speed[fly]
    warnings: list[str] = []
    meta: dict[str, Any] = {}
    for k, v0 in stated.items():
        s = flown[idx == k]
        off = s[np.abs(s - v0) > SPEED_TOLERANCE_M_S]
        if off.size == 0:
            continue
        card = cardset.cards[k]
        slow, fast = off[off < v0], off[off > v0]
        ranges = " and ".join(f"{a.min():.1f}-{a.max():.1f}" for a in (slow, fast) if a.size)
        warnings.append(f"{traj.source}: hemisphere {card.id!r} was measured at {v0:g} m/s; {off.size} of the "
                        f"{s.size} flying samples it serves fly at {ranges} m/s {what}, more than 5 kt from it: the "
                        f"map gives them the {v0:g} m/s levels")
        meta[card.id] = {"stated_m_s": v0, "flown_m_s": [[round(float(a.min()), 2), round(float(a.max()), 2)]
                                                         for a in (slow, fast) if a.size],
                         "samples": int(off.size), "of": int(s.size), "speed": what}
    return warnings, meta
