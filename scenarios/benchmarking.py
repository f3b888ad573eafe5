"""Helpers for the scripts in ``benchmarks/``: repeated timing and the shared figures file.

Figures are medians over repeats; comparisons are ratios against a baseline
measured in the same run, because the machines are noisy.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from vehid.identification.jsonable import to_jsonable

from .paths import results_directory

__all__ = ["median_seconds", "record_figures", "CommandTiming", "timed_command"]


def median_seconds(work: Callable[[], Any], *, repeats: int = 5, warmup: int = 1) -> float:
    """Median wall time of ``work()`` over ``repeats`` calls after ``warmup`` uncounted calls."""
    for _ in range(warmup):
        work()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


@dataclass(frozen=True)
class CommandTiming:
    """One run of a command: wall seconds, the process's own CPU seconds (user + system) and its output."""

    wall: float
    cpu: float
    stdout: str


def timed_command(command: Sequence[str], *, environment: Mapping[str, str] | None = None) -> CommandTiming:
    """Run ``command`` once and time it; a non-zero exit raises ``RuntimeError`` with the end of its errors.

    The CPU seconds are the child's own, from ``wait4``, so the caller's work and other processes do not
    count. Its output goes to temporary files rather than pipes: nothing is read until the child has been
    waited for, and a pipe's buffer would stop a child that printed more than the buffer holds.
    """
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        process = subprocess.Popen(list(command), stdout=out, stderr=err,
                                   env=None if environment is None else dict(environment))
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.perf_counter() - start
        process.returncode = os.waitstatus_to_exitcode(status)
        out.seek(0)
        err.seek(0)
        if process.returncode != 0:
            raise RuntimeError(f"{' '.join(command[-4:])} failed: {err.read().decode(errors='replace')[-300:]}")
        return CommandTiming(wall, usage.ru_utime + usage.ru_stime, out.read().decode(errors="replace"))


def record_figures(section: str, figures: dict[str, Any], path: Path | None = None) -> Path:
    """Merge ``figures`` under ``section`` into ``results/benchmarks.json`` (atomically).

    Other sections already in the file are kept, so each benchmark script
    updates only its own figures.
    """
    path = path if path is not None else results_directory() / "benchmarks.json"
    existing: dict[str, Any] = {}
    if path.exists():
        try:
            existing = json.loads(path.read_text())
        except json.JSONDecodeError:
            existing = {}
    existing[section] = {
        **to_jsonable(figures),
        "measured_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform()},
    }
    temporary = path.with_suffix(".json.tmp")
    temporary.write_text(json.dumps(existing, indent=2, sort_keys=True) + "\n")
    os.replace(temporary, path)
    return path
