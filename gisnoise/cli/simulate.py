"""``gisnoise simulate``: a synthetic measurement campaign from a scenario."""

from __future__ import annotations

import click

from gisnoise.cli.options import progress
from gisnoise.simulate import load_scenario, simulate


@click.command("simulate")
@click.argument("scenario", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(file_okay=False),
              help="Campaign folder to write (created; must be new or empty unless --overwrite).")
@click.option("--seed", type=int, default=None, help="Replace the scenario's seed.")
@click.option("--format", "fmt", type=click.Choice(["levels", "wav"]), default=None,
              help="Replace the scenario's output format: level CSVs with bands, or WAV audio.")
@click.option("--overwrite", is_flag=True, help="Write into a non-empty folder.")
@click.pass_context
def command(ctx: click.Context, scenario: str, out: str, seed: int | None, fmt: str | None, overwrite: bool) -> None:
    """Simulate a measurement campaign (flight logs, microphone levels or WAV, truth.json).

    SCENARIO is a JSON file with schema gisnoise/scenario/1 (examples in
    sample_data/scenarios/): vehicle and truth cards, flight patterns, microphones,
    weather, noise, background and injected effects.  The campaign folder can be read
    by `gisnoise fit`, `gisnoise diagnose` and `gisnoise campaign check`.
    """
    doc = load_scenario(scenario)
    if seed is not None:
        doc["seed"] = seed
    if fmt is not None:
        doc.setdefault("output", {})
        if isinstance(doc["output"], dict):
            doc["output"]["format"] = fmt
    with progress(ctx, "simulating", 100.0) as update:
        path = simulate(doc, out, progress=lambda f: update(100.0 * f), overwrite=overwrite)
    if not (ctx.find_root().obj or {}).get("quiet"):
        click.echo(f"wrote {path}")
