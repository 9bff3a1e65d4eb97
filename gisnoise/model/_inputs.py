"""What the effects read besides one row's geometry: the speed of sound, microphone heights, time series.

The extension terms of :mod:`gisnoise.model.effects` take the model inputs as a
mapping of per-row arrays plus the campaign facts under ``meta``; these helpers
derive from them what several effects share.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from gisnoise import acoustics, measure
from gisnoise.errors import InputError

__all__ = ["speed_of_sound", "mic_height_agl", "series_ids"]


def speed_of_sound(meta: Mapping[str, Any] | None) -> float | None:
    """Speed of sound (m/s) from the campaign facts, or None when they do not tell.

    ``speed_of_sound_m_s`` when given, else :func:`gisnoise.acoustics.speed_of_sound`
    of ``weather.temperature_c``.

    >>> round(speed_of_sound({"weather": {"temperature_c": 20.0}}), 2)
    343.21
    """
    if not meta:
        return None
    c = meta.get("speed_of_sound_m_s")
    if c is not None and np.isfinite(c) and c > 0:
        return float(c)
    w = meta.get("weather") or {}
    t = w.get("temperature_c", meta.get("temperature_c"))
    if t is None or not np.isfinite(t):
        return None
    return float(acoustics.speed_of_sound(float(t)))


def sound_speed_of(x: Mapping[str, Any]) -> float:
    """Speed of sound (m/s) of the inputs ``x`` (from ``x["meta"]``); an error when unknown."""
    c = speed_of_sound(x.get("meta"))
    if c is None:
        raise InputError("speed of sound unknown: give meta speed_of_sound_m_s or weather temperature_c",
                         field="meta")
    return c


def unit_to_mic(x: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors UAV -> microphone (n, 3) and path lengths (n,), from the ENU positions."""
    r = np.asarray(x["mic_enu"], dtype=float) - np.asarray(x["uav_enu"], dtype=float)
    d = np.linalg.norm(r, axis=-1)
    return r / np.maximum(d, 1e-9)[..., None], d


def mic_height_agl(x: Mapping[str, Any]) -> np.ndarray | None:
    """Microphone height above ground per row (m), or None when the data do not tell.

    From the input ``mic_agl`` when given, else from ``meta["microphones"]`` (a
    list of objects with ``id``, or a mapping id -> object) with ``height_agl_m``
    (or ``mount == "ground_plate"``: 0 m), matched to the rows by the input
    ``mic`` (ids) or else by microphone position (``enu``).
    """
    v = x.get("mic_agl")
    if v is not None:
        return np.asarray(v, dtype=float)
    meta = x.get("meta") or {}
    mics = meta.get("microphones")
    if not mics or "mic_enu" not in x:
        return None
    mic_enu = np.asarray(x["mic_enu"], dtype=float)
    h = np.full(len(mic_enu), np.nan)
    ids = x.get("mic")
    if isinstance(mics, Mapping):
        mics = [{"id": k, **v} for k, v in mics.items()]
    for m in mics:
        hm = m.get("height_agl_m", m.get("height_m"))
        if hm is None and m.get("mount") == "ground_plate":
            hm = 0.0
        if hm is None:
            continue
        if ids is not None and "id" in m:
            h[np.asarray(ids) == m["id"]] = float(hm)
        elif "enu" in m:
            h[np.all(np.isclose(mic_enu, np.asarray(m["enu"], dtype=float), atol=0.01), axis=-1)] = float(hm)
    return None if np.all(np.isnan(h)) else h


def series_ids(x: Mapping[str, Any]) -> np.ndarray:
    """Id of the time series (one microphone, one flight) of each row of the inputs ``x``.

    From the inputs ``mic`` and ``flight`` when given (:func:`gisnoise.measure.series_ids`);
    else consecutive rows form a series while the microphone position stays and
    the emission time increases by at most 2 s.
    """
    t = np.asarray(x["t_e"], dtype=float)
    if x.get("mic") is not None and x.get("flight") is not None:
        return measure.series_ids(x["mic"], x["flight"])
    m = np.asarray(x["mic_enu"], dtype=float)
    new = np.ones(len(t), dtype=bool)
    new[1:] = np.any(m[1:] != m[:-1], axis=-1) | (np.diff(t) <= 0.0) | (np.diff(t) > 2.0)
    return np.cumsum(new) - 1
