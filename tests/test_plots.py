"""Report figures and files: every plot function on small synthetic results, the report writer, tables."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from matplotlib.figure import Figure
from scipy import signal

from vehid.identification.errors import InputError
from vehid.identification.assessment.metrics import percentage_explanation
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios import plots
from vehid.scenarios.report import format_eigenvalues, markdown_table, write_report

RNG_SEED = 4


def _model(n=4, n_u=1, n_y=3) -> ModalModel:
    structure = ModalStructure.default(n, n_u, n_y)
    theta = structure.initial_parameters(sigma=-2.0, omega=3.0, omega_spread=2.0)
    rng = np.random.default_rng(RNG_SEED)
    theta[structure.slices()["B"]] = rng.normal(size=n * n_u)
    theta[structure.slices()["C"]] = 0.3 * rng.normal(size=structure.n_free_c)
    return ModalModel.from_parameters(structure, theta)


def _visible_axes(fig: Figure):
    return [ax for ax in fig.axes if ax.get_visible()]


def _assert_labelled(fig: Figure) -> None:
    """A title (figure or first axis), and every visible axis labelled on y; the bottom ones on x."""
    title = fig._suptitle.get_text() if fig._suptitle is not None else fig.axes[0].get_title()
    assert title.strip()
    for ax in _visible_axes(fig):
        assert ax.get_ylabel().strip()
    assert any(ax.get_xlabel().strip() for ax in _visible_axes(fig))


def _data_lines(ax):
    return ax.get_lines()


def test_parameter_history_groups_a_modal_model_by_matrix():
    model = _model()
    names = model.structure.parameter_names()
    history = model.parameters + np.linspace(1.0, 0.0, 8)[:, None]
    fig = plots.plot_parameter_history(history, names)
    assert isinstance(fig, Figure)
    _assert_labelled(fig)
    assert [ax.get_title().split(" (")[0] for ax in fig.axes] == ["modal", "B", "C", "D"]
    assert sum(len(_data_lines(ax)) for ax in fig.axes) == len(names)
    assert fig.axes[-1].get_xlabel() == "pass"


def test_parameter_history_explicit_groups_and_x_axis():
    values = np.arange(12.0).reshape(4, 3)
    fig = plots.plot_parameter_history(values, ["k", "m", "c"], groups={"stiff": [0], "rest": [1, 2]},
                                       passes=[0.5, 1.0, 1.5, 2.0], x_label="time (s)")
    assert len(fig.axes) == 2 and [len(_data_lines(ax)) for ax in fig.axes] == [1, 2]
    assert np.array_equal(fig.axes[1].get_lines()[0].get_xdata(), [0.5, 1.0, 1.5, 2.0])
    with pytest.raises(InputError, match="indexes beyond"):
        plots.plot_parameter_history(values, groups={"bad": [3]})


def test_convergence_draws_fit_and_log_trace():
    passes = 10
    fit = 100 - 20 * np.exp(-np.arange(passes))[:, None] * np.array([1.0, 2.0])
    fig = plots.plot_convergence(fit, np.logspace(2, -3, passes), fit_continuous=fit - 1,
                                 min_eig_p=np.logspace(-2, -6, passes), output_names=["a_y", "r"])
    _assert_labelled(fig)
    ax_fit, ax_trace = fig.axes
    assert len(_data_lines(ax_fit)) == 2 + 1 + 1  # two outputs, their mean, the simulated model's mean
    assert len(_data_lines(ax_trace)) == 2 and ax_trace.get_yscale() == "log"
    assert ax_fit.get_ylabel() == "R (%)"
    with pytest.raises(InputError, match="passes"):
        plots.plot_convergence(fit, np.ones(passes + 1))


def test_order_study_histories_and_final_values():
    orders = [3, 4, 5]
    fits = [np.linspace(90, 99 + k * 0.2, 6) for k in range(3)]
    traces = [np.logspace(1, -k, 6) for k in range(3)]
    fig = plots.plot_order_study(orders, fits, traces, drift=[np.arange(6.0) * k for k in range(3)])
    _assert_labelled(fig)
    assert len(fig.axes) == 3 and all(len(_data_lines(ax)) == 3 for ax in fig.axes)
    assert fig.axes[-1].get_yscale() == "log"
    final = plots.plot_order_study(orders, [97.0, 99.8, 99.9], [1e-3, 1e-5, 1e3])
    assert len(final.axes) == 2 and list(final.axes[0].get_lines()[0].get_xdata()) == orders
    assert final.axes[-1].get_xlabel() == "model order n"


def test_time_fits_one_axis_per_output_with_r_in_the_legend():
    t = np.arange(200) * 0.01
    y = np.c_[np.sin(t), np.cos(t) + 2.0]
    predictions = {"linear": 0.9 * y, "nonlinear": 0.99 * y}
    fig = plots.plot_time_fits(t, y, predictions, ["a_y", "r"], ["m/s^2", "rad/s"], window=(0.5, 1.5))
    _assert_labelled(fig)
    assert len(fig.axes) == 2 and all(len(_data_lines(ax)) == 1 + 2 for ax in fig.axes)
    assert fig.axes[0].get_ylabel() == "a_y (m/s^2)"
    expected = percentage_explanation(y, 0.9 * y)[1]
    labels = [text.get_text() for text in fig.axes[1].get_legend().get_texts()]
    assert labels[1] == f"linear (R = {expected:.2f} %)"
    shown = fig.axes[0].get_lines()[0].get_xdata()
    assert shown.min() >= 0.5 and shown.max() <= 1.5
    with pytest.raises(InputError, match="columns"):
        plots.plot_time_fits(t, y, {"bad": y[:, :1]})


def test_splines_mark_nodes_and_dash_extrapolation():
    x = np.linspace(-1.5, 1.5, 61)
    nodes = np.linspace(-1, 1, 5)
    curves = [np.tanh(x), x**2, -x]
    fig = plots.plot_splines([x] * 3, curves, [nodes] * 3, [np.tanh(nodes), nodes**2, -nodes],
                             ["sigma1", "c13", "b11"], x_labels=["x1 (-)", "x3 (-)", "u (-)"])
    _assert_labelled(fig)
    visible = _visible_axes(fig)
    assert len(fig.axes) == 4 and len(visible) == 3
    for ax in visible:
        lines = _data_lines(ax)
        assert len(lines) == 4  # inner spline, two dashed outer regions, nodes
        assert sum(line.get_linestyle() == "--" for line in lines) == 2
        assert len(lines[-1].get_xdata()) == nodes.size and lines[-1].get_marker() == "o"
    single = plots.plot_splines(x, np.tanh(x), nodes, np.tanh(nodes), "sigma1")
    assert len(single.axes) == 1


def test_eigenvalue_map_annotates_frequency_and_damping():
    model = _model()
    reference = np.array([-2.0 + 3.0j, -2.0 - 3.0j, -4.0])
    fig = plots.plot_eigenvalue_map({"identified": model, "other": reference}, reference_eigenvalues=reference)
    _assert_labelled(fig)
    (ax,) = fig.axes
    assert [text.get_text() for text in ax.get_legend().get_texts()] == ["identified", "other", "reference"]
    notes = [text.get_text() for text in ax.texts]
    # The model's two upper-half eigenvalues, the array's pair and real pole; the array's pair
    # -2 + 3j is also the model's first mode, and the same label on the same spot is drawn once.
    assert np.isclose(model.mode_eigenvalues()[0], reference[0])
    assert len(notes) == 2 + 2 - 1 and len(set(notes)) == len(notes)
    frequency = abs(model.mode_eigenvalues()[0]) / (2 * np.pi)
    assert any(note.startswith(f"{frequency:.2f} Hz") for note in notes)
    assert ax.get_xlabel() == "real part (1/s)"


def test_eigenvalue_map_draws_into_a_given_axis():
    fig = plots.new_figure()
    ax = fig.subplots(1, 2)[1]
    assert plots.plot_eigenvalue_map({"m": [-1 + 1j, -1 - 1j]}, ax=ax) is fig
    assert ax.get_lines()


def test_response_to_input_matches_scipy():
    A = np.array([[-1.0, 4.0], [-4.0, -1.0]])
    B = np.array([[1.0, 0.0], [0.5, 2.0]])
    C = np.array([[1.0, 0.0], [0.3, 1.0]])
    D = np.array([[0.3, 0.1], [0.2, -0.4]])  # no zero entry: scipy's tf conversion warns on one
    f = np.logspace(-2, 1, 30)
    for column in range(2):
        got = plots.response_to_input((A, B, C, D), f, column)
        for row in range(2):
            system = signal.StateSpace(A, B[:, [column]], C[[row]], D[[row]][:, [column]])
            _, expected = signal.freqresp(system, w=2 * np.pi * f)
            np.testing.assert_allclose(got[:, row], expected, rtol=1e-10)  # algebra, via scipy's polynomials
    model = _model()
    np.testing.assert_array_equal(plots.response_to_input(model, f),
                                  plots.response_to_input((model.A, model.B, model.C, model.D), f))
    with pytest.raises(InputError, match="input_index"):
        plots.response_to_input(model, f, 1)


def test_a_discrete_model_is_plotted_with_its_own_response():
    """At z = exp(j 2 pi f dt): periodic in 1/dt, and near the continuous system's well below it."""
    from vehid.identification.models.discrete import DiscreteModel
    from vehid.identification.models.statespace import continuous_to_discrete

    model, dt = _model(n_y=1), 0.05
    discrete = DiscreteModel(*continuous_to_discrete(model.A, model.B, model.C, model.D, dt), dt)
    f = np.array([0.02, 0.2, 2.0, 7.0])
    got = plots.response_to_input(discrete, f)
    np.testing.assert_array_equal(got, discrete.frequency_response(f)[:, :, 0])
    np.testing.assert_allclose(plots.response_to_input(discrete, f + 1 / dt), got, rtol=1e-9)
    # at f dt = 1e-3 the first-order-hold equivalent departs from the continuous response by O((2 pi f dt)^2)
    np.testing.assert_allclose(got[0], plots.response_to_input(model, f[:1])[0], rtol=(2 * np.pi * 1e-3) ** 2)
    # while at 7 Hz (f dt = 0.35) the two differ clearly: a plot evaluating the discrete model at s would be wrong
    assert abs(got[3, 0] - plots.response_to_input(model, f[3:])[0, 0]) > 0.01 * abs(got[3, 0])
    fig = plots.plot_bode({"discrete": discrete}, reference=model, frequencies=f)
    magnitude = fig.axes[0].get_lines()[0].get_ydata()
    np.testing.assert_allclose(magnitude, np.abs(got[:, 0]), rtol=1e-12)


def test_bode_magnitude_and_phase_per_output():
    model = _model()
    fig = plots.plot_bode({"identified": model}, reference=(model.A * 1.1, model.B, model.C, model.D),
                          output_units=["m/s^2", "rad/s", "rad"], input_name="steer", input_unit="rad",
                          frequencies=np.logspace(-1, 1, 40))
    _assert_labelled(fig)
    assert len(fig.axes) == 2 * 3
    assert all(len(_data_lines(ax)) == 2 for ax in fig.axes)
    assert fig.axes[0].get_yscale() == "log" and fig.axes[0].get_xscale() == "log"
    assert fig.axes[0].get_title() == "y1" and fig.axes[0].get_ylabel() == "|G| (m/s^2/rad)"
    assert fig._suptitle.get_text() == "Frequency response from steer"


def test_autocorrelation_definition_and_white_noise():
    rng = np.random.default_rng(RNG_SEED)
    e = rng.normal(size=(4000, 2))
    r = plots.autocorrelation(e, 20)
    assert r.shape == (21, 2) and np.allclose(r[0], 1.0)
    centred = e[:, 0] - e[:, 0].mean()
    assert r[3, 0] == pytest.approx(np.dot(centred[:-3], centred[3:]) / np.dot(centred, centred), rel=1e-12)
    # white noise: about 5 % of lags outside the band; 20 lags x 2 outputs, allow 8 (binomial, p < 1e-3)
    assert np.count_nonzero(np.abs(r[1:]) > 1.96 / np.sqrt(4000)) <= 8
    with pytest.raises(InputError, match="max_lag"):
        plots.autocorrelation(e, 4000)


def test_residual_autocorrelation_band():
    rng = np.random.default_rng(RNG_SEED)
    residuals = rng.normal(size=(400, 3))
    fig = plots.plot_residual_autocorrelation(residuals, 15, ["a_y", "r", "phi"], dt=0.002)
    _assert_labelled(fig)
    assert len(fig.axes) == 3 and fig.axes[-1].get_xlabel() == "lag (s)"
    band = 1.96 / np.sqrt(400)
    for ax in fig.axes:
        (patch,) = ax.patches
        extent = patch.get_path().transformed(patch.get_patch_transform()).get_extents()
        assert extent.y0 == pytest.approx(-band) and extent.y1 == pytest.approx(band)
        assert len(ax.get_lines()[0].get_xdata()) == 16


def test_plots_refuse_a_used_figure():
    fig = plots.new_figure()
    fig.subplots()
    with pytest.raises(InputError, match="empty figure"):
        plots.plot_convergence([99.0, 99.5], [1.0, 0.5], fig=fig)
    empty = plots.new_figure()
    assert plots.plot_convergence([99.0, 99.5], [1.0, 0.5], fig=empty) is empty


# ------------------------------------------------------------------ report
def _pdf_pages(path) -> int:
    # Matplotlib writes each page as an uncompressed "/Type /Page" object dictionary.
    return len(re.findall(rb"/Type\s*/Page\b(?!s)", path.read_bytes()))


def test_write_report_png_per_figure_and_one_pdf(tmp_path):
    figures = {
        "convergence": plots.plot_convergence([90.0, 99.0, 99.9], [10.0, 1.0, 0.1]),
        "eigenvalues": plots.plot_eigenvalue_map({"m": [-1 + 2j, -1 - 2j]}),
        "acf": plots.plot_residual_autocorrelation(np.random.default_rng(0).normal(size=(100, 1)), 5),
    }
    paths = write_report(figures, tmp_path / "report", dpi=50)
    assert [p.name for p in paths] == ["convergence.png", "eigenvalues.png", "acf.png", "report.pdf"]
    for path in paths[:-1]:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert paths[-1].read_bytes()[:5] == b"%PDF-"
    assert _pdf_pages(paths[-1]) == len(figures)


def test_write_report_rejects_bad_names(tmp_path):
    with pytest.raises(InputError, match="file stem"):
        write_report({"../escape": plots.new_figure()}, tmp_path)
    with pytest.raises(InputError, match="at least one"):
        write_report({}, tmp_path)


def test_markdown_table_in_the_style_of_table_5():
    rows = [
        {"n": 2, "eigenvalues": [complex(-2.3, 1.7), complex(-2.3, -1.7)], "linear": 99.60, "nonlinear": 99.73},
        {"n": 3, "eigenvalues": np.array([-9.3 + 2.5j, -9.3 - 2.5j, -3.3 + 0j]), "linear": 99.72,
         "nonlinear": None, "note": "a|b"},
    ]
    table = markdown_table(rows, headers={"linear": "linear R (%)"})
    assert table.splitlines() == [
        "| n | eigenvalues | linear R (%) | nonlinear | note |",
        "| ---: | --- | ---: | ---: | --- |",
        "| 2 | -2.3 ± 1.7j | 99.6 | 99.73 |  |",
        "| 3 | -9.3 ± 2.5j, -3.3 | 99.72 |  | a\\|b |",
    ]
    assert markdown_table(rows, ["n"]).count("\n") == 4
    assert format_eigenvalues([-1.0 + 0j]) == "-1"


def test_no_pyplot_anywhere():
    """The library modules never import pyplot, so nothing can open a window or call plt.show()."""
    script = textwrap.dedent(
        """
        import sys, tempfile
        import numpy as np
        from vehid.scenarios import plots, report
        figure = plots.plot_convergence([90.0, 99.0], [1.0, 0.1])
        report.write_report({"f": figure}, tempfile.mkdtemp(), dpi=30)
        assert "matplotlib.pyplot" not in sys.modules, "pyplot was imported"
        """
    )
    completed = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=False)
    assert completed.returncode == 0, completed.stderr


# ------------------------------------------------------------ axis ranges robust to outliers and failed candidates
def test_a_far_first_pass_leaves_the_convergence_axis_to_the_others():
    """A run whose first pass explained -80,000 % (a filter far from its start) and then settled at 90-98 %:
    the axis spans the settled passes, and the title counts the passes cut off."""
    fit = np.column_stack([np.r_[-80_000.0, np.linspace(60.0, 98.0, 19)], np.r_[-60_000.0, np.linspace(50.0, 90.0, 19)]])
    fig = plots.plot_convergence(fit, np.geomspace(1.0, 1e-3, 20), output_names=["yawRate", "ayCG"])
    low, high = fig.axes[0].get_ylim()
    assert 40.0 < low < 50.0 and 98.0 < high < 110.0  # the smallest settled value (50 %) is in view
    assert "beyond the frame" in fig.axes[0].get_title()
    labels = [text.get_text() for text in fig.axes[0].get_legend().get_texts()]
    assert "filter, yawRate" in labels and "filter, ayCG" in labels  # channel names, not y1, y2


def test_a_spike_and_a_diverging_candidate_do_not_set_the_time_fit_axis():
    """A one-sample spike of 100 times the signal and a candidate whose prediction runs off to 1e6."""
    t = np.arange(2000) * 0.01
    y = np.sin(2 * np.pi * 0.5 * t)[:, None]
    spiked = y.copy()
    spiked[700] = 100.0
    runaway = y * np.exp(t / 2.0)[:, None]  # 2e4 at the end
    fig = plots.plot_time_fits(t, spiked, {"returned": y, "failed": runaway}, ["ayCG"], ["m/s^2"])
    low, high = fig.axes[0].get_ylim()
    # the measured sine's range (one each side), widened by at most one such range for the predictions
    assert -3.5 < low < -1.0 and 1.0 < high < 3.5


def test_a_band_does_not_stretch_the_bode_axes_and_the_gain_has_a_unit():
    """A model whose covariance is huge: its band runs to zero gain and round the circle; the axes follow the curves."""
    model = _model(n=2, n_u=1, n_y=1)
    wide = model.with_parameter_covariance(1e4 * np.eye(model.parameters.size))
    frequencies = np.logspace(-1, 1, 50)
    fig = plots.plot_bode({"returned": wide}, frequencies=frequencies)
    magnitude, phase = fig.axes[0], fig.axes[1]
    response = np.abs(plots.response_to_input(model, frequencies)[:, 0])
    curve_phase = np.degrees(np.unwrap(np.angle(plots.response_to_input(model, frequencies)[:, 0])))
    low, high = magnitude.get_ylim()
    assert response.min() / 2 < low <= response.min() and response.max() <= high < 2 * response.max()
    low, high = phase.get_ylim()
    span = np.ptp(curve_phase)
    assert curve_phase.min() - 0.1 * span <= low <= curve_phase.min() and curve_phase.max() <= high
    assert high <= curve_phase.max() + 0.1 * span
    assert magnitude.get_ylabel() == "|G| (output unit/input unit)"  # units not given: said, not left out


def test_the_nodes_of_a_spline_model_are_grouped_by_matrix_with_legends():
    """A spline model's node ordinates (``sigma1[3]``): panels modal, B and D, one legend entry per coefficient."""
    coefficients = ("sigma1", "omega1", "b11", "b21", "d11")
    names = [f"{name}[{k}]" for name in coefficients for k in range(1, 6)]
    history = np.linspace(0.0, 1.0, 4)[:, None] + np.arange(len(names))[None, :]
    fig = plots.plot_parameter_history(history, names, groups=plots.parameter_groups(names))
    assert [ax.get_title() for ax in fig.axes] == ["modal (10 parameters)", "B (10 parameters)", "D (5 parameters)"]
    legends = [[text.get_text() for text in ax.get_legend().get_texts()] for ax in fig.axes]
    assert legends == [["sigma1 (nodes)", "omega1 (nodes)"], ["b11 (nodes)", "b21 (nodes)"], ["d11 (nodes)"]]
    assert sum(len(ax.get_lines()) for ax in fig.axes) == len(names)
