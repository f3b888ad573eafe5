"""The linear Kalman filter and the Rauch-Tung-Striebel smoother (seed appendix A.3; Kalman 1960).

Model (appendix eq. A.44), for k = 1, 2, ...::

    x(k) = A x(k-1) + B u(k-1) + w(k-1),   cov w = Q
    y(k) = C x(k)   + D u(k)   + v(k),     cov v = R

Filter (appendix eq. A.84-A.91), from ``x(0|0) = x0``, ``P(0|0) = P0``::

    x(k|k-1) = A x(k-1|k-1) + B u(k-1)
    P(k|k-1) = A P(k-1|k-1) A' + Q
    K(k)     = P(k|k-1) C' (C P(k|k-1) C' + R)^-1
    x(k|k)   = x(k|k-1) + K(k) (y(k) - C x(k|k-1) - D u(k))
    P(k|k)   = (I - K(k) C) P(k|k-1)

The covariance update is by default in Joseph form,
``(I - K C) P (I - K C)' + K R K'``, equal in exact arithmetic and
symmetric positive definite under rounding. The gain is computed by a
linear solve, never an explicit inverse.

Time-major arrays: ``y`` row ``k - 1`` is ``y(k)``; matrices may be constant
or given per step with a leading ``N`` axis (``A[k-1]`` maps step k-1 to k,
``C[k-1]`` observes ``y(k)``), which the singular pencil estimator uses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..argument_checks import finite_matrix
from ..errors import DivergenceError, InputError

__all__ = ["KalmanResult", "SmootherResult", "kalman_predict", "kalman_update", "kalman_filter", "rts_smoother"]


@dataclass(frozen=True, eq=False)
class KalmanResult:
    """Everything the filter computed, time-major (row k-1 belongs to step k).

    Attributes
    ----------
    x_prior, x_post : ndarray, shape (N, n)
        ``x(k|k-1)`` and ``x(k|k)``.
    P_prior, P_post : ndarray, shape (N, n, n)
        ``P(k|k-1)`` and ``P(k|k)``.
    gain : ndarray, shape (N, n, n_y)
        ``K(k)``.
    innovation : ndarray, shape (N, n_y)
        ``y(k) - C x(k|k-1) - D u(k)``.
    innovation_covariance : ndarray, shape (N, n_y, n_y)
        ``C P(k|k-1) C' + R``.
    log_likelihood : float
        Gaussian log-likelihood of the innovations.
    """

    x_prior: np.ndarray
    P_prior: np.ndarray
    x_post: np.ndarray
    P_post: np.ndarray
    gain: np.ndarray
    innovation: np.ndarray
    innovation_covariance: np.ndarray
    log_likelihood: float


@dataclass(frozen=True, eq=False)
class SmootherResult:
    """The smoothed states and their covariances.

    Attributes
    ----------
    x : ndarray, shape (N, n)
        ``x(k|N)``.
    P : ndarray, shape (N, n, n)
        ``P(k|N)``.
    """

    x: np.ndarray
    P: np.ndarray


def kalman_predict(x: np.ndarray, P: np.ndarray, A: np.ndarray, Q: np.ndarray,
                   B: np.ndarray | None = None, u: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Predict the state one step: the time update (appendix eq. A.84-A.85).

    Parameters
    ----------
    x : ndarray, shape (n,)
        ``x(k-1|k-1)``.
    P : ndarray, shape (n, n)
        ``P(k-1|k-1)``.
    A : ndarray, shape (n, n)
        State transition.
    Q : ndarray, shape (n, n)
        Process noise covariance.
    B : ndarray, shape (n, n_u), optional
        Input matrix.
    u : ndarray, shape (n_u,), optional
        ``u(k-1)``.

    Returns
    -------
    x : ndarray, shape (n,)
        ``x(k|k-1)``.
    P : ndarray, shape (n, n)
        ``P(k|k-1)``, symmetrised.
    """
    x = A @ x if B is None or u is None else A @ x + B @ u
    P = A @ P @ A.T + Q
    return x, 0.5 * (P + P.T)


def kalman_update(x: np.ndarray, P: np.ndarray, y: np.ndarray, C: np.ndarray, R: np.ndarray,
                  D: np.ndarray | None = None, u: np.ndarray | None = None, *, joseph: bool = True
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Correct the state by a measurement: the measurement update (eq. A.86-A.88).

    Parameters
    ----------
    x : ndarray, shape (n,)
        ``x(k|k-1)``.
    P : ndarray, shape (n, n)
        ``P(k|k-1)``.
    y : ndarray, shape (n_y,)
        ``y(k)``.
    C : ndarray, shape (n_y, n)
        Output matrix.
    R : ndarray, shape (n_y, n_y)
        Measurement noise covariance.
    D : ndarray, shape (n_y, n_u), optional
        Feed-through.
    u : ndarray, shape (n_u,), optional
        ``u(k)``.
    joseph : bool, default True
        Joseph-form covariance update.

    Returns
    -------
    x : ndarray, shape (n,)
        ``x(k|k)``.
    P : ndarray, shape (n, n)
        ``P(k|k)``.
    gain : ndarray, shape (n, n_y)
        ``K(k)``.
    innovation : ndarray, shape (n_y,)
        ``y(k) - C x(k|k-1) - D u(k)``.
    innovation_covariance : ndarray, shape (n_y, n_y)
        ``C P C' + R``.

    Raises
    ------
    DivergenceError
        A singular innovation covariance.
    """
    predicted = C @ x if D is None or u is None else C @ x + D @ u
    innovation = y - predicted
    pc = P @ C.T
    S = C @ pc + R
    S = 0.5 * (S + S.T)
    try:
        gain = np.linalg.solve(S, pc.T).T
    except np.linalg.LinAlgError:
        raise DivergenceError("the innovation covariance C P C' + R is singular") from None
    x = x + gain @ innovation
    if joseph:
        factor = np.eye(P.shape[0]) - gain @ C
        P = factor @ P @ factor.T + gain @ R @ gain.T
    else:
        P = P - gain @ pc.T
    return x, 0.5 * (P + P.T), gain, innovation, S


def _per_step(name: str, value: Any, n_steps: int, shape: tuple[int, int]) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 2:
        array = np.broadcast_to(array, (n_steps, *array.shape))
    if array.shape != (n_steps, *shape):
        raise InputError(f"{name} must have shape {shape} or {(n_steps, *shape)}; got {np.shape(value)}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name} contains a non-finite value")
    return array


def kalman_filter(y: Any, *, A: Any, C: Any, Q: Any, R: Any, x0: Any, P0: Any,
                  B: Any = None, D: Any = None, u: Any = None, joseph: bool = True) -> KalmanResult:
    """Run the linear Kalman filter over ``y(1..N)``.

    Parameters
    ----------
    y : array_like, shape (N, n_y)
        Measurements ``y(1), ..., y(N)``.
    A, C : array_like
        ``(n, n)`` and ``(n_y, n)``, or per step ``(N, n, n)`` and ``(N, n_y, n)``.
    Q, R : array_like
        Process and measurement noise covariances ``(n, n)``, ``(n_y, n_y)``
        (or per step).
    x0, P0 : array_like
        ``x(0|0)`` (n,) and ``P(0|0)`` (n, n).
    B, D, u : array_like, optional
        Input matrices and inputs ``u (N, n_u)``; ``u[k-1]`` is ``u(k)``,
        and the time update to step k uses ``u(k-1)`` (zero for k = 1).
    joseph : bool
        Joseph-form covariance update (default).

    Returns
    -------
    KalmanResult
        Predicted and filtered states and covariances, gains, innovations, log-likelihood.

    Raises
    ------
    InputError
        Wrong shapes or non-finite values.
    DivergenceError
        A singular innovation covariance or a non-finite state.
    """
    y = finite_matrix("y", y)
    n_steps, n_y = y.shape
    x = finite_matrix("x0", np.ravel(x0), ndim=1).copy()
    n = x.size
    P = finite_matrix("P0", P0).copy()
    if P.shape != (n, n):
        raise InputError(f"P0 must have shape {(n, n)}; got {P.shape}")
    A = _per_step("A", A, n_steps, (n, n))
    C = _per_step("C", C, n_steps, (n_y, n))
    Q = _per_step("Q", Q, n_steps, (n, n))
    R = _per_step("R", R, n_steps, (n_y, n_y))
    if u is None and (B is not None or D is not None):
        raise InputError("B and D need the inputs u")
    if u is not None:
        u = finite_matrix("u", u)
        if u.shape[0] != n_steps:
            raise InputError(f"u has {u.shape[0]} samples but y has {n_steps}: lengths must match")
        n_u = u.shape[1]
        B = None if B is None else _per_step("B", B, n_steps, (n, n_u))
        D = None if D is None else _per_step("D", D, n_steps, (n_y, n_u))
    x_prior = np.zeros((n_steps, n))
    x_post = np.zeros((n_steps, n))
    P_prior = np.zeros((n_steps, n, n))
    P_post = np.zeros((n_steps, n, n))
    gains = np.zeros((n_steps, n, n_y))
    innovations = np.zeros((n_steps, n_y))
    covariances = np.zeros((n_steps, n_y, n_y))
    log_likelihood = 0.0
    for k in range(n_steps):
        previous_u = None if u is None or k == 0 else u[k - 1]
        x, P = kalman_predict(x, P, A[k], Q[k], None if B is None or k == 0 else B[k - 1], previous_u)
        x_prior[k], P_prior[k] = x, P
        x, P, gains[k], innovations[k], covariances[k] = kalman_update(
            x, P, y[k], C[k], R[k], None if D is None else D[k], None if u is None else u[k], joseph=joseph
        )
        if not np.all(np.isfinite(x)):
            raise DivergenceError(f"the Kalman filter diverged at step {k + 1}")
        x_post[k], P_post[k] = x, P
        sign, logdet = np.linalg.slogdet(covariances[k])
        log_likelihood -= 0.5 * (logdet + innovations[k] @ np.linalg.solve(covariances[k], innovations[k])
                                 + n_y * np.log(2 * np.pi))
    return KalmanResult(x_prior, P_prior, x_post, P_post, gains, innovations, covariances, float(log_likelihood))


def rts_smoother(result: KalmanResult, A: Any) -> SmootherResult:
    """Rauch-Tung-Striebel fixed-interval smoother over a filter run (Rauch, Tung & Striebel 1965).

    ``G(k) = P(k|k) A' P(k+1|k)^-1``,
    ``x(k|N) = x(k|k) + G(k) (x(k+1|N) - x(k+1|k))``,
    ``P(k|N) = P(k|k) + G(k) (P(k+1|N) - P(k+1|k)) G(k)'``.

    Parameters
    ----------
    result : KalmanResult
        The filter's run.
    A : array_like
        The filter's A, constant or per step.

    Returns
    -------
    SmootherResult
        ``x(k|N)`` and ``P(k|N)``.
    """
    n_steps, n = result.x_post.shape
    A = _per_step("A", A, n_steps, (n, n))
    x = result.x_post.copy()
    P = result.P_post.copy()
    for k in range(n_steps - 2, -1, -1):
        gain = np.linalg.solve(result.P_prior[k + 1], A[k + 1] @ result.P_post[k]).T
        x[k] = result.x_post[k] + gain @ (x[k + 1] - result.x_prior[k + 1])
        P[k] = result.P_post[k] + gain @ (P[k + 1] - result.P_prior[k + 1]) @ gain.T
        P[k] = 0.5 * (P[k] + P[k].T)
    return SmootherResult(x, P)
