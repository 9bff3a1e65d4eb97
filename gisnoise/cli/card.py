"""``gisnoise card``: look at model cards (show their content, plot their directivity)."""

from __future__ import annotations

import json
import math

import click
import numpy as np

from gisnoise.jsonio import to_jsonable
from gisnoise.model import cards as gcards


@click.group("card")
def command() -> None:
    """Model cards: show a card, plot its directivity."""


@command.command("show")
@click.argument("card", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the card as JSON (validated, normalised).")
@click.option("--p-el", "p_el", type=float, default=1.1, show_default=True,
              help="Nondimensional power for the level summary (the paper's Fig. 7: 1.1).")
@click.option("--force", "force", is_flag=True,
              help="Show an implausible card for inspection (it is still refused by fit, maps, service, QGIS).")
def show(card: str, as_json: bool, p_el: float, force: bool = False) -> None:
    """Print CARD: phases, ansatz, parameters with standard deviations, statistics, provenance, notes."""
    from gisnoise.maps import directivity_grid
    from gisnoise.model import card_problems

    c = gcards.load(card, force=force)
    if force:
        for problem in card_problems(c):
            click.echo(f"IMPLAUSIBLE: {problem}", err=True)
    if as_json:
        click.echo(gcards.dumps(c), nl=False)
        return
    model = c.model
    click.echo(f"card      {c.id}")
    click.echo(f"vehicle   {c.vehicle}")
    click.echo(f"phases    {', '.join(c.served_phases)}")
    click.echo(f"ansatz    {c.ansatz}: {model.description}")
    click.echo(f"reference power {c.reference_power_w:g} W, reference distance {c.reference_distance_m:g} m")
    std = c.std
    click.echo("parameters" + ("" if std else " (no covariance)"))
    for k in model.params:
        v = c.parameters[k]
        s = f"  +- {std[k]:.4g}" if std else ""
        click.echo(f"  {k:>4} = {v: .6g}{s}")
    cov = c.cov
    if cov is not None:
        d = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = cov / np.outer(d, d)
        pairs = [(abs(corr[i, j]), model.params[i], model.params[j], corr[i, j])
                 for i in range(len(d)) for j in range(i + 1, len(d)) if np.isfinite(corr[i, j])]
        pairs.sort(reverse=True)
        if pairs:
            click.echo("strongest correlations: " + ", ".join(f"{a}-{b} {r:+.2f}" for _, a, b, r in pairs[:3]))
    if p_el > 0 and math.isfinite(p_el) and all(n in ("d", "phi", "theta", "p_el") for n in model.inputs):
        phi, theta, lvl = directivity_grid(c, p_el=p_el, distance_m=c.reference_distance_m, n_phi=181, n_theta=91)
        i, j = np.unravel_index(np.argmax(lvl), lvl.shape)
        where = (f"max at azimuth {phi[j]:.0f} deg, polar {theta[i]:.0f} deg" if np.ptp(lvl) > 1e-6
                 else "no directivity")
        click.echo(f"L_UAV at {c.reference_distance_m:g} m, P_el = {p_el:g}: {lvl.min():.1f} to {lvl.max():.1f} dB(A) "
                   f"over all emission angles ({where})")
    if c.statistics:
        short = {k: v for k, v in c.statistics.items() if len(json.dumps(to_jsonable(v))) <= 120}
        more = len(c.statistics) - len(short)
        click.echo("statistics " + json.dumps(to_jsonable(short))
                   + (f" (+{more} longer entries: --json)" if more else ""))
    if c.provenance:
        click.echo("provenance " + json.dumps(to_jsonable(c.provenance)))
    if c.notes:
        click.echo(f"notes     {c.notes}")


@command.command("plot")
@click.argument("card", type=click.Path(dir_okay=False))
@click.option("--p-el", "p_el", type=float, default=1.1, show_default=True,
              help="Nondimensional electric power (the paper's Fig. 7: 1.1, Fig. 9: 6.5).")
@click.option("--distance", "distance", type=float, default=30.0, show_default=True,
              help="Source-observer distance, m.")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Output PNG.")
def plot(card: str, p_el: float, distance: float, out: str) -> None:
    """Plot the directivity of CARD: L_UAV over azimuth and polar angle at one distance and power."""
    from gisnoise.maps import plot_directivity

    c = gcards.load(card)
    path = plot_directivity(c, out, p_el=p_el, distance_m=distance)
    click.echo(f"wrote {path}")


@command.command("list")
def list_cards() -> None:
    """List the cards the package bundles: id, phase, vehicle and the file it is in.

    Any of these ids can be given where a card file is asked for (``--card demo-horizontal``).
    """
    from gisnoise.data import bundled_card_ids, card_path

    for cid in bundled_card_ids():
        c = gcards.load(card_path(cid))
        click.echo(f"{cid:<22} {c.phase:<11} {c.vehicle[:28]:<28} {card_path(cid)}")
