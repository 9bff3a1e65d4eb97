"""Stretches of a flight log left out of its trajectory: where position, attitude or power is not yet (or no
longer) logged.

A trajectory needs position, attitude and power at every sample, so a reader keeps the span where all three
are logged (:mod:`gisnoise.flight.logs`, Time base).  Real logs start their topics at different times: an
estimator publishes attitude only once it has aligned, a GNSS receiver gives a 3D fix a minute after boot,
a battery monitor starts late.  What lies outside the kept span is *not* filled in: attitude sets the
direction of the sound (the model's azimuth and polar angle) and position its distance, and neither can be
held or guessed without putting invented levels on a map (as the geoid undulation is never guessed either).
It is said instead.

:func:`left_out` finds the stretches: the log's span is the union of the spans of the topics the trajectory
needs (position, attitude, every battery, the estimator's height), clipped to the logger's start where the
format gives one (PX4: a topic's first sample may be its last publication before logging began); a stretch
at the start or the end of it outside the kept span is named when it is longer than :data:`LEFT_OUT_MIN_S`
and two steps of the position source (a shorter one is the sampling's own edge).  Each stretch states the
topics that start late (or end early), the most power the batteries drew in it and how long the vehicle was
in the air in it by the log's own landed flag (PX4 ``vehicle_land_detected``, ArduPilot arming and landing
events; ``None``: the log does not say).  Readers keep them in the trajectory's ``metadata["log_left_out"]``;
:func:`left_out_warning` says, in the line every face shows (:func:`gisnoise.flight.readnotes.track_warning`),
those in which the vehicle may have made noise: it was in the air, or the log has no landed flag and the
batteries drew power.  A stretch spent on the ground is silent on any map (:attr:`Trajectory.flying`), so it
stays in the metadata only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["LEFT_OUT_MIN_S", "airborne_seconds", "left_out", "left_out_warning"]

LEFT_OUT_MIN_S = 1.0
"""A stretch shorter than this is not named, s: topics logged at 1-10 Hz start and end a sample apart."""


def airborne_seconds(a: float, b: float, t_flag: Any, airborne: Any) -> float:
    """Seconds in ``[a, b]`` (s) during which a step series says the vehicle is in the air.

    ``airborne[i]`` holds from ``t_flag[i]`` (s, increasing) to the next time; before the first, the first value.

    >>> airborne_seconds(0.0, 10.0, [1.0, 4.0, 6.0], [False, True, False])
    2.0
    >>> airborne_seconds(5.0, 10.0, [1.0, 4.0, 6.0], [False, True, False])
    1.0
    """
    tf = np.asarray(t_flag, dtype=float)
    up = np.asarray(airborne, dtype=bool)
    if not b > a or tf.size == 0:
        return 0.0
    edges = np.unique(np.concatenate([[a, b], tf[(tf > a) & (tf < b)]]))
    idx = np.clip(np.searchsorted(tf, edges[:-1], side="right") - 1, 0, len(tf) - 1)
    return float(np.sum(np.diff(edges)[up[idx]]))


def left_out(kept: tuple[float, float], spans: Mapping[str, tuple[float, float]], *, step_s: float,
             power: Sequence[tuple[np.ndarray, np.ndarray]] = (), flag: tuple[np.ndarray, np.ndarray] | None = None,
             log_start: float | None = None, offset_s: float = 0.0) -> list[dict[str, Any]]:
    """The stretches of a log left out of its trajectory (see the module docstring), as metadata.

    Parameters
    ----------
    kept : (float, float)
        The first and last time of the trajectory's time base, s on the log's clock.
    spans : mapping
        Per topic the trajectory needs, its first and last time, s on the log's clock.
    step_s : float
        The position source's median step, s.
    power : sequence of (times s, power W)
        The batteries' power series (empty: the power is not logged).
    flag : (times s, airborne bool) or None
        The log's landed flag as a step series of "in the air", or None when it has none.
    log_start : float, optional
        The logger's start, s on the log's clock: the log's span begins no earlier.
    offset_s : float
        The trajectory's time minus the log's clock, s.

    Returns
    -------
    list of dict
        Per stretch: ``part`` (``start`` or ``end``), ``log_s`` (its span on the log's clock, s), ``t_s`` (on
        the trajectory's), ``duration_s``, ``topics`` (``{name: first or last time on the log's clock}`` of the
        topics that start late or end early), ``max_power_w`` (None: no battery logged in it) and
        ``airborne_s`` (None: no landed flag).

    Examples
    --------
    >>> st = left_out((5.0, 20.0), {"gps": (0.5, 20.0), "attitude": (4.8, 20.2)}, step_s=0.2,
    ...               flag=(np.array([0.0, 2.0, 3.0]), np.array([False, True, False])))
    >>> [(s["part"], s["log_s"], s["topics"], s["airborne_s"]) for s in st]
    [('start', [0.5, 5.0], {'attitude': 4.8}, 1.0)]
    """
    first = min(a for a, _ in spans.values())
    last = max(b for _, b in spans.values())
    if log_start is not None:
        first = max(first, log_start)
    tol = max(LEFT_OUT_MIN_S, 2.0 * step_s)
    out = []
    for part, a, b in (("start", first, kept[0]), ("end", kept[1], last)):
        if not b - a > tol:
            continue
        if part == "start":
            topics = {n: s[0] for n, s in spans.items() if s[0] - first > tol}
            topics = topics or {max(spans, key=lambda n: spans[n][0]): max(s[0] for s in spans.values())}
        else:
            topics = {n: s[1] for n, s in spans.items() if last - s[1] > tol}
            topics = topics or {min(spans, key=lambda n: spans[n][1]): min(s[1] for s in spans.values())}
        out.append({"part": part, "log_s": [round(float(a), 6), round(float(b), 6)],
                    "t_s": [round(float(a + offset_s), 6), round(float(b + offset_s), 6)],
                    "duration_s": round(float(b - a), 6),
                    "topics": {n: round(float(v), 6) for n, v in sorted(topics.items(), key=lambda kv: kv[1])},
                    "max_power_w": _max_power(a, b, power),
                    "airborne_s": None if flag is None else round(airborne_seconds(a, b, *flag), 6)})
    return out


def _max_power(a: float, b: float, power: Sequence[tuple[np.ndarray, np.ndarray]]) -> float | None:
    """The most summed battery power (W) logged in ``[a, b]``, or None when no battery is logged there."""
    series = [(t, p) for t, p in power if len(t) and t[0] <= b and t[-1] >= a]
    if not series:
        return None
    times = np.unique(np.concatenate([t[(t >= a) & (t <= b)] for t, _ in series] + [np.array([a, b])]))
    total = np.zeros(len(times))
    for t, p in series:
        inside = (times >= t[0]) & (times <= t[-1])
        total[inside] += np.interp(times[inside], t, p)
    return round(float(np.max(total)), 3)


def _noisy(stretch: Mapping[str, Any]) -> bool:
    """Whether the vehicle may have made noise in a left-out stretch: in the air by the log's landed flag, or no
    landed flag and the batteries drew power."""
    if stretch.get("airborne_s") is not None:
        return bool(stretch["airborne_s"] > 0)
    return bool((stretch.get("max_power_w") or 0.0) > 0)


def left_out_warning(traj: Any) -> str | None:
    """The one-line warning for the stretches of ``traj``'s log left out in which the vehicle may have made noise
    (its ``metadata["log_left_out"]``: in the air by the log's landed flag, or no landed flag and the batteries
    drew power), or None."""
    meta = traj.metadata if isinstance(traj.metadata, Mapping) else {}
    said = [_describe(s) for s in meta.get("log_left_out") or [] if _noisy(s)]
    if not said:
        return None
    return f"{traj.source}: " + "; ".join(said) + ": the noise made there is missing from maps"


def _describe(s: Mapping[str, Any]) -> str:
    a, b = s["log_s"]
    t0, t1 = s["t_s"]
    which = "first" if s["part"] == "start" else "last"
    verb = "starts" if s["part"] == "start" else "ends"
    topics = ", ".join(f"{n} {verb} at {v:.2f} s" for n, v in s["topics"].items())
    air = s.get("airborne_s")
    flew = "the log has no landed flag" if air is None else ("the vehicle was in the air for "
                                                              f"{air:.1f} s" if air > 0 else "the vehicle was landed")
    p = s.get("max_power_w")
    drew = "no battery logged" if p is None else (f"the batteries drew up to {p:.0f} W" if p > 0 else
                                                 "the batteries drew no power")
    return (f"the {which} {s['duration_s']:.1f} s of the log ({a:.2f}-{b:.2f} s after boot, t = {t0:.1f} to "
            f"{t1:.1f} s) are left out ({topics}); there {flew} and {drew}")
