"""Entry point of the ``gisnoise`` command.

Subcommands live in one module each in this package; every module that defines
a click command or group named ``command`` is added to the group, so adding a
subcommand means adding a module.  Core errors become a one-line message and
exit status 2, never a traceback.
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
import struct
import sys
import zlib
from typing import Any

import click

from gisnoise import __version__
from gisnoise.errors import GisnoiseError

_SKIP = {"main", "options"}


class GisnoiseGroup(click.Group):
    """A group that turns :class:`GisnoiseError` into a usage-style exit 2."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except GisnoiseError as exc:
            click.echo(f"Error: {exc}", err=True)
            ctx.exit(2)
        except MemoryError:
            click.echo("Error: out of memory; use a coarser --resolution or a smaller grid", err=True)
            ctx.exit(2)
        except (click.exceptions.Exit, click.ClickException, click.Abort, KeyboardInterrupt, SystemExit):
            raise
        except (UnicodeError, ValueError, OSError, EOFError, ArithmeticError, struct.error, zlib.error) as exc:
            # last resort: malformed input a reader did not name; one line, never a traceback
            fld = getattr(exc, "field", None) or getattr(exc, "filename", None)
            click.echo(f"Error: {fld + ': ' if isinstance(fld, str) else ''}cannot read the input "
                       f"({type(exc).__name__}: {exc})", err=True)
            ctx.exit(2)


@click.group(cls=GisnoiseGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="gisnoise")
@click.option("-v", "--verbose", count=True, help="More log output (repeat for debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors; no progress bars.")
@click.pass_context
def cli(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """Drone noise from measurements to maps.

    \b
    Typical work:
      gisnoise contour route.csv --card horizontal.json --out map/   noise map of a route
      gisnoise simulate scenario.json --out campaign/                synthetic campaign
      gisnoise fit campaign/ --phase horizontal --out card.json      identify a model card
      gisnoise diagnose campaign/ --card card.json --out diag/       where and why it misses
    """
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    ctx.ensure_object(dict)
    ctx.obj["quiet"] = quiet


def _register() -> None:
    pkg = importlib.import_module(__package__)
    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        if info.name in _SKIP or info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{__package__}.{info.name}")
        cmd = getattr(mod, "command", None)
        if isinstance(cmd, click.Command):
            cli.add_command(cmd)


_register()


def main(argv: list[str] | None = None) -> None:
    cli.main(args=argv, prog_name="gisnoise")


if __name__ == "__main__":  # pragma: no cover
    main(sys.argv[1:])
