"""Exposure: population rasters and buildings, façade receivers, people and dwellings by level class.
"""

from __future__ import annotations

from gisnoise.exposure.exposure import (
    SCHEMA,
    coverage_warning,
    exposure_table,
    map_exposure,
    write_exposure,
)
from gisnoise.exposure.facades import (
    ASSESSMENT_HEIGHT_M,
    SCALE_TOLERANCE,
    FacadePoints,
    StoreyPoints,
    facade_levels,
    facade_points,
    most_exposed,
    most_exposed_storeys,
    point_levels,
    storey_points,
)
from gisnoise.exposure.layers import (
    BLOCK_M2,
    DENSEST_BLOCK_PER_KM2,
    DENSEST_DISTRICTS_PER_KM2,
    DWELLING_FIELDS,
    HEIGHT_FIELDS,
    LEVEL_FIELDS,
    RESIDENT_FIELDS,
    Buildings,
    LevelsRaster,
    Population,
    population_cells,
    read_buildings,
    read_levels,
    read_population,
)
from gisnoise.exposure.operations import (
    OPERATIONS_LEVELS,
    check_schedule_of,
    operations_exposure,
    operations_facade_levels,
)
from gisnoise.exposure.stats import (
    CLASS_WIDTH_DB,
    EVENT_EDGES,
    UNCOVERED_SHARE,
    area_above,
    cell_values,
    class_edges,
    covered_at,
    events_area_above,
    fraction_above,
    ground_cell_areas,
    level_field,
    person_db_above,
    population_coverage,
    population_event_exposure,
    population_exposure,
    population_points,
    population_scores,
    uncovered_shares,
)
from gisnoise.exposure.storeys import STOREY_HEIGHT_M, parse_height, parse_levels

__all__ = ['area_above', 'ASSESSMENT_HEIGHT_M', 'BLOCK_M2', 'Buildings', 'cell_values', 'check_schedule_of',
           'class_edges', 'CLASS_WIDTH_DB', 'coverage_warning', 'covered_at', 'DENSEST_BLOCK_PER_KM2',
           'DENSEST_DISTRICTS_PER_KM2', 'DWELLING_FIELDS', 'EVENT_EDGES', 'events_area_above', 'exposure_table',
           'facade_levels', 'facade_points', 'FacadePoints', 'fraction_above', 'ground_cell_areas', 'HEIGHT_FIELDS',
           'level_field', 'LEVEL_FIELDS', 'LevelsRaster', 'map_exposure', 'most_exposed', 'most_exposed_storeys',
           'operations_exposure', 'operations_facade_levels', 'OPERATIONS_LEVELS', 'parse_height', 'parse_levels',
           'person_db_above', 'point_levels', 'Population', 'population_cells', 'population_coverage', 'population_event_exposure',
           'population_exposure', 'population_points', 'population_scores', 'read_buildings', 'read_levels',
           'read_population', 'RESIDENT_FIELDS', 'SCALE_TOLERANCE', 'SCHEMA', 'STOREY_HEIGHT_M', 'storey_points',
           'StoreyPoints', 'UNCOVERED_SHARE', 'uncovered_shares', 'write_exposure']
