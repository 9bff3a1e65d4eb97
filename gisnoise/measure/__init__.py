"""Measurements: the campaign reader and level writer, the samples a fit and a diagnosis take.
"""

from __future__ import annotations

from gisnoise.measure.samples import Samples, series_ids, series_key

__all__ = ['Samples', 'series_key', 'series_ids']
