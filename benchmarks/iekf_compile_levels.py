"""What each compiler optimisation level costs to build and saves per pass, for the IEKF's pass library.

    python benchmarks/iekf_compile_levels.py [--samples 4000] [--repeats 3]

For linear modal structures of growing size, the pass library is compiled in an empty
cache at each of ``-O0``, ``-O1``, ``-O2`` and ``-O3 -march=native``, for both kernels
(the generated step and the structured loops), and one pass over a record of
``--samples`` samples is timed (median of ``--repeats`` after one unmeasured pass). A
suite on an empty cache pays the compile once per structure; an identification pays
the pass once per iteration (tens to hundreds), so the level to choose is the one
whose compile time plus the passes of a typical run is least. The load average is
recorded beside the figures: on a shared machine both times grow with it.

Figures go to ``results/benchmarks.json`` under ``iekf_compile_levels``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time

import numpy as np

from vehid.identification.compiled import compile_driver
from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_kernel import structured_pass_source
from vehid.identification.filtering.iekf_pass import _DRIVER, _CompiledPass, build_filter_step, pack_covariance
from vehid.identification.models.modal import ModalStructure
from vehid.scenarios.benchmarking import record_figures

LEVELS = ("-O0", "-O1", "-O2", "-O3 -march=native")
# (pattern, order, inputs, outputs): a single-output record, the handling study's shape, a larger one
STRUCTURES = (("default", 4, 1, 1), ("default", 4, 2, 3), ("default", 8, 1, 1))


def _library(filter_step, kernel: str, flags: str):
    if kernel == "structured":
        source, functions = structured_pass_source(filter_step)
        return compile_driver(tuple(functions), source, library_name="bench_loops", entry="vehid_iekf_pass",
                              n_integers=4, n_arrays=8, optimisation=flags)
    return compile_driver(filter_step.timed_step, _DRIVER, library_name="bench_pass", entry="vehid_iekf_pass",
                          n_integers=4, n_arrays=8, optimisation=flags)


def _pass_inputs(structure: ModalStructure, samples: int):
    rng = np.random.default_rng(0)
    theta = structure.initial_parameters(sigma=-2.0, omega=6.0, omega_spread=0.5)
    m = structure.n + theta.size
    state = np.concatenate([np.zeros(structure.n), theta, pack_covariance(1e-3 * np.eye(m))])
    u = rng.standard_normal((samples, structure.n_u))
    y = 0.1 * rng.standard_normal((samples, structure.n_y))
    return state, u, y, np.full(m, 1e-6), np.eye(structure.n_y)


def main(samples: int, repeats: int) -> dict:
    rows = []
    load_before = os.getloadavg()[0]
    for pattern, order, n_u, n_y in STRUCTURES:
        structure = ModalStructure.from_pattern(pattern, order, n_u, n_y)
        filter_step = build_filter_step(LinearModalFilterModel(structure), 0.01, "exact", "joseph")
        inputs = _pass_inputs(structure, samples)
        for kernel in ("generated", "structured"):
            for flags in LEVELS:
                with tempfile.TemporaryDirectory(prefix="vehid-bench-cache-") as cache:
                    previous = os.environ.get("VEHID_CACHE_DIR")
                    os.environ["VEHID_CACHE_DIR"] = cache
                    try:
                        start = time.perf_counter()
                        run = _CompiledPass(_library(filter_step, kernel, flags), filter_step)
                        compile_seconds = time.perf_counter() - start
                        run(*inputs)
                        times = []
                        for _ in range(repeats):
                            start = time.perf_counter()
                            run(*inputs)
                            times.append(time.perf_counter() - start)
                    finally:
                        if previous is None:
                            del os.environ["VEHID_CACHE_DIR"]
                        else:
                            os.environ["VEHID_CACHE_DIR"] = previous
                row = {"structure": f"{pattern} n={order} n_u={n_u} n_y={n_y}", "filter_states": filter_step.n_z,
                       "step_instructions": filter_step.timed_step.n_instructions(), "kernel": kernel,
                       "flags": flags, "compile_seconds": compile_seconds,
                       "pass_seconds_median": statistics.median(times), "samples": samples}
                rows.append(row)
                print(f"{row['structure']:28s} m={row['filter_states']:3d} {kernel:10s} {flags:18s} "
                      f"compile {compile_seconds:7.2f} s  pass {row['pass_seconds_median'] * 1e3:8.2f} ms", flush=True)
    figures = {"load_average_1min": [load_before, os.getloadavg()[0]], "rows": rows}
    record_figures("iekf_compile_levels", figures)
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4000, help="samples of the timed pass (default 4000)")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes per level (default 3)")
    arguments = parser.parse_args()
    main(arguments.samples, arguments.repeats)
