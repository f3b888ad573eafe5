"""Options declared once: the table checks IdentifyOptions when it is built and defines `vehid identify`'s flags.

Every test here is cheap (no identification runs): a bad value must be refused by construction, naming the
option, before any work; the command line must show the same table's defaults, choices and help; and no
library error may name a command-line flag (the command line translates option names into flags).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import json
import re
from pathlib import Path

import pytest

from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.choices import (C_PATTERNS, COVARIANCE_FORMS, DETRENDS, DISCRETIZATIONS, INITIAL_STATES,
                                          SCHEDULE_MAX_KNOTS, SCHEDULE_MIN_KNOTS, START_CHOICES, TIMESCALES)
from vehid.identification.errors import DivergenceError, InputError, OptionError
from vehid.identification.optionspec import Boolean, Number, Numbers, OneOf, option_specs, renamed_options
from vehid.scenarios.commands.flags import command_line_message

ROOT = Path(__file__).resolve().parents[1]
SPECS = option_specs(IdentifyOptions)
NAMES_A_FLAG = re.compile(r"(?<![\w-])--[a-z]")


def _bad_values(allowed) -> list:
    """Values the constraint must refuse, read off its own declaration (so every bound is exercised)."""
    if isinstance(allowed, OneOf):
        return ["bogus", 3]
    if isinstance(allowed, Boolean):
        return ["yes", 1]
    if isinstance(allowed, Number):
        bad = [float("nan"), "5", True]
        if allowed.low is not None:
            bad.append(allowed.low if allowed.low_open else allowed.low - 1)
        if allowed.high is not None:
            bad.append(allowed.high if allowed.high_open else allowed.high + 1)
        if allowed.whole:
            bad.append((allowed.low or 0) + 1.5)
        return bad
    if isinstance(allowed, Numbers):
        low = allowed.each.low if allowed.each.low is not None else 0.0
        bad = [(), "1,2", (float("inf"),) * allowed.fewest, (low - 1.0,) * allowed.fewest]
        if allowed.most is not None:
            bad.append(tuple(low + 1.0 + k for k in range(allowed.most + 1)))
        if allowed.increasing:
            bad.append(tuple(low + 1.0 + k for k in range(allowed.fewest))[::-1])
        return bad
    raise AssertionError(f"no bad values for {allowed!r}")


CASES = [(name, bad) for name, spec in SPECS.items() for bad in _bad_values(spec.allowed)]


@pytest.mark.parametrize("name, bad", CASES, ids=[f"{name}={bad!r}" for name, bad in CASES])
def test_a_bad_value_is_refused_when_the_options_are_built_naming_the_option(name, bad):
    with pytest.raises(OptionError) as caught:
        IdentifyOptions(**{name: bad})
    error = caught.value
    assert isinstance(error, ValueError) and isinstance(error, InputError) and error.exit_status == 2
    assert error.options == (name,) and str(error).startswith(f"'{name}' must be "), str(error)


@pytest.mark.parametrize("name, bad", [
    ("start", "bogus"), ("initial_state", "bogus"), ("discretization", "bogus"), ("covariance", "bogus"),
    ("timescale", "bogus"), ("detrend", "bogus"), ("method", "bogus"), ("pattern", "bogus"),
    ("schedule_knots", 50), ("schedule_grid", (3, 1)),
])
def test_the_values_that_once_constructed_are_refused(name, bad):
    """Each of these built an options object without error (a bad initial_state failed only after the filter ran)."""
    with pytest.raises(OptionError, match=f"^'{name}' must be"):
        IdentifyOptions(**{name: bad})


def test_every_option_is_declared_with_the_choices_of_its_kind():
    assert set(SPECS) == {field.name for field in dataclasses.fields(IdentifyOptions)}
    assert {name: SPECS[name].choices for name in ("start", "discretization", "covariance", "timescale",
                                                    "initial_state", "detrend", "pattern")} == {
        "start": START_CHOICES, "discretization": DISCRETIZATIONS, "covariance": COVARIANCE_FORMS,
        "timescale": TIMESCALES, "initial_state": INITIAL_STATES, "detrend": DETRENDS, "pattern": C_PATTERNS}
    from vehid.identification.comparators import COMPARATORS

    assert SPECS["method"].choices == tuple(COMPARATORS)  # the registry itself, read when checked
    for name, spec in SPECS.items():  # the defaults pass their own checks
        assert spec.check(spec.default) == spec.default, name
    # the Parameters section is written from the table: one entry per option
    assert all(f"\n{name} : " in IdentifyOptions.__doc__ for name in SPECS)


def test_the_built_in_methods_are_the_registry_s_and_a_refused_method_loads_no_estimator():
    """Until a method is registered the registry holds the built-in ones, named without importing it (it loads
    scipy.optimize); a command refused for its options pays only the parser's imports."""
    import subprocess
    import sys

    from vehid.identification.choices import ESTIMATORS
    from vehid.identification.comparators import COMPARATORS

    assert ESTIMATORS == tuple(COMPARATORS)
    probe = ("import sys\nfrom vehid.identification import IdentifyOptions, OptionError\n"
             "try:\n    IdentifyOptions(method='bogus')\nexcept OptionError:\n    pass\n"
             "print('vehid.identification.comparators' in sys.modules, 'scipy.optimize' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["False", "False"]


def test_bounds_are_closed_and_values_are_stored_as_checked():
    edges = IdentifyOptions(schedule_knots=SCHEDULE_MIN_KNOTS, nodes=9, passes=1, bootstrap=0, method="n4sid",
                            schedule_grid=[10, 20.5], schedule_p=[1e-2], nonlinear_p=(1e-7,), horizon=1)
    assert edges.schedule_grid == (10.0, 20.5) and edges.schedule_p == (0.01,)  # a list stored as a tuple: hashable
    assert IdentifyOptions(schedule_knots=SCHEDULE_MAX_KNOTS, passes=3.0).passes == 3  # an integral float is whole
    hash(edges)


def test_a_registered_estimator_is_accepted_once_it_is_registered(monkeypatch):
    from vehid.identification import comparators

    with pytest.raises(OptionError, match="'method'"):
        IdentifyOptions(method="mine")
    monkeypatch.setitem(comparators.COMPARATORS, "mine", comparators.COMPARATORS["arx"])
    assert IdentifyOptions(method="mine").method == "mine"


def test_bootstrap_applies_to_n4sid_alone_naming_both_options():
    assert IdentifyOptions(method="n4sid", bootstrap=20).bootstrap == 20
    with pytest.raises(OptionError) as caught:
        IdentifyOptions(method="arx", bootstrap=20)
    assert caught.value.options == ("bootstrap", "method")
    assert command_line_message(caught.value).startswith("--bootstrap applies to --method n4sid")


def test_the_knots_bounds_are_one_constraint_wherever_knots_are_given():
    """IdentifyOptions, the scheduled filter's options and its default grid refuse the same counts alike."""
    import numpy as np

    from vehid.identification.filtering.scheduled_iekf import ScheduledIEKFOptions, check_grid, default_grid

    speeds = np.linspace(10.0, 30.0, 200)
    for count in (SCHEDULE_MIN_KNOTS - 1, SCHEDULE_MAX_KNOTS + 1):
        wanted = f"must be a whole number from {SCHEDULE_MIN_KNOTS} to {SCHEDULE_MAX_KNOTS}; got {count}"
        for build in (lambda: IdentifyOptions(schedule_knots=count), lambda: ScheduledIEKFOptions(knots=count),
                      lambda: default_grid(speeds, count)):
            with pytest.raises(OptionError, match=wanted):
                build()
    for grid in ((20.0,), (30.0, 10.0), tuple(range(10, 10 + SCHEDULE_MAX_KNOTS + 1))):
        for build in (lambda: IdentifyOptions(schedule_grid=grid), lambda: ScheduledIEKFOptions(grid=grid),
                      lambda: check_grid(grid)):
            with pytest.raises(OptionError, match="strictly increasing"):
                build()


def test_detrend_is_checked_once_before_anything_is_computed():
    import numpy as np

    from vehid.identification.data import IOData, check_channels
    from vehid.identification.dataio.preparation import estimate_preparation, prepare

    t = np.arange(50) * 0.1
    record = IOData(t=t, u=np.sin(t)[:, None], y=np.cos(t)[:, None])
    for call in (prepare, estimate_preparation, check_channels):
        with pytest.raises(OptionError, match="^'detrend' must be one of mean, linear, none; got 'lines'$"):
            call(record, detrend="lines")


# ------------------------------------------------------------------------------------------------ the command line
def _identify_parser() -> argparse.ArgumentParser:
    from vehid.scenarios.commands import identify

    parser = argparse.ArgumentParser()
    identify.register(parser)
    return parser


def test_the_command_lines_defaults_choices_and_help_are_the_tables():
    parser = _identify_parser()
    actions = {action.dest: action for action in parser._actions}
    # --passes stays unset until given: --resume then runs to the archived run's own budget
    unset_until_given = {"passes"}
    for name, spec in SPECS.items():
        action = actions[name]
        assert action.option_strings[0] == "--" + name.replace("_", "-"), name
        assert action.default == (None if name in unset_until_given else spec.default), name
        if spec.choices is not None:
            assert tuple(action.choices) == spec.choices, name
        if isinstance(spec.allowed, Number):
            assert action.type is (int if spec.allowed.whole else float), name
        if isinstance(spec.allowed, Boolean):
            assert action.nargs == 0, name  # a switch
        declared = re.sub(r"``([a-z_]+)``", lambda m: "--" + m.group(1).replace("_", "-"), spec.help)
        assert action.help.replace("%%", "%").startswith(declared), name
    # parsed without a flag, the arguments give the library's defaults
    from vehid.scenarios.commands.identify import options_from_args

    assert options_from_args(parser.parse_args(["record.csv"])) == IdentifyOptions()


def _options_named_by_library_errors() -> set[str]:
    """The option names that library errors list (``OptionError(..., "name")``, ``options=("name",)``)."""
    names = set()
    for path in [*(ROOT / "identification").rglob("*.py"), *(ROOT / "vehicle").rglob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.Call):
                continue
            called = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
            listed = node.args[1:] if called == "OptionError" else []
            listed += [element for keyword in node.keywords if keyword.arg == "options"
                       for element in getattr(keyword.value, "elts", [])]
            names |= {item.value for item in listed if isinstance(item, ast.Constant) and isinstance(item.value, str)}
    return names


def test_every_option_a_library_error_names_is_a_flag_of_the_command_line():
    from vehid.scenarios.commands.flags import flag_of

    flags = {option for action in _identify_parser()._actions for option in action.option_strings}
    named = _options_named_by_library_errors()
    assert {"order", "dt", "time_column", "scale", "force", "allow_unstable"} <= named  # the scan finds them
    assert {name: flag_of(name) for name in named if flag_of(name) not in flags} == {}


@pytest.mark.parametrize("flags, shown", [
    (("--schedule", "u", "--schedule-knots", "50"), "--schedule-knots must be a whole number from 2 to 9; got 50"),
    (("--schedule", "u", "--schedule-grid", "3,1"), "--schedule-grid must be 2 to 9 finite numbers"),
    (("--nodes", "2"), "--nodes must be a whole number from 3 to 9; got 2"),
    (("--p", "0"), "--p must be a positive number; got 0.0"),
    (("--bootstrap", "5"), "--bootstrap applies to --method n4sid"),
])
def test_the_command_names_a_bad_option_by_its_flag_before_reading_any_data(flags, shown, monkeypatch, tmp_path):
    from conftest import run_vehid

    from vehid.identification.automatic import intake

    def read_nothing(*args, **kwargs):
        raise AssertionError("the data were read before the options were checked")

    monkeypatch.setattr(intake, "plan_run", read_nothing)
    record = tmp_path / "record.csv"
    record.write_text("t,u,y\n0,0,0\n0.1,1,1\n")
    run = run_vehid("identify", str(record), "--inputs", "u", "--outputs", "y", *flags, "--json")
    assert run.returncode == 2, run.stderr
    body = json.loads(run.stdout)
    assert body["exit_status"] == 2 and body["error"].startswith(shown), body
    assert run.stderr.strip() == f"vehid: error: {body['error']}"


def test_option_names_become_flags_only_where_the_error_lists_them():
    error = OptionError("'schedule_knots' must be a whole number; the channel 'p' is not 'schedule'", "schedule_knots")
    assert command_line_message(error) == "--schedule-knots must be a whole number; the channel 'p' is not 'schedule'"
    try:  # an error raised from one that names options: its message names them too
        try:
            raise OptionError("'dt' must be a positive number", "dt")
        except OptionError as cause:
            raise InputError(f"reading log.csv: {cause}") from cause
    except InputError as wrapped:
        assert command_line_message(wrapped) == "reading log.csv: --dt must be a positive number"
    diverged = DivergenceError("unstable: 'allow_unstable' keeps it", options=("allow_unstable",))
    assert command_line_message(diverged) == "unstable: --allow-unstable keeps it"


def test_a_setting_given_under_another_name_is_named_as_given():
    from vehid.scenarios.handling_study import spline_options

    with pytest.raises(OptionError) as caught:
        spline_options(p=-1.0)
    assert caught.value.options == ("nonlinear_p",) and str(caught.value).startswith("'nonlinear_p' must be")
    with pytest.raises(OptionError, match="^'nodes'"), renamed_options({"p": "nonlinear_p"}):
        raise OptionError("'nodes' must be a whole number", "nodes")  # an option not renamed passes as it was


# ----------------------------------------------------------------------------- no library message names a flag
def _error_strings(tree: ast.AST) -> set[tuple[int, str]]:
    """The string constants of every error raised or built (``raise X(...)``, ``SomeError(...)``), with those of
    the local names such a call uses: assigned (``option = "--dt"`` then ``f"{option} ..."``), looped over or a
    parameter's default."""
    def strings(node):
        return [c for c in ast.walk(node) if isinstance(c, ast.Constant) and isinstance(c.value, str)]

    found = set()
    for function in [node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]:
        assigned: dict[str, list[ast.Constant]] = {}
        positional = [*function.args.posonlyargs, *function.args.args]
        defaults = zip(positional[len(positional) - len(function.args.defaults):], function.args.defaults)
        for argument, default in [*defaults, *zip(function.args.kwonlyargs, function.args.kw_defaults)]:
            if default is not None:
                assigned.setdefault(argument.arg, []).extend(strings(default))
        for node in ast.walk(function):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.For) else []
            source = node.value if isinstance(node, ast.Assign) else getattr(node, "iter", None)
            for target in targets:
                for name in [n for n in ast.walk(target) if isinstance(n, ast.Name)]:
                    assigned.setdefault(name.id, []).extend(strings(source))
        for node in ast.walk(function):
            call = node.exc if isinstance(node, ast.Raise) else node
            if not isinstance(call, ast.Call):
                continue
            called = call.func.id if isinstance(call.func, ast.Name) else getattr(call.func, "attr", "")
            if not (isinstance(node, ast.Raise) or called.endswith("Error")):
                continue
            for part in ast.walk(call):
                if isinstance(part, ast.Constant) and isinstance(part.value, str):
                    found.add((part.lineno, part.value))
                elif isinstance(part, ast.Name):
                    found |= {(c.lineno, c.value) for c in assigned.get(part.id, [])}
    return found


def test_no_library_error_names_a_command_line_flag():
    """The library names options by their keywords; `vehid` shows flags (scenarios.commands.flags)."""
    offenders = []
    for path in sorted([*(ROOT / "identification").rglob("*.py"), *(ROOT / "vehicle").rglob("*.py")]):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        offenders += [f"{path.relative_to(ROOT)}:{line}: {text!r}" for line, text in sorted(_error_strings(tree))
                      if NAMES_A_FLAG.search(text)]
    assert offenders == []


def test_the_flag_scan_finds_a_flag_in_an_error_and_in_a_name_it_uses():
    source = ("def read(dt):\n"
              "    option = '--dt' if dt else '--time-scale'\n"
              "    raise InputError(f'{option} applies to files')\n"
              "def check():\n"
              "    return OutputTargetError('give --force to replace it')\n"
              "def convert(scale, ratio):\n"
              "    for flag, values in (('--scale', scale), ('--steering-ratio', ratio)):\n"
              "        raise InputError(f'{flag} names a channel')\n"
              "def window(text, what='--exclude'):\n"
              "    raise InputError(f'{what} is T0:T1')\n"
              "def fine():\n"
              "    raise InputError(\"'dt' must be positive\")\n")
    flagged = [text for _, text in _error_strings(ast.parse(source)) if NAMES_A_FLAG.search(text)]
    assert sorted(flagged) == ["--dt", "--exclude", "--scale", "--steering-ratio", "--time-scale",
                               "give --force to replace it"]
