"""Start-up of the command: help answers without importing the library stack."""

import os
import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from gisnoise.cli.main import cli, load_all

ROOT = Path(__file__).resolve().parents[1]

PROBE = """
import sys
from gisnoise.cli.main import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
heavy = sorted(m for m in ("numpy", "scipy", "numba", "pyproj", "rasterio", "gisnoise.maps", "gisnoise.model",
                            "gisnoise.measure") if m in sys.modules)
print("HEAVY", ",".join(heavy) or "-")
"""


def probe(*args):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, env=env, timeout=120)
    return out.stdout


def test_help_imports_no_library_stack():
    # what makes start-up slow (scipy.stats alone is seconds) stays out of --help
    for args in (("--help",), ("contour", "--help"), ("operations", "--help")):
        out = probe(*args)
        assert out.strip().splitlines()[-1] == "HEAVY -", (args, out[-300:])


def test_lazy_help_lists_the_same_commands_and_lines_as_the_imported_ones():
    lazy = CliRunner().invoke(cli, ["--help"]).output
    full = load_all()
    for name, cmd in full.commands.items():
        assert name in lazy
        first = (cmd.help or "").strip().splitlines()[0]
        assert first[:40] in lazy.replace("\n", " ").replace("  ", " ") or first[:30] in lazy, name
    assert {"campaign", "card", "contour", "design", "diagnose", "fit", "operations", "serve",
            "simulate"} <= set(full.commands)


def test_unknown_command_is_a_usage_error():
    res = CliRunner().invoke(cli, ["nosuch"])
    assert res.exit_code == 2 and "No such command 'nosuch'" in res.output


def test_files_named_in_help_texts_exist():
    """A help text that points to a file (``see x/y.py``, ``examples in sample_data/...``) points to one
    that is there: in the repository or in the package."""
    import re

    import click

    load_all()
    missing = []

    def walk(cmd: click.Command, path: list[str]) -> None:
        text = CliRunner().invoke(cli, [*path, "--help"], terminal_width=200).output
        for name in re.findall(r"[\w./-]+/[\w.-]+\.(?:py|md|json)\b", text):
            if name.split("/")[0].isupper():  # OUT/diagnosis.json: a file the command writes
                continue
            if not ((ROOT / name).exists() or (ROOT / "gisnoise" / name).exists()):
                missing.append((" ".join(path), name))
        for sub in sorted(getattr(cmd, "commands", {})):
            walk(cmd.commands[sub], [*path, sub])  # type: ignore[attr-defined]

    walk(cli, [])
    assert not missing, missing
