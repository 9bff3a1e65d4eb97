"""Trajectories from files and route plans: flight CSV, GeoJSON LineString with times, waypoints.

:func:`read_trajectory` accepts

flight CSV (``.csv``)
    the flight log of SPEC section 3 (:func:`gisnoise.flight.trajectory.read_flight_csv`);
GeoJSON ``LineString`` with times
    a ``Feature`` (or a ``FeatureCollection`` holding one) whose coordinates are
    ``[lon, lat, z]`` with ``properties.times`` (s, one per vertex) or
    ``[lon, lat, z, t]``.  ``z`` is the WGS84 ellipsoidal height (RFC 7946) unless
    ``properties.altitude_reference`` says ``agl`` or ``msl`` (see waypoints).  Optional
    per-vertex lists in ``properties``: ``power_w``, ``phase``, ``roll``, ``pitch``,
    ``yaw`` (deg), ``rpm``, ``airspeed_m_s``; missing ones are derived from the motion
    (:func:`derive_states`);
waypoints
    a route plan that :func:`route_from_waypoints` turns into a flown, time-stamped
    trajectory.  Either a JSON document::

        {"schema": "gisnoise/waypoints/1",
         "altitude_reference": "agl",        # agl (default) | msl | ellipsoid
         "ground_h_m": 0.0,                  # flat ground (ellipsoidal m) for agl without DEM
         "geoid_undulation_m": 0.0,          # msl -> ellipsoidal: h = alt + N
         "sample_dt_s": 0.5,
         "vehicle": {"mass_kg": 35, "cruise_speed_m_s": 25, ...},   # VehicleModel fields
         "waypoints": [{"lon": .., "lat": .., "alt": .., "speed": .., "phase": .., "hold_s": ..,
                        "heading_deg": ..}, ...]}

    or a GeoJSON ``FeatureCollection`` of ``Point`` features in flight order (properties
    as the waypoint entries; ``alt`` defaults to the third coordinate) with the
    settings in a foreign member ``"route": {...}``; or a GeoJSON ``LineString``
    without times (its vertices are the waypoints; ``properties.speed`` a number or
    one per vertex).

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
* Electric power (:class:`VehicleModel`): rotors by momentum theory,
  ``P = (T^1.5 / (FM sqrt(2 rho A)) + T w+ + T w-/2) / eta_motor`` for thrust ``T``
  and climb rate ``w``; wing-borne ``P = (D v + m a v + m g w) / eta_prop`` with drag
  ``D = q S (CD0 + CL^2 / (pi e AR))`` and lift ``n f m g`` (load factor ``n = 1/cos
  bank``); in transition the wing carries the fraction ``f = (v / v_transition)^2`` of the
  weight and the rotors the rest; plus a constant systems power.  The defaults give a
  35 kg cargo eVTOL about 2.5 kW in cruise at 25 m/s and 5.7 kW in hover.
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError, TrajectoryError
from gisnoise.flight.trajectory import Trajectory, read_flight_csv
from gisnoise.geo import LocalFrame, wrap_angle
from gisnoise.model import PHASES

__all__ = [
    "VehicleModel",
    "Route",
    "read_trajectory",
    "read_route",
    "route_from_waypoints",
    "trajectory_from_path",
    "derive_states",
    "trajectory_to_geojson",
    "WAYPOINTS_SCHEMA",
    "GRAVITY",
]

GRAVITY = 9.80665
WAYPOINTS_SCHEMA = "gisnoise/waypoints/1"
_WP_PREFIX = "gisnoise/waypoints/"
_MULTICOPTER = ("climb", "sink", "hover")
_VERTICAL_TOL_M = 2.0
_ALT_REFS = ("agl", "msl", "ellipsoid")


# --------------------------------------------------------------------------- vehicle


@dataclass(frozen=True)
class VehicleModel:
    """Performance and power model of a lift+cruise eVTOL UAV (SI units).

    The defaults describe a 35 kg cargo eVTOL with four 0.75 m lift rotors and a
    1.5 m^2 wing.  See the module docstring for the equations.

    Examples
    --------
    >>> v = VehicleModel()
    >>> round(v.hover_power_w())
    5682
    >>> round(float(v.power_w(25.0, 0.0, 0.0, 0.0)))
    2547
    """

    mass_kg: float = 35.0
    air_density_kg_m3: float = 1.225
    rotor_disk_area_m2: float = 1.767
    figure_of_merit: float = 0.65
    motor_efficiency: float = 0.85
    wing_area_m2: float = 1.5
    aspect_ratio: float = 12.0
    oswald_efficiency: float = 0.8
    cd0: float = 0.08
    propulsive_efficiency: float = 0.55
    systems_power_w: float = 150.0
    cruise_speed_m_s: float = 25.0
    transition_speed_m_s: float = 18.0
    climb_rate_m_s: float = 3.0
    sink_rate_m_s: float = 2.0
    multicopter_speed_m_s: float = 5.0
    max_bank_deg: float = 30.0
    acceleration_m_s2: float = 1.5
    vertical_acceleration_m_s2: float = 1.0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise InputError(f"vehicle: field '{f.name}' must be a positive number, got {v!r}",
                                 field=f"vehicle.{f.name}")
        if not 0 < self.max_bank_deg < 80:
            raise InputError(f"vehicle: field 'max_bank_deg' must be in (0, 80), got {self.max_bank_deg}",
                             field="vehicle.max_bank_deg")
        for name in ("figure_of_merit", "motor_efficiency", "propulsive_efficiency"):
            if getattr(self, name) > 1:
                raise InputError(f"vehicle: field '{name}' must be <= 1, got {getattr(self, name)}",
                                 field=f"vehicle.{name}")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> VehicleModel:
        if d is None:
            return cls()
        if not isinstance(d, Mapping):
            raise InputError("vehicle: must be an object of field -> number", field="vehicle")
        known = {f.name for f in fields(cls)}
        extra = [k for k in d if k not in known and k not in ("name", "reference_power_w")]
        if extra:
            raise InputError(f"vehicle: unknown field {extra[0]!r}; known: {', '.join(sorted(known))}",
                             field=f"vehicle.{extra[0]}")
        return cls(**{k: v for k, v in d.items() if k in known})

    @property
    def weight_n(self) -> float:
        return self.mass_kg * GRAVITY

    def rotor_power_w(self, thrust_n: Any, climb_m_s: Any = 0.0) -> np.ndarray:
        """Electric power of the lift rotors for thrust ``T`` (N) and climb rate ``w`` (m/s), W."""
        t = np.maximum(np.asarray(thrust_n, dtype=float), 0.0)
        w = np.asarray(climb_m_s, dtype=float)
        induced = t ** 1.5 / (self.figure_of_merit * math.sqrt(2.0 * self.air_density_kg_m3 * self.rotor_disk_area_m2))
        p = induced + t * np.maximum(w, 0.0) + 0.5 * t * np.minimum(w, 0.0)
        return np.maximum(p, 0.3 * induced) / self.motor_efficiency

    def hover_power_w(self) -> float:
        """Electric power in hover, W."""
        return float(self.rotor_power_w(self.weight_n)) + self.systems_power_w

    def power_w(self, speed_m_s: Any, climb_m_s: Any, bank_rad: Any, accel_m_s2: Any,
                wing_fraction: Any = 1.0) -> np.ndarray:
        """Electric power in forward flight, W; arrays broadcast.

        Parameters
        ----------
        speed_m_s : airspeed along the path (no wind), m/s.
        climb_m_s : vertical speed, m/s.
        bank_rad : bank angle, rad.
        accel_m_s2 : longitudinal acceleration, m/s^2.
        wing_fraction : share of the weight the wing carries (1 wing-borne, 0 hover).
        """
        v = np.maximum(np.asarray(speed_m_s, dtype=float), 0.0)
        w = np.asarray(climb_m_s, dtype=float)
        f = np.clip(np.asarray(wing_fraction, dtype=float), 0.0, 1.0)
        n = 1.0 / np.cos(np.asarray(bank_rad, dtype=float))
        q = 0.5 * self.air_density_kg_m3 * v * v
        qs = q * self.wing_area_m2
        lift = n * f * self.weight_n
        with np.errstate(divide="ignore", invalid="ignore"):
            induced = np.where(qs > 0, lift * lift / np.where(qs > 0, qs, 1.0)
                               / (math.pi * self.oswald_efficiency * self.aspect_ratio), 0.0)
        drag = qs * self.cd0 + induced
        wing = (drag * v + self.mass_kg * np.asarray(accel_m_s2, dtype=float) * v
                + self.weight_n * w * (f > 0)) / self.propulsive_efficiency
        rotors = np.where(f < 1.0, self.rotor_power_w((1.0 - f) * self.weight_n, np.where(f > 0, 0.0, w)), 0.0)
        return np.maximum(wing, 0.0) + rotors + self.systems_power_w

    def wing_fraction(self, speed_m_s: Any) -> np.ndarray:
        """Share of the weight on the wing at ``speed_m_s``: ``min(1, (v / v_transition)^2)``."""
        return np.clip((np.asarray(speed_m_s, dtype=float) / self.transition_speed_m_s) ** 2, 0.0, 1.0)


# --------------------------------------------------------------------------- reading


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


def read_trajectory(src: Any, *, dem: Any = None, dem_offset_m: float = 0.0,
                    vehicle: VehicleModel | None = None) -> Trajectory:
    """A trajectory from a flight CSV, a GeoJSON LineString with times, or waypoints.

    Parameters
    ----------
    src : Trajectory, path or dict
        A file (``.csv``, ``.json``, ``.geojson``), its parsed JSON object, or a trajectory.
    dem : path or Dem, optional
        Ground for AGL altitudes.
    dem_offset_m : float
        Added to DEM heights to give ellipsoidal heights, m.
    vehicle : VehicleModel, optional
        Overrides the document's vehicle for derived power.
    """
    return read_route(src, dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle).trajectory


def read_route(src: Any, *, dem: Any = None, dem_offset_m: float = 0.0,
               vehicle: VehicleModel | None = None) -> Route:
    """As :func:`read_trajectory`, also returning the ground height the source states."""
    if isinstance(src, Trajectory):
        return Route(src)
    if isinstance(src, Route):
        return src
    if isinstance(src, Mapping):
        return _from_json(src, source="route", dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle)
    if isinstance(src, (str, os.PathLike)):
        p = Path(src)
        if not p.is_file():
            raise TrajectoryError(f"{p}: no such trajectory file", field="trajectory")
        suffix = p.suffix.lower()
        if suffix == ".csv":
            return Route(read_flight_csv(p))
        try:
            text = p.read_text(encoding="utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            raise TrajectoryError(f"{p}: cannot read: {exc}", field="trajectory") from None
        if suffix in (".json", ".geojson") or text.lstrip().startswith("{"):
            try:
                doc = json.loads(text)
            except json.JSONDecodeError as exc:
                raise TrajectoryError(f"{p}: malformed JSON at line {exc.lineno} column {exc.colno}: {exc.msg}",
                                      field="json") from None
            return _from_json(doc, source=str(p), dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle)
        return Route(read_flight_csv(io.StringIO(text), source=str(p)))
    raise TrajectoryError(f"trajectory: expected a file path, a JSON object or a Trajectory, got "
                          f"{type(src).__name__}", field="trajectory")


def _from_json(doc: Any, *, source: str, dem: Any, dem_offset_m: float, vehicle: VehicleModel | None) -> Route:
    if not isinstance(doc, Mapping):
        raise TrajectoryError(f"{source}: expected a JSON object", field="trajectory")
    schema = doc.get("schema")
    if isinstance(schema, str) and schema.startswith(_WP_PREFIX):
        if schema != WAYPOINTS_SCHEMA:
            raise TrajectoryError(f"{source}: schema {schema!r} is not supported (reads {WAYPOINTS_SCHEMA!r})",
                                  field="schema")
        wps = doc.get("waypoints")
        if not isinstance(wps, list):
            raise TrajectoryError(f"{source}: field 'waypoints' must be a list", field="waypoints")
        return route_from_waypoints(wps, doc, source=source, dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle)
    typ = doc.get("type")
    if typ == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list) or not feats:
            raise TrajectoryError(f"{source}: the FeatureCollection has no features", field="features")
        types = [((f or {}).get("geometry") or {}).get("type") for f in feats]
        settings = doc.get("route") or {}
        if all(t == "Point" for t in types):
            wps = []
            for i, f in enumerate(feats):
                c = f["geometry"].get("coordinates") or []
                props = dict(f.get("properties") or {})
                if len(c) < 2:
                    raise TrajectoryError(f"{source}: feature {i}: Point needs [lon, lat]", field="coordinates")
                props.setdefault("lon", c[0])
                props.setdefault("lat", c[1])
                if len(c) > 2:
                    props.setdefault("alt", c[2])
                wps.append(props)
            return route_from_waypoints(wps, settings, source=source, dem=dem, dem_offset_m=dem_offset_m,
                                        vehicle=vehicle)
        lines = [f for f, t in zip(feats, types, strict=True) if t == "LineString"]
        if len(lines) == 1:
            return _from_linestring(lines[0], settings, source=source, dem=dem, dem_offset_m=dem_offset_m,
                                    vehicle=vehicle)
        raise TrajectoryError(f"{source}: a FeatureCollection must hold Point waypoints or one LineString, "
                              f"got {', '.join(sorted({str(t) for t in types}))}", field="features")
    if typ == "Feature":
        g = doc.get("geometry") or {}
        if g.get("type") == "LineString":
            return _from_linestring(doc, doc.get("route") or {}, source=source, dem=dem,
                                    dem_offset_m=dem_offset_m, vehicle=vehicle)
        raise TrajectoryError(f"{source}: a Feature must be a LineString, got {g.get('type')!r}", field="geometry")
    if typ == "LineString":
        return _from_linestring({"type": "Feature", "geometry": doc, "properties": {}}, {}, source=source, dem=dem,
                                dem_offset_m=dem_offset_m, vehicle=vehicle)
    raise TrajectoryError(f"{source}: not a waypoints document ({WAYPOINTS_SCHEMA}) nor GeoJSON LineString/"
                          "Points", field="trajectory")


def _settings(doc: Mapping[str, Any], source: str, vehicle: VehicleModel | None) -> dict[str, Any]:
    if not isinstance(doc, Mapping):
        raise TrajectoryError(f"{source}: route settings must be an object", field="route")
    ref = doc.get("altitude_reference", "agl")
    if ref not in _ALT_REFS:
        raise TrajectoryError(f"{source}: field 'altitude_reference' must be one of {', '.join(_ALT_REFS)}, "
                              f"got {ref!r}", field="altitude_reference")
    out = {"altitude_reference": ref}
    for k, default in (("ground_h_m", 0.0), ("geoid_undulation_m", 0.0), ("sample_dt_s", 0.5)):
        v = doc.get(k, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise TrajectoryError(f"{source}: field '{k}' must be a number, got {v!r}", field=k)
        out[k] = float(v)
    if not 0 < out["sample_dt_s"] <= 10:
        raise TrajectoryError(f"{source}: field 'sample_dt_s' must be in (0, 10] s, got {out['sample_dt_s']}",
                              field="sample_dt_s")
    out["vehicle"] = vehicle or VehicleModel.from_dict(doc.get("vehicle"))
    return out


def _heights(alt: np.ndarray, lon: np.ndarray, lat: np.ndarray, st: Mapping[str, Any], dem: Any,
             dem_offset_m: float, source: str) -> tuple[np.ndarray, float | None]:
    """Ellipsoidal heights of altitudes, and the flat ground height the source states (or None)."""
    ref = st["altitude_reference"]
    if ref == "ellipsoid":
        return alt, None
    if ref == "msl":
        return alt + st["geoid_undulation_m"], None
    if dem is None:
        return alt + st["ground_h_m"], st["ground_h_m"]
    from gisnoise.geo import Dem, read_dem, sample_dem

    d = dem if isinstance(dem, Dem) else read_dem(dem)
    g = sample_dem(d, lon, lat) + float(dem_offset_m)
    bad = ~np.isfinite(g)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise TrajectoryError(f"{source}: waypoint {i} ({lon[i]:.6f}, {lat[i]:.6f}) lies outside the DEM; "
                              "AGL altitudes need the ground there", field="alt")
    return alt + g, None


def _num(v: Any, name: str, source: str, i: int) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TrajectoryError(f"{source}: waypoint {i}: field '{name}' must be a number, got {v!r}", field=name)
    return float(v)


# --------------------------------------------------------------------------- timed paths


def derive_states(t: Any, e: Any, n: Any, u: Any, vehicle: VehicleModel | None = None, *,
                  phase: Any = None) -> dict[str, np.ndarray]:
    """Attitude, phase and power of a timed path from its motion (no wind).

    Parameters
    ----------
    t : array_like
        Time, s, strictly increasing.
    e, n, u : array_like
        Local ENU positions, m.
    vehicle : VehicleModel, optional
    phase : array_like of str, optional
        Given phases; derived when None: horizontal speed below 1 m/s is ``hover``
        (vertical speed below 0.3 m/s), ``climb`` or ``sink``; below the transition speed
        ``transition``; else ``horizontal``.

    Returns
    -------
    dict
        ``yaw`` (course), ``pitch`` (flight-path angle, 0 in multicopter phases),
        ``roll`` (coordinated-turn bank ``atan(v chi_dot / g)``), all deg; ``power_w`` (W),
        ``phase``, ``airspeed_m_s``.
    """
    veh = vehicle or VehicleModel()
    t = np.asarray(t, dtype=float)
    pos = np.stack([np.asarray(e, float), np.asarray(n, float), np.asarray(u, float)], axis=-1)
    if t.size < 2:
        vel = np.zeros_like(pos)
    else:
        vel = np.gradient(pos, t, axis=0, edge_order=1)
    vh = np.hypot(vel[:, 0], vel[:, 1])
    w = vel[:, 2]
    moving = vh > 0.5
    course = np.arctan2(vel[:, 0], vel[:, 1])
    if moving.any():
        idx = np.flatnonzero(moving)
        nearest = idx[np.clip(np.searchsorted(idx, np.arange(t.size)), 0, idx.size - 1)]
        course = np.where(moving, course, course[nearest])
    else:
        course = np.zeros(t.size)
    unwrapped = np.unwrap(course)
    rate = np.gradient(unwrapped, t) if t.size > 1 else np.zeros(t.size)
    speed = np.sqrt(vh ** 2 + w ** 2)
    accel = np.gradient(speed, t) if t.size > 1 else np.zeros(t.size)
    if phase is None:
        ph = np.where(vh < 1.0, np.where(w > 0.3, "climb", np.where(w < -0.3, "sink", "hover")),
                      np.where(vh < veh.transition_speed_m_s, "transition", "horizontal"))
    else:
        ph = np.asarray(phase).astype(str)
    multi = np.isin(ph, _MULTICOPTER)
    bank = np.where(multi, 0.0, np.arctan(vh * rate / GRAVITY))
    pitch = np.where(multi, 0.0, np.arctan2(w, np.maximum(vh, 1e-9)))
    f = np.where(multi, 0.0, np.where(ph == "transition", veh.wing_fraction(vh), 1.0))
    p_fwd = veh.power_w(vh, w, bank, accel, f)
    p_rot = veh.rotor_power_w(veh.weight_n, w) + veh.systems_power_w
    power = np.where(multi, p_rot, p_fwd)
    return {"yaw": np.degrees(wrap_angle(course)), "pitch": np.degrees(pitch), "roll": np.degrees(bank),
            "power_w": power, "phase": ph, "airspeed_m_s": speed}


def trajectory_from_path(t: Any, lat: Any, lon: Any, h: Any, *, vehicle: VehicleModel | None = None,
                         source: str = "path", **given: Any) -> Trajectory:
    """A trajectory from a timed path; fields in ``given`` (flight-CSV names) win over derived ones."""
    t = np.asarray(t, dtype=float)
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    h = np.asarray(h, dtype=float)
    if t.size == 0:
        raise TrajectoryError(f"{source}: the trajectory is empty", field="t")
    for name, a in (("t", t), ("lat", lat), ("lon", lon), ("h", h)):
        if not np.all(np.isfinite(a)):
            raise TrajectoryError(f"{source}: field '{name}' has NaN or infinite values", field=name)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise TrajectoryError(f"{source}: field 't' is not strictly increasing at sample {i}", field="t")
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h.min()))
    e, n, u = frame.to_enu(lat, lon, h)
    der = derive_states(t, e, n, u, vehicle, phase=given.get("phase"))
    kw: dict[str, Any] = {"t": t, "lat": lat, "lon": lon, "h": h}
    for k in ("roll", "pitch", "yaw", "power_w", "phase", "airspeed_m_s"):
        kw[k] = given[k] if given.get(k) is not None else der[k]
    if given.get("rpm") is not None:
        kw["rpm"] = given["rpm"]
    return Trajectory(**kw, source=source)


def _from_linestring(feat: Mapping[str, Any], settings: Mapping[str, Any], *, source: str, dem: Any,
                     dem_offset_m: float, vehicle: VehicleModel | None) -> Route:
    coords = (feat.get("geometry") or {}).get("coordinates")
    props = dict(feat.get("properties") or {})
    if not isinstance(coords, list) or not coords:
        raise TrajectoryError(f"{source}: the LineString has no coordinates", field="coordinates")
    widths = {len(c) if isinstance(c, list) else -1 for c in coords}
    if widths - {2, 3, 4}:
        raise TrajectoryError(f"{source}: LineString positions must be [lon, lat, z] or [lon, lat, z, t]",
                              field="coordinates")
    times = props.get("times")
    if times is None and widths == {4}:
        times = [c[3] for c in coords]
    st_doc = {**settings, **{k: props[k] for k in ("altitude_reference", "ground_h_m", "geoid_undulation_m",
                                                   "sample_dt_s", "vehicle") if k in props}}
    if "altitude_reference" not in st_doc and times is not None:
        st_doc["altitude_reference"] = "ellipsoid"  # RFC 7946: height above the WGS84 ellipsoid
    if times is None:
        speed = props.get("speed")
        wps = []
        for i, c in enumerate(coords):
            wp: dict[str, Any] = {"lon": c[0], "lat": c[1], "alt": c[2] if len(c) > 2 else None}
            if isinstance(speed, list):
                wp["speed"] = speed[i] if i < len(speed) else None
            elif speed is not None:
                wp["speed"] = speed
            if wp["alt"] is None:
                raise TrajectoryError(f"{source}: LineString vertex {i} has no altitude (z)", field="coordinates")
            wps.append(wp)
        return route_from_waypoints(wps, st_doc, source=source, dem=dem, dem_offset_m=dem_offset_m,
                                    vehicle=vehicle)
    if not isinstance(times, list) or len(times) != len(coords):
        raise TrajectoryError(f"{source}: properties.times must list one time (s) per vertex "
                              f"({len(coords)})", field="times")
    if widths != {3} and widths != {4}:
        raise TrajectoryError(f"{source}: a timed LineString needs [lon, lat, z] positions (z: height, m)",
                              field="coordinates")
    st = _settings(st_doc, source, vehicle)
    try:
        arr = np.array([c[:3] for c in coords], dtype=float)
        t = np.array(times, dtype=float)
    except (TypeError, ValueError):
        raise TrajectoryError(f"{source}: LineString coordinates and times must be numbers",
                              field="coordinates") from None
    lon, lat, alt = arr[:, 0], arr[:, 1], arr[:, 2]
    h, ground = _heights(alt, lon, lat, st, dem, dem_offset_m, source)
    given: dict[str, Any] = {}
    for k in ("power_w", "phase", "roll", "pitch", "yaw", "rpm", "airspeed_m_s"):
        v = props.get(k)
        if v is None:
            continue
        if not isinstance(v, list) or len(v) != len(coords):
            raise TrajectoryError(f"{source}: properties.{k} must list one value per vertex ({len(coords)})",
                                  field=k)
        given[k] = np.asarray(v, dtype=str if k == "phase" else float)
    traj = trajectory_from_path(t, lat, lon, h, vehicle=st["vehicle"], source=source, **given)
    return Route(traj, ground)


# --------------------------------------------------------------------------- waypoints


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
        if abs(lat[i]) > 90 or abs(lon[i]) > 360:
            raise TrajectoryError(f"{source}: waypoint {i}: lon/lat out of range ({lon[i]}, {lat[i]})",
                                  field="lat")
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
        hd = wp.get("heading_deg")
        hd = None if hd is None else math.radians(_num(hd, "heading_deg", source, i))
        extra.append((speed, phase, hold, hd))
    h, ground = _heights(alt, lon, lat, st, dem, dem_offset_m, source)
    frame = LocalFrame(float(lat[0]), float(lon[0]), float(h[0] - alt[0]) if st["altitude_reference"] == "agl"
                       else float(h.min()))
    e, n, u = frame.to_enu(lat, lon, h)
    wps = [_Wp(float(e[i]), float(n[i]), float(u[i]), *extra[i]) for i in range(len(waypoints))]

    dense = _fly(wps, veh)
    t = dense.cat("t")
    dt = st["sample_dt_s"]
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
        source=source)
    return Route(traj, ground)


def _leg_kinds(wps: Sequence[_Wp]) -> list[str]:
    kinds = []
    for a, b in zip(wps[:-1], wps[1:], strict=True):
        dh = math.hypot(b.e - a.e, b.n - a.n)
        if b.phase in _MULTICOPTER or dh < _VERTICAL_TOL_M:
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
    phase = b.phase if b.phase in _MULTICOPTER else ("climb" if d[2] > 0 else "sink")
    if b.phase is None and abs(d[2]) < 0.5:
        phase = "hover"
    yaw = math.atan2(d[0], d[1]) if dh >= _VERTICAL_TOL_M else heading
    power = veh.rotor_power_w(veh.weight_n, w) + veh.systems_power_w
    dense.add(dense.t_end + t, e=a.e + s * unit[0], n=a.n + s * unit[1], u=a.u + s * unit[2], yaw=yaw,
              pitch=0.0, roll=0.0, power=power, speed=sp, phase=phase)


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
    ns = max(3, int(math.ceil(total / 0.5)) + 1)
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
    for i in range(1, ns):
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * acc * ds))
    if end_rest:
        v[-1] = 0.0
    for i in range(ns - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * acc * ds))
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


# --------------------------------------------------------------------------- writing


def trajectory_to_geojson(route: Trajectory) -> dict[str, Any]:
    """A GeoJSON Feature LineString with times and per-vertex states of a trajectory (for export)."""
    props: dict[str, Any] = {"times": route.t.tolist(), "altitude_reference": "ellipsoid"}
    for k in ("power_w", "roll", "pitch", "yaw"):
        props[k] = np.asarray(getattr(route, k)).tolist()
    props["phase"] = [str(p) for p in route.phase]
    coords = [[float(a), float(b), float(c)] for a, b, c in zip(route.lon, route.lat, route.h, strict=True)]
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords}, "properties": props}
