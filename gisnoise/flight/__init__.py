"""Flights: trajectories, flight logs (CSV, PX4 ULog, ArduPilot DataFlash), waypoints and routes, the vehicle power model.
"""

from __future__ import annotations

from gisnoise.flight.logs import (
    FLIGHT_SUFFIXES,
    as_unix_time,
    gps_to_unix,
    phase_by_speed,
    quaternion_to_euler,
    read_flight,
)
from gisnoise.flight.patterns import (
    G,
    PathBuilder,
    fwd,
    right,
)
from gisnoise.flight.routes import (
    GRAVITY,
    VehicleModel,
    read_route,
    read_trajectory,
    route_from_waypoints,
    trajectory_to_geojson,
)
from gisnoise.flight.trajectory import (
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    Trajectory,
    from_columns,
    read_flight_csv,
)

__all__ = ['FLIGHT_SUFFIXES', 'G', 'GRAVITY', 'OPTIONAL_COLUMNS', 'PathBuilder', 'REQUIRED_COLUMNS', 'Trajectory', 'VehicleModel', 'as_unix_time', 'from_columns', 'fwd', 'gps_to_unix', 'phase_by_speed', 'quaternion_to_euler', 'read_flight', 'read_flight_csv', 'read_route', 'read_trajectory', 'right', 'route_from_waypoints', 'trajectory_to_geojson']
