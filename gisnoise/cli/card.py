"""``gisnoise card``: look at model cards (show their content, plot their directivity)."""

from __future__ import annotations

import json
import math

import click
import numpy as np

from gisnoise.cli.options import echo_warnings
from gisnoise.errors import InputError
from gisnoise.jsonio import to_jsonable
from gisnoise.model import HemisphereCard, fit_hemisphere, import_hemisphere, import_warnings, sample_card
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

    if not (0 < p_el <= 100):  # a level summary at no or negative power is no summary: refused, not dropped
        raise InputError(f"p_el: must be in (0, 100] (nondimensional power), got {p_el:g}", field="p_el")
    c = gcards.load(card, force=force)
    if force:
        for problem in card_problems(c):
            click.echo(f"IMPLAUSIBLE: {problem}", err=True)
    if as_json:
        click.echo(gcards.dumps(c), nl=False)
        return
    model = c.model
    if isinstance(c, HemisphereCard):
        _show_hemisphere(c)
        return
    click.echo(f"card      {c.id}")
    click.echo(f"vehicle   {c.vehicle}")
    click.echo(f"phases    {', '.join(c.served_phases)}")
    click.echo(f"ansatz    {c.ansatz}: {model.description}")
    click.echo(f"reference power {c.reference_power_w:g} W, reference distance {c.reference_distance_m:g} m")
    std = c.std
    click.echo("parameters" + ("" if std else " (no covariance)"))
    held = (c.provenance or {}).get("held_parameters") or {}
    fixed = (c.statistics or {}).get("fixed") or {}
    for k in model.params:
        v = c.parameters[k]
        s = f"  +- {std[k]:.4g}" if std else ""
        if k in held:  # not estimated: a zero row of the covariance, not a value known exactly
            s = f"  held: {held[k]}"
        elif k in fixed and std and std[k] == 0.0:
            s = "  fixed"
        click.echo(f"  {k:>4} = {v: .6g} [{model.unit(k) or '?'}]{s}")
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


def _show_hemisphere(c: HemisphereCard) -> None:
    """Summary of a measured hemisphere card."""
    click.echo(f"card      {c.id} (measured hemisphere)")
    click.echo(f"vehicle   {c.vehicle}")
    click.echo(f"phases    {', '.join(c.served_phases)}")
    cond = ", ".join(f"{k} {v:g}" if isinstance(v, (int, float)) else f"{k} {v}" for k, v in c.condition.items())
    click.echo(f"condition {cond or 'not stated'}")
    click.echo(f"table     {c.phi_deg.size} phi x {c.theta_deg.size} theta nodes (phi {c.phi_deg[0]:g}..{c.phi_deg[-1]:g}, "
               f"theta {c.theta_deg[0]:g}..{c.theta_deg[-1]:g} deg), {c.bands_hz.size} bands "
               f"{c.bands_hz[0]:g}-{c.bands_hz[-1]:g} Hz at radius {c.reference_distance_m:g} m")
    click.echo(f"measured  {int(c.measured.sum())} of {c.measured.size} nodes (the others filled)")
    a = c.atmosphere
    click.echo(f"atmosphere {a['temperature_c']:g} C, {a['humidity_pct']:g} % RH, {a['pressure_kpa']:g} kPa "
               "(back-propagation)")
    m = c.propagation_atmosphere
    click.echo(f"on maps   {m['temperature_c']:g} C, {m['humidity_pct']:g} % RH, {m['pressure_kpa']:g} kPa "
               "(ISO 9613-1 absorption)")
    w = c.sound_power_db()
    click.echo(f"sound power {w['overall_z']:.1f} dB, {w['overall_a']:.1f} dB(A) (re 1 pW: the table over the whole "
               f"sphere by solid angle, its upper half mirrored; the lower half alone {w['lower_half_z']:.1f} dB, "
               f"{w['lower_half_a']:.1f} dB(A))")
    own = c.statistics.get("file_sound_power_db", {}).get("Overall")
    if own is not None:
        click.echo(f"          the file states {own:.1f} dB for the lower half (its SWL_Bands: the nodes' mean square "
                   "pressure times 2 pi r^2, every node weighted alike, not by solid angle)")
    for w_ in import_warnings(c):
        click.echo(f"coverage  {w_}")
    top = c.loudest_direction()
    click.echo(f"max level {top['level_db_a']:.1f} dB(A) at {c.reference_distance_m:g} m, phi {top['phi_t_deg']:g} deg "
               f"({'ahead' if top['phi_t_deg'] < 0 else 'behind' if top['phi_t_deg'] > 0 else 'below'}), "
               f"theta {top['theta_t_deg']:g} deg ({'measured' if top['measured'] else 'filled'} node)")
    if c.notes:
        click.echo(f"notes     {c.notes}")


@command.command("import-hemisphere")
@click.argument("file", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Card file to write (JSON).")
@click.option("--id", "card_id", default=None, help="Card id (default: the file's stem).")
@click.option("--vehicle", default=None, help="Vehicle name (default: from a Salford file name).")
@click.option("--phase", default="horizontal", show_default=True, help="Flight phase the hemisphere stands for.")
@click.option("--also-phase", "also", multiple=True, help="Further phases the card serves (repeatable).")
@click.option("--radius", "radius", type=float, default=None,
              help="Radius of the table, m (default: the file's, else 1 m; refused against a radius the file states).")
@click.option("--temperature", type=float, default=None,
              help="Temperature of the back-propagation, C (Salford files: 25).")
@click.option("--humidity", type=float, default=None, help="Relative humidity of the back-propagation, %.")
@click.option("--pressure", type=float, default=101.325, show_default=True, help="Static pressure, kPa.")
@click.option("--measured-theta-max", type=float, default=60.0, show_default=True,
              help="Without a 'measured' column: nodes with |theta| above this were filled (deg).")
@click.option("--power", type=float, default=None, help="Electric power of the flight condition, W (recorded).")
@click.option("--force", is_flag=True, help="Overwrite --out.")
def import_hemisphere_cmd(file: str, out: str, card_id: str | None, vehicle: str | None, phase: str,
                          also: tuple[str, ...], radius: float | None, temperature: float | None,
                          humidity: float | None, pressure: float, measured_theta_max: float, power: float | None,
                          force: bool) -> None:
    """Make a hemisphere card from a measured hemisphere FILE: a Salford xlsx or a long-form CSV.

    CSV columns: band (nominal one-third-octave Hz), phi_deg (along the track, negative ahead),
    theta_deg (across it, positive starboard), level_db (SPL at the radius), optional radius_m
    and measured (1/0).  Angles in degrees as in the Salford hemispheres: 0 straight below, +-90 at
    the horizon.  Refused before anything is written: angles in radians, a band missing between the
    lowest and the highest, bands below 10 Hz, a card the maps would refuse (radius 1 m - 1 km,
    levels at 40 m -20..160 dB(A)).

    Maps read the table in the body frame: the flight's logged roll and pitch turn it.  A
    Salford table's angles are geometric, relative to the track, with the measured flight's own
    attitude inside them; a flight logged with a strong pitch reads other nodes than the
    measurement did at that geometry (pitch -10 deg: straight below reads phi -10 deg).
    """
    atm = None
    if (temperature is None) != (humidity is None):
        raise click.UsageError("give both --temperature and --humidity")
    if temperature is not None and humidity is not None:
        atm = {"temperature_c": temperature, "humidity_pct": humidity, "pressure_kpa": pressure}
    c = import_hemisphere(file, card_id=card_id, vehicle=vehicle, phase=phase, phases=also, radius_m=radius,
                          atmosphere=atm, measured_theta_max=measured_theta_max, reference_power_w=power)
    path = gcards.save(c, out, overwrite=force)
    click.echo(f"wrote {path}: {c.phi_deg.size} x {c.theta_deg.size} nodes, {c.bands_hz.size} bands, "
               f"{int(c.measured.sum())} nodes measured")
    echo_warnings(import_warnings(c))


@command.command("set-atmosphere")
@click.argument("hemisphere", type=click.Path(dir_okay=False))
@click.option("--temperature", type=float, required=True, help="Air temperature on the map, C.")
@click.option("--humidity", type=float, required=True, help="Relative humidity on the map, %.")
@click.option("--pressure", type=float, default=101.325, show_default=True, help="Static pressure, kPa.")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Card file to write.")
@click.option("--force", is_flag=True, help="Overwrite --out.")
def set_atmosphere_cmd(hemisphere: str, temperature: float, humidity: float, pressure: float, out: str,
                       force: bool) -> None:
    """Copy a HEMISPHERE card to propagate through another atmosphere on maps (ISO 9613-1 absorption)."""
    h = gcards.load(hemisphere)
    if not isinstance(h, HemisphereCard):
        raise click.BadParameter("not a hemisphere card", param_hint="HEMISPHERE")
    path = gcards.save(h.in_atmosphere(temperature, humidity, pressure), out, overwrite=force)
    click.echo(f"wrote {path}: map atmosphere {temperature:g} C, {humidity:g} % RH, {pressure:g} kPa")


@command.command("fit-hemisphere")
@click.argument("hemisphere", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Card file to write (JSON).")
@click.option("--distance", type=float, default=40.0, show_default=True,
              help="Distance at which the table's levels are fitted, m.")
@click.option("--force", is_flag=True, help="Overwrite --out.")
def fit_hemisphere_cmd(hemisphere: str, out: str, distance: float, force: bool) -> None:
    """Fit the paper ansatz (paper-offset) to the measured nodes of a HEMISPHERE card; prints the residual."""
    h = gcards.load(hemisphere)
    if not isinstance(h, HemisphereCard):
        raise click.BadParameter("not a hemisphere card", param_hint="HEMISPHERE")
    c = fit_hemisphere(h, distance_m=distance)
    path = gcards.save(c, out, overwrite=force)
    st = c.statistics
    click.echo(f"wrote {path}: residual RMS {st['residual_rms_db']:.2f} dB, max {st['residual_max_db']:.2f} dB "
               f"over {st['n_nodes']} measured nodes at {distance:g} m")


@command.command("sample-hemisphere")
@click.argument("card", type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Hemisphere card to write.")
@click.option("--p-el", "p_el", type=float, default=1.0, show_default=True, help="Nondimensional power.")
@click.option("--radius", type=float, default=None, help="Radius, m (default: the card's reference distance).")
@click.option("--force", is_flag=True, help="Overwrite --out.")
def sample_hemisphere_cmd(card: str, out: str, p_el: float, radius: float | None, force: bool) -> None:
    """Sample a parametric CARD into a hemisphere card (15 deg table angles) to compare it with a measured one."""
    h = sample_card(gcards.load(card), p_el=p_el, radius_m=radius)
    path = gcards.save(h, out, overwrite=force)
    click.echo(f"wrote {path}: {h.phi_deg.size} x {h.theta_deg.size} nodes at {h.reference_distance_m:g} m")


@command.command("plot")
@click.argument("card", type=click.Path(dir_okay=False))
@click.option("--p-el", "p_el", type=float, default=1.1, show_default=True,
              help="Nondimensional electric power (the paper's Fig. 7: 1.1, Fig. 9: 6.5); a measured hemisphere "
                   "has no power term.")
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
