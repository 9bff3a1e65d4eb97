"""The product's main job as one library call: trajectory + cards -> levels.tif, contours.geojson, map.png.

The command line (``gisnoise contour``), the service and the QGIS plugin all call
:func:`make_map`; it reads the trajectory (flight CSV, GeoJSON LineString with times
or waypoints: :func:`gisnoise.flight.routes.read_trajectory`), chooses the receiver grid
(:func:`gisnoise.maps.grids.grid_for_trajectory`), evaluates the metrics
(:func:`gisnoise.maps.evaluate.evaluate_grid`) and writes

``DIR/levels.tif``
    one float32 band per metric (:func:`gisnoise.maps.geotiff.write_geotiff`);
``DIR/contours.geojson``
    isobands and isolines of the level bands in WGS84 (:mod:`gisnoise.maps.contours`);
``DIR/map.png``
    with ``plot=True``: the map with levels, contours, track, scale bar and legend.

Two rules hold for every face:

* the ground (:mod:`gisnoise.maps.ground`, the same rule for :func:`~gisnoise.maps.evaluate.evaluate_grid`):
  without a DEM or a stated ground height, flat ground is taken from the
  track only when the track starts or ends on the ground
  (:func:`gisnoise.flight.ground_from_track`); otherwise the map is refused
  (:class:`~gisnoise.errors.InputError` on ``ground_h``, naming ``--ground-height`` and
  ``--dem``), since the receivers would be put at flight altitude;
* on-ground samples (:attr:`gisnoise.flight.Trajectory.flying`) make no sound: the
  metrics are evaluated over the flying stretches only (:func:`gisnoise.flight.flying_segments`)
  and summed in energy (LAmax the largest, SEL and LAeq as energy sums over the whole
  trajectory's period, time above added);
* a flight log cut short (it ends inside a message: :mod:`gisnoise.flight.logcut`) is mapped up to its last
  whole message, and a warning says the flight may go on beyond its last sample;
* airborne samples without electric power (zero battery current while no landed flag is
  set): when no airborne sample has power, the log does not measure the current in flight
  and the map is refused (``power_w``, naming ``--power-w``); when some have power, the
  unpowered ones are silent (motors stopped while the land detector, which lags a
  touchdown by about a second, still says airborne; or a sensor dropout) and a warning
  names how many (``metadata["warnings"]``, printed by the command line);
* samples where the vehicle lies upside down (inverted and at rest for 1 s or longer, which it
  cannot be in the air: :attr:`gisnoise.flight.Trajectory.lying`), motors still drawing power
  after a crash, are silent, and a warning names them (how many, when, attitude and power);
* powers against the cards' stated power ranges (:mod:`gisnoise.model.power_range`): a card
  without power term used at other powers is refused (``power_w``); a card with one used
  outside the powers it was fitted at gives a warning and ``metadata["power_outside_card_range"]``;
* speeds against the speed a hemisphere card was measured at (:mod:`gisnoise.maps.conditions`): samples
  more than 5 kt from it give a warning and ``metadata["hemisphere_speed_outside_condition"]``;
* a map whose energy came for more than half from hemisphere directions that were not measured
  (:func:`gisnoise.maps.hemifill.filled_share_warning`; with LAeq or SEL) gives a warning;
* cells coarse for the flight's height (:func:`gisnoise.maps.grids.resolution_warning`): the receivers are
  cell centres, the nearest up to half a cell's diagonal beside the track, so LAmax under it may fall short by
  up to 10 lg(1 + (res / sqrt(2) / H)^2) dB, H the flight's median height above the receivers while flying
  (:func:`flight_height`); above 1 dB a warning names the resolution and one that keeps it within 1 dB.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from gisnoise.errors import InputError
from gisnoise.flight import GROUND_HINT_CLI, Trajectory, flying_parts, read_route
from gisnoise.geo import GridSpec
from gisnoise.limits import check_work
from gisnoise.maps.cardset import CardSet, as_cardset
from gisnoise.maps.clipping import clip_warnings, parse_levels
from gisnoise.maps.contours import contours_text, write_geojson
from gisnoise.maps.evaluate import evaluate_grid
from gisnoise.maps.flightchecks import crs_scale_warning, flight_findings
from gisnoise.maps.geotiff import write_geotiff
from gisnoise.maps.grids import grid_for_map, resolution_warning
from gisnoise.maps.ground import GROUND_FROM_TRACK, checked_ground
from gisnoise.maps.hemifill import filled_share_warning
from gisnoise.maps.prepare import dem_nodata_warning
from gisnoise.maps.result import METRICS, MapResult, band_unit, snapshot_name
from gisnoise.model import ModelCard, check_card

__all__ = ["make_map", "evaluate_flying", "DEFAULT_LEVELS", "flight_height", "PRODUCT_FILES",
           "stale_products", "output_folder",
           "grid_line", "planned_instants"]

DEFAULT_LEVELS = (45.0, 50.0, 55.0, 60.0)


def make_map(
    trajectory: Trajectory | str | os.PathLike[str] | dict,
    cards: CardSet | Iterable[ModelCard | str | os.PathLike[str]] | ModelCard,
    out_dir: str | os.PathLike[str] | None,
    *,
    resolution_m: float = 10.0,
    margin_m: float | None = None,
    levels: Any = DEFAULT_LEVELS,
    metrics: Sequence[str] = METRICS,
    crs: Any = None,
    dem: Any = None,
    receiver_height: float = 1.5,
    ground_h: float | None = None,
    dem_offset_m: float = 0.0,
    uncertainty: bool = False,
    plot: bool = False,
    plot_metric: str | None = None,
    period_s: float | None = None,
    threshold_db: float | Sequence[float] | None = None,
    snapshot_t: float | None = None,
    substeps: int = 1,
    background: bool = False,
    engine: str = "auto",
    progress: Callable[[float], Any] | None = None,
    cancel: Callable[[], bool] | None = None,
    geoid_undulation_m: float | None = None,
    power_w: float | None = None,
    outputs: Sequence[str] = ("levels", "contours"),
    grid: GridSpec | None = None,
    also_written: Sequence[str] = (),
    announce: Callable[[str], Any] | None = None,
) -> dict[str, Any]:
    """Noise map of a trajectory: evaluate on a grid and write GeoTIFF, GeoJSON (and PNG).

    Parameters
    ----------
    trajectory : Trajectory, path or dict
        A trajectory, or a flight CSV, GeoJSON LineString with times or waypoints file
        (or its parsed JSON object, or a :class:`~gisnoise.flight.routes.Route`).
    cards : sequence of ModelCard or card paths, or CardSet
        One card per phase present in the trajectory.
    out_dir : path or None
        Output folder (created); None: no files, the GeoJSON answered in memory as ``contours_text``
        (``outputs`` must be ``("contours",)`` and ``plot`` false).
    resolution_m : float
        Cell size, m.
    margin_m : float, optional
        Margin around the track, m; default large enough that the lowest level's LAmax and LAeq
        contours close (:func:`gisnoise.maps.grids.grid_for_map`).  Contours cut by the grid's
        edge carry ``"clipped": true`` and a warning names their metric and levels.
    levels : sequence of float or str
        Contour levels, dB(A).
    metrics : sequence of str
        ``LAmax``, ``LAeq``, ``SEL``.
    crs : str, optional
        Projected CRS of the grid, default the local UTM zone.
    dem : path, optional
        DEM GeoTIFF for the receivers' ground heights.
    receiver_height : float
        Receiver height above ground, m.
    ground_h : float, optional
        Flat ground's ellipsoidal height without DEM, m (default: the height a waypoints
        route states, else the take-off or landing point of a track that starts or ends
        on the ground; a track in the air is refused).
    dem_offset_m : float
        Added to DEM heights to reach the trajectory's vertical datum, m.
    uncertainty : bool
        Add standard deviation and 95 %-confidence bands (cards need a covariance).
    plot : bool
        Also draw ``map.png``.
    plot_metric : str, optional
        Band drawn in ``map.png`` (default ``LAmax`` if computed, else the first level band).
    period_s, threshold_db, snapshot_t, substeps, background, engine
        Passed to :func:`~gisnoise.maps.evaluate.evaluate_grid`.
    geoid_undulation_m, power_w : float, optional
        For flight logs (``.bin``, ``.ulg``): the geoid undulation, m, and a constant power, W
        (:func:`gisnoise.flight.read_route`).
    progress : callable, optional
        Called with the fraction done (0-1).
    cancel : callable, optional
        Polled; returning true raises :class:`~gisnoise.errors.Cancelled`.
    outputs : sequence of str
        The files to write: ``levels`` (levels.tif) and/or ``contours`` (contours.geojson);
        a service answering with one of them writes only that one.
    grid : GridSpec, optional
        The receiver grid when the caller has chosen it already (the service checks its size before
        a map is made): ``resolution_m``, ``margin_m`` and ``crs`` are then not used.
    also_written : sequence of str
        Names of the files the caller writes into ``out_dir`` after the map (the command line's
        ``exposure.json`` and ``exposure.md``): not stale.  Product files of a map (:data:`PRODUCT_FILES`)
        already in ``out_dir`` that this run does not write describe an earlier run: a warning names them
        (:func:`stale_products`); they are kept.
    announce : callable, optional
        Called once before the evaluation with one line naming the grid (cells, resolution, CRS), the
        evaluation instants and the engine expected to run (:func:`grid_line`); the command line prints it,
        so a long map says what it does before it starts.

    Returns
    -------
    dict
        ``levels`` (Path of levels.tif), ``contours`` (Path of contours.geojson) as ``outputs`` asks
        (without ``out_dir``: ``contours_text``, the GeoJSON text),
        ``map`` (Path of map.png, with ``plot``), ``result`` (:class:`MapResult`),
        ``trajectory`` (:class:`Trajectory`), ``warnings`` (list of str: extent cut by the cell
        limit, receivers outside the DEM, clipped contours), ``timing_s`` (seconds: ``evaluate``, the evaluator; ``total``).
    """
    t_start = time.perf_counter()
    lv = parse_levels(levels)
    unknown = sorted(set(outputs) - {"levels", "contours"})
    if unknown or not outputs:
        raise InputError(f"outputs: give levels and/or contours, got {', '.join(map(str, outputs)) or 'none'}",
                         field="outputs")
    if out_dir is None and (plot or set(outputs) != {"contours"}):
        raise InputError("out: without an output folder only the contours are made, in memory (no GeoTIFF, "
                         "no plot)", field="out")
    if plot:
        from gisnoise.maps.plots import require_matplotlib

        require_matplotlib()
    if dem is not None and not isinstance(dem, np.ndarray):
        from gisnoise.geo import Dem, read_dem

        dem = dem if isinstance(dem, Dem) else read_dem(dem)  # read once: the route, the height check, the grid
    route = read_route(trajectory, dem=dem, dem_offset_m=dem_offset_m, geoid_undulation_m=geoid_undulation_m,
                       power_w=power_w)
    traj = route.trajectory
    cardset = as_cardset(cards)
    for card in cardset.cards:
        check_card(card)   # the plausibility guard: an implausible card never makes a map
    # the ground rule of every map (gisnoise.maps.ground): a ground the user gives lies below the flight; a ground
    # taken from the track's own take-off or landing point is within the log's height noise of it by construction
    ground = checked_ground([traj], receiver_height, ground_h, dem, stated_h=route.ground_h_m, hint=GROUND_HINT_CLI)
    from_track = ground is not None and ground.source == GROUND_FROM_TRACK
    ground_h = None if ground is None else float(ground)
    found = flight_findings(traj, cardset, ground_h=ground_h if from_track else None,
                            dem=dem if dem is not None and not isinstance(dem, np.ndarray) else None,
                            dem_offset_m=dem_offset_m)
    if grid is None:
        grid, warnings = grid_for_map(traj, cardset, lv[0], resolution_m=resolution_m, margin_m=margin_m, crs=crs,
                                      background=background, sel="SEL" in metrics)
    else:
        warnings = []
    scale = crs_scale_warning(grid, traj.lon, traj.lat)
    coarse = resolution_warning(float(grid.resolution[0]),
                                flight_height(traj, ground_h, dem, dem_offset_m, receiver_height))
    warnings = found.warnings + ([scale] if scale is not None else []) + ([coarse] if coarse is not None else []) \
        + warnings
    check_work(int(grid.width) * int(grid.height), len(traj) * max(int(substeps), 1))  # before any evaluation
    out = Path(out_dir) if out_dir is not None else None
    if out is not None and out.exists() and not out.is_dir():
        raise InputError(f"{out}: output exists and is not a folder", field="out")
    if out is not None:
        output_folder(out)  # before the evaluation: a folder that cannot be made is said at once
        written = ({"levels": "levels.tif", "contours": "contours.geojson"}[o] for o in outputs)
        stale = stale_products(out, [*written, *(["map.png"] if plot else []), *also_written])
        warnings = warnings + ([stale] if stale is not None else [])

    def eval_progress(f: float) -> None:
        if progress is not None:
            progress(0.9 * f)

    kw: dict[str, Any] = dict(metrics=metrics, receiver_height=receiver_height, dem=dem, ground_h=ground,
                              dem_offset_m=dem_offset_m, threshold_db=threshold_db, background=background,
                              substeps=substeps, uncertainty=uncertainty, engine=engine, cancel=cancel)
    _check_times(traj, snapshot_t, period_s, metrics)  # refused before the grid is announced
    if announce is not None:
        announce(grid_line(grid, planned_instants(traj, substeps), _expected_engine(engine, cardset, uncertainty)))
    t_eval = time.perf_counter()
    result = evaluate_flying(traj, cardset, grid, period_s=period_s, snapshot_t=snapshot_t, progress=eval_progress,
                             **kw)
    t_eval = time.perf_counter() - t_eval
    _check_cells(result, traj.source)
    # the vertical datum of the track (flight logs: MSL + geoid undulation, and which; the estimator's height)
    result.metadata.setdefault("trajectory", {}).update(
        {k: traj.metadata[k] for k in TRACK_HEIGHT_KEYS if k in traj.metadata})
    if found.power_outside:
        result.metadata["power_outside_card_range"] = found.power_outside
    if found.speed_outside:
        result.metadata["hemisphere_speed_outside_condition"] = found.speed_outside
    result.metadata["levels_db"] = lv
    dem_gap = dem_nodata_warning(result.metadata)
    filled = filled_share_warning(result.metadata)
    warnings = warnings + [w for w in (dem_gap, filled) if w is not None] + clip_warnings(result, lv)
    result.metadata["warnings"] = warnings
    paths: dict[str, Any] = {}
    if out is None:  # levels and plot were refused above
        paths["contours_text"] = contours_text(result, lv)
    else:
        out.mkdir(parents=True, exist_ok=True)
        if "levels" in outputs:
            paths["levels"] = write_geotiff(result, out / "levels.tif")
        if "contours" in outputs:
            paths["contours"] = write_geojson(result, out / "contours.geojson", lv)
    if progress is not None:
        progress(0.97)
    if plot and out is not None:
        from gisnoise.maps.plots import plot_map

        paths["map"] = plot_map(result, out / "map.png", levels=lv, trajectory=traj, metric=plot_metric)
    if progress is not None:
        progress(1.0)
    paths["result"] = result
    paths["timing_s"] = {"evaluate": t_eval, "total": time.perf_counter() - t_start}
    paths["trajectory"] = traj
    paths["warnings"] = warnings
    return paths


def grid_line(grid: GridSpec, instants: int, engine: str) -> str:
    """``grid: W x H cells of R m in CRS; N instants; engine E``: what a map evaluates, in one line."""
    auth = grid.crs.to_authority()
    return (f"grid: {grid.width} x {grid.height} cells of {grid.resolution[0]:g} m in "
            f"{':'.join(auth) if auth else grid.crs.name}; {int(instants)} instants; engine {engine}")


def planned_instants(traj: Trajectory, substeps: int = 1) -> int:
    """The evaluation instants of a map of ``traj`` (``metadata["evaluation_instants"]`` once evaluated): those
    of every flying stretch, ``(samples - 1) substeps + 1`` each (:func:`evaluate_flying`)."""
    parts = [traj] if bool(np.all(traj.flying)) else flying_parts(traj)
    k = max(int(substeps), 1)
    return int(sum((len(p) - 1) * k + 1 for p in parts))


def _expected_engine(engine: str, cardset: CardSet, uncertainty: bool) -> str:
    """The engine ``evaluate_grid`` will run (``auto`` resolved as it resolves it; it may still fall back to
    ``numpy`` when the fast engine refuses the flight, which ``metadata["engine"]`` then says)."""
    if engine != "auto":
        return engine
    from gisnoise.maps.evaluate import fast_engine_serves

    return "fast" if fast_engine_serves(cardset, uncertainty=uncertainty) is None else "numpy"


def output_folder(path: str | os.PathLike[str], *, field: str = "out") -> Path:
    """``path`` as an output folder: created (with its parents) if missing, and writable.

    Raises
    ------
    InputError
        On ``field``, naming the folder, when it cannot be created or written into.
    """
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{field}: cannot create the output folder {out} ({exc.strerror or exc})",
                         field=field) from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise InputError(f"{field}: cannot write into the output folder {out} (permission denied)", field=field)
    return out


PRODUCT_FILES = ("levels.tif", "contours.geojson", "map.png", "exposure.json", "exposure.md")
"""The files a map's folder holds (:func:`make_map`'s, and the exposure written beside them)."""


def stale_products(out_dir: str | os.PathLike[str], written: Iterable[str]) -> str | None:
    """The warning naming the product files (:data:`PRODUCT_FILES`) in ``out_dir`` that this run does not
    write (``written``): they describe an earlier run.  None when there are none."""
    out = Path(out_dir)
    if not out.is_dir():
        return None
    fresh = set(written)
    old = [f for f in PRODUCT_FILES if f not in fresh and (out / f).is_file()]
    if not old:
        return None
    return (f"out: {out} holds {', '.join(old)} from an earlier run: {'it describes' if len(old) == 1 else 'they describe'} "
            f"that run, not this map (kept; remove {'it' if len(old) == 1 else 'them'} or use a new folder)")


TRACK_HEIGHT_KEYS = ("height_datum", "height_note", "height_anchor_m", "height_anchor_range_m", "height_resets",
                     "geoid_model", "geoid_undulation_m")
"""The trajectory metadata on its heights that the map metadata repeats (see :mod:`gisnoise.flight.logs`)."""

def flight_height(traj: Trajectory, ground_h: float | None, dem: Any, dem_offset_m: float = 0.0,
                  receiver_height: float = 1.5) -> float | None:
    """The flight's median height above the receivers while flying, m (None when unknown).

    Over the flying samples (all when none flies): their height minus the ground's (``ground_h``, else the DEM
    under each sample plus ``dem_offset_m``; samples off the DEM are left out) minus ``receiver_height``.
    """
    fly = traj.flying if bool(np.any(traj.flying)) else np.ones(len(traj), dtype=bool)
    h = np.asarray(traj.h, dtype=float)[fly]
    if ground_h is not None:
        ground = np.full_like(h, float(ground_h))
    elif dem is not None and not isinstance(dem, np.ndarray):
        from gisnoise.geo import Dem, read_dem, sample_dem

        ground = sample_dem(dem if isinstance(dem, Dem) else read_dem(dem), np.asarray(traj.lon)[fly],
                            np.asarray(traj.lat)[fly]) + float(dem_offset_m)
    else:
        return None
    above = h - ground - float(receiver_height)
    above = above[np.isfinite(above)]
    return float(np.median(above)) if above.size else None


def _check_cells(result: MapResult, source: str) -> None:
    """Refuse a map with a non-finite or implausible level cell (NaN: no value, e.g. outside a DEM)."""
    from gisnoise.model import LEVEL_RANGE_DB

    for name, a in result.bands.items():
        if result.units.get(name) != "dB(A)":
            continue
        v = a[~np.isnan(a)]
        bad = np.isinf(v) & (v > 0) | (v > LEVEL_RANGE_DB[1] + 40.0)
        if bad.any():
            raise InputError(f"{source}: band {name} has {int(bad.sum())} implausible cells (up to "
                             f"{float(np.max(v)):.4g} dB(A)); no map written", field="cards")


def _part_progress(progress: Callable[[float], Any], k: int, n: int) -> Callable[[float], Any]:
    def update(f: float) -> None:
        progress((k + f) / n)
    return update


def evaluate_flying(traj: Trajectory, cards: Any, grid: Any, *, period_s: float | None = None,
                    snapshot_t: float | None = None, progress: Callable[[float], Any] | None = None,
                    **kw: Any) -> MapResult:
    """:func:`~gisnoise.maps.evaluate.evaluate_grid` by the rule of every map: samples on the ground make no noise.

    A track flying throughout is evaluated as it is; otherwise over its flying stretches, summed
    in energy (see the module docstring).  ``kw`` are :func:`evaluate_grid`'s further arguments.
    The ground is the whole track's, by the ground rule of every map (:mod:`gisnoise.maps.ground`: given, else
    stated, else the track's take-off or landing point, else refused), not each stretch's.
    """
    cardset = as_cardset(cards)
    if bool(np.all(traj.flying)):
        return evaluate_grid(traj, cardset, grid, period_s=period_s, snapshot_t=snapshot_t, progress=progress, **kw)
    # the stretches share the track's ground: a stretch in the air does not start on it
    kw = {**kw, "ground_h": checked_ground([traj], kw.get("receiver_height"), kw.get("ground_h"), kw.get("dem"))}
    return _evaluate_flying(traj, cardset, grid, period_s, snapshot_t, progress or (lambda f: None), kw)


def _check_times(traj: Trajectory, snapshot_t: float | None, period_s: float | None, metrics: Sequence[str]) -> None:
    """Refuse a snapshot outside the trajectory and an LAeq period shorter than it, as evaluate_grid does."""
    if snapshot_t is not None and not traj.t[0] <= float(snapshot_t) <= traj.t[-1]:  # as evaluate_grid refuses it
        raise InputError(f"snapshot_t={float(snapshot_t):g} s lies outside the trajectory "
                         f"({traj.t[0]:g}-{traj.t[-1]:g} s)", field="snapshot_t")
    if (period_s is not None and "LAeq" in metrics
            and float(period_s) < traj.duration_s * (1.0 - 1e-12)):  # the whole track's, as evaluate_grid asks
        raise InputError(f"period_s ({float(period_s):g} s) must cover the trajectory's duration "
                         f"({traj.duration_s:g} s)", field="period_s")


def _merged_filled_share(results: list[MapResult]) -> float:
    """The filled-energy share of the stretches' maps together: each stretch's share weighted by its energy (the sum
    over cells of its SEL or LAeq energy; the stretches share the LAeq period)."""
    num = den = 0.0
    for r in results:
        band = r.bands.get("SEL", r.bands.get("LAeq"))
        if band is None:
            continue
        lv = band[np.isfinite(band)]
        e = float(np.sum(10.0 ** ((lv - lv.max()) / 10.0))) * 10.0 ** (float(lv.max()) / 10.0) if lv.size else 0.0
        num += e * float(r.metadata.get("hemisphere_filled_energy_share", 0.0))
        den += e
    return num / den if den > 0 else 0.0


def _evaluate_flying(traj: Trajectory, cardset: CardSet, grid: Any, period_s: float | None,
                     snapshot_t: float | None, progress: Callable[[float], Any], kw: dict[str, Any]) -> MapResult:
    """Metrics over the flying stretches of ``traj`` summed in energy (see the module docstring)."""
    parts = flying_parts(traj)
    if kw.get("uncertainty") and len(parts) > 1:
        raise InputError(f"{traj.source}: uncertainty bands need one flying stretch; the track lands and takes "
                         f"off again ({len(parts)} stretches)", field="uncertainty")
    _check_times(traj, snapshot_t, period_s, kw.get("metrics", METRICS))
    period = traj.duration_s if period_s is None else period_s
    results: list[MapResult] = []
    for k, part in enumerate(parts):
        snap = snapshot_t if snapshot_t is not None and part.t[0] <= snapshot_t <= part.t[-1] else None
        results.append(evaluate_grid(part, cardset, grid, period_s=period, snapshot_t=snap,
                                     progress=_part_progress(progress, k, len(parts)), **kw))
    first = results[0]
    bands: dict[str, np.ndarray] = {}
    for name in first.bands:
        stack = np.stack([r.bands[name] for r in results if name in r.bands])
        if name.startswith("TA"):
            bands[name] = np.sum(stack, axis=0)
        elif name in ("LAeq", "SEL"):
            with np.errstate(divide="ignore"):
                bands[name] = 10.0 * np.log10(np.sum(10.0 ** (stack / 10.0), axis=0))
        else:
            bands[name] = np.max(stack, axis=0)
    if snapshot_t is not None:
        name = snapshot_name(float(snapshot_t))
        hit = [r for r in results if name in r.bands]
        bands[name] = hit[0].bands[name] if hit else np.full(grid.shape, -np.inf)
    meta = dict(first.metadata)
    meta["units"] = {b: band_unit(b) for b in bands}
    meta["trajectory"] = {"source": traj.source, "samples": len(traj), "t_start_s": float(traj.t[0]),
                          "t_end_s": float(traj.t[-1]), "duration_s": traj.duration_s}
    meta["snapshot_t_s"] = snapshot_t
    meta["flying_stretches"] = [[float(p.t[0]), float(p.t[-1])] for p in parts]
    meta["samples_on_ground"] = int(np.sum(~traj.flying))
    meta["evaluation_instants"] = int(sum(r.metadata.get("evaluation_instants", 0) for r in results))
    if "hemisphere_filled_energy_share" in meta:  # the stretches' shares, weighted by their energy
        meta["hemisphere_filled_energy_share"] = _merged_filled_share(results)
    if "period_s" in meta:
        meta["period_s"] = period
    return MapResult(bands, first.grid, meta)
