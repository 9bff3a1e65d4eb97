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


AIR_TEMPERATURE_C = (-90.0, 60.0)
"""Air temperatures met near the ground, deg C (the records: -89.2 and 56.7 deg C): outside, a temperature is
in another unit (293.15: kelvin)."""

AIR_PRESSURE_KPA = (25.0, 120.0)
"""Atmospheric pressures from the highest summits (about 33 kPa) to the lowest valleys (about 108 kPa), kPa:
outside, a pressure is in another unit (101325: pascal; 1013.25: hectopascal)."""


def _air(value: Any, name: str, what: str, unit: str, bounds: tuple[float, float],
         hint: Any) -> np.ndarray:
    """Finite values of ``name`` within ``bounds``; the first outside is refused with ``hint(v)`` (its other unit)."""
    a = _finite(value, name)
    lo, hi = bounds
    bad = (a < lo) | (a > hi)
    if np.any(bad):
        v = float(a[bad].flat[0])
        raise InputError(f"{name} must be {what} in {unit} within [{lo:g}, {hi:g}], got {v:g}{hint(v)}", field=name)
    return a


def _temperature(value: Any, name: str = "temperature_c") -> np.ndarray:
    """Finite air temperatures, deg C, within :data:`AIR_TEMPERATURE_C`."""
    return _air(value, name, "an air temperature", "deg C", AIR_TEMPERATURE_C,
                lambda v: f" ({v:g} K is {v - 273.15:g} deg C)" if 180.0 <= v <= 340.0 else "")


def _air_pressure(value: Any, name: str = "pressure_kpa") -> np.ndarray:
    """Finite atmospheric pressures, kPa, within :data:`AIR_PRESSURE_KPA`."""
    return _air(value, name, "an atmospheric pressure", "kPa", AIR_PRESSURE_KPA,
                lambda v: f" ({v:g} Pa is {v / 1000:g} kPa)" if 2.5e4 <= v <= 1.2e5 else
                f" ({v:g} hPa is {v / 10:g} kPa)" if 250.0 <= v <= 1200.0 else "")


def _bands_of(L_bands: Any, f_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """Band levels with the bands of the mid-band frequencies ``f_hz`` on their last axis."""
    L = _array(L_bands, "L_bands")
    f = _positive(f_hz, "f_hz")
    if f.ndim != 1 or L.ndim == 0 or L.shape[-1] != f.size:
        raise InputError(f"L_bands must have the {f.size} bands of f_hz on its last axis, got shape {L.shape}",
                         field="L_bands")
    return L, f
