"""The package layout: no import cycles between Samba modules, every console script is a
``main`` in a ``.cli.`` package, and pyproject.toml installs every package folder on disk.

The import graph is read from the source with :mod:`ast` (nothing is imported): every
``import`` and ``from ... import`` of samba_common, samba_mote and samba_server, at module
level or inside functions, relative or absolute. An import of ``a.b.c`` is an edge to the
module ``a.b.c`` only (not to the packages ``a`` and ``a.b`` that Python initialises first):
a package ``__init__`` re-exporting its submodules would otherwise make every submodule that
imports a sibling look cyclic. Imports under ``if TYPE_CHECKING:`` are not run, so not counted.
"""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("samba_common", "samba_mote", "samba_server")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (file, is a package __init__)."""
    mods = {}
    for top in PACKAGES:
        for f in sorted((ROOT / top).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            is_pkg = parts[-1] == "__init__"
            if is_pkg:
                parts = parts[:-1]
            mods[".".join(parts)] = (f, is_pkg)
    return mods


MODULES = _modules()


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST):
    """Every Import / ImportFrom node, except those under ``if TYPE_CHECKING:``."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        children = list(ast.iter_child_nodes(node))
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            children = node.orelse
        stack.extend(children)


def _owner(name: str) -> str | None:
    """The innermost Samba module ``name`` lives in (``a.b.c`` -> ``a.b`` if c is an attribute)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def import_graph() -> dict[str, set[str]]:
    """module -> the Samba modules it imports (itself excluded)."""
    graph: dict[str, set[str]] = {}
    for mod, (path, is_pkg) in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        package = mod if is_pkg else mod.rpartition(".")[0]
        deps: set[str] = set()
        for node in _imports(tree):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                if node.level:
                    base = package.split(".")
                    base = base[:len(base) - (node.level - 1)]
                    assert base, f"{path}:{node.lineno}: relative import beyond the top-level package"
                    origin = ".".join(base + ([node.module] if node.module else []))
                else:
                    origin = node.module or ""
                # ``from pkg import sub`` imports the submodule pkg.sub; ``from mod import name`` mod
                targets = [f"{origin}.{a.name}" if f"{origin}.{a.name}" in MODULES else origin for a in node.names]
            deps.update(t for t in map(_owner, targets) if t is not None)
        deps.discard(mod)
        graph[mod] = deps
    return graph


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle (a -> ... -> a) per strongly connected component that has one (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[set[str]] = []

    def visit(v: str) -> None:  # recursion depth <= number of modules
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    cycles = []
    for comp in components:  # shortest way back to the start inside the component (BFS)
        start = min(comp)
        prev: dict[str, str] = {}
        frontier = [start]
        while frontier and start not in prev:
            nxt = []
            for v in frontier:
                for w in sorted(graph[v] & comp):
                    if w not in prev:
                        prev[w] = v
                        nxt.append(w)
            frontier = nxt
        path = [start]
        while prev[path[-1]] != start:
            path.append(prev[path[-1]])
        cycles.append([start] + path[::-1])
    return cycles


def test_graph_sees_relative_and_function_level_imports() -> None:
    graph = import_graph()
    assert len(graph) > 50
    # relative (``from .record import ...``) at module level
    assert "samba_server.record" in graph["samba_server.replay"]
    # absolute, inside a function (``from samba_mote.sim.render import ...`` in project_take)
    assert "samba_mote.sim.render" in graph["samba_server.simmotes"]
    # ``from samba_server.recon import kernels``-style: the submodule, not the package
    assert "samba_server.recon.kernels" in graph["samba_server.recon.reconstruct"]


def test_find_cycles_reports_a_cycle() -> None:
    g = {"a": {"b"}, "b": {"c"}, "c": {"a", "d"}, "d": set(), "e": {"e"}}
    assert find_cycles(g) == [["a", "b", "c", "a"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles() -> None:
    graph = import_graph()
    cycles = find_cycles(graph)
    text = "\n".join(" -> ".join(c) for c in cycles)
    if cycles:
        print("import cycles:\n" + text)
    assert not cycles, f"import cycles between Samba modules:\n{text}"


@pytest.mark.parametrize("command", sorted(PYPROJECT["project"]["scripts"]))
def test_console_script_is_a_cli_main(command: str) -> None:
    target = PYPROJECT["project"]["scripts"][command]
    module, _, attr = target.partition(":")
    assert ".cli." in module + ".", f"{command} = {target!r}: entry points live in a .cli package"
    assert module.rpartition(".")[2] == command.removeprefix("samba-"), \
        f"{command} = {target!r}: samba-NAME is the module cli/NAME.py"
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    assert callable(obj), f"{command} = {target!r} is not callable"
    assert obj.__module__ == module, f"{command}: {attr} is defined in {obj.__module__}, not in {module}"


def _folders_on_disk() -> set[str]:
    """Installed package name of every folder holding code or data (configs/ -> samba_configs)."""
    roots = {top: ROOT / top for top in PACKAGES}
    roots.update({pkg: ROOT / d for pkg, d in PYPROJECT["tool"]["setuptools"].get("package-dir", {}).items()})
    found = set()
    for name, root in roots.items():
        for d in [root, *sorted(p for p in root.rglob("*") if p.is_dir())]:
            rel = d.relative_to(root).parts
            if any(part == "__pycache__" or part.startswith(".") for part in rel):
                continue
            if any(f.is_file() and not f.name.startswith(".") for f in d.iterdir()):
                found.add(".".join((name, *rel)))
    return found


def test_pyproject_installs_every_package_folder() -> None:
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    on_disk = _folders_on_disk()
    assert not on_disk - listed, f"add to [tool.setuptools] packages: {sorted(on_disk - listed)}"
    assert not listed - on_disk, f"listed in [tool.setuptools] packages but not on disk: {sorted(listed - on_disk)}"
