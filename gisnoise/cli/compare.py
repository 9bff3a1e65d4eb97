"""``gisnoise compare``: candidate routes ranked by exposure on one common grid, with difference maps."""

from __future__ import annotations

import click

from gisnoise.cli.options import card_option, out_dir_option, progress
from gisnoise.errors import InputError


def _floats(value: str, name: str) -> list[float]:
    try:
        return [float(v) for v in value.split(",") if v.strip()]
    except ValueError:
        raise click.BadParameter(f"expected numbers separated by commas, got {value!r}", param_hint=name) from None


@click.command("compare")
@click.argument("routes", nargs=-1, required=True, type=click.Path(dir_okay=False))
@card_option
@out_dir_option
@click.option("--population", "population", type=click.Path(dir_okay=False), default=None,
              help="Population raster (GeoTIFF, people per cell, any CRS).")
@click.option("--buildings", "buildings", type=click.Path(dir_okay=False), default=None,
              help="Building polygons with residents/dwellings (GeoPackage, GeoJSON, Shapefile).")
@click.option("--metric", "metric", type=click.Choice(["LAmax", "LAeq", "SEL"]), default="LAmax", show_default=True,
              help="Metric the routes are judged by.")
@click.option("--levels", "levels", default="45,50,55,60,65", show_default=True,
              help="Levels for 'people above', dB(A), ascending.")
@click.option("--rank-level", "rank_level", type=float, default=55.0, show_default=True,
              help="Rank by the people above this level first (one of --levels).")
@click.option("--resolution", "resolution", type=float, default=20.0, show_default=True,
              help="Cell size of the common grid, m.")
@click.option("--margin", "margin", type=float, default=None,
              help="Margin around all routes, m [default: from the cards, so that every route's zone above the "
                   "lowest level closes inside the grid, as gisnoise contour].")
@click.option("--crs", "crs", default=None, help="Projected CRS of the grid [default: local UTM].")
@click.option("--ground-height", "ground_h", type=float, default=None,
              help="Ellipsoidal height of flat ground, m, checked against every route as `gisnoise contour` checks "
                   "it [default: stated by the routes (they must agree), else the lowest take-off or landing point "
                   "of those that start or end on the ground].")
@click.option("--period", "period", type=float, default=None,
              help="LAeq only: the averaging period T, s, the same for every route (LAeq,T = SEL - 10 lg T, so "
                   "routes rank as by SEL) [default: the longest route's duration].")
@click.option("--engine", "engine", type=click.Choice(["auto", "numpy", "fast"]), default="auto", show_default=True,
              help="Evaluator engine (auto: the fast one where it serves the cards, as gisnoise contour).")
@click.pass_context
def command(ctx: click.Context, routes: tuple[str, ...], cards: tuple[str, ...], out: str, population: str | None,
            buildings: str | None, metric: str, levels: str, rank_level: float, resolution: float, margin: float | None,
            crs: str | None, ground_h: float | None, period: float | None, engine: str) -> None:
    """Rank candidate ROUTES (two or more trajectory or waypoint files) by the people they expose.

    Every route is evaluated on one grid around all of them, over one flat ground and, for LAeq,
    over one averaging period (stated in the outputs); writes DIR/comparison.json,
    DIR/comparison.md, DIR/levels.tif (one band per route) and DIR/difference.tif (each
    route minus the best, dB). Routes whose scores are equal as the table shows them (whole
    people, whole person-dB, 0.1 dB) share a rank ("tie"); counts that are lower bounds (a zone cut by the grid's
    edge or partly outside the population raster or on its nodata cells) are starred in the table and
    flagged lower_bound in comparison.json.
    """
    from gisnoise.exposure import read_buildings, read_population
    from gisnoise.planning import compare_routes, comparison_table, write_comparison

    if population is None and buildings is None:
        raise InputError("compare: give --population and/or --buildings", field="population")
    pop = read_population(population) if population else None
    b = read_buildings(buildings) if buildings else None
    with progress(ctx, "comparing routes", 1.0) as update:
        cmp = compare_routes(list(routes), list(cards), population=pop, buildings=b, metric=metric,
                             levels=_floats(levels, "--levels"), rank_level_db=rank_level, resolution_m=resolution,
                             margin_m=margin, crs=crs, ground_h=ground_h, engine=engine, period_s=period,
                             progress=update)
    paths = write_comparison(cmp, out)
    click.echo(comparison_table(cmp.doc, warnings=False).rstrip())
    for w in cmp.doc["warnings"]:
        click.echo(f"warning: {w}", err=True)
    for p in paths.values():
        click.echo(f"wrote {p}")
