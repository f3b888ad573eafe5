"""Benchmark: one IEKF pass over the 50,000-sample linear example (the same as `vehid bench iekf`).

Prints its figures and merges them into results/benchmarks.json under "iekf_linear".
"""

from __future__ import annotations

import sys

from vehid.scenarios.cli import main

if __name__ == "__main__":
    sys.exit(main(["bench", "iekf", *sys.argv[1:]]))
