"""The receiver grid of a map: around a trajectory's track, plus a margin.

The grid covers the track's bounding box plus ``margin_m`` on every side, snapped to
multiples of the resolution, in the local UTM zone unless a CRS is given
(:func:`gisnoise.geo.grid_for_points`); its size is limited by ``GISNOISE_MAX_CELLS``.
"""

from __future__ import annotations

from typing import Any

from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec, grid_for_points

__all__ = ["grid_for_trajectory"]


def grid_for_trajectory(traj: Trajectory, resolution_m: float = 10.0, margin_m: float = 500.0,
                        crs: Any = None) -> GridSpec:
    """The receiver grid around a trajectory's track: :func:`gisnoise.geo.grid_for_points` of its
    longitudes and latitudes, with the same parameters (the margin about the track's bounding box),
    result and errors.
    """
    return grid_for_points(traj.lon, traj.lat, resolution_m, margin_m, crs)
