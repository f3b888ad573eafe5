"""Reading a long CSV against the identification's first pass, and the peak memory of `vehid identify` on it.

The record: 1.8 million rows of 4 columns (``t, u1, y1, y2``; 1 h at 500 Hz),
the paper's eq. 15 system driven by its eq. 16-like input, outputs 1 and 2,
written with 9 significant digits (81 MB).

- ``read_seconds``: median of 3 reads (:func:`vehid.identification.read_record`,
  the identify command's reader);
- ``first_pass_seconds``: median of 3 first IEKF passes on that record (order
  4, exact discretisation, defaults), pass time including its scoring
  simulation; reads and passes alternate, so that both meet the same load;
- ``peak_rss_mb``: the largest resident set of ``vehid identify FILE --passes 3``
  (``/usr/bin/time -v``, "Maximum resident set size"), for this code and for the
  ``baseline`` tree given by ``--baseline PATH`` (the same command on the same
  file, measured in the same run).

Figures go to ``results/benchmarks.json`` under ``read_records``.
Usage: ``python benchmarks/read_records.py [--rows N] [--baseline PATH]``.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vehid.identification import IEKFOptions, ModalStructure, identify_iekf, read_record
from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.linear_example import DT, true_model


REPEATS = 3


def _write_record(path: Path, rows: int) -> None:
    rng = np.random.default_rng(0)
    t = np.arange(rows) * DT
    u = np.column_stack([np.convolve(rng.standard_normal(rows), np.ones(25) / 25, mode="same"),
                         np.zeros(rows)])
    y = true_model().simulate_outputs(u, DT)[:, :2]
    table = np.column_stack([t, u[:, 0], y])
    np.savetxt(path, table, delimiter=",", header="t,u1,y1,y2", comments="", fmt="%.9g")


def _peak_rss_mb(tree: str, path: Path) -> tuple[float, float]:
    env = dict(os.environ, PYTHONPATH=tree)
    command = ["/usr/bin/time", "-v", sys.executable, "-m", "vehid.scenarios.cli", "identify", str(path), "--inputs", "u1",
               "--outputs", "y1,y2", "--order", "4", "--passes", "3", "--quiet", "--json"]
    completed = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tree, check=False)
    if completed.returncode != 0:
        raise RuntimeError(f"identify failed under {tree}: {completed.stderr[-2000:]}")
    kilobytes = float(re.search(r"Maximum resident set size \(kbytes\): (\d+)", completed.stderr).group(1))
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): ([\d:.]+)", completed.stderr).group(1)
    seconds = sum(float(part) * 60**i for i, part in enumerate(reversed(wall.split(":"))))
    return kilobytes / 1024, seconds


def main(rows: int, baseline: str | None) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "long.csv"
        _write_record(path, rows)
        structure = ModalStructure.default(4, 1, 2)
        reads, passes = [], []
        for _ in range(REPEATS):  # interleaved, so that both see the same load of a shared machine
            start = time.perf_counter()
            data = read_record(path, inputs=["u1"], outputs=["y1", "y2"])
            reads.append(time.perf_counter() - start)
            if not passes:
                identify_iekf(data[:2000], structure, options=IEKFOptions(passes=1))  # compile outside the timing
            passes.append(identify_iekf(data, structure, options=IEKFOptions(passes=1)).history[0].seconds)
            del data
        read_seconds, first_pass = statistics.median(reads), statistics.median(passes)
        ours, ours_wall = _peak_rss_mb(str(Path(__file__).resolve().parents[1]), path)
        figures = {
            "rows": rows,
            "file_megabytes": path.stat().st_size / 1e6,
            "read_seconds": read_seconds,
            "first_pass_seconds": first_pass,
            "read_over_first_pass": read_seconds / first_pass,
            "read_seconds_each": reads,
            "first_pass_seconds_each": passes,
            "peak_rss_mb": ours,
            "identify_wall_seconds": ours_wall,
        }
        if baseline:
            base, base_wall = _peak_rss_mb(baseline, path)
            figures.update({"baseline_peak_rss_mb": base, "baseline_identify_wall_seconds": base_wall})
    record_figures("read_records", figures)
    for key, value in figures.items():
        shown = f"{value:.4g}" if isinstance(value, float) else (
            ", ".join(f"{v:.4g}" for v in value) if isinstance(value, list) else value)
        print(f"{key:32s} {shown}")
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_800_000)
    parser.add_argument("--baseline", help="a source tree to measure the same identify command under")
    arguments = parser.parse_args()
    main(arguments.rows, arguments.baseline)
