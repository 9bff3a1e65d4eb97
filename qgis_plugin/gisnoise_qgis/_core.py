"""Access to the gisnoise core from inside QGIS.

The built plugin carries the core in the folder ``ext`` next to this file and,
in ``vendor/<module>``, the packages the core needs that QGIS's Python may lack
or have too old (``vendor/bundled.json`` lists them with the minimum version the
core needs).  :func:`ensure_core` puts ``ext`` first on ``sys.path`` (the core
the plugin was built with wins over any other), puts a bundled package on the
path only when QGIS's own copy is missing or too old, and checks the compiled
packages QGIS must provide, so that an algorithm fails with one message naming
each missing package instead of an ImportError deep inside the core.
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

#: Compiled packages QGIS's Python must provide: module, minimum version, Debian package.
REQUIRED = (
    ("numpy", "1.24", "python3-numpy"),
    ("scipy", "1.10", "python3-scipy"),
    ("pyproj", "3.4", "python3-pyproj"),
    ("rasterio", "1.3", "python3-rasterio"),
    ("contourpy", "1.0", "python3-contourpy"),
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


def this_platform() -> str:
    """``linux``, ``windows`` or ``macos`` (else ``sys.platform``)."""
    if sys.platform.startswith("linux"):
        return "linux"
    if sys.platform == "win32":
        return "windows"
    if sys.platform == "darwin":
        return "macos"
    return sys.platform


def install_hint(requirements: list[str]) -> str:
    """How to install ``requirements`` (pip specifiers) into QGIS's own Python, on each platform."""
    spec = " ".join(f"'{r}'" for r in requirements)
    win = " ".join(f'"{r}"' for r in requirements)
    return (f"install into QGIS's Python, then restart QGIS. Linux: python3 -m pip install --user {spec} "
            f"(or your distribution's python3 packages of these versions); Windows: in the OSGeo4W Shell, "
            f"python -m pip install {win}; macOS: /Applications/QGIS.app/Contents/MacOS/bin/python3 -m pip "
            f"install --user {spec}")


def wheel_mismatch(wheel: str) -> str | None:
    """Why a bundled wheel (by file name) cannot load in this Python; None when its tags fit."""
    parts = wheel[:-4].split("-") if wheel.endswith(".whl") else []
    if len(parts) < 5:
        return None
    py_tag, plat_tag = parts[-3], parts[-1]
    want = f"cp{sys.version_info.major}{sys.version_info.minor}"
    plat = this_platform()
    plat_ok = {"linux": "linux" in plat_tag, "windows": plat_tag.startswith("win"),
               "macos": plat_tag.startswith("macosx")}.get(plat, False)
    tags_ok = want in py_tag.split(".") or "abi3" in parts[-2]
    if tags_ok and plat_ok:
        return None
    return (f"the bundled {wheel} is built for {py_tag} on {plat_tag}, but QGIS runs Python "
            f"{sys.version_info.major}.{sys.version_info.minor} on {plat}")


def _use_bundled(problems: list[str]) -> None:
    for item in bundled():
        module, minimum = item["module"], item["minimum"]
        have = installed_version(module)
        if have is not None and version_tuple(have) >= version_tuple(minimum):
            continue
        why = wheel_mismatch(item.get("wheel", "")) if item.get("compiled") else None
        if why:
            problems.append(f"{module} >= {minimum} (QGIS has {have or 'none'}; {why})")
            continue
        folder = os.path.join(VENDOR_DIR, module)
        if module in sys.modules:
            problems.append(f"{module} {have} is already loaded in this QGIS but the core needs >= {minimum}; "
                            f"the plugin bundles {item['version']}: restart QGIS to use it")
            continue
        if folder not in sys.path:
            sys.path.insert(0, folder)
        if item.get("compiled"):
            _load_isolated(folder, module)
        QgsMessageLog.logMessage(f"using the bundled {module} {item['version']} (QGIS has "
                                 f"{have or 'none'}, the core needs >= {minimum})", "gisnoise")


def _load_isolated(folder: str, module: str) -> None:
    """Import every extension module of a bundled compiled package, bound to its own libraries.

    QGIS itself links the system's GEOS (and GDAL, PROJ); on Linux the dynamic
    linker would resolve a bundled wheel's calls into its own copy of such a
    library to the already loaded system copy wherever the names match, mixing
    two versions in one call chain (a crash).  ``RTLD_DEEPBIND`` makes the
    wheel's modules look up their own libraries first.
    """
    deepbind = getattr(os, "RTLD_DEEPBIND", None)
    names = [module]
    pkg = os.path.join(folder, module)
    for dirpath, _dirs, files in os.walk(pkg):
        for f in files:
            if f.endswith((".so", ".pyd")):
                rel = os.path.relpath(os.path.join(dirpath, f.split(".")[0]), folder)
                names.append(rel.replace(os.sep, "."))
    flags = sys.getdlopenflags() if hasattr(sys, "getdlopenflags") else None
    if deepbind is not None and flags is not None:
        sys.setdlopenflags(flags | deepbind)
    try:
        for name in names:
            importlib.import_module(name)
    finally:
        if deepbind is not None and flags is not None:
            sys.setdlopenflags(flags)


#: Compiled packages the core needs that QGIS often lacks and the zip may bundle: module -> minimum.
BUNDLED_COMPILED = {"shapely": "2.0"}


def _unbundled_compiled(problems: list[str]) -> None:
    """A compiled package the core needs that neither QGIS (recent enough) nor the zip provides."""
    have_bundled = {item["module"] for item in bundled()}
    for module, minimum in BUNDLED_COMPILED.items():
        if module in have_bundled:
            continue
        have = installed_version(module)
        if have is None:
            problems.append(f"{module} >= {minimum} is not installed")
        elif version_tuple(have) < version_tuple(minimum):
            problems.append(f"{module} {have} is older than {minimum}")


def load_problems() -> str | None:
    """The plain message shown when the plugin loads and the core cannot work here, else None.

    Names each missing or too old package and how to install it on Linux, Windows and macOS.
    Does not import the core.
    """
    problems = missing_requirements()
    _unbundled_compiled(problems)
    if not problems:
        probe: list[str] = []
        _check_bundled(probe)
        problems = probe
    if not problems:
        return None
    reqs = []
    for line in problems:
        name = line.split()[0]
        minimum = dict((m, v) for m, v, _ in REQUIRED).get(name) or BUNDLED_COMPILED.get(name)
        if minimum:
            reqs.append(f"{name}>={minimum}")
    text = "gisnoise cannot run in this QGIS: " + "; ".join(problems) + "."
    if reqs:
        text += " To fix it, " + install_hint(reqs) + "."
    return text


def _check_bundled(problems: list[str]) -> None:
    """Like :func:`_use_bundled` without touching ``sys.path``: what the bundled packages cannot fix."""
    for item in bundled():
        module, minimum = item["module"], item["minimum"]
        have = installed_version(module)
        if have is not None and version_tuple(have) >= version_tuple(minimum):
            continue
        why = wheel_mismatch(item.get("wheel", "")) if item.get("compiled") else None
        if why:
            problems.append(f"{module} >= {minimum} (QGIS has {have or 'none'}; {why})")


def missing_requirements() -> list[str]:
    """One line per compiled requirement that is absent or too old in this Python."""
    problems = []
    if sys.version_info < (3, 10):  # noqa: UP036 - QGIS may bring an older Python than the project
        problems.append(f"Python >= 3.10 (QGIS runs Python {sys.version.split()[0]}; use a QGIS built with a newer "
                        "Python)")
    for module, minimum, debian in REQUIRED:
        have = installed_version(module)
        if have is None:
            problems.append(f"{module} >= {minimum} is not installed (Debian/Ubuntu: {debian})")
        elif version_tuple(have) < version_tuple(minimum):
            problems.append(f"{module} {have} is older than {minimum} (Debian/Ubuntu: {debian})")
    return problems


def ensure_core():
    """Make ``gisnoise`` importable and check what it needs.

    Returns
    -------
    module
        The ``gisnoise`` package.

    Raises
    ------
    QgsProcessingException
        Naming every missing or too old package, or the core itself.
    """
    global _ready
    if not _ready:
        if os.path.isdir(EXT_DIR) and EXT_DIR not in sys.path:
            sys.path.insert(0, EXT_DIR)
        problems = missing_requirements()
        _unbundled_compiled(problems)
        _use_bundled(problems)
        if problems:
            message = load_problems() or ("gisnoise needs these Python packages in QGIS's Python: "
                                          + "; ".join(problems))
            raise QgsProcessingException(message)
    try:
        gisnoise = importlib.import_module("gisnoise")
        importlib.import_module("gisnoise.maps.pipeline")
    except ImportError as exc:
        raise QgsProcessingException(
            f"the gisnoise core is not importable in QGIS's Python ({exc}); install the plugin from the zip "
            "made by scripts/build-plugin, which bundles it") from None
    _ready = True
    return gisnoise
