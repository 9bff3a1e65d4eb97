"""Sound in the atmosphere: speed of sound, ISO 9613-1 absorption and its correction in the bands
that stand clear of the background.

Levels are dB re 20 uPa.  Functions accept floats or arrays and broadcast.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from gisnoise.acoustics._checks import _air_pressure, _array, _bands_of, _finite, _positive, _scalar, _temperature
from gisnoise.acoustics.weighting import a_weighting
from gisnoise.errors import InputError

__all__ = [
    "speed_of_sound",
    "atmospheric_absorption",
    "absorption_correction",
    "absorption_corrected_level",
    "background_levels",
]


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
    t = _temperature(temperature_c)
    return 331.3 * np.sqrt(1.0 + t / 273.15)


def atmospheric_absorption(f_hz: Any, temperature_c: Any, humidity_pct: Any, pressure_kpa: Any = 101.325) -> np.ndarray:
    """Pure-tone atmospheric absorption coefficient of ISO 9613-1:1993, dB per metre.

    Equations (3)-(5) and (B.1)-(B.3) of ISO 9613-1: relaxation frequencies of
    oxygen and nitrogen from the molar concentration of water vapour.  The
    standard states +-10 % accuracy for -20 to 50 deg C, 10 to 100 % relative
    humidity, 50 Hz to 10 kHz and pressures below 200 kPa; outside, the formula
    is evaluated as is.  Temperatures and pressures no air near the ground has (a
    temperature in kelvin, a pressure in pascal or hectopascal) are refused.  Bands
    use their exact mid-band frequency.

    Parameters
    ----------
    f_hz : float or array_like
        Frequency, Hz (>= 0).
    temperature_c : float or array_like
        Air temperature, deg C (-90 to 60).
    humidity_pct : float or array_like
        Relative humidity, % (0-100).
    pressure_kpa : float or array_like
        Atmospheric pressure, kPa (25 to 120).

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
    t = _temperature(temperature_c)
    hr = _finite(humidity_pct, "humidity_pct")
    if np.any((hr < 0) | (hr > 100)):
        raise InputError(f"humidity_pct must be within [0, 100], got {hr[(hr < 0) | (hr > 100)].flat[0]}",
                         field="humidity_pct")
    pa = _air_pressure(pressure_kpa)
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
    L, f = _bands_of(L_bands, f_hz)
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
