"""What both evaluator engines start from: the checked request and the arrays it needs.

:func:`check_request` checks the trajectory, grid, cards, metrics, levels, substeps,
near-field limit, period and snapshot time of a call of
:func:`~gisnoise.maps.evaluate.evaluate_grid` (:class:`MapOptions`, as given).  Both the
NumPy engine (:mod:`gisnoise.maps.reference`) and the numba engine
(:mod:`gisnoise.maps.fastkernel`) then take from here the evaluation instants and the
state there (:func:`eval_states`, :func:`snapshot_state`), the trapezoid weights, the
ground under the receivers (:func:`ground_on_grid`), the local frame and the result's
band order and metadata, so that both engines read a request the same way.

Examples
--------
>>> import numpy as np
>>> trapezoid_weights(np.array([0.0, 1.0, 3.0]))
array([0.5, 1.5, 1. ])
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.errors import CardError, InputError, TrajectoryError
from gisnoise.flight import Trajectory
from gisnoise.geo import Dem, GridSpec, LocalFrame, read_dem, resample_dem
from gisnoise.limits import check_map_level
from gisnoise.maps._checks import as_float
from gisnoise.maps.cardset import CardSet, as_cardset
from gisnoise.maps.ground import GROUND_GIVEN, ChosenGround, checked_ground
from gisnoise.maps.result import METRICS, band_unit, snapshot_name, threshold_name
from gisnoise.model import ModelCard

__all__ = [
    "Ground",
    "MapOptions",
    "MapRequest",
    "band_order",
    "check_request",
    "dem_nodata_warning",
    "dem_on_grid",
    "eval_states",
    "ground_on_grid",
    "local_frame",
    "map_metadata",
    "require_covariances",
    "snapshot_state",
    "trapezoid_weights",
    "TIE_DB",
    "tie_std",
    "UNCERTAINTY_NOTE",
    "Z95",
]


# --------------------------------------------------------------------------- the request


@dataclass(frozen=True, eq=False)
class MapOptions:
    """The options of :func:`~gisnoise.maps.evaluate.evaluate_grid` as given (documented there).

    Each engine checks the ones it reads and refuses the other engine's own options.
    """

    metrics: Sequence[str] | str
    receiver_height: Any
    dem: Any
    ground_h: Any
    dem_offset_m: Any
    period_s: Any
    threshold_db: Any
    snapshot_t: Any
    background: bool
    substeps: Any
    uncertainty: bool
    chunk_cells: Any
    block_size: Any
    min_distance_m: Any
    temperature_c: Any
    kernel: Callable[..., tuple[np.ndarray, np.ndarray | None]] | None
    progress: Callable[[float], Any] | None
    cancel: Callable[[], bool] | None
    floor_db: Any
    threads: Any


@dataclass(frozen=True, eq=False)
class MapRequest:
    """A checked request: what to compute for which flight on which receivers.

    Attributes
    ----------
    traj : Trajectory
    grid : GridSpec
    cardset : CardSet
    metrics : list of str
        Metrics asked for, deduplicated, in the order given.
    thresholds : list of float
        Time-above levels, dB(A).
    substeps : int
        Sub-intervals per sample interval (>= 1).
    min_distance_m : float
        Near-field limit, m (> 0).
    integral : bool
        Whether time integrals (LAeq, SEL, time above) are asked for.
    period : float or None
        LAeq period, s (with LAeq).
    snap : float or None
        Snapshot time, s.
    ground : ChosenGround or None
        The flat ground under the receivers by the map's ground rule (:func:`gisnoise.maps.ground.checked_ground`);
        None: the DEM is the ground.
    """

    traj: Trajectory
    grid: GridSpec
    cardset: CardSet
    metrics: list[str]
    thresholds: list[float]
    substeps: int
    min_distance_m: float
    integral: bool
    period: float | None
    snap: float | None
    ground: ChosenGround | None = None


def check_request(traj: Any, cards: Any, grid: Any, opts: MapOptions) -> MapRequest:
    """The checked :class:`MapRequest` of a call; the first wrong input raises, naming its field."""
    check_flight_and_grid(traj, grid)
    cardset, metrics, thresholds = requested(cards, opts.metrics, opts.threshold_db, opts.snapshot_t)
    substeps, min_d = substeps_and_min_distance(opts.substeps, opts.min_distance_m)
    integral, period, snap = period_and_snapshot(traj, metrics, thresholds, opts.period_s, opts.snapshot_t)
    ground = checked_ground([traj], opts.receiver_height, opts.ground_h, opts.dem)  # the ground rule of every map
    return MapRequest(traj, grid, cardset, metrics, thresholds, substeps, min_d, integral, period, snap, ground)


def check_flight_and_grid(traj: Any, grid: Any) -> None:
    """Refuse a ``traj`` that is not a :class:`Trajectory` or a ``grid`` that is not a :class:`GridSpec`."""
    if not isinstance(traj, Trajectory):
        raise TrajectoryError(f"trajectory must be a Trajectory, got {type(traj).__name__}", field="trajectory")
    if not isinstance(grid, GridSpec):
        raise InputError(f"grid must be a GridSpec, got {type(grid).__name__}", field="grid")


def requested(cards: Any, metrics: Sequence[str] | str, threshold_db: Any,
              snapshot_t: Any) -> tuple[CardSet, list[str], list[float]]:
    """The card set, the metrics (deduplicated, checked) and the time-above levels (dB(A)) asked for."""
    cardset = as_cardset(cards)
    if isinstance(metrics, str):
        metrics = [m.strip() for m in metrics.split(",") if m.strip()]
    metrics = list(dict.fromkeys(metrics))
    bad = [m for m in metrics if m not in METRICS]
    if bad:
        raise InputError(f"metrics: unknown metric {bad[0]!r}; known: {', '.join(METRICS)}", field="metrics")
    thresholds: list[float] = []
    if threshold_db is not None:
        seq = [threshold_db] if np.ndim(threshold_db) == 0 else list(threshold_db)
        thresholds = [check_map_level("threshold_db", as_float(v, "threshold_db")) for v in seq]
    if not metrics and not thresholds and snapshot_t is None:
        raise InputError("metrics: nothing to compute (no metric, threshold or snapshot)", field="metrics")
    return cardset, metrics, thresholds


def substeps_and_min_distance(substeps: Any, min_distance_m: Any) -> tuple[int, float]:
    """Checked ``substeps`` (integer >= 1) and near-field limit (m, > 0)."""
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise InputError(f"substeps must be an integer >= 1, got {substeps!r}", field="substeps")
    return int(substeps), as_float(min_distance_m, "min_distance_m", minimum=0.0, strict=True)


def period_and_snapshot(traj: Trajectory, metrics: Sequence[str], thresholds: Sequence[float], period_s: Any,
                        snapshot_t: Any) -> tuple[bool, float | None, float | None]:
    """Whether time integrals are asked for, the LAeq period (s) and the snapshot time (s)."""
    integral = bool({"LAeq", "SEL"} & set(metrics)) or bool(thresholds)  # a trajectory has two samples or more
    duration = traj.duration_s
    period = None
    if "LAeq" in metrics:
        period = duration if period_s is None else as_float(period_s, "period_s", minimum=0.0, strict=True)
        if period < duration * (1.0 - 1e-12):
            raise InputError(f"period_s ({period:g} s) must cover the trajectory's duration ({duration:g} s)",
                             field="period_s")
    snap = None
    if snapshot_t is not None:
        snap = as_float(snapshot_t, "snapshot_t")
        if not traj.t[0] <= snap <= traj.t[-1]:
            raise InputError(f"snapshot_t={snap:g} s lies outside the trajectory "
                             f"({traj.t[0]:g}-{traj.t[-1]:g} s)", field="snapshot_t")
    return integral, period, snap


# --------------------------------------------------------------------------- instants


def eval_states(traj: Trajectory, substeps: int) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
    """Evaluation instants, the state there, and the index of the sample each starts from.

    With ``substeps > 1`` every sample interval is cut into equal sub-intervals and the
    state interpolated (:meth:`Trajectory.interpolate`).
    """
    if substeps == 1:
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


def snapshot_state(traj: Trajectory, cardset: CardSet, t_s: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The state at the single instant ``t_s`` (interpolated, without ``phase``) and its card index."""
    state = traj.interpolate(np.array([float(t_s)]))
    idx = cardset.assign(state.pop("phase"), [t_s], source=traj.source)
    return state, idx


def trapezoid_weights(t: np.ndarray) -> np.ndarray:
    """Weights ``w`` with ``sum(w * f) == trapezoid(f, t)`` (s)."""
    t = np.asarray(t, dtype=float)
    w = np.zeros_like(t)
    if t.size < 2:
        return w
    dt = np.diff(t)
    w[:-1] += 0.5 * dt
    w[1:] += 0.5 * dt
    return w


# --------------------------------------------------------------------------- receivers


_local = threading.local()


def local_frame(lat0: float, lon0: float, h0: float) -> LocalFrame:
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


def dem_on_grid(dem: Any, grid: GridSpec) -> np.ndarray:
    """Ground heights at the cell centres (m, NaN off the DEM) from a DEM file, a :class:`Dem` or an array."""
    if isinstance(dem, np.ndarray):
        a = np.asarray(dem, dtype=float)
        if a.shape != grid.shape:
            raise InputError(f"dem: array of shape {a.shape} does not match the grid {grid.shape}", field="dem")
        return a
    if not isinstance(dem, Dem):
        dem = read_dem(dem)
    return resample_dem(dem, grid)


@dataclass(frozen=True, eq=False)
class Ground:
    """The ground under the receivers.

    Attributes
    ----------
    heights : ndarray of shape ``grid.shape``, or None
        Ellipsoidal ground heights from a DEM (offset added), m, NaN where the DEM has no
        value; None for flat ground.
    h0 : float
        Height of the local frame's origin: the mean DEM height, or the flat ground's, m.
    description : dict
        How the ground was chosen (for the result's metadata).
    """

    heights: np.ndarray | None
    h0: float
    description: dict[str, Any]


def ground_on_grid(grid: GridSpec, *, dem: Any = None, ground_h: Any = None, dem_offset_m: Any = 0.0) -> Ground:
    """The ground of a map: from the DEM when given, else flat at ``ground_h``.

    ``ground_h`` is the ground chosen by the map's ground rule (:func:`gisnoise.maps.ground.checked_ground`; a
    :class:`~gisnoise.maps.ground.ChosenGround` names its source in the description, a plain number is given).
    With a DEM the description counts the receivers outside it or on its nodata (``dem_nodata_receivers``; they
    get nodata, and :func:`dem_nodata_warning` says so).
    """
    if dem is not None:
        heights = dem_on_grid(dem, grid) + as_float(dem_offset_m, "dem_offset_m")
        finite = np.isfinite(heights)
        if not finite.any():
            raise InputError("dem: the DEM does not cover the grid", field="dem")
        return Ground(heights, float(np.nanmean(heights)), {"ground": "dem", "dem_offset_m": float(dem_offset_m),
                                                            "dem_nodata_receivers": int((~finite).sum())})
    if ground_h is None:
        raise InputError("ground_h: give the ground height or a DEM", field="ground_h")
    g = as_float(ground_h, "ground_h")
    source = ground_h.source if isinstance(ground_h, ChosenGround) else GROUND_GIVEN
    return Ground(None, g, {"ground": "flat", "ground_h_m": g, "ground_h_source": source})


def dem_nodata_warning(metadata: Mapping[str, Any]) -> str | None:
    """The warning of a map whose receivers partly lie outside its DEM or on its nodata, or None.

    From the map metadata (``dem_nodata_receivers`` of :func:`ground_on_grid` and the grid's size).
    """
    n = int(metadata.get("dem_nodata_receivers") or 0)
    if n <= 0:
        return None
    grid = metadata.get("grid") or {}
    total = int(grid.get("width", 0)) * int(grid.get("height", 0))
    of = f" of {total}" if total else ""
    return f"dem: {n}{of} receivers lie outside the DEM or on its nodata; they get nodata (no level) on the map"


# --------------------------------------------------------------------------- the result


Z95 = 1.6448536269514722
"""One-sided 95 % quantile of the standard normal distribution (the ``*_p95`` bands: level - Z95 std)."""

TIE_DB = 0.1
"""Instants tie for a cell's LAmax within this, dB (:func:`tie_std`; far above the engines' float32 / float64
level difference, about 1e-5 dB)."""


def tie_std(std: Any, below_db: Any) -> Any:
    """What an instant brings to ``LAmax_std``: ``std - below_db^2 / (TIE_DB (TIE_DB - below_db))``, dB.

    ``std``: the instant's standard deviation ``sqrt(J C J^T)`` (``J = dL/dp`` there, ``C`` its
    card's covariance), dB; ``below_db``: how far its level lies below the cell's LAmax, dB,
    ``0 <= below_db < TIE_DB``.  Float or array_like.  ``LAmax_std`` is the largest of these over
    the instants within :data:`TIE_DB` of LAmax (both engines): the standard deviation at the
    maximum where one instant is loudest, the largest one where instants tie (the centre of a
    circle, symmetric passes).  An instant counts the less the further below it lies: 0.011 dB less
    at 0.01 dB below, 0.5 dB less at 0.05 dB, not at all at ``TIE_DB``.  So the band is continuous in
    the levels: the engines' level difference (1e-5 dB) moves it by less than 1e-8 dB at the loudest
    instant, and where a quieter instant decides by that difference times the slope there
    (``docs/performance.md``: at most 8e-4 dB in 1200 random maps).

    >>> tie_std(2.0, 0.0), tie_std(2.0, 0.05)
    (2.0, 1.5)
    """
    return std - below_db * below_db / (TIE_DB * (TIE_DB - below_db))


UNCERTAINTY_NOTE = ("delta method through the ansatz Jacobian with the cards' covariance; *_std standard deviation "
                    f"(dB); LAmax_std the largest of std_i - d_i^2 / ({TIE_DB:g} ({TIE_DB:g} - d_i)) over the instants "
                    f"i whose level lies d_i < {TIE_DB:g} dB below LAmax (std_i from dL/dp at i); *_p95 = level - "
                    "1.645 std, the level exceeded with 95 % confidence (one-sided, normal approximation)")
"""The map metadata's ``uncertainty`` entry, both engines."""


def require_covariances(cards: Iterable[ModelCard]) -> None:
    """Refuse uncertainty bands for a card without a parameter covariance (field ``covariance``)."""
    for c in cards:
        if c.cov is None:
            raise CardError(f"card {c.id!r} has no covariance; uncertainty needs cards with a parameter "
                            "covariance (fitted cards)", field="covariance")


def band_order(metrics: Sequence[str], thresholds: Sequence[float], snap: float | None,
               uncertainty: bool) -> list[str]:
    """Names of the result's bands, in the order both engines give them."""
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


def map_metadata(req: MapRequest, bands: Mapping[str, np.ndarray], n_instants: int, receiver_height_m: float,
                 ground_desc: Mapping[str, Any], background: bool, used: Iterable[int], *,
                 speed_of_sound_m_s: float | None = None) -> dict[str, Any]:
    """The metadata both engines give a :class:`MapResult` (``speed_of_sound_m_s`` only when given)."""
    used = set(used)
    traj, cardset = req.traj, req.cardset
    meta: dict[str, Any] = {
        "grid": req.grid.to_dict(),
        "units": {k: band_unit(k) for k in bands},
        "trajectory": {"source": traj.source, "samples": len(traj), "t_start_s": float(traj.t[0]),
                       "t_end_s": float(traj.t[-1]), "duration_s": traj.duration_s},
        "evaluation_instants": int(n_instants),
        "substeps": req.substeps,
        "time_integration": "trapezoid over the evaluation instants",
        "period_s": req.period,
        "receiver_height_m": receiver_height_m,
        **ground_desc,
        "background_included": bool(background),
        "min_distance_m": req.min_distance_m,
    }
    if speed_of_sound_m_s is not None:
        meta["speed_of_sound_m_s"] = speed_of_sound_m_s
    meta.update({
        "thresholds_db": req.thresholds,
        "snapshot_t_s": req.snap,
        "cards": {c.id: {"phase": c.phase, "phases": list(c.served_phases), "ansatz": c.ansatz}
                  for k, c in enumerate(cardset.cards) if k in used},
        "phases": cardset.phases,
    })
    return meta
