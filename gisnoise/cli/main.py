"""Entry point of the ``gisnoise`` command.

Subcommands live in one module each in this package; every module that defines
a click command or group named ``command`` is added to the group, so adding a
subcommand means adding a module.  Core errors become a one-line message and
exit status 2, never a traceback.

Start-up is instant: a subcommand's module (and the library stack it needs) is imported
only when that subcommand runs or shows its help; ``gisnoise --help`` reads the commands'
names and first help lines from the modules' source without importing them.
"""

from __future__ import annotations

import ast
import importlib
import logging
import os
import pkgutil
import struct
import sys
import zlib
from functools import cache
from pathlib import Path
from typing import Any

import click

from gisnoise import __version__
from gisnoise.errors import GisnoiseError

_SKIP = {"main", "options"}


@cache
def _subcommands() -> dict[str, tuple[str, str]]:
    """``{command name: (module, first help line)}`` of the subcommand modules, read from their source."""
    found: dict[str, tuple[str, str]] = {}
    pkg_dir = Path(__file__).resolve().parent
    for info in sorted(pkgutil.iter_modules([str(pkg_dir)]), key=lambda i: i.name):
        if info.name in _SKIP or info.name.startswith("_"):
            continue
        name, short = info.name, ""
        try:
            tree = ast.parse((pkg_dir / f"{info.name}.py").read_text(encoding="utf-8"))
        except (OSError, SyntaxError):  # e.g. a compiled-only module: its command is read on import
            found[name] = (info.name, short)
            continue
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name == "command":
                for dec in node.decorator_list:
                    if (isinstance(dec, ast.Call) and isinstance(dec.func, ast.Attribute)
                            and dec.func.attr in ("command", "group") and dec.args
                            and isinstance(dec.args[0], ast.Constant) and isinstance(dec.args[0].value, str)):
                        name = dec.args[0].value
                doc = ast.get_docstring(node) or ""
                short = doc.strip().split("\n")[0].strip() if doc else ""
        found[name] = (info.name, short)
    return found


class GisnoiseGroup(click.Group):
    """A group that turns :class:`GisnoiseError` into a usage-style exit 2 and imports subcommands lazily."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted(set(self.commands) | set(_subcommands()))

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in self.commands:
            # a subcommand lives in the module of its name: import it alone, without reading the others
            pkg_dir = Path(__file__).resolve().parent
            if cmd_name.isidentifier() and cmd_name not in _SKIP and (pkg_dir / f"{cmd_name}.py").is_file():
                self._load(cmd_name, cmd_name)
            entry = _subcommands().get(cmd_name) if cmd_name not in self.commands else None
            if entry is not None:
                self._load(entry[0], cmd_name)
        return self.commands.get(cmd_name)

    def _load(self, module: str, cmd_name: str) -> None:
        cmd = getattr(importlib.import_module(f"{__package__}.{module}"), "command", None)
        if isinstance(cmd, click.Command) and cmd.name == cmd_name:
            self.add_command(cmd, cmd_name)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        rows = []
        for name in self.list_commands(ctx):
            if name in self.commands:
                rows.append((name, self.commands[name].get_short_help_str(formatter.width)))
            else:
                short = _subcommands()[name][1]
                rows.append((name, short if len(short) <= 80 else short[:77] + "..."))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except GisnoiseError as exc:
            click.echo(f"Error: {exc}", err=True)
            ctx.exit(2)
        except MemoryError:
            click.echo("Error: out of memory; use a coarser --resolution or a smaller grid", err=True)
            ctx.exit(2)
        except click.NoSuchOption as exc:
            if exc.option_name in _GROUP_OPTIONS:  # `gisnoise contour ... -q`: say where it goes
                raise click.UsageError(f"{exc.format_message().rstrip('.')} for the command: {exc.option_name} is an "
                                       f"option of gisnoise itself and goes before it: gisnoise {exc.option_name} "
                                       f"{ctx.invoked_subcommand or 'COMMAND'} ...", ctx=exc.ctx) from None
            raise
        except (click.exceptions.Exit, click.ClickException, click.Abort, KeyboardInterrupt, SystemExit):
            raise
        except BrokenPipeError:
            # the reader of stdout stopped (`| head`): end quietly, as a command killed by SIGPIPE
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            ctx.exit(141)
        except (UnicodeError, ValueError, OSError, EOFError, ArithmeticError, struct.error, zlib.error) as exc:
            # last resort: malformed input a reader did not name; one line, never a traceback
            fld = getattr(exc, "field", None) or getattr(exc, "filename", None)
            click.echo(f"Error: {fld + ': ' if isinstance(fld, str) else ''}cannot read the input "
                       f"({type(exc).__name__}: {exc})", err=True)
            ctx.exit(2)


_GROUP_OPTIONS = ("-q", "--quiet", "-v", "--verbose")
"""Options of ``gisnoise`` itself, which users also type after the command."""


@click.group(cls=GisnoiseGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="gisnoise")
@click.option("-v", "--verbose", count=True, help="More log output (repeat for debug).")
@click.option("-q", "--quiet", is_flag=True,
              help="No progress bars or log lines; errors and warnings still print (a warning says where an answer "
                   "may be wrong); fit, design, diagnose, simulate, operations and exposure also leave out their "
                   "summary.")
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


def load_all() -> click.Group:
    """The group with every subcommand imported (for tools that walk ``cli.commands``)."""
    for name in _subcommands():
        cli.get_command(click.Context(cli), name)
    return cli


def main(argv: list[str] | None = None) -> None:
    cli.main(args=argv, prog_name="gisnoise")


if __name__ == "__main__":  # pragma: no cover
    main(sys.argv[1:])
