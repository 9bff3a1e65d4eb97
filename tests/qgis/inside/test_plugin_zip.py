"""The plugin zip loaded in a fresh QGIS without the compiled packages it bundles: a plain message."""

import json
import os
import shutil
import subprocess
import sys
import zipfile

import pytest

pytestmark = pytest.mark.qgis

LOAD = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
from qgis.core import QgsApplication
app = QgsApplication([], False)
app.initQgis()
import gisnoise_qgis

class Bar:
    messages = []
    def pushMessage(self, title, text, level=None, duration=None):
        self.messages.append(text)

class Iface:
    bar = Bar()
    def messageBar(self):
        return self.bar

plugin = gisnoise_qgis.classFactory(Iface())
plugin.initGui()
registered = QgsApplication.processingRegistry().providerById("gisnoise") is not None
plugin.unload()
print(json.dumps({"messages": Bar.messages, "registered": registered}))
"""


def _qgis_shapely():
    r = subprocess.run([sys.executable, "-c", "import shapely; print(shapely.__version__)"], capture_output=True,
                       text=True, timeout=60)
    return r.stdout.strip() if r.returncode == 0 else None


def _install(plugin_zip, root, edit):
    folder = root / "plugins"
    with zipfile.ZipFile(plugin_zip) as zf:
        zf.extractall(folder)
    vendor = folder / "gisnoise_qgis" / "vendor"
    manifest = json.loads((vendor / "bundled.json").read_text())
    manifest = edit(vendor, manifest)
    (vendor / "bundled.json").write_text(json.dumps(manifest))
    return folder


def _load(folder, tmp_path):
    runtime = tmp_path / "xdg"
    runtime.mkdir(mode=0o700, exist_ok=True)
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "XDG_RUNTIME_DIR": str(runtime),
           "QGIS_CUSTOM_CONFIG_PATH": str(tmp_path / "settings")}
    r = subprocess.run([sys.executable, "-c", LOAD, str(folder)], capture_output=True, text=True, timeout=120,
                       env=env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_without_the_bundled_shapely_the_plugin_says_what_to_install(plugin_zip, tmp_path):
    have = _qgis_shapely()
    if have is not None and int(have.split(".")[0]) >= 2:
        pytest.skip(f"this QGIS brings shapely {have}: nothing is missing")

    def drop_shapely(vendor, manifest):
        shutil.rmtree(vendor / "shapely")
        return [m for m in manifest if m["module"] != "shapely"]

    out = _load(_install(plugin_zip, tmp_path, drop_shapely), tmp_path)
    assert out["registered"]  # the provider still loads; its algorithms refuse with the same message
    assert len(out["messages"]) == 1
    text = out["messages"][0]
    assert text.startswith("gisnoise cannot run in this QGIS: shapely")
    assert ("older than 2.0" if have else "not installed") in text
    for platform_hint in ("Linux: python3 -m pip install --user 'shapely>=2.0'", "Windows: in the OSGeo4W Shell",
                          "macOS: /Applications/QGIS.app/Contents/MacOS/bin/python3 -m pip"):
        assert platform_hint in text


def test_a_bundled_wheel_for_another_python_is_named(plugin_zip, tmp_path):
    have = _qgis_shapely()
    if have is not None and int(have.split(".")[0]) >= 2:
        pytest.skip(f"this QGIS brings shapely {have}: the bundled wheel is not used")

    def other_python(vendor, manifest):
        for m in manifest:
            if m["module"] == "shapely":
                m["wheel"] = "shapely-2.0.6-cp39-cp39-win_amd64.whl"
        return manifest

    out = _load(_install(plugin_zip, tmp_path, other_python), tmp_path)
    text = out["messages"][0]
    minor = f"{sys.version_info.major}.{sys.version_info.minor}"
    assert f"the bundled shapely-2.0.6-cp39-cp39-win_amd64.whl is built for cp39 on win_amd64, but QGIS runs " \
           f"Python {minor} on linux" in text


def test_the_zip_as_built_loads_without_a_message(plugin_zip, tmp_path):
    out = _load(_install(plugin_zip, tmp_path, lambda vendor, manifest: manifest), tmp_path)
    assert out == {"messages": [], "registered": True}
