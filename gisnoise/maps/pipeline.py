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
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from gisnoise.errors import InputError
from gisnoise.flight import Trajectory, read_route
from gisnoise.limits import check_receivers
from gisnoise.maps.cardset import CardSet, as_cardset
from gisnoise.maps.contours import clip_warnings, parse_levels, write_geojson
from gisnoise.maps.evaluate import evaluate_grid
from gisnoise.maps.geotiff import write_geotiff
from gisnoise.maps.grids import grid_for_map
from gisnoise.maps.result import METRICS, MapResult
from gisnoise.model import ModelCard

__all__ = ["make_map", "DEFAULT_LEVELS"]

DEFAULT_LEVELS = (45.0, 50.0, 55.0, 60.0)


def make_map(
    trajectory: Trajectory | str | os.PathLike[str] | dict,
    cards: CardSet | Iterable[ModelCard | str | os.PathLike[str]] | ModelCard,
    out_dir: str | os.PathLike[str],
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
) -> dict[str, Any]:
    """Noise map of a trajectory: evaluate on a grid and write GeoTIFF, GeoJSON (and PNG).

    Parameters
    ----------
    trajectory : Trajectory, path or dict
        A trajectory, or a flight CSV, GeoJSON LineString with times or waypoints file
        (or its parsed JSON object, or a :class:`~gisnoise.flight.routes.Route`).
    cards : sequence of ModelCard or card paths, or CardSet
        One card per phase present in the trajectory.
    out_dir : path
        Output folder (created).
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
        route states, else the track's lowest point).
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
    progress : callable, optional
        Called with the fraction done (0-1).
    cancel : callable, optional
        Polled; returning true raises :class:`~gisnoise.errors.Cancelled`.

    Returns
    -------
    dict
        ``levels`` (Path of levels.tif), ``contours`` (Path of contours.geojson),
        ``map`` (Path of map.png, with ``plot``), ``result`` (:class:`MapResult`),
        ``trajectory`` (:class:`Trajectory`), ``warnings`` (list of str: extent cut by the cell
        limit, clipped contours).
    """
    lv = parse_levels(levels)
    if plot:
        from gisnoise.maps.plots import require_matplotlib

        require_matplotlib()
    route = read_route(trajectory, dem=dem, dem_offset_m=dem_offset_m)
    traj = route.trajectory
    if ground_h is None and dem is None:
        ground_h = route.ground_h_m
    check_receivers(receiver_height, ground_h, traj.h)  # the shared rule set (gisnoise.limits)
    cardset = as_cardset(cards)
    grid, warnings = grid_for_map(traj, cardset, lv[0], resolution_m=resolution_m, margin_m=margin_m, crs=crs,
                                  background=background)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: output exists and is not a folder", field="out")

    def eval_progress(f: float) -> None:
        if progress is not None:
            progress(0.9 * f)

    result: MapResult = evaluate_grid(
        traj, cardset, grid, metrics=metrics, receiver_height=receiver_height, dem=dem, ground_h=ground_h,
        dem_offset_m=dem_offset_m, period_s=period_s, threshold_db=threshold_db, snapshot_t=snapshot_t,
        background=background, substeps=substeps, uncertainty=uncertainty, engine=engine, progress=eval_progress,
        cancel=cancel)
    result.metadata["levels_db"] = lv
    warnings = warnings + clip_warnings(result, lv)
    result.metadata["warnings"] = warnings
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Any] = {}
    paths["levels"] = write_geotiff(result, out / "levels.tif")
    paths["contours"] = write_geojson(result, out / "contours.geojson", lv)
    if progress is not None:
        progress(0.97)
    if plot:
        from gisnoise.maps.plots import plot_map

        paths["map"] = plot_map(result, out / "map.png", levels=lv, trajectory=traj, metric=plot_metric)
    if progress is not None:
        progress(1.0)
    paths["result"] = result
    paths["trajectory"] = traj
    paths["warnings"] = warnings
    return paths
