"""The map result: noise metrics on a grid, with the names and units of its bands.

Band names: the metrics ``LAmax``, ``LAeq``, ``SEL`` (:data:`METRICS`), time above a
level ``TA<level>`` (:func:`threshold_name`), the snapshot ``LA@<t>s``
(:func:`snapshot_name`) and the uncertainty bands ``<metric>_std``, ``<metric>_p95``.

Examples
--------
>>> threshold_name(57.5), snapshot_name(120.0)
('TA57.5', 'LA@120s')
>>> band_unit("TA55"), band_unit("LAeq_std"), band_unit("LAeq")
('s', 'dB', 'dB(A)')
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.geo import GridSpec, apply_affine

__all__ = ["METRICS", "MapResult", "band_unit", "snapshot_name", "threshold_name"]

METRICS = ("LAmax", "LAeq", "SEL")
"""Metrics that ``metrics=`` may name; time above and snapshot are asked for by value."""


def threshold_name(level_db: float) -> str:
    """Band name of the time above ``level_db``: ``TA55``, ``TA57.5``."""
    return f"TA{level_db:g}"


def snapshot_name(t_s: float) -> str:
    """Band name of the snapshot at ``t_s``: ``LA@120s``."""
    return f"LA@{t_s:g}s"


def band_unit(name: str) -> str:
    """Unit of a band by its name: ``s`` for time above, ``dB`` for standard deviations, else ``dB(A)``."""
    if name.startswith("TA"):
        return "s"
    if name.endswith("_std"):
        return "dB"
    return "dB(A)"


@dataclass(frozen=True, eq=False)
class MapResult:
    """Noise metrics on a grid.

    Attributes
    ----------
    bands : dict of str -> ndarray
        Metric name -> array of shape ``grid.shape`` (row 0 north), float64; NaN where
        no value (receiver outside the DEM).
    grid : GridSpec
        The receivers.
    metadata : dict
        What was computed and how (``units`` per band, period, heights, cards, ...).
    """

    bands: dict[str, np.ndarray]
    grid: GridSpec
    metadata: dict[str, Any] = field(default_factory=dict)

    def band(self, name: str) -> np.ndarray:
        """One band by name; :class:`~gisnoise.errors.InputError` lists the known ones."""
        try:
            return self.bands[name]
        except KeyError:
            raise InputError(f"no band {name!r}; bands: {', '.join(self.bands)}", field="metric") from None

    @property
    def units(self) -> dict[str, str]:
        return dict(self.metadata.get("units", {}))

    def level_bands(self) -> list[str]:
        """Bands holding levels in dB(A) (the ones to contour)."""
        u = self.units
        return [b for b in self.bands if u.get(b) == "dB(A)"]

    def value_at(self, name: str, lon: Any, lat: Any) -> np.ndarray:
        """Band value of the cells containing ``lon, lat`` (deg); NaN outside the grid."""
        x, y = self.grid.from_wgs84(lon, lat)
        col, row = apply_affine(~self.grid.transform, x, y)
        col = np.floor(np.asarray(col)).astype(int)
        row = np.floor(np.asarray(row)).astype(int)
        a = self.band(name)
        inside = (row >= 0) & (row < self.grid.height) & (col >= 0) & (col < self.grid.width)
        out = np.full(np.shape(row), np.nan)
        out[inside] = a[row[inside], col[inside]]
        return out
