"""Maps: the evaluator (NumPy and numba engines), metrics over a grid, contours, plots, the map pipeline.
"""

from __future__ import annotations

