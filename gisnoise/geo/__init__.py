"""Geodesy and rasters: local ENU frames, receiver grids, GeoTIFF and DEM input/output.
"""

from __future__ import annotations

from gisnoise.geo.frames import LocalFrame, body_vector, dcm_ned_to_body, emission_angles, wrap_angle, wrap_deg
from gisnoise.geo.grid import (
    DEFAULT_MAX_CELLS,
    GridSpec,
    apply_affine,
    crs_label,
    grid_for_trajectory,
    max_cells,
    parse_crs,
    resample_dem,
    transformer,
    utm_crs,
)

__all__ = ['LocalFrame', 'dcm_ned_to_body', 'body_vector', 'emission_angles', 'wrap_angle', 'wrap_deg', 'GridSpec', 'DEFAULT_MAX_CELLS', 'max_cells', 'parse_crs', 'utm_crs', 'grid_for_trajectory', 'resample_dem', 'transformer', 'crs_label', 'apply_affine']
