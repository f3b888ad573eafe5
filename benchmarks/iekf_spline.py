"""Benchmark: the spline-nonlinear IEKF and the handling study.

Measures, in one run:
* seconds per nonlinear pass (n = 4, three outputs, p = 5 nodes, 30 s at 500 Hz
  of the vehicle's identification manoeuvre), median of repeats, beside the
  linear pass of the same order on the same data (the baseline);
* the same pass on both compiled kernels (the covariance algebra as C loops
  with the low-rank prediction, and the whole generated SX step), for the
  nonlinear and the linear model, timed in turn round by round, and their
  ratio (target: loops >= 2x);
* the build and compile time of the nonlinear step (a first run on a machine);
* with ``--study``, the wall time of the whole ``vehid study handling`` as a
  user runs it (subprocess, default settings).

Figures are printed and merged into results/benchmarks.json under "iekf_spline".
Target: the whole study in <= 10 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numpy as np

from vehid.identification import IEKFOptions, ModalStructure, identify_iekf
from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_pass import compiled_pass, pack_covariance
from vehid.identification.filtering.spline_iekf import residual_covariance, covering_ranges
from vehid.identification.models.spline_modal import SplineModalFilterModel, SplineModalModel
from vehid.scenarios.benchmarking import median_seconds, record_figures
from vehid.vehicle import baseline, make_manoeuvre, simulate

OUTPUTS = ["lateral_acceleration", "yaw_rate", "roll_angle"]


def measure(repeats: int) -> dict:
    data = simulate(baseline(), make_manoeuvre("identification", seed=0)).select_outputs(OUTPUTS)
    structure = ModalStructure.default(4, 1, 3)
    linear = identify_iekf(data, structure, options=IEKFOptions(normalize=True, passes=10, p=0.01))
    scale_u, scale_y = np.abs(data.u).max(0), np.abs(data.y).max(0)
    model = SplineModalModel.from_linear(linear.model, 5, scale_u, scale_y, data.dt)
    u_n, y_n = data.u / scale_u, data.y / scale_y
    y_hat, states = model.simulate_normalised(u_n)
    model, _ = model.resampled(covering_ranges(model.structure, states, model.ranges))
    R = residual_covariance(y_n, y_hat)

    started = time.perf_counter()
    spline_pass = compiled_pass(SplineModalFilterModel(model.structure), data.dt, "exact", "joseph")
    build_seconds = time.perf_counter() - started
    n, m = 4, 4 + model.structure.n_parameters
    q = np.concatenate([np.zeros(n), np.full(m - n, 1e-4)])
    state = np.concatenate([np.zeros(n), model.theta, pack_covariance(np.diag(q))])

    generated_pass = compiled_pass(SplineModalFilterModel(model.structure), data.dt, "exact", "joseph", "generated")
    structured_pass = compiled_pass(SplineModalFilterModel(model.structure), data.dt, "exact", "joseph", "structured")
    both = [lambda: generated_pass(state, u_n, y_n, q, R, model.constants),
            lambda: structured_pass(state, u_n, y_n, q, R, model.constants)]
    nonlinear_generated, nonlinear = interleaved_medians(both, repeats)
    # CPU time of this process: on a machine shared with other work it moves far less than wall time
    cpu_generated, cpu_structured = interleaved_medians(both, repeats, clock=time.process_time)

    linear_pass = compiled_pass(LinearModalFilterModel(structure), data.dt, "exact", "joseph")
    m_lin = 4 + structure.n_parameters
    q_lin = np.concatenate([np.zeros(4), np.full(structure.n_parameters, 0.01)])
    state_lin = np.concatenate([np.zeros(4), linear.state.theta, pack_covariance(np.diag(q_lin))])
    y_s = data.y / linear.state.output_scale
    u_s = data.u / linear.state.input_scale
    linear_seconds = median_seconds(lambda: linear_pass(state_lin, u_s, y_s, q_lin, np.eye(3)), repeats=repeats)
    runs = {kernel: compiled_pass(LinearModalFilterModel(structure), data.dt, "exact", "joseph", kernel)
            for kernel in ("structured", "generated")}
    timed = interleaved_medians([lambda run=run: run(state_lin, u_s, y_s, q_lin, np.eye(3)) for run in runs.values()],
                                repeats)
    kernels = dict(zip(runs, timed))
    return {
        "samples": data.n_samples,
        "nonlinear_filter_states": m,
        "nonlinear_step_instructions": spline_pass.filter_step.step.n_instructions(),
        "nonlinear_s_per_pass": nonlinear,
        "nonlinear_generated_step_s_per_pass": nonlinear_generated,
        "nonlinear_loops_speedup": nonlinear_generated / nonlinear,
        "nonlinear_loops_cpu_s_per_pass": cpu_structured,
        "nonlinear_generated_step_cpu_s_per_pass": cpu_generated,
        "nonlinear_loops_cpu_speedup": cpu_generated / cpu_structured,
        "linear_loops_s_per_pass": kernels["structured"],
        "linear_generated_step_s_per_pass": kernels["generated"],
        "linear_loops_speedup": kernels["generated"] / kernels["structured"],
        "linear_s_per_pass": linear_seconds,
        "nonlinear_to_linear_ratio": nonlinear / linear_seconds,
        "nonlinear_build_and_compile_s": build_seconds,
        "linear_filter_states": m_lin,
    }


def interleaved_medians(works: list, repeats: int, clock=time.perf_counter) -> list[float]:
    """Median time of each of ``works`` on ``clock``, called in turn every round, so that a change in
    the machine's load falls on all of them alike (one uncounted round first)."""
    times: list[list[float]] = [[] for _ in works]
    for round_index in range(repeats + 1):
        for work, record in zip(works, times):
            started = clock()
            work()
            if round_index:
                record.append(clock() - started)
    return [float(np.median(record)) for record in times]


def study_wall_time() -> float:
    started = time.perf_counter()
    completed = subprocess.run([sys.executable, "-m", "vehid.scenarios.cli", "study", "handling", "--quiet", "--json"],
                               capture_output=True, text=True, check=False)
    if completed.returncode != 0:
        raise RuntimeError(f"vehid study handling failed: {completed.stderr.strip()}")
    return time.perf_counter() - started


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--study", action="store_true", help="also time the whole vehid study handling")
    args = parser.parse_args(argv)
    figures = measure(args.repeats)
    print(f"nonlinear pass (n = 4, 3 outputs, 5 nodes, {figures['samples']} samples, "
          f"{figures['nonlinear_filter_states']} filter states): {figures['nonlinear_s_per_pass']:.3f} s median")
    print(f"  the whole generated step: {figures['nonlinear_generated_step_s_per_pass']:.3f} s; "
          f"loops with the low-rank prediction {figures['nonlinear_loops_speedup']:.2f}x faster (target >= 2x)")
    print(f"  CPU time per pass: loops {figures['nonlinear_loops_cpu_s_per_pass']:.3f} s, generated step "
          f"{figures['nonlinear_generated_step_cpu_s_per_pass']:.3f} s ({figures['nonlinear_loops_cpu_speedup']:.2f}x)")
    print(f"linear pass, loops {figures['linear_loops_s_per_pass'] * 1e3:.2f} ms against the generated step "
          f"{figures['linear_generated_step_s_per_pass'] * 1e3:.2f} ms ({figures['linear_loops_speedup']:.2f}x)")
    print(f"linear pass on the same data: {figures['linear_s_per_pass'] * 1e3:.2f} ms "
          f"(nonlinear/linear {figures['nonlinear_to_linear_ratio']:.0f}x)")
    print(f"nonlinear step build and compile (first run; cached after): {figures['nonlinear_build_and_compile_s']:.1f} s")
    if args.study:
        figures["study_handling_wall_s"] = study_wall_time()
        print(f"vehid study handling, whole: {figures['study_handling_wall_s']:.0f} s (target <= 600 s)")
    path = record_figures("iekf_spline", figures)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
