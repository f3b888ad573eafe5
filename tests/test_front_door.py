"""One front door: the command line is a client of the library.

The commands (``scenarios/commands``) map their arguments to the library's options and call the
library's functions (:func:`vehid.identification.identify`, :func:`~vehid.scenarios.identify_single_track`,
:func:`~vehid.scenarios.handling`, :func:`~vehid.scenarios.calibrate`); nothing below them reads a parsed
command line. The tests that each command prints the rendering of the library's result live beside their
fixtures (``test_library_identify``, ``test_single_track_cli``, ``test_vehicle_handling``,
``test_drive_calibration``).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ROOT / "scenarios"
#: Names a parsed command line travels under.
PARSED = {"args", "arguments", "namespace"}


def _parsed_reads(source: str) -> list[str]:
    """Where ``source`` reads a parsed command line: an attribute of a name in :data:`PARSED` (``args.order``),
    ``getattr``/``vars``/``hasattr`` of one, or argparse imported at all."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in PARSED:
            found.append(f"line {node.lineno}: {node.value.id}.{node.attr}")
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
              and node.func.id in ("getattr", "vars", "hasattr") and node.args
              and isinstance(node.args[0], ast.Name) and node.args[0].id in PARSED):
            found.append(f"line {node.lineno}: {node.func.id}({node.args[0].id}, ...)")
        elif isinstance(node, ast.Import) and any(alias.name == "argparse" for alias in node.names):
            found.append(f"line {node.lineno}: import argparse")
        elif isinstance(node, ast.ImportFrom) and node.module == "argparse":
            found.append(f"line {node.lineno}: from argparse import ...")
    return found


def test_nothing_below_the_commands_reads_a_parsed_command_line():
    reads = {}
    for path in sorted(SCENARIOS.rglob("*.py")):
        if "commands" in path.relative_to(SCENARIOS).parts:
            continue
        found = _parsed_reads(path.read_text(encoding="utf-8"))
        if found:
            reads[str(path.relative_to(ROOT))] = found
    assert reads == {}


def test_the_scan_finds_every_way_of_reading_a_parsed_command_line():
    # the scan above is only as good as this: each form of a read is found, a keyword named args is not
    source = ("import argparse\n"
              "def run(args, process):\n"
              "    process(args=(1, 2))\n"
              "    return args.order, getattr(args, 'p', None), vars(args), hasattr(namespace, 'x'), arguments.out\n")
    assert _parsed_reads(source) == ["line 1: import argparse", "line 4: args.order", "line 4: getattr(args, ...)",
                                     "line 4: vars(args, ...)", "line 4: hasattr(namespace, ...)",
                                     "line 4: arguments.out"]
