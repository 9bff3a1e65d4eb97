"""The package layout: dependencies flow one way, no import cycles, no private names across subpackages.

Read off the source with :mod:`ast` (nothing is imported), so the test also sees imports
inside functions ("deferred" imports).  ``docs/architecture.md`` draws the same table.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "gisnoise"
PLUGIN = ROOT / "qgis_plugin" / "gisnoise_qgis"

#: Top-level modules every subpackage may use (they import no subpackage themselves).
BASE = {"gisnoise", "gisnoise.errors", "gisnoise.jsonio", "gisnoise.data", "gisnoise.reporting", "gisnoise.limits"}

_LOW = {"acoustics", "geo", "flight"}
#: What each subpackage may import, besides itself and BASE.  The faces (cli, service) may import any.
ALLOWED: dict[str, set[str]] = {
    "acoustics": set(),
    "geo": set(),
    "flight": {"geo"},
    "measure": _LOW,
    "model": _LOW | {"measure"},
    "identify": _LOW | {"measure", "model"},
    "simulate": _LOW | {"measure", "model"},
    "diagnose": _LOW | {"measure", "model", "identify"},
    "design": _LOW | {"measure", "model", "identify", "simulate"},
    "maps": _LOW | {"model"},
    "ops": _LOW | {"model", "maps"},
    "exposure": _LOW | {"model", "maps", "ops"},
    "planning": _LOW | {"model", "maps", "exposure"},
}
FACES = {"cli", "service"}
#: Modules allowed above about 600 lines, and why (none today).
LONG_MODULES: dict[str, str] = {}
MAX_LINES = 620


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


MODULES = _modules()


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def _imports(path: Path, name: str) -> Iterator[tuple[str, str | None, bool, int]]:
    """(module, imported name or None, type-checking only, line) of every import in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]

    def visit(nodes: list[ast.stmt], typing_only: bool) -> Iterator[tuple[str, str | None, bool, int]]:
        for node in nodes:
            if isinstance(node, ast.If) and _is_type_checking(node):
                yield from visit(node.body, True)
                yield from visit(node.orelse, typing_only)
                continue
            if isinstance(node, ast.Import):
                for a in node.names:
                    yield a.name, None, typing_only, node.lineno
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - node.level + 1]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                for a in node.names:
                    yield mod, a.name, typing_only, node.lineno
            for child in ast.iter_child_nodes(node):
                if isinstance(child, ast.stmt):
                    yield from visit([child], typing_only)
                elif hasattr(child, "body") and isinstance(child.body, list):
                    yield from visit(child.body, typing_only)  # type: ignore[attr-defined]

    yield from visit(tree.body, False)


def _target(mod: str, name: str | None) -> str:
    """The module an import runs: ``from pkg import sub`` runs ``pkg.sub`` when that is a module."""
    if name and f"{mod}.{name}" in MODULES:
        return f"{mod}.{name}"
    return mod


def _subpackage(module: str) -> str | None:
    if module == "gisnoise.__main__":  # ``python -m gisnoise``: the command line's entry
        return "cli"
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] != "data" and (PKG / parts[1]).is_dir():
        return parts[1]
    return None


EDGES: list[tuple[str, str, str | None, bool, int]] = []  # (importer, target, name, typing-only, line)
for _name, _path in MODULES.items():
    for _mod, _imp, _typing, _line in _imports(_path, _name):
        if _mod == "gisnoise" or _mod.startswith("gisnoise."):
            EDGES.append((_name, _target(_mod, _imp), _imp, _typing, _line))


def test_subpackages_import_only_what_lies_below_them():
    bad = []
    for src, dst, _name, _typing, line in EDGES:
        a, b = _subpackage(src), _subpackage(dst)
        if b is None or a == b:
            if a is None and b is not None and src not in BASE | {"gisnoise"}:
                bad.append(f"{src}:{line} (a top-level module) imports {dst}")
            elif src in BASE and b is not None:
                bad.append(f"{src}:{line} (a base module) imports {dst}")
            continue
        if a is None:
            bad.append(f"{src}:{line} (a base module) imports {dst}")
        elif a in FACES:
            if b == "cli" and a != "cli":
                bad.append(f"{src}:{line} imports the command line {dst}")
        elif b in FACES:
            bad.append(f"{src}:{line} imports the face {dst}")
        elif b not in ALLOWED[a]:
            bad.append(f"{src}:{line} imports {dst}: {a} may import only {sorted(ALLOWED[a]) or 'nothing'}")
    assert not bad, "imports against the flow:\n" + "\n".join(bad)


def test_every_subpackage_is_in_the_table():
    found = {p.name for p in PKG.iterdir() if (p / "__init__.py").is_file()} - {"data"}
    assert found == set(ALLOWED) | FACES


def test_no_import_cycles_deferred_imports_included():
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for src, dst, _name, typing_only, _line in EDGES:
        if not typing_only and dst in graph and dst != src:
            graph[src].add(dst)
    # Tarjan's strongly connected components
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    import sys

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))
    for v in graph:
        if v not in index:
            strong(v)
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


def test_no_private_names_across_subpackages():
    bad = []
    for src, dst, name, _typing, line in EDGES:
        a, b = _subpackage(src), _subpackage(dst)
        private_module = any(part.startswith("_") and part != "__init__" for part in dst.split(".")[1:])
        private_name = bool(name) and name.startswith("_") and not name.startswith("__")
        if a == b and a is not None:
            continue
        if private_name or (private_module and not (a is None and b is None)):
            bad.append(f"{src}:{line} imports {dst}" + (f".{name}" if name else ""))
    assert not bad, "private names used across subpackages:\n" + "\n".join(bad)


@pytest.mark.skipif(not PLUGIN.is_dir(), reason="no QGIS plugin in this checkout")
def test_the_qgis_plugin_uses_only_public_names_of_the_core():
    bad = []
    for path in sorted(PLUGIN.rglob("*.py")):
        for mod, name, _typing, line in _imports(path, "gisnoise_qgis." + _module_name(path).split(".", 2)[-1]):
            if not (mod == "gisnoise" or mod.startswith("gisnoise.")):
                continue
            if any(p.startswith("_") for p in mod.split(".")[1:]) or (name or "").startswith("_"):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod}" + (f".{name}" if name else ""))
            if _subpackage(mod) in FACES:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports the face {mod}")
    assert not bad, "\n".join(bad)


def test_modules_are_short():
    long = []
    for path in MODULES.values():
        rel = path.relative_to(ROOT).as_posix()
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES and rel not in LONG_MODULES:
            long.append(f"{rel}: {n} lines")
    assert not long, "modules above about 600 lines:\n" + "\n".join(long)


def test_no_private_attributes_of_modules_of_other_subpackages():
    """``from gisnoise.model import effects as _e`` then ``_e._shift(...)`` is a private import too."""
    bad = []
    for src, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases: dict[str, str] = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("gisnoise"):
                for a in node.names:
                    if f"{node.module}.{a.name}" in MODULES:
                        aliases[a.asname or a.name] = f"{node.module}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.asname and a.name in MODULES:
                        aliases[a.asname] = a.name
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                dst = aliases[node.value.id]
                if _subpackage(dst) != _subpackage(src):
                    bad.append(f"{src}:{node.lineno} uses {dst}.{node.attr}")
    assert not bad, "private names used across subpackages:\n" + "\n".join(sorted(set(bad)))
