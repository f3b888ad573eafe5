"""Write report figures to disk and tables to markdown; draw and tabulate whatever an archive holds."""

from __future__ import annotations

import math
import re
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from vehid.identification.errors import InputError, WorkbenchError
from vehid.identification.assessment.residuals import DEFAULT_LAGS, nis_band, residual_tests
from vehid.identification.assessment.validation import default_horizon, predicted_scores

from . import plots
from .figure_style import known_unit

__all__ = [
    "write_report",
    "markdown_table",
    "format_cell",
    "format_eigenvalues",
    "archive_figures",
    "archive_table",
    "archive_verdict",
    "verdict_lines",
    "verdict_page",
    "handling_page",
    "archive_handling",
    "output_names_of",
    "record_output_names",
    "verdict_output_names",
]

_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


def write_report(
    figures: Mapping[str, Figure],
    out_dir: str | Path,
    *,
    dpi: int = 120,
    pdf_name: str = "report.pdf",
    title: str = "vehid report",
) -> list[Path]:
    """Save every figure as ``<name>.png`` and all of them in one PDF.

    Parameters
    ----------
    figures : mapping of str to Figure
        File stem (letters, digits, ``_.-``) to figure, in page order.
    out_dir : str or Path
        Created if missing.
    dpi : int
        Resolution of the PNGs (the PDF is vector).
    title : str
        The PDF's title metadata.

    Returns
    -------
    list of Path
        The PNGs in the order given, then the PDF.
    """
    if not figures:
        raise InputError("a report needs at least one figure")
    for name, figure in figures.items():
        if not _SAFE_NAME.fullmatch(name):
            raise InputError(f"figure name {name!r} must be letters, digits, '_', '.', '-' (a file stem)")
        if not isinstance(figure, Figure):
            raise InputError(f"figure {name!r} is a {type(figure).__name__}, not a matplotlib Figure")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, figure in figures.items():
        path = out_dir / f"{name}.png"
        figure.savefig(path, dpi=dpi, format="png")
        # The layout just solved places the PDF's page too: positions are fractions of the figure, and text
        # extents in inches hardly depend on the resolution (the PDF's axes land within 0.5 % of the figure
        # of a layout solved anew, at the default 120 dpi). Solving it again was half of the drawing time.
        figure.set_layout_engine("none")
        paths.append(path)
    pdf_path = out_dir / pdf_name
    with PdfPages(pdf_path, metadata={"Title": title, "Creator": "vehid"}) as pdf:
        for figure in figures.values():
            pdf.savefig(figure)
    paths.append(pdf_path)
    return paths


def format_eigenvalues(values: Any, digits: int = 3) -> str:
    """Eigenvalues as in the paper's Table 5: each conjugate pair once as ``a ± bj``, real ones as ``a``.

    Examples
    --------
    >>> format_eigenvalues([complex(-2.4, 2.5), complex(-2.4, -2.5), -13.0])
    '-2.4 ± 2.5j, -13'
    """
    values = np.asarray(values, dtype=complex).ravel()
    shown = [v for v in values if v.imag >= 0]
    return ", ".join(
        f"{v.real:.{digits}g} ± {v.imag:.{digits}g}j" if v.imag > 0 else f"{v.real:.{digits}g}" for v in shown
    )


def format_cell(value: Any, digits: int = 4) -> str:
    """One table cell: numbers to ``digits`` significant figures, complex sequences as eigenvalues.

    ``None`` and NaN become an empty cell; ``|`` is escaped for markdown.
    """
    if value is None:
        text = ""
    elif isinstance(value, (bool, np.bool_)):
        text = "yes" if value else "no"
    elif isinstance(value, (int, np.integer)):
        text = str(int(value))
    elif isinstance(value, (float, np.floating)):
        text = "" if math.isnan(value) else f"{float(value):.{digits}g}"
    elif isinstance(value, (complex, np.complexfloating)):
        text = format_eigenvalues([value, np.conj(value)], digits)
    elif isinstance(value, (list, tuple, np.ndarray)):
        items = list(np.asarray(value).ravel()) if isinstance(value, np.ndarray) else list(value)
        if items and all(isinstance(v, (complex, np.complexfloating)) for v in items):
            text = format_eigenvalues(items, digits)
        else:
            text = ", ".join(format_cell(v, digits) for v in items)
    else:
        text = str(value)
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[str] | None = None,
    *,
    headers: Mapping[str, str] | None = None,
    digits: int | Mapping[str, int] = 4,
) -> str:
    """A markdown table from a list of dicts (one row each), e.g. the paper's Table 5.

    Parameters
    ----------
    rows : sequence of mapping
        One dict per row; missing keys give empty cells.
    columns : sequence of str, optional
        Keys to show, in order; default: every key, in order of first appearance.
    headers : mapping of str to str, optional
        Header text per key (default: the key).
    digits : int or mapping of str to int
        Significant figures of numbers, for all columns or per column.

    Returns
    -------
    str
        The table, numeric columns right-aligned, ending in a newline.

    Examples
    --------
    >>> print(markdown_table([{"n": 2, "eigenvalues": [complex(-2.3, 1.7)], "R": 99.60}],
    ...                      headers={"R": "R (%)"}), end="")
    | n | eigenvalues | R (%) |
    | ---: | --- | ---: |
    | 2 | -2.3 ± 1.7j | 99.6 |
    """
    if columns is None:
        columns = list(dict.fromkeys(key for row in rows for key in row))
    if not columns:
        raise InputError("a table needs at least one column")
    headers = dict(headers or {})

    def places(key: str) -> int:
        return digits.get(key, 4) if isinstance(digits, Mapping) else digits

    def numeric(key: str) -> bool:
        cells = [row.get(key) for row in rows if row.get(key) is not None]
        return bool(cells) and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
            for v in cells
        )

    lines = [
        "| " + " | ".join(format_cell(headers.get(key, key)) for key in columns) + " |",
        "| " + " | ".join("---:" if numeric(key) else "---" for key in columns) + " |",
    ]
    for row in rows:
        lines.append("| " + " | ".join(format_cell(row.get(key), places(key)) for key in columns) + " |")
    return "\n".join(lines) + "\n"


def _stem(*parts: str) -> str:
    return "_".join(re.sub(r"[^A-Za-z0-9_.-]", "_", part) for part in parts)


def _mean_last(history: Mapping[str, np.ndarray], key: str) -> float | None:
    values = history.get(key)
    if values is None or len(values) == 0:
        return None
    return float(np.mean(values[-1]))


def _parameter_names(model: Any, n_theta: int) -> tuple[Sequence[str] | None, dict[str, list[int]] | None]:
    """The names of a run's parameters and their panels (None: the plot's own grouping by name).

    A modal model names each parameter (``sigma1``, ``b11``, ...). A spline model's parameters are the
    node ordinates of each coefficient's spline: named ``<coefficient>[k]`` and grouped, as the
    modal model's, into the modal, B, C and D panels.
    """
    structure = getattr(model, "structure", None)
    coefficients = getattr(structure, "coefficient_names", None)
    nodes = getattr(structure, "nodes", None)
    if callable(coefficients) and isinstance(nodes, int) and getattr(structure, "n_parameters", None) == n_theta:
        names = [f"{name}[{k + 1}]" for name in coefficients() for k in range(nodes)]
        return names, plots.parameter_groups(names)
    names = getattr(structure, "parameter_names", None)
    if callable(names) and getattr(structure, "n_parameters", None) == n_theta:
        return names(), None
    return None, None


@dataclass(frozen=True)
class ScoringRule:
    """How the command that wrote an archive scored its models, so that a report scores them alike.

    Attributes
    ----------
    initial_state : str
        ``"estimate"`` (least-squares initial state per record) or ``"zero"``.
    horizon : int or None
        A k-step-ahead horizon the command was given; None: each model's own
        default (simulation, or a short horizon for an unstable model).
    """

    initial_state: str = "estimate"
    horizon: int | None = None

    def horizon_for(self, model: Any) -> int | None:
        return self.horizon if self.horizon is not None else default_horizon(model)


@dataclass(frozen=True)
class Prediction:
    """A model's outputs on a record (restricted to the model's channels), scored as the command scores them."""

    record: Any
    outputs: np.ndarray
    fit: np.ndarray
    R: np.ndarray


def archive_verdict(archive: Any) -> dict[str, Any] | None:
    """The summary the identify command stored with its archive (scores, warnings, returned run), or None."""
    summary = getattr(archive, "summary", None)
    if getattr(archive, "kind", None) != "identification" or not isinstance(summary, Mapping) \
            or "warnings" not in summary:
        return None
    return dict(summary)


#: archive kinds whose study scores every model simulated from rest (the paper's R), as their reports draw them
FROM_REST_KINDS = ("linear-example",)


def _scoring_rule(archive: Any) -> ScoringRule:
    if getattr(archive, "kind", None) in FROM_REST_KINDS:
        return ScoringRule(initial_state="zero")
    rule = (archive_verdict(archive) or {}).get("scoring_rule") or {}
    return ScoringRule(initial_state=rule.get("initial_state") or "estimate", horizon=rule.get("horizon"))


def _schedule_of(archive: Any, record_name: str) -> tuple[str, str, np.ndarray] | None:
    """The schedule channel (name, unit, samples) of an archived record, where a scheduled run kept it."""
    stored = getattr(archive, "schedule", None)
    if not isinstance(stored, Mapping) or record_name not in (stored.get("records") or {}):
        return None
    return str(stored.get("channel")), str(stored.get("unit") or "-"), np.asarray(stored["records"][record_name])


def _is_scheduled(model: Any) -> bool:
    return hasattr(model, "model_at") and hasattr(model, "grid")


def _model_prediction(model: Any, record: Any, rule: ScoringRule = ScoringRule(),
                      schedule: tuple[str, str, np.ndarray] | None = None) -> Prediction | None:
    """The model on the record restricted to its inputs and outputs: outputs, NRMSE fit and R, by ``rule``.

    The same functions score it as the identify command (:func:`~vehid.identification.assessment.validation.score`),
    with the same initial state, so that a drawn curve is the one whose fit the command stated. A
    scheduled family simulates along the record's ``schedule`` (its name, unit and samples), which it
    needs: without one it is not drawn.
    """
    if not hasattr(model, "simulate_outputs"):
        return None
    inputs = tuple(getattr(model, "input_names", ()) or ())
    outputs = tuple(getattr(model, "output_names", ()) or ())
    if set(inputs) <= set(record.input_names) and set(outputs) <= set(record.output_names) and outputs:
        record = record.select_inputs(inputs).select_outputs(outputs)
    structure = getattr(model, "structure", None)
    sizes = getattr(structure, "linear", structure)  # a spline-modal structure keeps its sizes on its linear one
    if sizes is None or (record.n_u, record.n_y) != (sizes.n_u, sizes.n_y):
        return None
    shown = record
    if _is_scheduled(model):
        if schedule is None or len(schedule[2]) != record.n_samples:
            return None
        record = record.replace(u=np.column_stack([record.u, schedule[2]]), input_names=record.input_names + (schedule[0],),
                                input_units=record.input_units + (schedule[1],))
    horizon = rule.horizon_for(model)
    try:
        predicted, scores = predicted_scores(model, record, initial_state=rule.initial_state, horizon=horizon)
    except WorkbenchError:  # a model the scores do not cover: nothing to draw, as for a diverging one
        return None
    predicted = np.asarray(predicted, dtype=float)
    if not np.all(np.isfinite(predicted)):
        return None
    return Prediction(shown, predicted, scores.fit, scores.R)


def _channel_units(model: Any, records: Mapping[str, Any]) -> dict[str, Any]:
    """The Bode plot's channel names and units: the model's names, with units from a record that has those channels."""
    inputs = tuple(getattr(model, "input_names", ()) or ())
    outputs = tuple(getattr(model, "output_names", ()) or ())
    for record in records.values():
        if inputs and outputs and set(inputs) <= set(record.input_names) and set(outputs) <= set(record.output_names):
            input_units = dict(zip(record.input_names, record.input_units))
            output_units = dict(zip(record.output_names, record.output_units))
            return {"input_name": inputs[0], "input_unit": input_units[inputs[0]],
                    "output_names": list(outputs), "output_units": [output_units[name] for name in outputs]}
    # A model that kept no channel names (u1, y1, ...) describes the record it has the size of, as in the time fits.
    sizes = (np.shape(model.B)[1], np.shape(model.C)[0])
    for record in records.values():
        if (record.n_u, record.n_y) == sizes:
            return {"input_name": record.input_names[0], "input_unit": record.input_units[0],
                    "output_names": list(record.output_names), "output_units": list(record.output_units)}
    return {}


#: frozen models of a scheduled family drawn in the Bode and eigenvalue figures: its lowest, middle and highest knot
_FROZEN_KNOTS = 3


def _drawn_knots(count: int) -> list[int]:
    """The knots a scheduled family is drawn at, by index: its lowest, middle and highest."""
    return sorted({0, count // 2, count - 1})[:_FROZEN_KNOTS]


def _linear_views(name: str, model: Any, schedule_unit: str | None) -> dict[str, Any]:
    """The linear models that show ``model`` in a Bode plot and an eigenvalue map, by label.

    A modal model is itself; a scheduled family the frozen models at its lowest, middle and highest
    knot; a spline model its linearisation at rest. Anything else has none.
    """
    if all(hasattr(model, m) for m in "ABCD") and not hasattr(model, "linear_model"):
        return {name: model}
    if _is_scheduled(model):
        grid = np.asarray(model.grid, dtype=float)
        picked = _drawn_knots(grid.size)
        unit = known_unit(schedule_unit)
        return {f"{name} at {model.variable} = {grid[k]:.3g}" + (f" {unit}" if unit else ""): model.model_at(grid[k])
                for k in picked}
    if hasattr(model, "linear_model"):
        return {f"{name} (at rest)": model.linear_model()}
    return {}


def _ordered_runs(runs: Mapping[str, Any], returned: str | None) -> list[tuple[str, Any, str]]:
    """The runs as ``(name, run, label)``, the returned model's first and labelled so."""
    names = sorted(runs, key=lambda name: name != returned)
    return [(name, runs[name], f"{name} (returned)" if name == returned else name) for name in names]


def _most_divergent(parameters: np.ndarray) -> np.ndarray:
    """The history of the parameter that moved most, relative to its size, over the last half of the passes."""
    half = parameters.shape[0] // 2
    change = np.abs(parameters[-1] - parameters[half]) / np.maximum(np.abs(parameters[-1]), 1e-12)
    return parameters[:, int(np.argmax(change))]


def archive_figures(archive: Any, *, window: tuple[float, float] | None = None, max_lag: int = 50) -> dict[str, Figure]:
    """Every figure the contents of an archive allow, by file stem.

    Parameters
    ----------
    archive : vehid.identification.dataio.archive.Archive
        As :func:`vehid.identification.dataio.archive.read_archive` returns it.
    window : (float, float), optional
        Time range (s) of the time-fit figures.
    max_lag : int
        Largest lag of the residual autocorrelation, in samples.

    Returns
    -------
    dict of str to Figure
        Per run: ``parameters_<run>`` (a ``parameters`` history),
        ``convergence_<run>`` (``fit_filter`` and ``trace_p``); across runs:
        ``orders`` (two or more runs with histories and models of different
        order), ``eigenvalues`` and ``bode`` (models with A, B, C, D); per
        record: ``fits_<record>`` (models that can simulate it) and
        ``residuals_<record>_<run>`` and ``residual_tests_<record>_<run>``
        (whiteness and input cross-correlation with 99 % bands);
        ``innovation_consistency_<run>`` for IEKF runs that recorded their
        NIS beside an ``identification`` record; ``handling`` where a run's
        model is scheduled on speed with a ``yaw_rate`` output
        (:func:`archive_handling`).
    """
    figures: dict[str, Figure] = {}
    runs = archive.runs
    verdict = archive_verdict(archive) or {}
    returned = (verdict.get("scoring_rule") or {}).get("returned_run")
    names = record_output_names(archive)
    for name, run in runs.items():
        history = run.history
        if "parameters" in history and len(history["parameters"]):
            names_theta, groups = _parameter_names(run.model, history["parameters"].shape[1])
            figures[_stem("parameters", name)] = plots.plot_parameter_history(
                history["parameters"], names_theta, groups=groups,
                title=f"Parameter development over the passes: {name}")
        if "fit_filter" in history and "trace_p" in history and len(history["trace_p"]):
            fit = np.atleast_2d(history["fit_filter"].T).T
            outputs = output_names_of(run.model, names, fit.shape[1])
            figures[_stem("convergence", name)] = plots.plot_convergence(
                fit, history["trace_p"], fit_continuous=history.get("fit_continuous"),
                min_eig_p=history.get("min_eig_p"), output_names=outputs,
                title=f"Explanation and convergence per pass: {name}")
        nis = history.get("nis")
        record = archive.records.get("identification")
        if nis is not None and record is not None and len(nis) and np.all(np.isfinite(nis)):
            figures[_stem("innovation_consistency", name)] = plots.plot_innovation_consistency(
                nis, nis_band(record.n_samples, record.n_y), title=f"Innovation consistency per pass: {name}")
    studied = [run for run in runs.values()
               if {"fit_filter", "trace_p", "parameters"} <= set(run.history) and run.n_pass > 1
               and getattr(getattr(run.model, "structure", None), "n", None) is not None]
    orders = [run.model.structure.n for run in studied]
    if len(studied) > 1 and len(set(orders)) == len(orders):
        studied = [run for _, run in sorted(zip(orders, studied), key=lambda pair: pair[0])]
        figures["orders"] = plots.plot_order_study(
            sorted(orders), [run.history["fit_filter"].mean(axis=1) for run in studied],
            [run.history["trace_p"] for run in studied],
            drift=[_most_divergent(run.history["parameters"]) for run in studied])
    stored = getattr(archive, "schedule", None)  # archives written before schedules were kept have none
    schedule_unit = stored.get("unit") if isinstance(stored, Mapping) else None
    views: dict[str, Any] = {}  # linear views of every run, the returned model's first
    for name, run, label in _ordered_runs(runs, returned):
        views.update(_linear_views(label, run.model, schedule_unit))
    if views:
        figures["eigenvalues"] = plots.plot_eigenvalue_map(views)
        first = next(iter(views.values()))
        n_y = np.shape(first.C)[0]
        banded = [label for label in views if label.startswith(f"{returned} ")] if returned else None
        figures["bode"] = plots.plot_bode({k: m for k, m in views.items() if np.shape(m.C)[0] == n_y},
                                          bands=banded, **_channel_units(first, archive.records))
    rule = _scoring_rule(archive)
    for record_name, record in archive.records.items():
        predictions: dict[str, np.ndarray] = {}
        scores: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        shown = None
        for name, run, label in _ordered_runs(runs, returned):
            result = _model_prediction(run.model, record, rule, _schedule_of(archive, record_name))
            if result is None or (shown is not None and result.record.output_names != shown.output_names):
                continue
            shown, predictions[label], scores[label] = result.record, result.outputs, (result.fit, result.R)
            figures[_stem("residuals", record_name, name)] = plots.plot_residual_autocorrelation(
                shown.y - result.outputs, min(max_lag, shown.n_samples - 1), shown.output_names, dt=shown.dt,
                title=f"Residual autocorrelation: {name} on {record_name}")
            if shown.n_samples > 2 * DEFAULT_LAGS:
                tests = residual_tests(shown.u, shown.y - result.outputs, input_names=shown.input_names,
                                       output_names=shown.output_names)
                figures[_stem("residual_tests", record_name, name)] = plots.plot_residual_tests(
                    tests, dt=shown.dt, title=f"Residual tests: {name} on {record_name}")
        if shown is not None:
            figures[_stem("fits", record_name)] = plots.plot_time_fits(
                shown.t, shown.y, predictions, shown.output_names, shown.output_units, window=window,
                title=f"Model fits to {record_name} ({_rule_text(rule)})", scores=scores,
                spikes=spike_indices(record, shown.t))
    curves = archive_handling(archive)
    if curves:
        figures["handling"] = handling_page(curves)
    return figures


def record_output_names(archive: Any) -> tuple[str, ...]:
    """The output channels of the archive's first record (the names a model without its own describes)."""
    record = next(iter(archive.records.values()), None)
    return tuple(record.output_names) if record is not None else ()


def output_names_of(model: Any, record_names: Sequence[str], count: int) -> list[str] | None:
    """A model's output names, else the record's where the model kept only placeholders (``y1``, ...)."""
    own = tuple(getattr(model, "output_names", None) or ())
    placeholders = tuple(f"y{i + 1}" for i in range(count))
    if len(own) == count and own != placeholders:
        return list(own)
    return list(record_names) if len(record_names) == count else None


def spike_indices(record: Any, t: np.ndarray) -> dict[str, list[int]]:
    """Per channel, the samples of ``t`` (a record's time) at the spikes its cleaning listed (``meta["cleaning"]``)."""
    report = record.meta.get("cleaning") or {}
    found: dict[str, list[int]] = {}
    if t.size < 2:
        return found
    step = float(t[1] - t[0])
    for outlier in report.get("outliers", ()):
        k = int(round((outlier["time"] - float(report.get("time_offset", 0.0)) - float(t[0])) / step))
        if 0 <= k < t.size:
            found.setdefault(outlier["channel"], []).append(k)
    return found


def _rule_text(rule: ScoringRule) -> str:
    if rule.horizon is not None:
        return f"{rule.horizon}-step-ahead prediction"
    return f"simulated, initial state {rule.initial_state}"


def archive_table(archive: Any) -> list[dict[str, Any]]:
    """One row per run: order, passes, eigenvalues, final fits and trace(P), NRMSE fit and R on each record.

    Each model is scored on each record as the identify command that wrote the
    archive scored it (its initial-state rule, :class:`ScoringRule`); the run
    whose model the command returned is marked. Columns that no run fills are left out.
    """
    verdict = archive_verdict(archive) or {}
    rule = _scoring_rule(archive)
    returned = (verdict.get("scoring_rule") or {}).get("returned_run")
    rows = []
    for name, run in archive.runs.items():
        model = run.model
        row: dict[str, Any] = {
            "run": name,
            "returned": (name == returned) if returned is not None else None,
            "n": getattr(getattr(model, "structure", None), "n", None),
            "passes": run.n_pass or _passes_run(verdict, name, returned),
            "eigenvalues": _table_eigenvalues(model),
            "R filter (%)": _mean_last(run.history, "fit_filter"),
            "R simulated (%)": _mean_last(run.history, "fit_continuous"),
            "trace(P)": _mean_last(run.history, "trace_p"),
        }
        for record_name, record in archive.records.items():
            result = _model_prediction(model, record, rule, _schedule_of(archive, record_name))
            if result is not None:
                row[f"NRMSE fit {record_name} (%)"] = float(np.mean(result.fit))
                row[f"R {record_name} (%)"] = float(np.mean(result.R))
        rows.append(row)
    empty = {key for key in (rows[0] if rows else {}) if all(row.get(key) is None for row in rows)}
    return [{key: value for key, value in row.items() if key not in empty} for row in rows]


def _table_eigenvalues(model: Any) -> list[complex] | None:
    """A run's eigenvalues for the table: a scheduled family's at its middle knot (the figures draw it at
    its lowest, middle and highest), any other model's own; None for a model without them."""
    if not hasattr(model, "eigenvalues"):
        return None
    if _is_scheduled(model):
        grid = np.asarray(model.grid, dtype=float)
        drawn = _drawn_knots(grid.size)
        return list(model.eigenvalues(schedule=float(grid[drawn[len(drawn) // 2]])))
    return list(model.eigenvalues())


def _passes_run(verdict: Mapping[str, Any], name: str, returned: str | None) -> int:
    """The passes a run without a stored history made, as the command counted them (0 where unknown)."""
    if name in ("nonlinear", "scheduled"):  # their own runs, whichever model was returned
        return int((verdict.get(name) or {}).get("passes_run") or 0)
    if name == returned and name != "start":
        return int(verdict.get("passes_run") or 0)
    return 0


def _per_output(names: Sequence[str], values: Any) -> str:
    if values is None:
        return "-"
    return ", ".join(f"{name} {value:.2f} %" if value is not None else f"{name} -"
                     for name, value in zip(names, values))


def verdict_lines(verdict: Mapping[str, Any], output_names: Sequence[str]) -> list[str]:
    """The identify command's verdict on its returned model, as the report's summary states it.

    NRMSE fit and R side by side, on estimation and on validation data, with
    how they were scored, then every warning the command gave (or that it gave none).
    """
    rule = verdict.get("scoring_rule") or {}
    how = (f"{verdict['horizon']}-step-ahead prediction" if verdict.get("horizon")
           else f"simulated, initial state {verdict.get('initial_state', 'estimate')}")
    lines = [f"model returned: {rule.get('returned_run', verdict.get('method', '-'))} "
             f"({verdict.get('method', '-')}, order {verdict.get('order', '-')}; scores {how})"
             + ("" if not verdict.get("scheduled") else f"; scheduled on {verdict['scheduled'].get('channel')}"),
             f"estimation: NRMSE fit {_per_output(output_names, verdict.get('estimation_fit_percent'))}; "
             f"R {_per_output(output_names, verdict.get('estimation_R'))}"]
    if verdict.get("validation_fit_percent") is not None:
        lines.append(f"validation: NRMSE fit {_per_output(output_names, verdict.get('validation_fit_percent'))}; "
                     f"R {_per_output(output_names, verdict.get('validation_R'))}")
    else:
        lines.append("validation: none held out")
    warnings = verdict.get("warnings") or []
    lines += [f"warning: {line}" for line in warnings] if warnings else ["warnings: none"]
    lines += [f"note: {line}" for line in verdict.get("notes") or []]
    return lines


def verdict_output_names(archive: Any, verdict: Mapping[str, Any]) -> tuple[str, ...]:
    """The returned model's output names, else the first record's channels (where the model kept only
    placeholders ``y1``, ...): what labels the verdict's per-output scores."""
    returned = archive.runs.get((verdict.get("scoring_rule") or {}).get("returned_run"))
    names = record_output_names(archive)
    count = len(verdict.get("estimation_fit_percent") or names)
    return tuple(output_names_of(getattr(returned, "model", None), names, count) or names)


_PAGE_COLUMNS = 95  # characters per line of the verdict page at 9 pt on the report's width
_PAGE_LINE_HEIGHT = 0.2  # inch per line at 9 pt


def verdict_page(lines: Sequence[str], title: str = "Verdict of the identify command") -> Figure:
    """The verdict as the report's first page: each line wrapped to the page's width, long warnings included."""
    wrapped = [part for line in lines
               for part in textwrap.wrap(line, _PAGE_COLUMNS, subsequent_indent="    ") or [""]]
    height = max(plots.REPORT_SIZE[1] / 2, 0.9 + _PAGE_LINE_HEIGHT * len(wrapped))
    fig = plots.new_figure((plots.REPORT_SIZE[0], height))
    fig.suptitle(title)
    fig.text(0.02, 1.0 - 0.6 / height, "\n".join(wrapped), va="top", ha="left", fontsize=9, linespacing=1.35)
    return fig


_HANDLING_PANELS = (
    ("yaw_rate_gain", "yaw-rate gain r/delta (1/s)", 1.0),
    ("lateral_acceleration_gain", "lateral acc. gain (m/s^2 per deg)", math.pi / 180),
    ("understeer_gradient_deg_per_g", "understeer gradient (deg/g)", 1.0),
)
_BAND_SIGMAS = 2.0  # bands of +/- 2 std: about 95 % under the delta method's normal approximation


def handling_page(curves: Mapping[str, Sequence[Any]], *, title: str = "Handling against speed") -> Figure:
    """Gains and understeer gradient against speed, one line per model, +/- 2 std bands where known.

    Parameters
    ----------
    curves : mapping of str to sequence of HandlingMetrics
        Label (``identified``, ``source model (linearisation)``, ...) to the
        metrics at each speed (:func:`vehid.vehicle.handling.handling_metrics`).
    title : str

    Returns
    -------
    Figure
        Three panels sharing the speed axis; a panel whose metric no curve has is left out.
    """
    if not curves:
        raise InputError("a handling page needs at least one model's metrics")
    panels = [panel for panel in _HANDLING_PANELS
              if any(math.isfinite(getattr(m, panel[0])) for metrics in curves.values() for m in metrics)]
    fig = plots.new_figure((plots.REPORT_SIZE[0], max(plots.REPORT_SIZE[1], 1.2 + 1.8 * len(panels))))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (name, label, factor) in zip(axes, panels):
        ax.grid(True, alpha=0.3)
        for curve, metrics in curves.items():
            ordered = sorted(metrics, key=lambda m: m.speed)
            speed = np.array([m.speed for m in ordered])
            value = np.array([getattr(m, name) for m in ordered]) * factor
            std = np.array([m.std[name] for m in ordered]) * factor
            (line,) = ax.plot(speed, value, marker="o", label=curve)
            if np.any(np.isfinite(std)):
                ax.fill_between(speed, value - _BAND_SIGMAS * std, value + _BAND_SIGMAS * std,
                                color=line.get_color(), alpha=0.2, linewidth=0)
        ax.set_ylabel(label, fontsize=9)
    axes[0].legend(fontsize=9, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    axes[-1].set_xlabel("speed (m/s)")
    fig.suptitle(f"{title} (bands: +/- {_BAND_SIGMAS:g} std)")
    return fig


def archive_handling(archive: Any) -> dict[str, tuple[Any, ...]]:
    """Handling metrics of an archive's speed-scheduled models at their grid speeds, by run.

    A run qualifies when its model offers ``model_at`` (a family scheduled on
    speed) and has an output named ``yaw_rate``; its metrics are computed with
    the wheelbase its metadata gives (``wheelbase``, m), else without the
    understeer gradient. A model they cannot be computed for is left out.
    """
    from vehid.vehicle.handling import handling_metrics

    curves = {}
    for name, run in archive.runs.items():
        model = run.model
        if not hasattr(model, "model_at") or "yaw_rate" not in tuple(getattr(model, "output_names", None) or ()):
            continue
        if str(getattr(model, "variable", "speed")).lower() not in ("speed", "vx", "v", "velocity"):
            continue
        wheelbase = (getattr(model, "meta", None) or {}).get("wheelbase")
        try:
            curves[f"{name} (identified)"] = handling_metrics(
                model, list(model.grid), wheelbase=float(wheelbase) if isinstance(wheelbase, (int, float)) else None)
        except (InputError, np.linalg.LinAlgError):
            continue
    return curves

