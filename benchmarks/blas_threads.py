"""What one BLAS thread saves: commands timed with the workbench's limit and with the BLAS's own threads.

    python benchmarks/blas_threads.py [--repeats 5] [--parallel 2]

The workbench computes with one BLAS thread unless the environment sets a
thread count (:mod:`vehid.identification.blas`). Each case runs ``vehid
identify`` on committed public records twice over, interleaved so that both
meet the same load:

- ``one thread``: the environment as it is (no thread variable set), so the
  workbench's limit applies;
- ``BLAS threads``: ``OPENBLAS_NUM_THREADS`` (and ``OMP_NUM_THREADS``) set to
  the machine's core count, which the workbench keeps, as a user's choice.

``--parallel K`` runs K copies of the command at once (as a test run's
workers or a study's worker processes do), where spinning threads take the
cores from each other. Figures are medians of ``--repeats`` runs: wall
seconds and the CPU seconds of the process (user + system, from ``wait4``);
the ratios are the threaded run's over the limited one's. They go to
``results/benchmarks.json`` under ``blas_threads``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from vehid.scenarios.benchmarking import record_figures

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data"
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

# Default identification (p by cross-validation, hold-out 0.3) on two public records of the workbench's usual sizes.
CASES = {
    "identify ballbeam": ["identify", str(DATA / "ballbeam" / "ballbeam.dat"), "--inputs", "1", "--outputs", "2",
                          "--dt", "0.1", "--validation", "0.3", "--json", "--quiet"],
    "identify dryer": ["identify", str(DATA / "dryer" / "dryer.dat"), "--inputs", "1", "--outputs", "2",
                       "--dt", "0.08", "--validation", "0.3", "--json", "--quiet"],
}


def _environment(threads: int | None) -> dict[str, str]:
    environment = {key: value for key, value in os.environ.items() if key not in THREAD_VARIABLES}
    if threads is not None:
        environment["OPENBLAS_NUM_THREADS"] = environment["OMP_NUM_THREADS"] = str(threads)
    return environment


def _timed(arguments: list[str], environment: dict[str, str], parallel: int) -> tuple[float, float]:
    """Wall seconds until the last of ``parallel`` copies ends, and their CPU seconds per copy."""
    start = time.perf_counter()
    processes = [subprocess.Popen([sys.executable, "-m", "vehid.scenarios.cli", *arguments], env=environment,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for _ in range(parallel)]
    cpu = 0.0
    for process in processes:
        _, status, usage = os.wait4(process.pid, 0)
        if os.waitstatus_to_exitcode(status) not in (0, 3):
            raise SystemExit(f"{arguments[:2]} failed with status {os.waitstatus_to_exitcode(status)}")
        cpu += usage.ru_utime + usage.ru_stime
    return time.perf_counter() - start, cpu / parallel


def main(repeats: int, parallel: int) -> dict:
    cores = os.cpu_count() or 1
    settings = {"one thread": None, "BLAS threads": cores}
    figures: dict[str, dict] = {}
    for case, arguments in CASES.items():
        samples: dict[str, list[tuple[float, float]]] = {name: [] for name in settings}
        for _ in range(repeats):
            for name, threads in settings.items():
                samples[name].append(_timed(arguments, _environment(threads), parallel))
        row: dict[str, float] = {}
        for name, runs in samples.items():
            row[f"{name} wall s"] = statistics.median(run[0] for run in runs)
            row[f"{name} cpu s"] = statistics.median(run[1] for run in runs)
        row["wall ratio"] = row["BLAS threads wall s"] / row["one thread wall s"]
        row["cpu ratio"] = row["BLAS threads cpu s"] / row["one thread cpu s"]
        figures[case] = row
        print(f"{case} ({parallel} at once, median of {repeats}): one thread {row['one thread wall s']:.2f} s wall, "
              f"{row['one thread cpu s']:.2f} s CPU; {cores} BLAS threads {row['BLAS threads wall s']:.2f} s wall, "
              f"{row['BLAS threads cpu s']:.2f} s CPU (ratios {row['wall ratio']:.2f}, {row['cpu ratio']:.2f})")
    result = {"cases": figures, "parallel": parallel, "repeats": repeats, "cores": cores,
              "load_average": list(os.getloadavg())}
    record_figures("blas_threads", result)
    return result


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--parallel", type=int, default=2, help="copies of each command run at once")
    options = parser.parse_args()
    main(options.repeats, options.parallel)
