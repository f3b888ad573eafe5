"""Measure one IEKF pass over the 50,000-sample linear example, compiled against a NumPy reference.

Medians over repeats, also written to results/benchmarks.json under "iekf_linear".
"""

from __future__ import annotations

import argparse

NAME = "iekf"
GROUP = "bench"
HELP = "seconds per IEKF pass, compiled vs the NumPy reference"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=7, help="timed repeats per figure (default 7)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    # the filter and its compiler when the command runs, not for its --help
    from vehid.scenarios.benchmarking import record_figures
    from vehid.scenarios.iekf_benchmark import measure_iekf, report_text

    figures = measure_iekf(repeats=max(args.repeats, 1))
    path = record_figures("iekf_linear", figures)
    return figures, report_text(figures) + f"\nwrote {path}"
