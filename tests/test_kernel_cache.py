"""numba's disk cache of the fast kernels: compiled ahead by the set-up, and no error without it."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[1]

# the kernel's level against the paper's Eq. 9-11 from the model (one definition) in a fresh process
SCRIPT = """
import numpy as np
from gisnoise.maps import _numba, warm_up
from gisnoise.maps.fastkernel import level_from_body
from gisnoise.model import ModelCard
info = warm_up() if WARM else {"cached": _numba.cache_used}
card = ModelCard(id="c", vehicle="v", phase="horizontal", ansatz="paper-offset",
                 parameters=dict(p0=60.0, p1=10.0, p2=0.1, p3=0.0, p4=0.1, p5=0.0, p6=1.0, p7=30.0),
                 reference_power_w=1000.0)
# straight below the UAV at 40 m (the reference distance), reference power: theta = -pi/2, so
# L = p0 (1 + 0) (1 + p4 sin(-pi/2 - p5)) = 60 * 0.9 = 54 dB
lev = float(level_from_body(card, 0.0, 0.0, 40.0, 1000.0))
print("cached", info["cached"], "level", round(lev, 4))
"""


def run(env_extra, warm=True):
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(env_extra, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", f"WARM = {warm}\n" + SCRIPT], capture_output=True, text=True, env=env, timeout=600)


def test_unwritable_cache_compiles_in_memory_with_a_one_line_notice(tmp_path):
    # the only cache locator numba may use points at a directory that cannot exist
    blocker = tmp_path / "file"
    blocker.write_text("")
    out = run({"NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator",
               "NUMBA_CACHE_DIR": str(blocker / "cache")}, warm=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["cached", "False", "level", "54.0"]
    notices = [ln for ln in out.stderr.splitlines() if ln.strip()]
    assert len(notices) == 1 and "no writable cache directory" in notices[0]


def test_warm_up_fills_the_cache_that_later_processes_load(tmp_path):
    env = {"NUMBA_CACHE_LOCATOR_CLASSES": "UserProvidedCacheLocator", "NUMBA_CACHE_DIR": str(tmp_path)}
    first = run(env)
    assert first.returncode == 0, first.stderr
    assert first.stdout.split() == ["cached", "True", "level", "54.0"]
    assert first.stderr.strip() == ""
    files = sorted(p.name for p in tmp_path.rglob("*.nbi"))
    assert any(name.startswith("_numba._window_kernel") for name in files), files
    # the kernel of receiver-dependent effect terms (+doppler, +ground_reflection, ...) too
    assert any(name.startswith("_numba_receiver._receiver_window_kernel") for name in files), files
    stamps = {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*.nbc")}
    second = run(env)
    assert second.returncode == 0 and second.stdout == first.stdout
    # loaded, not compiled again: no kernel file was rewritten
    assert {p: p.stat().st_mtime_ns for p in tmp_path.rglob("*.nbc")} == stamps
