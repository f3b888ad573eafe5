"""The grey-box IEKF on models that are not vehicles: recovery, the scheduling signal, errors.

Truth comes from closed-form discretisations of linear systems (the matrix exponential of the
first-order-hold augmented system), not from the estimator's own Runge-Kutta step.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import scipy.linalg

from vehid.identification.data import IOData
from vehid.identification.errors import DivergenceError, InputError
from vehid.identification.filtering.greybox import GreyBoxOptions, identify_greybox
from vehid.identification.filtering.greybox_structure import GreyBoxModel, simulate_greybox
from vehid.identification.filtering.greybox_model import IdentifiedGreyBox


def _scheduled_first_order() -> GreyBoxModel:
    """dx/dt = -x / tau + b s u, y = x: a time constant and a gain scaled by a measured signal s."""
    x, u, theta, s = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("theta", 2), ca.SX.sym("s")
    rate = -x / theta[0] + theta[1] * s * u
    names = ["x", "u", "theta", "s"]
    return GreyBoxModel(
        dynamics=ca.Function("lag_dynamics", [x, u, theta, s], [rate], names, ["xdot"]),
        output=ca.Function("lag_output", [x, u, theta, s], [x], names, ["y"]),
        parameter_names=("time_constant", "gain"), parameter_units=("s", "-"), positive=(True, False),
        state_names=("x",), input_names=("u",), schedule_names=("s",), output_names=("y",),
    )


def _exact_first_order(tau: float, gain: float, u: np.ndarray, s: np.ndarray, dt: float) -> np.ndarray:
    """The lag driven by b s u, with s u linear between samples: exact per sample (augmented exponential)."""
    drive = gain * s * u
    A = np.array([[-1.0 / tau, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]) * dt
    Phi = scipy.linalg.expm(A)
    x = np.zeros(u.size)
    for k in range(u.size - 1):
        slope = (drive[k + 1] - drive[k]) / dt
        x[k + 1] = (Phi @ np.array([x[k], drive[k], slope]))[0]
    return x


@pytest.fixture(scope="module")
def lag_record():
    rng = np.random.default_rng(3)
    dt, n = 0.01, 4000
    t = dt * np.arange(n)
    u = np.convolve(rng.standard_normal(n), np.ones(20) / 20, mode="same")
    s = 1.0 + 0.5 * np.sin(2 * np.pi * t / t[-1])  # the gain's scheduling signal, from 0.5 to 1.5
    y = _exact_first_order(0.4, -2.0, u, s, dt)
    noise = 0.02 * np.std(y)
    return IOData(t=t, u=np.column_stack([u, s]), y=(y + noise * rng.standard_normal(n))[:, None]), noise


def test_recovers_a_scheduled_lag_from_a_wrong_start(lag_record):
    data, noise = lag_record
    result = identify_greybox(data, _scheduled_first_order(), [0.3, -1.5])
    truth = np.array([0.4, -2.0])
    # statistics: within three reported standard deviations (99.7 % each) and, since 2 % noise on 4000
    # samples determines both to a few parts in a thousand, within 1 % (the estimate is 0.1-0.3 % off)
    assert np.all(np.abs(result.parameters - truth) < 3 * result.std)
    assert np.all(np.abs(result.parameters / truth - 1) < 0.01)
    assert result.stop_reason == "converged"
    # the residual R reaches the noise variance: the fit leaves the noise and little else
    assert result.measurement_noise[0] == pytest.approx(noise**2, rel=0.1)
    assert result.correlation.shape == (2, 2) and result.correlation[0, 0] == pytest.approx(1.0)
    assert np.all(np.diff(result.trace_p) < 0)  # P shrinks from pass to pass as Q does
    # the estimate as a model value: the estimator's own recursion, its covariance, and at any schedule value
    # the lag's one pole -1 / tau (the schedule scales the gain only)
    model = IdentifiedGreyBox.from_result(result, schedule_range=[[0.5, 1.5]])
    np.testing.assert_array_equal(model.simulate(data).y, result.simulate(data))
    np.testing.assert_array_equal(model.parameter_covariance, result.covariance)
    assert model.eigenvalues(schedule=1.3)[0] == pytest.approx(-1 / result.parameters[0], rel=1e-12)


def test_the_rk4_simulation_matches_the_exact_one(lag_record):
    data, _ = lag_record
    # s held at 1: with s varying, s u is quadratic over a sample where the reference takes it linear
    data = data.replace(u=np.column_stack([data.u[:, 0], np.ones(data.n_samples)]))
    y, _ = simulate_greybox(_scheduled_first_order(), [0.4, -2.0], data)
    exact = _exact_first_order(0.4, -2.0, data.u[:, 0], data.u[:, 1], data.dt)
    # RK4 at dt / tau = 0.025 with a first-order hold: global error ~ (dt / tau)^4 / 120 of the state
    # (measured 1e-8 of the largest output)
    assert np.max(np.abs(y[:, 0] - exact)) < 1e-6 * np.max(np.abs(exact))


def test_positive_parameters_stay_positive_and_bad_input_is_named(lag_record):
    data, _ = lag_record
    model = _scheduled_first_order()
    with pytest.raises(InputError, match="time_constant.*positive"):
        identify_greybox(data, model, [-0.3, -1.5])
    with pytest.raises(InputError, match="gain.*starts at zero"):
        identify_greybox(data, model, [0.3, 0.0])
    with pytest.raises(InputError, match="1 input.*1 scheduling signal"):
        identify_greybox(data.replace(u=data.u[:, :1], input_names=None, input_units=None), model, [0.3, -1.5])
    with pytest.raises(InputError, match="measurement_noise"):
        GreyBoxOptions(measurement_noise="guess")


def test_a_divergence_names_the_pass(lag_record):
    data, _ = lag_record
    model = _scheduled_first_order()
    # a time constant of 1e-9 s puts RK4 at dt / tau = 1e7, far beyond its stability (2.8): each step
    # multiplies the state by some 4e26. The residual rule for R simulates the start first and says so;
    # with R from the data the first pass overflows within a few samples (a start of 1e-4 s the filter
    # still corrects), which must end as a DivergenceError naming the pass
    with pytest.raises(DivergenceError, match="start model's simulation is not finite"):
        identify_greybox(data, model, [1e-9, -1.5])
    with pytest.raises(DivergenceError, match="pass 1.*non-finite") as caught:
        identify_greybox(data, model, [1e-9, -1.5], options=GreyBoxOptions(measurement_noise="data"))
    assert caught.value.last_good is None  # nothing was finished before the first pass


def test_an_mx_model_is_the_same_model(lag_record):
    """Models built with CasADi's MX (as larger models are) are expanded to SX for the filter: same numbers."""
    data, _ = lag_record
    x, u, theta, s = ca.MX.sym("x"), ca.MX.sym("u"), ca.MX.sym("theta", 2), ca.MX.sym("s")
    names = ["x", "u", "theta", "s"]
    sx = _scheduled_first_order()
    mx = GreyBoxModel(
        dynamics=ca.Function("lag_dynamics_mx", [x, u, theta, s], [-x / theta[0] + theta[1] * s * u], names, ["xdot"]),
        output=ca.Function("lag_output_mx", [x, u, theta, s], [x], names, ["y"]),
        parameter_names=sx.parameter_names, parameter_units=sx.parameter_units, positive=sx.positive,
        state_names=sx.state_names, input_names=sx.input_names, schedule_names=sx.schedule_names,
        output_names=sx.output_names,
    )
    expected, _ = simulate_greybox(sx, [0.4, -2.0], data)
    found, _ = simulate_greybox(mx, [0.4, -2.0], data)
    assert np.max(np.abs(found - expected)) <= 1e-12 * np.max(np.abs(expected))  # algebra: rounding only
