"""Flights: trajectories, flight logs (CSV, PX4 ULog, ArduPilot DataFlash), waypoints and routes, the vehicle power model.
"""

from __future__ import annotations

from gisnoise.flight.trajectory import OPTIONAL_COLUMNS, REQUIRED_COLUMNS, Trajectory, read_flight_csv

__all__ = ['Trajectory', 'read_flight_csv', 'REQUIRED_COLUMNS', 'OPTIONAL_COLUMNS']
