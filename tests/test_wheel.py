"""The wheel works away from the checkout: bundled cards by id, the map, the service and its web page.

Builds the wheel, installs it into a new virtual environment in a temporary folder (the
third-party packages it needs are taken from the running environment through a ``.pth``
line, so nothing is downloaded), and there, with the temporary folder as working directory:

* ``gisnoise card list`` names the bundled cards and the files the package holds them in;
* ``gisnoise contour`` maps a flight the test writes with the bundled demo card named by id,
  and the map equals the one the checkout's package computes for the same inputs;
* ``gisnoise serve`` answers ``/`` (the web map) and ``/openapi.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import socket
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import numpy as np
import pytest
import rasterio

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.server


def _run(args: list[str], cwd: Path, env: dict[str, str] | None = None, timeout: float = 600) -> str:
    proc = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}"
    return proc.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(bin folder, clean environment, working folder) of a new venv with only the wheel installed."""
    pytest.importorskip("setuptools", minversion="77")
    base = tmp_path_factory.mktemp("wheel")
    dist = base / "dist"
    # build from a copy of the sources: setuptools' build/ folder in the checkout could hold stale modules
    src = base / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc", "*.egg-info")
    shutil.copytree(ROOT / "gisnoise", src / "gisnoise", ignore=ignore)
    for name in ("pyproject.toml", "README.md", "LICENSE"):
        shutil.copy2(ROOT / name, src / name)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(dist), str(src)],
         cwd=base)
    wheels = sorted(dist.glob("gisnoise-*.whl"))
    assert len(wheels) == 1, wheels
    venv = base / "venv"
    _run([sys.executable, "-m", "venv", str(venv)], cwd=base)
    py = venv / "bin" / "python"
    purelib = Path(_run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=base).strip())
    # third-party packages from the running environment, after the new venv's own site-packages
    deps = [sysconfig.get_paths()["purelib"], *site.getsitepackages()]
    (purelib / "zz_gisnoise_test_deps.pth").write_text("\n".join(dict.fromkeys(deps)) + "\n", encoding="utf-8")
    _run([str(py), "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheels[0])], cwd=base)
    work = base / "work"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    return venv / "bin", env, work


def test_wheel_holds_no_top_level_package_but_gisnoise(installed):
    bin_dir, env, work = installed
    names = _run([str(bin_dir / "python"), "-c",
                  "import importlib.metadata as m; print('\\n'.join(sorted({f.parts[0] for f in m.files('gisnoise')})))"],
                 cwd=work, env=env).split()
    assert [n for n in names if not n.startswith("gisnoise") and n != ".."] == []  # '..': the bin/ script
    where = _run([str(bin_dir / "python"), "-c", "import gisnoise; print(gisnoise.__file__)"], cwd=work, env=env)
    assert str(ROOT) not in where and "site-packages" in where


def test_bundled_cards_are_listed_with_their_files(installed):
    bin_dir, env, work = installed
    out = _run([str(bin_dir / "gisnoise"), "card", "list"], cwd=work, env=env)
    rows = {line.split()[0]: line.split()[-1] for line in out.splitlines() if line.strip()}
    assert {"demo-horizontal", "demo-climb", "demo-sink", "published-horizontal"} <= set(rows)
    p = Path(rows["demo-horizontal"])
    assert p.is_file() and "site-packages" in str(p)
    assert json.loads(p.read_text(encoding="utf-8"))["id"] == "demo-horizontal"


def test_contour_with_a_bundled_card_by_id_equals_the_checkout(installed, tmp_path):
    from gisnoise.flight import Trajectory
    from gisnoise.geo import LocalFrame
    from gisnoise.maps import make_map
    from gisnoise.model import load

    bin_dir, env, work = installed
    frame = LocalFrame(52.27, 10.52, 80.0)
    t = np.linspace(0.0, 30.0, 31)
    lat, lon, h = frame.to_wgs84(-150.0 + 10.0 * t, np.zeros_like(t), np.full_like(t, 140.0))
    traj = Trajectory(t=t, lat=lat, lon=lon, h=h, roll=0 * t, pitch=0 * t, yaw=np.full_like(t, 90.0),
                      power_w=np.full_like(t, 1500.0), phase=np.full(t.size, "horizontal"))
    traj.to_csv(work / "flight.csv")
    _run([str(bin_dir / "gisnoise"), "-q", "contour", "flight.csv", "--card", "demo-horizontal", "--out", "map",
          "--resolution", "20", "--margin", "200", "--levels", "45,50,55", "--ground-height", "80"], cwd=work, env=env)
    assert (work / "map" / "levels.tif").is_file() and (work / "map" / "contours.geojson").is_file()
    with rasterio.open(work / "map" / "levels.tif") as ds:
        lamax = ds.read(list(ds.descriptions).index("LAmax") + 1)

    ref = make_map(str(work / "flight.csv"), [load("demo-horizontal")], tmp_path / "ref", resolution_m=20.0, margin_m=200.0,
                   levels=[45.0, 50.0, 55.0], ground_h=80.0)
    with rasterio.open(tmp_path / "ref" / "levels.tif") as ds:
        expect = ds.read(list(ds.descriptions).index("LAmax") + 1)
    assert ref is not None
    np.testing.assert_array_equal(lamax, expect)
    assert 40.0 < float(np.nanmax(lamax)) < 100.0


def test_serve_answers_the_web_page_and_the_openapi_document(installed):
    pytest.importorskip("fastapi")
    import httpx

    bin_dir, env, work = installed
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = (work / "serve.log").open("w")
    proc = subprocess.Popen([str(bin_dir / "gisnoise"), "serve", "--host", "127.0.0.1", "--port", str(port),
                             "--data-dir", str(work / "data")], cwd=work, env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                page = httpx.get(f"http://127.0.0.1:{port}/", timeout=2)
                break
            except httpx.TransportError:
                assert proc.poll() is None, (work / "serve.log").read_text()
                assert time.monotonic() < deadline, "server not up"
                time.sleep(0.3)
        assert page.status_code == 200 and "<html" in page.text.lower()
        api = httpx.get(f"http://127.0.0.1:{port}/openapi.json", timeout=10)
        assert api.status_code == 200 and api.json()["info"]["title"]
        cards = httpx.get(f"http://127.0.0.1:{port}/cards", timeout=10)
        assert cards.status_code == 200 and "demo-horizontal" in cards.text
        route = httpx.get(f"http://127.0.0.1:{port}/samples/route", timeout=10)
        assert route.status_code == 200 and route.json()["type"] in ("FeatureCollection", "Feature")
    finally:
        proc.terminate()
        proc.wait(timeout=20)
        log.close()
