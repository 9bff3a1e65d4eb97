"""``gisnoise design``: microphone positions and flight altitudes for an identifiable campaign."""

from __future__ import annotations

import click

from gisnoise.cli.options import echo_warnings, progress


@click.command("design")
@click.argument("plan", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder (created): design.json, layout.geojson, report.html and figures.")
@click.option("--objective", "objectives", multiple=True, type=click.Choice(["paper", "d-optimal"]),
              help="Objective to optimize (repeat for both; default: the plan's objectives).")
@click.option("--study/--no-study", default=True, show_default=True,
              help="Run the plan's study: optimum against allowed displacement for several altitude ranges (Fig. 18).")
@click.option("--verify", "verify_seeds", type=click.IntRange(0, 10000), default=None,
              help="Closing-the-loop campaigns per design (simulated and refitted); default the plan's verify.seeds.")
@click.option("--seed", type=int, default=None, help="Replace the optimizer's seed.")
@click.option("--no-report", is_flag=True, help="Write design.json and layout.geojson only (no figures).")
@click.pass_context
def command(ctx: click.Context, plan: str, out: str, objectives: tuple[str, ...], study: bool,
            verify_seeds: int | None, seed: int | None, no_report: bool) -> None:
    """Optimize microphone positions and altitudes of a measurement campaign (paper section 6).

    PLAN is a JSON file with schema gisnoise/design-plan/1 (example:
    sample_data/plans/paper_racetrack.json): racetrack pattern, repetitions with their
    altitude ranges, microphones with their allowed displacement, exclusion polygons
    (GeoJSON, lon/lat), signal-to-noise margin and the model card.  Writes the optimized
    layout and altitudes (design.json, layout.geojson), the objective of the base and of
    each optimum, and a report with the paper's views.
    """
    from gisnoise.design import load_plan, run_design, write_outputs

    p = load_plan(plan)
    if seed is not None:
        doc = dict(p.doc)
        doc["optimizer"] = {**doc["optimizer"], "seed": seed}
        from gisnoise.design import resolve_plan

        p = resolve_plan(doc, card=p.card)
    with progress(ctx, "designing", 100.0) as update:
        res = run_design(p, objectives=list(objectives) or None, with_study=study, verify_seeds=verify_seeds,
                         progress=lambda f: update(100.0 * f))
    files = write_outputs(res, out, report=not no_report)
    echo_warnings(res.warnings)  # -q keeps them
    if not (ctx.find_root().obj or {}).get("quiet"):
        b = res.base
        click.echo(f"base: max |corr| {b.max_abs_corr:.3f}, log det {b.log_det_fisher:.2f}, altitudes "
                   f"{', '.join(f'{a:.0f}' for a in b.design.altitudes)} m")
        for name, o in res.optima.items():
            ev = o.evaluation
            click.echo(f"{name} optimum: max |corr| {ev.max_abs_corr:.3f}, log det {ev.log_det_fisher:.2f}, altitudes "
                       f"{', '.join(f'{a:.0f}' for a in ev.design.altitudes)} m")
        if res.verify is not None and "d-optimal" in res.verify.estimates:
            g = res.verify.geometric_mean_ratio("d-optimal")
            click.echo(f"closing the loop ({len(res.verify.seeds)} seeds): d-optimal campaigns scatter "
                       f"{1 / g:.1f} times less than base ones (geometric mean std ratio {g:.3f})")
        click.echo(f"wrote {', '.join(sorted(files))} to {out}")
