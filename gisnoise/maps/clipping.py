"""The levels of a contour map and where the edge of its values cuts them.

:func:`parse_levels` reads levels; :func:`clipped_levels` and :func:`clip_warnings` name the
levels whose contours reach the cells where the map's values end (a contour cut there rather than
closed by the levels): the grid's outer cells, and the cells next to cells without value (NaN:
receivers outside the DEM or on its nodata), where a contour stops as it stops at the grid's edge;
:func:`geojson_warnings` is what a GeoJSON of the map says in ``gisnoise.warnings``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.limits import check_map_level
from gisnoise.maps._checks import as_float
from gisnoise.maps.sel import metric_levels

if TYPE_CHECKING:  # pragma: no cover
    from gisnoise.maps.result import MapResult

__all__ = ["parse_levels", "edge_max", "cut_maxima", "clipped_levels", "clip_warnings", "geojson_warnings"]


def parse_levels(levels: Any, *, field: str = "levels") -> list[float]:
    """The contour levels of a map, dB(A), from a sequence or a comma-separated string: sorted, a level given
    twice merged into one (a map draws each level once), each finite and within [-50, 200] dB(A)
    (:func:`gisnoise.limits.check_map_level`: the A-weighted levels a microphone records).

    >>> parse_levels("60, 45,50,45")
    [45.0, 50.0, 60.0]
    >>> parse_levels([60, 45, -1000])
    Traceback (most recent call last):
    ...
    gisnoise.errors.InputError: levels: -1000 dB(A) is outside [-50, 200] dB(A) (the A-weighted levels a microphone records: below any measurement microphone's self-noise, above a jet engine at 1 m)
    """
    if isinstance(levels, str):
        parts = [p.strip() for p in levels.split(",") if p.strip()]
    elif np.ndim(levels) == 0:
        parts = [levels]
    else:
        parts = list(levels)
    out = [check_map_level(field, as_float(p, field)) for p in parts]
    if not out:
        raise InputError(f"{field}: give at least one level", field=field)
    return sorted(set(out))


def edge_max(z: np.ndarray) -> float:
    """The largest finite value in the cells where a 2-D band's values end (NaN when there is none).

    Those are the outer cells and the cells with a value next to (of the 8 neighbours) a cell without
    one (NaN): a contour reaching either is cut there, not closed by the levels (:func:`cut_maxima`).

    >>> edge_max(np.array([[1., 1., 1., 1.], [1., 5., 9., 1.], [1., 1., 1., 1.]]))
    1.0
    >>> edge_max(np.array([[1., 1., 1., 1.], [1., 5., np.nan, 1.], [1., 1., 1., 1.]]))
    5.0
    """
    outer, gap = cut_maxima(z)
    both = [v for v in (outer, gap) if np.isfinite(v)]
    return max(both) if both else float("nan")


def cut_maxima(z: np.ndarray) -> tuple[float, float]:
    """The largest finite values of a 2-D band in its outer cells and in its cells next to a cell without value.

    A cell next to one without value (NaN; -inf, no sound, is a value) is one of whose 8 neighbours is NaN:
    marching squares leaves out every square with a NaN corner, so the contours stop there.  Each maximum
    is NaN when there is no such finite cell.
    """
    a = np.asarray(z, dtype=float)
    if a.ndim != 2 or a.size == 0:
        return float("nan"), float("nan")
    edge = np.concatenate([a[0], a[-1], a[:, 0], a[:, -1]])
    edge = edge[np.isfinite(edge)]
    outer = float(edge.max()) if edge.size else float("nan")
    hole = np.isnan(a)
    if not hole.any():
        return outer, float("nan")
    near = np.zeros_like(hole)
    pad = np.pad(hole, 1)
    h, w = a.shape
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            near |= pad[dr:dr + h, dc:dc + w]
    v = a[near & np.isfinite(a)]
    return outer, float(v.max()) if v.size else float("nan")


def clipped_levels(result: MapResult, levels: Any, *, metrics: Sequence[str] | None = None) -> dict[str, list[float]]:
    """Metric -> the levels whose contours are cut: some outer cell, or some cell next to a cell without value,
    at or above them (:func:`edge_max`).

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
    """One line per metric whose contours are cut (:func:`clipped_levels`), naming the metric, the levels and
    the largest value at the grid's edge and next to the cells without value (receivers without DEM ground)."""
    out = []
    units = result.units
    for name, cut in clipped_levels(result, levels, metrics=metrics).items():
        unit = units.get(name, "dB(A)")
        outer, gap = cut_maxima(result.band(name))
        lo = min(cut)
        where, tails = [], []
        if outer >= lo:
            where.append(f"the grid's edge reaches {outer:.1f} {unit}")
            tails.append("a wider margin")
        if gap >= lo:
            where.append(f"the cells next to cells without a level (receivers without DEM ground) reach "
                         f"{gap:.1f} {unit}")
            tails.append("a DEM that covers the grid")
        lv = ", ".join(f"{v:g}" for v in cut)
        tail = f" ({' and '.join(tails)} {'shows' if len(tails) == 1 else 'show'} them whole)"
        out.append(f"{name} {lv} {unit} contours are clipped: {'; '.join(where)}; "
                   f"they carry \"clipped\": true{tail}")
    return out


def _is_clip_warning(w: str) -> bool:
    """Whether ``w`` is a line of :func:`clip_warnings` (it names clipped contours and ends with its tail)."""
    return " contours are clipped: " in w and w.endswith(" them whole)")


def geojson_warnings(result: MapResult, levels: Any, metrics: Sequence[str] | None) -> list[str]:
    """``gisnoise.warnings``: the map's own (``metadata["warnings"]``) and the clip warnings of these levels."""
    own = [w for w in result.metadata.get("warnings", []) if not _is_clip_warning(str(w))]
    return own + clip_warnings(result, levels, metrics=metrics)
