"""Singular pencil models (seed appendix A.4.2): conversions round-trip; the Kalman filter estimates jointly."""

import numpy as np
import pytest
from scipy.signal import lfilter

from vehid.identification import InputError
from vehid.identification.classical.least_squares import ArxModel, estimate_arx
from vehid.identification.classical.pencil import PencilModel, estimate_pencil

ALGEBRA = 1e-10  # conversions are a few small factorisations of well-conditioned matrices


def _markov(A, B, C, D, count=8):
    """Impulse response D, CB, CAB, ...: equal for equivalent realisations."""
    out, power = [D], np.eye(A.shape[0])
    for _ in range(count):
        out.append(C @ power @ B)
        power = A @ power
    return np.array(out)


def _random_system(seed=0, n=3, n_u=2, n_y=2):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A *= 0.8 / max(abs(np.linalg.eigvals(A)))
    return A, rng.standard_normal((n, n_u)), rng.standard_normal((n_y, n)), rng.standard_normal((n_y, n_u))


def test_state_space_round_trip_is_exact():
    system = _random_system()
    pencil = PencilModel.from_state_space(*system, dt=0.01)
    assert pencil.E.shape == (5, 3) and pencil.G.shape == (5, 4)
    *matrices, dt = pencil.to_statespace()
    assert dt == 0.01
    for original, back in zip(system, matrices):
        np.testing.assert_allclose(back, original, atol=ALGEBRA)
    with pytest.raises(InputError, match="no sample interval"):
        PencilModel.from_state_space(*system).to_statespace()


def test_pencil_in_other_coordinates_converts_to_an_equivalent_system():
    """Any row combination of the equations and any basis of x describe the same system."""
    system = _random_system(1)
    pencil = PencilModel.from_state_space(*system)
    rng = np.random.default_rng(2)
    rows = rng.standard_normal((5, 5)) + 3 * np.eye(5)
    basis = rng.standard_normal((3, 3)) + 3 * np.eye(3)
    mixed = PencilModel(rows @ pencil.E @ basis, rows @ pencil.F @ basis, rows @ pencil.G, 2, 2, dt=1.0)
    np.testing.assert_allclose(_markov(*mixed.to_statespace()[:4]), _markov(*system), atol=1e-9)


@pytest.mark.parametrize("n_u", [1, 2])
def test_arx_round_trip(n_u):
    a = np.array([1.0, -1.5, 0.7]).reshape(3, 1, 1)
    b = np.zeros((3, 1, n_u))
    b[:, 0, 0] = [0.2, 1.0, 0.5]
    if n_u == 2:
        b[:, 0, 1] = [0.0, -0.3, 0.1]
    pencil = PencilModel.from_arx(ArxModel(a, b, dt=0.01))
    back = pencil.to_arx()
    assert back.dt == 0.01
    np.testing.assert_allclose(back.a, a, atol=ALGEBRA)
    np.testing.assert_allclose(back.b, b, atol=ALGEBRA)


def test_bad_pencils_are_rejected():
    with pytest.raises(InputError, match="E has shape"):
        PencilModel(np.zeros((3, 2)), np.zeros((4, 2)), np.zeros((4, 3)), 1, 2)
    singular = PencilModel(np.zeros((3, 2)), np.ones((3, 2)), np.ones((3, 2)), 1, 1, dt=1.0)
    with pytest.raises(InputError, match="rank deficient"):
        singular.to_statespace()


def _armax(seed, n=3000, c1=0.5, sigma=0.1):
    """A = 1 - 1.5 q^-1 + 0.7 q^-2, B = q^-1 + 0.5 q^-2, C = 1 + c1 q^-1."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = sigma * rng.standard_normal(n)
    y = lfilter([0, 1, 0.5], [1, -1.5, 0.7], u) + lfilter([1, c1], [1, -1.5, 0.7], e)
    return u[:, None], y[:, None]


def test_joint_estimate_of_an_arx_model_equals_least_squares():
    """With C* = 0 the SP filter is exact Bayesian regression: batch LS up to the prior's weight."""
    u, y = _armax(0, c1=0.0)
    joint = estimate_pencil((u, y), na=2, nb=3, noise_variance=0.01, P0=1e6)
    batch = estimate_arx((u, y), na=2, nb=3)
    # the prior P0 = 1e6 against sum(phi^2)/sigma^2 ~ 1e7 per parameter shifts the estimate by ~1e-8
    np.testing.assert_allclose(joint.gamma, batch.theta[:, 0], atol=1e-6)


def test_joint_estimate_of_an_armax_model_recovers_its_parameters():
    u, y = _armax(1)
    joint = estimate_pencil((u, y), na=2, nb=3, noise=[0.5, 0.0], noise_variance=0.01)
    truth = [-1.5, 0.7, 0.0, 1.0, 0.5]
    # standard errors are ~0.1/sqrt(3000) * (gain of the regressors) < 0.005: 0.02 is four of them
    np.testing.assert_allclose(joint.gamma, truth, atol=0.02)
    np.testing.assert_allclose(joint.model.a[:, 0, 0], [1.0, *joint.gamma[:2]])
    assert joint.states.shape == (3000, 2) and joint.gamma_history.shape == (3000, 5)


def test_joint_estimator_rejects_bad_options():
    u, y = _armax(2, n=50)
    with pytest.raises(InputError, match="one output"):
        estimate_pencil((u, np.hstack([y, y])), na=2)
    with pytest.raises(InputError, match="at most na \\+ 1"):
        estimate_pencil((u, y), na=2, nb=4)
    with pytest.raises(InputError, match="noise needs"):
        estimate_pencil((u, y), na=2, noise=[0.1])
