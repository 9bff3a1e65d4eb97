"""The plugin zip in a fresh QGIS: pure Python only; without the compiled packages it needs, a plain message."""

import json
import os
import re
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.qgis

#: Loads the plugin like QGIS desktop does (classFactory, initGui with a message bar); BLOCK lists modules
#: made absent (sys.modules[name] = None: imports fail, find_spec says "not installed") or given an old version.
LOAD = r"""
import json, sys, types
sys.path.insert(0, sys.argv[1])
for item in json.loads(sys.argv[2]):
    name, _, version = item.partition("=")
    if version:
        fake = types.ModuleType(name)
        fake.__version__ = version
        sys.modules[name] = fake
    else:
        sys.modules[name] = None
from qgis.core import QgsApplication, QgsProcessingException
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
from gisnoise_qgis._core import ensure_core
try:
    core = ensure_core()
    from gisnoise.geo import shapes
    refused, core_from, shapely2 = None, core.__file__, shapes.SHAPELY2
except QgsProcessingException as exc:
    refused, core_from, shapely2 = str(exc), None, None
plugin.unload()
print(json.dumps({"messages": Bar.messages, "registered": registered, "refused": refused, "core": core_from,
                  "shapely2": shapely2}))
"""

HINTS = ("Linux: sudo apt install ", "(Debian, Ubuntu), sudo dnf install ", "(Fedora), or python3 -m pip install --user ",
         "Windows: in the OSGeo4W Shell, python -m pip install ",
         "macOS: /Applications/QGIS.app/Contents/MacOS/bin/python3 -m pip install --user ", "then restart QGIS")


def _install(plugin_zip, root):
    folder = root / "plugins"
    with zipfile.ZipFile(plugin_zip) as zf:
        zf.extractall(folder)
    return folder


def _load(folder, tmp_path, block=()):
    runtime = tmp_path / "xdg"
    runtime.mkdir(mode=0o700, exist_ok=True)
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "XDG_RUNTIME_DIR": str(runtime),
           "QGIS_CUSTOM_CONFIG_PATH": str(tmp_path / "settings")}
    r = subprocess.run([sys.executable, "-c", LOAD, str(folder), json.dumps(list(block))], capture_output=True,
                       text=True, timeout=120, env=env)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_zip_holds_no_compiled_code(plugin_zip):
    with zipfile.ZipFile(plugin_zip) as zf:
        names = zf.namelist()
        manifest = json.loads(zf.read("gisnoise_qgis/vendor/bundled.json"))
        text = zf.read("gisnoise_qgis/bundled.txt").decode()
    assert not [n for n in names if Path(n).suffix in (".so", ".pyd", ".dylib", ".dll") or n.endswith(".whl")]
    assert all(not m["compiled"] for m in manifest)
    assert "shapely >= 1.8" in text and "numpy >= 1.24" in text


def test_without_the_compiled_packages_the_plugin_says_what_to_install(plugin_zip, tmp_path):
    out = _load(_install(plugin_zip, tmp_path), tmp_path, block=["shapely", "contourpy", "rasterio"])
    assert out["registered"]  # the provider still loads; its algorithms refuse with the same message
    assert len(out["messages"]) == 1
    text = out["messages"][0]
    assert text.startswith("gisnoise cannot run in this QGIS: shapely >= 1.8 is not installed; rasterio >= 1.3 is "
                           "not installed; contourpy >= 1.0 is not installed. To fix it, install into QGIS's Python: ")
    for hint in HINTS:
        assert hint in text
    assert "sudo apt install python3-shapely python3-rasterio python3-contourpy (Debian" in text
    assert "python -m pip install \"shapely>=1.8\" \"rasterio>=1.3\" \"contourpy>=1.0\"" in text
    assert "numpy" not in text and "scipy" not in text  # what is there is not named
    assert out["refused"] == text and out["core"] is None


def test_a_too_old_shapely_is_named_with_its_version(plugin_zip, tmp_path):
    out = _load(_install(plugin_zip, tmp_path), tmp_path, block=["shapely=1.7.1"])
    (text,) = out["messages"]
    assert text.startswith("gisnoise cannot run in this QGIS: shapely 1.7.1 is older than 1.8. To fix it")
    assert out["refused"] == text
    # the Linux pip command, which this Python's pip must accept (Debian 12: PEP 668, --break-system-packages)
    from conftest import pip_output

    command = re.search(r"or (python3 -m pip install [^;]*);", text).group(1)
    assert command.endswith("--user 'shapely>=1.8'") or command.endswith("--user --break-system-packages "
                                                                          "'shapely>=1.8'")
    assert "externally-managed-environment" not in pip_output(command)


def test_the_zip_as_built_loads_without_a_message_on_qgis_own_packages(plugin_zip, tmp_path):
    import shapely

    folder = _install(plugin_zip, tmp_path)
    out = _load(folder, tmp_path)
    assert out["messages"] == [] and out["registered"] and out["refused"] is None
    assert Path(out["core"]).resolve() == (folder / "gisnoise_qgis" / "ext" / "gisnoise" / "__init__.py").resolve()
    assert out["shapely2"] is (int(shapely.__version__.split(".")[0]) >= 2)  # QGIS's own shapely (1.8 on 3.22)
