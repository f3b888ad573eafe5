"""The linear example of Best & Bogdanski 2017, section 4: Tables 1-4 and the order study.

The source system is eq. 15 (five states, two inputs, three outputs), the
data its exact response to the piecewise-linear inputs of eq. 16. The cases
run the Euler filter by default, as the paper does. Cases and what to expect:

``single-output`` (Table 1)
    Output 1, ``C = [1 1 1 1 1]``. With the paper's Euler filter the model
    converges to the Euler equivalent of eq. 15, eigenvalues
    ``(e^{lambda T} - 1)/T`` = -3.984, -14.874 +/- 9.704j, -9.510 +/- 39.323j,
    and D near [0.0123, -0.0023], R above 99.4 % after two passes; the
    exact filter converges to eq. 15 itself.
``three-output`` (Table 2)
    C's first row fixed to ones: R near 100 % while trace(P) and some
    parameters drift.
``three-output-constrained`` (Table 3)
    The eq. 18 pattern: trace(P) settles and all five eigenvalues are found.
``noise`` (Table 4)
    Output 1 with 10/30/50/70 % white noise (of the output's RMS): R against
    the noisy data and against the clean data.
``orders`` (Figure 5)
    Three outputs, n = 3..7 with the eq. 19 patterns: R, the trend of
    trace(P), parameter drift and the chosen order (paper: n = 4).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from vehid.identification.dataio.archive import write_archive, write_record
from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.filtering.iekf import IEKFOptions, IEKFResult, identify_iekf
from vehid.identification.dataio.iekf_archive import write_iekf_run
from vehid.identification.jsonable import to_jsonable
from vehid.identification.assessment.metrics import nrmse_fit_of_R, percentage_explanation
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.order import OrderAssessment, assess_orders

from .paths import results_path
from .study_settings import LINEAR_EXAMPLE_CASES

__all__ = [
    "CASES",
    "PAPER",
    "DT",
    "true_model",
    "identification_input",
    "make_data",
    "euler_equivalent",
    "CaseResult",
    "run_case",
    "planned_passes",
    "write_archive_for",
]

DT = 0.002  # [s] 500 Hz (eq. 16)
CASES = LINEAR_EXAMPLE_CASES
NOISE_RATIOS = (0.1, 0.3, 0.5, 0.7)
ORDERS = (3, 4, 5, 6, 7)

#: What the paper reports (Best & Bogdanski 2017, Tables 1-4, section 4.3).
PAPER: dict[str, Any] = {
    "single-output": {
        "eigenvalues": [complex(-4.09, 0), complex(-14.89, 9.83), complex(-14.89, -9.83), complex(-9.51, 39.32), complex(-9.51, -39.32)],
        "D": [[0.0123, -0.002]],
        "R_after_2_passes": 99.4,
    },
    "three-output": {
        "eigenvalues": [complex(-15.95, 0), complex(-13.94, 0.57), complex(-13.94, -0.57), complex(-9.46, 39.32), complex(-9.46, -39.32)],
    },
    "three-output-constrained": {
        "eigenvalues": [complex(-4.10, 0), complex(-14.93, 9.67), complex(-14.93, -9.67), complex(-9.51, 39.32), complex(-9.51, -39.32)],
    },
    "noise": {
        "R_noisy": {0.1: 98.97, 0.3: 91.75, 0.5: 79.45, 0.7: 66.84},
        "R_clean": {0.1: 99.96, 0.3: 99.97, 0.5: 99.60, 0.7: 99.90},
    },
    "orders": {
        "chosen_order": 4,
        "n4_eigenvalues": [complex(-9.57, 39.38), complex(-12.68, 10.27)],
        "finding": "n = 4 and 5 converge, n = 6 and 7 drift, n = 3 fits poorly",
    },
}

# Default settings per case: outputs used, C pattern, passes, p.
_CASE_SETTINGS: dict[str, dict[str, Any]] = {
    "single-output": {"outputs": (0,), "pattern": "all-ones", "passes": 60, "p": 1.0},
    "three-output": {"outputs": (0, 1, 2), "pattern": "all-ones", "passes": 40, "p": 1.0},
    "three-output-constrained": {"outputs": (0, 1, 2), "pattern": "eq18", "passes": 40, "p": 1.0},
    "noise": {"outputs": (0,), "pattern": "all-ones", "passes": 40, "p": 0.001},
    "orders": {"outputs": (0, 1, 2), "pattern": "eq19", "passes": 60, "p": 1.0},
}


def true_model(n_outputs: int = 3) -> ModalModel:
    """The source system of eq. 15 with its first ``n_outputs`` outputs (1 or 3), in pairs-first modal order.

    Eq. 15 lists the real pole first; here the pairs come first (states 1-2:
    -15 +/- 10j, states 3-4: -8 +/- 40j, state 5: -4), rows of B and columns
    of C permuted alike. The first row of C stays all ones (the ``all-ones``
    pattern).
    """
    if n_outputs not in (1, 3):
        raise InputError(f"the linear example has 1 or 3 outputs; got {n_outputs}")
    order = [1, 2, 3, 4, 0]
    A = np.array(
        [[-4, 0, 0, 0, 0], [0, -15, 10, 0, 0], [0, -10, -15, 0, 0], [0, 0, 0, -8, 40], [0, 0, 0, -40, -8]],
        dtype=float,
    )[np.ix_(order, order)]
    B = np.array([[0.1, 0.1], [0.3, -3], [1.5, 0], [10, -0.5], [0.7, 1]])[order]
    C = np.array([[1, 1, 1, 1, 1], [2, 0.3, 0.35, -1.35, -0.06], [2.75, -1.3, 3.6, 1.4, 0.77]])[:n_outputs, order]
    D = np.array([[0, 0], [1.5, 0.67], [-0.2, 1.4]])[:n_outputs]
    return ModalModel(
        ModalStructure.from_pattern("all-ones", 5, 2, n_outputs), A, B, C, D,
        input_names=("u1", "u2"), output_names=tuple(f"y{i + 1}" for i in range(n_outputs)),
        meta={"source": "Best & Bogdanski 2017, eq. 15"},
    )


def euler_equivalent(eigenvalues: Any, dt: float = DT) -> np.ndarray:
    """``(e^{lambda T} - 1)/T``: where the Euler filter's eigenvalues converge."""
    return (np.exp(np.asarray(eigenvalues, dtype=complex) * dt) - 1.0) / dt


def identification_input(seed: int = 0, *, duration: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 16: times (N,) and inputs (N, 2): N(0, 1) points at 50 Hz, linear between, plus offsets +0.1, -0.1.

    ``N = duration x 500``; samples past the last 50 Hz point hold its value.
    """
    if not duration > 0:
        raise InputError(f"duration must be positive; got {duration}")
    rng = np.random.default_rng(seed)
    coarse_dt = 0.02  # 50 Hz points
    n_coarse = int(round(duration / coarse_dt))
    coarse = rng.standard_normal((n_coarse, 2))
    t_coarse = np.arange(n_coarse) * coarse_dt
    t = np.arange(int(round(duration / DT))) * DT
    u = np.column_stack([np.interp(t, t_coarse, coarse[:, i]) for i in range(2)]) + np.array([0.1, -0.1])
    return t, u


def make_data(
    seed: int = 0,
    *,
    outputs: tuple[int, ...] = (0, 1, 2),
    noise_ratio: float = 0.0,
    duration: float = 100.0,
) -> tuple[IOData, np.ndarray]:
    """The eq. 16 record: returns the (possibly noisy) record and the clean outputs (N, n_y).

    Noise is white and Gaussian with a standard deviation of ``noise_ratio``
    times each output's RMS, drawn from a generator seeded with ``seed + 1_000_003``
    so that the inputs are the same with and without noise.
    """
    if not 0.0 <= noise_ratio < 10.0:
        raise InputError(f"noise_ratio must lie in [0, 10); got {noise_ratio}")
    t, u = identification_input(seed, duration=duration)
    clean = true_model().simulate_outputs(u, DT)[:, list(outputs)]
    y = clean
    if noise_ratio > 0:
        rms = np.sqrt(np.mean(clean**2, axis=0))
        y = clean + noise_ratio * rms * np.random.default_rng(seed + 1_000_003).standard_normal(clean.shape)
    data = IOData(
        t=t, u=u, y=y,
        input_names=("u1", "u2"),
        output_names=tuple(f"y{i + 1}" for i in outputs),
        meta={"source": "Best & Bogdanski 2017, eq. 15-16", "seed": seed, "noise_ratio": noise_ratio},
    )
    return data, clean


@dataclass(frozen=True, eq=False)
class CaseResult:
    """One case of the linear example: its runs, a table beside the paper's numbers, a JSON summary."""

    case: str
    settings: dict[str, Any]
    runs: dict[str, IEKFResult]
    data: dict[str, IOData]
    rows: tuple[dict[str, Any], ...]
    summary: dict[str, Any]
    text: str
    seconds: float
    orders: OrderAssessment | None = None
    extra: dict[str, Any] = field(default_factory=dict)


def _eigen_text(values: Any) -> str:
    parts = []
    for value in sorted(np.asarray(values, dtype=complex), key=lambda v: (v.real, -v.imag)):
        if abs(value.imag) < 1e-12:
            parts.append(f"{value.real:.3f}")
        elif value.imag > 0:
            parts.append(f"{value.real:.3f}±{value.imag:.3f}j")
    return ", ".join(parts)


def _model_summary(result: IEKFResult, data: IOData) -> dict[str, Any]:
    """A run's JSON keys: every ``*fit_percent`` an NRMSE fit and every ``*R`` its fit R (eq. 17) on ``data``.

    ``fit_percent``/``R`` per output of the continuous model simulated exactly from rest; the ``*_by_pass``
    lists the mean over the outputs after each pass, ``fit_percent_by_pass``/``R_by_pass`` of the model
    simulated with the filter's discretisation, ``fit_continuous_by_pass``/``R_continuous_by_pass``
    exactly. The fits are converted from the filter's R on the same samples
    (:func:`~vehid.identification.assessment.metrics.nrmse_fit_of_R`).
    """
    model = result.model

    def fit(R: Any) -> np.ndarray:
        return nrmse_fit_of_R(R, data.y)

    return {
        "eigenvalues": model.eigenvalues(),
        "fit_percent": fit(result.fit_percent),
        "R": result.fit_percent,
        "passes_run": result.passes_run,
        "discretization": result.options.discretization,
        "A": model.A,
        "B": model.B,
        "C": model.C,
        "D": model.D,
        "seconds": result.seconds,
        "fit_percent_by_pass": [float(np.mean(fit(record.fit_filter))) for record in result.history],
        "R_by_pass": [record.mean_fit_filter for record in result.history],
        "fit_continuous_by_pass": [float(np.mean(fit(record.fit_continuous))) for record in result.history],
        "R_continuous_by_pass": [record.mean_fit_continuous for record in result.history],
        "trace_p_by_pass": [record.trace_p for record in result.history],
        "stop_reason": result.stop_reason,
    }


def run_case(
    case: str,
    *,
    seed: int = 0,
    passes: int | None = None,
    discretization: str = "euler",
    p: float | None = None,
    covariance: str = "joseph",
    start: str = "default",
    on_pass: Callable[[str, Any, Any], None] | None = None,
    parameter_covariance: bool = True,
) -> CaseResult:
    """Run one case of the linear example.

    Parameters
    ----------
    case : one of :data:`CASES`
    seed : int
        Seed of the eq. 16 inputs (and of the noise).
    passes, p : optional
        Override the case's pass count and tuning parameter.
    discretization : {"euler", "exact", "exact-zoh"}
        ``euler`` reproduces the paper; ``exact`` identifies the continuous system.
    covariance, start :
        See :class:`vehid.identification.filtering.iekf.IEKFOptions`.
    on_pass : callable, optional
        ``on_pass(run_label, record, result)`` after every pass.
    parameter_covariance : bool
        Leave each model its parameter covariance (one more pass and the fit's sensitivity per run);
        False where only the estimates and the fits are read.
    """
    if case not in CASES:
        raise InputError(f"unknown case {case!r}; use one of {', '.join(CASES)}")
    settings = dict(_CASE_SETTINGS[case])
    if passes is not None:
        settings["passes"] = passes
    if p is not None:
        settings["p"] = p
    settings.update(seed=seed, discretization=discretization, covariance=covariance, start=start)
    options = IEKFOptions(
        p=settings["p"], passes=settings["passes"], discretization=discretization, covariance=covariance, start=start,
    )
    started = time.perf_counter()

    def callback(label: str):
        if on_pass is None:
            return None
        return lambda record, result: on_pass(label, record, result)

    if case == "noise":
        return _noise_case(settings, options, callback, started, parameter_covariance)
    if case == "orders":
        return _orders_case(settings, options, callback, started, parameter_covariance)

    data, _ = make_data(seed, outputs=settings["outputs"])
    structure = ModalStructure.from_pattern(settings["pattern"], 5, 2, len(settings["outputs"]))
    result = identify_iekf(data, structure, options=options, on_pass=callback(case),
                           parameter_covariance=parameter_covariance)
    truth = true_model().eigenvalues()
    reference = euler_equivalent(truth) if discretization == "euler" else truth
    paper = PAPER[case]
    rows = [
        {"quantity": "eigenvalues", "workbench": _eigen_text(result.model.eigenvalues()),
         "paper": _eigen_text(paper["eigenvalues"]),
         "reference": _eigen_text(reference) + (" (Euler equivalent of eq. 15)" if discretization == "euler" else " (eq. 15)")},
        {"quantity": "D", "workbench": np.round(result.model.D, 4).tolist(), "paper": paper.get("D", "-"), "reference": "0"},
        {"quantity": "R after pass 2 (filter discretisation), %",
         "workbench": round(result.history[min(1, len(result.history) - 1)].mean_fit_filter, 3),
         "paper": paper.get("R_after_2_passes", "-"), "reference": "-"},
        {"quantity": "R final, filter / continuous model, %",
         "workbench": f"{result.history[-1].mean_fit_filter:.4f} / {result.history[-1].mean_fit_continuous:.4f}",
         "paper": "~100", "reference": "-"},
        {"quantity": "trace(P) final", "workbench": f"{result.history[-1].trace_p:.4g}", "paper": "-", "reference": "-"},
    ]
    summary = {"case": case, **_model_summary(result, data), "paper": paper, "seed": seed}
    converged = "converged" if result.stop_reason == "converged" else f"not converged ({result.stop_reason})"
    text = _table_text(f"Linear example, {case} ({discretization}, {result.passes_run} passes, {converged}, seed {seed})", rows)
    return CaseResult(case, settings, {case: result}, {"identification": data}, tuple(rows), summary, text,
                      time.perf_counter() - started)


def _noise_case(settings, options, callback, started, parameter_covariance) -> CaseResult:
    structure = ModalStructure.from_pattern(settings["pattern"], 5, 2, 1)
    truth = true_model()
    runs, rows = {}, []
    for ratio in NOISE_RATIOS:
        data, clean = make_data(settings["seed"], outputs=(0,), noise_ratio=ratio)
        label = f"noise-{int(round(ratio * 100))}"
        runs[label] = identify_iekf(data, structure, options=options, on_pass=callback(label),
                                    parameter_covariance=parameter_covariance)
        predicted = runs[label].model.simulate_outputs(data.u, data.dt, method=options.simulation_method)
        true_on_noisy = percentage_explanation(data.y, truth.simulate_outputs(data.u, data.dt)[:, :1])[0]
        rows.append({
            "noise": f"{int(round(ratio * 100))} %",
            "R_noisy": float(percentage_explanation(data.y, predicted)[0]),
            "R_clean": float(percentage_explanation(clean, predicted)[0]),
            "R_noisy_true_model": float(true_on_noisy),
            "paper_R_noisy": PAPER["noise"]["R_noisy"][ratio],
            "paper_R_clean": PAPER["noise"]["R_clean"][ratio],
        })
    summary = {"case": "noise", "levels": rows, "p": options.p, "passes": options.passes,
               "discretization": options.discretization, "seed": settings["seed"],
               "seconds": time.perf_counter() - started}
    lines = [f"Linear example, noise (Table 4; {options.discretization}, p = {options.p:g}, seed {settings['seed']})",
             f"{'noise':>6} {'R noisy':>9} {'true model':>11} {'R clean':>9} {'paper noisy':>12} {'paper clean':>12}"]
    for row in rows:
        lines.append(f"{row['noise']:>6} {row['R_noisy']:9.3f} {row['R_noisy_true_model']:11.3f} {row['R_clean']:9.3f} "
                     f"{row['paper_R_noisy']:12.2f} {row['paper_R_clean']:12.2f}")
    return CaseResult("noise", settings, runs, {}, tuple(rows), summary, "\n".join(lines), time.perf_counter() - started)


def _orders_case(settings, options, callback, started, parameter_covariance) -> CaseResult:
    data, _ = make_data(settings["seed"], outputs=(0, 1, 2))
    runs = {}
    for order in ORDERS:
        structure = ModalStructure.from_pattern("eq19", order, 2, 3)
        runs[f"n{order}"] = identify_iekf(data, structure, options=options, on_pass=callback(f"n{order}"),
                                          parameter_covariance=parameter_covariance)
    assessment = assess_orders({int(label[1:]): result for label, result in runs.items()})
    rows = tuple(row.as_dict() for row in assessment.rows)
    summary = {"case": "orders", "table": list(rows), "chosen_order": assessment.chosen_order,
               "paper": PAPER["orders"], "discretization": options.discretization, "passes": options.passes,
               "seed": settings["seed"], "seconds": time.perf_counter() - started}
    lines = [f"Linear example, order study (Figure 5; {options.discretization}, {options.passes} passes, seed {settings['seed']})",
             assessment.text(), f"chosen order: {assessment.chosen_order} (paper: {PAPER['orders']['chosen_order']}; "
             f"{PAPER['orders']['finding']})"]
    return CaseResult("orders", settings, runs, {"identification": data}, rows, summary, "\n".join(lines),
                      time.perf_counter() - started, orders=assessment)


def _table_text(title: str, rows: list[dict[str, Any]]) -> str:
    lines = [title]
    for row in rows:
        lines.append(f"  {row['quantity']}")
        lines.append(f"    workbench: {row['workbench']}")
        lines.append(f"    paper:     {row['paper']}")
        if row.get("reference", "-") != "-":
            lines.append(f"    reference: {row['reference']}")
    return "\n".join(lines)


def planned_passes(case: str, passes: int | None = None) -> int:
    """The most passes a case can run in all (for progress displays)."""
    if case not in CASES:
        raise InputError(f"unknown case {case!r}; use one of {', '.join(CASES)}")
    per_run = passes if passes is not None else _CASE_SETTINGS[case]["passes"]
    runs = len(NOISE_RATIOS) if case == "noise" else len(ORDERS) if case == "orders" else 1
    return per_run * runs


def write_archive_for(result: CaseResult, out: str | Path | None = None, *, run: str | None = None) -> Path:
    """Write a case's archive (kind ``linear-example``): its data, every run and the summary.

    The default file is ``linear_example_<case>.h5`` under the results folder; a relative ``out`` is taken
    from the working directory. ``run`` names the command line that asked for it (``RUN_ATTRIBUTE``).
    """
    path = results_path(out, f"linear_example_{result.case}.h5")
    settings = to_jsonable(result.settings)
    with write_archive(path, kind="linear-example", config=settings, seeds=[result.settings["seed"]]) as archive:
        if run is not None:
            archive.attrs[RUN_ATTRIBUTE] = run
        for name, data in result.data.items():
            write_record(archive, name, data)
        for name, run in result.runs.items():
            write_iekf_run(archive, name, run)
        archive.attrs["summary_json"] = json.dumps(to_jsonable(result.summary))
    return path
