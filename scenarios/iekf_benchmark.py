"""Speed of one IEKF pass over the 50,000-sample linear example, compiled against the NumPy reference.

Shared by ``benchmarks/iekf_linear.py`` and ``vehid bench iekf``. The NumPy
reference costs the same per sample, so it is timed on a slice and scaled.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_pass import compiled_pass, numpy_reference_pass, pack_covariance
from vehid.identification.models.modal_structure import ModalStructure

from .benchmarking import median_seconds
from .linear_example import make_data

__all__ = ["measure_iekf"]

# The forms measured: label to (outputs, C pattern, discretisation, covariance).
_FORMS = {
    "paper_single": ((0,), "all-ones", "euler", "paper"),
    "default_single": ((0,), "all-ones", "exact", "joseph"),
    "default_three": ((0, 1, 2), "eq18", "exact", "joseph"),
}


def _setup(outputs, pattern, discretization, covariance, data_full):
    structure = ModalStructure.from_pattern(pattern, 5, 2, len(outputs))
    built = time.perf_counter()
    run = compiled_pass(LinearModalFilterModel(structure), data_full.dt, discretization, covariance)
    build_seconds = time.perf_counter() - built
    m = structure.n + structure.n_parameters
    q = np.concatenate([np.zeros(structure.n), np.ones(structure.n_parameters)])
    theta = structure.initial_parameters(sigma=-10.0, omega=10.0, omega_spread=0.5)
    state = np.concatenate([np.zeros(structure.n), theta, pack_covariance(np.diag(q))])
    u = data_full.u
    y = data_full.y[:, list(outputs)]
    r = np.eye(len(outputs))
    assert state.size == run.filter_step.n_state and m == run.filter_step.n_z
    return run, state, u, y, q, r, build_seconds


def measure_iekf(*, repeats: int = 7, reference_samples: int = 2000, include_reference: bool = True) -> dict[str, Any]:
    """Median seconds per 50,000-sample pass for each form, and the compiled/NumPy ratios.

    Keys (a public contract, read by other tools): ``single_output_s_per_pass``
    and ``numpy_reference_s_per_pass`` (the paper's form: euler, paper P
    update), ``default_single_output_s_per_pass`` and
    ``default_numpy_reference_s_per_pass`` (exact, Joseph), ``three_output_s_per_pass``
    (default form), ``speedup_vs_numpy``, ``default_speedup_vs_numpy``.
    """
    data, _ = make_data(0)
    n = data.n_samples
    figures: dict[str, Any] = {"samples": n, "repeats": repeats, "reference_samples": reference_samples}
    timings: dict[str, float] = {}
    for label, (outputs, pattern, discretization, covariance) in _FORMS.items():
        run, state, u, y, q, r, build_seconds = _setup(outputs, pattern, discretization, covariance, data)
        timings[label] = median_seconds(lambda: run(state, u, y, q, r), repeats=repeats)
        figures[f"{label}_build_seconds"] = build_seconds
        if include_reference and label != "default_three":
            cut = slice(0, reference_samples)
            slice_seconds = median_seconds(
                lambda: numpy_reference_pass(run.filter_step, state, u[cut], y[cut], q, r), repeats=3, warmup=1,
            )
            timings[f"{label}_numpy"] = slice_seconds * n / reference_samples
    figures.update(
        single_output_s_per_pass=timings["paper_single"],
        default_single_output_s_per_pass=timings["default_single"],
        three_output_s_per_pass=timings["default_three"],
    )
    if include_reference:
        figures.update(
            numpy_reference_s_per_pass=timings["paper_single_numpy"],
            default_numpy_reference_s_per_pass=timings["default_single_numpy"],
            speedup_vs_numpy=timings["paper_single_numpy"] / timings["paper_single"],
            default_speedup_vs_numpy=timings["default_single_numpy"] / timings["default_single"],
        )
    return figures


def report_text(figures: dict[str, Any]) -> str:
    """The figures as lines of text, against the targets."""
    lines = [f"IEKF pass over {figures['samples']} samples, median of {figures['repeats']}:"]
    lines.append(f"  paper form, single output:    {figures['single_output_s_per_pass'] * 1e3:8.2f} ms  (target <= 26 ms)")
    lines.append(f"  default form, single output:  {figures['default_single_output_s_per_pass'] * 1e3:8.2f} ms")
    lines.append(f"  default form, three outputs:  {figures['three_output_s_per_pass'] * 1e3:8.2f} ms  (target <= 200 ms)")
    if "numpy_reference_s_per_pass" in figures:
        lines.append(f"  NumPy reference, paper form:   {figures['numpy_reference_s_per_pass']:8.2f} s  "
                     f"-> speed-up {figures['speedup_vs_numpy']:.0f}x (target >= 80x)")
        lines.append(f"  NumPy reference, default form: {figures['default_numpy_reference_s_per_pass']:8.2f} s  "
                     f"-> speed-up {figures['default_speedup_vs_numpy']:.0f}x (target >= 80x)")
    return "\n".join(lines)
