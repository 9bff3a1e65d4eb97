"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

import click

card_option = click.option(
    "--card", "cards", multiple=True, required=True, type=click.Path(dir_okay=False),
    help="Model card JSON; repeat for one card per phase (horizontal, climb, sink, ...).",
)
out_dir_option = click.option("--out", "out", required=True, type=click.Path(file_okay=False),
                              help="Output folder (created).")


def building_field_options(f: Any) -> Any:
    """``--layer``, ``--residents-field``, ``--dwellings-field``, ``--height-field``, ``--levels-field`` and
    ``--storey-height``: how a buildings file is read, and its storeys."""
    for opt in reversed((
            click.option("--layer", "layer", default=None, help="Layer of the buildings file (GeoPackage)."),
            click.option("--residents-field", "residents_field", default=None,
                         help="Attribute with the residents of a building [default: the first of residents, "
                              "population, pop, inhabitants, persons, people; a layer with none of them is read "
                              "with a warning]."),
            click.option("--dwellings-field", "dwellings_field", default=None,
                         help="Attribute with the dwellings of a building [default: dwellings, households, units, "
                              "flats]."),
            click.option("--height-field", "height_field", default=None,
                         help="Attribute with the height of a building, m or ft ('10', '10 m', '12 ft') [default: "
                              "height, height_m, building_height]; a value that does not read is unknown, said in "
                              "a warning."),
            click.option("--levels-field", "levels_field", default=None,
                         help="Attribute with the storeys above ground of a building, for those without a height "
                              "[default: building:levels, building_levels, levels, storeys, floors]."),
            click.option("--storey-height", "storey_height", type=click.FloatRange(min=0.0, min_open=True),
                         default=3.0, show_default=True,
                         help="Height of a storey, m: a building with a height (or storeys) gets a receiver at the "
                              "middle of each storey, and its level at the most exposed one besides the façade "
                              "level at --facade-height."))):
        f = opt(f)
    return f


@contextmanager
def progress(ctx: click.Context | None, description: str, total: float | None) -> Iterator[Any]:
    """Progress on stderr, yielding ``update(done)``; silent with ``-q``.

    ``update`` takes the amount done so far (same unit as ``total``).  On a terminal: a rich progress bar,
    drawn from the first update on (what the command prints before, e.g. the grid of a map, stays above it
    on stdout).  Elsewhere (a log file, a pipe): plain lines (:class:`PlainProgress`), so a log shows
    that a long command is alive.
    """
    quiet = bool(ctx and ctx.find_root().obj and ctx.find_root().obj.get("quiet"))
    if quiet:
        yield lambda done: None
        return
    if not _stderr_is_terminal():
        plain = PlainProgress(description, total)
        stop = threading.Event()

        def beat() -> None:  # a line every PLAIN_EVERY_S even while the work reports nothing
            while not stop.wait(1.0):
                plain.tick()

        beater = threading.Thread(target=beat, name="gisnoise-progress", daemon=True)
        beater.start()
        try:
            yield plain
        finally:
            stop.set()
            beater.join()
        return
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    # on stderr: stdout carries the results alone (a bar on stdout left an empty line in piped output)
    bar = Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                   TimeRemainingColumn(), transient=True, console=Console(stderr=True))
    with ExitStack() as stack:
        task: list[Any] = []

        def update(done: float) -> None:
            if not task:
                stack.enter_context(bar)
                task.append(bar.add_task(description, total=total))
            bar.update(task[0], completed=done)

        yield update


def _stderr_is_terminal() -> bool:
    try:
        return bool(sys.stderr.isatty())
    except (AttributeError, ValueError):  # no stderr, or a closed one
        return False


PLAIN_STEP = 0.1
"""Plain progress prints a line every this fraction of the work (10 %) ..."""
PLAIN_EVERY_S = 10.0
"""... or when this many seconds passed since the last line."""
PLAIN_MIN_GAP_S = 2.0
"""A further tenth prints only this long after the last line (or the start): quick work stays one line or none."""


class PlainProgress:
    """Called as ``update(done)``: prints ``<description>: <percent> % after <s> s`` on stderr when the work passes a
    further :data:`PLAIN_STEP` at least :data:`PLAIN_MIN_GAP_S` after the last line (100 % whenever a line was
    printed before), or (:meth:`tick`, called by :func:`progress` every second from a thread) when
    :data:`PLAIN_EVERY_S` seconds passed since the last line, so a long stretch between two reports still says
    the command is alive.  ``total`` None: lines by time alone, without a percentage."""

    def __init__(self, description: str, total: float | None, *, echo: Callable[[str], Any] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self._say = echo if echo is not None else (lambda line: click.echo(line, err=True))
        self._clock = clock
        self._description, self._total = description, total
        self._t0 = self._last = clock()
        self._next = PLAIN_STEP
        self._done: float | None = None
        self._said = False
        self._lock = threading.Lock()

    def __call__(self, done: float) -> None:
        with self._lock:
            self._done = float(done)
            f = self._fraction()
            gap = self._clock() - self._last
            if f is not None and f >= self._next - 1e-9:
                self._next = (math.floor(f / PLAIN_STEP + 1e-9) + 1) * PLAIN_STEP
                if gap >= PLAIN_MIN_GAP_S or (f >= 1.0 and self._said):  # the end of work a log showed going on
                    self._line()
            elif gap >= PLAIN_EVERY_S:
                self._line()

    def tick(self) -> None:
        """A line when :data:`PLAIN_EVERY_S` seconds passed since the last one."""
        with self._lock:
            if self._clock() - self._last >= PLAIN_EVERY_S:
                self._line()

    def _fraction(self) -> float | None:
        return self._done / float(self._total) if self._total and self._done is not None else None

    def _line(self) -> None:
        now = self._clock()
        self._last = now
        self._said = True
        f = self._fraction()
        if f is None:
            self._say(f"{self._description}: running after {now - self._t0:.0f} s")
        else:
            self._say(f"{self._description}: {100.0 * f:.0f} % after {now - self._t0:.0f} s")


def echo_warnings(warnings: Iterable[str]) -> None:
    """Each warning on stderr as ``warning: <text>``, one line each (stdout carries the results alone)."""
    for w in warnings:
        click.echo(f"warning: {w}", err=True)
