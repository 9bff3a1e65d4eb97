"""``gisnoise exposure``: people and dwellings by 5 dB class of a written map, area above each level."""

from __future__ import annotations

from pathlib import Path

import click

from gisnoise.cli.options import building_field_options, echo_warnings
from gisnoise.errors import InputError


def _edges(value: str) -> list[float]:
    try:
        lo, hi = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected LOW,HIGH in dB, got {value!r}", param_hint="--classes") from None
    from gisnoise.exposure import class_edges

    return class_edges(lo, hi)


@click.command("exposure")
@click.argument("map_dir", type=click.Path(exists=True))
@click.option("--population", "population", type=click.Path(dir_okay=False), default=None,
              help="Population raster (GeoTIFF, people per cell, any CRS).")
@click.option("--buildings", "buildings", type=click.Path(dir_okay=False), default=None,
              help="Building polygons (GeoPackage, GeoJSON, Shapefile; courtyards too) with residents, dwellings, "
                   "height or building:levels attributes; needs --trajectory and --card.")
@building_field_options
@click.option("--trajectory", "trajectory", type=click.Path(dir_okay=False), default=None,
              help="The map's trajectory (for façade levels of --buildings).")
@click.option("--schedule", "schedule", type=click.Path(dir_okay=False), default=None,
              help="The schedule of a day of operations whose folder MAP_DIR is (for façade levels of --buildings); "
                   "another schedule (other contents than the one the folder records, or other flights or counts) "
                   "is refused.")
@click.option("--card", "cards", multiple=True, type=click.Path(dir_okay=False),
              help="The map's model cards, one per phase (for façade levels of --buildings).")
@click.option("--facade-height", "facade_height", type=float, default=4.0, show_default=True,
              help="Height of façade receivers above ground, m: the level buildings are classed by.")
@click.option("--facade-spacing", "facade_spacing", type=float, default=5.0, show_default=True,
              help="Longest wall segment per façade receiver, m.")
@click.option("--ground-height", "ground_h", type=float, default=None,
              help="Ellipsoidal height of flat ground for façade receivers, m [default: the map's].")
@click.option("--metrics", "metrics", default=None,
              help="Level bands to class, comma-separated [default: every dB(A) band of the map].")
@click.option("--classes", "classes", default="35,85", show_default=True,
              help="LOW,HIGH: 5 dB classes from LOW; the last class (>= HIGH) is open.")
@click.option("--out", "out", type=click.Path(file_okay=False), default=None,
              help="Folder for exposure.json and exposure.md [default: MAP_DIR].")
@click.pass_context
def command(ctx: click.Context, map_dir: str, population: str | None, buildings: str | None, layer: str | None,
            residents_field: str | None, dwellings_field: str | None, trajectory: str | None,
            cards: tuple[str, ...], facade_height: float, facade_spacing: float, ground_h: float | None,
            metrics: str | None, classes: str, out: str | None, schedule: str | None = None,
            height_field: str | None = None, levels_field: str | None = None, storey_height: float = 3.0) -> None:
    """Exposure of the map in MAP_DIR (its levels.tif, or the GeoTIFF itself): people by 5 dB class
    of each level band (from --population), buildings, residents and dwellings at the most
    exposed façade (from --buildings), area above each level.  Writes exposure.json and exposure.md.

    A folder of `gisnoise operations` (its operations.tif) is classed by Lden, Lday, Levening,
    Lnight, LAmax and the events of each NA<L> band; its buildings need --schedule, the one
    the folder was made from.

    A population raster that does not cover the map where the levels reach the classes (the map
    lies beyond it or on its nodata cells) leaves those people unknown: a warning gives the share
    uncovered and those classes are lower bounds. A raster holding a density (people per km²)
    instead of people per cell is refused. Only the part of the raster under the map is read.
    Buildings whose residents or dwellings are empty (null) are classed without them, said in a
    warning.  Buildings with a height (or building:levels) also get the level at their most exposed
    storey (receivers at the middle of each storey); they are classed at --facade-height.  Warnings
    go to stderr and atop exposure.md; with -q the table and the files written are not printed.
    """
    from gisnoise.exposure import map_exposure, read_buildings, read_levels, read_population, write_exposure

    p = Path(map_dir)
    tif = p / "levels.tif" if p.is_dir() else p
    if p.is_dir() and not tif.is_file() and (p / "operations.tif").is_file():
        tif = p / "operations.tif"
    if not tif.is_file():
        raise InputError(f"map: no levels.tif or operations.tif in {p}", field="map")
    if population is None and buildings is None:
        raise InputError("exposure: give --population and/or --buildings", field="population")
    edges = _edges(classes)
    levels = read_levels(tif)
    pop = read_population(population, within=levels.grid) if population else None  # the part under the map
    b = read_buildings(buildings, layer=layer, residents=residents_field, dwellings=dwellings_field,
                       height=height_field, levels=levels_field) if buildings else None
    if "Lden" in levels.bands:  # a day of operations
        from gisnoise.exposure import operations_exposure

        if metrics:
            raise InputError("metrics: a day of operations is classed by all its level and N-above bands",
                             field="metrics")
        if b is not None and schedule is None:
            raise InputError("buildings: façade levels of a day of operations need --schedule", field="schedule")
        sched = None
        if schedule is not None:
            from gisnoise.ops import load_schedule

            sched = load_schedule(schedule)  # checked against the folder's before anything is written
        doc = operations_exposure(levels, sched, population=pop, buildings=b, edges=edges,
                                  facade_height_m=facade_height, facade_spacing_m=facade_spacing,
                                  storey_height_m=storey_height)
        _written(ctx, doc, write_exposure(doc, out if out is not None else (p if p.is_dir() else p.parent)))
        return
    traj = None
    if b is not None:
        if trajectory is None or not cards:
            raise InputError("buildings: façade levels need --trajectory and --card (the map's flight)",
                             field="trajectory")
        from gisnoise.flight import read_route

        traj = read_route(trajectory).trajectory
    names = [m.strip() for m in metrics.split(",") if m.strip()] if metrics else None
    doc = map_exposure(levels, population=pop, buildings=b, trajectory=traj, cards=list(cards) or None,
                       metrics=names, edges=edges, facade_height_m=facade_height,
                       facade_spacing_m=facade_spacing, ground_h=ground_h, storey_height_m=storey_height)
    _written(ctx, doc, write_exposure(doc, out if out is not None else (p if p.is_dir() else p.parent)))


def _written(ctx: click.Context, doc: dict, paths: dict[str, Path]) -> None:
    """The table and the files written on stdout (not with -q: they are in the files), the warnings on stderr."""
    if not (ctx.find_root().obj or {}).get("quiet"):
        click.echo(paths["table"].read_text().rstrip())
        for v in paths.values():
            click.echo(f"wrote {v}")
    echo_warnings(doc.get("warnings", []))
