"""The comparison's rules: one ground, one LAeq period, pads within the population raster, ranks with ties.

Private helpers of :mod:`gisnoise.planning.compare`; the rules are stated in ``docs/planning.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.exposure import Population, covered_at
from gisnoise.flight import Trajectory, ground_from_track
from gisnoise.limits import GROUND_TOLERANCE_M, check_receivers

TIE_STEPS = (1.0, 1.0, 0.1)
"""The steps to which routes are scored before ranking: people (or residents) above the ranking level to the whole
person, person-dB to the whole person-dB, the peak level at a dwelling to 0.1 dB, as the table shows them.  Routes
equal at these steps tie (people within half a person of each other may tie: no count is finer than a person);
rounding, unlike a tolerance between pairs, orders any number of routes one way."""

DEM_HINT = ("compare has no DEM: map each route over its own ground with gisnoise contour --dem, or give the "
            "common ground with --ground-height M (field ground_h_m)")


def common_ground(names: Sequence[str], trajs: Mapping[str, Trajectory], stated: Mapping[str, float | None],
                  ground_h: float | None, receiver_height: float) -> tuple[float, float | None, list[str]]:
    """The flat ground of a comparison: ``(ground, taken, warnings)``.

    A given ``ground_h`` is checked for every route as a map checks it (:func:`gisnoise.limits.check_receivers`:
    at or below the lowest flying point; the error names the route), and routes that state another ground are
    named in a warning.  Without it: the routes' stated grounds (they must agree within
    :data:`~gisnoise.limits.GROUND_TOLERANCE_M`, else refused), else the lowest take-off or landing point;
    routes whose own ground differs from the one taken are named in a warning.  ``taken`` is the ground when it
    came from the routes (each track is then checked against it), else None.
    """
    own: dict[str, tuple[float, str]] = {n: (float(g), "states") for n in names if (g := stated[n]) is not None}
    if ground_h is not None:
        for n in names:
            t = trajs[n]
            try:
                check_receivers(receiver_height, ground_h, t.flying_heights())
            except InputError as exc:
                raise type(exc)(f"{n}: {exc}", field=exc.field) from None
        g = float(ground_h)
        return g, None, _differ(own, g, "the given ground")
    if own:
        lo, hi = min(v for v, _ in own.values()), max(v for v, _ in own.values())
        if hi - lo > GROUND_TOLERANCE_M:
            said = ", ".join(f"{n} {v:g} m" for n, (v, _) in own.items())
            raise InputError(f"ground_h_m: the routes state different grounds ({said}): over one flat ground a route "
                             f"on higher ground is judged up to {hi - lo:.1f} m higher above the receivers than it "
                             f"flies; {DEM_HINT}", field="ground_h_m")
    for n in names:
        if n not in own:
            g_track = ground_from_track(trajs[n])
            if g_track is not None:
                own[n] = (g_track, "takes off or lands at")
    if not own:
        raise InputError("ground unknown: no route states its ground or starts or ends on the ground (a take-off "
                         "or landing); give --ground-height M (field ground_h_m)", field="ground_h_m")
    stated_only = [v for n, (v, how) in own.items() if how == "states"]
    g = min(stated_only or [v for v, _ in own.values()])
    return g, g, _differ(own, g, "the lowest ground the routes give")


def _differ(own: Mapping[str, tuple[float, str]], used: float, which: str) -> list[str]:
    """The warning naming the routes whose own ground lies farther than the tolerance from the ground used."""
    off = {n: v for n, (v, _) in own.items() if abs(v - used) > GROUND_TOLERANCE_M}
    if not off:
        return []
    said = "; ".join(f"{n} {own[n][1]} {v:g} m" for n, v in off.items())
    return [f"grounds differ: {said}; every route is evaluated over one flat ground at {used:g} m ({which}), so a "
            f"route is judged by its height above that plane, not above its own ground; {DEM_HINT}"]


def common_period(trajs: Mapping[str, Trajectory], metric: str, period_s: float | None) -> float | None:
    """One averaging period for every route's ``LAeq`` (s): ``period_s``, else the longest route's duration.

    ``LAeq,T = SEL - 10 lg(T / 1 s)`` with the same ``T`` ranks the routes as their SEL does; each route's own
    duration would favour the longer file.  None for ``LAmax`` and ``SEL``, which have no period.
    """
    if metric != "LAeq":
        if period_s is not None:
            raise InputError(f"period_s: an averaging period applies to the metric LAeq only, not {metric} "
                             f"(got {period_s!r})", field="period_s")
        return None
    longest = max(trajs, key=lambda n: trajs[n].duration_s)
    d = float(trajs[longest].duration_s)
    if period_s is None:
        return d
    try:
        p = float(period_s)
    except (TypeError, ValueError):
        raise InputError(f"period_s: not a number: {period_s!r}", field="period_s") from None
    if not math.isfinite(p) or p < d * (1.0 - 1e-12):
        raise InputError(f"period_s: {p:g} s is shorter than route {longest}'s duration {d:.1f} s (LAeq over a common "
                         "period holds every route's whole flight)", field="period_s")
    return p


def pad_outside(pop: Population, lonlat: tuple[float, float]) -> bool:
    """Whether a point (lon, lat, deg) lies where the population raster holds no data: outside its extent or on one
    of its nodata cells (:func:`gisnoise.exposure.covered_at`)."""
    from gisnoise.geo import WGS84

    return not bool(covered_at(pop, WGS84, np.array([lonlat[0]]), np.array([lonlat[1]]))[0])


def _score(r: Mapping[str, Any], key: str) -> tuple[float, float, float]:
    """The row's ranking key: people above the ranking level, person-dB, peak dwelling level (None: lowest),
    each rounded to its step of :data:`TIE_STEPS`."""
    people = r["people_above"][key] if "people_above" in r else (r.get("residents_above") or {}).get(key, 0.0)
    peak = r.get("peak_dwelling_db")

    def step(v: float, s: float) -> float:
        return v if not math.isfinite(v) else math.floor(v / s + 0.5) * s

    return (step(float(people), TIE_STEPS[0]), step(float(r.get("person_db", 0.0)), TIE_STEPS[1]),
            -math.inf if peak is None else step(float(peak), TIE_STEPS[2]))


def rank_rows(rows: Sequence[dict[str, Any]], rank_key: str) -> list[dict[str, Any]]:
    """The rows best first (by :func:`_score`, then by name), each with ``rank`` (routes with equal scores share
    the rank, the next rank skips: 1, 1, 3) and ``tie`` (true when it shares its rank).  The order of the
    arguments never decides.

    Examples
    --------
    >>> rows = [{"route": "b", "people_above": {"55": 10.2}, "person_db": 3.0},
    ...         {"route": "a", "people_above": {"55": 9.9}, "person_db": 3.4},
    ...         {"route": "c", "people_above": {"55": 10.6}, "person_db": 0.0}]
    >>> [(r["route"], r["rank"], r["tie"]) for r in rank_rows(rows, "55")]
    [('a', 1, True), ('b', 1, True), ('c', 3, False)]
    """
    ranked = sorted(rows, key=lambda r: (_score(r, rank_key), str(r["route"])))
    for i, r in enumerate(ranked):
        same = i > 0 and _score(ranked[i - 1], rank_key) == _score(r, rank_key)
        r["rank"] = ranked[i - 1]["rank"] if same else i + 1
    counts: dict[int, int] = {}
    for r in ranked:
        counts[r["rank"]] = counts.get(r["rank"], 0) + 1
    for r in ranked:
        r["tie"] = counts[r["rank"]] > 1
    return ranked
