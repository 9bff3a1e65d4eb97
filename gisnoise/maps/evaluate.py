"""The reference evaluator: noise metrics of a trajectory on a grid of receivers.

For every receiver (cell centre of a :class:`~gisnoise.geo.grid.GridSpec`, at
``receiver_height`` above flat ground or a DEM) and every evaluation instant of the
trajectory (each sample, or finer with ``substeps``), the UAV level ``L_UAV`` is
computed by the card's ansatz (:mod:`gisnoise.model.ansatz`, one model definition for
evaluation, fitting and diagnosis).  The card of each instant is chosen by the
flight phase (:class:`CardSet`).  From the levels the evaluator forms

``LAmax``
    maximum over the evaluation instants, dB(A);
``LAeq``
    ``10 log10( (1/T) integral 10^(L/10) dt )`` over the period ``T`` (default the
    trajectory's duration; time outside the trajectory contributes nothing), dB(A);
``SEL``
    sound exposure level ``LAE = 10 log10( integral 10^(L/10) dt / 1 s )``, dB(A);
``TA<level>``
    time above a level, s, with the level taken linear between instants;
``LA@<t>s``
    snapshot: the level at one instant ``t`` (state interpolated), dB(A).

Integrals use the trapezoid rule over the evaluation instants (the samples, or
``substeps`` equal sub-intervals per sample interval with the state interpolated:
positions, power linearly, angles on the circle, phase from the earlier sample).

The work is vectorised over blocks of cells x instants whose size is bounded
(``block_size`` cell-instants), so memory stays bounded for any grid and
trajectory length.  The per-block physics is the pure function
:func:`_levels_chunk`, which a faster kernel can replace and be compared against.

Uncertainty (``uncertainty=True``) propagates the cards' parameter covariance by
the delta method through the ansatz's analytic Jacobian:

* ``LAeq_std``: ``sqrt(g^T C g)`` with ``g = sum_i w_i 10^(L_i/10) dL_i/dp / sum_i
  w_i 10^(L_i/10)`` (energy-weighted mean Jacobian; ``w_i`` trapezoid weights);
  the same for ``SEL``, which differs from LAeq by a constant;
* ``LAmax_std``: ``sqrt(J^T C J)`` with ``J = dL/dp`` at the instant of the maximum;
* ``LAmax_p95``, ``LAeq_p95``: ``L - 1.645 std``, the level that the true level
  exceeds with 95 % probability (one-sided, normal approximation of the linearised
  model).  Its contour bounds the area where the level is reached with 95 % confidence.

Parameters of different cards are independent (block-diagonal covariance); a card
that serves several phases is one block.

Examples
--------
>>> import numpy as np
>>> _trapezoid_weights(np.array([0.0, 1.0, 3.0]))
array([0.5, 1.5, 1. ])
"""

from __future__ import annotations

import logging
import math
import os
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from gisnoise.errors import Cancelled, CardError, GisnoiseError, InputError, TrajectoryError
from gisnoise.flight import Trajectory
from gisnoise.geo import WGS84, GridSpec, LocalFrame, apply_affine, emission_angles, resample_dem, transformer
from gisnoise.model import ModelCard
from gisnoise.model import cards as _cards

__all__ = [
    "CardSet",
    "MapResult",
    "METRICS",
    "Z95",
    "evaluate_grid",
    "snapshot_name",
    "threshold_name",
]

log = logging.getLogger(__name__)

METRICS = ("LAmax", "LAeq", "SEL")
"""Metrics that ``metrics=`` may name; time above and snapshot are asked for by value."""

Z95 = 1.6448536269514722
"""One-sided 95 % quantile of the standard normal distribution."""

DEFAULT_BLOCK = 1 << 18
"""Default cell-instants per block (about 2 MB per float64 temporary)."""

_BASE_INPUTS = ("d", "phi", "theta", "p_el")


# --------------------------------------------------------------------------- cards per phase


class CardSet:
    """Model cards by flight phase.

    Each card serves its ``phase`` and the extra ``phases`` it lists.  A card's own
    ``phase`` takes precedence over another card's extra phases; two cards with the
    same own phase, or two cards listing the same extra phase (and no card having it
    as its own), are ambiguous and refused.

    Parameters
    ----------
    cards : iterable of ModelCard or path
        Cards, or card files to load.

    Examples
    --------
    >>> from gisnoise.model.cards import ModelCard
    >>> p = {"p1": 13.4, "p2": 0.18, "p3": -0.28, "p4": -0.37, "p5": 1.05, "p6": 0.94, "p7": 40.4}
    >>> h = ModelCard(id="h", vehicle="v", phase="horizontal", ansatz="paper", parameters=p,
    ...               reference_power_w=1500.0, phases=("transition",))
    >>> CardSet([h]).card_for("transition").id
    'h'
    """

    def __init__(self, cards: Iterable[ModelCard | str | os.PathLike[str]] | ModelCard) -> None:
        if isinstance(cards, ModelCard):
            cards = [cards]
        loaded: list[ModelCard] = []
        for c in cards:
            loaded.append(c if isinstance(c, ModelCard) else _cards.load(c))
        if not loaded:
            raise CardError("at least one model card is needed", field="card")
        uniq: list[ModelCard] = []
        for c in loaded:
            if not any(c is u for u in uniq):
                uniq.append(c)
        self.cards: tuple[ModelCard, ...] = tuple(uniq)
        own: dict[str, int] = {}
        extra: dict[str, list[int]] = {}
        for i, c in enumerate(self.cards):
            if c.phase in own:
                raise CardError(f"cards {self.cards[own[c.phase]].id!r} and {c.id!r} both serve phase "
                                f"{c.phase!r}; give one card per phase", field="card")
            own[c.phase] = i
            for ph in c.served_phases[1:]:
                extra.setdefault(ph, []).append(i)
        self._index: dict[str, int] = dict(own)
        for ph, idx in extra.items():
            if ph in own:
                continue
            if len(idx) > 1:
                ids = ", ".join(repr(self.cards[i].id) for i in idx)
                raise CardError(f"cards {ids} all serve phase {ph!r}; give one card per phase", field="card")
            self._index[ph] = idx[0]

    def __len__(self) -> int:
        return len(self.cards)

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.cards)

    @property
    def phases(self) -> dict[str, str]:
        """Phase -> id of the card serving it."""
        return {ph: self.cards[i].id for ph, i in sorted(self._index.items())}

    def card_for(self, phase: str) -> ModelCard:
        """The card serving ``phase``; :class:`~gisnoise.errors.CardError` if none does."""
        try:
            return self.cards[self._index[phase]]
        except KeyError:
            raise CardError(f"no model card serves phase {phase!r} (cards serve "
                            f"{', '.join(self.phases) or 'nothing'})", field="phase") from None

    def assign(self, phase: Any, t: Any = None, *, source: str = "trajectory") -> np.ndarray:
        """Index into :attr:`cards` of every sample's card.

        Raises :class:`~gisnoise.errors.CardError` naming the first unserved phase and
        the range of samples (and times, when ``t`` is given) that have it.
        """
        phase = np.asarray(phase).astype(str)
        out = np.empty(phase.shape, dtype=np.intp)
        for ph in map(str, np.unique(phase)):
            m = phase == ph
            if ph not in self._index:
                idx = np.flatnonzero(m)
                i0, i1 = int(idx[0]), int(idx[-1])
                when = ""
                if t is not None:
                    tt = np.asarray(t, dtype=float)
                    when = f", t = {tt[i0]:g}-{tt[i1]:g} s"
                raise CardError(
                    f"{source}: no model card serves phase {ph!r} ({idx.size} samples, samples {i0}-{i1}{when}); "
                    f"cards serve {', '.join(self.phases)}; add a card whose phase or phases include {ph!r}",
                    field="phase")
            out[m] = self._index[ph]
        return out


# --------------------------------------------------------------------------- result


@dataclass(frozen=True, eq=False)
class MapResult:
    """Noise metrics on a grid.

    Attributes
    ----------
    bands : dict of str -> ndarray
        Metric name -> array of shape ``grid.shape`` (row 0 north), float64; NaN where
        no value (receiver outside the DEM).
    grid : GridSpec
        The receivers.
    metadata : dict
        What was computed and how (``units`` per band, period, heights, cards, ...).
    """

    bands: dict[str, np.ndarray]
    grid: GridSpec
    metadata: dict[str, Any] = field(default_factory=dict)

    def band(self, name: str) -> np.ndarray:
        """One band by name; :class:`~gisnoise.errors.InputError` lists the known ones."""
        try:
            return self.bands[name]
        except KeyError:
            raise InputError(f"no band {name!r}; bands: {', '.join(self.bands)}", field="metric") from None

    @property
    def units(self) -> dict[str, str]:
        return dict(self.metadata.get("units", {}))

    def level_bands(self) -> list[str]:
        """Bands holding levels in dB(A) (the ones to contour)."""
        u = self.units
        return [b for b in self.bands if u.get(b) == "dB(A)"]

    def value_at(self, name: str, lon: Any, lat: Any) -> np.ndarray:
        """Band value of the cells containing ``lon, lat`` (deg); NaN outside the grid."""
        x, y = self.grid.from_wgs84(lon, lat)
        col, row = apply_affine(~self.grid.transform, x, y)
        col = np.floor(np.asarray(col)).astype(int)
        row = np.floor(np.asarray(row)).astype(int)
        a = self.band(name)
        inside = (row >= 0) & (row < self.grid.height) & (col >= 0) & (col < self.grid.width)
        out = np.full(np.shape(row), np.nan)
        out[inside] = a[row[inside], col[inside]]
        return out


# --------------------------------------------------------------------------- helpers


_local = threading.local()


def _local_frame(lat0: float, lon0: float, h0: float) -> LocalFrame:
    """A cached :class:`LocalFrame` (per thread; building its pyproj pipelines takes about a millisecond)."""
    cache = getattr(_local, "frames", None)
    if cache is None:
        cache = _local.frames = {}
    key = (float(lat0), float(lon0), float(h0))
    fr = cache.get(key)
    if fr is None:
        if len(cache) > 32:
            cache.clear()
        fr = cache[key] = LocalFrame(*key)
    return fr


def _trapezoid_weights(t: np.ndarray) -> np.ndarray:
    """Weights ``w`` with ``sum(w * f) == trapezoid(f, t)`` (s)."""
    t = np.asarray(t, dtype=float)
    w = np.zeros_like(t)
    if t.size < 2:
        return w
    dt = np.diff(t)
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    return w


def threshold_name(level_db: float) -> str:
    """Band name of the time above ``level_db``: ``TA55``, ``TA57.5``."""
    return f"TA{level_db:g}"


def snapshot_name(t_s: float) -> str:
    """Band name of the snapshot at ``t_s``: ``LA@120s``."""
    return f"LA@{t_s:g}s"


def _time_above(L: np.ndarray, dt: np.ndarray, thr: float) -> np.ndarray:
    """Time (s) with ``L > thr``, ``L`` linear between columns; ``L (nc, m)``, ``dt (m-1,)``."""
    a = L[:, :-1] - thr
    b = L[:, 1:] - thr
    up_a = a >= 0
    up_b = b >= 0
    mixed = up_a != up_b
    denom = np.where(mixed, np.abs(a - b), 1.0)
    frac = np.where(up_a & up_b, 1.0, np.where(mixed, np.maximum(a, b) / denom, 0.0))
    return frac @ dt


def _as_float(v: Any, name: str, *, minimum: float | None = None, strict: bool = False) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {v!r}", field=name) from None
    if not math.isfinite(f):
        raise InputError(f"{name} must be finite, got {v!r}", field=name)
    if minimum is not None and (f < minimum or (strict and f == minimum)):
        raise InputError(f"{name} must be {'>' if strict else '>='} {minimum:g}, got {v!r}", field=name)
    return f


def _check_flight_and_grid(traj: Any, grid: Any) -> None:
    """Refuse a ``traj`` that is not a :class:`Trajectory` or a ``grid`` that is not a :class:`GridSpec`."""
    if not isinstance(traj, Trajectory):
        raise TrajectoryError(f"trajectory must be a Trajectory, got {type(traj).__name__}", field="trajectory")
    if not isinstance(grid, GridSpec):
        raise InputError(f"grid must be a GridSpec, got {type(grid).__name__}", field="grid")


def _requested(cards: Any, metrics: Sequence[str] | str, threshold_db: Any,
               snapshot_t: Any) -> tuple[CardSet, list[str], list[float]]:
    """The card set, the metrics (deduplicated, checked) and the time-above levels (dB(A)) asked for."""
    cardset = cards if isinstance(cards, CardSet) else CardSet(cards)
    if isinstance(metrics, str):
        metrics = [m.strip() for m in metrics.split(",") if m.strip()]
    metrics = list(dict.fromkeys(metrics))
    bad = [m for m in metrics if m not in METRICS]
    if bad:
        raise InputError(f"metrics: unknown metric {bad[0]!r}; known: {', '.join(METRICS)}", field="metrics")
    thresholds: list[float] = []
    if threshold_db is not None:
        seq = [threshold_db] if np.ndim(threshold_db) == 0 else list(threshold_db)
        thresholds = [_as_float(v, "threshold_db") for v in seq]
    if not metrics and not thresholds and snapshot_t is None:
        raise InputError("metrics: nothing to compute (no metric, threshold or snapshot)", field="metrics")
    return cardset, metrics, thresholds


def _substeps_and_min_distance(substeps: Any, min_distance_m: Any) -> tuple[int, float]:
    """Checked ``substeps`` (integer >= 1) and near-field limit (m, > 0)."""
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise InputError(f"substeps must be an integer >= 1, got {substeps!r}", field="substeps")
    return int(substeps), _as_float(min_distance_m, "min_distance_m", minimum=0.0, strict=True)


def _period_and_snapshot(traj: Trajectory, metrics: Sequence[str], thresholds: Sequence[float], period_s: Any,
                         snapshot_t: Any) -> tuple[bool, float | None, float | None]:
    """Whether time integrals are asked for, the LAeq period (s) and the snapshot time (s)."""
    integral = bool({"LAeq", "SEL"} & set(metrics)) or bool(thresholds)
    if integral and len(traj) < 2:
        raise TrajectoryError(f"{traj.source}: LAeq, SEL and time above need at least two samples, got "
                              f"{len(traj)}", field="t")
    duration = traj.duration_s
    period = None
    if "LAeq" in metrics:
        period = duration if period_s is None else _as_float(period_s, "period_s", minimum=0.0, strict=True)
        if period < duration * (1.0 - 1e-12):
            raise InputError(f"period_s ({period:g} s) must cover the trajectory's duration ({duration:g} s)",
                             field="period_s")
    snap = None
    if snapshot_t is not None:
        snap = _as_float(snapshot_t, "snapshot_t")
        if not traj.t[0] <= snap <= traj.t[-1]:
            raise InputError(f"snapshot_t={snap:g} s lies outside the trajectory "
                             f"({traj.t[0]:g}-{traj.t[-1]:g} s)", field="snapshot_t")
    return integral, period, snap


def _eval_states(traj: Trajectory, substeps: int) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Evaluation instants, the state there, and the index of the sample each starts from."""
    if substeps == 1 or len(traj) < 2:
        state = {k: getattr(traj, k) for k in ("lat", "lon", "h", "roll", "pitch", "yaw", "power_w")}
        for k in ("rpm", "airspeed_m_s"):
            if getattr(traj, k) is not None:
                state[k] = getattr(traj, k)
        return traj.t, state, np.arange(len(traj))
    t = traj.t
    frac = np.arange(substeps) / substeps
    te = (t[:-1, None] + np.diff(t)[:, None] * frac[None, :]).ravel()
    te = np.append(te, t[-1])
    src = np.append(np.repeat(np.arange(len(t) - 1), substeps), len(t) - 1)
    state = traj.interpolate(te)
    state.pop("phase", None)
    return te, state, src


class _SampleExtras:
    """Per-instant inputs beyond ``d, phi, theta, p_el`` that extended ansatzes read.

    Names and units as :meth:`gisnoise.measure.samples.Samples.inputs`: ``bank`` (rad),
    ``speed`` (ground speed, m/s), ``rpm`` (1/min), ``airspeed`` (m/s), ``roll``,
    ``pitch``, ``yaw`` (deg), ``t_e`` (s), ``uav_enu`` and ``vel_enu`` (m, m/s,
    trailing axis 3), ``mic_enu`` (receiver, m, trailing axis 3), ``meta`` (dict).
    Per-instant arrays are passed with shape ``(1, n)`` (vectors ``(1, n, 3)``) and
    receiver arrays ``(nc, 1, 3)`` so they broadcast against ``d``.
    """

    def __init__(self, t: np.ndarray, state: Mapping[str, np.ndarray], src_enu: np.ndarray) -> None:
        self.t = t
        self.state = state
        self.src = src_enu
        self._vel: np.ndarray | None = None

    def vel(self) -> np.ndarray:
        if self._vel is None:
            if self.t.size > 1:
                self._vel = np.gradient(self.src, self.t, axis=0)
            else:
                self._vel = np.zeros_like(self.src)
        return self._vel

    def get(self, name: str) -> np.ndarray | None:
        s = self.state
        if name == "bank":
            return np.radians(s["roll"])
        if name in ("roll", "pitch", "yaw"):
            return np.asarray(s[name])
        if name == "speed":
            return np.linalg.norm(self.vel(), axis=1)
        if name == "vel_enu":
            return self.vel()
        if name == "uav_enu":
            return self.src
        if name in ("t_e", "t"):
            return self.t
        if name == "rpm":
            return s.get("rpm")
        if name == "airspeed":
            return s.get("airspeed_m_s")
        return None


def _needed_extras(cards: Sequence[ModelCard], extras: _SampleExtras, used: Iterable[int]) -> tuple[dict, list]:
    sample: dict[str, np.ndarray] = {}
    receiver: list[str] = []
    for k in used:
        c = cards[k]
        for name in c.model.inputs:
            if name in _BASE_INPUTS or name in sample or name in receiver:
                continue
            if name == "mic_enu":
                receiver.append(name)
                continue
            if name == "meta":
                continue
            v = extras.get(name)
            if v is None:
                raise InputError(f"card {c.id!r} (ansatz {c.ansatz!r}) needs input {name!r}, "
                                 "which the trajectory does not provide", field=name)
            sample[name] = np.asarray(v, dtype=float)
    return sample, receiver


# --------------------------------------------------------------------------- the per-block kernel


def _levels_chunk(
    rcv: np.ndarray,
    src: np.ndarray,
    att: np.ndarray,
    power_w: np.ndarray,
    card_idx: np.ndarray,
    cards: Sequence[ModelCard],
    *,
    background: bool = False,
    sample_extras: Mapping[str, np.ndarray] | None = None,
    receiver_extras: Sequence[str] = (),
    jac_offsets: Sequence[int] | None = None,
    n_jac: int = 0,
    min_distance_m: float = 1.0,
    receiver_agl_m: float = 1.5,
    meta: Mapping[str, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Levels of ``nc`` receivers x ``ns`` instants: the evaluator's physics, pure.

    Parameters
    ----------
    rcv : ndarray, shape (nc, 3)
        Receiver positions, local ENU, m.
    src : ndarray, shape (ns, 3)
        UAV positions, same frame, m.
    att : ndarray, shape (ns, 3)
        UAV yaw, pitch, roll, rad (Z-Y-X).
    power_w : ndarray, shape (ns,)
        Electric power, W.
    card_idx : ndarray of int, shape (ns,)
        Index into ``cards`` of each instant's card.
    cards : sequence of ModelCard
    background : bool
        Add each card's background level (Eq. 8).
    sample_extras : dict, optional
        Further per-instant inputs (arrays with leading axis ``ns``).
    receiver_extras : sequence of str
        Names of receiver inputs to pass (only ``mic_enu``: ``rcv``).
    jac_offsets : sequence of int, optional
        When given, also return ``J (nc, ns, n_jac)`` with card ``k``'s
        ``dL/dp`` in columns ``jac_offsets[k]:jac_offsets[k] + n_params``, zero elsewhere.
    n_jac : int
        Total Jacobian columns.
    min_distance_m : float
        Distances are clamped to at least this (the point-source model's near-field limit), m.
    receiver_agl_m : float
        Receiver height above ground (input ``mic_agl`` of extensions such as ground reflection), m.
    meta : dict, optional
        Facts for extensions (``speed_of_sound_m_s``), passed as input ``meta``.

    Returns
    -------
    L : ndarray, shape (nc, ns)
        Level, dB(A).
    J : ndarray, shape (nc, ns, n_jac), or None
    """
    de = rcv[:, 0, None] - src[None, :, 0]
    dn = rcv[:, 1, None] - src[None, :, 1]
    du = rcv[:, 2, None] - src[None, :, 2]
    d, phi, theta = emission_angles(de, dn, du, att[:, 0], att[:, 1], att[:, 2])
    del de, dn, du
    np.maximum(d, min_distance_m, out=d)
    nc, ns = d.shape
    L = np.empty((nc, ns))
    J = np.zeros((nc, ns, n_jac)) if jac_offsets is not None else None
    sample_extras = sample_extras or {}
    ks = np.unique(card_idx)
    for k in ks:
        card = cards[int(k)]
        sel: Any = slice(None) if ks.size == 1 else np.flatnonzero(card_idx == k)
        x = card.inputs(d[:, sel], phi[:, sel], theta[:, sel], power_w[None, sel])
        for name, v in sample_extras.items():
            x[name] = v[None, sel]
        for name in receiver_extras:
            x[name] = rcv[:, None, :]
        x["mic_agl"] = receiver_agl_m
        x["meta"] = dict(meta or {})
        try:
            if J is None:
                L[:, sel] = card.level(x, background=background)
                continue
            lv, jk = card.model.level_and_jacobian(card.p, x, background=background,
                                                   d_ref=card.reference_distance_m)
        except (ValueError, IndexError, KeyError, TypeError) as exc:
            if isinstance(exc, GisnoiseError):
                raise
            raise InputError(f"card {card.id!r}: ansatz {card.ansatz!r} cannot be evaluated on a map "
                             f"({type(exc).__name__}: {exc})", field="ansatz") from None
        assert jac_offsets is not None
        L[:, sel] = lv
        o = jac_offsets[int(k)]
        if ks.size == 1:
            J[:, :, o:o + jk.shape[-1]] = jk
        else:
            J[:, sel, o:o + jk.shape[-1]] = jk
    return L, J


# --------------------------------------------------------------------------- the evaluator


def evaluate_grid(
    traj: Trajectory,
    cards: CardSet | Iterable[ModelCard] | ModelCard,
    grid: GridSpec,
    *,
    metrics: Sequence[str] = METRICS,
    receiver_height: float = 1.5,
    dem: Any = None,
    ground_h: float | None = None,
    dem_offset_m: float = 0.0,
    period_s: float | None = None,
    threshold_db: float | Sequence[float] | None = None,
    snapshot_t: float | None = None,
    background: bool = False,
    substeps: int = 1,
    uncertainty: bool = False,
    chunk_cells: int | None = None,
    block_size: int = DEFAULT_BLOCK,
    min_distance_m: float = 1.0,
    temperature_c: float = 15.0,
    kernel: Callable[..., tuple[np.ndarray, np.ndarray | None]] | None = None,
    progress: Callable[[float], Any] | None = None,
    cancel: Callable[[], bool] | None = None,
    engine: str = "numpy",
    floor_db: float | None = None,
) -> MapResult:
    """Noise metrics of a trajectory on a grid of receivers (see the module docstring).

    Parameters
    ----------
    traj : Trajectory
        The flight.  Each sample's phase picks its card.
    cards : CardSet, sequence of ModelCard, or ModelCard
        Cards serving the trajectory's phases.
    grid : GridSpec
        Receivers at the cell centres.
    metrics : sequence of str
        Any of ``LAmax``, ``LAeq``, ``SEL``.
    receiver_height : float
        Receiver height above the ground, m.
    dem : path, Dem or ndarray, optional
        Ground heights: a DEM file or :class:`~gisnoise.geo.raster.Dem` (resampled to the
        grid, bilinear) or an array of shape ``grid.shape`` (m).  Heights are taken in the
        trajectory's vertical datum (ellipsoidal) after adding ``dem_offset_m``.
    ground_h : float, optional
        Flat ground's ellipsoidal height when there is no DEM, m.  Default: the
        trajectory's lowest height (a route that takes off or lands).
    dem_offset_m : float
        Added to DEM heights (e.g. the geoid undulation for an orthometric DEM), m.
    period_s : float, optional
        LAeq period, s, at least the trajectory's duration; default the duration.
    threshold_db : float or sequence of float, optional
        Levels for time-above bands ``TA<level>`` (s), dB(A).
    snapshot_t : float, optional
        Time of a snapshot band ``LA@<t>s``, s, within the trajectory.
    background : bool
        Include the cards' background level (Eq. 8); default the UAV alone.
    substeps : int
        Sub-intervals per sample interval for the time integration (>= 1).
    uncertainty : bool
        Add ``LAmax_std``, ``LAeq_std``, ``LAmax_p95``, ``LAeq_p95`` from the cards' covariance.
    chunk_cells : int, optional
        Receivers per block (default from ``block_size``).
    block_size : int
        Cell-instants per block; bounds the memory (about 20 float64 arrays of this size).
    min_distance_m : float
        Near-field limit: distances below it are clamped, m.
    temperature_c : float
        Air temperature, deg C, for extended ansatzes that need the speed of sound
        (Doppler, ground reflection): ``c = 331.3 sqrt(1 + T / 273.15)`` m/s.  Default
        15 deg C (ISA sea level).  The paper's ansatz does not use it.
    kernel : callable, optional
        Replacement for :func:`_levels_chunk` with the same signature and results (a
        compiled kernel); default the NumPy reference.
    progress : callable, optional
        Called with the fraction done (0-1) after every block.
    cancel : callable, optional
        Polled between blocks; returning true raises :class:`~gisnoise.errors.Cancelled`.
    engine : {"numpy", "fast"}
        ``"fast"``: the numba kernel of :mod:`gisnoise.maps.fastkernel` (same bands within
        0.01 dB; ansatzes ``paper`` and ``paper-offset``; no uncertainty).
    floor_db : float, optional
        With ``engine="fast"``: audibility floor, dB(A); cells certainly below it at every
        instant are skipped (NaN).

    Returns
    -------
    MapResult
    """
    if engine != "numpy":
        from gisnoise.maps.fastkernel import evaluate_grid_fast

        return evaluate_grid_fast(
            traj, cards, grid, engine=engine, metrics=metrics, receiver_height=receiver_height, dem=dem,
            ground_h=ground_h, dem_offset_m=dem_offset_m, period_s=period_s, threshold_db=threshold_db,
            snapshot_t=snapshot_t, background=background, substeps=substeps, uncertainty=uncertainty,
            chunk_cells=chunk_cells, min_distance_m=min_distance_m, kernel=kernel, progress=progress,
            cancel=cancel, floor_db=floor_db)
    if floor_db is not None:
        raise InputError("floor_db: the audibility floor is an option of engine='fast'", field="floor_db")
    _check_flight_and_grid(traj, grid)
    cardset, metrics, thresholds = _requested(cards, metrics, threshold_db, snapshot_t)
    hr = _as_float(receiver_height, "receiver_height")
    substeps, min_d = _substeps_and_min_distance(substeps, min_distance_m)
    temp = _as_float(temperature_c, "temperature_c", minimum=-273.15, strict=True)
    c_sound = 331.3 * math.sqrt(1.0 + temp / 273.15)
    block = int(block_size)
    if block < 1:
        raise InputError(f"block_size must be >= 1, got {block_size!r}", field="block_size")

    integral, period, snap = _period_and_snapshot(traj, metrics, thresholds, period_s, snapshot_t)

    card_idx_samples = cardset.assign(traj.phase, traj.t, source=traj.source)
    used = sorted(set(card_idx_samples.tolist()))
    t_eval, state, src_sample = _eval_states(traj, substeps)
    card_idx = card_idx_samples[src_sample]
    ns = t_eval.size
    weights = _trapezoid_weights(t_eval)

    # jacobian layout: one block of columns per card (cards are independent)
    want_jac = bool(uncertainty) and bool({"LAmax", "LAeq", "SEL"} & set(metrics))
    offsets: list[int] = []
    n_jac = 0
    cov = np.zeros((0, 0))
    if uncertainty:
        for c in cardset.cards:
            offsets.append(n_jac)
            n_jac += c.model.n_params
        cov = np.zeros((n_jac, n_jac))
        for k in used:
            c = cardset.cards[k]
            if c.cov is None:
                raise CardError(f"card {c.id!r} has no covariance; uncertainty needs cards with a parameter "
                                "covariance (fitted cards)", field="covariance")
            o = offsets[k]
            cov[o:o + c.model.n_params, o:o + c.model.n_params] = c.cov

    # ground and frame
    ground_desc: dict[str, Any]
    if dem is not None:
        ground = _dem_on_grid(dem, grid) + _as_float(dem_offset_m, "dem_offset_m")
        finite = np.isfinite(ground)
        if not finite.any():
            raise InputError("dem: the DEM does not cover the grid", field="dem")
        if not finite.all():
            log.warning("dem: %d of %d receivers lie outside the DEM or on nodata; they get nodata",
                        int((~finite).sum()), finite.size)
        h0 = float(np.nanmean(ground))
        ground_desc = {"ground": "dem", "dem_offset_m": float(dem_offset_m)}
    else:
        if ground_h is None:
            g = float(np.min(traj.h))
            i_low = int(np.argmin(traj.h))
            if traj.phase[i_low] == "horizontal":
                log.warning("ground height taken as the trajectory's lowest point (%.1f m) although it is in "
                            "horizontal flight there; state the ground height", g)
            ground_desc = {"ground": "flat", "ground_h_m": g, "ground_h_source": "lowest trajectory point"}
        else:
            g = _as_float(ground_h, "ground_h")
            ground_desc = {"ground": "flat", "ground_h_m": g, "ground_h_source": "given"}
        ground = None
        h0 = g
    lon_c, lat_c = grid.centre_wgs84()
    frame = _local_frame(lat_c, lon_c, h0)
    src_enu = np.stack(frame.to_enu(state["lat"], state["lon"], state["h"]), axis=-1)
    att = np.stack([np.radians(state["yaw"]), np.radians(state["pitch"]), np.radians(state["roll"])], axis=-1)
    power = np.asarray(state["power_w"], dtype=float)
    extras = _SampleExtras(t_eval, state, src_enu)
    sample_extras, receiver_extras = _needed_extras(cardset.cards, extras, used)

    snap_args = None
    if snap is not None:
        s_state = traj.interpolate(np.array([snap]))
        s_idx = cardset.assign(s_state["phase"], [snap], source=traj.source)
        s_src = np.stack(frame.to_enu(s_state["lat"], s_state["lon"], s_state["h"]), axis=-1)
        s_att = np.stack([np.radians(s_state["yaw"]), np.radians(s_state["pitch"]),
                          np.radians(s_state["roll"])], axis=-1)
        s_extras = _SampleExtras(np.array([snap]), s_state, s_src)
        s_extras._vel = extras.vel()[[int(np.clip(np.searchsorted(t_eval, snap), 0, ns - 1))]]
        s_sample_extras, _ = _needed_extras(cardset.cards, s_extras, sorted(set(s_idx.tolist())))
        snap_args = (s_src, s_att, np.asarray(s_state["power_w"], dtype=float), s_idx, s_sample_extras)

    # blocks
    per_elem = 1 + (n_jac if want_jac else 0)
    budget = max(1, block // per_elem)
    if chunk_cells is not None:
        if isinstance(chunk_cells, bool) or int(chunk_cells) < 1:
            raise InputError(f"chunk_cells must be >= 1, got {chunk_cells!r}", field="chunk_cells")
        nc_chunk = int(chunk_cells)
        ns_chunk = max(1, min(ns, budget // nc_chunk))
    else:
        ns_chunk = max(2, min(ns, budget // 64))
        nc_chunk = max(1, budget // ns_chunk)
    n_cells = grid.n_cells
    nc_chunk = min(nc_chunk, n_cells)
    total_work = float(n_cells) * (ns + (1 if snap is not None else 0))

    out = {name: np.full(n_cells, np.nan) for name in _band_order(metrics, thresholds, snap, uncertainty)}
    levels_fn = _levels_chunk if kernel is None else kernel
    to_wgs = transformer(grid.crs, WGS84)
    ground_flat = None if ground is None else ground.ravel()
    done = 0.0
    kw = dict(background=background, receiver_extras=receiver_extras, min_distance_m=min_d, receiver_agl_m=hr,
              meta={"speed_of_sound_m_s": c_sound, "temperature_c": temp})
    for c0 in range(0, n_cells, nc_chunk):
        c1 = min(c0 + nc_chunk, n_cells)
        nc = c1 - c0
        x, y = grid.flat_centres(c0, c1)
        lon, lat = to_wgs.transform(x, y)
        hgt = (np.full(nc, h0) if ground_flat is None else ground_flat[c0:c1]) + hr
        valid = np.isfinite(hgt)
        hgt = np.where(valid, hgt, h0 + hr)
        rcv = np.stack(frame.to_enu(lat, lon, hgt), axis=-1)

        lmax = np.full(nc, -np.inf)
        jmax = np.zeros((nc, n_jac)) if want_jac else None
        energy = np.zeros(nc)
        gsum = np.zeros((nc, n_jac)) if want_jac else None
        tabove = [np.zeros(nc) for _ in thresholds]
        for s0 in range(0, ns, ns_chunk):
            if cancel is not None and cancel():
                raise Cancelled("cancelled", field="cancel")
            s1 = min(s0 + ns_chunk, ns)
            e1 = min(s1 + 1, ns)  # one more instant for the intervals
            sl = slice(s0, e1)
            L, J = levels_fn(
                rcv, src_enu[sl], att[sl], power[sl], card_idx[sl], cardset.cards,
                sample_extras={k: v[sl] for k, v in sample_extras.items()},
                jac_offsets=offsets if want_jac else None, n_jac=n_jac, **kw)
            m = s1 - s0
            Lm = L[:, :m]
            if "LAmax" in metrics or want_jac:
                am = np.argmax(Lm, axis=1)
                mx = Lm[np.arange(nc), am]
                upd = mx > lmax
                lmax[upd] = mx[upd]
                if jmax is not None and J is not None:
                    jmax[upd] = J[np.flatnonzero(upd), am[upd], :]
            if integral:
                e = np.power(10.0, Lm / 10.0)
                ew = e * weights[s0:s1]
                energy += ew.sum(axis=1)
                if gsum is not None and J is not None:
                    gsum += np.einsum("cs,csp->cp", ew, J[:, :m, :])
                if thresholds and L.shape[1] > 1:
                    dt = np.diff(t_eval[s0:e1])
                    for i, thr in enumerate(thresholds):
                        tabove[i] += _time_above(L, dt, thr)
            done += nc * m
            if progress is not None:
                progress(min(done / total_work, 1.0))

        sl_c = slice(c0, c1)
        if "LAmax" in metrics:
            out["LAmax"][sl_c] = lmax
        if "SEL" in metrics:
            out["SEL"][sl_c] = 10.0 * np.log10(energy)
        if "LAeq" in metrics:
            assert period is not None
            out["LAeq"][sl_c] = 10.0 * np.log10(energy / period)
        for i, thr in enumerate(thresholds):
            out[threshold_name(thr)][sl_c] = tabove[i]
        if snap_args is not None:
            s_src, s_att, s_pow, s_idx, s_sx = snap_args
            Ls, _ = levels_fn(rcv, s_src, s_att, s_pow, s_idx, cardset.cards, sample_extras=s_sx, **kw)
            out[snapshot_name(snap)][sl_c] = Ls[:, 0]  # type: ignore[arg-type]
            done += nc
            if progress is not None:
                progress(min(done / total_work, 1.0))
        if uncertainty:
            if "LAmax" in metrics and jmax is not None:
                s = np.sqrt(np.maximum(np.einsum("cp,pq,cq->c", jmax, cov, jmax), 0.0))
                out["LAmax_std"][sl_c] = s
                out["LAmax_p95"][sl_c] = lmax - Z95 * s
            if ("LAeq" in metrics or "SEL" in metrics) and gsum is not None:
                g = gsum / energy[:, None]
                s = np.sqrt(np.maximum(np.einsum("cp,pq,cq->c", g, cov, g), 0.0))
                if "LAeq" in metrics:
                    out["LAeq_std"][sl_c] = s
                    out["LAeq_p95"][sl_c] = out["LAeq"][sl_c] - Z95 * s
                if "SEL" in metrics:
                    out["SEL_std"][sl_c] = s
        if not valid.all():
            for a in out.values():
                a[sl_c][~valid] = np.nan

    bands = {k: v.reshape(grid.shape) for k, v in out.items()}
    meta = _map_metadata(grid, bands, traj, ns, substeps, period, hr, ground_desc, background, min_d, thresholds,
                         snap, cardset, used, speed_of_sound_m_s=c_sound)
    if uncertainty:
        meta["uncertainty"] = ("delta method through the ansatz Jacobian with the cards' covariance; "
                               "*_std standard deviation (dB); *_p95 = level - 1.645 std, the level exceeded "
                               "with 95 % confidence (one-sided, normal approximation)")
    return MapResult(bands=bands, grid=grid, metadata=meta)


def _map_metadata(grid: GridSpec, bands: Mapping[str, np.ndarray], traj: Trajectory, n_instants: int,
                  substeps: int, period: float | None, receiver_height_m: float, ground_desc: Mapping[str, Any],
                  background: bool, min_d: float, thresholds: Sequence[float], snap: float | None, cardset: CardSet,
                  used: Iterable[int], *, speed_of_sound_m_s: float | None = None) -> dict[str, Any]:
    """The metadata both engines give a :class:`MapResult` (``speed_of_sound_m_s`` only when given)."""
    used = set(used)
    meta: dict[str, Any] = {
        "grid": grid.to_dict(),
        "units": {k: _unit(k) for k in bands},
        "trajectory": {"source": traj.source, "samples": len(traj), "t_start_s": float(traj.t[0]),
                       "t_end_s": float(traj.t[-1]), "duration_s": traj.duration_s},
        "evaluation_instants": int(n_instants),
        "substeps": substeps,
        "time_integration": "trapezoid over the evaluation instants",
        "period_s": period,
        "receiver_height_m": receiver_height_m,
        **ground_desc,
        "background_included": bool(background),
        "min_distance_m": min_d,
    }
    if speed_of_sound_m_s is not None:
        meta["speed_of_sound_m_s"] = speed_of_sound_m_s
    meta.update({
        "thresholds_db": thresholds,
        "snapshot_t_s": snap,
        "cards": {c.id: {"phase": c.phase, "phases": list(c.served_phases), "ansatz": c.ansatz}
                  for k, c in enumerate(cardset.cards) if k in used},
        "phases": cardset.phases,
    })
    return meta


def _band_order(metrics: Sequence[str], thresholds: Sequence[float], snap: float | None,
                uncertainty: bool) -> list[str]:
    names = [m for m in METRICS if m in metrics]
    names += [threshold_name(t) for t in thresholds]
    if snap is not None:
        names.append(snapshot_name(snap))
    if uncertainty:
        if "LAmax" in metrics:
            names += ["LAmax_std", "LAmax_p95"]
        if "LAeq" in metrics:
            names += ["LAeq_std", "LAeq_p95"]
        if "SEL" in metrics:
            names += ["SEL_std"]
    return list(dict.fromkeys(names))


def _unit(name: str) -> str:
    if name.startswith("TA"):
        return "s"
    if name.endswith("_std"):
        return "dB"
    return "dB(A)"


def _dem_on_grid(dem: Any, grid: GridSpec) -> np.ndarray:
    from gisnoise.geo import Dem, read_dem

    if isinstance(dem, np.ndarray):
        a = np.asarray(dem, dtype=float)
        if a.shape != grid.shape:
            raise InputError(f"dem: array of shape {a.shape} does not match the grid {grid.shape}", field="dem")
        return a
    if not isinstance(dem, Dem):
        dem = read_dem(dem)
    return resample_dem(dem, grid)
