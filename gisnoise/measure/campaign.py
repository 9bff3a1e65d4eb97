"""The measurement campaign: folder -> levels at emission time (:class:`~gisnoise.measure.samples.Samples`).

A campaign folder (see the specification, section 3)::

    campaign.json
    flights/<flight>.csv | .ulg | .bin
    mics/<mic>/<flight>.csv     # levels: t, LA, optional L_<nominal Hz>
    mics/<mic>/<flight>.wav     # or raw audio (mono, first sample at start_utc)

:func:`read_campaign` reads and checks everything and raises
:class:`~gisnoise.errors.CampaignError` (naming the file and field) at the first
problem; :func:`check_campaign` collects every problem instead.  Where both a level
CSV and a WAV exist for a microphone and flight, the CSV is read (``gisnoise
campaign levels`` writes it from the WAV).

Optional keys of ``campaign.json`` beyond the specification: ``sample_rate_hz`` (all
WAV files must have it; otherwise they must share one rate), ``block_s`` (averaging
block of WAV input, default 0.125 s), per microphone ``full_scale_v`` (voltage of
digital full scale of integer or float WAV samples, default 1 V) and
``background_db`` (the A-weighted background level, dB, replacing the estimate),
per flight ``geoid_undulation_m`` (for logs that give heights above mean sea level
only), and ``exclusions``: ``[{"flight": .., "t0": .., "t1": .., "mic": ..}]``
(reception times, s since the flight's start; ``mic`` optional).

:meth:`Campaign.samples` turns the levels into one row per microphone and block:

1. emission time from ``t_r = t_e + |x_uav(t_e) - x_mic| / c`` (:func:`emission_time`,
   solved to 1e-9 s on the piecewise-linear ENU track);
2. the flight state at ``t_e`` (:meth:`Trajectory.interpolate`, angles on the circle),
   ground velocity from the differentiated positions, distance and emission angles
   (:func:`gisnoise.geo.frames.emission_angles`);
3. optionally (``absorption=True``) the ISO 9613-1 absorption over the path ``d`` added
   back to the bands that stand 10 dB or more above their background; the level becomes
   ``10 log10(10^(LA/10) + sum_b 10^(LA_b/10) (10^(alpha_b d / 10) - 1))`` with ``LA_b``
   the A-weighted band level.  ``bands`` stay as measured;
4. masks, one reason per row, in this priority: ``outside_flight`` (emission time
   outside the flight log), ``excluded`` (user intervals), ``event`` (see
   :func:`detect_events`), ``low_snr`` (level below background + ``snr_db``).

Background and events (per microphone and flight).  The background is, in this
order: ``background_db`` of campaign.json; the median level of the blocks whose
emission lies outside the flight log (8 or more; the UAV is not flying then, and the
value must not exceed the quiet end of the in-flight levels); the plateau ``B`` of
:func:`fit_level_trend` when the levels show it; else NaN, and then no row is masked
``low_snr``.  :func:`fit_level_trend` (spreading with distance, loudness with power,
an offset per phase, power-summed with the background) also gives each row's
expected level; the level minus it, on every microphone at once, is what
:func:`detect_events` examines.  Band backgrounds for the absorption correction are
the median band levels of the blocks outside the flight log when there are 8 or
more, else the 10th percentile of each band over the farthest quarter of the
distances (which overstates it while the UAV is still audible there, so fewer bands
are corrected: the correction errs towards too little).
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
import re
import struct
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.acoustics import physics as acoustics
from gisnoise.errors import CampaignError, GisnoiseError
from gisnoise.flight import FLIGHT_SUFFIXES, Trajectory, as_unix_time, read_flight
from gisnoise.geo import LocalFrame, emission_angles
from gisnoise.measure.samples import Samples

__all__ = [
    "SCHEMA",
    "Campaign",
    "Microphone",
    "Flight",
    "Exclusion",
    "LevelSeries",
    "Problem",
    "read_campaign",
    "check_campaign",
    "inspect_campaign",
    "emission_time",
    "detect_events",
    "fit_level_trend",
    "read_level_csv",
    "write_level_csv",
    "wav_levels",
    "write_levels",
    "band_column",
    "DEFAULT_SNR_DB",
    "DEFAULT_EVENT_DB",
    "DEFAULT_BLOCK_S",
    "SIGNAL_BAND_MARGIN_DB",
]

log = logging.getLogger(__name__)

SCHEMA = "gisnoise/campaign/1"
SCHEMA_PREFIX = "gisnoise/campaign/"
SUPPORTED_VERSIONS = (1,)
DEFAULT_SNR_DB = 3.0
"""Rows whose level is below the background plus this, dB, are masked ``low_snr``."""
DEFAULT_EVENT_DB = 6.0
"""Joint rise on all microphones above the geometric trend that flags an ``event``, dB."""
DEFAULT_BLOCK_S = 0.125
SIGNAL_BAND_MARGIN_DB = 10.0
"""A band is absorption-corrected only when this far above its background, dB."""
BACKGROUND_PERCENTILE = 10.0
EVENT_SMOOTHING_S = 0.5
_BAND_RE = re.compile(r"^L_")
ProgressFn = Callable[[float, float], None]


# ======================================================================= value objects
@dataclass(frozen=True)
class Problem:
    """One problem found in a campaign: the file, the field and a one-line message."""

    file: str
    field: str
    message: str

    def __str__(self) -> str:
        return self.message


@dataclass(frozen=True)
class Microphone:
    """A microphone: id, WGS84 position (deg, deg, m ellipsoidal), mount, calibration."""

    id: str
    lat: float
    lon: float
    h: float
    mount: str = "free_field"
    sensitivity_v_per_pa: float | None = None
    full_scale_v: float = 1.0
    background_db: float | None = None
    height_agl_m: float | None = None
    """Height of the capsule above the ground, m (for ground reflection); None when not stated."""


@dataclass(frozen=True)
class Flight:
    """A flight: id, start instant (unix s, UTC), its log file and geoid undulation (m)."""

    id: str
    start_utc: float
    log: str
    geoid_undulation_m: float | None = None


@dataclass(frozen=True)
class Exclusion:
    """A user-excluded reception-time interval [t0, t1] s of one flight (one or all mics)."""

    flight: str
    t0: float
    t1: float
    mic: str | None = None
    reason: str = ""


@dataclass(frozen=True, eq=False)
class LevelSeries:
    """Levels of one microphone during one flight.

    Attributes
    ----------
    mic, flight : str
    source : str
        File the levels came from.
    t : ndarray
        Reception time at the block centre, s since the flight's start.
    la : ndarray
        A-weighted level, free field, dB(A).
    band_f : ndarray or None
        Exact mid-band frequencies, Hz.
    bands : ndarray or None
        Unweighted band levels, free field, dB, shape (n, nb).
    """

    mic: str
    flight: str
    source: str
    t: np.ndarray
    la: np.ndarray
    band_f: np.ndarray | None = None
    bands: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Campaign:
    """A read and checked campaign.  Build with :func:`read_campaign`.

    Attributes
    ----------
    folder : Path
    origin : LocalFrame
        ENU frame of the campaign (``origin`` of campaign.json).
    weather : dict
        ``temperature_c``, ``humidity_pct``, ``pressure_kpa`` and optional wind.
    vehicle : dict
        ``name`` and ``reference_power_w`` (W).
    speed_of_sound_m_s : float
    microphones : tuple of Microphone
    flights : tuple of Flight
    trajectories : dict flight id -> Trajectory
    levels : tuple of LevelSeries
    exclusions : tuple of Exclusion
    absorption : bool
    snr_db, event_db : float
    """

    folder: Path
    origin: LocalFrame
    weather: Mapping[str, Any]
    vehicle: Mapping[str, Any]
    speed_of_sound_m_s: float
    microphones: tuple[Microphone, ...]
    flights: tuple[Flight, ...]
    trajectories: Mapping[str, Trajectory]
    levels: tuple[LevelSeries, ...]
    exclusions: tuple[Exclusion, ...] = ()
    absorption: bool = False
    snr_db: float = DEFAULT_SNR_DB
    event_db: float = DEFAULT_EVENT_DB
    _samples: list[Samples] = field(default_factory=list, repr=False, compare=False)

    @property
    def reference_power_w(self) -> float:
        return float(self.vehicle["reference_power_w"])

    def microphone(self, mic_id: str) -> Microphone:
        for m in self.microphones:
            if m.id == mic_id:
                return m
        raise KeyError(mic_id)

    def mic_enu(self, mic_id: str) -> np.ndarray:
        """ENU position of a microphone, m."""
        m = self.microphone(mic_id)
        return np.array([float(v) for v in self.origin.to_enu(m.lat, m.lon, m.h)])

    def samples(self) -> Samples:
        """All microphones and flights stacked at emission time (computed once)."""
        if not self._samples:
            self._samples.append(_build_samples(self))
        return self._samples[0]


# ======================================================================= pure kernels
def emission_time(t_r: Any, t_nodes: Any, enu_nodes: Any, mic_enu: Any, c_m_s: float, *,
                  tol_s: float = 1e-9, max_iter: int = 60) -> np.ndarray:
    """Solve ``t_r = t_e + |x(t_e) - x_mic| / c`` for the emission times ``t_e``.

    ``x(t)`` is the piecewise-linear track through ``enu_nodes`` at ``t_nodes`` (held
    constant outside them).  Safeguarded Newton iteration, vectorized over ``t_r``:
    each Newton step on the linear segment is kept when it reduces the residual, else
    the fixed-point step ``t_e = t_r - |x(t_e) - x_mic| / c`` (a contraction with factor
    ``|v| / c``) is taken; iterates until every residual is below ``tol_s``.

    Parameters
    ----------
    t_r : float or array_like
        Reception times, s.
    t_nodes : array_like, shape (m,)
        Track times, s, strictly increasing.
    enu_nodes : array_like, shape (m, 3)
        Track positions, m.
    mic_enu : array_like, shape (3,)
        Microphone position, m.
    c_m_s : float
        Speed of sound, m/s.

    Returns
    -------
    ndarray
        Emission times, s, shaped like ``t_r``.

    Examples
    --------
    >>> t_e = emission_time(10.0, [0.0, 100.0], [[0, 0, 340.0], [0, 0, 340.0]], [0, 0, 0], 340.0)
    >>> round(float(t_e), 12)
    9.0
    """
    t_r = np.asarray(t_r, dtype=float)
    tn = np.asarray(t_nodes, dtype=float)
    xn = np.asarray(enu_nodes, dtype=float).reshape(-1, 3)
    m = np.asarray(mic_enu, dtype=float).reshape(3)
    if not (np.isfinite(c_m_s) and c_m_s > 0):
        raise CampaignError(f"speed of sound must be positive, got {c_m_s!r}", field="speed_of_sound_m_s")
    if len(tn) != len(xn) or len(tn) < 2:
        raise CampaignError("emission_time: need at least 2 track nodes with positions", field="t_nodes")
    seg_v = np.diff(xn, axis=0) / np.diff(tn)[:, None]
    vmax = float(np.max(np.linalg.norm(seg_v, axis=1)))
    if vmax >= c_m_s:
        raise CampaignError(f"track speed {vmax:.1f} m/s is not below the speed of sound", field="t_nodes")

    def state(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack([np.interp(t, tn, xn[:, i]) for i in range(3)], axis=-1)
        k = np.searchsorted(tn, t, side="right") - 1
        inside = (k >= 0) & (k < len(tn) - 1)
        v = np.where(inside[..., None], seg_v[np.clip(k, 0, len(tn) - 2)], 0.0)
        return x, v

    flat = t_r.reshape(-1)
    x, _ = state(flat)
    t = flat - np.linalg.norm(x - m, axis=-1) / c_m_s
    for _ in range(max_iter):
        x, v = state(t)
        r = x - m
        dist = np.linalg.norm(r, axis=-1)
        f = t + dist / c_m_s - flat
        if np.all(np.abs(f) < tol_s):
            return t.reshape(t_r.shape)
        fp = 1.0 + np.einsum("ij,ij->i", r, v) / np.maximum(dist, 1e-12) / c_m_s
        t_newton = t - f / fp
        xn_, _ = state(t_newton)
        f_newton = t_newton + np.linalg.norm(xn_ - m, axis=-1) / c_m_s - flat
        t_fixed = flat - dist / c_m_s
        t = np.where(np.abs(f_newton) < np.abs(f), t_newton, t_fixed)
    raise CampaignError(f"emission time did not converge to {tol_s:g} s in {max_iter} iterations",
                        field="t_e")  # pragma: no cover - contraction guarantees convergence


def detect_events(t: Sequence[np.ndarray], excess_db: Sequence[np.ndarray], *, event_db: float = DEFAULT_EVENT_DB,
                  smoothing_s: float = EVENT_SMOOTHING_S) -> list[np.ndarray]:
    """Flag blocks where every microphone's level rises above its expectation at once.

    Parameters
    ----------
    t : sequence of arrays
        Reception times of each microphone's blocks, s (increasing).
    excess_db : sequence of arrays
        Level minus the expectation (geometric trend and background) per block, dB;
        NaN where unknown.
    event_db : float
        Joint rise that flags an event, dB; the flag extends over the neighbouring
        blocks while the joint rise stays above half of it.
    smoothing_s : float
        Width of the moving average applied to each excess first, s.

    Returns
    -------
    list of bool arrays
        Per microphone, True where the block lies in a joint rise.  With fewer than
        two microphones nothing is flagged (a rise on one microphone is geometry's
        or the UAV's as likely as an event's).

    Examples
    --------
    >>> t = [np.arange(10.0), np.arange(10.0) + 0.05]
    >>> e = [np.r_[np.zeros(5), 9, 9, 9, 0, 0], np.r_[np.zeros(5), 8, 8, 8, 0, 0]]
    >>> detect_events(t, e, smoothing_s=0.0)[0].astype(int).tolist()
    [0, 0, 0, 0, 0, 1, 1, 1, 0, 0]
    """
    n = len(t)
    out = [np.zeros(len(tt), dtype=bool) for tt in t]
    if n < 2:
        return out
    smooth = []
    for tt, e in zip(t, excess_db, strict=True):
        tt = np.asarray(tt, dtype=float)
        e = np.asarray(e, dtype=float)
        smooth.append((tt, _moving_mean(tt, e, smoothing_s)))
    for i, (ti, _) in enumerate(smooth):
        joint = np.full(len(ti), np.inf)
        for tj, ej in smooth:
            ok = np.isfinite(ej)
            if ok.sum() < 2:
                joint[:] = -np.inf
                break
            val = np.interp(ti, tj[ok], ej[ok], left=np.nan, right=np.nan)
            joint = np.fmin(joint, np.where(np.isnan(val), -np.inf, val))
        out[i] = _hysteresis(joint, event_db, 0.5 * event_db)
    return out


def _hysteresis(x: np.ndarray, high: float, low: float) -> np.ndarray:
    """True on the runs of ``x > low`` that contain at least one ``x > high``."""
    above = x > low
    if not above.any():
        return above
    run = np.cumsum(np.diff(np.concatenate([[False], above])).astype(bool) & above)  # run id of each start
    run = np.where(above, run, 0)
    hit = np.unique(run[(x > high) & above])
    return np.isin(run, hit[hit > 0])


def _moving_mean(t: np.ndarray, v: np.ndarray, width: float) -> np.ndarray:
    if width <= 0 or len(t) < 2:
        return v
    ok = np.isfinite(v)
    vv = np.where(ok, v, 0.0)
    c = np.concatenate([[0.0], np.cumsum(vv)])
    cn = np.concatenate([[0], np.cumsum(ok)])
    lo = np.searchsorted(t, t - width / 2, side="left")
    hi = np.searchsorted(t, t + width / 2, side="right")
    cnt = cn[hi] - cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(cnt > 0, (c[hi] - c[lo]) / np.maximum(cnt, 1), np.nan)


# ======================================================================= level files
def band_column(f_hz: float) -> str:
    """Column name ``L_<nominal Hz>`` of the one-third-octave band at ``f_hz`` (:func:`acoustics.band_name`).

    Examples
    --------
    >>> band_column(158.489), band_column(1258.9), band_column(31.62)
    ('L_160', 'L_1250', 'L_31.5')
    """
    return str(acoustics.band_name(float(f_hz)))


def _band_key(f_hz: Any) -> np.ndarray:
    """Nominal frequency, Hz: the key that identifies a band across files."""
    return np.asarray(acoustics.nominal_frequency(f_hz), dtype=float)


def read_level_csv(path: str | os.PathLike[str], *, mic: str = "", flight: str = "") -> LevelSeries:
    """Read a level CSV (``t``, ``LA``, optional ``L_<nominal Hz>``); errors name file and field."""
    src = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise CampaignError(f"{src}: missing microphone file", field="path") from None
    rows = [r for r in csv.reader(io.StringIO(text)) if r and any(x.strip() for x in r)]
    if not rows:
        raise CampaignError(f"{src}: the file is empty", field="t")
    header = [h.strip() for h in rows[0]]
    for need in ("t", "LA"):
        if need not in header:
            raise CampaignError(f"{src}: missing column '{need}'", field=need)
    band_cols = []
    for j, h in enumerate(header):
        if _BAND_RE.match(h):
            if not acoustics.is_band_name(h) or not 10.0 <= float(h[2:]) <= 20000.0:
                raise CampaignError(f"{src}: column '{h}' is not a one-third-octave band of 10 Hz-20 kHz", field=h)
            band_cols.append((j, h, float(acoustics.band_frequency(h))))
    data = np.full((len(rows) - 1, len(header)), np.nan)
    used = [header.index("t"), header.index("LA")] + [j for j, _, _ in band_cols]
    for i, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise CampaignError(f"{src}: line {i} has {len(r)} fields, header has {len(header)}", field="csv")
        for j in used:
            try:
                data[i - 2, j] = float(r[j])
            except ValueError:
                raise CampaignError(f"{src}: column '{header[j]}' line {i}: not a number: {r[j]!r}",
                                    field=header[j]) from None
    for k, j in enumerate(used):
        col = data[:, j]
        # a band may be -inf (digital silence); t, LA and everything else must be finite
        bad = ~np.isfinite(col) if k < 2 else (np.isnan(col) | (col == np.inf))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise CampaignError(f"{src}: column '{header[j]}' line {i + 2}: NaN or infinite value", field=header[j])
    t = data[:, header.index("t")]
    if len(t) == 0:
        raise CampaignError(f"{src}: no rows", field="t")
    dt = np.diff(t)
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0]) + 1
        raise CampaignError(f"{src}: column 't' is not strictly increasing at line {i + 2} "
                            f"({t[i]:g} s after {t[i - 1]:g} s)", field="t")
    band_f = bands = None
    if band_cols:
        band_cols.sort(key=lambda b: b[2])
        band_f = np.array([b[2] for b in band_cols])
        bands = data[:, [b[0] for b in band_cols]]
    return LevelSeries(mic=mic, flight=flight, source=src, t=t, la=data[:, header.index("LA")],
                       band_f=band_f, bands=bands)


def write_level_csv(path: str | os.PathLike[str] | None, t: Any, la: Any, band_f: Any = None,
                    bands: Any = None) -> str:
    """Write a level CSV: ``t`` (s), ``LA`` (dB(A)) and one ``L_<nominal>`` column per band (dB).

    Returns the text; writes it to ``path`` when given.
    """
    t = np.asarray(t, dtype=float)
    la = np.asarray(la, dtype=float)
    cols = ["t", "LA"]
    mat = [t, la]
    if band_f is not None and bands is not None:
        bands = np.asarray(bands, dtype=float).reshape(len(t), -1)
        for j, f in enumerate(np.asarray(band_f, dtype=float)):
            cols.append(band_column(f))
            mat.append(bands[:, j])
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    arr = np.column_stack(mat)
    for row in arr:
        w.writerow([f"{row[0]:.6f}"] + [f"{v:.3f}" for v in row[1:]])
    text = buf.getvalue()
    if path is not None:
        Path(path).write_text(text, encoding="utf-8")
    return text


def _wav_rate(path: Path) -> int:
    """Sample rate of a WAV file from its ``fmt`` chunk (the data is not read)."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
            if len(head) < 12 or head[:4] not in (b"RIFF", b"RF64") or head[8:12] != b"WAVE":
                raise CampaignError(f"{path}: not a WAV file (no RIFF/WAVE header)", field="path")
            while True:
                ch = fh.read(8)
                if len(ch) < 8:
                    raise CampaignError(f"{path}: WAV file without a 'fmt ' chunk", field="path")
                cid, size = ch[:4], struct.unpack("<I", ch[4:])[0]
                if cid == b"fmt ":
                    body = fh.read(min(size, 16))
                    if len(body) < 8:
                        raise CampaignError(f"{path}: truncated WAV 'fmt ' chunk", field="path")
                    return int(struct.unpack("<I", body[4:8])[0])
                fh.seek(size + (size & 1), 1)
    except FileNotFoundError:
        raise CampaignError(f"{path}: missing microphone file", field="path") from None
    except OSError as exc:
        raise CampaignError(f"{path}: cannot read WAV file ({exc})", field="path") from None


def wav_levels(path: str | os.PathLike[str], mic: Microphone, *, block_s: float = DEFAULT_BLOCK_S,
               flight: str = "", sample_rate_hz: float | None = None) -> LevelSeries:
    """Levels of a WAV recording: bands, A-weighted level per block, mount correction.

    Sample values (float, or integer PCM with full scale 1) times ``mic.full_scale_v``
    are volts; divided by ``mic.sensitivity_v_per_pa`` they are pascals
    (:func:`gisnoise.acoustics.physics.wav_band_levels`).  The mount correction of ``mic.mount``
    is added to the bands, and the overall level is their A-weighted sum, so the result
    is free field.

    Parameters
    ----------
    path : path-like
        Mono WAV file, first sample at the flight's ``start_utc``.
    mic : Microphone
        Its calibration and mount.
    block_s : float
        Averaging block, s.
    flight : str
        Flight id recorded in the result.
    sample_rate_hz : float, optional
        Required sample rate, Hz.
    """
    p = Path(path)
    rate = _wav_rate(p)
    if sample_rate_hz is not None and rate != sample_rate_hz:
        raise CampaignError(f"{p}: sample_rate_hz is {rate} Hz, the campaign states {sample_rate_hz:g} Hz",
                            field="sample_rate_hz")
    if mic.sensitivity_v_per_pa is None:
        raise CampaignError(f"microphone '{mic.id}': field 'sensitivity_v_per_pa' is needed for WAV input ({p})",
                            field="sensitivity_v_per_pa")
    t, f, lev = acoustics.wav_band_levels(p, mic.sensitivity_v_per_pa / mic.full_scale_v, block_s)
    bands = np.asarray(lev, dtype=float) + acoustics.mount_correction(mic.mount)
    la = acoustics.overall_a_level(bands, f)
    return LevelSeries(mic=mic.id, flight=flight, source=str(p), t=np.asarray(t, dtype=float),
                       la=np.asarray(la, dtype=float), band_f=np.asarray(f, dtype=float), bands=bands)


# ======================================================================= reading
class _Collector:
    """Raise at the first problem (strict) or collect them all."""

    def __init__(self, strict: bool) -> None:
        self.strict = strict
        self.problems: list[Problem] = []

    def add(self, file: str, field: str, message: str) -> None:
        if self.strict:
            raise CampaignError(message, field=field)
        self.problems.append(Problem(file, field, message))

    def error(self, file: str, exc: GisnoiseError) -> None:
        self.add(file, exc.field or "", str(exc))


def read_campaign(folder: str | os.PathLike[str], *, exclusions: Iterable[Any] | None = None,
                  absorption: bool = False, snr_db: float = DEFAULT_SNR_DB, event_db: float = DEFAULT_EVENT_DB,
                  block_s: float | None = None, progress: ProgressFn | None = None) -> Campaign:
    """Read and check a campaign folder.

    Parameters
    ----------
    folder : path-like
        The campaign folder (``campaign.json``, ``flights/``, ``mics/``).
    exclusions : iterable, optional
        Extra excluded intervals: :class:`Exclusion`, mappings with ``flight``, ``t0``,
        ``t1`` (reception time, s) and optional ``mic``, or tuples
        ``(flight, t0, t1[, mic])``.  Added to those of campaign.json.
    absorption : bool
        Correct levels for atmospheric absorption (rows with band levels only).
    snr_db : float
        Margin above the background below which rows are masked ``low_snr``, dB.
    event_db : float
        Joint rise flagging an ``event``, dB.
    block_s : float, optional
        Averaging block for WAV input, s (default: campaign.json ``block_s`` or 0.125).
    progress : callable, optional
        ``progress(done, total)`` after each microphone file; may raise
        :class:`~gisnoise.errors.Cancelled`.

    Raises
    ------
    CampaignError
        At the first problem, naming the file and the field.
    """
    camp, _ = _load(folder, strict=True, exclusions=exclusions, absorption=absorption, snr_db=snr_db,
                    event_db=event_db, block_s=block_s, progress=progress)
    assert camp is not None
    return camp


def inspect_campaign(folder: str | os.PathLike[str], **kwargs: Any) -> tuple[Campaign | None, list[Problem]]:
    """Read what can be read and collect every problem (the keywords of :func:`read_campaign`).

    Returns the campaign built from the readable parts (None when campaign.json
    itself is unusable) and the problems.  Samples are computed to find problems of
    the geometry (levels outside the flight log, say).
    """
    camp, collector = _load(folder, strict=False, **kwargs)
    if camp is not None and camp.levels:
        try:
            s = camp.samples()
        except GisnoiseError as exc:
            collector.error(str(Path(folder) / "campaign.json"), exc)
        else:
            for lv in camp.levels:
                m = (s.mic == lv.mic) & (s.flight == lv.flight)
                if m.any() and np.all(s.mask_reason[m] == "outside_flight"):
                    collector.add(lv.source, "t", f"{lv.source}: no block falls within the flight log of "
                                  f"'{lv.flight}' (check start_utc)")
    return camp, collector.problems


def check_campaign(folder: str | os.PathLike[str], **kwargs: Any) -> list[Problem]:
    """Every problem of a campaign folder (empty when it reads cleanly)."""
    return inspect_campaign(folder, **kwargs)[1]


def _load(folder: str | os.PathLike[str], *, strict: bool, exclusions: Iterable[Any] | None = None,
          absorption: bool = False, snr_db: float = DEFAULT_SNR_DB, event_db: float = DEFAULT_EVENT_DB,
          block_s: float | None = None, progress: ProgressFn | None = None) -> tuple[Campaign | None, _Collector]:
    col = _Collector(strict)
    root = Path(folder)
    cj = root / "campaign.json"
    cjs = str(cj)
    for name, v in (("snr_db", snr_db), ("event_db", event_db)):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0):
            raise CampaignError(f"{name} must be a non-negative number, got {v!r}", field=name)
    if not root.is_dir():
        col.add(str(root), "folder", f"{root}: no such campaign folder")
        return None, col
    try:
        doc = json.loads(cj.read_text(encoding="utf-8"))
    except FileNotFoundError:
        col.add(cjs, "campaign.json", f"{cjs}: missing campaign file")
        return None, col
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        col.add(cjs, "campaign.json", f"{cjs}: not valid JSON ({exc})")
        return None, col
    if not isinstance(doc, dict):
        col.add(cjs, "campaign.json", f"{cjs}: expected a JSON object")
        return None, col
    header = _parse_header(cjs, doc, col, absorption)
    if header is None:
        return None, col
    origin, weather, vehicle, c = header
    mics = _parse_mics(cjs, doc, col)
    flights = _parse_flights(cjs, root, doc, col)
    excl = _parse_exclusions(cjs, doc.get("exclusions"), col, "exclusions")
    excl += _parse_exclusions("exclusions", list(exclusions) if exclusions is not None else None, col,
                              "exclusions")
    fids, mids = {f.id for f in flights}, {m.id for m in mics}
    raw_mids = {m.get("id") for m in doc.get("microphones", []) if isinstance(m, dict)} \
        if isinstance(doc.get("microphones"), list) else set()
    for i, e in enumerate(excl):
        if e.flight not in fids:
            col.add(cjs, "exclusions", f"{cjs}: exclusion {i} names unknown flight {e.flight!r}")
        elif e.mic is not None and e.mic not in mids and e.mic not in raw_mids:
            col.add(cjs, "exclusions", f"{cjs}: exclusion {i} names unknown microphone {e.mic!r}")
    rate = doc.get("sample_rate_hz")
    if rate is not None and not (_is_number(rate) and rate > 0):
        col.add(cjs, "sample_rate_hz", f"{cjs}: field 'sample_rate_hz' must be a positive number, got {rate!r}")
        rate = None
    if block_s is None:
        block_s = doc.get("block_s", DEFAULT_BLOCK_S)
    if not (_is_number(block_s) and block_s > 0):
        col.add(cjs, "block_s", f"{cjs}: field 'block_s' must be a positive number, got {block_s!r}")
        block_s = DEFAULT_BLOCK_S
    # flights
    trajectories: dict[str, Trajectory] = {}
    for f in flights:
        if not f.log:
            continue
        try:
            trajectories[f.id] = read_flight(f.log, start_utc=f.start_utc, geoid_undulation_m=f.geoid_undulation_m)
        except GisnoiseError as exc:
            col.error(f.log, exc)
    # microphone files
    pairs = []
    for m in mics:
        for f in flights:
            base = root / "mics" / m.id / f.id
            csv_p, wav_p = base.with_suffix(".csv"), base.with_suffix(".wav")
            if csv_p.is_file():
                pairs.append((m, f, csv_p))
            elif wav_p.is_file():
                pairs.append((m, f, wav_p))
            else:
                col.add(str(wav_p), "mics", f"{wav_p}: missing microphone file (no {f.id}.wav or {f.id}.csv "
                        f"for microphone '{m.id}', flight '{f.id}')")
    wavs = [p for _, _, p in pairs if p.suffix == ".wav"]
    bad_rate: set[Path] = set()
    if wavs:
        rates = {}
        for p in wavs:
            try:
                rates[p] = _wav_rate(p)
            except GisnoiseError as exc:
                col.error(str(p), exc)
                bad_rate.add(p)
        if rate is None and rates:
            common = _common_rate(root, {f.id for f in flights}, rates)
            for p, r in rates.items():
                if r != common:
                    col.add(str(p), "sample_rate_hz", f"{p}: sample_rate_hz is {r} Hz, the campaign's other WAV "
                            f"files have {common} Hz")
                    bad_rate.add(p)
        elif rate is not None:
            for p, r in rates.items():
                if r != rate:
                    col.add(str(p), "sample_rate_hz", f"{p}: sample_rate_hz is {r} Hz, campaign.json states "
                            f"{rate:g} Hz")
                    bad_rate.add(p)
    levels = []
    total = float(len(pairs))
    for k, (m, f, p) in enumerate(pairs):
        if p in bad_rate:
            continue
        try:
            if p.suffix == ".csv":
                levels.append(read_level_csv(p, mic=m.id, flight=f.id))
            else:
                levels.append(wav_levels(p, m, block_s=float(block_s), flight=f.id))
        except GisnoiseError as exc:
            col.error(str(p), exc)
        if progress is not None:
            progress(k + 1.0, total)
    camp = Campaign(folder=root, origin=origin, weather=weather, vehicle=vehicle, speed_of_sound_m_s=c,
                    microphones=tuple(mics), flights=tuple(f for f in flights if f.id in trajectories),
                    trajectories=trajectories,
                    levels=tuple(lv for lv in levels if lv.flight in trajectories),
                    exclusions=tuple(excl), absorption=bool(absorption), snr_db=float(snr_db),
                    event_db=float(event_db))
    return camp, col


def _common_rate(root: Path, flight_ids: set[str], rates: Mapping[Path, int]) -> int:
    """The sample rate most WAV files of the campaign share (ties: the higher rate)."""
    every = dict(rates)
    for p in sorted(root.glob("mics/*/*.wav")):
        if p.stem in flight_ids and p not in every:
            try:
                every[p] = _wav_rate(p)
            except GisnoiseError:
                continue
    vals = list(every.values())
    return max(set(vals), key=lambda r: (vals.count(r), r))


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _parse_header(cjs: str, doc: Mapping[str, Any], col: _Collector,
                  absorption: bool) -> tuple[LocalFrame, dict[str, Any], dict[str, Any], float] | None:
    schema = doc.get("schema")
    if not isinstance(schema, str) or not schema.startswith(SCHEMA_PREFIX):
        col.add(cjs, "schema", f"{cjs}: field 'schema' must be '{SCHEMA}', got {schema!r}")
        return None
    try:
        version = int(schema[len(SCHEMA_PREFIX):])
    except ValueError:
        version = -1
    if version not in SUPPORTED_VERSIONS:
        col.add(cjs, "schema", f"{cjs}: field 'schema': unknown version {schema!r}; this release reads {SCHEMA}")
        return None
    ok = True
    o = doc.get("origin")
    origin = None
    if not isinstance(o, dict) or not all(_is_number(o.get(k)) for k in ("lat", "lon", "h")):
        col.add(cjs, "origin", f"{cjs}: field 'origin' needs numbers lat, lon, h, got {o!r}")
        ok = False
    else:
        try:
            origin = LocalFrame(float(o["lat"]), float(o["lon"]), float(o["h"]))
        except GisnoiseError as exc:
            col.add(cjs, "origin", f"{cjs}: field 'origin': {exc}")
            ok = False
    w = doc.get("weather", {})
    weather: dict[str, Any] = {}
    if not isinstance(w, dict):
        col.add(cjs, "weather", f"{cjs}: field 'weather' must be an object")
        w = {}
    limits = {"temperature_c": (-60.0, 60.0), "humidity_pct": (0.0, 100.0), "pressure_kpa": (50.0, 110.0),
              "wind_speed_m_s": (0.0, 60.0), "wind_from_deg": (-360.0, 360.0)}
    for k, (lo, hi) in limits.items():
        v = w.get(k)
        if v is None:
            continue
        if not _is_number(v) or not lo <= v <= hi:
            col.add(cjs, f"weather.{k}", f"{cjs}: field 'weather.{k}' must be a number in [{lo:g}, {hi:g}], "
                    f"got {v!r}")
            ok = False
            continue
        weather[k] = float(v)
    weather.setdefault("pressure_kpa", 101.325)
    c = doc.get("speed_of_sound_m_s")
    if c is None:
        if "temperature_c" not in weather:
            col.add(cjs, "weather.temperature_c", f"{cjs}: field 'weather.temperature_c' is needed when "
                    "'speed_of_sound_m_s' is null")
            ok = False
            c = float("nan")
        else:
            c = float(acoustics.speed_of_sound(weather["temperature_c"]))
    elif not _is_number(c) or not 250.0 <= c <= 400.0:
        col.add(cjs, "speed_of_sound_m_s", f"{cjs}: field 'speed_of_sound_m_s' must be in [250, 400] m/s, "
                f"got {c!r}")
        ok = False
    if absorption:
        for k in ("temperature_c", "humidity_pct"):
            if k not in weather:
                col.add(cjs, f"weather.{k}", f"{cjs}: field 'weather.{k}' is needed for the absorption correction")
                ok = False
    v = doc.get("vehicle")
    vehicle: dict[str, Any] = {}
    if not isinstance(v, dict) or not _is_number(v.get("reference_power_w")) or v["reference_power_w"] <= 0:
        got = v.get("reference_power_w") if isinstance(v, dict) else v
        col.add(cjs, "vehicle.reference_power_w", f"{cjs}: field 'vehicle.reference_power_w' must be a positive "
                f"number (W), got {got!r}")
        ok = False
    else:
        vehicle = dict(v)
        vehicle["reference_power_w"] = float(v["reference_power_w"])
        vehicle.setdefault("name", "")
    if not ok or origin is None:
        return None
    return origin, weather, vehicle, float(c)


def _named_entries(cjs: str, doc: Mapping[str, Any], key: str, kind: str,
                   col: _Collector) -> Iterator[tuple[str, dict[str, Any], str]]:
    """``(where, entry, id)`` of each entry of the list ``doc[key]`` that is an object with a valid, unique id.

    The list being missing or empty, an entry not an object, a bad id and a duplicate ``kind`` id are
    reported to ``col`` (the entry is skipped)."""
    raw = doc.get(key)
    if not isinstance(raw, list) or not raw:
        col.add(cjs, key, f"{cjs}: field '{key}' must be a non-empty list")
        return
    seen = set()
    for i, m in enumerate(raw):
        where = f"{key}[{i}]"
        if not isinstance(m, dict):
            col.add(cjs, where, f"{cjs}: field '{where}' must be an object")
            continue
        mid = m.get("id")
        if not isinstance(mid, str) or not mid or "/" in mid or "\\" in mid:
            col.add(cjs, f"{where}.id", f"{cjs}: field '{where}.id' must be a non-empty name, got {mid!r}")
            continue
        if mid in seen:
            col.add(cjs, f"{where}.id", f"{cjs}: field '{where}.id': duplicate {kind} id {mid!r}")
            continue
        seen.add(mid)
        yield where, m, mid


def _parse_mics(cjs: str, doc: Mapping[str, Any], col: _Collector) -> list[Microphone]:
    out: list[Microphone] = []
    for where, m, mid in _named_entries(cjs, doc, "microphones", "microphone", col):
        good = True
        for k in ("lat", "lon", "h"):
            if not _is_number(m.get(k)):
                col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' must be a number, got {m.get(k)!r}")
                good = False
        mount = m.get("mount", "free_field")
        if not isinstance(mount, str) or mount not in acoustics.MOUNT_CORRECTIONS_DB:
            col.add(cjs, f"{where}.mount", f"{cjs}: field '{where}.mount': unknown mount {mount!r}; known: "
                    f"{', '.join(acoustics.MOUNT_CORRECTIONS_DB)}")
            good = False
        extra: dict[str, Any] = {}
        for k in ("sensitivity_v_per_pa", "full_scale_v", "background_db", "height_agl_m"):
            v = m.get(k)
            if v is None:
                continue
            if not _is_number(v) or (k == "height_agl_m" and v < 0) or (k not in ("background_db", "height_agl_m")
                                                                        and v <= 0):
                col.add(cjs, f"{where}.{k}", f"{cjs}: field '{where}.{k}' must be a positive number, got {v!r}")
                good = False
            else:
                extra[k] = float(v)
        if good:
            out.append(Microphone(id=mid, lat=float(m["lat"]), lon=float(m["lon"]), h=float(m["h"]),
                                  mount=str(mount), **extra))
    return out


def _parse_flights(cjs: str, root: Path, doc: Mapping[str, Any], col: _Collector) -> list[Flight]:
    out: list[Flight] = []
    for where, f, fid in _named_entries(cjs, doc, "flights", "flight", col):
        try:
            start = as_unix_time(f.get("start_utc"), field=f"{where}.start_utc")
        except GisnoiseError as exc:
            col.add(cjs, f"{where}.start_utc", f"{cjs}: field {exc}")
            continue
        und = f.get("geoid_undulation_m")
        if und is not None and not _is_number(und):
            col.add(cjs, f"{where}.geoid_undulation_m", f"{cjs}: field '{where}.geoid_undulation_m' must be a "
                    f"number, got {und!r}")
            continue
        logs = [root / "flights" / f"{fid}{s}" for s in FLIGHT_SUFFIXES]
        found = [p for p in logs if p.is_file()]
        if not found:
            col.add(str(logs[0]), "flights", f"{logs[0]}: missing flight log for flight '{fid}' "
                    f"(.csv, .ulg or .bin)")
            log_path = ""
        elif len(found) > 1:
            col.add(str(found[0]), "flights", f"{found[0]}: flight '{fid}' has several logs "
                    f"({', '.join(p.name for p in found)}); keep one")
            log_path = ""
        else:
            log_path = str(found[0])
        out.append(Flight(id=fid, start_utc=start, log=log_path,
                          geoid_undulation_m=None if und is None else float(und)))
    return out


def _parse_exclusions(src: str, raw: Any, col: _Collector, where: str) -> list[Exclusion]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        col.add(src, where, f"{src}: field '{where}' must be a list")
        return []
    out = []
    for i, e in enumerate(raw):
        w = f"{where}[{i}]"
        if isinstance(e, Exclusion):
            out.append(e)
            continue
        if isinstance(e, (tuple, list)) and len(e) in (3, 4):
            e = dict(zip(("flight", "t0", "t1", "mic"), e, strict=False))
        if not isinstance(e, dict):
            col.add(src, w, f"{src}: field '{w}' must be an object with flight, t0, t1")
            continue
        if not isinstance(e.get("flight"), str) or not _is_number(e.get("t0")) or not _is_number(e.get("t1")) \
                or e["t1"] < e["t0"]:
            col.add(src, w, f"{src}: field '{w}' needs flight (name) and t0 <= t1 (s), got {e!r}")
            continue
        mic = e.get("mic")
        out.append(Exclusion(flight=e["flight"], t0=float(e["t0"]), t1=float(e["t1"]),
                             mic=None if mic is None else str(mic), reason=str(e.get("reason", ""))))
    return out


def write_levels(folder: str | os.PathLike[str], *, block_s: float | None = None, force: bool = False,
                 progress: ProgressFn | None = None) -> list[Path]:
    """Turn every WAV of a campaign into a level CSV beside it (``mics/<mic>/<flight>.csv``).

    The CSV holds ``t`` (block centre, s), ``LA`` (free field, dB(A)) and the free-field
    band levels ``L_<nominal>`` (dB).  Existing CSVs are refused unless ``force``.

    Parameters
    ----------
    folder : path-like
        Campaign folder.
    block_s : float, optional
        Averaging block, s (default: campaign.json ``block_s`` or 0.125).
    force : bool
        Overwrite existing level CSVs.
    progress : callable, optional
        ``progress(done_s, total_s)`` in seconds of audio.

    Returns
    -------
    list of Path
        The files written.
    """
    col = _Collector(strict=True)
    root = Path(folder)
    cj = root / "campaign.json"
    try:
        doc = json.loads(cj.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CampaignError(f"{cj}: missing campaign file", field="campaign.json") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{cj}: not valid JSON ({exc})", field="campaign.json") from None
    if not isinstance(doc, dict):
        raise CampaignError(f"{cj}: expected a JSON object", field="campaign.json")
    mics = _parse_mics(str(cj), doc, col)
    flights = [f.get("id") for f in doc.get("flights", []) if isinstance(f, dict)]
    if block_s is None:
        block_s = doc.get("block_s", DEFAULT_BLOCK_S)
    if not (_is_number(block_s) and block_s > 0):
        raise CampaignError(f"block_s must be a positive number, got {block_s!r}", field="block_s")
    rate = doc.get("sample_rate_hz")
    jobs = []
    for m in mics:
        for fid in flights:
            wav = root / "mics" / m.id / f"{fid}.wav"
            if wav.is_file():
                jobs.append((m, str(fid), wav))
    if not jobs:
        raise CampaignError(f"{root / 'mics'}: no WAV file of a known microphone and flight", field="mics")
    info = {wav: _wav_rate(wav) for _, _, wav in jobs}
    rates = list(info.values())
    common = float(rate) if _is_number(rate) else float(max(set(rates), key=lambda r: (rates.count(r), r)))
    for wav, fs in info.items():
        if fs != common:
            which = "campaign.json states" if _is_number(rate) else "the campaign's other WAV files have"
            raise CampaignError(f"{wav}: sample_rate_hz is {fs} Hz, {which} {common:g} Hz", field="sample_rate_hz")
        target = wav.with_suffix(".csv")
        if target.exists() and not force:
            raise CampaignError(f"{target}: exists; use --force to overwrite", field="force")
    durations = {wav: max(wav.stat().st_size, 1) / fs for wav, fs in info.items()}  # proportional to seconds
    total = float(sum(durations.values()))
    done = 0.0
    written = []
    for m, fid, wav in jobs:
        lv = wav_levels(wav, m, block_s=float(block_s), flight=fid, sample_rate_hz=common)
        target = wav.with_suffix(".csv")
        write_level_csv(target, lv.t, lv.la, lv.band_f, lv.bands)
        written.append(target)
        done += durations[wav]
        if progress is not None:
            progress(done, total)
    return written


# ======================================================================= samples
def _build_samples(camp: Campaign) -> Samples:
    c = camp.speed_of_sound_m_s
    parts: list[dict[str, Any]] = []
    band_set = np.unique(np.concatenate([_band_key(lv.band_f) for lv in camp.levels if lv.band_f is not None]
                                        or [np.zeros(0)]))
    band_f = np.asarray(acoustics.exact_frequency(band_set), dtype=float) if band_set.size else None
    mic_pos = {m.id: camp.mic_enu(m.id) for m in camp.microphones}
    tracks = {}
    for fid, tr in camp.trajectories.items():
        enu = np.stack(tr.enu(camp.origin), axis=-1)
        vel = np.gradient(enu, tr.t, axis=0) if len(tr) > 1 else np.zeros_like(enu)
        tracks[fid] = (tr, enu, vel)
    for lv in camp.levels:
        tr, enu, vel = tracks[lv.flight]
        m = mic_pos[lv.mic]
        t_e = emission_time(lv.t, tr.t, enu, m, c)
        st = tr.interpolate(t_e)
        x = np.stack([np.interp(t_e, tr.t, enu[:, i]) for i in range(3)], axis=-1)
        v = np.stack([np.interp(t_e, tr.t, vel[:, i]) for i in range(3)], axis=-1)
        r = m - x
        d, phi, theta = emission_angles(r[:, 0], r[:, 1], r[:, 2], np.radians(st["yaw"]), np.radians(st["pitch"]),
                                        np.radians(st["roll"]))
        n = len(lv.t)
        bands = None
        if band_f is not None:
            bands = np.full((n, len(band_f)), np.nan)
            if lv.bands is not None:
                cols = np.searchsorted(band_set, _band_key(lv.band_f))
                bands[:, cols] = lv.bands
        parts.append({
            "mic": np.full(n, lv.mic, dtype=object), "flight": np.full(n, lv.flight, dtype=object),
            "t_r": lv.t, "t_e": t_e, "level": lv.la.copy(), "d": d, "phi": phi, "theta": theta,
            "power_w": st["power_w"], "phase": st["phase"], "roll": st["roll"], "pitch": st["pitch"],
            "yaw": st["yaw"], "uav_enu": x, "mic_enu": np.broadcast_to(m, (n, 3)).copy(), "vel_enu": v,
            "rpm": st.get("rpm", np.full(n, np.nan)), "airspeed_m_s": st.get("airspeed_m_s", np.full(n, np.nan)),
            "bands": bands,
            "outside": (t_e < tr.t[0]) | (t_e > tr.t[-1]),
            "has_bands": lv.bands is not None,
        })
    if not parts:
        raise CampaignError(f"{camp.folder}: no microphone levels to read", field="mics")
    cat = {k: np.concatenate([p[k] for p in parts]) for k in parts[0] if k not in ("bands", "has_bands")}
    bands_all = np.concatenate([p["bands"] for p in parts]) if band_f is not None else None
    mic = cat["mic"].astype(str)
    flight = cat["flight"].astype(str)
    n = len(mic)
    level = cat["level"]
    outside = cat["outside"]

    # absorption (band-wise, bands clear of their background only), on the measured level
    meta_uncorrected = []
    if camp.absorption:
        level = level.copy()
        w = camp.weather
        start = 0
        for p in parts:
            k = len(p["t_r"])
            sl = slice(start, start + k)
            start += k
            if not p["has_bands"] or bands_all is None or band_f is None:
                meta_uncorrected.append((str(p["mic"][0]), str(p["flight"][0])))
                continue
            b = bands_all[sl]
            d = cat["d"][sl]
            quiet = outside[sl]
            if quiet.sum() >= 8:   # blocks before/after the flight: the background itself
                bg_b = np.array([np.median(col[np.isfinite(col)]) if np.isfinite(col).any() else np.nan
                                 for col in b[quiet].T])
            else:                  # the quiet end of the farthest quarter (high while the UAV is audible)
                far = ~quiet
                if far.any():
                    far &= d >= np.percentile(d[far], 75.0)
                bg_b = acoustics.background_levels(b[far], BACKGROUND_PERCENTILE) if far.any() else \
                    np.full(b.shape[1], np.inf)
            bg_b = np.where(np.isnan(bg_b), np.inf, bg_b)  # a band absent here is never corrected
            level[sl] = acoustics.absorption_corrected_level(
                level[sl], b, band_f, d, w["temperature_c"], w["humidity_pct"], w.get("pressure_kpa", 101.325),
                background_db=bg_b, min_snr_db=SIGNAL_BAND_MARGIN_DB)

    # masks
    reason = np.full(n, "", dtype=object)
    excluded = np.zeros(n, dtype=bool)
    for e in camp.exclusions:
        sel = (flight == e.flight) & (cat["t_r"] >= e.t0) & (cat["t_r"] <= e.t1)
        if e.mic is not None:
            sel &= mic == e.mic
        excluded |= sel
    background, excess, bg_how = _background_and_excess(camp, mic, flight, cat, level, outside, excluded)
    with np.errstate(invalid="ignore"):
        low = level < background + camp.snr_db
    event = np.zeros(n, dtype=bool)
    for fid in np.unique(flight):
        rows = [np.flatnonzero((flight == fid) & (mic == mid)) for mid in np.unique(mic[flight == fid])]
        flags = detect_events([cat["t_r"][r] for r in rows], [excess[r] for r in rows], event_db=camp.event_db)
        for r, fl in zip(rows, flags, strict=True):
            event[r] = fl
    reason[low] = "low_snr"
    reason[event] = "event"
    reason[excluded] = "excluded"
    reason[outside] = "outside_flight"
    reason = reason.astype(str)

    rpm = cat["rpm"] if np.isfinite(cat["rpm"]).any() else None
    airspeed = cat["airspeed_m_s"] if np.isfinite(cat["airspeed_m_s"]).any() else None
    meta = {
        "folder": camp.folder.name,
        "origin": {"lat": camp.origin.lat0, "lon": camp.origin.lon0, "h": camp.origin.h0},
        "weather": dict(camp.weather),
        "vehicle": dict(camp.vehicle),
        "reference_power_w": camp.reference_power_w,
        "speed_of_sound_m_s": c,
        "absorption_corrected": bool(camp.absorption),
        "absorption_uncorrected_series": meta_uncorrected,
        "background": bg_how,
        "snr_db": camp.snr_db,
        "event_db": camp.event_db,
        "flights": {f.id: {"start_utc": f.start_utc, "log": Path(f.log).name} for f in camp.flights},
        "microphones": {m.id: {"lat": m.lat, "lon": m.lon, "h": m.h, "mount": m.mount,
                               **({} if m.height_agl_m is None else {"height_agl_m": m.height_agl_m})}
                        for m in camp.microphones},
    }
    if meta_uncorrected:
        log.info("absorption not corrected for %d series without band levels", len(meta_uncorrected))
    return Samples(mic=mic, flight=flight, t_r=cat["t_r"], t_e=cat["t_e"], level=level, d=cat["d"],
                   phi=cat["phi"], theta=cat["theta"], power_w=cat["power_w"], phase=cat["phase"].astype(str),
                   roll=cat["roll"], pitch=cat["pitch"], yaw=cat["yaw"], uav_enu=cat["uav_enu"],
                   mic_enu=cat["mic_enu"], vel_enu=cat["vel_enu"], valid=reason == "", mask_reason=reason,
                   rpm=rpm, airspeed_m_s=airspeed, band_f=band_f, bands=bands_all, background_db=background,
                   meta=meta)


def _background_and_excess(camp: Campaign, mic: np.ndarray, flight: np.ndarray, cat: Mapping[str, np.ndarray],
                           level: np.ndarray, outside: np.ndarray,
                           excluded: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Background per row, level minus expectation per row, and how each background was found."""
    n = len(level)
    background = np.full(n, np.nan)
    excess = np.full(n, np.nan)
    given = {m.id: m.background_db for m in camp.microphones}
    how: list[dict[str, Any]] = []
    for mid in np.unique(mic):
        for fid in np.unique(flight[mic == mid]):
            idx = np.flatnonzero((mic == mid) & (flight == fid))
            use = ~(outside[idx] | excluded[idx])
            bg, source = given.get(mid), "campaign.json"
            if bg is None:
                bg, source = _quiet_background(level[idx], outside[idx] & ~excluded[idx], use), "outside_flight"
            fit = fit_level_trend(level[idx], cat["d"][idx], cat["power_w"][idx], phase=cat["phase"][idx],
                                  use=use, background_db=bg)
            if fit is None:
                background[idx] = np.nan if bg is None else bg
                how.append({"mic": str(mid), "flight": str(fid), "background_db": background[idx[0]],
                            "source": source if bg is not None else "none"})
                continue
            expected, b = fit
            if bg is None:
                source = "plateau_fit" if np.isfinite(b) else "none"
            background[idx] = b
            how.append({"mic": str(mid), "flight": str(fid), "background_db": float(b), "source": source})
            ex = level[idx] - expected
            ex[~use] = np.nan
            excess[idx] = ex - np.nanmedian(ex)
    return background, excess, how


def _quiet_background(level: np.ndarray, quiet: np.ndarray, flying: np.ndarray) -> float | None:
    """Median level of the blocks whose emission lies outside the flight log (at least 8 of them),
    unless it is not below the quiet end of the in-flight levels (then the UAV was audible)."""
    if quiet.sum() < 8:
        return None
    b = float(np.median(level[quiet]))
    if flying.sum() >= 8 and b > float(np.percentile(level[flying], 5.0)) + 1.0:
        return None
    return b


def fit_level_trend(level: Any, d: Any, power_w: Any, *, phase: Any = None, use: Any = None,
                    background_db: float | None = None) -> tuple[np.ndarray, float] | None:
    """Robust fit of ``L = 10 log10(10^((a_phase + b log10(d/40) + c log10 P)/10) + 10^(B/10))``.

    The trend of one microphone during one flight (spreading with distance, loudness
    with power, one offset per flight phase) power-summed with a background plateau
    ``B``; soft-L1 loss (scale 1 dB) so events and directivity do not drag it.  The
    power term is left out when the power does not vary, a phase with fewer than 8
    rows shares the offset of the most common phase.

    The plateau is accepted only where the data show it: at least 10 % of the rows
    within 2 dB above ``B`` and at most 2 % more than 3 dB below it.  Otherwise the
    background is not determined (``B`` is NaN) and the trend is refitted alone.

    Parameters
    ----------
    level : array_like
        Levels, dB(A).
    d : array_like
        Distances, m.
    power_w : array_like
        Electric power, W.
    phase : array_like of str, optional
        Flight phase of each row.
    use : array_like of bool, optional
        Rows to fit (default all).
    background_db : float, optional
        Known background; only the trend is fitted then.

    Returns
    -------
    (expected, B) or None
        Expected level of every row, dB(A), and the background, dB(A) (NaN when not
        determined); None with fewer than 8 rows to fit.

    Examples
    --------
    >>> d = np.geomspace(30.0, 3000.0, 200)
    >>> L = 10 * np.log10(10 ** ((70 - 20 * np.log10(d / 40)) / 10) + 10 ** 4.0)
    >>> expected, b = fit_level_trend(L, d, np.full(200, 1000.0))
    >>> round(b, 3), round(float(np.max(np.abs(expected - L))), 3)
    (40.0, 0.0)
    >>> expected, b = fit_level_trend(L[:100], d[:100], np.full(100, 1000.0))  # never near 40 dB
    >>> b
    nan
    """
    from scipy.optimize import least_squares

    level = np.asarray(level, dtype=float)
    n = len(level)
    ld = np.log10(np.maximum(np.asarray(d, dtype=float), 1e-3) / 40.0)
    p = np.maximum(np.asarray(power_w, dtype=float), 1e-9)
    use = np.ones(n, dtype=bool) if use is None else np.asarray(use, dtype=bool)
    if use.sum() < 8:
        return None
    ph = np.full(n, "", dtype=object) if phase is None else np.asarray(phase, dtype=object)
    names, counts = np.unique(ph[use].astype(str), return_counts=True)
    main = names[int(np.argmax(counts))]
    kept = [str(nm) for nm, c in zip(names, counts, strict=True) if c >= 8 and nm != main]
    offsets = [np.ones(n)] + [(ph == nm).astype(float) for nm in kept]  # main phase + differences
    lp = np.log10(p / np.median(p[use]))
    cols = offsets + [ld] + ([lp] if np.std(lp[use]) > 1e-3 else [])
    a = np.column_stack(cols)
    k = a.shape[1]
    i_b = len(offsets)  # column of log10(d / 40)
    lv, au = level[use], a[use]
    top = lv >= np.median(lv)
    coef0, *_ = np.linalg.lstsq(au[top] if top.sum() >= 2 * k else au, lv[top] if top.sum() >= 2 * k else lv,
                                rcond=None)
    ln10 = np.log(10.0) / 10.0
    lower = [-np.inf] * k
    upper = [np.inf] * k
    lower[i_b], upper[i_b] = -60.0, 20.0
    x0 = np.array(coef0, dtype=float)
    x0[i_b] = float(np.clip(x0[i_b], -59.0, 19.0))

    def solve(bg: float | None) -> tuple[np.ndarray, float]:
        if bg is not None:
            def resid(x: np.ndarray) -> np.ndarray:
                return np.logaddexp(au @ x * ln10, bg * ln10) / ln10 - lv
            r = least_squares(resid, x0, bounds=(lower, upper), loss="soft_l1", f_scale=1.0)
            return r.x, bg
        lo_b = float(lv.min()) - 30.0
        xb = np.append(x0, np.clip(np.percentile(lv, 5.0) - 1.0, lo_b + 1e-6, lv.max() - 1e-6))

        def resid_b(x: np.ndarray) -> np.ndarray:
            return np.logaddexp(au @ x[:k] * ln10, x[k] * ln10) / ln10 - lv
        r = least_squares(resid_b, xb, bounds=(lower + [lo_b], upper + [float(lv.max())]), loss="soft_l1",
                          f_scale=1.0)
        return r.x[:k], float(r.x[k])

    if background_db is not None:
        x, b = solve(float(background_db))
    else:
        x, b = solve(None)
        if np.mean(lv < b + 2.0) < 0.10 or np.mean(lv < b - 3.0) > 0.02:
            x, b = solve(-np.inf)
            b = float("nan")
    expected = np.logaddexp(a @ x * ln10, (b if np.isfinite(b) else -np.inf) * ln10) / ln10
    return expected, b


