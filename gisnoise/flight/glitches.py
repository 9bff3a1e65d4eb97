"""Position glitches: samples no UAV can be at, mended where the track around them tells where it was.

A GNSS receiver can report a fix kilometres off for a moment (multipath, a cold start, a reset), and a
log damaged inside its messages can hold a fix at latitude 0, longitude 0.  Mapped as read, such a sample
makes a noise island where nothing flew (one instant, loud enough for an LAmax spot), or stretches the
grid over half the globe.  Physics fixes the test: between two consecutive samples a vehicle of the
product's class moves at most :data:`gisnoise.limits.MAX_UAV_SPEED_M_S` times the time between them.

:func:`mend_glitches` walks the segments that break that bound.  From the last sample before such a
segment it looks for the first later sample it could reach at that speed, within
:data:`GLITCH_MAX_S`: the samples between are a glitch, and their positions are replaced by the straight,
uniform flight between those two samples (their other fields, attitude and power, stay as logged).  A
glitch at the track's start or end, with no sample beyond it to reach, takes the nearest good position
(of the two sides of the jump, the one with fewer samples, lasting at most :data:`GLITCH_MAX_S`).
A jump after which the track does not come back within :data:`GLITCH_MAX_S` (an estimator's position
reset, or two tracks joined) cannot be mended from the flight: which side is right is not known, so the
track is kept as logged on both sides and the warning names the jump (where, how far), for the user to
judge the map there.  Samples that are not glitches keep their positions bit for bit.

The readers of flight logs mend the positions on their time base before the phase and the on-ground
samples are derived from them; flight CSVs and timed GeoJSON paths are mended as they are read.  The
trajectory's metadata lists the glitches (``position_glitches``: times on its own clock, the jump and
its speed) and the jumps kept (``position_jumps``), from which :func:`glitch_warning` makes the one-line
warning every map, fit and diagnosis shows (through :func:`gisnoise.flight.track_warning`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.geo import LocalFrame
from gisnoise.limits import MAX_UAV_SPEED_M_S, current

__all__ = ["GLITCH_MAX_S", "Glitches", "glitch_warning", "mend_glitches", "step_lengths"]

GLITCH_MAX_S = 10.0
"""Longest glitch mended, s: a track that stays away longer is refused (the flight there is not known)."""


@dataclass(frozen=True)
class Glitches:
    """What :func:`mend_glitches` found: ``runs`` as ``(first, end)`` sample indices (``end`` exclusive), the
    largest jump into or out of each (m) and its speed (m/s); ``jumps`` kept as logged, as ``(i, jump, speed)``
    (between samples ``i`` and ``i + 1``); ``lat``, ``lon``, ``h`` the mended positions."""

    runs: tuple[tuple[int, int, float, float], ...]
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    jumps: tuple[tuple[int, float, float], ...] = ()

    def metadata(self, t: Any) -> dict[str, Any]:
        """The trajectory's ``position_glitches`` and ``position_jumps`` (those there are) on its clock ``t``
        (s; the reader's time base shifted)."""
        tt = np.asarray(t, dtype=float)
        out: dict[str, Any] = {}
        if self.runs:
            out["position_glitches"] = [
                {"t_first_s": float(tt[i0]), "t_last_s": float(tt[i1 - 1]), "samples": int(i1 - i0),
                 "jump_m": round(jump, 1), "speed_m_s": round(speed, 1)} for i0, i1, jump, speed in self.runs]
        if self.jumps:
            out["position_jumps"] = [{"t_s": float(tt[i]), "t_next_s": float(tt[i + 1]), "jump_m": round(jump, 1),
                                      "speed_m_s": round(speed, 1)} for i, jump, speed in self.jumps]
        return out


def mend_glitches(t: Any, lat: Any, lon: Any, h: Any) -> Glitches:
    """Find and mend the position glitches of a track (see the module docstring).

    ``t`` in s, increasing; ``lat``, ``lon`` in deg, ``h`` in m.  A track with fewer than three samples, a
    non-finite value, times that do not increase or a position outside the limits (latitude, longitude,
    :mod:`gisnoise.limits` heights) is returned as it is (the trajectory's own checks refuse those, naming
    them).

    >>> t = np.arange(6.0)
    >>> lat = np.full(6, 52.0); lon = 10.0 + 1e-4 * t; lon[3] = 11.0   # one fix 68 km east, for one second
    >>> g = mend_glitches(t, lat, lon, np.full(6, 100.0))
    >>> [r[:2] for r in g.runs], round(float(g.lon[3]), 6)
    ([(3, 4)], 10.0003)
    """
    t, lat, lon, h = (np.asarray(a, dtype=float) for a in (t, lat, lon, h))
    same = Glitches((), lat, lon, h)
    n = t.size
    if n < 3 or not all(np.all(np.isfinite(a)) for a in (t, lat, lon, h)) or np.any(np.diff(t) <= 0):
        return same
    lim = current()
    if (np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 180.0) or np.any(h < lim.min_height_m)
            or np.any(h > lim.max_height_m)):
        return same  # a value out of range is refused by the trajectory's checks, naming it, not mended
    if not _may_be_fast(t, lat, lon, h):
        return same
    frame, p, step = step_lengths(lat, lon, h)
    fast = np.flatnonzero(step > MAX_UAV_SPEED_M_S * np.diff(t))
    if fast.size == 0:
        return same

    def reach(i: int, j: int) -> bool:  # sample j within the speed bound of sample i
        return bool(np.linalg.norm(p[j] - p[i]) <= MAX_UAV_SPEED_M_S * abs(t[j] - t[i]))

    runs: list[tuple[int, int, float, float]] = []
    jumps: list[tuple[int, float, float]] = []
    k = 0
    while True:
        nxt = fast[fast >= k]
        if nxt.size == 0:
            break
        a = int(nxt[0])  # the segment a -> a + 1 breaks the bound: a is the last good sample
        end = None
        for j in range(a + 2, n):  # the run a + 1 .. j - 1 lasts t[j - 1] - t[a + 1]
            if t[j - 1] - t[a + 1] > GLITCH_MAX_S:
                break
            if reach(a, j):
                end = j
                break
        # else the track starts in the glitch (samples 0 .. a) or ends in it (a + 1 ..): the shorter side
        ends = [(i1 - i0, i0, i1) for i0, i1 in ((0, a + 1), (a + 1, n))
                if t[i1 - 1] - t[i0] <= GLITCH_MAX_S and not (i0 == 0 and runs)]
        if end is not None:
            i0, i1 = a + 1, end
        elif ends:
            _, i0, i1 = min(ends)
        else:  # kept as logged, and said
            jumps.append((a, float(step[a]), float(step[a] / (t[a + 1] - t[a]))))
            k = a + 1
            continue
        edges = [s for s in (i0 - 1, i1 - 1) if 0 <= s < n - 1]
        jump = max(float(step[s]) for s in edges)
        speed = max(float(step[s] / (t[s + 1] - t[s])) for s in edges)
        runs.append((i0, i1, jump, speed))
        k = i1
    lat, lon, h = lat.copy(), lon.copy(), h.copy()
    for i0, i1, _, _ in runs:
        idx = np.arange(i0, i1)
        if i0 == 0 or i1 == n:  # held at the nearest good sample, as logged
            g = i1 if i0 == 0 else i0 - 1
            lat[idx], lon[idx], h[idx] = lat[g], lon[g], h[g]
            continue
        f = ((t[idx] - t[i0 - 1]) / (t[i1] - t[i0 - 1]))[:, None]
        q = p[i0 - 1] + f * (p[i1] - p[i0 - 1])
        lat[idx], lon[idx], h[idx] = frame.to_wgs84(q[:, 0], q[:, 1], q[:, 2])
    return Glitches(tuple(runs), lat, lon, h, tuple(jumps))


_R_CURVATURE_MAX_M = 6_399_593.6
"""The WGS84 ellipsoid's largest radius of curvature (meridional and prime vertical, at the poles), m."""


def step_lengths(lat: Any, lon: Any, h: Any) -> tuple[LocalFrame, np.ndarray, np.ndarray]:
    """A local frame at a track's median point, the track's positions in it, m (shape (n, 3)), and the straight
    distance between consecutive samples, m (shape (n - 1,))."""
    lat, lon, h = (np.asarray(a, dtype=float) for a in (lat, lon, h))
    frame = LocalFrame(float(np.median(lat)), float(np.median(lon)), float(np.median(h)))
    p = np.stack(frame.to_enu(lat, lon, h), axis=-1)
    return frame, p, np.linalg.norm(np.diff(p, axis=0), axis=1)


def _may_be_fast(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray) -> bool:
    """Whether some step of the track may break the speed bound, from an upper bound of each step's length: the
    path along the meridian, then the parallel, then the vertical is no shorter than the straight step, and its
    arcs are no longer than (largest radius of curvature + highest height) times their angle.  The local frame,
    which costs more than the rest, is then needed only for tracks that may hold a glitch."""
    r = _R_CURVATURE_MAX_M + max(float(np.max(h)), 0.0)
    dlat = np.radians(np.abs(np.diff(lat)))
    dlon = np.radians(np.abs(np.diff(lon)))
    dlon = np.minimum(dlon, 2.0 * np.pi - dlon)  # across the antimeridian
    bound = r * (dlat + dlon) + np.abs(np.diff(h))
    return bool(np.any(bound > MAX_UAV_SPEED_M_S * np.diff(t)))


def glitch_warning(traj: Any) -> str | None:
    """The one-line warning for a trajectory whose position glitches were mended (its ``metadata
    ["position_glitches"]``); None when there were none."""
    meta = traj.metadata if isinstance(traj.metadata, Mapping) else {}
    runs, jumps = meta.get("position_glitches") or [], meta.get("position_jumps") or []
    said = []
    if runs:
        said.append(_mended(traj.source, runs))
    for j in jumps[:3]:
        said.append(f"{traj.source}: the position jumps {j['jump_m']:,.0f} m between t = {j['t_s']:.2f} and "
                    f"{j['t_next_s']:.2f} s ({j['speed_m_s']:,.0f} m/s, faster than any UAV flies) and does not come "
                    f"back within {GLITCH_MAX_S:g} s: a position reset or two tracks joined, kept as logged on both "
                    "sides (one of them is off by the jump)")
    if len(jumps) > 3:
        said.append(f"{traj.source}: {len(jumps) - 3} more such jumps")
    return "; ".join(said) if said else None


def _mended(source: str, runs: list[Mapping[str, Any]]) -> str:
    worst = max(runs, key=lambda r: r["jump_m"])

    def span(r: Mapping[str, Any]) -> str:
        a, b = f"{r['t_first_s']:.1f}", f"{r['t_last_s']:.1f}"
        return f"t = {a} s" if a == b else f"t = {a}-{b} s"

    when = ", ".join(span(r) for r in runs[:3]) + (f" and {len(runs) - 3} more" if len(runs) > 3 else "")
    n = sum(r["samples"] for r in runs)
    what = (f"{n} sample{'s' if n != 1 else ''} in {len(runs)} position glitches" if len(runs) > 1 else
            f"{n} sample{'s' if n != 1 else ''} in a position glitch")
    return (f"{source}: {what} ({when}; a jump of up to {worst['jump_m']:,.0f} m at {worst['speed_m_s']:,.0f} "
            f"m/s, faster than any UAV flies) mended: there the track runs straight between the samples around it")
