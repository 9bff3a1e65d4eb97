"""Planning: candidate routes compared by exposure on one grid.
"""

from __future__ import annotations

from gisnoise.planning.compare import (
    COMPARISON_SCHEMA,
    Comparison,
    compare_routes,
    comparison_table,
    routes_margin,
    score_route,
    write_comparison,
)
from gisnoise.planning.optimize import (
    Optimized,
    corridor_half_width,
    optimize_route,
    waypoints_geojson,
)

__all__ = ['COMPARISON_SCHEMA', 'Comparison', 'Optimized', 'compare_routes', 'comparison_table', 'corridor_half_width',
           'optimize_route', 'routes_margin', 'score_route', 'waypoints_geojson', 'write_comparison']
