"""Helpers for the scripts in ``benchmarks/``: repeated timing and the shared figures file.

Figures are medians over repeats; comparisons are ratios against a baseline
measured in the same run, because the machines are noisy.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
from pathlib import Path
from typing import Any, Callable

from vehid.identification.jsonable import to_jsonable

from .paths import results_directory

__all__ = ["median_seconds", "record_figures"]


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
