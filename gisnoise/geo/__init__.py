"""Geodesy and rasters: local ENU frames, receiver grids, DEM input.
"""

from __future__ import annotations

from gisnoise.geo.area import (
    areal_scale,
    cell_areas,
)
from gisnoise.geo.frames import (
    LocalFrame,
    body_vector,
    centre_lon,
    dcm_ned_to_body,
    emission_angles,
    wrap_angle,
    wrap_deg,
)
from gisnoise.geo.geoid import (
    GEOID_GRID_ENV,
    GEOID_GRIDS,
    GEOID_WAY_OUT,
    GeoidGrid,
    find_geoid_grid,
    geoid_search_dirs,
    geoid_undulation,
)
from gisnoise.geo.grid import (
    DEFAULT_MAX_CELLS,
    WGS84,
    GridSpec,
    apply_affine,
    check_cell_limit,
    crs_label,
    grid_for_points,
    max_cells,
    parse_crs,
    resample_dem,
    scale_factor,
    transformer,
    utm_crs,
)
from gisnoise.geo.raster import (
    Dem,
    raster_window,
    read_dem,
    sample_dem,
)

__all__ = ['DEFAULT_MAX_CELLS', 'Dem', 'areal_scale', 'cell_areas', 'GEOID_GRIDS', 'GEOID_GRID_ENV', 'GEOID_WAY_OUT', 'GeoidGrid', 'find_geoid_grid', 'geoid_search_dirs', 'geoid_undulation', 'GridSpec', 'LocalFrame', 'WGS84', 'apply_affine', 'body_vector', 'centre_lon', 'check_cell_limit', 'crs_label', 'dcm_ned_to_body', 'emission_angles', 'grid_for_points', 'max_cells', 'parse_crs', 'raster_window', 'read_dem', 'resample_dem', 'sample_dem', 'scale_factor', 'transformer', 'utm_crs', 'wrap_angle', 'wrap_deg']
