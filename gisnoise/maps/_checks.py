"""Checked numbers of the map inputs: one refusal of non-numbers, non-finite and out-of-range values."""

from __future__ import annotations

import math
from typing import Any

from gisnoise.errors import InputError


def as_float(v: Any, name: str, *, minimum: float | None = None, strict: bool = False) -> float:
    """``v`` as a finite float, at least ``minimum`` (above it with ``strict``); else InputError naming ``name``.

    >>> as_float("2.5", "margin_m", minimum=0.0)
    2.5
    """
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {v!r}", field=name) from None
    if not math.isfinite(f):
        raise InputError(f"{name} must be finite, got {v!r}", field=name)
    if minimum is not None and (f < minimum or (strict and f == minimum)):
        raise InputError(f"{name} must be {'>' if strict else '>='} {minimum:g}, got {v!r}", field=name)
    return f
