"""The layout shows the architecture: dependencies point one way, no import cycle, no private name crosses a module.

The imports are read from the sources (every ``import`` statement, those inside functions
included, since a lazy import is still a dependency), so the checks hold whatever a test
happened to import before.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("identification", "vehicle", "scenarios")


def _modules() -> dict[str, tuple[Path, bool]]:
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            name = ".".join(["vehid", *(parts[:-1] if is_package else parts)])
            found[name] = (path, is_package)
    return found


MODULES = _modules()


def _imports(name: str) -> list[tuple[str, tuple[str, ...]]]:
    """(module imported from, names imported) of every import statement of module ``name``."""
    path, is_package = MODULES[name]
    package = name if is_package else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.append((target, tuple(alias.name for alias in node.names)))
        elif isinstance(node, ast.Import):
            found.extend((alias.name, ()) for alias in node.names)
    return found


def _dependencies(name: str) -> set[str]:
    deps = set()
    for target, names in _imports(name):
        for imported in names:
            if f"{target}.{imported}" in MODULES:  # ``from package import module``
                deps.add(f"{target}.{imported}")
        if target in MODULES and not (names and all(f"{target}.{n}" in MODULES for n in names)):
            deps.add(target)
    deps.discard(name)
    # a package's __init__ re-exports lazily; an edge into it says nothing of the modules it names
    return {dep for dep in deps if not MODULES[dep][1]}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for other in graph[node]:
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

    for node in graph:
        if node not in index:
            visit(node)
    return components


def test_the_import_graph_has_no_cycle():
    graph = {name: _dependencies(name) for name in MODULES}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    # the check above is only as good as this search: a two- and a three-module cycle are found
    graph = {"a": {"b"}, "b": {"a"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert sorted(_cycles(graph)) == [["a", "b"], ["c", "d", "e"]]


@pytest.mark.parametrize("package, forbidden", [
    ("vehid.identification", ("vehid.vehicle", "vehid.scenarios")),
    ("vehid.vehicle", ("vehid.scenarios",)),
])
def test_dependencies_point_one_way(package, forbidden):
    wrong = [(name, target) for name in MODULES if name.startswith(package)
             for target, _ in _imports(name) if target.startswith(forbidden)]
    assert wrong == []


def test_no_private_name_is_imported_from_another_module():
    crossing = [(name, target, imported) for name in MODULES for target, names in _imports(name)
                if target.startswith("vehid.") for imported in names
                if imported.startswith("_") and not imported.startswith("__")]
    assert crossing == []


def test_former_module_names_are_the_same_modules():
    # code written before the sub-packages imports the flat names; each must be the module itself, or a
    # class would exist twice and isinstance checks and archives would disagree
    import importlib

    import vehid.identification as package
    from vehid.identification.models.modal import ModalModel

    for former, current in package._FORMER_MODULES.items():
        assert importlib.import_module(f"vehid.identification.{former}") is \
            importlib.import_module(f"vehid.identification.{current}"), former
    assert importlib.import_module("vehid.identification.modal").ModalModel is ModalModel
    assert importlib.import_module("vehid.identification.modal").__spec__.name == "vehid.identification.models.modal"


@pytest.mark.parametrize("package_name", ["vehid.identification", "vehid.vehicle"])
def test_exported_names_stay_the_exported_values_once_every_submodule_is_imported(package_name):
    # importing a submodule sets it as an attribute of its package: an exported function of the same
    # name (identification's ``least_squares`` and its former module name, vehicle's ``linearize``)
    # would be replaced by the module, and ``from package import name`` would give a module
    import importlib
    import pkgutil

    package = importlib.import_module(package_name)
    for info in pkgutil.iter_modules(package.__path__):
        importlib.import_module(f"{package_name}.{info.name}")
    for former in getattr(package, "_FORMER_MODULES", {}):
        importlib.import_module(f"{package_name}.{former}")
    for name, module in package._MODULE_OF.items():
        assert getattr(package, name) is getattr(importlib.import_module(f"{package_name}.{module}"), name), name
