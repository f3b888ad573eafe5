"""The spline-nonlinear modal model and IEKF (Best & Bogdanski 2017, section 5).

Independent truth: the linear model (which the nonlinear one must equal when
every spline is constant), the linear filter (which the nonlinear filter must
reduce to when the node ordinates of each coefficient move together), and a
known spline-nonlinear system whose splines the filter must recover.
"""

import casadi as ca
import numpy as np
import pytest

from vehid.identification import IEKFOptions, IOData, ModalModel, ModalStructure, identify_iekf
from vehid.identification.errors import InputError
from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_pass import compiled_pass, pack_covariance
from vehid.identification.filtering.spline_iekf import SplineIEKFOptions, identify_spline_iekf
from vehid.identification.models.spline_modal import SplineModalFilterModel, SplineModalModel, SplineModalStructure
from vehid.scenarios.linear_example import make_data, true_model

DT = 0.002


def test_constant_splines_equal_the_linear_model():
    # every node at the linear value: the same model, to rounding (1e-12 of the signal)
    linear = true_model()
    data, _ = make_data(0, duration=6.0)
    model = SplineModalModel.from_linear(linear, 5, np.abs(data.u).max(0), np.abs(data.y).max(0), DT)
    y = model.simulate_outputs(data.u)
    assert np.max(np.abs(y - linear.simulate_outputs(data.u, DT))) < 1e-12 * np.max(np.abs(y))
    back = model.linear_model()
    for name in "ABCD":
        assert np.allclose(getattr(back, name), getattr(linear, name), rtol=0, atol=1e-12)
    pair = [model.modes(amplitude=amplitude)[0] for amplitude in (0.0, 0.5, 2.0)]
    assert np.allclose([mode.frequency_hz for mode in pair], np.hypot(15, 10) / (2 * np.pi))
    assert np.allclose([mode.damping for mode in pair], 15 / np.hypot(15, 10))


def _small_linear_system():
    """A pair and a real pole, one input, two outputs: small enough to compile its spline filter quickly."""
    structure = ModalStructure.default(3, 1, 2)
    theta = np.array([-5.0, 9.0, -2.0, 1.0, -0.5, 0.8, 0.4, 0.3, -0.2, 0.1, 0.05])
    return ModalModel.from_parameters(structure, theta)


def test_constant_splines_reduce_the_filter_to_the_linear_filter():
    """With the ordinates of each coefficient fully correlated in P (P_lin kron 1 1') and no process
    noise, every ordinate of a coefficient gets the linear filter's update: the passes agree to 1e-10."""
    linear = _small_linear_system()
    structure = linear.structure
    rng = np.random.default_rng(3)
    u = np.interp(np.arange(1500) / 10, np.arange(151), rng.standard_normal(151))[:, None]
    y = linear.simulate_outputs(u, DT)
    spline = SplineModalStructure(structure, 4)
    theta = linear.parameters + 0.05  # off the truth, so that the filter moves the parameters
    n, k, p = structure.n, structure.n_parameters, spline.nodes
    ranges = spline.default_ranges() * 3.0
    linear_pass = compiled_pass(LinearModalFilterModel(structure), DT, "exact", "joseph")
    spline_pass = compiled_pass(SplineModalFilterModel(spline), DT, "exact", "joseph")
    P_theta = 0.5 * np.eye(k)
    P_linear = np.zeros((n + k, n + k))
    P_linear[n:, n:] = P_theta
    P_spline = np.zeros((n + k * p, n + k * p))
    P_spline[n:, n:] = np.kron(P_theta, np.ones((p, p)))
    R = np.eye(2)
    lin_state, lin_innovations = linear_pass(
        np.concatenate([np.zeros(n), theta, pack_covariance(P_linear)]), u, y, np.zeros(n + k), R)
    spl_state, spl_innovations = spline_pass(
        np.concatenate([np.zeros(n), np.repeat(theta, p), pack_covariance(P_spline)]), u, y,
        np.zeros(n + k * p), R, spline.constants(ranges))
    assert np.max(np.abs(lin_innovations - spl_innovations)) < 1e-10 * np.max(np.abs(y))
    ordinates = spl_state[n:n + k * p].reshape(k, p)
    assert np.allclose(ordinates, lin_state[n:n + k][:, None], rtol=0, atol=1e-10)
    assert not np.allclose(lin_state[n:n + k], theta)  # the parameters did move


def _true_nonlinear_system():
    """A single pair whose damping and frequency fall with amplitude (the handling finding), one input, one output."""
    structure = SplineModalStructure(ModalStructure.default(2, 1, 1), 5)
    linear = ModalModel.from_parameters(structure.linear, [-6.0, 12.0, 4.0, -2.0, 0.3])
    model = SplineModalModel.from_linear(linear, 5, np.ones(1), np.ones(1), DT, ranges=np.array([[0.0, 1.0], [-1, 1], [-1, 1], [-1, 1]]))
    gammas = structure.gammas(model.theta).copy()
    gammas[0] = [-6.0, -5.2, -4.5, -4.1, -4.0]  # sigma(amplitude), flattening so that it stays stable beyond
    gammas[1] = [12.0, 11.2, 10.5, 10.1, 10.0]  # omega(amplitude)
    return model.with_parameters(gammas.ravel())


def test_recovers_a_known_spline_nonlinear_system():
    truth = _true_nonlinear_system()
    rng = np.random.default_rng(11)
    n = 10_000
    coarse = rng.standard_normal(n // 10 + 1)
    u = np.interp(np.arange(n) / 10, np.arange(coarse.size), coarse)[:, None] * 5.0
    y = truth.simulate_outputs(u)
    data = IOData(t=np.arange(n) * DT, u=u, y=y)
    linear = identify_iekf(data, truth.structure.linear, options=IEKFOptions(passes=30, p=0.1)).model
    result = identify_spline_iekf(data, linear, options=SplineIEKFOptions(nodes=5, p=1e-3, passes=25, fit_tolerance=0))
    # the nonlinear model must leave at most a tenth of the linear start's unexplained energy
    assert 100 - result.fit_percent[0] < 0.1 * (100 - result.start_fit[0])
    # sigma and omega as functions of amplitude where the data lie densely (10th to 90th percentile),
    # compared in the true model's state units (the identified model's states are scaled by max |y|):
    # within 5 % of the true variation plus 2 % of the value (a stated, measured tolerance)
    _, states = truth.simulate_outputs(u, return_states=True)
    amplitude = np.hypot(states[:, 0], states[:, 1])
    grid = np.linspace(*np.percentile(amplitude, [10, 90]), 9)
    scale = result.model.state_scale()[0]
    for name in ("sigma1", "omega1"):
        expected = truth.coefficient(name, grid)
        assert np.ptp(expected) > 1.0  # the data do reach the nonlinear part
        found = result.model.coefficient(name, grid / scale)
        assert np.max(np.abs(found - expected)) < 0.05 * np.ptp(expected) + 0.02 * np.max(np.abs(expected)), name


def test_export_as_a_casadi_function_simulates_the_same(tmp_path):
    truth = _true_nonlinear_system()
    u = np.sin(np.linspace(0, 20, 800))[:, None]
    function = truth.to_casadi(n_samples=u.shape[0])
    path = tmp_path / "model.casadi"
    function.save(str(path))
    loaded = ca.Function.load(str(path))
    y = np.asarray(loaded(u.T)).T
    assert np.max(np.abs(y - truth.simulate_outputs(u))) < 1e-12


def test_spline_tables_and_bad_input():
    truth = _true_nonlinear_system()
    tables = truth.spline_tables()
    assert tables["sigma1"]["variable"] == "amplitude1"
    assert np.allclose(tables["sigma1"]["values"], [-6.0, -5.2, -4.5, -4.1, -4.0])
    assert tables["b11"]["variable"] == "u1" and np.allclose(tables["b11"]["nodes"], np.linspace(-1, 1, 5))
    with pytest.raises(InputError, match="'nodes' must be a whole number"):
        SplineIEKFOptions(nodes=2)
    with pytest.raises(InputError, match="identified at dt"):
        truth.simulate_outputs(np.zeros((10, 1)), 0.01)
    with pytest.raises(InputError, match="u must have shape"):
        truth.simulate_outputs(np.zeros((10, 2)))
