"""Maps: the evaluator (NumPy and numba engines), metrics over a grid, contours, rasters, plots, the map pipeline.
"""

from __future__ import annotations

from gisnoise.maps.cardset import (
    CardSet,
)
from gisnoise.maps.contours import (
    clip_warnings,
    clipped_levels,
    contour_features,
    contours_geojson,
    contours_text,
    geojson_text,
    isobands,
    isolines,
    parse_levels,
    write_geojson,
)
from gisnoise.maps.evaluate import (
    DEFAULT_ENGINE,
    ENGINES,
    evaluate_grid,
    evaluate_grid_fast,
    fast_engine_serves,
)
from gisnoise.maps.fastkernel import (
    WindowResult,
    require_numba,
    run_grid,
    run_window,
    warm_up,
    window_lattice,
)
from gisnoise.maps.flightchecks import (
    FlightFindings,
    crs_scale_warning,
    flight_findings,
)
from gisnoise.maps.geotiff import (
    NODATA,
    write_geotiff,
)
from gisnoise.maps.grids import (
    MAX_DISTANCE_M,
    SIZED_METRICS,
    audible_distance,
    auto_margin,
    grid_for_map,
    grid_for_trajectory,
    level_table,
)
from gisnoise.maps.ground import (
    ChosenGround,
    checked_ground,
)
from gisnoise.maps.hemisource import (
    prepare_flight,
)
from gisnoise.maps.instants import (
    FlightInstants,
)
from gisnoise.maps.palette import (
    ISOLINE_COLOUR,
    NOISE_CLASSES,
    PALETTE_NAME,
    PHASE_COLOURS,
    class_colours,
    class_labels,
    colour_for,
    palette_doc,
)
from gisnoise.maps.pipeline import (
    evaluate_flying,
    make_map,
)
from gisnoise.maps.plots import (
    directivity_grid,
    plot_directivity,
    plot_map,
)
from gisnoise.maps.powers import (
    check_power_ranges,
)
from gisnoise.maps.prepare import (
    TIE_DB,
    Z95,
    tie_std,
)
from gisnoise.maps.receivers import (
    Receivers,
    receivers_for,
    segment_cells,
)
from gisnoise.maps.result import (
    METRICS,
    MapResult,
    band_unit,
    snapshot_name,
    threshold_name,
)
from gisnoise.maps.sel import (
    SEL_OFFSET_DB,
    metric_levels,
    sel_edge_bound,
    sel_margin,
)
from gisnoise.maps.threads import (
    default_threads,
    map_threads,
)

__all__ = ['audible_distance', 'auto_margin', 'band_unit', 'CardSet', 'check_power_ranges', 'checked_ground', 'ChosenGround', 'class_colours', 'class_labels', 'clip_warnings', 'clipped_levels', 'colour_for', 'contour_features', 'contours_geojson', 'contours_text', 'DEFAULT_ENGINE', 'default_threads', 'directivity_grid', 'ENGINES', 'evaluate_flying', 'evaluate_grid', 'evaluate_grid_fast', 'fast_engine_serves', 'FlightFindings', 'flight_findings', 'crs_scale_warning', 'FlightInstants', 'geojson_text', 'grid_for_map', 'grid_for_trajectory', 'isobands', 'ISOLINE_COLOUR', 'isolines', 'level_table', 'make_map', 'map_threads', 'MapResult', 'MAX_DISTANCE_M', 'metric_levels', 'METRICS', 'NODATA', 'NOISE_CLASSES', 'palette_doc', 'PALETTE_NAME', 'parse_levels', 'PHASE_COLOURS', 'plot_directivity', 'plot_map', 'prepare_flight', 'Receivers', 'receivers_for', 'require_numba', 'run_grid', 'run_window', 'segment_cells', 'sel_edge_bound', 'sel_margin', 'SEL_OFFSET_DB', 'SIZED_METRICS', 'snapshot_name', 'threshold_name', 'TIE_DB', 'tie_std', 'warm_up', 'window_lattice', 'WindowResult', 'write_geojson', 'write_geotiff', 'Z95']
