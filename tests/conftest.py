"""The order in which a parallel run hands out its test files.

The suite runs in worker processes (pytest-xdist, ``--dist loadfile``: each file in one worker,
so that a file's module-scoped fixtures, a simulated study, an identified model, a built wheel,
are computed once). A worker that draws a file of several minutes near the end keeps the whole
run waiting while the others sit idle; the files that hold a test marked ``slow`` therefore go
out first, those with most of them before the others, and the many short files fill the gaps. A serial run keeps the usual order.
"""

from __future__ import annotations

import pytest


def _in_parallel(config: pytest.Config) -> bool:
    """Whether this process is one of several workers (the controller of a parallel run collects nothing)."""
    return hasattr(config, "workerinput") and config.workerinput.get("workercount", 1) > 1


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
