"""Periods of the day and the day-evening-night level of EU Directive 2002/49/EC, Annex I.

``day``
    07:00-19:00 (12 h);
``evening``
    19:00-23:00 (4 h), weighted +5 dB in Lden;
``night``
    23:00-07:00 (8 h), weighted +10 dB in Lden;

    Lden = 10 log10( (12 10^(Lday/10) + 4 10^((Levening+5)/10) + 8 10^((Lnight+10)/10)) / 24 )

with ``Lday``, ``Levening``, ``Lnight`` the A-weighted equivalent levels of each period.
A flight counts in the period in which it departs (:func:`period_of`).

Examples
--------
>>> round(float(lden(50.0, 50.0, 50.0)), 2)
56.4
>>> period_of("06:59"), period_of("07:00"), period_of("22:59:59"), period_of("23:00")
('night', 'day', 'evening', 'night')
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["PENALTY_DB", "PERIODS", "PERIOD_HOURS", "PERIOD_START_H", "lden", "lden_energy", "period_of"]

PERIODS = ("day", "evening", "night")
PERIOD_START_H = {"day": 7.0, "evening": 19.0, "night": 23.0}
"""Local clock time (h) at which each period begins (EU Directive 2002/49/EC, Annex I)."""
PERIOD_HOURS = {"day": 12.0, "evening": 4.0, "night": 8.0}
PENALTY_DB = {"day": 0.0, "evening": 5.0, "night": 10.0}


def lden(l_day: Any, l_evening: Any, l_night: Any) -> np.ndarray:
    """Day-evening-night level (EU Directive 2002/49/EC, Annex I), dB.

    ``10 log10((12 10^(Ld/10) + 4 10^((Le + 5)/10) + 8 10^((Ln + 10)/10)) / 24)``.
    Levels in dB(A), float or array_like (they broadcast); ``-inf`` for a period
    without sound.
    """
    ld, le, ln = (np.asarray(v, dtype=float) for v in (l_day, l_evening, l_night))
    e = lden_energy(10.0 ** (ld / 10.0), 10.0 ** (le / 10.0), 10.0 ** (ln / 10.0))
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(e)


def lden_energy(e_day: Any, e_evening: Any, e_night: Any) -> Any:
    """The weighted mean of the period energies ``10^(L/10)`` behind :func:`lden`."""
    return (PERIOD_HOURS["day"] * e_day * 10.0 ** (PENALTY_DB["day"] / 10.0)
            + PERIOD_HOURS["evening"] * e_evening * 10.0 ** (PENALTY_DB["evening"] / 10.0)
            + PERIOD_HOURS["night"] * e_night * 10.0 ** (PENALTY_DB["night"] / 10.0)) / 24.0


def period_of(clock: str | float) -> str:
    """The period (``day``, ``evening``, ``night``) of a local clock time ``"HH:MM[:SS]"`` or a number of hours
    after midnight (7.5 is 07:30), within 0-24 h.  A bool (JSON ``true``) is neither: refused."""
    if isinstance(clock, (bool, np.bool_)) or not isinstance(clock, (str, int, float, np.integer, np.floating)):
        raise InputError(f"departures: {clock!r} is not a clock time HH:MM[:SS] nor a number of hours after midnight",
                         field="departures")
    if isinstance(clock, str):
        parts = clock.strip().split(":")
        try:
            if not 2 <= len(parts) <= 3:
                raise ValueError
            hh, mm = int(parts[0]), int(parts[1])
            ss = float(parts[2]) if len(parts) == 3 else 0.0
        except ValueError:
            raise InputError(f"departures: {clock!r} is not a clock time HH:MM[:SS]", field="departures") from None
        if not (0 <= hh <= 23 and 0 <= mm <= 59 and 0 <= ss < 60):
            raise InputError(f"departures: {clock!r} is not a clock time HH:MM[:SS]", field="departures")
        hours = hh + mm / 60.0 + ss / 3600.0
    else:
        hours = float(clock)
        if not (math.isfinite(hours) and 0.0 <= hours < 24.0):
            raise InputError(f"departures: {clock!r} h is not within 0-24 h", field="departures")
    if PERIOD_START_H["day"] <= hours < PERIOD_START_H["evening"]:
        return "day"
    if PERIOD_START_H["evening"] <= hours < PERIOD_START_H["night"]:
        return "evening"
    return "night"

