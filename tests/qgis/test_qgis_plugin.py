"""The QGIS plugin in a real headless QGIS.

QGIS's Python is not the project's: this test runs the tests in ``inside/`` with
pytest under QGIS's Python (``/usr/bin/python3`` on Debian, or
``GISNOISE_QGIS_PYTHON``), offscreen.  They build the plugin zip, install it into a
fresh profile, register the provider, run every algorithm through
``processing.run`` and ``qgis_process``, and compare the maps with the command
line of this environment.

Off CI the test skips when QGIS is absent; on CI (``CI=true``) a missing QGIS is a
failure, since ``scripts/install-system-deps`` installs it.
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.qgis

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
QGIS_PYTHON = os.environ.get("GISNOISE_QGIS_PYTHON", "/usr/bin/python3")


def _qgis_problem():
    """None when QGIS's Python can run the inside tests, else the reason."""
    if not Path(QGIS_PYTHON).exists():
        return f"no QGIS Python at {QGIS_PYTHON}"
    r = subprocess.run([QGIS_PYTHON, "-c", "import qgis.core, pytest"], capture_output=True, text=True,
                       env=_env(), timeout=120)
    if r.returncode != 0:
        return f"{QGIS_PYTHON} cannot import qgis.core and pytest: {r.stderr.strip().splitlines()[-1:]}"
    return None


def _env(**extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP", "PYTEST_ADDOPTS")
           and not k.startswith("PYTEST_XDIST") and k != "PYTEST_CURRENT_TEST"}
    venv_bin = str(Path(sys.executable).parent)
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if p != venv_bin)
    env.update(extra)
    return env


def _cli():
    exe = Path(sys.executable).parent / "gisnoise"
    if exe.exists():
        return str(exe)
    found = shutil.which("gisnoise")
    if not found:
        pytest.fail("the gisnoise command is not installed in this environment")
    return found


def test_plugin_in_real_qgis(tmp_path):
    problem = _qgis_problem()
    if problem:
        if os.environ.get("CI") == "true":
            pytest.fail(f"QGIS is missing on CI ({problem}); scripts/install-system-deps should have installed it")
        pytest.skip(problem)
    runtime = tmp_path / "xdg"
    runtime.mkdir(mode=0o700)
    env = _env(QT_QPA_PLATFORM="offscreen", GISNOISE_INSIDE_QGIS="1", GISNOISE_CLI=_cli(),
               GISNOISE_REPO=str(ROOT), GISNOISE_BUILD_PYTHON=sys.executable, XDG_RUNTIME_DIR=str(runtime), PYTHONDONTWRITEBYTECODE="1",
               HOME=str(tmp_path / "home"))
    cmd = [QGIS_PYTHON, "-m", "pytest", "-c", str(HERE / "inside" / "pytest.ini"), "--rootdir", str(HERE / "inside"),
           "--basetemp", str(tmp_path / "inside"), "-q", str(HERE / "inside")]
    r = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    report = (r.stdout + r.stderr)[-20000:]
    assert r.returncode == 0, f"tests inside QGIS failed:\n{report}"
    assert " passed" in r.stdout and "skipped" not in r.stdout.splitlines()[-1], report
