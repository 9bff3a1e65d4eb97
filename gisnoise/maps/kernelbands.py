"""The level bands of a fast-engine map from its kernel's accumulators (parametric and hemisphere kernels alike).

The window kernels (:mod:`gisnoise.maps.fastkernel`, :mod:`gisnoise.maps.hemisource`) return per
cell the largest energy ``emax``, the trapezoid energy ``energy``, the time above each threshold
``ta`` and whether the cell was computed (within audibility, else certainly below the floor);
:func:`kernel_bands` turns them into the map's bands, NaN where not computed or not valid.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.maps.prepare import band_order
from gisnoise.maps.result import snapshot_name, threshold_name

__all__ = ["chunk_cells_of", "db", "kernel_bands"]


def db(x: np.ndarray) -> np.ndarray:
    """``10 log10(x)`` with 0 -> -inf and no warning."""
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(x)


def chunk_cells_of(value: Any, default: int) -> int:
    """Cells per kernel call: ``value`` checked (at least 1), or ``default`` when None."""
    if value is None:
        return int(default)
    if isinstance(value, bool) or int(value) < 1:
        raise InputError(f"chunk_cells must be >= 1, got {value!r}", field="chunk_cells")
    return int(value)


def kernel_bands(res: Any, shape: tuple[int, int], metrics: Sequence[str], thresholds: Sequence[float],
                 snap: float | None, period: float | None, floor: float | None, snap_res: Any = None,
                 valid: np.ndarray | None = None) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The bands of ``res`` (a window result over the whole grid of ``shape``) and the cells below the floor.

    ``snap_res``: the snapshot instant's result (band ``LA@<t>s``); ``valid``: cells with a
    receiver (False: NaN in every band).  Time above stays 0 in skipped cells when its
    threshold is at or above the floor (they are certainly below it).
    """
    below = ~res.computed
    bands = {name: np.full(shape, np.nan) for name in band_order(metrics, thresholds, snap, False)}
    if "LAmax" in metrics:
        bands["LAmax"] = db(res.emax.astype(np.float64))
    if "SEL" in metrics:
        bands["SEL"] = db(res.energy)
    if "LAeq" in metrics:
        assert period is not None
        bands["LAeq"] = db(res.energy / period)
    for i, thr in enumerate(thresholds):
        a = res.ta[i].copy()
        if floor is None or thr < floor:
            a[below] = np.nan
        bands[threshold_name(thr)] = a
    for name in ("LAmax", "SEL", "LAeq"):
        if name in bands:
            bands[name][below] = np.nan
    if snap_res is not None and snap is not None:
        a = db(snap_res.emax.astype(np.float64))
        a[~snap_res.computed] = np.nan
        bands[snapshot_name(snap)] = a
    if valid is not None and not valid.all():
        for a in bands.values():
            a[~valid] = np.nan
    return bands, below
