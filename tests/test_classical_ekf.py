"""The joint EKF (seed appendix A.4.1): the linear case equals the Kalman filter; a bicycle model's
cornering stiffnesses are recovered from noisy simulated data."""

import casadi as ca
import numpy as np
import pytest

from vehid.identification import InputError
from vehid.identification.classical.ekf import NonlinearModel, ekf_joint
from vehid.identification.classical.kalman import kalman_filter
from vehid.scenarios.textbook import ekf_bicycle_example


def _linear_model():
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("u", 1)
    p = ca.SX.sym("p", 1)
    a = np.array([[0.9, 0.2], [-0.1, 0.8]])
    x_next = ca.mtimes(ca.DM(a), x) + ca.vertcat(p[0] * u[0], u[0])
    return NonlinearModel(x, u, p, x_next, ca.vertcat(x[0] + x[1]), "linear"), a


def test_ekf_on_a_linear_model_with_a_frozen_parameter_equals_the_kalman_filter():
    """With zero variance on p (= 0.5), the EKF is the KF of the linear model, to rounding."""
    model, a = _linear_model()
    rng = np.random.default_rng(0)
    u = rng.standard_normal((300, 1))
    u[0] = 0.0  # the EKF predicts to row 0 with u(-1) = u(0); the KF applies no input there
    y = rng.standard_normal((300, 1))
    ekf = ekf_joint(model, (u, y), x0=[0.1, -0.2], p0=[0.5], P0=[1.0, 2.0, 0.0], Q=[0.1, 0.2, 0.0], R=[0.5])
    kf = kalman_filter(y, A=a, C=[[1.0, 1.0]], Q=np.diag([0.1, 0.2]), R=[[0.5]], x0=[0.1, -0.2],
                       P0=np.diag([1.0, 2.0]), B=[[0.5], [1.0]], u=u)
    np.testing.assert_allclose(ekf.states, kf.x_post, atol=1e-12)  # same algebra, rounding only
    np.testing.assert_allclose(ekf.innovations, kf.innovation, atol=1e-12)
    np.testing.assert_allclose(ekf.parameters, 0.5)


def test_ekf_recovers_the_cornering_stiffnesses_of_a_bicycle_model():
    """2000 samples (20 s at 100 Hz), 0.005 rad/s and 0.05 m/s^2 noise, start 50 % low.

    Tolerance 1 %: the filter's own standard deviations are ~0.1 % and the errors over seeds
    0-3 lie below 0.2 %, so 1 % leaves room for the seed but still fails a wrong model.
    """
    result = ekf_bicycle_example(seed=0)
    np.testing.assert_allclose(result["estimate_N_per_rad"], result["true_N_per_rad"], rtol=0.01)
    assert all(s < 0.005 * t for s, t in zip(result["std_N_per_rad"], result["true_N_per_rad"]))


def test_compiled_ekf_equals_the_virtual_machine():
    model, _ = _linear_model()
    rng = np.random.default_rng(1)
    u, y = rng.standard_normal((600, 1)), rng.standard_normal((600, 1))
    options = dict(x0=[0.0, 0.0], p0=[0.0], P0=[1.0, 1.0, 1.0], Q=[0.01, 0.01, 1e-6], R=[1.0])
    plain = ekf_joint(model, (u, y), **options)
    compiled = ekf_joint(model, (u, y), compiled=True, **options)
    np.testing.assert_allclose(compiled.states, plain.states, atol=1e-12)  # same expressions, C vs VM
    np.testing.assert_allclose(compiled.parameters, plain.parameters, atol=1e-12)


def test_bad_models_and_data_are_rejected():
    model, _ = _linear_model()
    stray = ca.SX.sym("stray")
    with pytest.raises(InputError, match="not states, inputs or parameters: stray"):
        NonlinearModel(model.x, model.u, model.p, model.x_next + stray, model.y)
    with pytest.raises(InputError, match="x_next has"):
        NonlinearModel(model.x, model.u, model.p, model.x_next[0], model.y)
    with pytest.raises(InputError, match="1 inputs and 1 outputs"):
        ekf_joint(model, (np.zeros((5, 2)), np.zeros((5, 1))), x0=[0, 0], p0=[0], P0=[1, 1, 1], Q=[0, 0, 0], R=[1])
    with pytest.raises(InputError, match="P0 must be"):
        ekf_joint(model, (np.zeros((5, 1)), np.zeros((5, 1))), x0=[0, 0], p0=[0], P0=[1, 1], Q=[0, 0, 0], R=[1])
