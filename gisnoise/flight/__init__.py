"""Flights: trajectories, flight logs (CSV, PX4 ULog, ArduPilot DataFlash), waypoints and routes, the vehicle power model.
"""

from __future__ import annotations

from gisnoise.flight.clock import (
    as_unix_time,
    gps_to_unix,
)
from gisnoise.flight.dataflash import (
    read_dataflash,
)
from gisnoise.flight.ground import (
    GROUND_HINT_CLI,
    GROUND_RULE,
    GROUND_TOLERANCE_M,
    flying_parts,
    flying_segments,
    ground_from_track,
)
from gisnoise.flight.logcut import (
    LogCut,
    dataflash_cut,
    ulog_cut,
)
from gisnoise.flight.logdamage import (
    LogDamage,
    dataflash_damage,
    log_damage_warning,
    ulog_damage,
)
from gisnoise.flight.logs import (
    FLIGHT_SUFFIXES,
    read_flight,
)
from gisnoise.flight.logspan import (
    LEFT_OUT_MIN_S,
    left_out_warning,
)
from gisnoise.flight.paths import (
    derive_states,
    trajectory_from_path,
)
from gisnoise.flight.patterns import (
    G,
    PathBuilder,
    fwd,
    right,
)
from gisnoise.flight.phases import (
    HOVER_MAX_SPEED_M_S,
    MULTICOPTER_PHASES,
    PHASES,
    VERTICAL_MIN_SPEED_M_S,
    phase_by_speed,
    smoothed_speed,
)
from gisnoise.flight.readnotes import (
    track_warning,
)
from gisnoise.flight.rest import (
    LYING_MIN_S,
    lying_inverted,
)
from gisnoise.flight.routes import (
    LOG_MAP_RATE_HZ,
    read_route,
    read_trajectory,
    trajectory_to_geojson,
)
from gisnoise.flight.trajectory import (
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    Trajectory,
    from_columns,
    read_flight_csv,
)
from gisnoise.flight.ulog import (
    quaternion_to_euler,
    read_ulog,
)
from gisnoise.flight.vehicle import (
    GRAVITY,
    VehicleModel,
)
from gisnoise.flight.waypoints import (
    WAYPOINTS_SCHEMA,
    Route,
    route_from_waypoints,
)

__all__ = ['FLIGHT_SUFFIXES', 'G', 'GRAVITY', 'GROUND_HINT_CLI', 'GROUND_RULE', 'GROUND_TOLERANCE_M', 'flying_parts', 'flying_segments', 'ground_from_track', 'HOVER_MAX_SPEED_M_S', 'LEFT_OUT_MIN_S', 'LOG_MAP_RATE_HZ', 'LYING_MIN_S', 'LogCut', 'LogDamage', 'MULTICOPTER_PHASES', 'OPTIONAL_COLUMNS', 'PHASES', 'PathBuilder', 'REQUIRED_COLUMNS', 'Route', 'Trajectory', 'VERTICAL_MIN_SPEED_M_S', 'VehicleModel', 'WAYPOINTS_SCHEMA', 'as_unix_time', 'dataflash_cut', 'dataflash_damage', 'derive_states', 'from_columns', 'fwd', 'gps_to_unix', 'track_warning', 'left_out_warning', 'log_damage_warning', 'lying_inverted', 'phase_by_speed', 'quaternion_to_euler', 'read_dataflash', 'read_flight', 'read_flight_csv', 'read_route', 'read_trajectory', 'read_ulog', 'right', 'route_from_waypoints', 'smoothed_speed', 'trajectory_from_path', 'trajectory_to_geojson', 'ulog_cut', 'ulog_damage']
