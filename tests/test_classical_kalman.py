"""The linear Kalman filter (seed appendix A.3): the appendix's scalar example, a batch reference, the smoother."""

import numpy as np
import pytest

from vehid.identification import InputError
from vehid.identification.classical.kalman import kalman_filter, rts_smoother
from vehid.scenarios.textbook import kalman_example

# The appendix's example (A.92): x(k+1) = phi x(k) + w(k), y(k) = x(k) + v(k), phi = 1, P0 = 100,
# Q = 25, R = 15. Its Table A.1 is an image in our copy of the text, so the reference values below
# are the closed form, worked by hand: P(k|k-1) = P(k-1|k-1) + 25, K = P(k|k-1) / (P(k|k-1) + 15),
# P(k|k) = 15 P(k|k-1) / (P(k|k-1) + 15). k = 1: 125, 125/140, 1875/140.
ALGEBRA = 1e-12  # scalar recursions of a few steps: rounding only


def test_textbook_example_first_step_by_hand():
    rows = kalman_example(steps=5)
    first = rows[0]
    assert first["k"] == 1
    assert first["P_prior"] == pytest.approx(125.0, rel=ALGEBRA)
    assert first["K"] == pytest.approx(125.0 / 140.0, rel=ALGEBRA)
    assert first["P_post"] == pytest.approx(1875.0 / 140.0, rel=ALGEBRA)
    assert rows[1]["P_prior"] == pytest.approx(1875.0 / 140.0 + 25.0, rel=ALGEBRA)


def test_textbook_example_closed_form_and_steady_state():
    rows = kalman_example(steps=5)
    assert [row["k"] for row in rows] == [1, 2, 3, 4, 5]
    post = 100.0
    for row in rows:
        prior = post + 25.0
        gain = prior / (prior + 15.0)
        post = (1.0 - gain) * prior
        assert (row["P_prior"], row["K"], row["P_post"]) == pytest.approx((prior, gain, post), rel=ALGEBRA)
    # P(k|k) tends to the root of P^2 + 25 P - 375 = 0 (the Riccati fixed point), 10.5489...
    steady = (-25.0 + np.sqrt(25.0**2 + 4 * 375.0)) / 2.0
    long_run = kalman_example(steps=40)
    assert long_run[-1]["P_post"] == pytest.approx(steady, rel=1e-10)
    assert rows[4]["P_post"] == pytest.approx(steady, rel=2e-3)  # within 0.2 % after five steps


def _random_walk(n=25, seed=0):
    rng = np.random.default_rng(seed)
    x = np.cumsum(5.0 * rng.standard_normal(n))
    return x + np.sqrt(15.0) * rng.standard_normal(n)


def _batch_smoother(y, x0, P0, q, r):
    """The smoothed states as one weighted least-squares problem over x(0..N) (the joint Gaussian's mode)."""
    n = y.size
    rows, rhs, weights = [], [], []

    def equation(entries, value, variance):
        row = np.zeros(n + 1)
        for index, coefficient in entries:
            row[index] = coefficient
        rows.append(row)
        rhs.append(value)
        weights.append(1.0 / variance)

    equation([(0, 1.0)], x0, P0)  # prior on x(0)
    for k in range(1, n + 1):
        equation([(k, 1.0), (k - 1, -1.0)], 0.0, q)  # x(k) = x(k-1) + w
        equation([(k, 1.0)], y[k - 1], r)  # y(k) = x(k) + v
    w = np.sqrt(np.array(weights))
    solution = np.linalg.lstsq(np.array(rows) * w[:, None], np.array(rhs) * w, rcond=None)[0]
    return solution[1:]


def test_filter_and_smoother_equal_the_batch_solution():
    y = _random_walk()
    run = kalman_filter(y, A=[[1.0]], C=[[1.0]], Q=[[25.0]], R=[[15.0]], x0=[0.0], P0=[[100.0]])
    smoothed = rts_smoother(run, [[1.0]])
    batch = _batch_smoother(y, 0.0, 100.0, 25.0, 15.0)
    np.testing.assert_allclose(smoothed.x[:, 0], batch, atol=1e-9)  # two exact solutions, rounding only
    # the smoother's last estimate is the filter's; the filter's last equals the batch fit of all data
    assert smoothed.x[-1, 0] == pytest.approx(run.x_post[-1, 0], abs=ALGEBRA)
    assert np.all(smoothed.P[:, 0, 0] <= run.P_post[:, 0, 0] + ALGEBRA)


def test_joseph_and_plain_updates_agree_and_inputs_enter():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((50, 1))
    y = rng.standard_normal((50, 2))
    options = dict(A=[[0.9, 0.1], [0.0, 0.8]], C=[[1.0, 0.0], [1.0, 1.0]], Q=0.1 * np.eye(2), R=np.eye(2),
                   x0=[0.0, 0.0], P0=np.eye(2), B=[[1.0], [0.5]], D=[[0.0], [0.2]], u=u)
    joseph = kalman_filter(y, **options)
    plain = kalman_filter(y, joseph=False, **options)
    np.testing.assert_allclose(joseph.x_post, plain.x_post, atol=1e-10)
    without = kalman_filter(y, **{**options, "u": np.zeros_like(u)})
    assert np.abs(without.x_post - joseph.x_post).max() > 0.1


def test_bad_shapes_are_named():
    with pytest.raises(InputError, match="A must have shape"):
        kalman_filter(np.zeros((5, 1)), A=np.eye(2), C=[[1.0]], Q=[[1.0]], R=[[1.0]], x0=[0.0], P0=[[1.0]])
    with pytest.raises(InputError, match="non-finite"):
        kalman_filter(np.full((5, 1), np.nan), A=[[1.0]], C=[[1.0]], Q=[[1.0]], R=[[1.0]], x0=[0.0], P0=[[1.0]])
    with pytest.raises(InputError, match="need the inputs"):
        kalman_filter(np.zeros((5, 1)), A=[[1.0]], C=[[1.0]], Q=[[1.0]], R=[[1.0]], x0=[0.0], P0=[[1.0]], B=[[1.0]])
