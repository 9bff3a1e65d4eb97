"""The ``gisnoise`` command line: a click group, one module per subcommand."""

from .main import cli, main

__all__ = ["cli", "main"]
