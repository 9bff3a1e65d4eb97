"""Waypoint routes: a route plan flown into a time-stamped trajectory, and the route settings.

A route plan (:func:`route_from_waypoints`; :func:`gisnoise.flight.routes.read_route`
reads it from files) is either a JSON document::

    {"schema": "gisnoise/waypoints/1",
     "altitude_reference": "agl",        # agl (default) | msl | ellipsoid
     "ground_h_m": 0.0,                  # flat ground (ellipsoidal m) for agl without DEM
     "geoid_undulation_m": null,         # msl -> ellipsoidal: h = alt + N (null: the EGM96 grid, gisnoise.geo.geoid)
     "sample_dt_s": 0.5,
     "vehicle": {"mass_kg": 35, "cruise_speed_m_s": 25, ...},   # VehicleModel fields
     "waypoints": [{"lon": .., "lat": .., "alt": .., "speed": .., "phase": .., "hold_s": ..,
                    "heading_deg": ..}, ...]}

or a GeoJSON ``FeatureCollection`` of ``Point`` features in flight order (properties
as the waypoint entries; ``alt`` defaults to the third coordinate) with the settings
in a foreign member ``"route": {...}``; or a GeoJSON ``LineString`` without times (its
vertices are the waypoints; ``properties.speed`` a number or one per vertex).

How waypoints are flown (the model, stated):

* A leg between two waypoints less than 2 m apart horizontally is flown in multicopter
  mode, vertically (phase ``climb`` or ``sink``), with a trapezoidal speed profile
  (climb or sink rate, vertical acceleration).  A waypoint's ``phase`` of ``climb``,
  ``sink`` or ``hover`` makes its incoming leg a straight multicopter leg of that phase
  at ``multicopter_speed_m_s``.
* Consecutive other legs form a wing-borne section: straight legs joined by
  coordinated fly-by turns of radius ``R = v^2 / (g tan(max_bank))`` (smaller when the
  legs are short, with the speed then limited to ``sqrt(g R tan(max_bank))``); bank
  ``phi = atan(v^2 / (g R))`` (right turn positive), heading along the track (no wind),
  pitch = flight-path angle; altitude linear in path length between waypoints.  The
  speed of a leg is its end waypoint's ``speed`` (default cruise speed); it changes
  with the longitudinal acceleration.  A section that follows or precedes a multicopter
  leg or a hold starts or ends at rest: the speed ramps between 0 and cruise; below
  ``transition_speed_m_s`` the phase is ``transition``, above it ``horizontal``.  A
  route that starts or ends with a wing-borne leg starts or ends at its leg speed
  (already flying).
* ``hold_s`` at a waypoint hovers there (phase ``hover``).
* Electric power from the vehicle power model (:class:`~gisnoise.flight.vehicle.VehicleModel`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.errors import TrajectoryError
from gisnoise.flight._logkernels import msl_height_datum, msl_to_ellipsoid_undulation
from gisnoise.flight.phases import MULTICOPTER_PHASES, PHASES
from gisnoise.flight.trajectory import Trajectory
from gisnoise.flight.vehicle import GRAVITY, VehicleModel
from gisnoise.geo import LocalFrame, wrap_angle
from gisnoise.limits import check_heights, check_range, check_samples, current

__all__ = ["Route", "route_from_waypoints", "WAYPOINTS_SCHEMA"]

WAYPOINTS_SCHEMA = "gisnoise/waypoints/1"
_WP_PREFIX = "gisnoise/waypoints/"
_VERTICAL_TOL_M = 2.0
_ALT_REFS = ("agl", "msl", "ellipsoid")


@dataclass(frozen=True, eq=False)
class Route:
    """A trajectory and what its source says about the ground.

    Attributes
    ----------
    trajectory : Trajectory
    ground_h_m : float or None
        Ellipsoidal height of flat ground stated by the source (waypoints with AGL
        altitudes and no DEM), else None.
    """

    trajectory: Trajectory
    ground_h_m: float | None = None


def _settings(doc: Mapping[str, Any], source: str, vehicle: VehicleModel | None) -> dict[str, Any]:
    if not isinstance(doc, Mapping):
        raise TrajectoryError(f"{source}: route settings must be an object", field="route")
    ref = doc.get("altitude_reference", "agl")
    if ref not in _ALT_REFS:
        raise TrajectoryError(f"{source}: field 'altitude_reference' must be one of {', '.join(_ALT_REFS)}, "
                              f"got {ref!r}", field="altitude_reference")
    out: dict[str, Any] = {"altitude_reference": ref}
    out["geoid_undulation_m"] = None   # msl: None takes N from the geoid grid at each waypoint
    for k, default in (("ground_h_m", 0.0), ("geoid_undulation_m", None), ("sample_dt_s", 0.5)):
        v = doc.get(k, default)
        if v is None and default is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise TrajectoryError(f"{source}: field '{k}' must be a number, got {v!r}", field=k)
        out[k] = float(v)
    if not 0 < out["sample_dt_s"] <= 10:
        raise TrajectoryError(f"{source}: field 'sample_dt_s' must be in (0, 10] s, got {out['sample_dt_s']}",
                              field="sample_dt_s")
    out["vehicle"] = vehicle or VehicleModel.from_dict(doc.get("vehicle"))
    return out


def _heights(alt: np.ndarray, lon: np.ndarray, lat: np.ndarray, st: Mapping[str, Any], dem: Any,
             dem_offset_m: float, source: str) -> tuple[np.ndarray, float | None, dict[str, Any]]:
    """Ellipsoidal heights of altitudes, the flat ground height the source states (or None), and for heights
    above mean sea level the geoid metadata (:func:`~gisnoise.flight._logkernels.msl_to_ellipsoid_undulation`)."""
    ref = st["altitude_reference"]
    if ref == "ellipsoid":
        return alt, None, {}
    if ref == "msl":
        n, meta = msl_to_ellipsoid_undulation(lat, lon, st.get("geoid_undulation_m"),
                                              what=f"{source}: altitude_reference 'msl'")
        return alt + n, None, {"height_datum": msl_height_datum("alt", meta), **meta}
    if dem is None:
        return alt + st["ground_h_m"], st["ground_h_m"], {}
    from gisnoise.geo import Dem, read_dem, sample_dem

    d = dem if isinstance(dem, Dem) else read_dem(dem)
    g = sample_dem(d, lon, lat) + float(dem_offset_m)
    bad = ~np.isfinite(g)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise TrajectoryError(f"{source}: waypoint {i} ({lon[i]:.6f}, {lat[i]:.6f}) lies outside the DEM; "
                              "AGL altitudes need the ground there", field="alt")
    return alt + g, None, {}


def _num(v: Any, name: str, source: str, i: int) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TrajectoryError(f"{source}: waypoint {i}: field '{name}' must be a number, got {v!r}", field=name)
    return float(v)


@dataclass
class _Wp:
    e: float
    n: float
    u: float
    speed: float | None
    phase: str | None
    hold_s: float
    heading: float | None  # rad


@dataclass
class _Dense:
    """Densely sampled states of one piece of the route."""

    t: list[np.ndarray] = field(default_factory=list)
    e: list[np.ndarray] = field(default_factory=list)
    n: list[np.ndarray] = field(default_factory=list)
    u: list[np.ndarray] = field(default_factory=list)
    yaw: list[np.ndarray] = field(default_factory=list)
    pitch: list[np.ndarray] = field(default_factory=list)
    roll: list[np.ndarray] = field(default_factory=list)
    power: list[np.ndarray] = field(default_factory=list)
    speed: list[np.ndarray] = field(default_factory=list)
    phase: list[np.ndarray] = field(default_factory=list)

    @property
    def t_end(self) -> float:
        return float(self.t[-1][-1]) if self.t else 0.0

    def add(self, t: np.ndarray, **kw: Any) -> None:
        if self.t:  # drop a repeated joint instant
            keep = t > self.t_end + 1e-9
            t = t[keep]
            kw = {k: (np.broadcast_to(v, keep.shape)[keep]) for k, v in kw.items()}
        else:
            kw = {k: np.broadcast_to(v, t.shape) for k, v in kw.items()}
        if t.size == 0:
            return
        self.t.append(t)
        for k, v in kw.items():
            getattr(self, k).append(np.asarray(v))

    def cat(self, name: str) -> np.ndarray:
        return np.concatenate(getattr(self, name))


def route_from_waypoints(waypoints: Sequence[Mapping[str, Any]], settings: Mapping[str, Any] | None = None, *,
                         source: str = "waypoints", dem: Any = None, dem_offset_m: float = 0.0,
                         vehicle: VehicleModel | None = None) -> Route:
    """Fly a list of waypoints (see the module docstring) into a time-stamped trajectory.

    Parameters
    ----------
    waypoints : sequence of dict
        ``lon``, ``lat`` (deg), ``alt`` (m), optional ``speed`` (m/s), ``phase``,
        ``hold_s`` (s), ``heading_deg`` (deg, for multicopter legs and holds).
    settings : dict, optional
        ``altitude_reference``, ``ground_h_m``, ``geoid_undulation_m``, ``sample_dt_s``,
        ``vehicle``.

    Returns
    -------
    Route
        Samples every ``sample_dt_s`` from t = 0 and at the end.
    """
    st = _settings(settings or {}, source, vehicle)
    veh: VehicleModel = st["vehicle"]
    if len(waypoints) < 2:
        raise TrajectoryError(f"{source}: a route needs at least two waypoints, got {len(waypoints)}",
                              field="waypoints")
    lon = np.empty(len(waypoints))
    lat = np.empty(len(waypoints))
    alt = np.empty(len(waypoints))
    extra = []
    for i, wp in enumerate(waypoints):
        if not isinstance(wp, Mapping):
            raise TrajectoryError(f"{source}: waypoint {i} must be an object", field="waypoints")
        for name, arr in (("lon", lon), ("lat", lat), ("alt", alt)):
            if name not in wp:
                raise TrajectoryError(f"{source}: waypoint {i} lacks field '{name}'", field=name)
            arr[i] = _num(wp[name], name, source, i)
        # the shared rule set: latitude within -90..90 deg, longitude within -180..180 deg, never wrapped
        check_range("lat", lat[i], -90.0, 90.0, unit="deg", source=f"{source}: waypoint {i}", error=TrajectoryError)
        check_range("lon", lon[i], -180.0, 180.0, unit="deg", source=f"{source}: waypoint {i}", error=TrajectoryError,
                    why="longitudes are not wrapped")
        speed = wp.get("speed")
        if speed is not None:
            speed = _num(speed, "speed", source, i)
            if speed <= 0:
                raise TrajectoryError(f"{source}: waypoint {i}: field 'speed' must be > 0, got {speed}",
                                      field="speed")
        phase = wp.get("phase")
        if phase is not None and phase not in PHASES:
            raise TrajectoryError(f"{source}: waypoint {i}: field 'phase' must be one of {', '.join(PHASES)}, "
                                  f"got {phase!r}", field="phase")
        hold = _num(wp.get("hold_s", 0.0), "hold_s", source, i)
        if hold < 0:
            raise TrajectoryError(f"{source}: waypoint {i}: field 'hold_s' must be >= 0", field="hold_s")
        check_range("hold_s", hold, 0.0, current().max_duration_s, unit="s", source=f"{source}: waypoint {i}",
                    error=TrajectoryError)
        hd = wp.get("heading_deg")
        hd = None if hd is None else math.radians(_num(hd, "heading_deg", source, i))
        extra.append((speed, phase, hold, hd))
    h, ground, datum = _heights(alt, lon, lat, st, dem, dem_offset_m, source)
    check_heights(h, field="alt", source=f"{source}: waypoints", error=TrajectoryError)  # before any geometry
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0] - alt[0]) if st["altitude_reference"] == "agl"
                       else float(h.min()))
    e, n, u = frame.to_enu(lat, lon, h)
    wps = [_Wp(float(e[i]), float(n[i]), float(u[i]), *extra[i]) for i in range(len(waypoints))]

    dense = _fly(wps, veh)
    t = dense.cat("t")
    dt = st["sample_dt_s"]
    check_samples(t[-1] / dt + 2, field="sample_dt_s", what="route")  # before allocating
    t_out = np.arange(0.0, t[-1], dt)
    if t[-1] - t_out[-1] > 1e-6:
        t_out = np.append(t_out, t[-1])
    ee, nn, uu = (np.interp(t_out, t, dense.cat(k)) for k in ("e", "n", "u"))
    yaw = dense.cat("yaw")
    yaw_o = np.arctan2(np.interp(t_out, t, np.sin(yaw)), np.interp(t_out, t, np.cos(yaw)))
    # a sample between two dense instants belongs to the motion ending at the later one
    idx = np.clip(np.searchsorted(t, t_out, side="left"), 0, t.size - 1)
    lat_o, lon_o, h_o = frame.to_wgs84(ee, nn, uu)
    traj = Trajectory(
        t=t_out, lat=lat_o, lon=lon_o, h=h_o,
        roll=np.degrees(np.interp(t_out, t, dense.cat("roll"))),
        pitch=np.degrees(np.interp(t_out, t, dense.cat("pitch"))),
        yaw=np.degrees(yaw_o), power_w=np.interp(t_out, t, dense.cat("power")),
        phase=dense.cat("phase")[idx], airspeed_m_s=np.interp(t_out, t, dense.cat("speed")),
        source=source, metadata=datum)
    return Route(traj, ground)


def _leg_kinds(wps: Sequence[_Wp]) -> list[str]:
    kinds = []
    for a, b in zip(wps[:-1], wps[1:], strict=True):
        dh = math.hypot(b.e - a.e, b.n - a.n)
        if b.phase in MULTICOPTER_PHASES or dh < _VERTICAL_TOL_M:
            kinds.append("multi")
        else:
            kinds.append("forward")
    return kinds


def _fly(wps: Sequence[_Wp], veh: VehicleModel) -> _Dense:
    kinds = _leg_kinds(wps)
    nleg = len(kinds)
    # heading for multicopter legs and holds: the course of the nearest wing-borne leg
    courses = [math.atan2(b.e - a.e, b.n - a.n) for a, b in zip(wps[:-1], wps[1:], strict=True)]
    fwd = [i for i, k in enumerate(kinds) if k == "forward"]

    def heading_near(leg: int, wp: _Wp | None = None) -> float:
        if wp is not None and wp.heading is not None:
            return wp.heading
        if not fwd:
            return 0.0
        nxt = [i for i in fwd if i >= leg]
        return courses[nxt[0]] if nxt else courses[fwd[-1]]

    dense = _Dense()
    heading = heading_near(0, wps[0])
    _hold(dense, wps[0], wps[0].hold_s, heading, veh)
    i = 0
    while i < nleg:
        if kinds[i] == "multi":
            heading = heading_near(i, wps[i + 1])
            _multicopter_leg(dense, wps[i], wps[i + 1], heading, veh)
            _hold(dense, wps[i + 1], wps[i + 1].hold_s, heading, veh)
            i += 1
            continue
        j = i
        while j + 1 < nleg and kinds[j + 1] == "forward" and wps[j + 1].hold_s == 0:
            j += 1
        start_rest = i > 0 and (kinds[i - 1] == "multi" or wps[i].hold_s > 0)
        end_rest = (j + 1 < nleg and kinds[j + 1] == "multi") or wps[j + 1].hold_s > 0
        if i == 0 and wps[0].hold_s > 0:
            start_rest = True
        heading = _forward_section(dense, wps[i:j + 2], veh, start_rest, end_rest)
        _hold(dense, wps[j + 1], wps[j + 1].hold_s, heading, veh)
        i = j + 1
    if not dense.t:
        raise TrajectoryError("waypoints: the route has no length and no hold", field="waypoints")
    return dense


def _hold(dense: _Dense, wp: _Wp, hold_s: float, heading: float, veh: VehicleModel) -> None:
    if hold_s <= 0:
        return
    t0 = dense.t_end
    check_samples(hold_s / 0.1, field="hold_s", what="hold", dense=True)
    t = t0 + np.linspace(0.0, hold_s, max(2, int(math.ceil(hold_s / 0.1)) + 1))
    dense.add(t, e=wp.e, n=wp.n, u=wp.u, yaw=heading, pitch=0.0, roll=0.0, power=veh.hover_power_w(),
              speed=0.0, phase="hover")


def _trapezoid_profile(dist: float, vmax: float, acc: float, dt: float = 0.1) -> tuple[np.ndarray, np.ndarray,
                                                                                      np.ndarray]:
    """Times, distance and speed of a rest-to-rest move of ``dist`` m (trapezoidal speed)."""
    if dist <= 0:
        return np.zeros(1), np.zeros(1), np.zeros(1)
    v = min(vmax, math.sqrt(acc * dist))
    ta = v / acc
    tc = (dist - v * ta) / v
    total = 2 * ta + tc
    check_samples(total / dt, field="speed", what="leg", dense=True)
    t = np.linspace(0.0, total, max(3, int(math.ceil(total / dt)) + 1))
    s = np.where(t < ta, 0.5 * acc * t ** 2,
                 np.where(t < ta + tc, 0.5 * acc * ta ** 2 + v * (t - ta),
                          dist - 0.5 * acc * np.maximum(total - t, 0.0) ** 2))
    sp = np.where(t < ta, acc * t, np.where(t < ta + tc, v, acc * np.maximum(total - t, 0.0)))
    return t, s, sp


def _multicopter_leg(dense: _Dense, a: _Wp, b: _Wp, heading: float, veh: VehicleModel) -> None:
    d = np.array([b.e - a.e, b.n - a.n, b.u - a.u])
    dist = float(np.linalg.norm(d))
    if dist < 1e-6:
        return
    dh = math.hypot(d[0], d[1])
    limits = []
    if abs(d[2]) > 1e-9:
        rate = veh.climb_rate_m_s if d[2] > 0 else veh.sink_rate_m_s
        if b.speed is not None and dh < _VERTICAL_TOL_M:
            rate = b.speed
        limits.append(rate * dist / abs(d[2]))
    if dh > 1e-9:
        limits.append((b.speed or veh.multicopter_speed_m_s) * dist / dh)
    t, s, sp = _trapezoid_profile(dist, min(limits), veh.vertical_acceleration_m_s2)
    unit = d / dist
    w = sp * unit[2]
    phase = b.phase if b.phase in MULTICOPTER_PHASES else ("climb" if d[2] > 0 else "sink")
    if b.phase is None and abs(d[2]) < 0.5:
        phase = "hover"
    yaw = math.atan2(d[0], d[1]) if dh >= _VERTICAL_TOL_M else heading
    power = veh.rotor_power_w(veh.weight_n, w) + veh.systems_power_w
    dense.add(dense.t_end + t, e=a.e + s * unit[0], n=a.n + s * unit[1], u=a.u + s * unit[2], yaw=yaw,
              pitch=0.0, roll=0.0, power=power, speed=sp, phase=phase)


def _rate_limited(q: np.ndarray, c: float) -> np.ndarray:
    """``q[i] = min(q[i], q[i - 1] + c)`` in order, at once: ``min over j <= i of q[j] + c (i - j)``.

    >>> _rate_limited(np.array([0.0, 9.0, 9.0, 1.0, 9.0]), 2.0).tolist()
    [0.0, 2.0, 4.0, 1.0, 3.0]
    """
    ci = c * np.arange(q.size)
    return ci + np.minimum.accumulate(q - ci)


def _forward_section(dense: _Dense, wps: Sequence[_Wp], veh: VehicleModel, start_rest: bool,
                     end_rest: bool) -> float:
    """Fly wing-borne through ``wps`` with fly-by turns; returns the final course (rad)."""
    g = GRAVITY
    tan_b = math.tan(math.radians(veh.max_bank_deg))
    p = np.array([[w.e, w.n] for w in wps])
    legs = np.diff(p, axis=0)
    length = np.hypot(legs[:, 0], legs[:, 1])
    course = np.arctan2(legs[:, 0], legs[:, 1])
    vleg = np.array([w.speed or veh.cruise_speed_m_s for w in wps[1:]])
    m = len(legs)
    # fly-by fillets at interior waypoints
    tang = np.zeros(m + 1)
    radius = np.full(m + 1, np.inf)
    turn = np.zeros(m + 1)
    for k in range(1, m):
        dchi = float(wrap_angle(course[k] - course[k - 1]))
        if abs(dchi) < 1e-6:
            continue
        turn[k] = dchi
        r0 = min(vleg[k - 1], vleg[k]) ** 2 / (g * tan_b)
        tmax = 0.5 * min(length[k - 1], length[k])
        r = min(r0, tmax / math.tan(abs(dchi) / 2.0))
        radius[k] = r
        tang[k] = r * math.tan(abs(dchi) / 2.0)
    # primitives: (kind, s0, s1, data)
    prims: list[tuple[str, float, float, Any]] = []
    s_wp = np.zeros(m + 1)
    s = 0.0
    for k in range(m):
        start = p[k] + tang[k] * np.array([math.sin(course[k]), math.cos(course[k])])
        ln = length[k] - tang[k] - tang[k + 1]
        if ln > 1e-9:
            prims.append(("line", s, s + ln, (start, course[k], vleg[k])))
            s += ln
        if k + 1 < m and radius[k + 1] < np.inf:
            r = radius[k + 1]
            arc = r * abs(turn[k + 1])
            a0 = p[k + 1] - tang[k + 1] * np.array([math.sin(course[k]), math.cos(course[k])])
            sig = math.copysign(1.0, turn[k + 1])
            vlim = min(vleg[k], vleg[k + 1], math.sqrt(g * r * tan_b))
            prims.append(("arc", s, s + arc, (a0, course[k], sig, r, vlim)))
            s_wp[k + 1] = s + 0.5 * arc
            s += arc
        else:
            s_wp[k + 1] = s
    total = s
    s_wp[-1] = total
    if total <= 0:
        return float(course[-1]) if m else 0.0
    check_samples(total / 0.5 + 1.0, field="waypoints", what="path", dense=True)  # a non-finite length too
    ns = max(3, math.ceil(total / 0.5) + 1)
    sg = np.linspace(0.0, total, ns)
    ds = sg[1] - sg[0]
    vlim = np.full(ns, np.inf)
    kappa = np.zeros(ns)
    chi = np.zeros(ns)
    pe = np.zeros(ns)
    pn = np.zeros(ns)
    for kind, s0, s1, data in prims:
        sel = (sg >= s0 - 1e-9) & (sg <= s1 + 1e-9)
        q = sg[sel] - s0
        if kind == "line":
            start, c, v = data
            pe[sel] = start[0] + q * math.sin(c)
            pn[sel] = start[1] + q * math.cos(c)
            chi[sel] = c
            vlim[sel] = np.minimum(vlim[sel], v)
        else:
            a0, c0, sig, r, v = data
            cc = c0 + sig * q / r
            rn0 = np.array([math.cos(c0), -math.sin(c0)])
            centre = a0 + sig * r * rn0
            pe[sel] = centre[0] - sig * r * np.cos(cc)
            pn[sel] = centre[1] + sig * r * np.sin(cc)
            chi[sel] = cc
            kappa[sel] = sig / r
            vlim[sel] = np.minimum(vlim[sel], v)
    vlim = np.where(np.isfinite(vlim), vlim, veh.cruise_speed_m_s)
    u_s = np.interp(sg, s_wp, [w.u for w in wps])
    acc = veh.acceleration_m_s2
    v = vlim.copy()
    if start_rest:
        v[0] = 0.0
    # speed limited by the acceleration forwards and backwards: v[i] = min(v[i], sqrt(v[i -+ 1]^2 + 2 acc ds))
    v = np.sqrt(_rate_limited(v * v, 2 * acc * ds))
    if end_rest:
        v[-1] = 0.0
    v = np.sqrt(_rate_limited((v * v)[::-1], 2 * acc * ds))[::-1]
    dt = 2 * ds / np.maximum(v[:-1] + v[1:], 1e-9)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    gamma = np.arctan(np.gradient(u_s, sg))
    vh = v * np.cos(gamma)
    w = v * np.sin(gamma)
    bank = np.arctan(v * v * kappa / g)
    accel = np.gradient(v, t)
    auto = np.where(v < veh.transition_speed_m_s, "transition", "horizontal")
    leg_of = np.clip(np.searchsorted(s_wp, sg, side="right") - 1, 0, m - 1)
    given = np.array([wps[k + 1].phase or "" for k in range(m)], dtype=object)[leg_of].astype(str)
    phase = np.where(given != "", given, auto)
    f = np.where(phase == "transition", veh.wing_fraction(vh), 1.0)
    power = veh.power_w(v, w, bank, accel, f)
    dense.add(dense.t_end + t, e=pe, n=pn, u=u_s, yaw=chi, pitch=gamma, roll=bank, power=power, speed=v,
              phase=phase)
    return float(chi[-1])
