"""The fast evaluator engine: the numba kernel in float32 for the ``paper`` ansatzes.

``evaluate_grid(..., engine="fast")`` (:func:`gisnoise.maps.evaluate.evaluate_grid`)
runs :func:`evaluate_fast`: the same bands as the NumPy engine
(:mod:`gisnoise.maps.reference`) within 0.01 dB, much faster.  It evaluates the ansatzes
``paper`` and ``paper-offset`` of :mod:`gisnoise.model.ansatz` (Eq. 8-11; the tests
check the kernel against the registry's definition) and their effect extensions: per-instant
terms (:mod:`gisnoise.maps.fast_effects`) in this kernel, receiver-dependent ones
(:mod:`gisnoise.maps.receiver_terms`) in its sibling :mod:`gisnoise.maps._numba_receiver`,
which :func:`run_window` picks for a flight with such terms; the uncertainty bands of ``paper``
and ``paper-offset`` cards in :mod:`gisnoise.maps.fast_uncertainty`.  It refuses every other
ansatz, the uncertainty bands of effect extensions and a ``kernel=`` replacement.

The engine's steps, each usable alone (the operations of :mod:`gisnoise.ops` run them
per tile):

* the flight in the kernel's form: :func:`~gisnoise.maps.instants.prepare_flight`
  (cards' coefficients, instants, gains, rotations, audibility radii);
* the receivers: :func:`~gisnoise.maps.receivers.receivers_for` (a lattice of exact
  positions per row segment, DEM heights);
* the kernel (:mod:`gisnoise.maps._numba`, how it is fast is told there) on a window of
  rows and columns, :func:`run_window`, or on a whole grid in blocks of rows spread over
  threads, :func:`run_grid` (:mod:`gisnoise.maps.threads`).

One compiled function serves a whole grid, a tile of it and a single instant, so tiles
aligned to segments give bitwise the same cells as the whole grid.

**Audibility floor.**  With ``floor_db``, cells whose level is, by a bound over all
emission angles, below the floor at every instant are not computed: NaN in the level
bands (their LAmax is certainly below ``floor_db``), 0 in time-above bands of levels at
or above the floor; every other cell is computed over all instants, exactly.

Accumulation: the maximum and the trapezoid energy ``sum w_i 10^(L_i/10)`` per cell
(energy in float64), time above levels linear between instants as the NumPy engine.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from gisnoise.acoustics import speed_of_sound
from gisnoise.errors import Cancelled, InputError
from gisnoise.maps import _numba as _kernels
from gisnoise.maps import _numba_receiver as _rx_kernels
from gisnoise.maps._checks import as_float
from gisnoise.maps._poly import _ATAN_C, _EXP2_C, _LOG2_C, _poly_eval  # noqa: F401  (the kernel's polynomials)
from gisnoise.maps.fast_effects import NotOnFastEngine
from gisnoise.maps.fast_uncertainty import uncertainty_bands, uncertainty_refusal
from gisnoise.maps.hemifill import has_hemisphere
from gisnoise.maps.hemisource import HemiFlight, evaluate_hemisphere_fast, run_hemi_window
from gisnoise.maps.instants import (
    FAST_ANSATZES,
    FlightInstants,
    _audibility_radius,  # noqa: F401  (the bound behind the audibility floor)
    card_coefficients,
    directivity_range,
    prepare_flight,
    snapshot_instant,
)
from gisnoise.maps.kernelbands import chunk_cells_of, kernel_bands
from gisnoise.maps.prepare import (
    UNCERTAINTY_NOTE,
    MapOptions,
    band_order,
    check_request,
    map_metadata,
    require_covariances,
)
from gisnoise.maps.receiver_terms import kernel_flags
from gisnoise.maps.receivers import SEGMENT_M, Receivers, receivers_for, segment_cells
from gisnoise.maps.result import MapResult
from gisnoise.maps.threads import default_threads, map_threads, row_blocks
from gisnoise.model import HemisphereCard, ModelCard

__all__ = [
    "DEFAULT_CHUNK_CELLS",
    "FAST_ANSATZES",
    "SEGMENT_M",
    "FlightInstants",
    "Receivers",
    "WindowResult",
    "card_coefficients",
    "directivity_range",
    "evaluate_fast",
    "warm_up",
    "level_from_body",
    "prepare_flight",
    "receivers_for",
    "require_numba",
    "run_grid",
    "run_window",
    "segment_cells",
    "snapshot_instant",
    "window_lattice",
]

DEFAULT_CHUNK_CELLS = 1 << 17
"""Cells per kernel call (whole rows); the unit of progress, cancel and threading."""


def require_numba() -> None:
    """Refuse the fast engine when numba (the optional extra ``fast``) is not installed."""
    if _kernels.numba is None:
        raise InputError("engine 'fast' needs numba (pip install 'gisnoise[fast]')", field="engine")


def level_from_body(card: ModelCard, xb: Any, yb: Any, zb: Any, power_w: Any, *,
                    min_distance_m: float = 1.0) -> np.ndarray:
    """The kernel's ``L_UAV`` (dB, float32) for body vectors ``(xb, yb, zb)`` (m) and power (W).

    Arrays broadcast.  The tests compare it with the ansatz of :mod:`gisnoise.model.ansatz` at
    the emission angles of the same vectors.
    """
    require_numba()
    p0, p1, row = card_coefficients(card, min_distance_m=min_distance_m)
    xb, yb, zb, pw = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (xb, yb, zb, power_w)))
    g = p0 + p1 * np.log10(pw.ravel() / card.reference_power_w)
    out = _kernels._level_points(xb.astype(np.float32).ravel(), yb.astype(np.float32).ravel(),
                                 zb.astype(np.float32).ravel(), g, row)
    return out.reshape(xb.shape)


# --------------------------------------------------------------------------- running the kernel


@dataclass(frozen=True, eq=False)
class WindowResult:
    """Kernel output on a window of rows ``r0:r1`` and columns ``c0:c1``.

    ``emax`` (float32) the largest ``10^(L/10)``; ``energy`` (float64) ``sum w_i 10^(L_i/10)``, s;
    ``ta`` (float64, one plane per threshold) time above, s; ``computed`` (bool) the cells
    within audibility (the others are zero and certainly below the floor).
    """

    emax: np.ndarray
    energy: np.ndarray
    ta: np.ndarray
    computed: np.ndarray


def window_lattice(rc: Receivers, r0: int, r1: int, c0: int, c1: int) -> tuple[np.ndarray, np.ndarray]:
    """The lattice (:meth:`Receivers.lattice`) a window needs; compute it once for many flights."""
    return rc.lattice(r0, r1, c0 // rc.seg, -(-c1 // rc.seg))


def run_window(fl: FlightInstants, rc: Receivers, r0: int, r1: int, c0: int, c1: int,
               thresholds: Sequence[float] = (), *, lattice: tuple[np.ndarray, np.ndarray] | None = None
               ) -> WindowResult:
    """Run the kernel on rows ``r0:r1`` and columns ``c0:c1`` of the grid (releases the GIL).

    ``c0`` and ``c1`` should be multiples of ``rc.seg`` (or ``c1`` the grid's width) so that
    the window's cells equal the whole grid's bit for bit.  ``lattice``: the window's
    :func:`window_lattice`, when already computed.
    """
    require_numba()
    if isinstance(fl, HemiFlight):  # a flight with hemisphere cards: their kernel (maps/hemisource.py)
        return run_hemi_window(fl, rc, r0, r1, c0, c1, thresholds, lattice=lattice)  # type: ignore[return-value]
    dh = rc.window_heights(r0, r1, c0, c1)
    k = rc.seg
    m0 = c0 // k
    P, U = window_lattice(rc, r0, r1, c0, c1) if lattice is None else lattice
    nr, ncw = r1 - r0, c1 - c0
    thr = np.asarray(list(thresholds), dtype=np.float64)
    emax = np.zeros((nr, ncw), np.float32)
    energy = np.zeros((nr, ncw), np.float64)
    ta = np.zeros((thr.size, nr, ncw), np.float64)
    computed = np.zeros((nr, ncw), np.uint8)
    if fl.rx is not None:  # receiver-dependent effect terms: their kernel (maps/_numba_receiver.py)
        hr = rc.height_agl
        _rx_kernels._receiver_window_kernel(P, U, dh, rc.dh is not None, k, m0, c0, ncw, fl.src, fl.C, fl.gain,
                                            fl.cidx, fl.coef, fl.w, fl.dt, fl.radius, thr, fl.rx, float(hr),
                                            kernel_flags(fl.rx, hr), emax, energy, ta, computed)
        return WindowResult(emax, energy, ta, computed.astype(bool))
    _kernels._window_kernel(P, U, dh, rc.dh is not None, k, m0, c0, ncw, fl.src, fl.C, fl.gain, fl.cidx, fl.coef,
                            fl.w, fl.dt, fl.radius, thr, emax, energy, ta, computed)
    return WindowResult(emax, energy, ta, computed.astype(bool))


def run_grid(fl: FlightInstants, rc: Receivers, thresholds: Sequence[float] = (), *, threads: int | None = None,
             chunk_cells: int = DEFAULT_CHUNK_CELLS, progress: Callable[[float], Any] | None = None,
             cancel: Callable[[], bool] | None = None) -> WindowResult:
    """The kernel on the whole grid, in blocks of rows spread over ``threads`` threads.

    ``progress`` gets the fraction of rows done after every block; ``cancel`` is polled
    between blocks and, returning true, raises :class:`~gisnoise.errors.Cancelled`.
    """
    H, W = rc.grid.shape
    nthreads = default_threads() if threads is None else max(1, int(threads))
    blocks = row_blocks(H, W, chunk_cells, nthreads)
    nt = len(list(thresholds))
    emax = np.zeros((H, W), np.float32)
    energy = np.zeros((H, W), np.float64)
    ta = np.zeros((nt, H, W), np.float64)
    computed = np.zeros((H, W), bool)
    done = 0

    def put(b: tuple[int, int], res: WindowResult) -> None:
        nonlocal done
        r0, r1 = b
        emax[r0:r1] = res.emax
        energy[r0:r1] = res.energy
        ta[:, r0:r1] = res.ta
        computed[r0:r1] = res.computed
        done += r1 - r0
        if progress is not None:
            progress(done / H)

    def check() -> None:
        if cancel is not None and cancel():
            raise Cancelled("cancelled", field="cancel")

    map_threads(lambda b: run_window(fl, rc, b[0], b[1], 0, W, thresholds), blocks, put, nthreads, poll=check)
    return WindowResult(emax, energy, ta, computed)


# --------------------------------------------------------------------------- compiling ahead


def warm_up() -> dict[str, Any]:
    """Compile the kernels now (and store them in numba's disk cache) on a tiny map.

    The set-up (``scripts/_env.sh``) calls it once after installing, so that the first map
    does not wait for the compiler; later processes load the kernels from the cache.

    Returns
    -------
    dict
        ``seconds`` taken and ``cached`` (whether the kernels are cached on disk).
    """
    import time

    from affine import Affine

    from gisnoise.flight import Trajectory
    from gisnoise.geo import GridSpec, LocalFrame
    from gisnoise.model import ModelCard, sample_card

    require_numba()
    t0 = time.perf_counter()
    lat0, lon0 = 52.0, 10.0
    lat, lon, h = LocalFrame(lat0, lon0, 0.0).to_wgs84(np.array([-20.0, 20.0]), np.zeros(2), np.full(2, 30.0))
    traj = Trajectory(t=np.array([0.0, 2.0]), lat=lat, lon=lon, h=h, roll=np.zeros(2), pitch=np.zeros(2),
                      yaw=np.full(2, 90.0), power_w=np.full(2, 1000.0), phase=np.array(["horizontal"] * 2))
    crs = f"+proj=tmerc +lat_0={lat0} +lon_0={lon0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
    grid = GridSpec(crs, Affine(10.0, 0.0, -20.0, 0.0, -10.0, 20.0), 4, 4)
    card = ModelCard(id="warm-up", vehicle="warm-up", phase="horizontal", ansatz="paper-offset",
                     parameters=dict(p0=60.0, p1=10.0, p2=0.1, p3=0.0, p4=0.1, p5=0.0, p6=1.0, p7=30.0),
                     reference_power_w=1000.0)
    opts = MapOptions(metrics=("LAmax", "LAeq", "SEL"), receiver_height=1.5, dem=None, ground_h=0.0,
                      dem_offset_m=0.0, period_s=None, threshold_db=50.0, snapshot_t=1.0, background=False,
                      substeps=1, uncertainty=False, chunk_cells=None, block_size=1, min_distance_m=1.0,
                      temperature_c=15.0, kernel=None, progress=None, cancel=None, floor_db=None, threads=1)
    evaluate_fast(traj, card, grid, opts)
    rx_card = ModelCard(id="warm-up-rx", vehicle="warm-up", phase="horizontal",
                        ansatz="paper-offset+atmospheric_absorption+wind+doppler+ground_reflection",
                        parameters=dict(card.parameters, a_abs=5.0, w_east=0.1, w_north=0.1, q_doppler=1.0,
                                        r_ground=0.5, f_ground=500.0), reference_power_w=1000.0)
    evaluate_fast(traj, rx_card, grid, opts)  # the kernel of receiver-dependent terms (maps/_numba_receiver.py)
    evaluate_fast(traj, sample_card(card), grid, opts)  # the hemisphere kernel (maps/_hemikernel.py)
    cov = tuple(tuple(0.01 * float(i == j) for j in range(8)) for i in range(8))
    evaluate_fast(traj, dataclasses.replace(card, covariance=cov), grid,  # the uncertainty kernel (maps/_numba_jac.py)
                  dataclasses.replace(opts, uncertainty=True))
    level_from_body(card, 1.0, 1.0, 1.0, 1000.0)
    return {"seconds": time.perf_counter() - t0, "cached": bool(_kernels.cache_used)}


# --------------------------------------------------------------------------- the engine


def evaluate_fast(traj: Any, cards: Any, grid: Any, opts: MapOptions) -> MapResult:
    """The numba engine behind :func:`~gisnoise.maps.evaluate.evaluate_grid` (``engine="fast"``).

    ``opts.chunk_cells`` is the number of cells per kernel call (whole rows, default
    :data:`DEFAULT_CHUNK_CELLS`); ``block_size`` is not used (the kernel keeps no cells x
    instants arrays); ``temperature_c`` gives the speed of sound of the receiver-dependent
    terms (Doppler, ground reflection) as in the NumPy engine.  ``metadata["engine"] ==
    "fast"``, ``metadata["cells_below_floor"]``.
    """
    if opts.kernel is not None:
        raise InputError("kernel: a replacement block function belongs to engine='numpy'", field="kernel")
    require_numba()
    req = check_request(traj, cards, grid, opts)
    if opts.uncertainty:
        used_cards = [req.cardset.cards[k] for k in sorted(set(req.cardset.assign(req.traj.phase, req.traj.t,
                                                                                    source=req.traj.source).tolist()))]
        why = uncertainty_refusal(used_cards + [c for c in req.cardset.cards if isinstance(c, HemisphereCard)])
        if why is not None:  # (NotOnFastEngine: engine="auto" takes the NumPy engine)
            raise NotOnFastEngine(f"uncertainty: {why}; use engine='numpy'", field="engine")
        require_covariances(used_cards)
    if has_hemisphere(req.cardset.cards):  # measured hemispheres: their own kernel (maps/hemisource.py)
        return evaluate_hemisphere_fast(req, opts)
    traj, grid, metrics, thresholds = req.traj, req.grid, req.metrics, req.thresholds
    period, snap = req.period, req.snap
    progress, cancel, threads, background = opts.progress, opts.cancel, opts.threads, opts.background
    floor = None if opts.floor_db is None else as_float(opts.floor_db, "floor_db")
    chunk = chunk_cells_of(opts.chunk_cells, DEFAULT_CHUNK_CELLS)
    temp = as_float(opts.temperature_c, "temperature_c", minimum=-273.15, strict=True)

    rc = receivers_for(grid, [traj], receiver_height=opts.receiver_height, dem=opts.dem, ground_h=req.ground,
                       dem_offset_m=opts.dem_offset_m)
    frame = rc.frame
    fl = prepare_flight(traj, req.cardset, frame, substeps=req.substeps, background=background,
                        min_distance_m=req.min_distance_m, floor_db=floor, temperature_c=temp)
    share = 1.0 if snap is None else fl.n / (fl.n + 1.0)
    # the uncertainty bands' kernel takes about three times the levels' (bench/bench_uncertainty.py)
    lev_share = 0.25 if opts.uncertainty and {"LAmax", "LAeq", "SEL"} & set(metrics) else 1.0

    def prog(f: float) -> None:
        if progress is not None:
            progress(lev_share * share * f)

    res = run_grid(fl, rc, thresholds, threads=threads, chunk_cells=chunk, progress=prog, cancel=cancel)
    s = None
    if snap is not None:
        s_fl = snapshot_instant(traj, req.cardset, frame, snap, background=background,
                                min_distance_m=req.min_distance_m, floor_db=floor, substeps=req.substeps,
                                temperature_c=temp)
        s = run_grid(s_fl, rc, (), threads=threads, chunk_cells=chunk, cancel=cancel,
                     progress=None if progress is None else (lambda f: progress(lev_share * (share + (1 - share) * f))))
    bands, below = kernel_bands(res, grid.shape, metrics, thresholds, snap, period, floor, s, rc.valid)
    if opts.uncertainty:  # the delta method's bands (maps/fast_uncertainty.py)
        bands.update(uncertainty_bands(req.cardset.cards, fl, rc, metrics, bands, background=background,
                                       min_distance_m=req.min_distance_m, threads=threads, chunk_cells=chunk,
                                       cancel=cancel, progress=None if progress is None else
                                       (lambda f: progress(lev_share + (1.0 - lev_share) * f))))
        bands = {name: bands[name] for name in band_order(metrics, thresholds, snap, True)}
    used = sorted(set(fl.cidx.tolist()))
    meta = map_metadata(req, bands, fl.n, float(opts.receiver_height), rc.ground or {}, background, used)
    meta.update({"engine": "fast", "floor_db": floor, "cells_below_floor": int(below.sum())})
    if opts.uncertainty:
        meta["uncertainty"] = UNCERTAINTY_NOTE
    if fl.rx is not None:  # the speed of sound of the receiver-dependent terms, as the NumPy engine states it
        meta["speed_of_sound_m_s"] = float(speed_of_sound(temp))
    return MapResult(bands=bands, grid=grid, metadata=meta)
