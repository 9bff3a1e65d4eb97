"""The levels of a contour map and where the grid's edge cuts them.

:func:`parse_levels` reads levels; :func:`clipped_levels` and :func:`clip_warnings` name the
levels whose contours reach the grid's outer cells (a contour cut by the edge rather than closed
by the levels); :func:`geojson_warnings` is what a GeoJSON of the map says in ``gisnoise.warnings``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.maps._checks import as_float
from gisnoise.maps.sel import metric_levels

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.maps.result import MapResult

__all__ = ["parse_levels", "edge_max", "clipped_levels", "clip_warnings", "geojson_warnings"]


def parse_levels(levels: Any, *, field: str = "levels") -> list[float]:
    """Sorted unique finite levels from a sequence or a comma-separated string (dB).

    >>> parse_levels("60, 45,50")
    [45.0, 50.0, 60.0]
    """
    if isinstance(levels, str):
        parts = [p.strip() for p in levels.split(",") if p.strip()]
    elif np.ndim(levels) == 0:
        parts = [levels]
    else:
        parts = list(levels)
    out = [as_float(p, field) for p in parts]
    if not out:
        raise InputError(f"{field}: give at least one level", field=field)
    return sorted(set(out))


def edge_max(z: np.ndarray) -> float:
    """The largest finite value in the outer cells of a 2-D band (NaN when there is none)."""
    a = np.asarray(z, dtype=float)
    if a.ndim != 2 or a.size == 0:
        return float("nan")
    edge = np.concatenate([a[0], a[-1], a[:, 0], a[:, -1]])
    edge = edge[np.isfinite(edge)]
    return float(edge.max()) if edge.size else float("nan")


def clipped_levels(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> dict[str, list[float]]:
    """Metric -> the levels whose contours the grid's edge cuts (some outer cell at or above them).

    Only metrics with at least one such level are listed; ``metrics`` defaults to the level bands.
    """
    lv = parse_levels(levels)
    names = result.level_bands() if metrics is None else list(metrics)
    out: dict[str, list[float]] = {}
    for name in names:
        top = edge_max(result.band(name))
        cut = [lo for lo in metric_levels(name, lv) if top >= lo]
        if cut:
            out[name] = cut
    return out


def clip_warnings(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> list[str]:
    """One line per metric whose contours the grid's edge cuts, naming the metric, levels and edge maximum."""
    out = []
    units = result.units
    for name, cut in clipped_levels(result, levels, metrics=metrics).items():
        unit = units.get(name, "dB(A)")
        top = edge_max(result.band(name))
        lv = ", ".join(f"{v:g}" for v in cut)
        out.append(f"{name} {lv} {unit} contours are clipped: the grid's edge reaches {top:.1f} {unit}; "
                   f"they carry \"clipped\": true{_CLIP_TAIL}")
    return out


_CLIP_TAIL = " (a wider margin shows them whole)"  # how a line of clip_warnings ends


def geojson_warnings(result: MapResult, levels: Any, metrics: Sequence[str] | None) -> list[str]:
    """``gisnoise.warnings``: the map's own (``metadata["warnings"]``) and the clip warnings of these levels."""
    own = [w for w in result.metadata.get("warnings", []) if not str(w).endswith(_CLIP_TAIL)]
    return own + clip_warnings(result, levels, metrics=metrics)
