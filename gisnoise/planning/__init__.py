"""Planning: candidate routes compared by exposure on one grid.
"""

from __future__ import annotations

from gisnoise.planning.compare import (
    COMPARISON_SCHEMA,
    Comparison,
    compare_routes,
    comparison_table,
    write_comparison,
)

__all__ = ['COMPARISON_SCHEMA', 'Comparison', 'compare_routes', 'comparison_table', 'write_comparison']
