"""Maps: the evaluator (NumPy and numba engines), metrics over a grid, contours, plots, the map pipeline.
"""

from __future__ import annotations

from gisnoise.maps.contours import (
    contour_features,
    contours_geojson,
    isobands,
    isolines,
    parse_levels,
    write_geojson,
)
from gisnoise.maps.evaluate import (
    CardSet,
    MapResult,
    evaluate_grid,
)
from gisnoise.maps.fastkernel import (
    evaluate_grid_fast,
    segment_cells,
)
from gisnoise.maps.pipeline import (
    make_map,
)
from gisnoise.maps.plots import (
    directivity_grid,
    plot_directivity,
)

__all__ = ['CardSet', 'MapResult', 'contour_features', 'contours_geojson', 'directivity_grid', 'evaluate_grid', 'evaluate_grid_fast', 'isobands', 'isolines', 'make_map', 'parse_levels', 'plot_directivity', 'segment_cells', 'write_geojson']
