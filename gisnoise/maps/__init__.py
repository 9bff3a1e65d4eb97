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
    isobands,
    isolines,
    parse_levels,
    write_geojson,
)
from gisnoise.maps.evaluate import (
    ENGINES,
    evaluate_grid,
    evaluate_grid_fast,
)
from gisnoise.maps.fastkernel import (
    WindowResult,
    require_numba,
    run_grid,
    run_window,
    window_lattice,
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
)
from gisnoise.maps.instants import (
    FlightInstants,
    prepare_flight,
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
    make_map,
)
from gisnoise.maps.plots import (
    directivity_grid,
    plot_directivity,
)
from gisnoise.maps.receivers import (
    Receivers,
    receivers_for,
    segment_cells,
)
from gisnoise.maps.reference import (
    Z95,
)
from gisnoise.maps.result import (
    METRICS,
    MapResult,
    band_unit,
    snapshot_name,
    threshold_name,
)
from gisnoise.maps.threads import (
    default_threads,
    map_threads,
)

__all__ = ['CardSet', 'ENGINES', 'FlightInstants', 'ISOLINE_COLOUR', 'NOISE_CLASSES', 'PALETTE_NAME', 'PHASE_COLOURS', 'class_colours', 'class_labels', 'colour_for', 'palette_doc', 'MAX_DISTANCE_M', 'METRICS', 'MapResult', 'SIZED_METRICS', 'audible_distance', 'auto_margin', 'clip_warnings', 'clipped_levels', 'grid_for_map', 'NODATA', 'Receivers', 'WindowResult', 'Z95', 'band_unit', 'contour_features', 'contours_geojson', 'default_threads', 'directivity_grid', 'evaluate_grid', 'evaluate_grid_fast', 'grid_for_trajectory', 'isobands', 'isolines', 'make_map', 'map_threads', 'parse_levels', 'plot_directivity', 'prepare_flight', 'receivers_for', 'require_numba', 'run_grid', 'run_window', 'segment_cells', 'snapshot_name', 'threshold_name', 'window_lattice', 'write_geojson', 'write_geotiff']
