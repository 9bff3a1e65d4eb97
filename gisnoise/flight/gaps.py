"""Holes in a track read from a file: stretches without a sample, which readers bridge straight.

A flight CSV or log whose samples stop for a while (a logger's pause, a GNSS outage, rows cut from a
file) is read as it is: between the samples around the hole the state is interpolated linearly, as
between any two samples, so a turn or a climb inside it is lost.  :func:`track_gaps` finds the holes
longer than :data:`TRACK_GAP_S` and :data:`GAP_FACTOR` times the track's usual step; readers keep them
in the trajectory's ``metadata["track_gaps"]`` and :func:`gap_warning` says them in the line every face
shows (:func:`gisnoise.flight.readnotes.track_warning`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["GAP_FACTOR", "TRACK_GAP_S", "gap_metadata", "gap_warning", "track_gaps"]

TRACK_GAP_S = 5.0
"""A hole shorter than this is not named, s.  A GNSS receiver logged at 5 Hz pauses for a second or two now and
then (the real ArduCopter log of the tests: 2.2 s once in 4 minutes); over 5 s a multicopter can turn round."""
GAP_FACTOR = 5.0
"""Nor one shorter than this many of the track's median steps (a log written at 0.2 Hz has 5 s steps)."""


def track_gaps(t: Any) -> list[tuple[int, float]]:
    """The holes of a track's times ``t`` (s, increasing): ``(i, seconds)`` for each step ``t[i] -> t[i + 1]``
    longer than :data:`TRACK_GAP_S` and :data:`GAP_FACTOR` median steps.

    >>> track_gaps(np.r_[np.arange(0.0, 5.0, 0.5), np.arange(15.0, 20.0, 0.5)])
    [(9, 10.5)]
    >>> track_gaps(np.r_[np.arange(0.0, 5.0, 0.2), np.arange(7.2, 9.0, 0.2)])   # a GNSS pause of 2.4 s
    []
    >>> track_gaps(np.arange(0.0, 60.0, 5.0))   # a slow logger: every step alike
    []
    >>> track_gaps([0.0, np.nan, 1.0, 20.0])      # times the trajectory refuses: not judged here
    []
    """
    tt = np.asarray(t, dtype=float)
    if tt.ndim != 1 or tt.size < 3 or not np.all(np.isfinite(tt)):
        return []  # the trajectory's own checks refuse such times, naming them
    dt = np.diff(tt)
    if not np.all(dt > 0.0):
        return []
    limit = max(TRACK_GAP_S, GAP_FACTOR * float(np.median(dt)))
    return [(int(i), float(dt[i])) for i in np.flatnonzero(dt > limit)]


def gap_metadata(t: Any) -> dict[str, Any]:
    """``{"track_gaps": [{"t_s", "t_next_s", "gap_s"}, ...]}`` on the trajectory's clock ``t``; empty without holes."""
    tt = np.asarray(t, dtype=float)
    gaps = track_gaps(tt)
    if not gaps:
        return {}
    return {"track_gaps": [{"t_s": float(tt[i]), "t_next_s": float(tt[i + 1]), "gap_s": round(g, 3)}
                           for i, g in gaps]}


def gap_warning(traj: Any) -> str | None:
    """The one-line warning for a trajectory read with holes (its ``metadata["track_gaps"]``), or None."""
    meta = traj.metadata if isinstance(traj.metadata, Mapping) else {}
    gaps = meta.get("track_gaps") or []
    if not gaps:
        return None
    when = ", ".join(f"{g['gap_s']:.1f} s from t = {g['t_s']:.1f} s" for g in gaps[:3])
    more = f" and {len(gaps) - 3} more" if len(gaps) > 3 else ""
    what = "a hole" if len(gaps) == 1 else f"{len(gaps)} holes"
    return (f"{traj.source}: the track has {what} without samples ({when}{more}): position, attitude and power are "
            "interpolated straight across, so a turn or climb there is lost")
