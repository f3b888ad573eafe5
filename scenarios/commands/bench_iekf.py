"""Measure one IEKF pass over the 50,000-sample linear example.

The compiled pass in the paper's form (Euler, paper covariance update) and in
the default form (exact discretisation, Joseph update), each beside a plain
NumPy reference of the same form measured in the same run, and the default
three-output pass. Figures are medians; they are also written to
results/benchmarks.json under "iekf_linear".
"""

from __future__ import annotations

import argparse

from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.iekf_benchmark import measure_iekf, report_text

NAME = "iekf"
GROUP = "bench"
HELP = "seconds per IEKF pass, compiled vs the NumPy reference"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats per figure (default 7)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    figures = measure_iekf(repeats=max(args.repeats, 1))
    path = record_figures("iekf_linear", figures)
    return figures, report_text(figures) + f"\nwrote {path}"
