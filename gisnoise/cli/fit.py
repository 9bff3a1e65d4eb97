"""``gisnoise fit``: identify a model card from a measurement campaign."""

from __future__ import annotations

import math

import click

from gisnoise.cli.options import echo_warnings, progress
from gisnoise.errors import InputError
from gisnoise.model import PHASES, load, save
from gisnoise.model.cards import SCHEMA_PREFIX


def _check_out(out: str, force: bool) -> None:
    """Refuse an --out that exists, before the fit: a model card unless ``force`` (as the ``card``
    commands), anything else (the campaign's campaign.json, say) always: the card replaces an older
    card, never another file."""
    import json
    from pathlib import Path

    p = Path(out)
    if not p.exists():
        return
    what = "a folder" if p.is_dir() else "not a model card"
    if p.is_file():
        try:
            doc = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            doc = None
        if isinstance(doc, dict) and str(doc.get("schema", "")).startswith(SCHEMA_PREFIX):
            if force:
                return
            raise InputError(f"--out {out}: exists; refusing to overwrite (--force overwrites it)", field="out")
        if isinstance(doc, dict) and doc.get("schema"):
            what = f"a {doc['schema']} document, not a model card"
    raise InputError(f"--out {out}: exists and is {what}; refusing to write the card over it", field="out")


def _parse_fix(items: tuple[str, ...]) -> dict[str, float]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            v = float(value)
        except ValueError:
            v = math.nan
        if not sep or not name or not math.isfinite(v):
            raise InputError(f"--fix expects NAME=VALUE with a finite number, got {item!r}", field="fix")
        out[name.strip()] = v
    return out


@click.command("fit")
@click.argument("campaign", type=click.Path(file_okay=False))
@click.option("--phase", required=True, type=click.Choice(PHASES), help="Flight phase to fit.")
@click.option("--ansatz", default=None,
              help="Ansatz to fit (default: the --start card's, else paper-offset).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), help="Model card JSON to write.")
@click.option("--force", is_flag=True, help="Overwrite --out when it is a model card.")
@click.option("--report", "report", type=click.Path(file_okay=False), default=None,
              help="Folder for the fit report (PNG, JSON numbers, report.html).")
@click.option("--start", "start", type=click.Path(dir_okay=False), default=None,
              help="Card with start values; also gives the new card's id, vehicle, served phases and notes.")
@click.option("--id", "card_id", default=None, help="Card id (default: <vehicle>-<phase> or the --start card's).")
@click.option("--serves", multiple=True, type=click.Choice(PHASES),
              help="Further phase the card serves (repeat), e.g. --serves transition.")
@click.option("--fix", multiple=True, metavar="NAME=VALUE", help="Hold a parameter at a value (repeat).")
@click.option("--absorption", is_flag=True, help="Correct levels for atmospheric absorption when reading (needs band levels in every microphone file).")
@click.option("--max-iter", default=100, show_default=True, type=click.IntRange(1, 100000),
              help="Maximum Gauss-Newton iterations.")
@click.option("--covariance", type=click.Choice(["corrected", "cramer-rao"]), default="corrected", show_default=True,
              help="Covariance written to the card: corrected for residual autocorrelation, or the Cramer-Rao bound.")
@click.pass_context
def command(ctx: click.Context, campaign: str, phase: str, ansatz: str | None, out: str, report: str | None,
            start: str | None, card_id: str | None, serves: tuple[str, ...], fix: tuple[str, ...], absorption: bool,
            max_iter: int, covariance: str, force: bool) -> None:
    """Fit a model card to a measurement campaign (output-error maximum likelihood).

    CAMPAIGN is a campaign folder (campaign.json, flights/, mics/).  The usable samples
    of --phase are fitted with one noise variance per microphone; the card gets the
    parameters, their covariance, fit statistics and provenance.  A fit that does not
    converge, or whose parameters the data cannot tell apart, writes no card and
    says why.  An existing --out is refused unless it is a model card and --force is given.
    """
    from gisnoise.identify import fit_campaign
    from gisnoise.measure import campaign_log_warnings, read_campaign

    quiet = bool((ctx.find_root().obj or {}).get("quiet"))
    _check_out(out, force)
    if card_id is not None:
        from gisnoise.limits import check_id

        check_id(card_id, field="--id")
    template = load(start) if start else None
    name = ansatz or (template.ansatz if template else "paper-offset")
    fixed = _parse_fix(fix)
    camp = read_campaign(campaign, absorption=absorption)
    echo_warnings(campaign_log_warnings(camp))  # a log cut short is fitted up to its cut, and said
    with progress(ctx, f"fitting {phase}", float(max_iter)) as update:
        res = fit_campaign(camp, phase, name, p0=template, fixed=fixed or None, max_iter=max_iter,
                           progress=lambda i, cost: update(float(i)))
    echo_warnings(res.info.get("warnings") or [])  # a microphone the model misses alone: said, the card written
    card = res.to_card(template, id=card_id, phase=phase, phases=list(serves) if serves else None,
                       covariance=covariance)
    path = save(card, out, overwrite=force)  # a card written there during the fit is not replaced either
    if report:
        from gisnoise.identify import write_report

        write_report(res, report)
    if not quiet:
        click.echo(res.summary())
        click.echo(f"wrote {path}" + (f" and the report in {report}" if report else ""))
