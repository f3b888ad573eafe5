"""The order in which a parallel run hands out its test files.

The suite runs in worker processes (pytest-xdist, ``--dist loadfile``: each file in one worker,
so that a file's module-scoped fixtures, a simulated study, an identified model, a built wheel,
are computed once). A worker that draws a file of several minutes near the end keeps the whole
run waiting while the others sit idle; the files that hold a test marked ``slow`` therefore go
out first, those with most of them before the others, and the many short files fill the gaps. A serial run keeps the usual order.

Each test process computes as the workbench's commands do: on one BLAS thread, unless the
environment chose a thread count (:mod:`vehid.identification.blas`). The tests' own NumPy work
(reference solutions, simulations, classical estimators called directly) otherwise left OpenBLAS's
second thread spinning, and the two workers of a 2-core run lost that time to each other.
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import warnings
from dataclasses import dataclass

import pytest


def _in_parallel(config: pytest.Config) -> bool:
    """Whether this process is one of several workers (the controller of a parallel run collects nothing)."""
    return hasattr(config, "workerinput") and config.workerinput.get("workercount", 1) > 1


# the BLAS thread limit of this test process, lifted when the run ends
_BLAS_LIMIT = pytest.StashKey()


def pytest_configure(config: pytest.Config) -> None:
    from vehid.identification.blas import blas_threads_chosen

    if blas_threads_chosen():  # a run that sets a count (a measurement across thread counts) keeps it
        return
    # Only the libraries loaded in this process are limited, at run time: no environment variable is
    # set, so processes the tests start (a command's subprocess, a study's workers) see the environment
    # unchanged and limit themselves as the workbench does.
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401  (SciPy's own OpenBLAS, loaded now so that it is limited too)
    from threadpoolctl import threadpool_limits

    config.stash[_BLAS_LIMIT] = threadpool_limits(limits=1, user_api="blas")


def pytest_unconfigure(config: pytest.Config) -> None:
    limit = config.stash.get(_BLAS_LIMIT, None)
    if limit is not None:
        limit.restore_original_limits()


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not _in_parallel(config):
        return
    file_of = {id(item): item.nodeid.split("::", 1)[0] for item in items}
    slow_tests: dict[str, int] = {}
    for item in items:
        if item.get_closest_marker("slow") is not None:
            slow_tests[file_of[id(item)]] = slow_tests.get(file_of[id(item)], 0) + 1
    first_position: dict[str, int] = {}
    for index, item in enumerate(items):
        first_position.setdefault(file_of[id(item)], index)
    position = {id(item): index for index, item in enumerate(items)}
    # Most slow tests first (the longest file is the likeliest to finish last); the sort is stable and
    # keyed on the collection alone, so every worker turns its identical collection into the same order
    # (xdist checks) and each file's tests stay together and in their own order.
    items.sort(key=lambda item: (-slow_tests.get(file_of[id(item)], 0), first_position[file_of[id(item)]],
                                 position[id(item)]))


@dataclass(frozen=True)
class CommandRun:
    """What one ``vehid`` command gave: its exit status and the text it wrote to stdout and stderr."""

    returncode: int
    stdout: str
    stderr: str


def run_vehid(*argv: str, cwd: str | os.PathLike | None = None) -> CommandRun:
    """Run ``vehid argv...`` in this process, as the console script would, and return what it gave.

    A separate process pays the interpreter's start, the workbench's imports and the building of every
    symbolic function again (about 2 s of a short identification run); in this process a second command
    finds them built. What the command does is the same: ``main`` is the console script's entry point,
    Python warnings are shown on stderr as the command shows them (not turned into errors by the suite's
    filter, which a separate process would not see either), and the logging set-up, the warnings' display
    and the working folder the command changes are put back afterwards. A test of what only a process can
    show (a signal, the environment, C-level output) still starts one.
    """
    from vehid.scenarios.cli import main

    root = logging.getLogger()
    saved_handlers, saved_level, saved_show = root.handlers[:], root.level, warnings.showwarning
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.ExitStack() as stack:
            if cwd is not None:
                stack.enter_context(contextlib.chdir(cwd))
            stack.enter_context(warnings.catch_warnings())
            warnings.simplefilter("default")
            stack.enter_context(contextlib.redirect_stdout(out))
            stack.enter_context(contextlib.redirect_stderr(err))
            try:
                status = main([str(argument) for argument in argv])
            except SystemExit as exc:  # argparse's usage errors end the process with their status
                status = exc.code if isinstance(exc.code, int) else 1
    finally:
        root.handlers[:], warnings.showwarning = saved_handlers, saved_show
        root.setLevel(saved_level)
    return CommandRun(status, out.getvalue(), err.getvalue())


def printed_json(value):
    """A value as a command's ``--json`` prints it (the JSON round trip of :func:`~vehid.identification.jsonable.to_jsonable`)."""
    import json

    from vehid.identification.jsonable import to_jsonable

    return json.loads(json.dumps(to_jsonable(value), allow_nan=False))


def without_run_times(value):
    """A JSON value without its run times (keys ``seconds`` and ``*_seconds``): two runs of one computation differ in
    them alone."""
    if isinstance(value, dict):
        return {key: without_run_times(item) for key, item in value.items() if not key.endswith("seconds")}
    if isinstance(value, list):
        return [without_run_times(item) for item in value]
    return value


def library_spy(monkeypatch: pytest.MonkeyPatch, module: object, name: str) -> tuple[object, list]:
    """Replace ``module.name`` (a library function a command calls) by a spy that keeps each result it returns, or
    the result a failure carries (a late failure's finished part, a result with warnings under ``strict``);
    the original function and the list of results."""
    library, results = getattr(module, name), []

    def spy(*args, **kwargs):
        try:
            results.append(library(*args, **kwargs))
        except Exception as exc:
            if getattr(exc, "result", None) is not None:
                results.append(exc.result)
            raise
        return results[-1]

    monkeypatch.setattr(module, name, spy)
    return library, results


def mutable_parts(value, path="result", seen=None):
    """Where a value reachable from ``value`` through dataclass fields, mappings and sequences can be changed:
    a dict, a list, a set, a writeable array, or a dataclass that is not frozen."""
    import dataclasses
    from collections.abc import Mapping

    import numpy as np

    seen = set() if seen is None else seen
    if id(value) in seen:
        return []
    seen.add(id(value))
    if isinstance(value, (dict, list, set)):
        return [path]
    if isinstance(value, np.ndarray):
        return [path] if value.flags.writeable else []
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        if not value.__dataclass_params__.frozen:
            return [path]
        return [found for field in dataclasses.fields(value)
                for found in mutable_parts(getattr(value, field.name), f"{path}.{field.name}", seen)]
    if isinstance(value, Mapping):
        return [found for key, item in value.items() for found in mutable_parts(item, f"{path}[{key!r}]", seen)]
    if isinstance(value, tuple):
        return [found for i, item in enumerate(value) for found in mutable_parts(item, f"{path}[{i}]", seen)]
    return []


@pytest.fixture(scope="session")
def vehid_command():
    """:func:`run_vehid`, for tests and module fixtures that run commands."""
    return run_vehid


#: The committed race car's lap (tests/data/race_car_250lm/SOURCE.md), its first 40 s: a scheduled run on a real
#: log that costs a few seconds (order 2, p given, ten passes, three knots, one scheduled p)
RACE_CAR_LOG = os.path.join(os.path.dirname(__file__), "data", "race_car_250lm", "20140222_01_01_03_250lm.csv")
SCHEDULED_RACE_CAR_ARGS = ("--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule", "vx", "--order", "2",
                           "--p", "1e-5", "--passes", "10", "--schedule-p", "1e-2", "--schedule-knots", "3",
                           "--validation", "0.3", "--segment", "390:430")


@pytest.fixture(scope="session")
def scheduled_race_car_run(tmp_path_factory):
    """``vehid identify --schedule vx --json --out`` on the race car's log: its JSON summary and its archive's path."""
    import json

    archive = tmp_path_factory.mktemp("scheduled_race_car") / "run.h5"
    completed = run_vehid("identify", RACE_CAR_LOG, *SCHEDULED_RACE_CAR_ARGS, "--json", "--quiet", "--out", archive)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout), archive


def returned_run(archive_path: str | os.PathLike) -> str:
    """The run of an identification archive that holds the model its command returned (the filter's own run,
    its refined model's, its start's, the scheduled family's or the spline model's), as the archive names it."""
    from vehid.identification.dataio.archive import read_archive
    from vehid.scenarios.report import archive_verdict

    verdict = archive_verdict(read_archive(archive_path)) or {}
    return (verdict.get("scoring_rule") or {})["returned_run"]


def load_benchmark_module(name: str):
    """A script or helper module of ``benchmarks/`` (not a package), loaded once per process under its own name.

    The benchmarks import their helpers by bare name (``_real_records``, ``_baselines``), as a script beside
    them does, and dataclasses look their module up by name: each is registered in ``sys.modules`` and a
    module already loaded there is returned as it is.
    """
    import importlib.util
    import sys
    from pathlib import Path

    if name in sys.modules:
        return sys.modules[name]
    path = Path(__file__).resolve().parent.parent / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
