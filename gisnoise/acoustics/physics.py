"""Acoustic preprocessing: calibrated pressure -> band levels -> A-weighted level.

The chain of the paper's section 3 (SPEC section 2), as pure array functions:

* :func:`third_octave_centres`, :func:`nominal_frequency`, :func:`band_name`,
  :func:`band_frequency` -- one-third-octave bands of IEC 61260-1 (base 10) and
  the ``L_<nominal Hz>`` column names of level files;
* :func:`band_levels` -- a multirate IIR filter bank (IEC 61260-1 class 1)
  giving unweighted band levels per averaging block;
* :func:`a_weighting`, :func:`overall_a_level` -- IEC 61672-1 A-weighting and
  the A-weighted overall level of band levels;
* :func:`mount_correction` -- free-field correction of the microphone mount;
* :func:`speed_of_sound`, :func:`atmospheric_absorption`,
  :func:`absorption_correction`, :func:`absorption_corrected_level` -- ISO 9613-1
  absorption and its per-band correction (only bands clear of background);
* :func:`calibrate`, :func:`read_wav`, :func:`write_wav`, :func:`wav_band_levels`
  -- WAV audio in volts and its calibration to pascals.

Levels are dB re 20 uPa.  Functions accept floats or arrays and broadcast.

Examples
--------
>>> import numpy as np
>>> fs = 48000.0
>>> t = np.arange(int(2 * fs)) / fs
>>> p = np.sqrt(2.0) * np.sin(2 * np.pi * 1000.0 * t)   # 1 Pa RMS, 1 kHz
>>> t_s, f_hz, L = band_levels(p, fs)
>>> band_name(f_hz[16]), round(float(L[8, 16]), 1)
('L_1000', 94.0)
>>> round(float(overall_a_level(L[8], f_hz)), 1)
94.0
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from gisnoise.acoustics import _filterbank
from gisnoise.acoustics._filterbank import band_edges
from gisnoise.errors import InputError

__all__ = [
    "P_REF",
    "MOUNT_CORRECTIONS_DB",
    "a_weighting",
    "third_octave_centres",
    "nominal_frequency",
    "exact_frequency",
    "band_name",
    "band_edges",
    "band_frequency",
    "is_band_name",
    "band_levels",
    "overall_a_level",
    "mount_correction",
    "speed_of_sound",
    "atmospheric_absorption",
    "absorption_correction",
    "absorption_corrected_level",
    "background_levels",
    "calibrate",
    "read_wav",
    "write_wav",
    "wav_band_levels",
]

P_REF = 20e-6
"""Reference sound pressure, Pa."""

_R10 = (1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0, 6.3, 8.0)
"""Nominal mantissas of one-third-octave mid-band frequencies (IEC 61260-1 Annex E, ISO 266)."""

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

_BAND_NAME = re.compile(r"^L_(\d+(?:\.\d+)?)$")


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


# --------------------------------------------------------------------------- bands


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


# ----------------------------------------------------------------------- weighting


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
    L = _array(L_bands, "L_bands")
    f = _positive(f_hz, "f_hz")
    if f.ndim != 1 or L.ndim == 0 or L.shape[-1] != f.size:
        raise InputError(
            f"L_bands must have the {f.size} bands of f_hz on its last axis, got shape {L.shape}",
            field="L_bands",
        )
    nan = np.any(np.isnan(L), axis=-1)
    out = _energy_sum(np.where(np.isnan(L), -np.inf, L) + a_weighting(f), axis=-1)
    return np.where(nan, np.nan, out)


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


# ---------------------------------------------------------------------- atmosphere


def speed_of_sound(temperature_c: Any) -> np.ndarray:
    """Speed of sound in air, ``c = 331.3 sqrt(1 + T / 273.15)`` m/s.

    Parameters
    ----------
    temperature_c : float or array_like
        Air temperature, deg C (> -273.15).

    Examples
    --------
    >>> round(float(speed_of_sound(20.0)), 2)
    343.21
    """
    t = _finite(temperature_c, "temperature_c")
    if np.any(t <= -273.15):
        raise InputError(f"temperature_c must be > -273.15, got {t[t <= -273.15].flat[0]}", field="temperature_c")
    return 331.3 * np.sqrt(1.0 + t / 273.15)


def atmospheric_absorption(f_hz: Any, temperature_c: Any, humidity_pct: Any, pressure_kpa: Any = 101.325) -> np.ndarray:
    """Pure-tone atmospheric absorption coefficient of ISO 9613-1:1993, dB per metre.

    Equations (3)-(5) and (B.1)-(B.3) of ISO 9613-1: relaxation frequencies of
    oxygen and nitrogen from the molar concentration of water vapour.  The
    standard states +-10 % accuracy for -20 to 50 deg C, 10 to 100 % relative
    humidity, 50 Hz to 10 kHz and pressures below 200 kPa; outside, the formula
    is evaluated as is.  Bands use their exact mid-band frequency.

    Parameters
    ----------
    f_hz : float or array_like
        Frequency, Hz (>= 0).
    temperature_c : float or array_like
        Air temperature, deg C.
    humidity_pct : float or array_like
        Relative humidity, % (0-100).
    pressure_kpa : float or array_like
        Atmospheric pressure, kPa (> 0).

    Returns
    -------
    ndarray
        Attenuation coefficient alpha, dB/m.

    Examples
    --------
    >>> round(float(atmospheric_absorption(1000.0, 20.0, 70.0)) * 1000, 2)   # dB/km
    4.98
    """
    f = _positive(f_hz, "f_hz", allow_zero=True)
    t = _finite(temperature_c, "temperature_c")
    if np.any(t <= -273.15):
        raise InputError(f"temperature_c must be > -273.15, got {t[t <= -273.15].flat[0]}", field="temperature_c")
    hr = _finite(humidity_pct, "humidity_pct")
    if np.any((hr < 0) | (hr > 100)):
        raise InputError(f"humidity_pct must be within [0, 100], got {hr[(hr < 0) | (hr > 100)].flat[0]}",
                         field="humidity_pct")
    pa = _positive(pressure_kpa, "pressure_kpa")
    pr, t0, t01 = 101.325, 293.15, 273.16
    tk = t + 273.15
    psat_rel = 10.0 ** (-6.8346 * (t01 / tk) ** 1.261 + 4.6151)  # p_sat / p_r
    h = hr * psat_rel * (pr / pa)  # molar concentration of water vapour, %
    fro = (pa / pr) * (24.0 + 4.04e4 * h * (0.02 + h) / (0.391 + h))
    frn = (pa / pr) * (tk / t0) ** -0.5 * (9.0 + 280.0 * h * np.exp(-4.170 * ((tk / t0) ** (-1.0 / 3.0) - 1.0)))
    f2 = f * f
    return 8.686 * f2 * (
        1.84e-11 * (pr / pa) * (tk / t0) ** 0.5
        + (tk / t0) ** -2.5
        * (0.01275 * np.exp(-2239.1 / tk) / (fro + f2 / fro) + 0.1068 * np.exp(-3352.0 / tk) / (frn + f2 / frn))
    )


def background_levels(L_bands: Any, percentile: float = 10.0) -> np.ndarray:
    """Background level of each band: a low percentile of its levels over time.

    ``percentile=10`` gives the level exceeded 90 % of the time (L90), the usual
    residual-sound estimate when the source is away part of the time.

    Parameters
    ----------
    L_bands : array_like, shape (n, nb)
        Band levels over time, dB; NaN entries are ignored.
    percentile : float
        Percentile in [0, 100].

    Returns
    -------
    ndarray, shape (nb,)
        Background band levels, dB (NaN for a band without any level).
    """
    L = _array(L_bands, "L_bands")
    if L.ndim != 2:
        raise InputError(f"L_bands must be 2-D (time, band), got shape {L.shape}", field="L_bands")
    q = _scalar(percentile, "percentile")
    if not 0.0 <= q <= 100.0:
        raise InputError(f"percentile must be within [0, 100], got {q}", field="percentile")
    out = np.full(L.shape[1], np.nan)
    for j in range(L.shape[1]):
        col = L[:, j][~np.isnan(L[:, j])]
        if col.size:
            out[j] = np.percentile(col, q)
    return out


def absorption_correction(
    L_bands: Any,
    f_hz: Any,
    distance_m: Any,
    temperature_c: float,
    humidity_pct: float,
    pressure_kpa: float = 101.325,
    *,
    background_db: Any,
    min_snr_db: float = 10.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Undo atmospheric absorption over ``distance_m`` in bands that stand clear of background.

    A band is corrected (``L + alpha(fm) * d``) only where it stands at least
    ``min_snr_db`` above its background; elsewhere it is returned unchanged,
    since correcting background would invent sound.

    Parameters
    ----------
    L_bands : array_like, shape (n, nb) or (nb,)
        Measured unweighted band levels, dB (NaN: absent, never corrected).
    f_hz : array_like, shape (nb,)
        Exact mid-band frequencies, Hz.
    distance_m : float or array_like, shape (n,)
        Propagation distance of each row, m.
    temperature_c, humidity_pct, pressure_kpa : float
        Weather (deg C, %, kPa).
    background_db : array_like, shape (nb,) or (n, nb)
        Background level of each band, dB (see :func:`background_levels`);
        pass ``-inf`` to declare a band background-free.
    min_snr_db : float
        Margin above background required for a correction, dB.

    Returns
    -------
    L_corrected : ndarray, same shape as ``L_bands``
        Band levels with the correction applied where allowed, dB.
    corrected : ndarray of bool, same shape
        True where a band was corrected.

    Examples
    --------
    >>> f = np.array([1000.0, 8000.0])
    >>> L, ok = absorption_correction([[60.0, 45.0]], f, 200.0, 20.0, 70.0, background_db=[40.0, 40.0])
    >>> np.round(L, 2).tolist(), ok.tolist()
    ([[61.0, 45.0]], [[True, False]])
    """
    L = _array(L_bands, "L_bands")
    f = _positive(f_hz, "f_hz")
    if f.ndim != 1 or L.ndim == 0 or L.shape[-1] != f.size:
        raise InputError(f"L_bands must have the {f.size} bands of f_hz on its last axis, got shape {L.shape}",
                         field="L_bands")
    d = _positive(distance_m, "distance_m", allow_zero=True)
    if L.ndim == 2 and d.ndim == 1:
        d = d[:, None]
    bg = _array(background_db, "background_db")
    if np.any(np.isnan(bg)):
        raise InputError("background_db must not be NaN (use -inf for a background-free band)",
                         field="background_db")
    snr = _scalar(min_snr_db, "min_snr_db")
    alpha = atmospheric_absorption(f, temperature_c, humidity_pct, pressure_kpa)
    try:
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(L) & (L - bg >= snr)
        gain = alpha * d
        corrected = np.where(ok, L + gain, L)
    except ValueError:
        raise InputError(f"distance_m {d.shape} and background_db {bg.shape} must broadcast against "
                         f"L_bands {L.shape}", field="distance_m") from None
    return corrected, np.broadcast_to(ok, corrected.shape).copy()


def absorption_corrected_level(
    level_db: Any,
    L_bands: Any,
    f_hz: Any,
    distance_m: Any,
    temperature_c: float,
    humidity_pct: float,
    pressure_kpa: float = 101.325,
    *,
    background_db: Any,
    min_snr_db: float = 10.0,
) -> np.ndarray:
    """A-weighted level with the absorbed energy of the clear bands added back.

    ``LA_c = 10 lg(10^(LA/10) + sum_b 10^((L_b + A_b)/10) (10^(alpha_b d/10) - 1))``
    over the bands :func:`absorption_correction` corrects; the rest of the
    measured level (other bands, background) is kept as measured.  Works with
    any subset of bands (level files may carry only some).

    Parameters
    ----------
    level_db : float or array_like, shape (n,)
        Measured A-weighted level, dB(A).
    L_bands, f_hz, distance_m, temperature_c, humidity_pct, pressure_kpa, background_db, min_snr_db
        As in :func:`absorption_correction`.

    Returns
    -------
    ndarray, shape (n,)
        Absorption-corrected A-weighted level, dB(A).

    Examples
    --------
    >>> f = np.array([1000.0])
    >>> round(float(absorption_corrected_level(60.0, [[60.0]], f, 200.0, 20.0, 70.0,
    ...                                        background_db=[30.0])[0]), 3)
    60.996
    """
    la = _array(level_db, "level_db")
    L = _array(L_bands, "L_bands")
    if L.ndim == 1:
        L = L[None, :]
    corrected, ok = absorption_correction(L, f_hz, distance_m, temperature_c, humidity_pct, pressure_kpa,
                                          background_db=background_db, min_snr_db=min_snr_db)
    aw = a_weighting(_positive(f_hz, "f_hz"))
    with np.errstate(over="ignore", invalid="ignore"):  # -inf - -inf in bands that stay uncorrected
        gain_db = np.where(ok, corrected - L, 0.0)
        extra = np.where(ok, 10.0 ** ((L + aw) / 10.0) * (10.0 ** (gain_db / 10.0) - 1.0), 0.0)
        return 10.0 * np.log10(10.0 ** (la / 10.0) + extra.sum(axis=-1))


# ------------------------------------------------------------------- filter bank


def _bands_for(fs_hz: float, f_min: float, f_max: float | None) -> np.ndarray:
    top = _filterbank.max_centre(fs_hz)
    if f_max is None:
        f = third_octave_centres(f_min, 20000.0)
        f = f[f <= top]
    else:
        f = third_octave_centres(f_min, f_max)
        if f[-1] > top:
            raise InputError(
                f"f_max {f_max:g} Hz needs a sample rate above {2 * f[-1] * _filterbank.G ** (1 / 6) / 0.95:.0f} Hz,"
                f" got fs_hz {fs_hz:g}", field="fs_hz")
    if f.size == 0:
        raise InputError(f"fs_hz {fs_hz:g} is too low for any band from {f_min:g} Hz", field="fs_hz")
    return f


def _block_grid(n: int, fs: float, block_s: float) -> tuple[float, int]:
    block_len = block_s * fs
    if block_len < 1.0:
        raise InputError(f"block_s must span at least one sample (1/fs = {1 / fs:g} s), got {block_s}",
                         field="block_s")
    return block_len, int(math.floor(n / block_len + 1e-9))


def _levels_from_ms(ms: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 10.0 * np.log10(ms / P_REF**2)


def band_levels(
    pressure_pa: Any,
    fs_hz: float,
    block_s: float = 0.125,
    *,
    f_min: float = 25.0,
    f_max: float | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One-third-octave band levels per averaging block (IEC 61260-1 class 1, base 10).

    Each band is an 8th-order Butterworth band-pass (4 biquads) between the exact
    band edges, run at a decimated rate for low bands (half-band anti-alias
    stages); the block mean square of its output, referred to 20 uPa, is the
    band level.  Blocks are consecutive, ``block_s`` long, starting at the
    first sample; a trailing partial block is dropped.  Block edges are shifted
    by each band's group delay, so band levels of one block describe the same
    stretch of sound.  The filters start at rest and the recording ends
    abruptly: the first and last blocks of the low bands hold the filters'
    settling (a steady 25 Hz tone reads about 1 dB low there).  The response of
    every band meets the class 1 acceptance limits of IEC 61260-1:2014
    (checked at 44.1, 48 and 96 kHz).

    Parameters
    ----------
    pressure_pa : array_like, shape (n,)
        Calibrated sound pressure, Pa, sampled at ``fs_hz``.
    fs_hz : float
        Sample rate, Hz.
    block_s : float
        Averaging block length, s (need not be a whole number of samples).
    f_min : float
        Nominal frequency of the lowest band, Hz.
    f_max : float, optional
        Nominal frequency of the highest band, Hz.  Default: 20 kHz, or the
        highest band whose upper edge stays below 95 % of the Nyquist frequency
        (16 kHz at 44.1 kHz).  An explicit ``f_max`` the rate cannot serve is an error.
    progress : callable, optional
        Called as ``progress(fraction_done)`` while filtering; may raise to cancel.

    Returns
    -------
    t_s : ndarray, shape (n_blocks,)
        Block centre times, s after the first sample.
    f_hz : ndarray, shape (nb,)
        Exact mid-band frequencies, Hz.
    L_dB : ndarray, shape (n_blocks, nb)
        Unweighted band levels, dB re 20 uPa (-inf for digital silence).

    Notes
    -----
    Adjacent Butterworth bands overlap: for broadband sound the energy sum of
    all bands exceeds the true overall level by about 0.11 dB (effective
    bandwidth of the 4th-order prototype); for a tone it is exact.
    """
    fs = _scalar(fs_hz, "fs_hz")
    if fs <= 0:
        raise InputError(f"fs_hz must be > 0, got {fs}", field="fs_hz")
    blk = _scalar(block_s, "block_s")
    if blk <= 0:
        raise InputError(f"block_s must be > 0, got {blk}", field="block_s")
    x = _array(pressure_pa, "pressure_pa")
    if x.ndim != 1:
        raise InputError(f"pressure_pa must be 1-D (mono), got shape {x.shape}", field="pressure_pa")
    if not np.all(np.isfinite(x)):
        raise InputError(f"pressure_pa must be finite, first bad sample at index {int(np.argmin(np.isfinite(x)))}",
                         field="pressure_pa")
    f = _bands_for(fs, _scalar(f_min, "f_min"), None if f_max is None else _scalar(f_max, "f_max"))
    block_len, n_blocks = _block_grid(x.size, fs, blk)
    bank = _filterbank.design(fs, f)
    ms = _filterbank.run(bank, x, block_len, n_blocks, progress=progress)
    t = (np.arange(n_blocks) + 0.5) * blk
    return t, f.copy(), _levels_from_ms(ms)


# --------------------------------------------------------------------------- audio


def calibrate(volts: Any, sensitivity_v_per_pa: float) -> np.ndarray:
    """Sound pressure (Pa) from a microphone signal in volts: ``p = v / sensitivity``.

    Examples
    --------
    >>> calibrate([0.05, -0.1], 0.05).tolist()
    [1.0, -2.0]
    """
    s = _scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    if s <= 0:
        raise InputError(f"sensitivity_v_per_pa must be > 0, got {s}", field="sensitivity_v_per_pa")
    return _array(volts, "volts") / s


def _wav_open(path: str | os.PathLike[str], mmap: bool) -> tuple[float, np.ndarray]:
    from scipy.io import wavfile

    name = os.fspath(path)
    if not os.path.isfile(name):
        raise InputError(f"{name}: WAV file not found", field="path")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", wavfile.WavFileWarning)  # unknown chunks (LIST, bext, ...)
            try:
                fs, data = wavfile.read(name, mmap=mmap)
            except ValueError:
                if not mmap:
                    raise
                fs, data = wavfile.read(name, mmap=False)  # 24-bit PCM cannot be memory-mapped
    except (ValueError, OSError) as exc:
        raise InputError(f"{name}: not a readable WAV file ({exc})", field="path") from None
    if data.ndim != 1:
        raise InputError(f"{name}: WAV must be mono, got {data.shape[1]} channels", field="channels")
    return float(fs), data


def _wav_scale(data: np.ndarray, name: str) -> float:
    """Factor from stored WAV values to volts (full-scale integer PCM = 1 V)."""
    kind = data.dtype.kind
    if kind == "f":
        return 1.0
    if kind == "i":
        return 1.0 / float(2 ** (8 * data.dtype.itemsize - 1))
    if kind == "u":  # 8-bit PCM is unsigned, offset 128
        raise InputError(f"{name}: 8-bit unsigned PCM is not supported, use 16/24/32-bit or float",
                         field="sample_format")
    raise InputError(f"{name}: unsupported WAV sample type {data.dtype}", field="sample_format")


def _check_rate(fs: float, expected: float | None, name: str) -> None:
    if expected is not None and abs(fs - float(expected)) > 1e-6 * float(expected):
        raise InputError(f"{name}: sample rate {fs:g} Hz, expected {float(expected):g} Hz", field="sample_rate")


def read_wav(
    path: str | os.PathLike[str],
    sensitivity_v_per_pa: float | None = None,
    *,
    expected_fs_hz: float | None = None,
) -> tuple[np.ndarray, float]:
    """Read a mono WAV file as volts, or as pascals when the sensitivity is given.

    Stored values are volts: float WAV as is, integer PCM scaled so full scale
    is 1 V (int16 32768 -> 1 V; 24-bit PCM is read left-justified in int32).

    Parameters
    ----------
    path : path-like
        WAV file.
    sensitivity_v_per_pa : float, optional
        Microphone sensitivity, V/Pa; when given the result is in Pa.
    expected_fs_hz : float, optional
        Required sample rate, Hz; another rate is an error naming ``sample_rate``.

    Returns
    -------
    signal : ndarray of float64, shape (n,)
        Volts, or pascals with a sensitivity.
    fs_hz : float
        Sample rate, Hz.
    """
    name = os.fspath(path)
    fs, data = _wav_open(name, mmap=False)
    _check_rate(fs, expected_fs_hz, name)
    v = data.astype(np.float64) * _wav_scale(data, name)
    if sensitivity_v_per_pa is not None:
        v = calibrate(v, sensitivity_v_per_pa)
    return v, fs


def write_wav(
    path: str | os.PathLike[str],
    pressure_pa: Any,
    fs_hz: float,
    sensitivity_v_per_pa: float,
    *,
    dtype: str = "float32",
) -> None:
    """Write sound pressure as a mono WAV of volts (the inverse of :func:`read_wav`).

    Parameters
    ----------
    path : path-like
        Output file.
    pressure_pa : array_like, shape (n,)
        Sound pressure, Pa.
    fs_hz : float
        Sample rate, Hz (a whole number).
    sensitivity_v_per_pa : float
        Microphone sensitivity, V/Pa.
    dtype : {"float32", "float64", "int16", "int32"}
        Sample format; integer PCM has full scale 1 V and clipping is an error.
    """
    from scipy.io import wavfile

    p = _finite(pressure_pa, "pressure_pa")
    if p.ndim != 1:
        raise InputError(f"pressure_pa must be 1-D (mono), got shape {p.shape}", field="pressure_pa")
    fs = _scalar(fs_hz, "fs_hz")
    if fs <= 0 or fs != round(fs):
        raise InputError(f"fs_hz must be a positive whole number for WAV, got {fs}", field="fs_hz")
    s = _scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    if s <= 0:
        raise InputError(f"sensitivity_v_per_pa must be > 0, got {s}", field="sensitivity_v_per_pa")
    v = p * s
    if dtype in ("float32", "float64"):
        data = v.astype(dtype)
    elif dtype in ("int16", "int32"):
        full = float(2 ** (8 * np.dtype(dtype).itemsize - 1))
        q = np.round(v * full)
        if np.any(q > full - 1) or np.any(q < -full):
            peak = float(np.max(np.abs(v)))
            raise InputError(f"signal peak {peak:.3g} V clips {dtype} PCM (full scale 1 V)", field="pressure_pa")
        data = q.astype(dtype)
    else:
        raise InputError(f"dtype must be float32, float64, int16 or int32, got {dtype!r}", field="dtype")
    wavfile.write(os.fspath(path), int(fs), data)


def wav_band_levels(
    path: str | os.PathLike[str],
    sensitivity_v_per_pa: float,
    block_s: float = 0.125,
    *,
    expected_fs_hz: float | None = None,
    f_min: float = 25.0,
    f_max: float | None = None,
    progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`band_levels` of a WAV file, read chunk by chunk (memory-mapped when possible).

    Parameters
    ----------
    path : path-like
        Mono WAV file of volts (see :func:`read_wav`).
    sensitivity_v_per_pa : float
        Microphone sensitivity, V/Pa.
    block_s, f_min, f_max, progress
        As in :func:`band_levels`.
    expected_fs_hz : float, optional
        Required sample rate, Hz.

    Returns
    -------
    t_s, f_hz, L_dB
        As in :func:`band_levels`; ``t_s`` counts from the first sample.
    """
    name = os.fspath(path)
    s = _scalar(sensitivity_v_per_pa, "sensitivity_v_per_pa")
    if s <= 0:
        raise InputError(f"sensitivity_v_per_pa must be > 0, got {s}", field="sensitivity_v_per_pa")
    blk = _scalar(block_s, "block_s")
    if blk <= 0:
        raise InputError(f"block_s must be > 0, got {blk}", field="block_s")
    fs, data = _wav_open(name, mmap=True)
    _check_rate(fs, expected_fs_hz, name)
    scale = _wav_scale(data, name) / s

    def check(chunk: np.ndarray, start: int) -> None:
        if not np.all(np.isfinite(chunk)):
            bad = start + int(np.argmin(np.isfinite(chunk)))
            raise InputError(f"{name}: non-finite sample at index {bad}", field="samples")

    f = _bands_for(fs, _scalar(f_min, "f_min"), None if f_max is None else _scalar(f_max, "f_max"))
    block_len, n_blocks = _block_grid(len(data), fs, blk)
    bank = _filterbank.design(fs, f)
    ms = _filterbank.run(bank, data, block_len, n_blocks, scale=scale, check=check, progress=progress)
    t = (np.arange(n_blocks) + 0.5) * blk
    return t, f.copy(), _levels_from_ms(ms)
