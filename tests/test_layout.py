"""The layout shows the architecture: dependencies point one way, no import cycle, no private name crosses a module.

The imports are read from the sources (every ``import`` statement, those inside functions
included, since a lazy import is still a dependency; relative imports resolved; a name taken
from a package that re-exports it lazily counted as an import of the module defining it), so the
checks hold whatever a test happened to import before. The benchmark scripts are read too: they
run outside the suite, and an import of a moved or private name would otherwise break them unseen.
"""

from __future__ import annotations

import ast
import functools
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("identification", "vehicle", "scenarios")


@dataclass(frozen=True)
class Source:
    """One Python file read by the checks: its dotted name, path, and whether it is a package's ``__init__``."""

    name: str
    path: Path
    is_package: bool

    @property
    def package(self) -> str:
        """The package its relative imports start from."""
        return self.name if self.is_package else self.name.rpartition(".")[0]


@dataclass(frozen=True)
class Import:
    """One imported module or name, and the statement that imports it."""

    source: Source
    target: str          # the module imported from, relative imports resolved
    names: tuple[str, ...]
    line: int

    def where(self) -> str:
        code = _lines(self.source.path)[self.line - 1].strip()
        return f"{self.source.path.relative_to(ROOT)}:{self.line}: {code}"


@functools.cache
def _lines(path: Path) -> list[str]:
    return path.read_text(encoding="utf-8").splitlines()


@functools.cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"))


def _sources() -> dict[str, Source]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            name = ".".join(["vehid", *(parts[:-1] if is_package else parts)])
            found[name] = Source(name, path, is_package)
    return found


MODULES = _sources()
# the scripts beside each other in benchmarks/ import one another by their bare names (``import _baselines``)
BENCHMARKS = {path.stem: Source(path.stem, path, False) for path in sorted((ROOT / "benchmarks").glob("*.py"))}


@functools.cache
def _imports(source: Source) -> list[Import]:
    """Every import statement of ``source``, at any depth."""
    found = []
    for node in ast.walk(_tree(source.path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = source.package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append(Import(source, target, tuple(alias.name for alias in node.names), node.lineno))
        elif isinstance(node, ast.Import):
            found.extend(Import(source, alias.name, (), node.lineno) for alias in node.names)
    return found


def _lazy_exports(package: Source) -> dict[str, str]:
    """Name -> defining module of a package that re-exports its modules' names (its ``_EXPORTS`` table)."""
    for node in _tree(package.path).body:
        if isinstance(node, ast.AnnAssign | ast.Assign):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(target, ast.Name) and target.id == "_EXPORTS" for target in targets):
                exports = ast.literal_eval(node.value)
                return {name: f"{package.name}.{module}" for module, names in exports.items() for name in names}
    return {}


EXPORTED = {name: _lazy_exports(source) for name, source in MODULES.items() if source.is_package}


def _dependencies(imported: Import) -> set[str]:
    """The workbench modules an import statement needs: a re-exported name counts as its defining module."""
    target, names = imported.target, imported.names
    if not names:
        return {target} if target in MODULES else set()
    deps = set()
    for name in names:
        if f"{target}.{name}" in MODULES:  # ``from package import module``
            deps.add(f"{target}.{name}")
        elif name in EXPORTED.get(target, {}):
            deps.add(EXPORTED[target][name])
        elif target in MODULES:
            deps.add(target)
    return deps


def unit_of(module: str) -> str:
    """The part of the layout a module belongs to: a sub-package, or a module of the identification foundation.

    Identification's sub-packages (models, filtering, classical, assessment, dataio, automatic) are
    one unit each; the modules directly in ``identification/`` are each their own unit: the foundation
    below the sub-packages (data, errors, compiled code) and the faces above them (the comparators,
    the pipeline), so that none of them can both serve the sub-packages and lean on them. ``vehicle`` is one unit,
    and ``scenarios`` three: its studies, the commands above them, and the ``vehid`` entry point
    (``scenarios.cli``) above the commands.
    """
    if module == "vehid.scenarios.cli":
        return "scenarios.cli"
    parts = module.split(".")[1:]
    if len(parts) > 1 and parts[0] in ("identification", "scenarios"):
        inner = MODULES.get(f"vehid.{parts[0]}.{parts[1]}")
        if (inner is not None and inner.is_package) or parts[0] == "identification":
            return f"{parts[0]}.{parts[1]}"
    return parts[0]


def unit_edges() -> dict[tuple[str, str], list[Import]]:
    """(unit, unit it imports) -> the import statements that make the edge."""
    edges: dict[tuple[str, str], list[Import]] = {}
    for name, source in MODULES.items():
        for imported in _imports(source):
            for dep in _dependencies(imported):
                if unit_of(dep) != unit_of(name):
                    edges.setdefault((unit_of(name), unit_of(dep)), []).append(imported)
    return edges


def strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in sorted(graph.get(node, ())):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in on_stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return components


def shortest_cycle(graph: dict[str, set[str]], start: str) -> list[str]:
    """The shortest path from ``start`` back to itself, as its nodes (``start`` first), or [] if there is none."""
    came_from: dict[str, str] = {}
    queue = deque([start])
    while queue:
        node = queue.popleft()
        for other in sorted(graph.get(node, ())):
            if other == start:
                path = [node]
                while path[-1] != start:
                    path.append(came_from[path[-1]])
                return path[::-1]
            if other not in came_from:
                came_from[other] = node
                queue.append(other)
    return []


def describe_cycles(edges: dict[tuple[str, str], list[Import]]) -> list[str]:
    """One paragraph per cycle between units: a shortest cycle, then every edge among the units it joins.

    Each edge inside a strongly connected component lies on some cycle, so each is listed with the
    import lines that make it: any one of them removed may be what breaks the cycle.
    """
    graph: dict[str, set[str]] = {}
    for source, target in edges:
        graph.setdefault(source, set()).add(target)
    paragraphs = []
    for component in strongly_connected(graph):
        inside = {node: graph[node] & set(component) for node in component}
        cycle = shortest_cycle(inside, component[0])
        lines = [f"{' -> '.join(cycle + cycle[:1])} (a cycle among {', '.join(component)})"]
        for source in component:
            for target in sorted(inside[source]):
                lines.append(f"  {source} -> {target}:")
                lines.extend(f"    {imported.where()}" for imported in edges[source, target])
        paragraphs.append("\n".join(lines))
    return paragraphs


def test_the_sub_packages_depend_one_way():
    cycles = describe_cycles(unit_edges())
    assert not cycles, "import cycles between parts of the layout:\n" + "\n".join(cycles)


def test_the_import_graph_of_modules_has_no_cycle():
    graph = {name: {dep for imported in _imports(source) for dep in _dependencies(imported)} - {name}
             for name, source in MODULES.items()}
    # a package's __init__ re-exports lazily; an edge into it says nothing of the modules it names
    graph = {name: {dep for dep in deps if not MODULES[dep].is_package} for name, deps in graph.items()}
    assert strongly_connected(graph) == []


def test_the_cycle_finder_finds_a_cycle_and_names_its_imports():
    # the checks above are only as good as this search: a two- and a three-node cycle are found, a
    # node leading into a cycle is not part of it, and the report names the shortest cycle's imports
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c", "d"}, "f": {"a"}}
    assert sorted(strongly_connected(graph)) == [["a", "b"], ["c", "d", "e"]]
    assert shortest_cycle(graph, "d") == ["d", "e"]
    assert shortest_cycle(graph, "f") == []

    models, filtering = MODULES["vehid.identification.models.modal"], MODULES["vehid.identification.filtering.iekf"]
    edges = {("models", "filtering"): [Import(models, "x", (), 1)], ("filtering", "models"): [Import(filtering, "y", (), 1)]}
    (paragraph,) = describe_cycles(edges)
    assert paragraph.startswith("filtering -> models -> filtering (a cycle among filtering, models)")
    assert "identification/models/modal.py:1:" in paragraph and "identification/filtering/iekf.py:1:" in paragraph


def test_the_units_are_the_sub_packages():
    assert unit_of("vehid.identification.models.modal") == "identification.models"
    assert unit_of("vehid.identification.automatic.run") == "identification.automatic"
    assert unit_of("vehid.identification.data") == "identification.data"
    assert unit_of("vehid.identification") == "identification"
    assert unit_of("vehid.vehicle.single_track") == "vehicle"
    assert unit_of("vehid.scenarios.commands.identify") == "scenarios.commands"
    assert unit_of("vehid.scenarios.report") == "scenarios"
    assert unit_of("vehid.scenarios.cli") == "scenarios.cli"


def test_a_re_exported_name_counts_as_its_module():
    # ``from vehid.identification import IOData`` needs identification.data, not the package's __init__
    source = MODULES["vehid.scenarios.report"]
    assert _dependencies(Import(source, "vehid.identification", ("IOData",), 1)) == {"vehid.identification.data"}
    assert _dependencies(Import(source, "vehid.vehicle", ("linearize",), 1)) == {"vehid.vehicle.linearize"}


@pytest.mark.parametrize("package, forbidden", [
    ("vehid.identification", ("vehid.vehicle", "vehid.scenarios")),
    ("vehid.vehicle", ("vehid.scenarios",)),
])
def test_dependencies_point_one_way(package, forbidden):
    wrong = [imported.where() for name, source in MODULES.items() if name.startswith(package)
             for imported in _imports(source)
             for target in {imported.target, *_dependencies(imported)} if target.startswith(forbidden)]
    assert not wrong, "\n".join(wrong)


def _all_sources() -> list[Source]:
    return [*MODULES.values(), *BENCHMARKS.values()]


# The single-track command's RK4 step count, read by two benchmarks that simulate the identified model as the
# command does; it is private to the command's module until that module gives it a public name.
PRIVATE_USES_NAMED = {("vehid.scenarios.single_track_identify", "_substeps")}


def test_no_private_name_is_imported_from_another_module():
    crossing = sorted({imported.where() for source in _all_sources() for imported in _imports(source)
                       if imported.target.startswith("vehid.") or imported.target in BENCHMARKS
                       for name in imported.names if name.startswith("_") and not name.startswith("__")
                       and (imported.target, name) not in PRIVATE_USES_NAMED})
    assert not crossing, "\n".join(crossing)


def test_a_private_module_is_imported_only_inside_its_package():
    # ``_name`` says: this package's own business. A module of another package (or a benchmark
    # script) that imports it would break when the package rearranges its insides.
    def private_package(module: str) -> str | None:
        parts = module.split(".")
        for depth, part in enumerate(parts):
            if part.startswith("_") and not part.startswith("__"):
                return ".".join(parts[:depth])
        return None

    crossing = []
    for source in _all_sources():
        for imported in _imports(source):
            for dep in _dependencies(imported) | {imported.target}:
                owner = private_package(dep)
                if owner is not None and dep in MODULES and not (source.name + ".").startswith(owner + "."):
                    crossing.append(imported.where())
    assert not crossing, "\n".join(crossing)


@functools.cache
def _defined_names(source: Source) -> frozenset[str]:
    """Names a module binds at its top level: definitions, assignments and imports, those under ``if``/``try`` too."""
    names = set()
    pending = list(_tree(source.path).body)
    while pending:
        node = pending.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            names.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
            continue
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Name) and isinstance(child.ctx, ast.Store):
                names.add(child.id)
            elif isinstance(child, ast.stmt | ast.excepthandler | ast.Tuple | ast.List | ast.Starred):
                pending.append(child)
    return frozenset(names)


def test_every_workbench_import_names_a_module_and_a_name_that_exist():
    # the benchmark scripts are not run by the suite: a module renamed or moved, or a name renamed,
    # would leave them importing what is gone
    missing = []
    for source in _all_sources():
        for imported in _imports(source):
            target = imported.target
            if not target.startswith("vehid."):
                continue
            if target not in MODULES:
                missing.append(imported.where())
                continue
            defined = _defined_names(MODULES[target]) | set(EXPORTED.get(target, {}))
            missing.extend(imported.where() for name in imported.names
                           if name not in defined and f"{target}.{name}" not in MODULES)
    assert not missing, "\n".join(missing)


@pytest.mark.parametrize("package_name", ["vehid.identification", "vehid.vehicle"])
def test_exported_names_stay_the_exported_values_once_every_submodule_is_imported(package_name):
    # importing a submodule sets it as an attribute of its package: an exported function of the same
    # name (identification's ``least_squares`` beside classical's module of that name, vehicle's ``linearize``) would be replaced by the module, and ``from package import name``
    # would give a module
    import importlib
    import pkgutil

    package = importlib.import_module(package_name)
    for info in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"{package_name}.{info.name}")
    for name, module in package._MODULE_OF.items():
        assert getattr(package, name) is getattr(importlib.import_module(f"{package_name}.{module}"), name), name
