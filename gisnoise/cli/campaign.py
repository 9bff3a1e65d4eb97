"""``gisnoise campaign``: check a measurement campaign, turn its WAV files into levels."""

from __future__ import annotations

from collections import Counter

import click
import numpy as np

from gisnoise.cli.options import echo_warnings, progress
from gisnoise.errors import GisnoiseError
from gisnoise.measure import (
    DEFAULT_EVENT_DB,
    DEFAULT_SNR_DB,
    Samples,
    campaign_log_warnings,
    inspect_campaign,
    write_levels,
)

campaign_arg = click.argument("campaign", type=click.Path(file_okay=False))


@click.group("campaign")
def command() -> None:
    """Measurement campaigns: check them, compute levels from audio."""


@command.command("check")
@campaign_arg
@click.option("--absorption", is_flag=True, help="Apply the atmospheric-absorption correction (needs bands).")
@click.option("--snr-db", type=float, default=DEFAULT_SNR_DB, show_default=True,
              help="Rows below background + this (dB) are masked low_snr.")
@click.option("--event-db", type=float, default=DEFAULT_EVENT_DB, show_default=True,
              help="Joint rise on all microphones (dB) flagged as an event.")
@click.pass_context
def check(ctx: click.Context, campaign: str, absorption: bool, snr_db: float, event_db: float) -> None:
    """Summary of CAMPAIGN and every problem found (exit status 2 if any).

    \b
    Example:
      gisnoise campaign check campaign/
    """
    with progress(ctx, "reading campaign", 1.0) as update:
        camp, problems = inspect_campaign(campaign, absorption=absorption, snr_db=snr_db, event_db=event_db,
                                          progress=lambda done, total: update(done / max(total, 1.0)))
    if camp is not None:
        click.echo(f"Campaign {camp.folder}  origin {camp.origin.lat0:.6f}, {camp.origin.lon0:.6f}, "
                   f"{camp.origin.h0:.1f} m  c = {camp.speed_of_sound_m_s:.1f} m/s  "
                   f"reference power {camp.reference_power_w:g} W")
        s = None
        if camp.levels:
            try:
                s = camp.samples()
            except GisnoiseError:  # already among the problems
                s = None
        click.echo("")
        click.echo(f"{'flight':<16}{'log':<24}{'duration_s':>11}{'log_rows':>10}{'blocks':>9}{'valid':>9}  phases")
        for f in camp.flights:
            tr = camp.trajectories[f.id]
            sel = s.flight == f.id if s is not None else np.zeros(0, bool)
            phases = ", ".join(f"{p} {n}" for p, n in sorted(Counter(tr.phase.tolist()).items()))
            click.echo(f"{f.id:<16}{_short(f.log):<24}{tr.duration_s:>11.1f}{len(tr):>10d}"
                       f"{int(sel.sum()):>9d}{int((s.valid[sel]).sum()) if s is not None else 0:>9d}  {phases}")
        echo_warnings(campaign_log_warnings(camp))   # a log cut short reads up to its cut: not a problem, but said
        click.echo("")
        click.echo(f"{'microphone':<16}{'mount':<14}{'files':>6}{'blocks':>9}{'valid':>9}{'background_dB':>15}")
        for m in camp.microphones:
            nfiles = sum(1 for lv in camp.levels if lv.mic == m.id)
            sel = s.mic == m.id if s is not None else np.zeros(0, bool)
            bgs = _background_text(s, m.id)
            click.echo(f"{m.id:<16}{m.mount:<14}{nfiles:>6d}{int(sel.sum()):>9d}"
                       f"{int(s.valid[sel].sum()) if s is not None else 0:>9d}{bgs:>15}")
        if s is not None:
            counts = Counter(s.mask_reason[~s.valid].tolist())
            click.echo("")
            click.echo(f"samples {len(s)}, valid {int(s.valid.sum())}, masked {int((~s.valid).sum())}"
                       + ("".join(f", {k} {v}" for k, v in sorted(counts.items())) if counts else ""))
    if problems:
        click.echo(f"{len(problems)} problem(s):", err=True)
        for p in problems:
            click.echo(f"Error: {p.message}", err=True)
        ctx.exit(2)
    click.echo("no problems found")


def _background_text(s: Samples | None, mic: str) -> str:
    """Background of a microphone over its flights: one value, a range, or '-' when not determined."""
    if s is None or s.background_db is None:
        return "-"
    bg = s.background_db[s.mic == mic]
    bg = bg[np.isfinite(bg)]
    if bg.size == 0:
        return "-"
    lo, hi = float(bg.min()), float(bg.max())
    return f"{lo:.1f}" if hi - lo < 0.05 else f"{lo:.1f}-{hi:.1f}"


def _short(path: str) -> str:
    from pathlib import Path

    return Path(path).name if path else "-"


@command.command("levels")
@campaign_arg
@click.option("--block", "block_s", type=float, default=None,
              help="Averaging block, s [default: campaign.json block_s or 0.125].")
@click.option("--force", is_flag=True, help="Overwrite existing level CSVs.")
@click.pass_context
def levels(ctx: click.Context, campaign: str, block_s: float | None, force: bool) -> None:
    """Compute level CSVs (LA and one-third-octave bands) from the WAV files of CAMPAIGN.

    Each mics/<mic>/<flight>.wav becomes mics/<mic>/<flight>.csv beside it, free
    field (mount correction applied), with columns t, LA and L_<nominal Hz>, and
    <flight>.source.json, the calibration and WAV it was computed from (campaign
    check refuses the CSV once campaign.json's calibration or the WAV changes).  A
    clipped or dropped-out recording (digital zeros) is refused naming its times,
    unless campaign.json's exclusions hold them: their blocks are left out.

    \b
    Example:
      gisnoise campaign levels campaign/ --block 0.125
    """
    if block_s is not None and not block_s > 0:
        raise click.BadParameter(f"must be positive, got {block_s:g}", param_hint="--block")
    warnings: list[str] = []
    with progress(ctx, "audio -> levels", 1.0) as update:
        written = write_levels(campaign, block_s=block_s, force=force,
                               progress=lambda done, total: update(done / max(total, 1e-12)), warn=warnings.append)
    echo_warnings(warnings)  # a sample rate that cannot carry the bands up to 16 kHz: written, and said
    for p in written:
        click.echo(str(p))
    click.echo(f"wrote {len(written)} level file(s)")
