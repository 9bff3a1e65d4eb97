"""``gisnoise operations``: a day of flights -> Lden, LAeq per period, N-above, time above."""

from __future__ import annotations

import click

from gisnoise.cli.contour import _echo_bands_and_files
from gisnoise.cli.options import building_field_options, echo_warnings, out_dir_option, progress
from gisnoise.errors import InputError


@click.command("operations")
@click.argument("schedule", type=click.Path(dir_okay=False))
@out_dir_option
@click.option("--scheduler", "scheduler", default=None, metavar="ADDRESS",
              help="Run on the Dask scheduler at ADDRESS (e.g. tcp://scheduler:8786) "
                   "[default: $GISNOISE_DASK_SCHEDULER, else this machine in one process].")
@click.option("--workers", "workers", type=click.IntRange(min=1), default=None,
              help="Start a local Dask cluster of N worker processes for the run [default: none: on one "
                   "machine the kernel's threads do the same work with less overhead].")
@click.option("--single-process", "single_process", is_flag=True,
              help="No Dask even if $GISNOISE_DASK_SCHEDULER is set: one process, tiles on threads (same bands). "
                   "The default without --scheduler and --workers.")
@click.option("--threads", "threads", type=click.IntRange(min=1), default=None,
              help="Threads of the one-process run [default: $GISNOISE_THREADS, else the CPUs].")
@click.option("--tile-cells", "tile_cells", type=click.IntRange(min=1), default=None,
              help="Cells per tile: the unit of work and of memory per task [default: 262144 (2^18); in one "
                   "process also small enough for eight tiles a thread].")
@click.option("--memory-limit", "memory_limit", default=None,
              help="Memory per worker of a local cluster, e.g. 2GiB [default: Dask's].")
@click.option("--levels", "levels", default=None,
              help="Contour levels of Lden and Lnight, dB(A), comma-separated [default: the schedule's].")
@click.option("--plot", "plot", is_flag=True, help="Also draw DIR/map.png: Lden with its contours.")
@click.option("--population", "population", type=click.Path(dir_okay=False), default=None,
              help="Population raster (GeoTIFF, people per cell, any CRS): also write DIR/exposure.json and "
                   "exposure.md (people by 5 dB class of Lden, Lday, Levening, Lnight, LAmax and by events of NA<L>).")
@click.option("--buildings", "buildings", type=click.Path(dir_okay=False), default=None,
              help="Buildings with residents/dwellings (GeoPackage, GeoJSON, Shapefile): the same at each building's "
                   "most exposed façade, and the levels at the most exposed storey of those with a height or "
                   "building:levels, in DIR/exposure.json and exposure.md (flat ground only).")
@click.option("--facade-height", "facade_height", type=click.FloatRange(min=0.0, min_open=True), default=4.0,
              show_default=True, help="Height of façade receivers above ground, m.")
@building_field_options
@click.pass_context
def command(ctx: click.Context, schedule: str, out: str, scheduler: str | None, workers: int | None,
            single_process: bool, threads: int | None, tile_cells: int | None, memory_limit: str | None, levels: str | None,
            plot: bool, population: str | None = None, buildings: str | None = None,
            facade_height: float = 4.0, layer: str | None = None, residents_field: str | None = None,
            dwellings_field: str | None = None, height_field: str | None = None, levels_field: str | None = None,
            storey_height: float = 3.0) -> None:
    """Noise of a day of operations: DIR/operations.tif, DIR/contours.geojson, DIR/summary.json.

    SCHEDULE is a JSON file (schema gisnoise/operations/1): model cards, the receiver grid
    (or resolution and margin around the flights), ground, thresholds and the flights, each
    a trajectory file with counts per period {"day", "evening", "night"} or departure
    clock times ("HH:MM[:SS]", or a number of hours after midnight: 7.5 is 07:30).  Periods and
    Lden follow EU Directive 2002/49/EC (day 07-19, evening 19-23 +5 dB, night 23-07 +10 dB).
    Bands: Lden, Lday, Levening, Lnight, LAmax, and per threshold L: NA<L>_<period>, NA<L>
    (flights with LAmax above L) and TA<L>_<period>, TA<L> (time above L, s).

    Each flight is checked as its own map would be.  A ground_h_m above a flight's lowest
    flying point is refused; a flight whose own ground (its route's, or its take-off or landing
    point) lies so far from the day's flat ground that its levels under the track move by more
    than 1 dB is named in a warning (the schedule's ground_h_m, or without it the lowest of the
    flights' grounds); a dem maps each flight over its own ground.  Warnings go to stderr, also
    with -q, which leaves out the grid, the bands' maxima and the files written.

    \b
    Examples:
      gisnoise operations day.json --out ops/                   this machine, threads
      gisnoise operations day.json --out ops/ --workers 4       local Dask cluster
      gisnoise operations day.json --out ops/ --scheduler tcp://sched:8786

    Dask's own log lines show with -v only.
    """
    import logging
    import os

    from gisnoise.maps import parse_levels
    from gisnoise.ops import evaluate_operations, load_schedule, write_operations

    if single_process and (scheduler or workers):
        raise click.UsageError("--single-process excludes --scheduler and --workers")
    if logging.getLogger().getEffectiveLevel() > logging.INFO:  # without -v: no Dask chatter, no shutdown noise
        for name in ("distributed", "tornado", "asyncio", "bokeh"):
            logging.getLogger(name).setLevel(logging.CRITICAL)
        # Dask sets its loggers' levels from its configuration when distributed is imported (after the lines
        # above), in this process and in a local cluster's worker processes: the same setting through the
        # environment reaches them all
        os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "error")
    sched = load_schedule(schedule)
    lv = None if levels is None else parse_levels(levels, field="levels")
    pop = bld = None
    if population or buildings:  # read the layers first: a bad layer costs no evaluation
        from gisnoise.exposure import read_buildings, read_population

        if buildings and sched.dem is not None:
            raise InputError("buildings: façade levels need flat ground; the schedule gives a DEM", field="buildings")
        pop = read_population(population) if population else None
        bld = read_buildings(buildings, layer=layer, residents=residents_field, dwellings=dwellings_field,
                             height=height_field, levels=levels_field) if buildings else None
    with progress(ctx, "operations", 1.0) as update:
        res = evaluate_operations(sched, scheduler=scheduler, workers=workers, single_process=single_process,
                                  threads=threads,
                                  tile_cells=tile_cells, memory_limit=memory_limit, progress=update)
    paths = write_operations(res, out, lv, plot=plot,
                             tracks=[(f.id, f.trajectory) for f in sched.flights if f.total > 0])
    exposed: list[str] = []
    if pop is not None or bld is not None:
        from gisnoise.exposure import operations_exposure, write_exposure

        doc = operations_exposure(res, sched, population=pop, buildings=bld, facade_height_m=facade_height,
                                  storey_height_m=storey_height)
        ex = write_exposure(doc, out)
        paths["exposure"], paths["table"] = ex["exposure"], ex["table"]
        exposed = [f"exposure: {w}" for w in doc.get("warnings", [])]
    from gisnoise.maps import clip_warnings

    contoured = list(lv if lv is not None else sched.levels_db)
    # warnings say where the answers may be wrong: printed with -q too
    echo_warnings(res.metadata["warnings"] + (clip_warnings(res, contoured, metrics=["Lden", "Lnight"])
                                              if contoured else []) + exposed)
    if (ctx.find_root().obj or {}).get("quiet"):  # -q: the grid, the bands' maxima and the files are in the files
        return
    g = res.grid
    ex = res.metadata["execution"]
    how = (f"Dask ({ex['workers']} workers, {ex['tasks']} tasks)" if ex["executor"] == "dask"
           else f"{ex['threads']} threads")
    nf = len(res.metadata["flights"])
    click.echo(f"grid: {g.width} x {g.height} cells of {g.resolution[0]:g} m; {nf} flight{'s' if nf != 1 else ''}; "
               f"{res.metadata['tiles']} tiles on {how}")
    _echo_bands_and_files(res, paths, ("levels", "contours", "summary", "map", "exposure", "table"))
