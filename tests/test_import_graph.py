"""No import circles among fir_gym's modules (docs/architecture.md#import-graph).

The oracle is the source, not an import: every module of the *installed* package
(``fir_gym``, with ``fir_gym.envs`` and ``fir_gym.estimators`` where the package-dir
mapping puts them) is parsed with :mod:`ast`, every ``import`` statement in it — at module
level and inside functions, methods and ``try`` blocks alike, since a function-level import
runs as soon as the function does — becomes an edge to the fir_gym module it loads, and the
graph must be acyclic. The rules that turn a statement into edges:

- Relative imports are resolved against the importing module's package (a package's
  ``__init__`` is its own package).
- ``import a.b.c`` and ``from a.b.c import name`` load ``a.b.c``; ``from a.b import c``
  loads the submodule ``a.b.c`` when ``c`` is one, and ``a.b`` itself otherwise (a name
  its ``__init__`` binds).
- Loading ``a.b.c`` runs ``a/__init__`` and ``a/b/__init__`` first, so it is an edge to
  those packages too — **except to the importing module's own ancestors**. A module's
  ancestor packages have always started initialising before the module runs (Python
  imports ``fir_gym.scenarios`` before ``fir_gym.scenarios.paper003``), so the implied
  edge back to them is no circle; counting it would make every package ``__init__`` that
  re-exports its submodules (``fir_gym/__init__`` registering the plants,
  ``scenarios/__init__`` listing the papers) a spurious cycle. An *explicit* import of an
  ancestor package (``from .. import ENV_IDS``, ``from . import x`` where ``x`` is a name
  the ``__init__`` binds) reads something that ``__init__`` must already have bound, and
  is an edge like any other.
- Imports under ``if TYPE_CHECKING:`` never run and make no edge; imports built at run
  time from strings (``importlib.import_module``) are not seen.

So a cycle reported here is a real runtime circle: one of its modules can start running
while another of its modules is only partly initialised.
"""

from __future__ import annotations

import ast
import importlib.util
import os
from pathlib import Path

PACKAGE = "fir_gym"
#: the sub-packages pyproject's package-dir maps from elsewhere (docs/architecture.md#package-dir):
#: inside the installed fir_gym folder, and walked on their own too for an install that maps
#: them through an import hook
MAPPED = ("fir_gym.envs", "fir_gym.estimators")


def installed_modules() -> dict[str, Path]:
    """Every module of the installed package: dotted name -> source file."""
    modules: dict[str, Path] = {}
    for package in (PACKAGE, *MAPPED):
        spec = importlib.util.find_spec(package)
        assert spec is not None and spec.submodule_search_locations, package
        for location in spec.submodule_search_locations:
            modules.update(_walk(package, Path(location)))
    return modules


def _walk(package: str, top: Path) -> dict[str, Path]:
    """The modules of ``package`` under its folder ``top`` (sub-packages are folders with an
    ``__init__.py``; the strict editable install is a tree of links, so links are followed)."""
    modules: dict[str, Path] = {}
    for folder, dirs, files in os.walk(top, followlinks=True):
        dirs[:] = sorted(d for d in dirs if d != "__pycache__")
        if "__init__.py" not in files:
            dirs[:] = []              # not a package: nothing below it is importable
            continue
        parts = [package, *Path(folder).relative_to(top).parts]
        for name in sorted(files):
            if name.endswith(".py"):
                stem = name[:-3]
                dotted = ".".join(parts if stem == "__init__" else [*parts, stem])
                modules[dotted] = Path(folder) / name
    return modules


def _is_type_checking(test: ast.expr) -> bool:
    return ((isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
            or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"))


def _runtime_imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement that can run, at any depth, except under ``TYPE_CHECKING``."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            found.append(node)
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return found


def _ancestors(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def import_edges(module: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The fir_gym modules that running ``module`` can load (the rules of this file's
    docstring)."""
    is_package = path.name == "__init__.py"
    package = module if is_package else module.rpartition(".")[0]
    own_ancestors = set(_ancestors(module))
    explicit: set[str] = set()
    for node in _runtime_imports(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            explicit.update(alias.name for alias in node.names)
            continue
        if node.level:
            base = package.split(".")
            if node.level > 1:
                base = base[:-(node.level - 1)]
            source = ".".join([*base, node.module] if node.module else base)
        else:
            source = node.module or ""
        for alias in node.names:
            submodule = f"{source}.{alias.name}"
            explicit.add(submodule if submodule in modules else source)
    edges: set[str] = set()
    for target in explicit:
        if target not in modules:
            continue                    # outside fir_gym (numpy, gymnasium, ...)
        edges.add(target)
        edges.update(a for a in _ancestors(target) if a not in own_ancestors)
    edges.discard(module)
    return edges


def import_graph() -> dict[str, set[str]]:
    modules = installed_modules()
    return {name: import_edges(name, path, modules) for name, path in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as ``[a, b, ..., a]``, or None (an iterative depth-first
    search, nodes and edges visited in sorted order so the report is reproducible)."""
    white, grey, black = 0, 1, 2
    colour = dict.fromkeys(graph, white)
    for root in sorted(graph):
        if colour[root] != white:
            continue
        stack = [(root, iter(sorted(graph[root])))]
        colour[root] = grey
        while stack:
            node, children = stack[-1]
            for child in children:
                if colour.get(child, black) == grey:
                    path = [n for n, _ in stack]
                    return path[path.index(child):] + [child]
                if colour.get(child) == white:
                    colour[child] = grey
                    stack.append((child, iter(sorted(graph[child]))))
                    break
            else:
                colour[node] = black
                stack.pop()
    return None


def test_the_graph_sees_the_package():
    graph = import_graph()
    assert {"fir_gym", "fir_gym.envs", "fir_gym.estimators", "fir_gym.cli"} <= set(graph)
    # a function-level import is an edge (the commands import what they run)
    assert "fir_gym.scenarios.runner" in graph["fir_gym._commands"]


def test_find_cycle_reports_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_no_import_circles():
    graph = import_graph()
    cycles = []
    # report every circle, one at a time: cut the edge that closes each one found
    while (cycle := find_cycle(graph)) is not None:
        cycles.append(" -> ".join(cycle))
        graph[cycle[-2]].discard(cycle[-1])
    assert not cycles, "import circles:\n" + "\n".join(cycles)
