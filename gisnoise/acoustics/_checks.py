"""Checks of the numeric inputs of the acoustics functions; errors name the offending field."""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.errors import InputError


def _array(value: Any, name: str) -> np.ndarray:
    """Float array of ``value``; InputError naming ``name`` when not numeric."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be numeric, got {value!r}", field=name) from None
    return arr


def _finite(value: Any, name: str) -> np.ndarray:
    arr = _array(value, name)
    if not np.all(np.isfinite(arr)):
        bad = arr[~np.isfinite(arr)].flat[0]
        raise InputError(f"{name} must be finite, got {bad}", field=name)
    return arr


def _positive(value: Any, name: str, *, allow_zero: bool = False) -> np.ndarray:
    arr = _finite(value, name)
    bad = arr < 0 if allow_zero else arr <= 0
    if np.any(bad):
        limit = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name} must be {limit}, got {arr[bad].flat[0]}", field=name)
    return arr


def _scalar(value: Any, name: str) -> float:
    arr = _finite(value, name)
    if arr.ndim != 0:
        raise InputError(f"{name} must be a single number, got shape {arr.shape}", field=name)
    return float(arr)


def _positive_scalar(value: Any, name: str) -> float:
    """A single finite number > 0; InputError naming ``name`` otherwise."""
    v = _scalar(value, name)
    if v <= 0:
        raise InputError(f"{name} must be > 0, got {v}", field=name)
    return v


def _temperature(value: Any, name: str = "temperature_c") -> np.ndarray:
    """Finite air temperatures, deg C, above absolute zero."""
    t = _finite(value, name)
    if np.any(t <= -273.15):
        raise InputError(f"{name} must be > -273.15, got {t[t <= -273.15].flat[0]}", field=name)
    return t


def _bands_of(L_bands: Any, f_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """Band levels with the bands of the mid-band frequencies ``f_hz`` on their last axis."""
    L = _array(L_bands, "L_bands")
    f = _positive(f_hz, "f_hz")
    if f.ndim != 1 or L.ndim == 0 or L.shape[-1] != f.size:
        raise InputError(f"L_bands must have the {f.size} bands of f_hz on its last axis, got shape {L.shape}",
                         field="L_bands")
    return L, f
