"""The handling study's report, drawn from its archive (``results/handling_study.h5``).

Figures by PNG stem: ``fits_identification`` and ``fits_validation`` (the
chosen order's models simulated from rest; the paper's Figures 7 and 9),
``splines`` (Figure 8), ``mode_amplitude`` (the first mode's frequency and
damping against its amplitude, every order), ``orders`` (Table 5),
``linear_parameters``, ``linear_convergence`` and ``nonlinear_convergence``
(Figures 1-4), ``eigenvalues`` and ``bode`` (beside the vehicle's
linearisation), ``residuals`` and ``residual_tests``. Models that carry a
parameter covariance get 95 % bands. Besides the figures, ``table.md`` holds
the Table-5 style table and ``nonlinear_n<order>.casadi`` the chosen
nonlinear model as a CasADi Function (``casadi.Function.load``; input steer
(1, N) in rad, outputs (3, N)).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from vehid.identification.dataio.archive import Archive, RunName, read_archive
from vehid.identification.errors import InputError
from vehid.identification.assessment.residuals import residual_tests
from vehid.identification.models.delta_method import normal_quantile

from . import plots
from .figure_style import add_legend
from .report import format_eigenvalues, markdown_table, write_report

__all__ = ["handling_figures", "handling_table", "write_handling_report"]

TABLE_HEADERS = {
    "order": "n",
    "linear_eigenvalues": "linear eigenvalues",
    "linear_identification_R": "linear identification R %",
    "nonlinear_identification_R": "nonlinear identification R %",
    "linear_validation_R": "linear validation R %",
    "nonlinear_validation_R": "nonlinear validation R %",
}


def _study(archive: Archive | str | Path) -> Archive:
    """A finished study's archive, read whole (a path is read here, once)."""
    if not isinstance(archive, Archive):
        archive = read_archive(archive, kinds=["handling-study"])
    if archive.summary is None:
        raise InputError("the archive holds an unfinished handling study (no summary yet): "
                         "finish it with vehid study handling --resume ARCHIVE")
    return archive


def _models(archive: Archive, kind: str) -> dict[int, Any]:
    """The models of one kind of run (``linear``, ``nonlinear``), by order."""
    orders = {name: RunName.parse(name) for name in archive.runs}
    return {parsed.order: archive.runs[name].model for name, parsed in orders.items()
            if parsed is not None and parsed.kind == kind and archive.runs[name].model is not None}


def handling_table(summary: dict[str, Any]) -> str:
    """The Table-5 style table as markdown, with the chosen order below it."""
    rows = []
    for row in summary["table"]:
        cells = {key: "" if row[key] is None else f"{row[key]:.2f}" for key in TABLE_HEADERS if key.endswith("_R")}
        eigenvalues = format_eigenvalues([complex(*v) for v in row["linear_eigenvalues"]], 3)
        rows.append({"order": row["order"], "linear_eigenvalues": eigenvalues, **cells})
    text = markdown_table(rows, list(TABLE_HEADERS), headers=TABLE_HEADERS)
    return text + f"\nChosen order: {summary['chosen_order']}.\n"


def handling_figures(archive: Archive | str | Path) -> dict[str, Figure]:
    """Every figure of the handling report, from the study's archive (read, or its path)."""
    archive = _study(archive)
    summary, records = archive.summary, archive.records
    linear, nonlinear = _models(archive, "linear"), _models(archive, "nonlinear")
    chosen = summary["chosen_order"]
    figures: dict[str, Figure] = {}
    names = list(records["identification"].output_names)
    units = list(records["identification"].output_units)

    for record_name in ("identification", "validation"):
        data = records[record_name]
        predictions = {f"{kind} n = {chosen}": models[chosen].simulate_outputs(data.u, data.dt)
                       for kind, models in (("linear", linear), ("nonlinear", nonlinear)) if chosen in models}
        figures[f"fits_{record_name}"] = plots.plot_time_fits(
            data.t, data.y, predictions, names, units,
            title=f"Handling model fits on the {record_name} manoeuvre (n = {chosen})",
        )

    if chosen in nonlinear:
        model = nonlinear[chosen]
        coefficient_names = model.structure.coefficient_names()
        picks = [name for name in ("sigma1", "omega1") if name in coefficient_names]
        picks += [name for name in coefficient_names if name.startswith(("b", "c"))][:2]
        xs, values, node_x, node_y, x_labels, spreads = [], [], [], [], [], []
        tables = model.spline_tables()
        for name in picks:
            table = tables[name]
            nodes = table["nodes"]
            span = nodes[-1] - nodes[0]
            lower = 0.0 if table["variable"].startswith("amplitude") else nodes[0] - 0.2 * span  # amplitudes are >= 0
            grid = np.linspace(lower, nodes[-1] + 0.2 * span, 200)
            xs.append(grid)
            values.append(model.coefficient(name, grid))
            spreads.append(model.coefficient_std(name, grid))
            node_x.append(nodes)
            node_y.append(table["values"])
            x_labels.append(f"{table['variable']} (normalised)")
        figures["splines"] = plots.plot_splines(
            xs, values, node_x, node_y, picks, x_labels=x_labels,
            title=f"Splined coefficients of the nonlinear model (n = {chosen})",
        )
        _shade(figures["splines"].axes, xs, values, spreads)

    curves = [run for run in summary.get("nonlinear_runs", []) if run.get("mode_frequency_hz")]
    if curves:
        figure = plots.new_figure()
        frequency_axis = figure.add_subplot(2, 1, 1)
        damping_axis = figure.add_subplot(2, 1, 2, sharex=frequency_axis)
        for run in curves:
            amplitudes = run["mode_amplitudes"]
            line = frequency_axis.plot(amplitudes, run["mode_frequency_hz"][0], marker="o", label=f"n = {run['order']}")
            damping_axis.plot(amplitudes, run["mode_damping"][0], marker="o", label=f"n = {run['order']}")
            model = nonlinear.get(run["order"])
            if getattr(model, "parameter_covariance", None) is not None:
                spread = model.mode_frequency_damping_std(0, amplitudes)
                _shade([frequency_axis, damping_axis], [amplitudes] * 2,
                       [run["mode_frequency_hz"][0], run["mode_damping"][0]], spread, color=line[0].get_color())
        frequency_axis.set_ylabel("frequency (Hz)")
        damping_axis.set_ylabel("damping ratio (-)")
        damping_axis.set_xlabel("first mode's amplitude (normalised state units)")
        frequency_axis.set_title("First mode of the nonlinear models against its amplitude")
        add_legend(frequency_axis)
        for axis in (frequency_axis, damping_axis):
            axis.grid(True, alpha=0.3)
        figures["mode_amplitude"] = figure

    table = summary["table"]
    figure = plots.new_figure()
    axis = figure.add_subplot(1, 1, 1)
    orders = [row["order"] for row in table]
    for key, label, style in (
        ("linear_identification_R", "linear, identification", "o--"),
        ("nonlinear_identification_R", "nonlinear, identification", "o-"),
        ("linear_validation_R", "linear, validation", "s--"),
        ("nonlinear_validation_R", "nonlinear, validation", "s-"),
    ):
        values = [np.nan if row[key] is None else row[key] for row in table]
        axis.plot(orders, values, style, label=label)
    axis.axvline(chosen, color="0.6", linestyle=":", label=f"chosen n = {chosen}")
    axis.set_xlabel("model order n")
    axis.set_ylabel("mean R over the outputs (%)")
    axis.set_title("Handling study: explanation per order (Table 5)")
    axis.set_xticks(orders)
    axis.grid(True, alpha=0.3)
    add_legend(axis)
    figures["orders"] = figure

    if chosen in linear:
        history = archive.runs[str(RunName("linear", chosen))].history
        figures["linear_parameters"] = plots.plot_parameter_history(
            history["parameters"], linear[chosen].structure.parameter_names(),
            title=f"Linear model parameters over the passes (n = {chosen})",
        )
        figures["linear_convergence"] = plots.plot_convergence(
            history["fit_filter"], history["trace_p"], min_eig_p=history["min_eig_p"], output_names=names,
            title=f"Linear IEKF: R and trace(P) per pass (n = {chosen})",
        )
    nonlinear_run = archive.runs.get(str(RunName("nonlinear", chosen)))
    if nonlinear_run is not None and len(nonlinear_run.history.get("fit_filter", ())):
        figures["nonlinear_convergence"] = plots.plot_convergence(
            nonlinear_run.history["fit_filter"], nonlinear_run.history["trace_p"],
            output_names=names, title=f"Nonlinear IEKF: R and trace(P) per pass (n = {chosen})",
        )

    vehicle = summary.get("vehicle_linearization")
    reference = reference_eigenvalues = None
    if vehicle:
        reference = tuple(np.array(vehicle[key]) for key in ("A", "B", "C", "D"))
        reference_eigenvalues = np.linalg.eigvals(reference[0])
        reference_eigenvalues = reference_eigenvalues[np.abs(reference_eigenvalues) < 60]  # the handling band
    models = {f"n = {order}": model for order, model in sorted(linear.items())}
    if models:
        figures["eigenvalues"] = plots.plot_eigenvalue_map(
            models, reference_eigenvalues, title="Identified linear models and the vehicle's modes (circles)",
        )
        figures["bode"] = plots.plot_bode(
            models, reference=reference, output_names=names, output_units=units, input_name="steer", input_unit="rad",
            frequencies=np.logspace(-1.3, 1.2, 200),
            title="Steer to outputs: identified linear models and the vehicle's linearisation",
        )
    if chosen in nonlinear:
        data = records["validation"]
        residuals = data.y - nonlinear[chosen].simulate_outputs(data.u, data.dt)
        figures["residuals"] = plots.plot_residual_autocorrelation(
            residuals, 100, names, dt=data.dt,
            title=f"Residual autocorrelation, nonlinear n = {chosen}, validation data",
        )
    data = records["identification"]
    for kind, model in (("linear", linear.get(chosen)), ("nonlinear", nonlinear.get(chosen))):
        if model is not None:
            tests = residual_tests(data.u, data.y - model.simulate_outputs(data.u, data.dt), input_names=data.input_names,
                                   output_names=names)
            figures[f"residual_tests_{kind}"] = plots.plot_residual_tests(
                tests, dt=data.dt, title=f"Residual tests, {kind} n = {chosen}, identification data")
    return figures


def _shade(axes: Any, xs: Any, values: Any, spreads: Any, color: Any = "tab:blue") -> None:
    """A 95 % band (+/- 1.96 std, delta method) under each curve whose spread is known."""
    z = normal_quantile(0.95)
    for axis, x, value, spread in zip(axes, xs, values, spreads):
        spread = np.asarray(spread, dtype=float)
        if np.all(np.isfinite(spread)):
            value = np.asarray(value, dtype=float)
            axis.fill_between(x, value - z * spread, value + z * spread, color=color, alpha=0.2, linewidth=0,
                              label="95 % band")


def write_handling_report(archive: Archive | str | Path, out_dir: str | Path) -> list[Path]:
    """Write the report beside the archive: PNGs, ``report.pdf``, ``table.md`` and the CasADi export.

    ``archive`` is the study's archive as :func:`~identification.dataio.archive.read_archive` returns it, or its path.
    """
    archive = _study(archive)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = handling_figures(archive)
    written = write_report(figures, out_dir, title="vehid handling study")
    for figure in figures.values():
        figure.clear()
    table_path = out_dir / "table.md"
    table_path.write_text("# Handling study (Table 5 style)\n\n" + handling_table(archive.summary))
    written.append(table_path)
    chosen = archive.summary["chosen_order"]
    nonlinear = _models(archive, "nonlinear")
    if chosen in nonlinear:
        export = out_dir / f"nonlinear_n{chosen}.casadi"
        nonlinear[chosen].to_casadi(n_samples=archive.records["identification"].n_samples).save(str(export))
        written.append(export)
    return written
