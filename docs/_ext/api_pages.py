"""Sphinx extension: the API reference and command-line pages, written from the code at build time.

The reference lists each package's ``__all__`` grouped by the module that
defines each name, so a name added to a package appears in the reference
without anyone editing a page. The pages are written as soon as the configuration is
read, before Sphinx lists its sources and autosummary scans them, and
autosummary then writes one page per name from its numpydoc docstring.

The command-line page holds the ``--help`` of ``vehid`` and of every command,
taken from the parser the program itself builds.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import os
from pathlib import Path
from typing import Any

PACKAGES = {
    "vehid.identification": "Identification: models, estimators, metrics, data and archives",
    "vehid.vehicle": "The vehicle: parameters, symbolic model, simulation, manoeuvres",
    "vehid.scenarios": "Scenarios: the commands' library functions (a car's single-track model, handling)",
}
_HELP_WIDTH = "78"  # what the page's code blocks show without scrolling


def _defining_module(package: Any, name: str) -> str:
    """The submodule that defines ``name``, as a short name (``iekf``), or ``""`` if not found."""
    explicit = getattr(package, "_MODULE_OF", None)
    if isinstance(explicit, dict) and name in explicit:
        return str(explicit[name])
    value = getattr(package, name)
    module = getattr(value, "__module__", None)
    if inspect.isclass(value) or inspect.isfunction(value) or inspect.isbuiltin(value):
        if module and module.startswith(package.__name__ + "."):
            return module[len(package.__name__) + 1:]
    # Constants carry no module: the first imported submodule holding the same object.
    for attribute in sorted(vars(package)):
        sub = getattr(package, attribute)
        if inspect.ismodule(sub) and sub.__name__.startswith(package.__name__ + ".") and getattr(sub, name, None) is value:
            return sub.__name__[len(package.__name__) + 1:]
    return ""


def _module_summary(package_name: str, module: str) -> str:
    if not module:
        return ""
    doc = inspect.getdoc(importlib.import_module(f"{package_name}.{module}")) or ""
    return doc.strip().splitlines()[0] if doc.strip() else ""


def package_page(package_name: str, title: str) -> str:
    """reStructuredText of one package's reference: its docstring, then its names by module."""
    package = importlib.import_module(package_name)
    groups: dict[str, list[str]] = {}
    for name in package.__all__:
        groups.setdefault(_defining_module(package, name), []).append(name)
    lines = [title, "=" * len(title), "", f".. currentmodule:: {package_name}", ""]
    lines += [f".. automodule:: {package_name}", "   :no-members:", ""]
    for module in sorted(groups, key=lambda m: (m == "", m)):
        heading = f"``{module}``" if module else "Other names"
        lines += [heading, "-" * len(heading), ""]
        summary = _module_summary(package_name, module)
        if summary:
            lines += [summary, ""]
        lines += [".. autosummary::", "   :toctree: generated", "   :nosignatures:", ""]
        lines += [f"   {name}" for name in groups[module]]
        lines.append("")
    return "\n".join(lines)


def _subcommands(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> list[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    found = [(words, parser)]
    for action in parser._actions:  # argparse offers no public way to walk its subparsers
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                found += _subcommands(sub, (*words, name))
    return found


def command_line_page() -> str:
    """reStructuredText of the ``--help`` of every command of the program."""
    from vehid.scenarios.cli import build_parser

    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = _HELP_WIDTH  # argparse wraps to the terminal; pages need one width
    try:
        parser = build_parser()
        commands = _subcommands(parser, ("vehid",))
        texts = [(words, sub.format_help()) for words, sub in commands]
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved
    title = "Command-line reference"
    lines = [title, "=" * len(title), "",
             "The ``--help`` of ``vehid`` and of each of its commands, as the program prints it. "
             ":doc:`../guide/command_line` explains the common options, the exit status and the outputs.", ""]
    for words, text in texts:
        heading = " ".join(words)
        lines += [heading, "-" * len(heading), "", ".. code-block:: text", ""]
        lines += [("   " + line).rstrip() for line in text.rstrip().splitlines()]
        lines.append("")
    return "\n".join(lines)


def _write_if_changed(path: Path, text: str) -> None:
    # An unchanged page keeps its time stamp, so Sphinx does not read it again.
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def write_pages(app: Any, config: Any = None) -> None:
    folder = Path(app.srcdir) / "api"
    folder.mkdir(exist_ok=True)
    for package_name, title in PACKAGES.items():
        _write_if_changed(folder / f"{package_name.split('.')[-1]}.rst", package_page(package_name, title))
    _write_if_changed(folder / "command_line.rst", command_line_page())


def setup(app: Any) -> dict[str, Any]:
    # Sphinx lists the source files, and autosummary scans them for its directives,
    # once the builder starts: the pages must exist by then.
    app.connect("config-inited", write_pages)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
