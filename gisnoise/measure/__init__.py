"""Measurements: the campaign reader and level writer, the samples a fit and a diagnosis take.
"""

from __future__ import annotations

from gisnoise.measure.samples import Samples

__all__ = ['Samples']
