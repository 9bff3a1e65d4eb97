"""The ``gisnoise`` command line: a click group, one module per subcommand."""

from gisnoise.cli.main import cli, main

__all__ = ["cli", "main"]
