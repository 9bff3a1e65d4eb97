"""Flight patterns for the campaign simulator: a path builder sampled in time.

Kernel of :mod:`gisnoise.simulate.simulate`.  A flight is a sequence of patterns flown one
after the other from where the previous one ended; horizontal patterns are joined
by Dubins paths (turn - straight - turn at a fixed radius), so position and track
heading are continuous and every turn is a coordinated turn of known radius.

Headings are radians from north, clockwise positive; positions are local ENU metres
(``u`` is the height above the flat ground).  Forward is ``(sin h, cos h)`` in
``(e, n)``; a right turn increases the heading.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["PathBuilder", "G", "fwd", "right", "heading_of", "dubins_csc", "turn_then_straight"]

G = 9.80665
"""Standard gravity, m/s^2."""

_TWO_PI = 2.0 * math.pi


def fwd(h: float) -> np.ndarray:
    """Unit vector (e, n) along heading ``h`` (rad)."""
    return np.array([math.sin(h), math.cos(h)])


def right(h: float) -> np.ndarray:
    """Unit vector (e, n) to the right of heading ``h`` (rad)."""
    return np.array([math.cos(h), -math.sin(h)])


def heading_of(v: np.ndarray) -> float:
    """Heading (rad, from north clockwise) of the vector ``v = (e, n)``."""
    return math.atan2(float(v[0]), float(v[1]))


def _ccw_to(a: float, b: float) -> float:
    """Right-turn (heading-increasing) angle from ``a`` to ``b`` in [0, 2 pi)."""
    return (b - a) % _TWO_PI


@dataclass(frozen=True)
class Arc:
    """A turn: signed angle (rad, + right) at radius (m)."""

    angle: float
    radius: float

    @property
    def length(self) -> float:
        return abs(self.angle) * self.radius


@dataclass(frozen=True)
class Line:
    length: float


def dubins_csc(p0: np.ndarray, h0: float, p1: np.ndarray, h1: float, radius: float) -> list[Arc | Line]:
    """Shortest turn-straight-turn path from pose ``(p0, h0)`` to ``(p1, h1)``.

    Parameters
    ----------
    p0, p1 : ndarray, shape (2,)
        Start and end positions (e, n), m.
    h0, h1 : float
        Start and end headings, rad.
    radius : float
        Turn radius, m.

    Returns
    -------
    list of Arc and Line
        Segments with zero-length pieces dropped.

    Examples
    --------
    >>> segs = dubins_csc(np.zeros(2), 0.0, np.array([0.0, 100.0]), 0.0, 50.0)
    >>> [type(s).__name__ for s in segs], round(segs[0].length, 6)
    (['Line'], 100.0)
    """
    best: tuple[float, list[Arc | Line]] | None = None
    for s0 in (1, -1):  # +1 right, -1 left
        for s1 in (1, -1):
            c0 = p0 + s0 * radius * right(h0)
            c1 = p1 + s1 * radius * right(h1)
            v = c1 - c0
            dist = float(np.hypot(*v))
            if s0 == s1:
                if dist < 1e-9:
                    hs = h0
                    length = 0.0
                else:
                    hs = heading_of(v)
                    length = dist
            else:
                if dist < 2.0 * radius:
                    continue
                length = math.sqrt(dist * dist - 4.0 * radius * radius)
                alpha = math.atan2(2.0 * radius, length)
                # right-then-left: the centre line lies left of the straight
                hs = heading_of(v) + alpha if s0 == 1 else heading_of(v) - alpha
            a0 = _ccw_to(h0, hs) if s0 == 1 else -_ccw_to(hs, h0)
            a1 = _ccw_to(hs, h1) if s1 == 1 else -_ccw_to(h1, hs)
            total = radius * (abs(a0) + abs(a1)) + length
            if best is None or total < best[0] - 1e-9:
                best = (total, [Arc(a0, radius), Line(length), Arc(a1, radius)])
    assert best is not None  # same-direction paths always exist
    return [s for s in best[1] if s.length > 1e-9]


def turn_then_straight(p0: np.ndarray, h0: float, p1: np.ndarray, radius: float) -> list[Arc | Line]:
    """Shortest turn-straight path from pose ``(p0, h0)`` to the point ``p1`` (any final heading)."""
    best: tuple[float, list[Arc | Line]] | None = None
    for s in (1, -1):
        c = p0 + s * radius * right(h0)
        v = p1 - c
        dist = float(np.hypot(*v))
        if dist <= radius * (1.0 + 1e-9):
            continue
        length = math.sqrt(dist * dist - radius * radius)
        beta = math.atan2(radius, length)
        hs = heading_of(v) + beta if s == 1 else heading_of(v) - beta
        a = _ccw_to(h0, hs) if s == 1 else -_ccw_to(hs, h0)
        if abs(abs(a) - _TWO_PI) < 1e-9:
            a = 0.0
        total = radius * abs(a) + length
        if best is None or total < best[0]:
            best = (total, [Arc(a, radius), Line(length)])
    if best is None:  # the point is inside both turning circles: go straight past it first
        return [Line(2.0 * radius)] + turn_then_straight(p0 + 2.0 * radius * fwd(h0), h0, p1, radius)
    return [s for s in best[1] if s.length > 1e-9]


@dataclass
class PathBuilder:
    """Builds a sampled flight path pattern by pattern.

    The builder holds the current pose (``e``, ``n``, ``u`` m; ``heading`` rad),
    ground speed ``speed`` (m/s) and time ``t`` (s).  Each method appends samples
    at the rate ``1 / dt``; the last sample of a segment is the first of the next,
    so the joined path is continuous.

    Per sample it records time, position, track heading, ground speed, vertical
    speed, signed turn radius (``inf`` on straights; + right), an explicit yaw
    (NaN where yaw follows the track), the flight phase and the turn number
    (-1 when not turning).
    """

    e: float
    n: float
    u: float
    heading: float
    dt: float
    speed: float = 0.0
    t: float = 0.0
    cols: dict[str, list[np.ndarray]] = field(default_factory=dict)
    turns: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(t0, t1, radius m, speed m/s) of each coordinated turn."""
    phases: list[tuple[float, float, str]] = field(default_factory=list)
    _yaw: float = float("nan")

    # -------------------------------------------------------------- sampling
    def _times(self, duration: float) -> np.ndarray:
        k = max(1, int(math.ceil(duration / self.dt - 1e-9)))
        return np.linspace(0.0, duration, k + 1)[:-1]

    def _emit(self, s: np.ndarray, **arrays: np.ndarray | float | str) -> None:
        n = len(s)
        for k, v in arrays.items():
            a = np.full(n, v, dtype=object if isinstance(v, str) else float) if np.isscalar(v) else np.asarray(v)
            self.cols.setdefault(k, []).append(a)

    def _phase(self, t0: float, t1: float, phase: str) -> None:
        if self.phases and self.phases[-1][2] == phase and abs(self.phases[-1][1] - t0) < 1e-9:
            self.phases[-1] = (self.phases[-1][0], t1, phase)
        else:
            self.phases.append((t0, t1, phase))

    def finish(self) -> dict[str, np.ndarray]:
        """Close the path with its final sample and return the columns."""
        self._emit(np.zeros(1), t=self.t, e=self.e, n=self.n, u=self.u, track=self.heading,
                   speed=self.speed, vz=0.0, radius=math.inf, yaw=self._yaw,
                   phase=self.phases[-1][2] if self.phases else "hover", turn=-1.0)
        out = {k: np.concatenate(v) for k, v in self.cols.items()}
        out["phase"] = out["phase"].astype(str)
        return out

    # -------------------------------------------------------------- horizontal
    def line(self, length: float, speed: float, to_u: float | None = None, phase: str = "horizontal") -> None:
        """Straight flight of ``length`` m at ground ``speed`` m/s, height changing linearly to ``to_u``."""
        if length <= 0:
            return
        du = 0.0 if to_u is None else to_u - self.u
        dur = length / speed
        s = self._times(dur)
        f = fwd(self.heading)
        self._emit(s, t=self.t + s, e=self.e + f[0] * speed * s, n=self.n + f[1] * speed * s,
                   u=self.u + du * s / dur, track=self.heading, speed=speed, vz=du / dur,
                   radius=math.inf, yaw=math.nan, phase=phase, turn=-1.0)
        self._phase(self.t, self.t + dur, phase)
        self.e, self.n = self.e + f[0] * length, self.n + f[1] * length
        self.u += du
        self.t += dur
        self.speed = speed
        self._yaw = math.nan

    def arc(self, angle: float, radius: float, speed: float, to_u: float | None = None) -> None:
        """Coordinated turn through ``angle`` rad (+ right) at ``radius`` m and ground ``speed`` m/s."""
        if abs(angle) * radius <= 1e-9:
            return
        sign = 1.0 if angle > 0 else -1.0
        du = 0.0 if to_u is None else to_u - self.u
        dur = abs(angle) * radius / speed
        s = self._times(dur)
        c = np.array([self.e, self.n]) + sign * radius * right(self.heading)
        h = self.heading + sign * speed / radius * s
        pos = c[:, None] - sign * radius * np.stack([np.cos(h), -np.sin(h)])
        turn_no = float(len(self.turns))
        self._emit(s, t=self.t + s, e=pos[0], n=pos[1], u=self.u + du * s / dur, track=h, speed=speed,
                   vz=du / dur, radius=sign * radius, yaw=math.nan, phase="horizontal", turn=turn_no)
        self.turns.append((self.t, self.t + dur, radius, speed))
        self._phase(self.t, self.t + dur, "horizontal")
        h1 = self.heading + angle
        end = c - sign * radius * right(h1)
        self.e, self.n = float(end[0]), float(end[1])
        self.heading = float((h1 + math.pi) % _TWO_PI - math.pi)
        self.u += du
        self.t += dur
        self.speed = speed
        self._yaw = math.nan

    def segments(self, segs: list[Arc | Line], speed: float, to_u: float | None = None) -> None:
        """Fly Dubins segments, spreading the height change to ``to_u`` over their length."""
        total = sum(s.length for s in segs)
        u0 = self.u
        du = 0.0 if to_u is None else to_u - u0
        done = 0.0
        for s in segs:
            done += s.length
            target = u0 + du * done / total if total > 0 else None
            if isinstance(s, Arc):
                self.arc(s.angle, s.radius, speed, to_u=target)
            else:
                self.line(s.length, speed, to_u=target)

    def transition(self, duration: float, to_speed: float) -> None:
        """Straight flight along the heading with the ground speed changing linearly (phase ``transition``)."""
        v0 = self.speed
        s = self._times(duration)
        f = fwd(self.heading)
        dist = v0 * s + 0.5 * (to_speed - v0) / duration * s * s
        self._emit(s, t=self.t + s, e=self.e + f[0] * dist, n=self.n + f[1] * dist, u=self.u,
                   track=self.heading, speed=v0 + (to_speed - v0) * s / duration, vz=0.0, radius=math.inf,
                   yaw=math.nan, phase="transition", turn=-1.0)
        self._phase(self.t, self.t + duration, "transition")
        total = 0.5 * (v0 + to_speed) * duration
        self.e, self.n = self.e + f[0] * total, self.n + f[1] * total
        self.t += duration
        self.speed = to_speed
        self._yaw = math.nan

    # -------------------------------------------------------------- vertical
    def vertical(self, to_u: float, rate: float, yaw_rate: float = 0.0) -> None:
        """Vertical climb or sink to height ``to_u`` m at ``rate`` m/s (phase ``climb``/``sink``)."""
        du = to_u - self.u
        if abs(du) < 1e-9:
            return
        phase = "climb" if du > 0 else "sink"
        dur = abs(du) / rate
        self._hold(dur, phase, vz=du / dur, yaw_rate=yaw_rate)
        self.u = to_u

    def hover(self, duration: float, yaw_rate: float = 0.0) -> None:
        """Hold position for ``duration`` s, yawing at ``yaw_rate`` rad/s (phase ``hover``)."""
        self._hold(duration, "hover", vz=0.0, yaw_rate=yaw_rate)

    def _hold(self, dur: float, phase: str, vz: float, yaw_rate: float) -> None:
        s = self._times(dur)
        yaw0 = self.heading if math.isnan(self._yaw) else self._yaw
        self._emit(s, t=self.t + s, e=self.e, n=self.n, u=self.u + vz * s, track=self.heading, speed=0.0,
                   vz=vz, radius=math.inf, yaw=yaw0 + yaw_rate * s, phase=phase, turn=-1.0)
        self._phase(self.t, self.t + dur, phase)
        self.t += dur
        self.speed = 0.0
        self._yaw = float((yaw0 + yaw_rate * dur + math.pi) % _TWO_PI - math.pi)
        self.heading = self._yaw

    # -------------------------------------------------------------- patterns
    def approach(self, p: np.ndarray, heading: float | None, radius: float, speed: float, to_u: float,
                 max_climb_angle: float) -> None:
        """Fly to point ``p`` (with ``heading`` if given) and height ``to_u``.

        The height changes linearly along the path; when the path is too short for
        ``max_climb_angle`` (rad), full circles at ``radius`` are flown first to gain
        or lose the rest.
        """
        p0 = np.array([self.e, self.n])
        segs = (dubins_csc(p0, self.heading, p, heading, radius) if heading is not None
                else turn_then_straight(p0, self.heading, p, radius))
        length = sum(s.length for s in segs)
        du = to_u - self.u
        need = abs(du) / math.tan(max_climb_angle)
        if need > length:
            circles = int(math.ceil((need - length) / (_TWO_PI * radius)))
            u_mid = self.u + du * (1.0 - length / need) if length > 0 else to_u
            for _ in range(circles):
                self.arc(_TWO_PI, radius, speed, to_u=self.u + (u_mid - self.u) / (circles - _))
        self.segments(segs, speed, to_u=to_u)

    def racetrack(self, centre: np.ndarray, heading: float, straight: float, radius: float, heights: list[float],
                  laps: int, speed: float, turn: int, max_climb_angle: float) -> None:
        """Racetrack loops about ``centre``: straights of ``straight`` m along ``heading`` and back,
        joined by 180 degree coordinated turns of ``radius`` m to the right (``turn = +1``) or left (-1).

        ``laps`` laps are flown at each height of ``heights`` in turn; the climb to the next
        height takes the first straight and turn of its first lap.
        """
        entry = centre - 0.5 * straight * fwd(heading) - turn * radius * right(heading)
        self.approach(entry, heading, radius, speed, heights[0], max_climb_angle)
        for k, height in enumerate(heights):
            for lap in range(laps):
                first = lap == 0 and k > 0
                mid = self.u + (height - self.u) * straight / (straight + math.pi * radius)
                self.line(straight, speed, to_u=mid if first else None)
                self.arc(turn * math.pi, radius, speed, to_u=height if first else None)
                self.line(straight, speed)
                self.arc(turn * math.pi, radius, speed)

    def flyby(self, through: np.ndarray, heading: float, length: float, radius: float, height: float,
              speed: float, max_climb_angle: float) -> None:
        """A straight pass of ``length`` m centred on ``through`` along ``heading`` at ``height`` m."""
        start = through - 0.5 * length * fwd(heading)
        self.approach(start, heading, radius, speed, height, max_climb_angle)
        self.line(length, speed)
