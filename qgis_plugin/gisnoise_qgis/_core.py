"""Access to the gisnoise core from inside QGIS.

The built plugin carries the core in the folder ``ext`` next to this file and,
in ``vendor/<module>``, the pure-Python packages the core needs that QGIS's
Python may lack or have too old (``vendor/bundled.json`` lists them with the
minimum version the core needs).  Nothing compiled is bundled: numpy, GDAL and
the other compiled packages (:data:`REQUIRED`) come from QGIS's own Python, so
one zip loads on every platform and Python QGIS runs.  shapely 1.8 (QGIS 3.22,
Debian 12, Ubuntu 22.04) is enough: the core calls it through
``gisnoise.geo.shapes``.

:func:`load_problems` (run when the plugin loads) names each missing or too old
package and how to install it on Linux, Windows and macOS; :func:`ensure_core`
puts ``ext`` first on ``sys.path`` (the core the plugin was built with wins over
any other), puts a bundled package on the path only when QGIS's own copy is
missing or too old, and refuses with the same message, so an algorithm never
fails with an ImportError deep inside the core.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import json
import os
import sys

from qgis.core import QgsMessageLog, QgsProcessingException

HERE = os.path.dirname(os.path.abspath(__file__))
EXT_DIR = os.path.join(HERE, "ext")
VENDOR_DIR = os.path.join(HERE, "vendor")

#: Compiled packages QGIS's Python must provide: module (= pip name), minimum version, Debian/Ubuntu package,
#: Fedora package.  scripts/build-plugin reads its list of what QGIS provides from here.
REQUIRED = (
    ("numpy", "1.24", "python3-numpy", "python3-numpy"),
    ("scipy", "1.10", "python3-scipy", "python3-scipy"),
    ("pyproj", "3.4", "python3-pyproj", "python3-pyproj"),
    ("shapely", "1.8", "python3-shapely", "python3-shapely"),
    ("rasterio", "1.3", "python3-rasterio", "python3-rasterio"),
    ("contourpy", "1.0", "python3-contourpy", "python3-contourpy"),
)

_ready = False


def version_tuple(text: str) -> tuple[int, ...]:
    """``"2.0.1"`` -> ``(2, 0, 1)``; stops at the first part without digits."""
    out = []
    for part in str(text).split(".")[:3]:
        digits = ""
        for ch in part:
            if not ch.isdigit():
                break
            digits += ch
        if not digits:
            break
        out.append(int(digits))
    return tuple(out)


def installed_version(module: str) -> str | None:
    """Version of ``module`` in this Python without importing it; None when absent."""
    loaded = sys.modules.get(module)
    if loaded is not None:
        return str(getattr(loaded, "__version__", "0"))
    if importlib.util.find_spec(module) is None:
        return None
    for dist in importlib.metadata.packages_distributions().get(module, ()):
        try:
            return importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    return str(getattr(importlib.import_module(module), "__version__", "0"))


def bundled() -> list[dict]:
    """The packages the built plugin bundles (empty when running from the sources)."""
    path = os.path.join(VENDOR_DIR, "bundled.json")
    if not os.path.exists(path):
        return []
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


def externally_managed() -> bool:
    """Whether this Python is managed by the operating system (PEP 668: Debian 12, Ubuntu 23.04 and newer, ...).

    Its pip then refuses to install anything, even with ``--user``, unless given ``--break-system-packages``;
    with ``--user`` that option only lets pip write into the user's own site-packages.
    """
    import sysconfig

    if sys.prefix != sys.base_prefix:  # a virtual environment is never marked
        return False
    stdlib = sysconfig.get_path("stdlib")
    return bool(stdlib) and os.path.isfile(os.path.join(stdlib, "EXTERNALLY-MANAGED"))


def linux_pip(spec: str) -> str:
    """The pip command that installs ``spec`` into the user's site-packages of this Linux Python."""
    if externally_managed():
        return f"python3 -m pip install --user --break-system-packages {spec}"
    return f"python3 -m pip install --user {spec}"


def pip_hint(modules: list[str]) -> str:
    """How to pip-install ``modules`` into QGIS's Python on Linux, Windows and macOS (for packages no Linux
    distribution has)."""
    spec = " ".join(modules)
    linux = linux_pip(spec)
    if "--break-system-packages" in linux:
        linux += (" (into your home folder only; this Python is managed by the system (PEP 668), so pip needs "
                  "--break-system-packages even with --user)")
    return (f"Linux: {linux}; Windows: in the OSGeo4W Shell, python -m pip install {spec}; "
            f"macOS: /Applications/QGIS.app/Contents/MacOS/bin/python3 -m pip install --user {spec}; "
            "then restart QGIS")


def install_hint(missing: list[tuple[str, str, str, str]]) -> str:
    """How to install ``missing`` ((module, minimum, Debian package, Fedora package)) into QGIS's Python."""
    spec = " ".join(f"'{m}>={v}'" for m, v, _, _ in missing)
    win = " ".join(f'"{m}>={v}"' for m, v, _, _ in missing)
    debian = " ".join(d for _, _, d, _ in missing)
    fedora = " ".join(f for _, _, _, f in missing)
    return (f"Linux: sudo apt install {debian} (Debian, Ubuntu), sudo dnf install {fedora} (Fedora), or "
            f"{linux_pip(spec)}; "
            f"Windows: in the OSGeo4W Shell, python -m pip install {win}; "
            f"macOS: /Applications/QGIS.app/Contents/MacOS/bin/python3 -m pip install --user {spec}; "
            "then restart QGIS")


def missing_requirements() -> list[tuple[str, str, str, str, str | None]]:
    """(module, minimum, Debian package, Fedora package, installed version or None) of each compiled
    package QGIS's Python lacks or has too old."""
    out = []
    for module, minimum, debian, fedora in REQUIRED:
        try:
            have = installed_version(module)
        except ImportError:  # present but broken (a compiled part for another Python): as good as absent
            have = None
        if have is None or version_tuple(have) < version_tuple(minimum):
            out.append((module, minimum, debian, fedora, have))
    return out


def load_problems() -> str | None:
    """The plain message shown when the plugin loads and the core cannot work here, else None.

    Names each missing or too old package and how to install it on Linux, Windows and macOS.
    Does not import the core.
    """
    parts = []
    if sys.version_info < (3, 10):  # noqa: UP036 - QGIS may bring an older Python than the project
        parts.append(f"it needs Python >= 3.10 (this QGIS runs Python {sys.version.split()[0]}; use QGIS 3.22 or "
                     "newer built with a newer Python)")
    missing = missing_requirements()
    for module, minimum, _, _, have in missing:
        parts.append(f"{module} >= {minimum} is not installed" if have is None
                     else f"{module} {have} is older than {minimum}")
    if not parts:
        return None
    text = "gisnoise cannot run in this QGIS: " + "; ".join(parts) + "."
    if missing:
        text += " To fix it, install into QGIS's Python: " + install_hint([m[:4] for m in missing]) + "."
    return text


def _use_bundled() -> None:
    """Put each bundled pure-Python package on ``sys.path`` when QGIS's own is missing or too old."""
    for item in bundled():
        module, minimum = item["module"], item["minimum"]
        have = installed_version(module)
        if have is not None and version_tuple(have) >= version_tuple(minimum):
            continue
        folder = os.path.join(VENDOR_DIR, module)
        if folder not in sys.path:
            sys.path.insert(0, folder)
        QgsMessageLog.logMessage(f"using the bundled {module} {item['version']} (QGIS has "
                                 f"{have or 'none'}, the core needs >= {minimum})", "gisnoise")


def ensure_core():
    """Make ``gisnoise`` importable and check what it needs.

    Returns
    -------
    module
        The ``gisnoise`` package.

    Raises
    ------
    QgsProcessingException
        Naming every missing or too old package (the message of :func:`load_problems`), or the core itself.
    """
    global _ready
    if not _ready:
        if os.path.isdir(EXT_DIR) and EXT_DIR not in sys.path:
            sys.path.insert(0, EXT_DIR)
        message = load_problems()
        if message:
            raise QgsProcessingException(message)
        _use_bundled()
    try:
        gisnoise = importlib.import_module("gisnoise")
        importlib.import_module("gisnoise.maps.pipeline")
    except ImportError as exc:
        raise QgsProcessingException(
            f"the gisnoise core is not importable in QGIS's Python ({exc}); install the plugin from the zip "
            "made by scripts/build-plugin, which bundles it") from None
    _ready = True
    return gisnoise
