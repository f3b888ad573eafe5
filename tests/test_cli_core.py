"""The command line's shared behaviour: help, JSON conversion."""

import json
import subprocess
import sys

import numpy as np

from scenarios.cli import build_parser, to_jsonable


def test_json_conversion_of_numpy_and_complex():
    converted = to_jsonable({"a": np.arange(2), "e": [complex(-1, 2)], "n": float("nan")})
    assert json.dumps(converted, allow_nan=False) == '{"a": [0, 1], "e": [[-1.0, 2.0]], "n": null}'


def test_top_level_help_lists_groups():
    completed = subprocess.run(
        [sys.executable, "-m", "scenarios.cli", "--help"], capture_output=True, text=True, check=False
    )
    assert completed.returncode == 0
    assert "study" in completed.stdout and "bench" in completed.stdout


def test_parser_builds():
    assert build_parser().prog == "vehid"
