"""Levels against listed positions: the spherical-spreading rule of ``campaign check``.

A microphone's level ``L`` at distance ``d`` from the drone gives the source's level at 1 m,
``L + 20 lg d`` (spherical spreading).  Computed with the distance from the *listed*
position, it is the same at every microphone to within the drone's directivity and the
ground; a microphone whose value lies far from the others' was not where campaign.json
says.  :func:`spreading_outliers` applies the rule per flight, :func:`spreading_notes`
words its findings (``gisnoise campaign check``, the diagnosis' contradictions).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from gisnoise.errors import InputError

__all__ = ["OUTLIER_DB", "WINDOW_S", "spreading_notes", "spreading_outliers"]

OUTLIER_DB = 20.0
"""How far (dB) a microphone's source level from its listed position may lie from the others' before it is named."""

WINDOW_S = 20.0
"""The loudest reception time per microphone and flight (s) over which :func:`spreading_outliers` takes the median."""


def spreading_outliers(s: Any, limit_db: float = OUTLIER_DB,
                       window_s: float = WINDOW_S) -> list[tuple[str, str, float, float, float]]:
    """Microphones whose listed position their levels contradict: ``(mic, flight, level, distance, offset)``.

    Per flight and microphone, the valid samples of its loudest ``window_s`` seconds (its
    closest approaches; every valid sample when it has fewer) each give the source's level at
    1 m from the listed position, ``L + 20 lg d`` (spherical spreading, ``d`` at least 1 m).
    The microphone's source level is their median; ``level`` and ``distance`` are those of
    the median sample (the lower middle one of an even count).  Against the median over the
    microphones (three or more: one misplaced microphone does not move it), an offset beyond
    ``limit_db`` (20 dB: ten times the distance, far more than a drone's directivity or the
    ground change) means the listed position cannot be where the levels were measured.

    Why a median over the loudest seconds and not the loudest sample: a sound the reader did
    not mask (a shout, a passing car, a door, heard by one microphone only, so no joint rise)
    can be a microphone's loudest sample and puts the source tens of dB off.  The loudest
    20 s are the tops of the drone's closest passes; over them its direction to the
    microphone changes, and with it the source level by a few dB only (directivity; the
    honest microphones of the simulated diagnosis scenarios lie within 5 dB of the median),
    so the median of the window is the drone's source level within a few dB.  A sound
    shorter than half the window is a minority of its samples and cannot carry the median
    beyond the drone's own values (an 85 dB(A) sound of 4 s moves it by at most 3.3 dB, one
    of 10 s by 6.4 dB; one of 12 s or more can trip the rule).  A listed position kilometres
    or ten times the distance off shifts every sample of the window alike and is still named
    (0.05 deg, 5.6 km, north: +32 to +43 dB).

    Parameters
    ----------
    s : Samples
        The samples (rows with ``valid`` and a finite level count).
    limit_db : float
        Offset beyond which a microphone is named, dB (``-inf``: every judged microphone).
    window_s : float
        The loudest reception time per microphone and flight that is judged, s; the
        block length is the median step of the microphone's reception times.

    Returns
    -------
    list of tuple
        ``(mic, flight, level in dB(A), listed distance in m, offset in dB)`` per finding.

    Examples
    --------
    >>> from gisnoise.measure import Samples
    >>> n = 80
    >>> t = np.tile(np.arange(n) * 0.125, 3)
    >>> d = np.repeat([40.0, 80.0, 4000.0], n)          # listed distances, m
    >>> true = np.repeat([40.0, 80.0, 40.0], n)         # where the levels were measured
    >>> lv = 70.0 - 20 * np.log10(true / 40.0)
    >>> z = np.zeros(3 * n)
    >>> s = Samples(mic=np.repeat(["a", "b", "c"], n), flight=np.full(3 * n, "f1"), t_r=t, t_e=t, level=lv,
    ...             d=d, phi=z, theta=z, power_w=z + 3000.0, phase=np.full(3 * n, "hover"), roll=z, pitch=z,
    ...             yaw=z, uav_enu=np.zeros((3 * n, 3)), mic_enu=np.zeros((3 * n, 3)),
    ...             vel_enu=np.zeros((3 * n, 3)), valid=np.ones(3 * n, bool), mask_reason=np.full(3 * n, ""))
    >>> [(m, f, round(off, 1)) for m, f, _, _, off in spreading_outliers(s)]
    [('c', 'f1', 40.0)]
    """
    if not (isinstance(window_s, (int, float)) and math.isfinite(window_s) and window_s > 0):
        raise InputError(f"window_s must be a positive number of seconds, got {window_s!r}", field="window_s")
    out = []
    for flight in np.unique(s.flight):
        src: dict[str, tuple[float, float, float]] = {}
        for mic in np.unique(s.mic):
            series = (s.flight == flight) & (s.mic == mic)
            rows = np.flatnonzero(series & s.valid & np.isfinite(s.level))
            if rows.size >= 3:
                steps = np.diff(np.unique(s.t_r[series]))
                n = rows.size if steps.size == 0 else max(1, int(round(window_s / float(np.median(steps)))))
                loud = rows[np.argsort(-s.level[rows], kind="stable")[:n]]
                d = np.maximum(s.d[loud].astype(float), 1.0)
                lw = s.level[loud] + 20.0 * np.log10(d)
                k = int(np.argsort(lw, kind="stable")[(lw.size - 1) // 2])
                src[str(mic)] = (float(lw[k]), float(s.level[loud[k]]), float(d[k]))
        if len(src) < 3:
            continue
        mid = float(np.median([v[0] for v in src.values()]))
        for mic, (lw_mic, level, dist) in src.items():
            off = lw_mic - mid
            if abs(off) > limit_db:
                out.append((mic, str(flight), level, dist, off))
    return out


def spreading_notes(s: Any) -> list[str]:
    """One sentence per :func:`spreading_outliers` finding (``campaign check``, the diagnosis' contradictions)."""
    return [f"microphone '{mic}': the median of its loudest {WINDOW_S:.0f} s in flight '{flight}', {level:.1f} dB(A) "
            f"at {dist:.0f} m from its listed position, puts the source {off:+.0f} dB off what the microphones' "
            "median hears from theirs (spherical spreading); check its position"
            for mic, flight, level, dist, off in spreading_outliers(s)]
