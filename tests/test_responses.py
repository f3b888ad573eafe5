"""Response objects: what simulations, frequency responses and handling metrics return, and what they draw.

Truth is closed form: a first-order lag ``1 / (tau s + 1)`` (its step response ``1 - exp(-t / tau)``, its gain
``1 / sqrt(1 + (omega tau)^2)`` and phase ``-atan(omega tau)``), three such lags in series (whose unwrapped
phase runs past -180 degrees to -270), and the textbook bicycle's steady yaw-rate gain ``V / (L + K V^2)``.
The figures are checked by the data their lines hold, which must be the response's own, and by being drawn
without pyplot (no window, no global figure).
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from vehid.identification import (ContinuousModel, DiscreteModel, FrequencyResponse, IOData, TimeResponse, read_value,
                                  write_value)
from vehid.identification.errors import InputError
from vehid.vehicle.handling import HandlingResponse, handling_metrics

TAU = 0.5  # [s] the lag's time constant
DT = 0.01


def _lag(gain: float = 1.0) -> ContinuousModel:
    return ContinuousModel([[-1.0 / TAU]], [[gain / TAU]], [[1.0]], [[0.0]], input_names=("u",),
                           output_names=("y",))


def _step_record(n: int = 300) -> IOData:
    t = np.arange(n) * DT
    measured = 1.0 - np.exp(-t / TAU)  # the lag's own step response, sampled
    return IOData(t=t, u=np.ones((n, 1)), y=measured[:, None], input_names=("u",), output_names=("y",),
                  input_units=("V",), output_units=("m",))


def _no_pyplot_figures() -> bool:
    """Nothing registered with pyplot (where pyplot was ever imported)."""
    import sys

    return "matplotlib.pyplot" not in sys.modules or not sys.modules["matplotlib.pyplot"].get_fignums()


def test_a_simulation_is_a_record_with_the_measurement_it_answers(tmp_path):
    record = _step_record()
    response = _lag().simulate(record)
    assert isinstance(response, TimeResponse) and isinstance(response, IOData)
    # foh is exact for a constant input: the simulated step is the closed form to rounding
    np.testing.assert_allclose(response.y[:, 0], 1.0 - np.exp(-record.t / TAU), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(response.measured, record.y)
    np.testing.assert_allclose(response.residuals, record.y - response.y, rtol=0, atol=0)
    assert response.output_units == ("m",) and response.input_units == ("V",)
    part = response[100:200]  # the measurement is sliced with the rest
    np.testing.assert_array_equal(part.measured, record.y[100:200])
    np.testing.assert_array_equal(part.t, record.t[100:200])
    with h5py.File(tmp_path / "response.h5", "w") as handle:
        write_value(handle, "response", response)
    with h5py.File(tmp_path / "response.h5", "r") as handle:
        back = read_value(handle, "response")
    assert type(back) is TimeResponse
    np.testing.assert_array_equal(back.measured, response.measured)
    np.testing.assert_array_equal(back.y, response.y)
    with pytest.raises(InputError, match="measured outputs have shape"):
        response.replace(measured=np.zeros((3, 1)))


def test_a_time_response_draws_its_own_data_without_pyplot():
    record = _step_record()
    response = _lag().simulate(record)
    fig = response.plot(label="lag")
    assert isinstance(fig, Figure) and isinstance(fig.canvas, FigureCanvasAgg) and len(fig.axes) == 1
    measured, simulated = fig.axes[0].get_lines()
    np.testing.assert_array_equal(measured.get_ydata(), record.y[:, 0])
    np.testing.assert_array_equal(simulated.get_ydata(), response.y[:, 0])
    assert simulated.get_label() == "lag" and fig.axes[0].get_ylabel() == "y (m)"
    # onto given axes: a second model beside the first, on the same figure
    twice = _lag(gain=2.0).simulate(record).plot(ax=fig.axes[0], label="twice", measured=False)
    assert twice is fig and len(fig.axes[0].get_lines()) == 3
    np.testing.assert_allclose(fig.axes[0].get_lines()[-1].get_ydata(), 2.0 * response.y[:, 0], rtol=1e-12)
    with pytest.raises(InputError, match="one matplotlib Axes or 1"):
        response.plot(ax=[fig.axes[0], fig.axes[0]])
    assert _no_pyplot_figures()


def test_a_frequency_response_is_the_closed_form_and_converts_like_the_array():
    f_hz = np.array([0.0, 1.0 / (2 * np.pi * TAU), 10.0])
    response = _lag().frequency_response(f_hz)
    assert isinstance(response, FrequencyResponse) and response.shape == (3, 1, 1) and len(response) == 3
    omega_tau = 2 * np.pi * f_hz * TAU
    np.testing.assert_allclose(response.magnitude[:, 0, 0], 1 / np.sqrt(1 + omega_tau**2), rtol=1e-12)
    np.testing.assert_allclose(response.phase_deg[:, 0, 0], -np.degrees(np.arctan(omega_tau)), rtol=0, atol=1e-10)
    np.testing.assert_allclose(response.omega, 2 * np.pi * f_hz, rtol=0, atol=0)
    exact = 1 / (1j * omega_tau + 1)
    np.testing.assert_allclose(np.asarray(response)[:, 0, 0], exact, rtol=1e-12)  # what it replaced
    np.testing.assert_allclose(response[:, 0, 0], exact, rtol=1e-12)
    np.testing.assert_allclose(np.abs(response - exact[:, None, None]), 0.0, atol=1e-12)
    assert response.input_names == ("u",) and response.output_names == ("y",)


def test_the_phase_is_unwrapped_past_a_half_turn():
    """Three lags in series: the phase falls through -180 degrees towards -270, continuously."""
    A = np.array([[-2.0, 0.0, 0.0], [2.0, -2.0, 0.0], [0.0, 2.0, -2.0]])  # each 1 / (TAU s + 1)
    series = ContinuousModel(A, [[2.0], [0.0], [0.0]], [[0.0, 0.0, 1.0]], [[0.0]])
    f_hz = np.logspace(-2, 1.5, 80)
    phase = series.frequency_response(f_hz).phase_deg[:, 0, 0]
    np.testing.assert_allclose(phase, -3 * np.degrees(np.arctan(2 * np.pi * f_hz * TAU)), rtol=0, atol=1e-9)
    assert phase[-1] < -260.0  # past the half turn that wrapping would fold back to +90


def test_a_bode_plot_draws_magnitude_and_phase_and_marks_a_discrete_model_s_nyquist_frequency():
    f_hz = np.logspace(-1, 1.5, 40)
    response = _lag().frequency_response(f_hz)
    fig = response.plot(label="lag")
    top, bottom = fig.axes
    np.testing.assert_array_equal(top.get_lines()[0].get_ydata(), response.magnitude[:, 0, 0])
    np.testing.assert_array_equal(bottom.get_lines()[0].get_ydata(), response.phase_deg[:, 0, 0])
    assert top.get_xscale() == "log" and top.get_yscale() == "log"
    held = DiscreteModel([[math.exp(-DT / TAU)]], [[1.0 - math.exp(-DT / TAU)]], [[1.0]], [[0.0]], DT)
    discrete = held.frequency_response(f_hz)
    assert discrete.dt == DT
    fig = discrete.plot()
    marks = [line for line in fig.axes[0].get_lines() if np.all(np.asarray(line.get_xdata()) == 0.5 / DT)]
    assert marks, "a discrete model's response shows its Nyquist frequency"
    with pytest.raises(InputError, match="two positive frequencies"):
        _lag().frequency_response([0.0, 1.0]).plot()
    with pytest.raises(InputError, match=r"\(n_f, n_y, n_u\)"):
        FrequencyResponse(f_hz, np.zeros((3, 1, 1)))
    assert _no_pyplot_figures()


def test_handling_metrics_return_a_response_that_unpacks_like_the_tuple_it_was():
    # the textbook bicycle at 20 m/s: m 1500 kg, l_f 1.2 m, l_r 1.5 m, C_f 80 kN/rad, C_r 100 kN/rad, I_z 2500 kg m^2
    speed, wheelbase = 20.0, 2.7
    understeer = 1500.0 / wheelbase * (1.5 / 80e3 - 1.2 / 100e3)  # K (rad per m/s^2)
    bicycle = ContinuousModel([[-6.0, -18.2], [1.08, -6.804]], [[80e3 / 1500], [1.2 * 80e3 / 2500]],
                              [[0.0, 1.0], [-6.0, 1.8]], [[0.0], [80e3 / 1500]], input_names=("steer",),
                              output_names=("yaw_rate", "lateral_acceleration"))
    response = handling_metrics(bicycle, speed, wheelbase=wheelbase)
    assert isinstance(response, HandlingResponse)
    (at_speed,) = response  # unpacks as the tuple it replaced
    assert response[0] is at_speed and len(response) == 1 and list(response) == [at_speed]
    np.testing.assert_allclose(response.value("yaw_rate_gain"), speed / (wheelbase + understeer * speed**2), rtol=1e-9)
    np.testing.assert_allclose(response.value("understeer_gradient_deg_per_g"),
                               understeer * 9.81 * 180 / math.pi, rtol=1e-9)
    assert np.isnan(response.std("yaw_rate_gain")).all()  # no parameter covariance, no spread
    fig = response.plot(label="bicycle")
    assert [axis.get_ylabel() for axis in fig.axes] == ["yaw rate gain (1/s)", "lateral acceleration gain (m/s^2/rad)",
                                                         "understeer gradient (deg/g)"]
    np.testing.assert_allclose(fig.axes[0].get_lines()[0].get_ydata(), response.value("yaw_rate_gain"), rtol=0)
    with pytest.raises(InputError, match="unknown handling metric 'grip'"):
        response.value("grip")
    assert response.as_dict() == [at_speed.as_dict()]
    assert _no_pyplot_figures()


def test_the_figures_are_drawn_without_pyplot():
    """The modules that draw the responses import no pyplot (a Figure on its own canvas: no window, no global state)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for module in ("identification/models/responses.py", "vehicle/handling_figure.py"):
        tree = ast.parse((root / module).read_text(encoding="utf-8"))
        imported = [alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names]
        imported += [f"{node.module}.{alias.name}" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                     for alias in node.names]
        assert "matplotlib" in " ".join(imported), module  # the search sees the module's imports
        assert not [name for name in imported if "pyplot" in name], module
