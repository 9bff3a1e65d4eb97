"""``gisnoise contour``: the noise map of a trajectory (GeoTIFF levels, GeoJSON contours, PNG map)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import click

from gisnoise.cli.options import building_field_options, card_option, out_dir_option, progress
from gisnoise.errors import InputError


def _levels(ctx: click.Context, param: click.Parameter, value: Any) -> list[float] | None:
    if value is None:
        return None
    try:
        from gisnoise.maps import parse_levels  # deferred: --help answers without the map stack

        return parse_levels(value, field=param.opts[0] if param.opts else "levels")
    except InputError as exc:
        raise click.BadParameter(str(exc).split(": ", 1)[-1]) from None


def _metrics(ctx: click.Context, param: click.Parameter, value: str) -> list[str]:
    return [m.strip() for m in value.split(",") if m.strip()]


def _atmosphere(ctx: click.Context, param: click.Parameter, value: Any) -> tuple[float, ...] | None:
    """``T,RH[,P]`` (deg C, %, kPa) as numbers."""
    if value is None:
        return None
    try:
        parts = tuple(float(v) for v in str(value).split(","))
    except ValueError:
        raise InputError(f"atmosphere: expected TEMPERATURE_C,HUMIDITY_PCT[,PRESSURE_KPA], got {value!r}",
                         field="atmosphere") from None
    if len(parts) not in (2, 3):
        raise InputError(f"atmosphere: expected 2 or 3 numbers (C, % RH[, kPa]), got {value!r}", field="atmosphere")
    return parts


def _cards_in_atmosphere(cards: Sequence[str], atmosphere: tuple[float, ...]) -> list[Any]:
    """The cards loaded, hemisphere cards propagating through ``atmosphere`` on the map."""
    from gisnoise.model import HemisphereCard, load

    loaded = [load(c) for c in cards]
    if not any(isinstance(c, HemisphereCard) for c in loaded):
        raise InputError("atmosphere: applies to hemisphere cards (their ISO 9613-1 absorption); none of the "
                         "cards is one", field="atmosphere")
    return [c.in_atmosphere(*atmosphere) if isinstance(c, HemisphereCard) else c for c in loaded]


def _echo_bands_and_files(res: Any, paths: Mapping[str, Any], keys: Sequence[str]) -> None:
    """Echo the maximum of every band of ``res`` (a MapResult) that has values, then ``wrote <path>``
    for each of ``keys`` that ``paths`` holds (shared by the contour and operations commands)."""
    import numpy as np

    for name in res.bands:
        a = res.bands[name]
        if np.isfinite(a).any():
            click.echo(f"{name}: max {np.nanmax(a):.1f} {res.units.get(name, '')}")
    for key in keys:
        if key in paths:
            click.echo(f"wrote {paths[key]}")


@click.command("contour")
@click.argument("trajectory", type=click.Path(dir_okay=False))
@card_option
@out_dir_option
@click.option("--resolution", "resolution", type=float, default=10.0, show_default=True,
              help="Cell size of the receiver grid, m.")
@click.option("--margin", "margin", type=float, default=None,
              help="Margin around the track, m [default: from the cards, so the lowest level's LAmax and LAeq "
                   "contours close]; contours the grid's edge cuts carry \"clipped\": true and a warning.")
@click.option("--levels", "levels", default="45,50,55,60", show_default=True, callback=_levels,
              help="Contour levels, dB(A), comma-separated, each within -50..200 (the levels a microphone "
                   "records); sorted, a level given twice is drawn once.  SEL is contoured 10 dB higher (a flyover's "
                   "SEL exceeds its LAmax by about 10 dB): the default SEL contours are 55-70 dB(A).")
@click.option("--dem", "dem", type=click.Path(dir_okay=False), default=None,
              help="DEM GeoTIFF: receivers stand on it (heights in the trajectory's vertical datum, "
                   "see --dem-offset).")
@click.option("--dem-offset", "dem_offset", type=float, default=0.0, show_default=True,
              help="Added to DEM heights (e.g. the geoid undulation for an orthometric DEM), m.")
@click.option("--receiver-height", "receiver_height", type=float, default=1.5, show_default=True,
              help="Receiver height above ground, m.")
@click.option("--ground-height", "ground_h", type=float, default=None,
              help="Ellipsoidal height of flat ground without --dem, m [default: stated by the route, else the "
                   "take-off or landing point of a track that starts or ends on the ground; a track that is "
                   "airborne throughout needs --ground-height or --dem].")
@click.option("--power-w", "power_w", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="Constant electric power, W, for a flight log (.ulg, .bin) without battery current.")
@click.option("--geoid-undulation", "geoid_undulation", type=float, default=None,
              help="Geoid undulation N (ellipsoidal minus mean-sea-level height), m, for a flight log with "
                   "heights above mean sea level (ArduPilot .bin) [default: the EGM96 grid at each sample, "
                   "from proj-data or GISNOISE_GEOID_GRID].")
@click.option("--crs", "crs", default=None, help="Projected CRS of the grid, e.g. EPSG:25832 [default: local UTM].")
@click.option("--metrics", "metrics", default="LAmax,LAeq,SEL", show_default=True, callback=_metrics,
              help="Metrics: any of LAmax, LAeq, SEL.")
@click.option("--period", "period", type=float, default=None,
              help="LAeq period, s [default: the trajectory's duration].")
@click.option("--threshold", "threshold", default=None, callback=_levels,
              help="Levels for time-above bands TA<level> (s), dB(A), comma-separated, each within -50..200.")
@click.option("--snapshot", "snapshot", type=float, default=None,
              help="Add the level at this instant (s) as band LA@<t>s.")
@click.option("--substeps", "substeps", type=click.IntRange(min=1), default=1, show_default=True,
              help="Sub-intervals per sample interval for time integration.")
@click.option("--background", "background", is_flag=True, help="Include the cards' background level.")
@click.option("--uncertainty", "uncertainty", is_flag=True,
              help="Add LAmax_std, LAeq_std, SEL_std and the 95 %-confidence levels LAmax_p95, LAeq_p95 "
                   "(delta method; cards need a covariance; where instants tie for LAmax, LAmax_std is the "
                   "largest of their standard deviations, see gisnoise.maps.tie_std).  The fast engine "
                   "computes them for paper and paper-offset cards; for effect extensions --engine auto takes "
                   "the NumPy engine (several times slower).")
@click.option("--plot", "plot", is_flag=True, help="Also draw DIR/map.png.")
@click.option("--engine", "engine", type=click.Choice(["auto", "numpy", "fast"]), default="auto", show_default=True,
              help="Evaluator.  'fast': the numba float32 kernel (paper ansatzes and their effect extensions "
                   "alone and chained: +bank_angle, +rpm, +doppler, +wind, +ground_reflection, "
                   "+atmospheric_absorption; hemisphere cards), equal to 'numpy' within 0.01 dB and tens of "
                   "times faster; --uncertainty of paper cards).  'numpy': the reference (any ansatz, every "
                   "--uncertainty band).  'auto': 'fast' unless --uncertainty of an effect extension, a card it "
                   "does not implement, or hemisphere cards together with receiver-dependent extensions need "
                   "'numpy'; the engine that ran is printed.")
@click.option("--atmosphere", "atmosphere", default=None, callback=_atmosphere, metavar="T,RH[,P]",
              help="Atmosphere of the hemisphere cards' absorption on the map: temperature (C), relative humidity "
                   "(%) and optionally pressure (kPa, default 101.325) [default: each card's map atmosphere, "
                   "else the one its table was back-propagated with].")
@click.option("--population", "population", type=click.Path(dir_okay=False), default=None,
              help="Population raster (GeoTIFF, people per cell): also write DIR/exposure.json and exposure.md.")
@click.option("--buildings", "buildings", type=click.Path(dir_okay=False), default=None,
              help="Buildings with residents/dwellings: façade levels in DIR/exposure.json and exposure.md.")
@building_field_options
@click.pass_context
def command(ctx: click.Context, trajectory: str, cards: tuple[str, ...], out: str, resolution: float, margin: float | None,
            levels: list[float], dem: str | None, dem_offset: float, receiver_height: float, ground_h: float | None,
            crs: str | None, metrics: list[str], period: float | None, threshold: list[float] | None,
            snapshot: float | None, substeps: int, background: bool, uncertainty: bool, plot: bool,
            engine: str, population: str | None = None, buildings: str | None = None,
            power_w: float | None = None, geoid_undulation: float | None = None,
            atmosphere: tuple[float, ...] | None = None, layer: str | None = None,
            residents_field: str | None = None, dwellings_field: str | None = None, height_field: str | None = None,
            levels_field: str | None = None, storey_height: float = 3.0) -> None:
    """Noise map of TRAJECTORY: DIR/levels.tif, DIR/contours.geojson (and DIR/map.png).

    TRAJECTORY is a flight CSV (t, lat, lon, h, roll, pitch, yaw, power_w, phase), a PX4 .ulg or
    ArduPilot .bin flight log, a GeoJSON LineString with times, or waypoints (JSON or GeoJSON
    points).  Samples on the ground (landed, zero current) make no noise.  Give one --card per flight
    phase; a card serves its phase and the phases it lists.
    """
    from gisnoise.maps import make_map

    announced: list[str] = []

    def say(line: str) -> None:  # before the evaluation (and before the bar), so a long map says what it does first
        announced.append(line)
        click.echo(line)

    with progress(ctx, "evaluating", 1.0) as update:
        paths = make_map(
            trajectory, list(cards) if atmosphere is None else _cards_in_atmosphere(cards, atmosphere), out,
            resolution_m=resolution, margin_m=margin, levels=levels,
            metrics=metrics, crs=crs, dem=dem, receiver_height=receiver_height, ground_h=ground_h,
            dem_offset_m=dem_offset, uncertainty=uncertainty, plot=plot, period_s=period,
            threshold_db=threshold, snapshot_t=snapshot, substeps=substeps, background=background,
            engine=engine, progress=update, geoid_undulation_m=geoid_undulation, power_w=power_w,
            also_written=("exposure.json", "exposure.md") if population or buildings else (),
            announce=say)
    res = paths["result"]
    ran = res.metadata.get("engine", engine)
    if announced and not announced[0].endswith(f"; engine {ran}"):
        click.echo(f"engine: {ran} ran (the fast engine refused the request)")
    if population or buildings:
        from gisnoise.exposure import map_exposure, read_buildings, read_levels, read_population, write_exposure

        if dem is not None and buildings:
            raise InputError("buildings: façade levels need flat ground; without --dem", field="buildings")
        written = read_levels(paths["levels"])
        pop = read_population(population, within=written.grid) if population else None  # the part under the map
        bld = read_buildings(buildings, layer=layer, residents=residents_field, dwellings=dwellings_field,
                             height=height_field, levels=levels_field) if buildings else None
        doc = map_exposure(written, population=pop, buildings=bld, trajectory=paths["trajectory"], cards=list(cards),
                           storey_height_m=storey_height)
        paths.update(write_exposure(doc, out))
        paths["warnings"] = list(paths.get("warnings", [])) + [f"exposure: {w}" for w in doc.get("warnings", [])]
    _echo_bands_and_files(res, paths, ("levels", "contours", "map", "exposure", "table"))
    for w in paths.get("warnings", []):
        click.echo(f"warning: {w}", err=True)
