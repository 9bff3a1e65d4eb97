"""Start-up of the command: help answers without importing the library stack."""

import os
import subprocess
import sys
from pathlib import Path

import pytest
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


def test_python_m_gisnoise_is_the_command():
    # an environment whose scripts folder is not on the PATH still has the command: same name, same version
    from gisnoise import __version__

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-m", "gisnoise", "--version"], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"gisnoise, version {__version__}"


def test_unknown_command_is_a_usage_error():
    res = CliRunner().invoke(cli, ["nosuch"])
    assert res.exit_code == 2 and "No such command 'nosuch'" in res.output


@pytest.mark.parametrize("opt", ["-q", "--verbose"])
def test_a_global_option_after_the_command_says_where_it_goes(opt):
    """`gisnoise contour route.csv -q` is a usage error that shows the right order (it said only "No such option")."""
    res = CliRunner().invoke(cli, ["contour", "route.csv", opt])
    assert res.exit_code == 2
    assert f"goes before it: gisnoise {opt} contour ..." in res.output


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


def test_progress_goes_to_stderr_and_stdout_holds_the_results(tmp_path):
    """Piped stdout carries the results alone (the progress bar writes to stderr): the first line of a map's output is
    its grid, and a refused map writes nothing to stdout."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    route = ROOT / "gisnoise" / "data" / "routes" / "delivery_route.geojson"
    cmd = [sys.executable, "-m", "gisnoise.cli.main", "contour", str(route), "--card", "demo-horizontal", "--card",
           "demo-climb", "--card", "demo-sink", "--resolution", "200", "--metrics", "LAmax"]
    ok = subprocess.run([*cmd, "--out", str(tmp_path / "m")], capture_output=True, text=True, env=env, timeout=300)
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.splitlines()[0].startswith("grid:"), ok.stdout
    bad = subprocess.run([*cmd, "--out", str(tmp_path / "b"), "--levels", "x"], capture_output=True, text=True,
                         env=env, timeout=300)
    assert bad.returncode == 2 and bad.stdout == "" and "Error" in bad.stderr


def test_the_python_of_the_scripts_imports_names_that_exist():
    """A script with embedded Python (scripts/make_demo_cards) imports only names the package has."""
    import ast
    import importlib
    import re

    seen = 0
    for script in sorted((ROOT / "scripts").iterdir()):
        text = script.read_text(errors="replace") if script.is_file() else ""
        for body in re.findall(r"<<'PY'\n(.*?)\nPY\n", text, flags=re.S):
            for node in ast.walk(ast.parse(body)):
                if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("gisnoise"):
                    mod = importlib.import_module(node.module)
                    for alias in node.names:
                        seen += 1
                        sub = hasattr(mod, "__path__") and importlib.util.find_spec(f"{node.module}.{alias.name}")
                        assert hasattr(mod, alias.name) or sub, (script.name, node.module, alias.name)
    assert seen >= 1


def test_a_reader_that_stops_early_ends_the_command_quietly():
    """`gisnoise card show CARD | head -1`: when the reader of stdout closes it, the command stops without an error
    message (it said 'cannot read the input (BrokenPipeError ...)')."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-c", "from gisnoise.cli.main import main; main()", "card", "show",
                          "demo-horizontal"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    assert p.stdout is not None and p.stderr is not None
    p.stdout.close()  # before the command writes: its first write meets a closed pipe
    with p.stderr:
        err = p.stderr.read().decode()
    p.wait(timeout=120)
    assert "Error" not in err and "Traceback" not in err and "Exception ignored" not in err, err
    assert p.returncode == 141
