"""``gisnoise diagnose``: where a card misses a campaign, which effect explains it, how far the gap shrinks."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import click

from gisnoise.cli.options import echo_warnings, progress
from gisnoise.model import load


@click.command("diagnose")
@click.argument("campaign", type=click.Path(file_okay=False))
@click.option("--card", "card_path", required=True, type=click.Path(dir_okay=False),
              help="Model card to diagnose (its ansatz is the base of every candidate extension).")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False),
              help="Output folder: diagnosis.json, report.html and figures.")
@click.option("--effect", "effects", multiple=True,
              help="Candidate effect to test (repeat; default: the whole library).")
@click.option("--alpha", default=0.01, show_default=True, type=click.FloatRange(0.0, 1.0, min_open=True, max_open=True),
              help="Family-wise significance level of the extension tests.")
@click.option("--absorption", is_flag=True, help="Correct levels for atmospheric absorption when reading (needs band levels in every microphone file).")
@click.option("--position-radius", "position_radius", default=50.0, show_default=True, type=click.FloatRange(0.0, 500.0),
              help="Search each microphone's position within this horizontal radius, m, of where the campaign puts "
                   "it (a wrong position is reported, not believed); 0: take the stated positions as they are.")
@click.option("--no-report", is_flag=True, help="Write diagnosis.json only.")
@click.pass_context
def command(ctx: click.Context, campaign: str, card_path: str, out: str, effects: tuple[str, ...], alpha: float,
            absorption: bool, position_radius: float, no_report: bool) -> None:
    """Diagnose the gap between a model card and a measurement campaign.

    CAMPAIGN is a campaign folder (campaign.json, flights/, mics/ with WAV or level
    CSV files).  Writes OUT/diagnosis.json (segments where the card misses, every
    candidate effect with its significance and held-out shrinkage, the verdict)
    and OUT/report.html with the figures.
    """
    from gisnoise.diagnose import check_diagnosable, run_diagnosis, with_mic_heights, write_diagnosis, write_report
    from gisnoise.measure import campaign_log_warnings, read_campaign

    quiet = bool((ctx.find_root().obj or {}).get("quiet"))
    card = load(card_path)
    check_diagnosable(card)  # before the campaign is read
    camp = read_campaign(campaign, absorption=absorption)
    echo_warnings(campaign_log_warnings(camp))  # a log cut short is diagnosed up to its cut, and said
    samples = with_mic_heights(camp.samples(), campaign)
    names = list(effects) or None
    n_steps = 3 + (len(names) if names else 8)
    with progress(ctx, "diagnosing", float(n_steps)) as update:
        diag = run_diagnosis(samples, card, candidates=names, alpha=alpha, position_radius_m=position_radius,
                             progress=lambda done, total, what: update(float(done)))
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    path = write_diagnosis(diag, folder, campaign=str(campaign))
    if not no_report:
        with progress(ctx, "writing the report", 1.0) as update:
            write_report(diag, folder, progress=lambda done, total: update(done / max(total, 1)))
    if not quiet:
        for sentence in (diag.result.get("metadata") or {}).get("contradictions") or []:
            click.echo(f"campaign: {sentence}")
        click.echo(_card_line(card.parameters, diag.result.get("baseline") or {}))
        v = diag.result["verdict"]
        if v["effect"]:
            click.echo(f"verdict: {v['effect']} (held-out rms {v['rms_db_holdout_baseline']:.2f} -> "
                       f"{v['rms_db_holdout_extended']:.2f} dB, shrinkage {v['holdout_shrinkage_pct']:.1f} %)")
        else:
            click.echo(f"verdict: no effect ({v['reason']})")
        for sentence in v.get("level_offsets") or []:
            click.echo(f"unexplained: {sentence}")
        judged = (v.get("candidates_judged_with") or {}).get("sentence")
        if judged:
            click.echo(f"judged with offsets: {judged}")
        click.echo(f"{len(diag.result['segments'])} segment(s) where the card misses; wrote {path}"
                   + ("" if no_report else f" and {folder / 'report.html'}"))


def _card_line(card_params: Mapping[str, float], base: Mapping[str, object]) -> str:
    """How far the card itself misses: its RMS residual, the refit's, and the parameters the refit moves by
    more than 3 of its corrected standard deviations (largest first)."""
    refit = base.get("parameters") or {}
    std = base.get("std_corrected") or {}
    assert isinstance(refit, dict) and isinstance(std, dict)
    moved = []
    for k, v in refit.items():
        sd = std.get(k)
        if k in card_params and isinstance(sd, (int, float)) and sd > 0:
            z = (float(v) - float(card_params[k])) / float(sd)
            if abs(z) > 3.0:
                moved.append((abs(z), f"{k} {float(v) - float(card_params[k]):+.3g} ({abs(z):.0f} std)"))
    moved.sort(reverse=True)
    line = f"card: rms {base.get('rms_db_card', float('nan')):.2f} dB against these data, refitted {base.get('rms_db_fit', float('nan')):.2f} dB"
    return line + ("; the refit moves " + ", ".join(t for _, t in moved[:4]) if moved else "")
