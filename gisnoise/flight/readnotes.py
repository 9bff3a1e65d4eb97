"""What reading a track left out or mended, in the one line every face shows.

A trajectory's metadata records what its reading did that the user must know: a log cut short
(``log_cut``, :mod:`gisnoise.flight.logcut`), stretches of a log damaged inside left out
(``log_corrupt``, :mod:`gisnoise.flight.logdamage`), stretches at a log's start or end left out because
position, attitude or power is not logged there (``log_left_out``, :mod:`gisnoise.flight.logspan`; said
when the vehicle may have made noise in them), position glitches mended and jumps kept
(``position_glitches``, ``position_jumps``, :mod:`gisnoise.flight.glitches`), holes without samples
bridged straight (``track_gaps``, :mod:`gisnoise.flight.gaps`).
:func:`track_warning` joins them into one line naming the file; maps (:mod:`gisnoise.maps.flightchecks`),
``gisnoise campaign check``, fits and diagnoses (:func:`gisnoise.measure.campaign_log_warnings`), the
service and QGIS show that line.
"""

from __future__ import annotations

from typing import Any

from gisnoise.flight.gaps import gap_warning
from gisnoise.flight.glitches import glitch_warning
from gisnoise.flight.logcut import cut_warning
from gisnoise.flight.logdamage import log_damage_warning
from gisnoise.flight.logspan import left_out_warning

__all__ = ["track_warning"]


def track_warning(traj: Any) -> str | None:
    """The one-line warning for what reading ``traj`` left out or mended, or None when nothing.

    Joins, in this order and with ``"; "``, the cut (:func:`~gisnoise.flight.logcut.cut_warning`), the damage
    (:func:`~gisnoise.flight.logdamage.log_damage_warning`), the stretches left out at the log's start or end
    (:func:`~gisnoise.flight.logspan.left_out_warning`), the position glitches
    (:func:`~gisnoise.flight.glitches.glitch_warning`) and the holes (:func:`~gisnoise.flight.gaps.gap_warning`) that
    hold.
    """
    said = [w for w in (cut_warning(traj), log_damage_warning(traj), left_out_warning(traj), glitch_warning(traj),
                        gap_warning(traj)) if w is not None]
    return "; ".join(said) if said else None
