"""The evaluator: noise metrics of a trajectory on a grid of receivers, on the NumPy or the numba engine.

For every receiver (cell centre of a :class:`~gisnoise.geo.grid.GridSpec`, at
``receiver_height`` above flat ground or a DEM, the ground taken and checked by the
ground rule of every map, :mod:`gisnoise.maps.ground`) and every evaluation instant of the
trajectory (each sample, or finer with ``substeps``), the UAV level ``L_UAV`` is
computed by the card's ansatz (:mod:`gisnoise.model.ansatz`, one model definition for
evaluation, fitting and diagnosis).  The card of each instant is chosen by the
flight phase (:class:`~gisnoise.maps.cardset.CardSet`).  From the levels the evaluator forms

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

:func:`evaluate_grid` chooses the engine; both read the request the same way
(:mod:`gisnoise.maps.prepare`):

``engine="auto"`` (the default)
    the fast engine whenever it computes what is asked (:func:`fast_engine_serves`), else
    the NumPy engine: for the uncertainty bands of cards other than ``paper``/``paper-offset``,
    a ``kernel=`` replacement, or cards it does not implement.  ``metadata["engine"]`` names the engine that ran;

``engine="numpy"``
    the reference (:mod:`gisnoise.maps.reference`): any ansatz, the uncertainty bands
    (delta method with the cards' covariance), bounded memory in blocks of cells x instants;
``engine="fast"``
    the numba kernel in float32 (:mod:`gisnoise.maps.fastkernel`): the ansatzes ``paper``
    and ``paper-offset`` and their extensions by per-instant effects (``bank_angle``,
    ``rpm``; :mod:`gisnoise.maps.fast_effects`) and by receiver-dependent ones
    (``atmospheric_absorption``, ``wind``, ``doppler``, ``ground_reflection``;
    :mod:`gisnoise.maps.receiver_terms`), alone and in chains, and measured hemisphere cards
    (:mod:`gisnoise.maps.hemisource`), the same bands within 0.01 dB, an optional
    audibility floor.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

from gisnoise.errors import CardError, InputError
from gisnoise.flight import Trajectory
from gisnoise.geo import GridSpec
from gisnoise.maps import _numba
from gisnoise.maps.cardset import CardSet, as_cardset
from gisnoise.maps.fast_effects import NotOnFastEngine, base_card
from gisnoise.maps.fast_uncertainty import uncertainty_refusal
from gisnoise.maps.fastkernel import evaluate_fast
from gisnoise.maps.hemifill import has_hemisphere
from gisnoise.maps.prepare import MapOptions
from gisnoise.maps.receiver_terms import receiver_terms
from gisnoise.maps.reference import DEFAULT_BLOCK, evaluate_numpy
from gisnoise.maps.result import METRICS, MapResult
from gisnoise.model import HemisphereCard, ModelCard, check_card

__all__ = ["DEFAULT_ENGINE", "ENGINES", "evaluate_grid", "evaluate_grid_fast", "fast_engine_serves"]

log = logging.getLogger(__name__)

ENGINES = ("auto", "numpy", "fast")
"""The evaluator's engines (``auto``: the fast one whenever it computes what is asked)."""

DEFAULT_ENGINE = "auto"


def fast_engine_serves(cards: CardSet | Iterable[ModelCard] | ModelCard, *, uncertainty: bool = False,
                       kernel: Any = None) -> str | None:
    """Why the fast engine cannot compute a request (one line), or None when it can.

    It cannot without numba or with a ``kernel=`` replacement, the uncertainty bands of cards
    other than ``paper``/``paper-offset`` (:func:`~gisnoise.maps.fast_uncertainty.uncertainty_refusal`), or
    for a card whose ansatz is neither ``paper``/``paper-offset`` nor one of their
    extensions by per-instant effects and the receiver-dependent ones of
    :mod:`gisnoise.maps.receiver_terms` (hemisphere cards it computes, but not in one
    request with receiver-dependent terms).
    """
    if _numba.numba is None:
        return "numba is not installed"
    if kernel is not None:
        return "a kernel replacement belongs to the NumPy engine"
    cs = as_cardset(cards).cards
    if uncertainty:  # the delta method's bands of paper and paper-offset cards (maps/fast_uncertainty.py): every
        return uncertainty_refusal(cs)  # card of the set here; evaluate_grid's "auto" asks of the cards flown
    hemi = has_hemisphere(cs)
    for c in cs:
        if isinstance(c, HemisphereCard):  # measured hemispheres: their kernel (maps/hemisource.py)
            continue
        try:
            base_card(c)
            if receiver_terms(c) is not None and hemi:
                return (f"card {c.id!r}: the receiver-dependent terms of {c.ansatz!r} are not combined with "
                        "measured hemisphere cards on the fast engine")
        except CardError as exc:
            return str(exc)
    return None


def evaluate_grid(
    traj: Trajectory,
    cards: CardSet | Iterable[ModelCard] | ModelCard,
    grid: GridSpec,
    *,
    metrics: Sequence[str] | str = METRICS,
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
    engine: str = DEFAULT_ENGINE,
    floor_db: float | None = None,
    threads: int | None = None,
    check_cards: bool = True,
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
        Receiver height above the ground, m: 0 (on the ground) or more.
    dem : path, Dem or ndarray, optional
        Ground heights: a DEM file or :class:`~gisnoise.geo.raster.Dem` (resampled to the
        grid, bilinear) or an array of shape ``grid.shape`` (m).  Heights are taken in the
        trajectory's vertical datum (ellipsoidal) after adding ``dem_offset_m``.
    ground_h : float, optional
        Flat ground's ellipsoidal height when there is no DEM, m, at or below the trajectory's lowest flying
        point.  Default, by the ground rule of every map (:mod:`gisnoise.maps.ground`): the ground the
        trajectory's source states (a waypoints route), else the trajectory's own take-off or landing point
        (:func:`gisnoise.flight.ground_from_track`); a trajectory that starts and ends in the air (a flyover, a
        slice of a log) is refused (:class:`~gisnoise.errors.InputError` on ``ground_h``).
        ``metadata["ground_h_source"]`` says which.
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
        Receivers per block (default from ``block_size``); with ``engine="fast"`` cells per
        kernel call (whole rows, default :data:`~gisnoise.maps.fastkernel.DEFAULT_CHUNK_CELLS`).
    block_size : int
        Cell-instants per block; bounds the memory (about 20 float64 arrays of this size).
        Not used by ``engine="fast"`` (the kernel keeps no cells x instants arrays).
    min_distance_m : float
        Near-field limit: distances below it are clamped, m.
    temperature_c : float
        Air temperature, deg C, for extended ansatzes that need the speed of sound
        (Doppler, ground reflection): ``c = 331.3 sqrt(1 + T / 273.15)`` m/s.  Default
        15 deg C (ISA sea level).  The paper's ansatz does not use it.
    kernel : callable, optional
        Replacement for the NumPy engine's block function
        (:func:`gisnoise.maps.reference._levels_chunk`) with the same signature and results (a
        compiled kernel); default the NumPy reference.
    progress : callable, optional
        Called with the fraction done (0-1) after every block.
    cancel : callable, optional
        Polled between blocks; returning true raises :class:`~gisnoise.errors.Cancelled`.
    engine : {"auto", "numpy", "fast"}
        ``"fast"``: the numba kernel of :mod:`gisnoise.maps.fastkernel` (same bands within
        0.01 dB; ansatzes ``paper``, ``paper-offset`` and their effect extensions, per-instant
        and receiver-dependent, alone and chained; hemisphere cards; the uncertainty bands of
        ``paper`` and ``paper-offset`` cards).  ``"auto"`` (default): the fast engine when
        :func:`fast_engine_serves` finds nothing against it, else the NumPy engine (logged;
        ``metadata["engine"]`` names the engine that ran).
    floor_db : float, optional
        With ``engine="fast"``: audibility floor, dB(A).  Cells whose level is, by a bound
        over all emission angles, below it at every instant are not computed: NaN in the
        level bands, 0 in time-above bands of levels >= ``floor_db``.  Default: every cell
        is computed.
    threads : int, optional
        With ``engine="fast"``: kernel threads (default
        :func:`~gisnoise.maps.threads.default_threads`).
    check_cards : bool
        Refuse a card the plausibility guard refuses (:func:`gisnoise.model.check_card`:
        :class:`~gisnoise.model.ImplausibleCardError` naming the parameters).  Only engine
        comparisons on synthetic cards turn it off.

    Returns
    -------
    MapResult
        With ``engine="fast"`` also ``metadata["engine"] == "fast"`` and
        ``metadata["cells_below_floor"]``.

    Raises
    ------
    InputError
        On the first wrong input, naming its field; as :func:`gisnoise.maps.make_map` refuses them: no ground known,
        a ``ground_h`` above the trajectory's lowest flying point, a ``receiver_height`` below 0.
    """
    opts = MapOptions(
        metrics=metrics, receiver_height=receiver_height, dem=dem, ground_h=ground_h, dem_offset_m=dem_offset_m,
        period_s=period_s, threshold_db=threshold_db, snapshot_t=snapshot_t, background=background,
        substeps=substeps, uncertainty=uncertainty, chunk_cells=chunk_cells, block_size=block_size,
        min_distance_m=min_distance_m, temperature_c=temperature_c, kernel=kernel, progress=progress,
        cancel=cancel, floor_db=floor_db, threads=threads)
    cards = as_cardset(cards)
    for card in cards if check_cards else ():  # the plausibility guard (cached per card content): never a map of an implausible card
        check_card(card)
    if engine == "auto":
        # the uncertainty bands: evaluate_fast checks the cards the flight uses (an unused one may be any)
        why = fast_engine_serves(cards, kernel=kernel)
        if why is None:
            try:
                return evaluate_fast(traj, cards, grid, opts)
            except NotOnFastEngine as exc:  # refused while reading the flight, before any cell is computed
                why = str(exc)
        log.info("NumPy engine: %s", why)
        engine = "numpy"
    if engine == "numpy":
        res = evaluate_numpy(traj, cards, grid, opts)
        res.metadata.setdefault("engine", "numpy")
        return res
    if engine == "fast":
        return evaluate_fast(traj, cards, grid, opts)
    raise InputError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}", field="engine")


def evaluate_grid_fast(traj: Trajectory, cards: CardSet | Iterable[ModelCard] | ModelCard, grid: GridSpec, *,
                       engine: str = "fast", **options: Any) -> MapResult:
    """:func:`evaluate_grid` with the fast kernel (``engine="fast"``; same parameters and bands).

    The fast engine refuses ``uncertainty`` for cards other than ``paper``/``paper-offset`` (their
    Jacobian stays with the NumPy engine) and a ``kernel``; ``floor_db`` and ``threads`` are its own options.

    Returns
    -------
    MapResult
        The bands of the NumPy engine within 0.01 dB; ``metadata["engine"] == "fast"``,
        ``metadata["cells_below_floor"]``.
    """
    if engine != "fast":
        raise InputError(f"engine must be 'numpy' or 'fast', got {engine!r}", field="engine")
    return evaluate_grid(traj, cards, grid, engine="fast", **options)
