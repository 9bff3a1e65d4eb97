"""Weighting and summing band levels: IEC 61672-1 A-weighting, the A-weighted overall level of
band levels, the free-field correction of a microphone mount.

Levels are dB re 20 uPa.  Functions accept floats or arrays and broadcast.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from gisnoise.acoustics._checks import _bands_of, _positive
from gisnoise.acoustics.bands import third_octave_centres
from gisnoise.errors import InputError

__all__ = ["MOUNT_CORRECTIONS_DB", "a_weighting", "overall_a_level", "mount_correction", "pink_band_loss_db"]

# IEC 61672-1:2013 equations (E.1)-(E.6): pole frequencies and the 1 kHz normalisation
_F1, _F2, _F3, _F4 = 20.598997, 107.65265, 737.86223, 12194.217
_A1000 = -2.000

MOUNT_CORRECTIONS_DB: Mapping[str, float] = MappingProxyType(
    {"ground_plate": -6.0, "free_field": 0.0, "pole": 0.0}
)
"""Free-field correction (dB) added to levels measured with each microphone mount.

A microphone flush on a ground plate receives the direct and the in-phase
reflected wave, +6 dB over free field; free-field and pole-mounted
microphones need no correction."""


def a_weighting(f_hz: Any) -> np.ndarray:
    """A-weighting of IEC 61672-1:2013 (analytic definition, Annex E), dB.

    ``A(f) = 20 lg[f4^2 f^4 / ((f^2+f1^2) sqrt(f^2+f2^2) sqrt(f^2+f3^2) (f^2+f4^2))] - A1000``
    with f1 = 20.598997 Hz, f2 = 107.65265 Hz, f3 = 737.86223 Hz,
    f4 = 12194.217 Hz and A1000 = -2.000 dB.

    Parameters
    ----------
    f_hz : float or array_like
        Frequency, Hz, >= 0 (0 Hz gives -inf).

    Returns
    -------
    ndarray
        Weighting, dB (0.0 at 1 kHz).

    Examples
    --------
    >>> np.round(a_weighting([10.0, 1000.0, 19952.6]), 1).tolist()
    [-70.4, 0.0, -9.3]
    """
    f = _positive(f_hz, "f_hz", allow_zero=True)
    f2 = f * f
    num = _F4**2 * f2 * f2
    den = (f2 + _F1**2) * np.sqrt(f2 + _F2**2) * np.sqrt(f2 + _F3**2) * (f2 + _F4**2)
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(num / den) - _A1000


def _energy_sum(levels: np.ndarray, axis: int = -1) -> np.ndarray:
    """10 lg sum 10^(L/10) along ``axis``; -inf when every term is -inf."""
    top = np.max(levels, axis=axis, keepdims=True)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.sum(10.0 ** ((levels - safe) / 10.0), axis=axis, keepdims=True)
        out = safe + 10.0 * np.log10(s)
    out = np.where(np.isneginf(top), -np.inf, out)
    out = np.where(np.isposinf(top), np.inf, out)
    return np.squeeze(out, axis=axis)


def overall_a_level(L_bands: Any, f_hz: Any) -> np.ndarray:
    """A-weighted overall level of unweighted band levels.

    ``LA = 10 lg sum_b 10^((L_b + A(f_b)) / 10)`` over the last axis.

    Parameters
    ----------
    L_bands : array_like, shape (..., nb)
        Unweighted band levels, dB.  A NaN band makes the result NaN (a missing
        band is not silently treated as silence); -inf is silence.
    f_hz : array_like, shape (nb,)
        Exact mid-band frequencies, Hz.

    Returns
    -------
    ndarray, shape (...)
        A-weighted level, dB(A).

    Examples
    --------
    >>> round(float(overall_a_level([94.0, 94.0], [1000.0, 1000.0])), 2)
    97.01
    """
    L, f = _bands_of(L_bands, f_hz)
    nan = np.any(np.isnan(L), axis=-1)
    out = _energy_sum(np.where(np.isnan(L), -np.inf, L) + a_weighting(f), axis=-1)
    return np.where(nan, np.nan, out)


def pink_band_loss_db(f_top_hz: Any, f_min_hz: float = 25.0, f_max_hz: float = 20000.0) -> np.ndarray:
    """How much lower the A-weighted level of a pink spectrum reads without the bands above ``f_top_hz``, dB.

    Pink sound carries equal energy in every one-third-octave band; over the bands from ``f_min_hz`` to
    ``f_max_hz`` (nominal) its A-weighted level is ``10 lg sum_b 10^(A(f_b)/10)`` plus a constant, each band
    weighted at its exact mid-band frequency.  The loss is that sum over all the bands over the sum over
    those up to ``f_top_hz``:  what a recording whose sample rate carries the bands up to ``f_top_hz``
    only misses of a broadband source (less for a source whose energy falls off faster with frequency, as
    most do; none for one that is silent above ``f_top_hz``).

    Parameters
    ----------
    f_top_hz : float or array_like
        Mid-band frequency of the highest band kept (exact or nominal), Hz.
    f_min_hz, f_max_hz : float
        Nominal frequencies of the lowest and the highest band of the full set, Hz.

    Returns
    -------
    ndarray
        Loss, dB (0 when every band is kept).

    Examples
    --------
    >>> np.round(pink_band_loss_db([3150, 6300, 16000, 20000]), 2).tolist()
    [1.85, 0.61, 0.03, 0.0]
    """
    top = _positive(f_top_hz, "f_top_hz")
    f = third_octave_centres(f_min_hz, f_max_hz)
    w = 10.0 ** (a_weighting(f) / 10.0)
    kept = np.sum(np.where(f < top[..., None] * 10.0 ** 0.05, w, 0.0), axis=-1)  # up to the band holding f_top
    with np.errstate(divide="ignore"):
        return np.asarray(10.0 * np.log10(np.sum(w) / kept))


def mount_correction(mount: str) -> float:
    """Free-field correction (dB) to add to levels from a microphone with this mount.

    ``"ground_plate"`` -6 dB (pressure doubling on the plate), ``"free_field"``
    and ``"pole"`` 0 dB.

    Raises
    ------
    InputError
        For any other mount, naming the field ``mount``.

    Examples
    --------
    >>> mount_correction("ground_plate"), mount_correction("pole")
    (-6.0, 0.0)
    """
    try:
        return float(MOUNT_CORRECTIONS_DB[mount])
    except (KeyError, TypeError):
        known = ", ".join(MOUNT_CORRECTIONS_DB)
        raise InputError(f"unknown microphone mount {mount!r} (known: {known})", field="mount") from None
