"""Building heights as layers hold them (OpenStreetMap's forms), and the storeys of a building.

Heights
-------
:func:`parse_height` reads a ``height`` value: a number (metres), or text holding a number and
an optional unit, as OpenStreetMap writes heights: ``"10"``, ``"10 m"``, ``"10.5m"``,
``"12 ft"``, ``"40'"``, ``"40'6\\""`` (feet and inches).  Units: ``m``, ``metre(s)``,
``meter(s)`` (metres) and ``ft``, ``foot``, ``feet``, ``'`` (international feet of 0.3048 m);
a decimal point, not a comma.  A height is more than 0 and at most :data:`MAX_HEIGHT_M`
(1000 m); anything else (``"~10"``, ``"10;12"``, ``"-3"``, ``0``) is not a height: NaN, unknown.
:func:`parse_levels` reads ``building:levels`` (storeys above ground): a number more than 0 and
at most :data:`MAX_LEVELS`, else NaN.

Storeys
-------
A building's height H is its height, else (no height, or none that reads) its levels times
the storey height (:data:`STOREY_HEIGHT_M`, 3 m) (:func:`roof_heights`).  It has
``n = floor(H / storey_height + 1/2)`` storeys, at least 1, of equal height H / n; a receiver
stands at the middle of each storey, ``(k + 1/2) H / n`` above the ground for ``k = 0 ... n - 1``
(:func:`storey_receiver_heights`): window height, up to the top storey just below the roof.
A building without a height has no storeys; its façade is judged at the assessment height alone.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

__all__ = ["STOREY_HEIGHT_M", "MAX_HEIGHT_M", "MAX_LEVELS", "FOOT_M", "is_blank", "parse_height", "parse_levels",
           "roof_heights", "storey_receiver_heights"]

STOREY_HEIGHT_M = 3.0
"""Height of a storey, m: turns ``building:levels`` into a height, and a height into storeys."""
MAX_HEIGHT_M = 1000.0
"""The largest height read as a building's, m (the tallest building is 828 m)."""
MAX_LEVELS = 300.0
"""The most storeys read as a building's."""
FOOT_M = 0.3048
"""The international foot, m."""

_NUMBER = r"(\d+(?:\.\d*)?|\.\d+)"
_WITH_UNIT = re.compile(rf"^{_NUMBER}\s*(m|metres?|meters?|ft|foot|feet|')?$", re.IGNORECASE)
_FEET_INCHES = re.compile(rf"^{_NUMBER}\s*'\s*{_NUMBER}\s*(\"|''|in)$", re.IGNORECASE)


def _plain_number(v: Any) -> float | None:
    """``v`` as a float when it is a number (not a bool), else None."""
    v = v.item() if isinstance(v, np.generic) else v
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


def is_blank(v: Any) -> bool:
    """True for a value that holds nothing: None, NaN, an empty or blank text.

    >>> [is_blank(v) for v in (None, float("nan"), "", "  ", "0", 0)]
    [True, True, True, True, False, False]
    """
    if v is None:
        return True
    if isinstance(v, str):
        return not v.strip()
    f = _plain_number(v)
    return f is not None and math.isnan(f)


def parse_height(v: Any) -> float:
    """A building's height in m from a layer's value (see the module docstring); NaN when it is none.

    Examples
    --------
    >>> [parse_height(v) for v in (12, 10.5, "10", "10 m", "10.5m", " 7 Metres ")]
    [12.0, 10.5, 10.0, 10.0, 10.5, 7.0]
    >>> round(parse_height("12 ft"), 4), round(parse_height("40'6\\""), 4)
    (3.6576, 12.3444)
    >>> [parse_height(v) for v in ("~10", "10;12", "-3", 0, "10,5", None, "", 2000)]
    [nan, nan, nan, nan, nan, nan, nan, nan]
    """
    f = _plain_number(v)
    if f is None and isinstance(v, str):
        s = v.strip()
        m = _WITH_UNIT.match(s)
        if m is not None:
            unit = (m.group(2) or "m").lower()
            f = float(m.group(1)) * (FOOT_M if unit in ("ft", "foot", "feet", "'") else 1.0)
        else:
            fi = _FEET_INCHES.match(s)
            if fi is not None:
                f = (float(fi.group(1)) + float(fi.group(2)) / 12.0) * FOOT_M
    if f is None or not (math.isfinite(f) and 0.0 < f <= MAX_HEIGHT_M):
        return math.nan
    return f


def parse_levels(v: Any) -> float:
    """Storeys above ground from a layer's ``building:levels`` value (a number or its text); NaN when it is none.

    >>> [parse_levels(v) for v in (5, "20", " 2.5 ", "3;4", "-1", 0, None)]
    [5.0, 20.0, 2.5, nan, nan, nan, nan]
    """
    f = _plain_number(v)
    if f is None and isinstance(v, str):
        m = re.fullmatch(_NUMBER, v.strip())
        f = float(m.group(1)) if m is not None else None
    if f is None or not (math.isfinite(f) and 0.0 < f <= MAX_LEVELS):
        return math.nan
    return f


def roof_heights(height_m: np.ndarray | None, levels: np.ndarray | None, n: int,
                 storey_height_m: float = STOREY_HEIGHT_M) -> np.ndarray:
    """Height of each of ``n`` buildings, m: its height, else its levels x ``storey_height_m``, else NaN.

    >>> roof_heights(np.array([15.0, np.nan, np.nan]), np.array([9.0, 4.0, np.nan]), 3).tolist()
    [15.0, 12.0, nan]
    """
    h = np.full(n, np.nan) if height_m is None else np.asarray(height_m, dtype=float).copy()
    if levels is not None:
        gap = ~np.isfinite(h)
        h[gap] = np.asarray(levels, dtype=float)[gap] * storey_height_m
    return h


def storey_receiver_heights(height_m: float, storey_height_m: float = STOREY_HEIGHT_M) -> np.ndarray:
    """Receiver heights above ground of a building ``height_m`` high, m: the middle of each storey (see the module
    docstring); none for an unknown height.

    >>> storey_receiver_heights(15.0).tolist()
    [1.5, 4.5, 7.5, 10.5, 13.5]
    >>> storey_receiver_heights(10.0).round(3).tolist()  # 3 storeys of 3.333 m
    [1.667, 5.0, 8.333]
    >>> storey_receiver_heights(2.0).tolist(), storey_receiver_heights(float("nan")).tolist()
    ([1.0], [])
    """
    if not math.isfinite(height_m) or height_m <= 0:
        return np.zeros(0)
    n = max(1, math.floor(height_m / storey_height_m + 0.5))
    return (np.arange(n) + 0.5) * (height_m / n)
