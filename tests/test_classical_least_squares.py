"""Batch and recursive least squares (seed appendix A.2.1-A.2.4, A.5) on seeded data."""

import numpy as np
import pytest

from vehid.identification import ExcitationError, InputError
from vehid.identification.classical.factorised import ud_covariance, ud_factor
from vehid.identification.classical.least_squares import arx_regressors, estimate_arx, least_squares
from vehid.identification.classical.recursive import estimate_arx_recursive, recursive_least_squares

# Algebraic identities are checked to 1e-10: the regressions here have
# condition numbers below 1e3, so rounding stays near 1e-13.
ALGEBRA = 1e-10


def _arx_data(n=600, seed=0, noise=0.0):
    """y(k) = 1.5 y(k-1) - 0.7 y(k-2) + u(k-1) + 0.5 u(k-2) + e, a stable second-order ARX."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = noise * rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 1.5 * y[k - 1] - 0.7 * y[k - 2] + u[k - 1] + 0.5 * u[k - 2] + e[k]
    return u[:, None], y[:, None]


def test_arx_recovers_noise_free_parameters():
    u, y = _arx_data()
    result = estimate_arx((u, y), na=2, nb=2, nk=1)
    # theta = [a1, a2, b1, b2] with the sign convention A(q) = 1 + a1 q^-1 + a2 q^-2
    np.testing.assert_allclose(result.theta.ravel(), [-1.5, 0.7, 1.0, 0.5], atol=ALGEBRA)
    assert result.regressor_names == ("-y1(k-1)", "-y1(k-2)", "u1(k-1)", "u1(k-2)")
    np.testing.assert_allclose(result.model.a[:, 0, 0], [1, -1.5, 0.7], atol=ALGEBRA)


def test_covariance_matches_monte_carlo_spread():
    """sigma^2 (Phi'Phi)^-1 (eq. A.58) predicts the spread of the estimates over 200 seeded records."""
    estimates, predicted = [], []
    for seed in range(200):
        u, y = _arx_data(n=400, seed=seed, noise=0.3)
        result = estimate_arx((u, y), na=2, nb=2, nk=1)
        estimates.append(result.theta.ravel())
        predicted.append(np.sqrt(np.diag(result.covariance[0])))
    spread = np.std(estimates, axis=0)
    # The sample standard deviation of 200 draws is within ~15 % (3 sigma: 3/sqrt(2*200)) of the truth.
    np.testing.assert_allclose(spread, np.mean(predicted, axis=0), rtol=0.15)


def test_mimo_arx_equals_per_output_fits():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((300, 2))
    y = np.column_stack([np.convolve(u[:, 0], [0, 1, 0.5])[:300], np.convolve(u[:, 1], [0.2, -1])[:300]])
    y += 0.01 * rng.standard_normal(y.shape)
    both = estimate_arx((u, y), na=1, nb=2, nk=0)
    assert both.theta.shape == (2 + 4, 2)
    phi, target, _, _ = arx_regressors(u, y, na=1, nb=2, nk=0)
    for output in range(2):
        single = least_squares(phi, target[:, output])
        np.testing.assert_allclose(both.theta[:, output], single.theta[:, 0], atol=ALGEBRA)


def test_unexciting_input_is_rejected():
    u = np.ones((200, 1))  # a constant excites only the static gain: u(k-1) and u(k-2) are collinear
    y = np.cumsum(u) * 0.1
    with pytest.raises(ExcitationError, match="persistently exciting"):
        estimate_arx((u, y[:, None]), na=1, nb=2, nk=1)
    with pytest.raises(ExcitationError, match="identically zero"):
        estimate_arx((np.zeros((50, 1)), np.ones((50, 1))), na=1, nb=1, nk=1)


@pytest.mark.parametrize(
    "arrays, options, message",
    [
        ((np.full((10, 1), np.nan), np.zeros((10, 1))), {"na": 1}, "non-finite"),
        ((np.zeros((10, 1)), np.zeros((9, 1))), {"na": 1}, "lengths must match"),
        ((np.ones((6, 1)), np.ones((6, 1))), {"na": 3, "nb": 3}, "fewer equations than unknowns"),
        ((np.ones((10, 1)), np.ones((10, 1))), {"na": -1}, "na must be"),
        ((np.ones((10, 2)), np.ones((10, 1))), {"na": 1, "nb": [1, 2, 3]}, "one value per input"),
    ],
)
def test_bad_input_is_named(arrays, options, message):
    with pytest.raises(InputError, match=message):
        estimate_arx(arrays, **options)


def test_rls_equals_batch_least_squares():
    """Started from a batch fit of the first samples (appendix Remark 2), RLS reproduces batch LS."""
    u, y = _arx_data(noise=0.2)
    phi, target, _, _ = arx_regressors(u, y, na=2, nb=2, nk=1)
    batch = least_squares(phi, target)
    start = least_squares(phi[:20], target[:20])
    p0 = start.gram_inverse
    for form in ("plain", "sqrt", "ud"):
        run = recursive_least_squares(phi[20:], target[20:], P0=p0, theta0=start.theta, form=form)
        np.testing.assert_allclose(run.theta, batch.theta, atol=ALGEBRA, err_msg=form)
        np.testing.assert_allclose(run.covariance, batch.gram_inverse, atol=ALGEBRA)


def test_factorised_forms_equal_plain_with_forgetting():
    """Square-root and UD' RLS equal plain RLS at every step on well-conditioned data."""
    rng = np.random.default_rng(5)
    phi = rng.standard_normal((300, 4))
    y = phi @ [1.0, -2.0, 0.5, 3.0] + 0.1 * rng.standard_normal(300)
    plain = recursive_least_squares(phi, y, forgetting=0.97, P0=10.0)
    for form in ("sqrt", "ud"):
        other = recursive_least_squares(phi, y, forgetting=0.97, P0=10.0, form=form)
        np.testing.assert_allclose(other.history, plain.history, atol=ALGEBRA, err_msg=form)
        np.testing.assert_allclose(other.trace, plain.trace, rtol=ALGEBRA, err_msg=form)


def test_ud_factor_round_trip():
    rng = np.random.default_rng(2)
    a = rng.standard_normal((5, 5))
    p = a @ a.T + np.eye(5)
    u, d = ud_factor(p)
    assert np.allclose(np.tril(u, -1), 0) and np.allclose(np.diag(u), 1) and np.all(d > 0)
    np.testing.assert_allclose(ud_covariance(u, d), p, atol=ALGEBRA)


def test_forgetting_tracks_a_step_change():
    """y = theta(k) u with theta stepping 1 -> 2 at k = 500: lambda = 0.95 follows, lambda = 1 averages."""
    rng = np.random.default_rng(7)
    u = rng.standard_normal(1000)
    theta = np.where(np.arange(1000) < 500, 1.0, 2.0)
    y = theta * u + 0.05 * rng.standard_normal(1000)
    tracking = recursive_least_squares(u, y, forgetting=0.95)
    ordinary = recursive_least_squares(u, y, forgetting=1.0)
    # Memory of lambda = 0.95 is ~1/(1-lambda) = 20 samples: 200 samples after the step the estimate is
    # within 0.05 of 2 (noise contributes ~0.05/sqrt(20) ~ 0.01); RLS without forgetting weighs the
    # 500 old samples against 200 new ones and sits near (500 + 2*200)/700 ~ 1.3.
    assert abs(tracking.history[700, 0, 0] - 2.0) < 0.05
    assert abs(ordinary.history[700, 0, 0] - 2.0) > 0.5


def test_sliding_window_equals_batch_on_the_window():
    u, y = _arx_data(noise=0.2)
    phi, target, _, _ = arx_regressors(u, y, na=2, nb=2, nk=1)
    run = recursive_least_squares(phi, target, window=80)
    for k in (79, 200, len(target) - 1):
        batch = least_squares(phi[k - 79: k + 1], target[k - 79: k + 1])
        np.testing.assert_allclose(run.history[k], batch.theta, atol=1e-8)  # down-dates accumulate rounding


@pytest.mark.parametrize("value", [0.0, -0.5, 1.01, float("nan"), "x"])
def test_forgetting_factor_outside_range_is_rejected(value):
    with pytest.raises(InputError, match="forgetting factor"):
        recursive_least_squares(np.ones((5, 1)), np.ones(5), forgetting=value)


def test_bad_recursive_options_are_rejected():
    with pytest.raises(InputError, match="unknown RLS form"):
        recursive_least_squares(np.ones((5, 1)), np.ones(5), form="qr")
    with pytest.raises(InputError, match="window"):
        recursive_least_squares(np.ones((5, 1)), np.ones(5), window=3, forgetting=0.9)
    with pytest.raises(InputError, match="positive definite"):
        recursive_least_squares(np.ones((5, 2)), np.ones(5), P0=-np.eye(2))


def test_recursive_arx_model():
    u, y = _arx_data()
    run = estimate_arx_recursive((u, y), na=2, nb=2, nk=1, P0=1e8)
    np.testing.assert_allclose(run.theta.ravel(), [-1.5, 0.7, 1.0, 0.5], atol=1e-5)  # prior 1e-8 regularises
    assert run.model is not None and run.model.a.shape == (3, 1, 1)
