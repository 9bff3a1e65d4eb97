"""Options and helpers shared by the subcommands."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

import click

card_option = click.option(
    "--card", "cards", multiple=True, required=True, type=click.Path(dir_okay=False),
    help="Model card JSON; repeat for one card per phase (horizontal, climb, sink, ...).",
)
out_dir_option = click.option("--out", "out", required=True, type=click.Path(file_okay=False),
                              help="Output folder (created).")


@contextmanager
def progress(ctx: click.Context | None, description: str, total: float | None) -> Iterator[Any]:
    """A rich progress bar yielding ``update(done)``; silent with ``-q``.

    ``update`` takes the amount done so far (same unit as ``total``).
    """
    quiet = bool(ctx and ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    if quiet:
        yield lambda done: None
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    # on stderr: stdout carries the results alone (a bar on stdout left an empty line in piped output)
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeRemainingColumn(), transient=True, console=Console(stderr=True)) as bar:
        task = bar.add_task(description, total=total)
        yield lambda done: bar.update(task, completed=done)


def echo_warnings(warnings: Iterable[str]) -> None:
    """Each warning on stderr as ``warning: <text>``, one line each (stdout carries the results alone)."""
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
