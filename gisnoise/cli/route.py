"""``gisnoise route optimize``: a quieter flyable route between two pads, compared with the direct route."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from gisnoise.cli.options import card_option, out_dir_option, progress
from gisnoise.errors import InputError


def _lonlat(value: str, name: str) -> tuple[float, float]:
    try:
        lon, lat = (float(v) for v in value.split(","))
    except ValueError:
        raise click.BadParameter(f"expected LON,LAT in degrees, got {value!r}", param_hint=name) from None
    if not (-180 <= lon <= 180 and -90 <= lat <= 90):
        raise click.BadParameter(f"LON,LAT out of range: {value!r}", param_hint=name)
    return lon, lat


def _read_avoid(path: str) -> list[Any]:
    import geopandas as gpd

    try:
        df = gpd.read_file(path, engine="pyogrio")
    except Exception as exc:  # pyogrio's errors are many; the message names the file
        raise InputError(f"avoid: cannot read {path}: {str(exc).splitlines()[0]}", field="avoid") from None
    if df.crs is None:
        raise InputError(f"avoid: {path} has no CRS", field="avoid")
    df = df.to_crs(4326)
    out = []
    for i, g in enumerate(df.geometry):
        if g is None or g.geom_type not in ("Polygon", "MultiPolygon"):
            raise InputError(f"avoid: feature {i} is not a polygon", field="avoid")
        out.extend(list(g.geoms) if g.geom_type == "MultiPolygon" else [g])
    return out


@click.group("route")
def command() -> None:
    """Route planning: a quieter route between two pads."""


@command.command("optimize")
@click.option("--from", "start", required=True, help="Take-off pad LON,LAT (deg).")
@click.option("--to", "goal", required=True, help="Landing pad LON,LAT (deg).")
@card_option
@out_dir_option
@click.option("--population", "population", type=click.Path(dir_okay=False), default=None,
              help="Population raster (GeoTIFF, people per cell, any CRS).")
@click.option("--buildings", "buildings", type=click.Path(dir_okay=False), default=None,
              help="Building polygons with residents or dwellings.")
@click.option("--avoid", "avoid", type=click.Path(dir_okay=False), default=None,
              help="No-fly polygons (GeoJSON, GeoPackage, Shapefile).")
@click.option("--altitude", "altitude", type=float, default=60.0, show_default=True,
              help="Cruise altitude above ground, m.")
@click.option("--max-detour", "max_detour", type=float, default=30.0, show_default=True,
              help="Longest route as percent more than the direct distance.")
@click.option("--turn-radius", "turn_radius", type=float, default=None,
              help="Smallest turn radius, m [default: the vehicle's v^2 / (g tan(max bank))].")
@click.option("--rank-level", "rank_level", type=float, default=55.0, show_default=True,
              help="Minimize the people above this LAmax, dB(A).")
@click.option("--resolution", "resolution", type=float, default=50.0, show_default=True,
              help="Cost grid cell, m.")
@click.option("--ground-height", "ground_h", type=float, default=0.0, show_default=True,
              help="Ellipsoidal height of flat ground, m.")
@click.pass_context
def optimize(ctx: click.Context, start: str, goal: str, cards: tuple[str, ...], out: str, population: str | None,
             buildings: str | None, avoid: str | None, altitude: float, max_detour: float,
             turn_radius: float | None, rank_level: float, resolution: float, ground_h: float) -> None:
    """Least-exposure flyable route from --from to --to, re-evaluated against the direct route.

    Writes DIR/route.geojson (waypoints of the optimized route, readable by `gisnoise contour`),
    DIR/direct.geojson, DIR/optimize.json (method, lengths, people above the level of both)
    and the comparison (comparison.json, comparison.md, levels.tif, difference.tif).
    When the searched route is not better than the direct one by the comparison's ranking
    (a tie is not better), the direct route is kept: route.geojson holds it and one line says so.
    Both pads must lie within the population raster, on cells with data.
    """
    from gisnoise.exposure import read_buildings, read_population
    from gisnoise.planning import optimize_route, waypoints_geojson, write_comparison

    if population is None and buildings is None:
        raise InputError("route optimize: give --population and/or --buildings", field="population")
    s, g = _lonlat(start, "--from"), _lonlat(goal, "--to")
    pop = read_population(population) if population else None
    b = read_buildings(buildings) if buildings else None
    polys = _read_avoid(avoid) if avoid else []
    with progress(ctx, "searching and comparing", 1.0) as update:
        res = optimize_route(s, g, list(cards), population=pop, buildings=b, avoid=polys, altitude_m=altitude,
                             max_detour_pct=max_detour, turn_radius_m=turn_radius, rank_level_db=rank_level,
                             resolution_m=resolution, ground_h=ground_h, progress=update)
    o = Path(out)
    paths = write_comparison(res.comparison, o)
    for name, doc in (("route.geojson", res.optimized_doc), ("direct.geojson", res.direct_doc)):
        (o / name).write_text(json.dumps(waypoints_geojson(doc, name=name.split(".")[0]), indent=1))
    (o / "optimize.json").write_text(json.dumps(res.summary, indent=1))
    for w in res.comparison.doc["warnings"]:  # each route checked as its map would be, and clipped counts
        click.echo(f"warning: {w}", err=True)
    sm = res.summary
    key = f"{rank_level:g}"
    if sm["kept_direct"]:
        click.echo(sm["note"])
    else:
        click.echo(f"direct {sm['direct_length_m']:.0f} m, optimized {sm['optimized_length_m']:.0f} m "
                   f"(+{sm['detour_pct']:.1f} %, limit {max_detour:g} %), turn radius {sm['turn_radius_m']:.0f} m")
        star = {n: " *" if sm.get(f"lower_bound_{key}_{n}") else "" for n in ("direct", "optimized")}
        said = "; * lower bound: see the warnings" if any(star.values()) else ""
        click.echo(f"people above {key} dB(A) LAmax: direct {sm[f'people_above_{key}_direct']:.0f}{star['direct']}, "
                   f"optimized {sm[f'people_above_{key}_optimized']:.0f}{star['optimized']} "
                   f"({sm['reduction_pct']:.1f} % fewer{said})")
    for p in [*paths.values(), o / "route.geojson", o / "direct.geojson", o / "optimize.json"]:
        click.echo(f"wrote {p}")
