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
    ``yaw`` (deg), ``rpm``, ``airspeed_m_s``.  The vertices are flown straight at constant
    velocity between their times; a leg longer than ``sample_dt_s`` (a ``properties`` or request
    setting, default 0.5 s, as waypoints) is cut into equal parts no longer than it, so a planned leg of
    a few vertices is heard all along it, not only at its vertices.  The states missing from
    ``properties`` are derived from the motion of these samples
    (:func:`~gisnoise.flight.paths.derive_states`): a cruise leg between two vertices is flown at its
    own speed, phase and power; given states are linear in time between their vertices (angles the
    shorter way round, a phase held from its vertex on);
waypoints
    a route plan (a ``gisnoise/waypoints/1`` JSON document, a GeoJSON ``FeatureCollection``
    of ``Point`` features or a ``LineString`` without times) that
    :func:`~gisnoise.flight.waypoints.route_from_waypoints` flies into a time-stamped
    trajectory; :mod:`gisnoise.flight.waypoints` states the formats and how waypoints
    are flown, :mod:`gisnoise.flight.vehicle` the power model.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import TrajectoryError
from gisnoise.flight.glitches import step_lengths
from gisnoise.flight.logs import read_flight
from gisnoise.flight.paths import trajectory_from_path
from gisnoise.flight.trajectory import Trajectory, read_flight_csv
from gisnoise.flight.vehicle import VehicleModel
from gisnoise.flight.waypoints import _WP_PREFIX, WAYPOINTS_SCHEMA, Route, _heights, _settings, route_from_waypoints
from gisnoise.limits import MAX_UAV_SPEED_M_S, check_samples, check_times

__all__ = ["read_trajectory", "read_route", "trajectory_to_geojson", "LOG_MAP_RATE_HZ"]

LOG_MAP_RATE_HZ = 10.0
"""Rate at which :func:`read_route` samples a flight log (``.ulg``, ``.bin``) for a map, Hz."""


def read_trajectory(src: Any, *, dem: Any = None, dem_offset_m: float = 0.0,
                    vehicle: VehicleModel | None = None, geoid_undulation_m: float | None = None,
                    power_w: float | None = None) -> Trajectory:
    """A trajectory from a flight CSV, a flight log, a GeoJSON LineString with times, or waypoints.

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
    geoid_undulation_m : float, optional
        For flight logs with heights above mean sea level (``.bin``), m.
    power_w : float, optional
        For flight logs: a constant electric power in place of the logged one, W.
    """
    route = read_route(src, dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle,
                       geoid_undulation_m=geoid_undulation_m, power_w=power_w)
    if route.ground_h_m is not None:
        route.trajectory.metadata["ground_h_m"] = route.ground_h_m   # the ground the source states
    return route.trajectory


def read_route(src: Any, *, dem: Any = None, dem_offset_m: float = 0.0,
               vehicle: VehicleModel | None = None, geoid_undulation_m: float | None = None,
               power_w: float | None = None) -> Route:
    """As :func:`read_trajectory`, also returning the ground height the source states.

    The one reader of trajectories for every face: a flight CSV, a PX4 ``.ulg`` or an
    ArduPilot ``.bin`` (any letter case, :func:`gisnoise.flight.logs.read_flight`), a
    GeoJSON LineString with times, or waypoints.  ``geoid_undulation_m`` (the site's geoid
    undulation) makes heights above mean sea level ellipsoidal: those of flight logs and of
    ``msl`` waypoints or LineStrings, over a document's own value.  ``power_w`` applies to flight
    logs only; given with a source that states its power, it is refused (field ``power_w``).
    """
    route = _read(src, dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle, geoid_undulation_m=geoid_undulation_m,
                  power_w=power_w)
    tr = route.trajectory
    if power_w is not None and not str(tr.metadata.get("power", "")).startswith("constant"):
        raise TrajectoryError(f"{tr.source}: power_w applies to flight logs (.ulg, .bin) without battery current; "
                              "this trajectory states its power", field="power_w")
    return route


def _read(src: Any, *, dem: Any, dem_offset_m: float, vehicle: VehicleModel | None,
          geoid_undulation_m: float | None, power_w: float | None) -> Route:
    if isinstance(src, Trajectory):
        return Route(src)
    if isinstance(src, Route):
        return src
    if isinstance(src, Mapping):
        return _from_json(src, source="route", dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle,
                          geoid_undulation_m=geoid_undulation_m)
    if isinstance(src, (str, os.PathLike)):
        p = Path(src)
        if not p.is_file():
            raise TrajectoryError(f"{p}: no such trajectory file", field="trajectory")
        suffix = p.suffix.lower()
        if suffix == ".csv":
            return Route(read_flight_csv(p))
        if suffix in (".ulg", ".bin"):
            # maps sample a log at LOG_MAP_RATE_HZ: GPS at 1-5 Hz would miss short hops
            return Route(read_flight(p, geoid_undulation_m=geoid_undulation_m, power_w=power_w,
                                     rate_hz=LOG_MAP_RATE_HZ))
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
            return _from_json(doc, source=str(p), dem=dem, dem_offset_m=dem_offset_m, vehicle=vehicle,
                              geoid_undulation_m=geoid_undulation_m)
        return Route(read_flight_csv(io.StringIO(text), source=str(p)))
    raise TrajectoryError(f"trajectory: expected a file path, a JSON object or a Trajectory, got "
                          f"{type(src).__name__}", field="trajectory")


def _from_json(doc: Any, *, source: str, dem: Any, dem_offset_m: float, vehicle: VehicleModel | None,
               geoid_undulation_m: float | None = None) -> Route:
    if not isinstance(doc, Mapping):
        raise TrajectoryError(f"{source}: expected a JSON object", field="trajectory")
    given = {} if geoid_undulation_m is None else {"geoid_undulation_m": float(geoid_undulation_m)}  # overrides
    _check_crs_member(doc, source)
    schema = doc.get("schema")
    if isinstance(schema, str) and schema.startswith(_WP_PREFIX):
        if schema != WAYPOINTS_SCHEMA:
            raise TrajectoryError(f"{source}: schema {schema!r} is not supported (reads {WAYPOINTS_SCHEMA!r})",
                                  field="schema")
        wps = doc.get("waypoints")
        if not isinstance(wps, list):
            raise TrajectoryError(f"{source}: field 'waypoints' must be a list", field="waypoints")
        return route_from_waypoints(wps, {**doc, **given}, source=source, dem=dem, dem_offset_m=dem_offset_m,
                                    vehicle=vehicle)
    typ = doc.get("type")
    if typ == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list) or not feats:
            raise TrajectoryError(f"{source}: the FeatureCollection has no features", field="features")
        types = [((f or {}).get("geometry") or {}).get("type") for f in feats]
        settings = doc.get("route") or {}
        if not isinstance(settings, Mapping):
            raise TrajectoryError(f"{source}: route settings must be an object", field="route")
        settings = {**settings, **given}
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
                                    vehicle=vehicle, given=given)
        raise TrajectoryError(f"{source}: a FeatureCollection must hold Point waypoints or one LineString, "
                              f"got {', '.join(sorted({str(t) for t in types}))}", field="features")
    if typ == "Feature":
        g = doc.get("geometry") or {}
        if g.get("type") == "LineString":
            return _from_linestring(doc, doc.get("route") or {}, source=source, dem=dem,
                                    dem_offset_m=dem_offset_m, vehicle=vehicle, given=given)
        raise TrajectoryError(f"{source}: a Feature must be a LineString, got {g.get('type')!r}", field="geometry")
    if typ == "LineString":
        return _from_linestring({"type": "Feature", "geometry": doc, "properties": {}}, {}, source=source, dem=dem,
                                dem_offset_m=dem_offset_m, vehicle=vehicle, given=given)
    raise TrajectoryError(f"{source}: not a waypoints document ({WAYPOINTS_SCHEMA}) nor GeoJSON LineString/"
                          "Points", field="trajectory")


def _from_linestring(feat: Mapping[str, Any], settings: Mapping[str, Any], *, source: str, dem: Any,
                     dem_offset_m: float, vehicle: VehicleModel | None, given: Mapping[str, Any]) -> Route:
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
                                                   "sample_dt_s", "vehicle") if k in props}, **given}
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
    _check_lon_lat(lon, lat, source)
    h, ground, datum = _heights(alt, lon, lat, st, dem, dem_offset_m, source)
    states: dict[str, Any] = {}
    for k in ("power_w", "phase", "roll", "pitch", "yaw", "rpm", "airspeed_m_s"):
        v = props.get(k)
        if v is None:
            continue
        if not isinstance(v, list) or len(v) != len(coords):
            raise TrajectoryError(f"{source}: properties.{k} must list one value per vertex ({len(coords)})",
                                  field=k)
        states[k] = np.asarray(v, dtype=str if k == "phase" else float)
    if t.size > 1 and np.any(np.diff(t) <= 0):
        i = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise TrajectoryError(f"{source}: properties.times must increase strictly; vertex {i} is at t = {t[i]:g} s "
                              f"after {t[i - 1]:g} s", field="times")
    check_times(t, source=source, error=TrajectoryError)  # a gap between vertices is a gap, before it is sampled
    _check_leg_speeds(t, lat, lon, h, source)
    tt, at = _sample_times(t, st["sample_dt_s"])
    # the path is sampled first, so that the states derived from its motion are those of legs flown straight at
    # constant velocity, not of the vertices alone (a 20 s climb beside a 75 s cruise leg gave the cruise 4 m/s)
    lat_s, lon_s, h_s = _along(lat, t, tt, at), _along_lon(lon, t, tt, at), _along(h, t, tt, at)
    given_s = {k: _state_along(k, v, t, tt, at) for k, v in states.items()}
    traj = trajectory_from_path(tt, lat_s, lon_s, h_s, vehicle=st["vehicle"], source=source, **given_s)
    traj.metadata.update(datum)
    return Route(traj, ground)


_WGS84_NAMES = ("urn:ogc:def:crs:ogc:1.3:crs84", "urn:ogc:def:crs:epsg::4326", "epsg:4326", "crs84", "ogc:crs84")
"""Names of WGS84 longitude, latitude in the ``crs`` member of pre-RFC 7946 GeoJSON (compared in lower case)."""


def _check_crs_member(doc: Mapping[str, Any], source: str) -> None:
    """Refuse a GeoJSON ``crs`` member naming another CRS than WGS84 longitude, latitude: RFC 7946 positions are
    in WGS84, and the member is not read (a route in a projected CRS would be taken for degrees)."""
    crs = doc.get("crs")
    if crs is None:
        return
    name = ((crs.get("properties") or {}).get("name") if isinstance(crs, Mapping) else None)
    if isinstance(name, str) and name.strip().lower() in _WGS84_NAMES:
        return
    raise TrajectoryError(f"{source}: crs: GeoJSON positions are WGS84 longitude, latitude in degrees (RFC 7946); "
                          f"the file names {name or crs!r}, which is not read: reproject the route to EPSG:4326",
                          field="crs")


def _check_lon_lat(lon: np.ndarray, lat: np.ndarray, source: str) -> None:
    """Refuse positions that are not longitude, latitude in degrees, naming the first such vertex."""
    bad = ~((np.abs(lon) <= 180.0) & (np.abs(lat) <= 90.0))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise TrajectoryError(f"{source}: coordinates: vertex {i} is ({lon[i]:.2f}, {lat[i]:.2f}), not WGS84 "
                              f"longitude, latitude in degrees (RFC 7946); reproject a route in a projected CRS to "
                              f"EPSG:4326", field="coordinates")


def _check_leg_speeds(t: np.ndarray, lat: np.ndarray, lon: np.ndarray, h: np.ndarray, source: str) -> None:
    """Refuse a leg flown faster than any UAV flies (:data:`~gisnoise.limits.MAX_UAV_SPEED_M_S`): its times or
    coordinates are wrong (the power derived from it would be refused as out of range, misleadingly)."""
    if t.size < 2:
        return
    _, _, length = step_lengths(lat, lon, h)
    speed = length / np.diff(t)
    if np.any(speed > MAX_UAV_SPEED_M_S):
        i = int(np.argmax(speed > MAX_UAV_SPEED_M_S))
        raise TrajectoryError(f"{source}: the leg from vertex {i} to {i + 1} is {length[i]:,.0f} m long in "
                              f"{t[i + 1] - t[i]:g} s ({speed[i]:,.0f} m/s, faster than the {MAX_UAV_SPEED_M_S:g} m/s "
                              "a UAV flies): check properties.times and the coordinates", field="times")


def _sample_times(t: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Times of a timed path with every leg longer than ``dt`` s cut into equal parts no longer than it, and the
    indices of its vertices among them."""
    parts = np.ceil(np.diff(t) / dt - 1e-9).astype(np.int64) if t.size > 1 else np.zeros(0, np.int64)
    parts = np.maximum(parts, 1)
    check_samples(float(parts.sum()) + 1, field="sample_dt_s", what="LineString")  # before allocating
    leg = np.repeat(np.arange(t.size - 1), parts)
    k = np.arange(leg.size) - np.repeat(np.cumsum(parts) - parts, parts)   # part k of its leg
    tt = np.append(t[leg] + (t[leg + 1] - t[leg]) * k / parts[leg], t[-1])
    at = np.append(np.cumsum(parts) - parts, leg.size)
    return tt, at


def _along(v: np.ndarray, t: np.ndarray, tt: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``v`` (one value per vertex) linear in time between the vertices, the vertices' values exactly."""
    out = np.interp(tt, t, v)
    out[at] = v
    return out


def _along_lon(lon: np.ndarray, t: np.ndarray, tt: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Longitudes (deg) linear in time along each leg's shorter way round (a leg across 180 deg stays short)."""
    out = (np.interp(tt, t, np.unwrap(lon, period=360.0)) + 180.0) % 360.0 - 180.0
    out[at] = lon
    return out


def _state_along(name: str, v: np.ndarray, t: np.ndarray, tt: np.ndarray, at: np.ndarray) -> np.ndarray:
    """A state given per vertex at the sample times: the phase of the vertex before, angles the shorter way
    round, other values linear in time; the vertices' values exactly."""
    if name == "phase":
        return v[np.clip(np.searchsorted(t, tt, side="right") - 1, 0, t.size - 1)]
    if name in ("roll", "pitch", "yaw"):
        return _along_lon(v, t, tt, at)  # degrees on the circle, in [-180, 180)
    return _along(v, t, tt, at)


def trajectory_to_geojson(route: Trajectory) -> dict[str, Any]:
    """A GeoJSON Feature LineString with times and per-vertex states of a trajectory (for export)."""
    props: dict[str, Any] = {"times": route.t.tolist(), "altitude_reference": "ellipsoid"}
    for k in ("power_w", "roll", "pitch", "yaw"):
        props[k] = np.asarray(getattr(route, k)).tolist()
    props["phase"] = [str(p) for p in route.phase]
    coords = [[float(a), float(b), float(c)] for a, b, c in zip(route.lon, route.lat, route.h, strict=True)]
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords}, "properties": props}
