"""What each compiler optimisation level costs to build and saves per pass, for the IEKF's pass library.

    python benchmarks/iekf_compile_levels.py [--samples 4000] [--repeats 3]

For linear modal structures of growing size, the pass library is compiled in an empty
cache at each of ``-O0``, ``-O1``, ``-O2`` and ``-O3 -march=native``, for both kernels
(the generated step and the structured loops), and one pass over a record of
``--samples`` samples is timed (median of ``--repeats`` after one unmeasured pass). A
suite on an empty cache pays the compile once per structure; an identification pays
the pass once per iteration (tens to hundreds), so the level to choose is the one
whose compile time plus the passes of a typical run is least. The load average is
recorded beside the figures: on a shared machine both times grow with it, so the
compiler's CPU time and the pass's CPU time are recorded too, and from them, per
structure and kernel, the break-even of ``-O0`` against ``-O3 -march=native``: the
filter steps (samples x passes) below which the quick build costs less in all
(``QUICK_COMPILE_STEPS`` of the pass module sits at the smallest of these).

Figures go to ``results/benchmarks.json`` under ``iekf_compile_levels``.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time

import numpy as np

from vehid.identification.compiled import compile_driver
from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_kernel import structured_pass_source
from vehid.identification.filtering.iekf_pass import PASS_DRIVER, CompiledPass, build_filter_step, pack_covariance
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.benchmarking import record_figures

LEVELS = ("-O0", "-O1", "-O2", "-O3 -march=native")
# (pattern, order, inputs, outputs): single-output records of growing order, the handling study's shape
STRUCTURES = (("default", 2, 1, 1), ("default", 4, 1, 1), ("default", 6, 1, 1), ("default", 4, 2, 3), ("default", 8, 1, 1))


def _library(filter_step, kernel: str, flags: str):
    if kernel == "structured":
        source, functions = structured_pass_source(filter_step)
        return compile_driver(tuple(functions), source, library_name="bench_loops", entry="vehid_iekf_pass",
                              n_integers=4, n_arrays=8, optimisation=flags)
    return compile_driver(filter_step.timed_step, PASS_DRIVER, library_name="bench_pass", entry="vehid_iekf_pass",
                          n_integers=4, n_arrays=8, optimisation=flags)


def _pass_inputs(structure: ModalStructure, samples: int):
    rng = np.random.default_rng(0)
    theta = structure.initial_parameters(sigma=-2.0, omega=6.0, omega_spread=0.5)
    m = structure.n + theta.size
    state = np.concatenate([np.zeros(structure.n), theta, pack_covariance(1e-3 * np.eye(m))])
    u = rng.standard_normal((samples, structure.n_u))
    y = 0.1 * rng.standard_normal((samples, structure.n_y))
    return state, u, y, np.full(m, 1e-6), np.eye(structure.n_y)


def _break_even(rows: list[dict]) -> list[dict]:
    """Per structure and kernel, the filter steps below which ``-O0`` costs less CPU than ``-O3 -march=native``
    in all (compile plus steps): the extra compile over the time each step saves."""
    found = []
    for quick in (row for row in rows if row["flags"] == "-O0"):
        full = next(row for row in rows if row["flags"] == "-O3 -march=native"
                    and (row["structure"], row["kernel"]) == (quick["structure"], quick["kernel"]))
        saved_per_step = (quick["pass_cpu_seconds_min"] - full["pass_cpu_seconds_min"]) / quick["samples"]
        extra_compile = full["compile_cpu_seconds"] - quick["compile_cpu_seconds"]
        steps = extra_compile / saved_per_step if saved_per_step > 0 else float("inf")
        found.append({"structure": quick["structure"], "kernel": quick["kernel"],
                      "step_instructions": quick["step_instructions"], "break_even_steps": steps})
    return found


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
                        compiler_cpu = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
                        run = CompiledPass(_library(filter_step, kernel, flags), filter_step)
                        compile_seconds = time.perf_counter() - start
                        compile_cpu = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime - compiler_cpu
                        run(*inputs)
                        times, cpu_times = [], []
                        for _ in range(repeats):
                            start = time.perf_counter()
                            cpu_start = time.process_time()
                            run(*inputs)
                            times.append(time.perf_counter() - start)
                            cpu_times.append(time.process_time() - cpu_start)
                    finally:
                        if previous is None:
                            del os.environ["VEHID_CACHE_DIR"]
                        else:
                            os.environ["VEHID_CACHE_DIR"] = previous
                row = {"structure": f"{pattern} n={order} n_u={n_u} n_y={n_y}", "filter_states": filter_step.n_z,
                       "step_instructions": filter_step.timed_step.n_instructions(), "kernel": kernel,
                       "flags": flags, "compile_seconds": compile_seconds, "compile_cpu_seconds": compile_cpu,
                       "pass_seconds_median": statistics.median(times), "pass_cpu_seconds_min": min(cpu_times),
                       "samples": samples}
                rows.append(row)
                print(f"{row['structure']:28s} m={row['filter_states']:3d} {kernel:10s} {flags:18s} "
                      f"compile {compile_seconds:7.2f} s ({compile_cpu:6.2f} s CPU)  "
                      f"pass {row['pass_seconds_median'] * 1e3:8.2f} ms ({min(cpu_times) * 1e3:8.2f} ms CPU)", flush=True)
    figures = {"load_average_1min": [load_before, os.getloadavg()[0]], "rows": rows,
               "quick_break_even_steps": _break_even(rows)}
    record_figures("iekf_compile_levels", figures)
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=4000, help="samples of the timed pass (default 4000)")
    parser.add_argument("--repeats", type=int, default=3, help="timed passes per level (default 3)")
    arguments = parser.parse_args()
    main(arguments.samples, arguments.repeats)
