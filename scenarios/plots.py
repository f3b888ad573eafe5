"""Report figures: side-effect free functions from plain results to a matplotlib Figure.

Every function takes arrays, models or :class:`~identification.data.IOData`
values and an optional empty ``fig`` (or ``ax``) to draw into, and returns the
Figure. Nothing here imports ``matplotlib.pyplot`` or changes global state
(object-oriented API, Agg canvas), so the functions are safe in scripts,
tests and servers alike. The figures follow Best & Bogdanski (2017), Figures
1-5 and 7-9, plus an eigenvalue map, Bode plots and residual tests.
"""

from __future__ import annotations

import re
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

from vehid.identification.errors import InputError
from vehid.identification.assessment.metrics import percentage_explanation
from vehid.identification.assessment.residuals import autocorrelation as residual_autocorrelation
from vehid.identification.models.delta_method import frequency_response_band

# The shared style and the pole map live in their own modules; they stay part of this module's API.
from .figure_style import (  # noqa: F401
    REPORT_SIZE,
    add_legend,
    channel_label,
    display_samples,
    figure_legend,
    figure_of_size,
    known_unit,
    new_figure,
    robust_range,
    set_robust_limits,
    style_axes,
    with_unit,
)
from .pole_map import ELLIPSE_SCALE, eigenvalue_view, plot_eigenvalue_map  # noqa: F401

__all__ = [
    "REPORT_SIZE",
    "new_figure",
    "channel_label",
    "display_samples",
    "parameter_groups",
    "plot_parameter_history",
    "plot_convergence",
    "plot_order_study",
    "plot_time_fits",
    "mark_spikes",
    "plot_splines",
    "eigenvalue_view",
    "plot_eigenvalue_map",
    "response_to_input",
    "plot_bode",
    "autocorrelation",
    "plot_residual_autocorrelation",
    "plot_residual_tests",
    "plot_innovation_consistency",
]

# Axis labels of the parameter groups of a modal model (ModalStructure.parameter_names).
_GROUP_LABELS = {
    "modal": "sigma, omega (rad/s)",
    "B": "b_ij (state/(s input))",
    "C": "c_ij (output/state)",
    "D": "d_ij (output/input)",
}
_GROUP_PATTERNS = (("modal", r"(sigma|omega)\d+"), ("B", r"b\d+"), ("C", r"c\d+"), ("D", r"d\d+"))
_NODE = re.compile(r"(?P<coefficient>.+)\[(?P<node>\d+)\]")  # a spline coefficient's node ordinate: ``sigma1[3]``


def _matrix(name: str, value: Any, columns: int | None = None) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2:
        raise InputError(f"{name} must be 2-D (n_pass or N, columns); got shape {array.shape}")
    if columns is not None and array.shape[1] != columns:
        raise InputError(f"{name} has {array.shape[1]} columns; expected {columns}")
    return array


def _names(given: Sequence[str] | None, count: int, stem: str) -> list[str]:
    if given is None:
        return [f"{stem}{i + 1}" for i in range(count)]
    names = [str(name) for name in given]
    if len(names) != count:
        raise InputError(f"{len(names)} names given for {count} {stem} columns")
    return names


def _pass_axis(passes: Any, count: int) -> np.ndarray:
    if passes is None:
        return np.arange(1, count + 1)
    passes = np.asarray(passes, dtype=float).ravel()
    if passes.size != count:
        raise InputError(f"passes has {passes.size} entries for {count} rows")
    return passes


def parameter_groups(names: Sequence[str]) -> dict[str, list[int]]:
    """Indices of theta by group (``modal``, ``B``, ``C``, ``D``, ``other``) from parameter names.

    Names as :meth:`ModalStructure.parameter_names` gives them (``sigma1``,
    ``omega1``, ``b11``, ``c21``, ``d11``), or a spline coefficient's node
    ordinates (``sigma1[3]``); groups that would be empty are left out.
    """
    groups: dict[str, list[int]] = {}
    for index, name in enumerate(names):
        node = _NODE.fullmatch(name)
        base = node["coefficient"] if node else name
        group = next((g for g, pattern in _GROUP_PATTERNS if re.fullmatch(pattern, base)), "other")
        groups.setdefault(group, []).append(index)
    order = [g for g, _ in _GROUP_PATTERNS] + ["other"]
    return {g: groups[g] for g in order if g in groups}


def plot_parameter_history(
    parameters: Any,
    names: Sequence[str] | None = None,
    *,
    groups: Mapping[str, Sequence[int]] | None = None,
    passes: Any = None,
    x_label: str = "pass",
    title: str = "Parameter development over the passes",
    fig: Figure | None = None,
) -> Figure:
    """Each parameter against the pass (Best & Bogdanski 2017, Figure 1).

    Parameters
    ----------
    parameters : array_like, shape (n_pass, n_theta)
        The parameter vector at the end of each pass (or at each sample, with
        ``passes`` the times in seconds and ``x_label="time (s)"``).
    names : sequence of str, optional
        Parameter names; with a modal model's names (``sigma1``, ``b11``, ...)
        the parameters are grouped into subplots: modal, B, C, D.
    groups : mapping of str to index sequence, optional
        Explicit groups (subplot title -> indices into theta); overrides the
        grouping by name.
    passes : array_like, shape (n_pass,), optional
        x values; default 1..n_pass.

    Returns
    -------
    Figure
        One axis per group, one line per parameter; a legend where a group
        has at most 12 parameters.
    """
    values = _matrix("parameters", parameters)
    n_theta = values.shape[1]
    names = _names(names, n_theta, "theta")
    if groups is None:
        groups = parameter_groups(names) if len(names) > 1 else {"parameters": [0]}
    groups = {label: list(indices) for label, indices in groups.items() if len(indices)}
    for label, indices in groups.items():
        if min(indices) < 0 or max(indices) >= n_theta:
            raise InputError(f"group {label!r} indexes beyond the {n_theta} parameters")
    x = _pass_axis(passes, values.shape[0])
    count = len(groups)
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 1.0 + 1.9 * count)))
    axes = fig.subplots(count, 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, indices) in zip(axes, groups.items()):
        style_axes(ax)
        colours: dict[str, Any] = {}  # a spline coefficient's nodes share a colour and one legend entry
        for index in indices:
            node = _NODE.fullmatch(names[index])
            if node is None:
                ax.plot(x, values[:, index], label=names[index], linewidth=1.2)
                continue
            coefficient = node["coefficient"]
            first = coefficient not in colours
            (line,) = ax.plot(x, values[:, index], linewidth=1.2, color=colours.get(coefficient),
                              label=f"{coefficient} (nodes)" if first else None)
            colours.setdefault(coefficient, line.get_color())
        # a spline filter keeps its node ordinates in its normalised units (signals over their largest magnitude)
        ax.set_ylabel("node ordinates (normalised)" if colours else _GROUP_LABELS.get(label, "value"), fontsize=10)
        ax.set_title(f"{label} ({len(indices)} parameters)" if label in _GROUP_LABELS else label, fontsize=10)
        add_legend(ax, loc="center left", bbox_to_anchor=(1.02, 0.5), ncols=1 + len(ax.get_legend_handles_labels()[1]) // 7)
    axes[-1].set_xlabel(x_label)
    fig.suptitle(title)
    return fig


def plot_convergence(
    fit_filter: Any,
    trace_p: Any,
    *,
    fit_continuous: Any = None,
    min_eig_p: Any = None,
    passes: Any = None,
    output_names: Sequence[str] | None = None,
    title: str = "Explanation and convergence per pass",
    fig: Figure | None = None,
) -> Figure:
    """R and trace(P) per pass (Best & Bogdanski 2017, Figures 2-4).

    Parameters
    ----------
    fit_filter : array_like, shape (n_pass, n_y) or (n_pass,)
        R (eq. 17, percent) of the filter's predictions in each pass, per
        output or already averaged. With several outputs each is drawn thin
        and their mean thick.
    trace_p : array_like, shape (n_pass,)
        Trace of the parameter covariance after each pass; log scale.
    fit_continuous : array_like, shape (n_pass, n_y) or (n_pass,), optional
        R of each pass's final model simulated over the record (mean drawn dashed).
    min_eig_p : array_like, shape (n_pass,), optional
        Smallest eigenvalue of P, drawn on the trace axis.
    passes : array_like, optional
        x values; default 1..n_pass.

    Returns
    -------
    Figure
        Two axes: R (%) and trace(P) (log).
    """
    fit = _matrix("fit_filter", fit_filter)
    trace = np.asarray(trace_p, dtype=float).ravel()
    if trace.size != fit.shape[0]:
        raise InputError(f"trace_p has {trace.size} passes but fit_filter {fit.shape[0]}")
    x = _pass_axis(passes, fit.shape[0])
    fig = figure_of_size(fig, REPORT_SIZE)
    ax_fit, ax_trace = (style_axes(ax) for ax in fig.subplots(2, 1, sharex=True))
    if fit.shape[1] > 1:
        for name, column in zip(_names(output_names, fit.shape[1], "y"), fit.T):
            ax_fit.plot(x, column, linewidth=0.8, alpha=0.7, label=f"filter, {channel_label(name)}")
    ax_fit.plot(x, fit.mean(axis=1), color="k", linewidth=1.8,
                label="filter" + (" (mean)" if fit.shape[1] > 1 else ""))
    if fit_continuous is not None:
        continuous = _matrix("fit_continuous", fit_continuous)
        if continuous.shape[0] != fit.shape[0]:
            raise InputError(f"fit_continuous has {continuous.shape[0]} passes but fit_filter {fit.shape[0]}")
        ax_fit.plot(x, continuous.mean(axis=1), color="tab:red", linestyle="--", linewidth=1.8,
                    label="simulated model" + (" (mean)" if continuous.shape[1] > 1 else ""))
    # a first pass far off (R of -80,000 %) would flatten every other pass: the range leaves such passes out
    shown = [fit, continuous] if fit_continuous is not None else [fit]
    beyond = set_robust_limits(ax_fit, np.concatenate([part.ravel() for part in shown]))
    ax_fit.ticklabel_format(axis="y", useOffset=False)  # a settled fit's ticks in percent, not "+9.78e1" above them
    ax_fit.set_ylabel("R (%)")
    ax_fit.set_title("(a) percentage explanation R (eq. 17)"
                     + (f"; {beyond} value{'s' if beyond > 1 else ''} beyond the frame" if beyond else ""), fontsize=10)
    add_legend(ax_fit)
    ax_trace.semilogy(x, trace, color="tab:blue", linewidth=1.8, label="trace(P)")
    if min_eig_p is not None:
        smallest = np.asarray(min_eig_p, dtype=float).ravel()
        if smallest.size != trace.size:
            raise InputError(f"min_eig_p has {smallest.size} passes but trace_p {trace.size}")
        ax_trace.semilogy(x, smallest, color="tab:orange", linestyle="--", linewidth=1.5,
                          label="smallest eigenvalue of P")
    ax_trace.set_ylabel("parameter covariance (-)")
    ax_trace.set_xlabel("pass")
    ax_trace.set_title("(b) trace of the parameter covariance P", fontsize=10)
    add_legend(ax_trace)
    fig.suptitle(title)
    return fig


def plot_order_study(
    orders: Sequence[int],
    mean_r: Sequence[Any],
    trace_p: Sequence[Any],
    *,
    drift: Sequence[Any] | None = None,
    title: str = "Model-order study",
    fig: Figure | None = None,
) -> Figure:
    """Explanation and convergence for each model order (Best & Bogdanski 2017, Figure 5).

    Parameters
    ----------
    orders : sequence of int
    mean_r : sequence of float or of arrays (n_pass,)
        Mean R (percent) per order: final values, or the per-pass history.
    trace_p : sequence of float or of arrays (n_pass,)
        trace(P) per order, final or per pass (log scale).
    drift : sequence of float or of arrays, optional
        The most divergent parameter per order (Figure 5b), final or per pass.

    Returns
    -------
    Figure
        With histories: one line per order on each axis against the pass.
        With final values: one marker line on each axis against n.
    """
    orders = [int(n) for n in orders]
    panels = [("(a) mean percentage explanation", "mean R (%)", mean_r, False),
              ("(b) most divergent parameter", "parameter value", drift, False),
              ("(c) trace of P", "trace(P) (-)", trace_p, True)]
    panels = [panel for panel in panels if panel[2] is not None]
    for label, _, series, _ in panels:
        if len(series) != len(orders):
            raise InputError(f"{label.split(') ')[1]}: {len(series)} entries for {len(orders)} orders")
    histories = np.ndim(mean_r[0]) > 0 if len(mean_r) else False
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 1.5 + 1.8 * len(panels))))
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (label, y_label, series, log) in zip(axes, panels):
        style_axes(ax)
        if histories:
            for n, values in zip(orders, series):
                values = np.asarray(values, dtype=float).ravel()
                ax.plot(np.arange(1, values.size + 1), values, linewidth=1.4, label=f"n = {n}")
            add_legend(ax, loc="center left", bbox_to_anchor=(1.02, 0.5))
        else:
            ax.plot(orders, np.asarray(series, dtype=float), marker="o", linewidth=1.4)
            ax.set_xticks(orders)
        if log:
            ax.set_yscale("log")
        ax.set_ylabel(y_label)
        ax.set_title(label, fontsize=10)
    axes[-1].set_xlabel("pass" if histories else "model order n")
    fig.suptitle(title)
    return fig


def plot_time_fits(
    t: Any,
    y_measured: Any,
    predictions: Mapping[str, Any],
    output_names: Sequence[str] | None = None,
    units: Sequence[str] | None = None,
    *,
    window: tuple[float, float] | None = None,
    title: str = "Model fits to the data",
    fig: Figure | None = None,
    scores: Mapping[str, tuple[Any, Any]] | None = None,
    spikes: Mapping[str, Sequence[int]] | None = None,
) -> Figure:
    """Measured outputs against model predictions (Best & Bogdanski 2017, Figures 7 and 9).

    Parameters
    ----------
    t : array_like, shape (N,)
        Time (s).
    y_measured : array_like, shape (N, n_y)
    predictions : mapping of str to array_like (N, n_y)
        Label (e.g. ``"linear n=4"``, ``"nonlinear n=4"``) to predicted outputs.
    output_names, units : sequence of str, optional
        One per output, for the axis labels.
    window : (float, float), optional
        Show only this time range (s), e.g. a stretch at high lateral
        acceleration; only its samples are drawn, but R in the legend is
        always over the whole record given.
    scores : mapping of str to (array_like, array_like), optional
        Per prediction label, the NRMSE fit and R per output (percent) as the
        caller scored them (e.g. past a k-step horizon); the legend then shows
        both, labelled. Without it the legend shows R over the whole record.
    spikes : mapping of str to sequence of int, optional
        Per output name, the sample indices of its spikes and drop-outs
        (:func:`~vehid.identification.dataio.cleaning.find_outliers`): each is
        marked, and the output's axis range is set by its other samples, a
        spike beyond it drawn at the axis' edge (:func:`mark_spikes`).

    Returns
    -------
    Figure
        One axis per output holding the measurement (black) and one line per
        prediction, labelled with its R (eq. 17) for that output, the legend
        beside the axis. Long records are drawn thinned to a min/max envelope
        (:func:`display_samples`); R is computed from every sample.
    """
    t = np.asarray(t, dtype=float).ravel()
    y = _matrix("y_measured", y_measured)
    if y.shape[0] != t.size:
        raise InputError(f"y_measured has {y.shape[0]} samples but t has {t.size}")
    n_y = y.shape[1]
    names = _names(output_names, n_y, "y")
    units = _names(units, n_y, "unit") if units is not None else ["-"] * n_y
    predicted = {label: _matrix(f"prediction {label!r}", value, n_y) for label, value in predictions.items()}
    for label, value in predicted.items():
        if value.shape[0] != t.size:
            raise InputError(f"prediction {label!r} has {value.shape[0]} samples but t has {t.size}")
    fits = {label: percentage_explanation(y, value) for label, value in predicted.items()}
    shown = np.ones(t.size, dtype=bool) if window is None else (t >= window[0]) & (t <= window[1])
    if not np.any(shown):
        raise InputError(f"window {window} holds no samples of t ({t[0]:g}..{t[-1]:g} s)")
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 1.0 + 1.7 * n_y)))
    axes = fig.subplots(n_y, 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        style_axes(ax)
        ax.plot(*display_samples(t[shown], y[shown, i]), color="k", linewidth=1.6, label="measured")
        for label, value in predicted.items():
            if scores is not None and label in scores:
                fit, R = (np.ravel(np.asarray(part, dtype=float)) for part in scores[label])
                text = f"{label} (NRMSE fit = {fit[i]:.2f} %, R = {R[i]:.2f} %)"
            else:
                text = f"{label} (R = {fits[label][i]:.2f} %)"
            ax.plot(*display_samples(t[shown], value[shown, i]), linewidth=1.2, label=text)
        marked = [k for k in (spikes or {}).get(names[i], ()) if 0 <= k < t.size and shown[k]]
        clean = shown.copy()
        clean[marked] = False
        # the measurement without its listed spikes sets the range; an unlisted spike or a prediction that
        # runs away is cut at the frame, a listed spike marked where it lies or at the edge it passes
        set_robust_limits(ax, y[clean, i], extra=[value[shown, i] for value in predicted.values()])
        if marked:
            mark_spikes(ax, t, y[:, i], marked)
        ax.set_ylabel(with_unit(channel_label(names[i]), units[i]))
        add_legend(ax)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title)
    return fig


def mark_spikes(ax: Axes, t: np.ndarray, measured: np.ndarray, indices: Sequence[int]) -> None:
    """Mark a channel's spikes on its axis, whose range the other samples have set.

    A spike inside the range is ringed where it lies; one beyond it is drawn as a triangle at the edge
    it passes, pointing out, so that one glitch neither squashes the record into a line nor goes unseen.
    """
    low, high = ax.get_ylim()
    at = np.asarray(indices, dtype=int)
    spike_t, spike_y = t[at], measured[at]
    inside = (spike_y >= low) & (spike_y <= high)
    label = f"spike or drop-out ({at.size})"
    if inside.any():
        ax.plot(spike_t[inside], spike_y[inside], linestyle="none", marker="o", markersize=9, markerfacecolor="none",
                markeredgecolor="crimson", markeredgewidth=1.5, label=label)
        label = None
    for above, marker, edge in ((True, "^", high), (False, "v", low)):
        beyond = (spike_y > high) if above else (spike_y < low)
        if beyond.any():
            ax.plot(spike_t[beyond], np.full(int(beyond.sum()), edge), linestyle="none", marker=marker, markersize=9,
                    color="crimson", clip_on=False, label=label)
            label = None
    ax.set_ylim(low, high)


def plot_splines(
    x: Any,
    values: Any,
    node_x: Any,
    node_y: Any,
    labels: Sequence[str] | str,
    *,
    x_labels: Sequence[str] | str | None = None,
    title: str = "Splined coefficients",
    fig: Figure | None = None,
) -> Figure:
    """Coefficients against the variable they depend on, nodes marked (Best & Bogdanski 2017, Figure 8).

    Parameters
    ----------
    x, values : array_like (n_grid,) or sequence of them
        The evaluation grid of each spline and the coefficient's value on it.
    node_x, node_y : array_like (p,) or sequence of them
        Node positions and ordinates of each spline.
    labels : str or sequence of str
        Name of each coefficient (e.g. ``"sigma1"``), the y-axis label.
    x_labels : str or sequence of str, optional
        Name of the variable each depends on (e.g. ``"x1 (-)"``); default ``"x (-)"``.

    Returns
    -------
    Figure
        One axis per spline: solid between the outer nodes, dashed where it
        extrapolates linearly beyond them, nodes as markers.
    """
    single = np.ndim(values) == 1 and np.ndim(np.asarray(values, dtype=object)[0]) == 0
    if single:
        x, values, node_x, node_y = [x], [values], [node_x], [node_y]
    labels = [labels] if isinstance(labels, str) else list(labels)
    count = len(values)
    if not (len(x) == len(node_x) == len(node_y) == len(labels) == count):
        raise InputError("x, values, node_x, node_y and labels need one entry per spline")
    if x_labels is None or isinstance(x_labels, str):
        x_labels = [x_labels or "x (-)"] * count
    columns = 1 if count == 1 else 2 if count <= 4 else 3
    rows = -(-count // columns)
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 2.2 * rows)))
    axes = fig.subplots(rows, columns, squeeze=False).ravel()
    for i, ax in enumerate(axes):
        if i >= count:
            ax.set_visible(False)
            continue
        style_axes(ax)
        grid = np.asarray(x[i], dtype=float).ravel()
        curve = np.asarray(values[i], dtype=float).ravel()
        nodes_x = np.asarray(node_x[i], dtype=float).ravel()
        nodes_y = np.asarray(node_y[i], dtype=float).ravel()
        if grid.size != curve.size or nodes_x.size != nodes_y.size:
            raise InputError(f"spline {labels[i]!r}: x and values, node_x and node_y must match in length")
        inner = (grid >= nodes_x.min()) & (grid <= nodes_x.max())
        ax.plot(grid[inner], curve[inner], color="tab:blue", linewidth=1.6, label="spline")
        for side in (grid <= nodes_x.min(), grid >= nodes_x.max()):
            if np.count_nonzero(side) > 1:
                ax.plot(grid[side], curve[side], color="tab:blue", linestyle="--", linewidth=1.4)
        ax.plot(nodes_x, nodes_y, linestyle="none", marker="o", color="tab:red", markersize=5, label="nodes")
        ax.set_xlabel(x_labels[i])
        ax.set_ylabel(labels[i])
        ax.set_title(labels[i], fontsize=10)
    figure_legend(fig, axes[0])
    fig.suptitle(title)
    return fig


def _as_model(model: Any) -> Any:
    """``model`` itself where it offers a frequency response; an ``(A, B, C, D)`` tuple as a continuous model."""
    if hasattr(model, "frequency_response") and hasattr(model, "to_statespace"):
        return model
    from vehid.identification.models.discrete import ContinuousModel

    matrices = tuple(model) if isinstance(model, (tuple, list)) else ()
    if len(matrices) != 4:
        raise InputError("a model must meet the identified-model protocol or be an (A, B, C, D) tuple")
    A, B, C, D = (np.atleast_2d(np.asarray(m, dtype=float)) for m in matrices)
    try:
        return ContinuousModel(A, B, C, D)
    except InputError as exc:
        raise InputError(f"inconsistent state-space shapes A {A.shape}, B {B.shape}, C {C.shape}, D {D.shape}: "
                         f"{exc}") from None


def response_to_input(model: Any, frequencies_hz: Any, input_index: int = 0) -> np.ndarray:
    """The model's own frequency response from one input: column ``input_index`` of ``model.frequency_response``.

    A discrete-time model's response is its own, at ``z = exp(j 2 pi f dt)``.

    Parameters
    ----------
    model : IdentifiedModel or (A, B, C, D)
        A tuple is a continuous-time state-space model.
    frequencies_hz : array_like, shape (n_f,)
        Frequencies in Hz (``w = 2 pi f``).
    input_index : int
        The input (column of B and D).

    Returns
    -------
    ndarray of complex, shape (n_f, n_y)

    Examples
    --------
    >>> g = response_to_input(([[-1.0]], [[1.0]], [[1.0]], [[0.0]]), [1 / (2 * np.pi)])
    >>> np.round(g, 6)
    array([[0.5-0.5j]])
    """
    model = _as_model(model)
    if not 0 <= input_index < model.n_u:
        raise InputError(f"input_index {input_index} out of range for {model.n_u} inputs")
    return model.frequency_response(np.asarray(frequencies_hz, dtype=float).ravel())[:, :, input_index]


def plot_bode(
    models: Mapping[str, Any],
    *,
    reference: Any = None,
    input_index: int = 0,
    output_names: Sequence[str] | None = None,
    output_units: Sequence[str] | None = None,
    input_name: str | None = None,
    input_unit: str = "-",
    frequencies: Any = None,
    title: str | None = None,
    fig: Figure | None = None,
    confidence: bool = True,
    bands: Sequence[str] | None = None,
) -> Figure:
    """Magnitude and phase from one input to every output, for several models.

    Models that carry a parameter covariance get their 95 % band shaded
    (delta method, :func:`vehid.identification.models.delta_method.frequency_response_band`)
    unless ``confidence`` is False; with ``bands``, only the models of those labels. The curves set
    each axis's range, all of them (:func:`~vehid.scenarios.figure_style.set_robust_limits`): a band that
    runs to nothing or round the circle is cut at the frame.

    Parameters
    ----------
    models : mapping of str to ModalModel or (A, B, C, D)
    reference : ModalModel or (A, B, C, D), optional
        E.g. the linearised source model; drawn black dashed.
    output_names, output_units : sequence of str, optional
        Default: the first model's output names; units unknown (``-``).
    input_name, input_unit : str, optional
        For the title and the magnitude's unit; default the first model's
        name of input ``input_index``, unit unknown. A unit that is unknown
        (``-``) is left out of the labels rather than printed as ``(-)``.
    frequencies : array_like, optional
        In Hz; default 200 points from 0.05 to 25 Hz, log-spaced.

    Returns
    -------
    Figure
        Two rows (magnitude, log-log; phase in degrees, unwrapped), one column per output.
    """
    frequencies = np.logspace(np.log10(0.05), np.log10(25.0), 200) if frequencies is None else \
        np.asarray(frequencies, dtype=float).ravel()
    if frequencies.size < 2 or np.any(frequencies <= 0):
        raise InputError("frequencies must hold at least two positive values (Hz)")
    curves = {label: response_to_input(model, frequencies, input_index) for label, model in models.items()}
    if reference is not None:
        curves["reference"] = response_to_input(reference, frequencies, input_index)
    if not curves:
        raise InputError("give at least one model to plot")
    n_y = next(iter(curves.values())).shape[1]
    if any(g.shape[1] != n_y for g in curves.values()):
        raise InputError("all models must have the same number of outputs")
    shaded = {label: frequency_response_band(model, frequencies) for label, model in models.items()
              if confidence and getattr(model, "parameter_covariance", None) is not None
              and (bands is None or label in bands)}
    if output_names is None:
        first = next(iter(models.values()), None)
        output_names = getattr(first, "output_names", None)
    names = _names(output_names, n_y, "y")
    units = _names(output_units, n_y, "unit") if output_units is not None else ["-"] * n_y
    if input_name is None:
        known = getattr(next(iter(models.values()), None), "input_names", None)
        input_name = known[input_index] if known is not None and len(known) > input_index else f"u{input_index + 1}"
    fig = figure_of_size(fig, (max(REPORT_SIZE[0], 2.6 * n_y), REPORT_SIZE[1]))
    axes = fig.subplots(2, n_y, sharex=True, squeeze=False)
    for i in range(n_y):
        ax_mag, ax_phase = style_axes(axes[0, i]), style_axes(axes[1, i])
        phases = []
        for label, g in curves.items():
            style = {"color": "k", "linestyle": "--"} if label == "reference" else {}
            lines = ax_mag.loglog(frequencies, np.abs(g[:, i]), linewidth=1.4, label=label, **style)
            phase = np.degrees(np.unwrap(np.angle(g[:, i])))
            phases.append(phase)
            ax_phase.semilogx(frequencies, phase, linewidth=1.4, **style)
            if label in shaded:
                band = shaded[label]
                lower, upper = (edge[:, i, input_index] for edge in band.magnitude_band())
                ax_mag.fill_between(frequencies, lower, upper, color=lines[0].get_color(), alpha=0.2, linewidth=0)
                spread = band.normal_quantile() * band.phase_deg_std[:, i, input_index]
                ax_phase.fill_between(frequencies, phase - spread, phase + spread, color=lines[0].get_color(),
                                      alpha=0.2, linewidth=0)
        # the curves set the ranges; a band that runs to nothing or round the circle is cut at the frame
        set_robust_limits(ax_mag, [np.abs(g[:, i]) for g in curves.values()], log=True, outliers=False)
        set_robust_limits(ax_phase, phases, outliers=False)
        _log_ticks(ax_mag)
        ax_mag.set_title(channel_label(names[i]), fontsize=10)
        ax_mag.set_ylabel(_gain_label(units[i], input_unit))
        ax_phase.set_ylabel("phase (deg)")
        ax_phase.set_xlabel("frequency (Hz)")
    figure_legend(fig, axes[0, 0])
    fig.suptitle(title or f"Frequency response from {channel_label(input_name)}")
    return fig


def _log_ticks(ax: Axes) -> None:
    """Tick labels on a log y axis that never collide: powers of ten, or 1-2-5 steps where less than two decades show.

    Matplotlib labels the minor ticks of a short log axis (3e-1, 4e-1, ...),
    which run into each other on a narrow panel.
    """
    low, high = ax.get_ylim()
    if low > 0 and np.log10(high / low) < 2.0:
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _gain_label(output_unit: str, input_unit: str) -> str:
    """``|G| (out/in)``, saying so where a unit is unknown instead of printing ``(-/-)``."""
    output_unit, input_unit = known_unit(output_unit), known_unit(input_unit)
    if not (output_unit or input_unit):
        return "|G| (output unit/input unit)"
    if not input_unit:
        return f"|G| ({output_unit} per input unit)"
    return f"|G| ({output_unit or 'output unit'}/{input_unit})"


def autocorrelation(residuals: Any, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation of each residual column at lags 0..max_lag, shape (max_lag + 1, n_y).

    See :func:`vehid.identification.assessment.residuals.autocorrelation`.
    """
    return residual_autocorrelation(_matrix("residuals", residuals), max_lag)


def plot_residual_autocorrelation(
    residuals: Any,
    max_lag: int = 50,
    output_names: Sequence[str] | None = None,
    *,
    dt: float | None = None,
    title: str = "Residual autocorrelation",
    fig: Figure | None = None,
) -> Figure:
    """Autocorrelation of each output's residual with the 95 % band of white noise, +-1.96/sqrt(N).

    Parameters
    ----------
    residuals : array_like, shape (N, n_y)
        Measured minus predicted outputs.
    max_lag : int
        Largest lag in samples.
    dt : float, optional
        Sample interval (s); the lag axis is then in seconds.

    Returns
    -------
    Figure
        One axis per output: the autocorrelation as stems and the band shaded.
    """
    r = autocorrelation(residuals, max_lag)
    n_samples, n_y = _matrix("residuals", residuals).shape
    names = _names(output_names, n_y, "y")
    band = 1.96 / np.sqrt(n_samples)
    lags = np.arange(max_lag + 1) * (dt if dt else 1.0)
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 1.0 + 1.6 * n_y)))
    axes = fig.subplots(n_y, 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        style_axes(ax)
        ax.axhspan(-band, band, color="tab:blue", alpha=0.15, label=f"95 % band (\u00b1{band:.3f})")
        ax.vlines(lags, 0.0, r[:, i], color="k", linewidth=1.2)
        ax.plot(lags, r[:, i], linestyle="none", marker="o", markersize=3, color="k", label="autocorrelation")
        outside = np.count_nonzero(np.abs(r[1:, i]) > band)
        ax.set_ylabel("autocorrelation (-)")
        ax.set_title(f"{channel_label(names[i])}: {outside} of {max_lag} lags outside the band", fontsize=10)
    figure_legend(fig, axes[0])
    axes[-1].set_xlabel("lag (s)" if dt else "lag (samples)")
    fig.suptitle(title)
    return fig


def plot_residual_tests(tests: Any, *, dt: float | None = None, title: str = "Residual tests",
                        fig: Figure | None = None) -> Figure:
    """The residual-test page: per output, the autocorrelation and the input cross-correlations with their band.

    Parameters
    ----------
    tests : vehid.identification.assessment.residuals.ResidualTests
    dt : float, optional
        Sample interval (s): lags in seconds.

    Returns
    -------
    Figure
        One row per output: left the autocorrelation at lags 1..L with the
        Ljung-Box p-value, right each input's cross-correlation at lags
        -L..L with the largest magnitude; the band ``+/- z / sqrt(N)`` at the
        tests' level shaded.
    """
    n_y = len(tests.output_names)
    scale = dt if dt else 1.0
    fig = figure_of_size(fig, (REPORT_SIZE[0], max(REPORT_SIZE[1], 1.2 + 1.9 * n_y)))
    axes = fig.subplots(n_y, 2, squeeze=False)
    band = tests.bound
    level = f"{100 * tests.level:g} %"
    lags = np.arange(-tests.lags, tests.lags + 1) * scale
    # What each column shows is said once, above it; each panel's own title
    # keeps to its verdict, so that two titles side by side fit their columns.
    axes[0, 0].annotate("autocorrelation (Ljung-Box)", (0.5, 1.0), xycoords="axes fraction",
                        xytext=(0, 18), textcoords="offset points", ha="center", va="bottom", fontsize=10)
    axes[0, 1].annotate("cross-correlation with the inputs", (0.5, 1.0), xycoords="axes fraction",
                        xytext=(0, 18), textcoords="offset points", ha="center", va="bottom", fontsize=10)
    for i, name in enumerate(tests.output_names):
        left, right = style_axes(axes[i, 0]), style_axes(axes[i, 1])
        for ax in (left, right):
            ax.axhspan(-band, band, color="tab:blue", alpha=0.15)
        auto = tests.autocorrelation[1:, i]
        left.vlines(np.arange(1, tests.lags + 1) * scale, 0.0, auto, color="k", linewidth=1.2)
        verdict = "white" if tests.white[i] else "NOT white"
        left.set_title(f"p = {tests.residual_whiteness_p[i]:.3g}: {verdict}", fontsize=9)
        left.set_ylabel(channel_label(name), fontsize=9)
        for j, input_name in enumerate(tests.input_names):
            right.plot(lags, tests.cross_correlation[:, j, i], marker="o", markersize=2, linewidth=0.8,
                       label=channel_label(input_name))
        independent = "independent" if tests.independent[i] else "NOT independent"
        right.set_title(f"p = {tests.input_correlation_p[i]:.3g}: {independent}", fontsize=9)
        if len(tests.input_names) > 1 and i == 0:
            add_legend(right, fontsize=7)
    for ax in axes[-1]:
        ax.set_xlabel("lag (s)" if dt else "lag (samples)")
    fig.suptitle(f"{title} ({level} bands, N = {tests.samples})")
    return fig


def plot_innovation_consistency(nis: Any, band: tuple[float, float], *, title: str = "Innovation consistency",
                                fig: Figure | None = None) -> Figure:
    """The IEKF's mean normalised innovation squared per pass against the band of a consistent filter.

    Parameters
    ----------
    nis : array_like, shape (n_pass,)
        Mean ``e' R^-1 e`` of each pass.
    band : (float, float)
        :func:`vehid.identification.assessment.residuals.nis_band` for the record.

    Returns
    -------
    Figure
        Above the band the filter's R is too small for the data, below it too large.
    """
    nis = np.asarray(nis, dtype=float).ravel()
    fig = figure_of_size(fig, REPORT_SIZE)
    ax = style_axes(fig.subplots())
    passes = np.arange(1, nis.size + 1)
    ax.axhspan(band[0], band[1], color="tab:green", alpha=0.2, label="99 % band of a consistent filter")
    ax.semilogy(passes, nis, marker="o", color="k", label="mean NIS")
    ax.set_xlabel("pass")
    ax.set_ylabel("mean e' R^-1 e (-)")
    ax.set_title(title)
    add_legend(ax)
    return fig
