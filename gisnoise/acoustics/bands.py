"""One-third-octave bands of IEC 61260-1 (base 10): mid-band and edge frequencies, level-file column names.

The mid-band frequencies are ``fm = 1000 * 10**(x/10)`` Hz for integer ``x``; a band
spans ``fm * G**(-1/6)`` to ``fm * G**(1/6)`` with ``G = 10**0.3``.  Level files name a
band's column ``L_<nominal Hz>`` after its ISO 266 preferred frequency (``L_160``,
``L_1250``, ``L_31.5``).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from gisnoise.acoustics._checks import _positive, _scalar
from gisnoise.errors import InputError

__all__ = [
    "third_octave_centres",
    "nominal_frequency",
    "exact_frequency",
    "band_name",
    "band_edges",
    "band_frequency",
    "is_band_name",
]

G = 10.0 ** 0.3
"""Base-10 octave frequency ratio of IEC 61260-1."""

_R10 = (1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0, 6.3, 8.0)
"""Nominal mantissas of one-third-octave mid-band frequencies (IEC 61260-1 Annex E, ISO 266)."""


_BAND_NAME = re.compile(r"^L_(\d+(?:\.\d+)?)$")


def band_edges(f_hz: Any) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper band-edge frequencies (Hz) of one-third-octave bands, base 10.

    Parameters
    ----------
    f_hz : float or array_like
        Exact mid-band frequencies, Hz.

    Returns
    -------
    lower, upper : ndarray
        ``f_hz * G**(-1/6)`` and ``f_hz * G**(1/6)``, Hz.

    Examples
    --------
    >>> lo, hi = band_edges(1000.0)
    >>> round(float(lo), 1), round(float(hi), 1)
    (891.3, 1122.0)
    """
    f = np.asarray(f_hz, dtype=float)
    return f * G ** (-1.0 / 6.0), f * G ** (1.0 / 6.0)


def _band_index(f_hz: np.ndarray) -> np.ndarray:
    """Band number x of ``1000 * 10**(x/10)`` nearest to each frequency."""
    return np.round(10.0 * np.log10(f_hz / 1000.0)).astype(int)


def third_octave_centres(f_min: float = 25.0, f_max: float = 20000.0) -> np.ndarray:
    """Exact mid-band frequencies of the one-third-octave bands from ``f_min`` to ``f_max``.

    Base-10 system of IEC 61260-1: ``fm = 1000 * 10**(x/10)`` Hz for integer x.
    A band is included when its nominal frequency lies in ``[f_min, f_max]``
    (``f_min=25, f_max=20000`` gives the 30 bands 25 Hz ... 20 kHz).

    Parameters
    ----------
    f_min, f_max : float
        Lowest and highest nominal mid-band frequency, Hz.

    Returns
    -------
    ndarray
        Exact mid-band frequencies, Hz, ascending.

    Examples
    --------
    >>> f = third_octave_centres()
    >>> len(f), round(float(f[0]), 3), float(f[16]), round(float(f[-1]), 1)
    (30, 25.119, 1000.0, 19952.6)
    """
    lo = _scalar(f_min, "f_min")
    hi = _scalar(f_max, "f_max")
    if lo <= 0:
        raise InputError(f"f_min must be > 0 Hz, got {lo}", field="f_min")
    if hi < lo:
        raise InputError(f"f_max must be >= f_min ({lo} Hz), got {hi}", field="f_max")
    x0, x1 = _band_index(np.array([lo, hi]))
    return 1000.0 * 10.0 ** (np.arange(x0, x1 + 1) / 10.0)


def nominal_frequency(f_hz: Any) -> np.ndarray:
    """Nominal (preferred) mid-band frequency of the one-third-octave band holding ``f_hz``.

    Float or array_like, Hz.  The band is the one whose exact mid-band frequency
    is nearest on a log scale; the nominal value is its IEC 61260-1 / ISO 266
    preferred number (25, 31.5, 40, ..., 12500, 16000, 20000).

    Examples
    --------
    >>> nominal_frequency([25.119, 1258.9, 19952.6]).tolist()
    [25.0, 1250.0, 20000.0]
    """
    f = _positive(f_hz, "f_hz")
    x = _band_index(f)
    decade = np.floor_divide(x, 10)
    mant = np.asarray(_R10)[np.mod(x, 10)]
    return np.round(mant * 10.0 ** (decade + 3), 6)


def exact_frequency(nominal_hz: Any) -> np.ndarray:
    """Exact base-10 mid-band frequency (Hz) of the band with nominal frequency ``nominal_hz``.

    Examples
    --------
    >>> round(float(exact_frequency(31.5)), 3)
    31.623
    """
    f = _positive(nominal_hz, "nominal_hz")
    return 1000.0 * 10.0 ** (_band_index(f) / 10.0)


def _format_nominal(v: float) -> str:
    return str(int(round(v))) if abs(v - round(v)) < 1e-9 else f"{v:g}"


def band_name(f_hz: Any) -> Any:
    """Level-file column name ``L_<nominal Hz>`` of the band holding ``f_hz``.

    Returns a str for a scalar, a list of str for an array.

    Examples
    --------
    >>> band_name(158.49), band_name([31.62, 1258.9])
    ('L_160', ['L_31.5', 'L_1250'])
    """
    nom = nominal_frequency(f_hz)
    if nom.ndim == 0:
        return "L_" + _format_nominal(float(nom))
    return ["L_" + _format_nominal(float(v)) for v in nom.ravel()]


def is_band_name(name: str) -> bool:
    """True when ``name`` is a one-third-octave band column ``L_<nominal Hz>``."""
    m = _BAND_NAME.match(str(name))
    if not m:
        return False
    v = float(m.group(1))
    return v > 0 and abs(float(nominal_frequency(v)) - v) <= 1e-9 * v


def band_frequency(name: str) -> float:
    """Exact mid-band frequency (Hz) of a band column name ``L_<nominal Hz>``.

    Raises
    ------
    InputError
        When ``name`` is not of that form or not a nominal one-third-octave frequency.

    Examples
    --------
    >>> round(band_frequency("L_1250"), 3)
    1258.925
    """
    if not is_band_name(name):
        raise InputError(
            f"{name!r} is not a one-third-octave band column (L_<nominal Hz>, e.g. L_160, L_1250)",
            field=str(name),
        )
    m = _BAND_NAME.match(str(name))
    assert m is not None
    return float(exact_frequency(float(m.group(1))))
