"""The command line's shared behaviour: help, JSON conversion."""

import json
import subprocess
import sys

import numpy as np

from vehid.scenarios.cli import build_parser, to_jsonable


def test_json_conversion_of_numpy_and_complex():
    converted = to_jsonable({"a": np.arange(2), "e": [complex(-1, 2)], "n": float("nan")})
    assert json.dumps(converted, allow_nan=False) == '{"a": [0, 1], "e": [[-1.0, 2.0]], "n": null}'


def test_top_level_help_lists_groups():
    completed = subprocess.run(
        [sys.executable, "-m", "vehid.scenarios.cli", "--help"], capture_output=True, text=True, check=False
    )
    assert completed.returncode == 0
    assert "study" in completed.stdout and "bench" in completed.stdout


def test_parser_builds():
    assert build_parser().prog == "vehid"


def _subcommands():
    from vehid.scenarios.commands.parser import GROUPS, command_modules

    commands = []
    for module in command_modules():
        commands.append([module.NAME] if module.GROUP is None else [module.GROUP, module.NAME])
    assert {"study", "bench"} == set(GROUPS)
    return commands


def test_every_subcommand_has_help_json_and_quiet():
    commands = _subcommands()
    assert ["identify"] in commands and ["study", "handling"] in commands and ["report"] in commands
    for command in commands:
        completed = subprocess.run(
            [sys.executable, "-m", "vehid.scenarios.cli", *command, "--help"], capture_output=True, text=True, check=False
        )
        assert completed.returncode == 0, (command, completed.stderr)
        assert "--json" in completed.stdout and "--quiet" in completed.stdout, command
