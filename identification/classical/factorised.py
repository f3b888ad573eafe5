"""Factorised recursive least squares: square-root and UDU' forms (seed appendix A.5).

Both propagate a factor of the covariance ``P`` instead of ``P`` itself, so
that ``P`` stays positive (semi-)definite whatever the rounding, where the
plain update ``P <- (P - K phi' P) / lambda`` (appendix eq. A.113) can lose
positivity (A.114-A.116). One step of each, for a regressor ``phi`` (n,),
outputs ``y`` (n_y,) sharing it, and a forgetting factor ``lambda``
(``K = P phi / (lambda + phi' P phi)``, appendix eq. A.76-A.78):

* :func:`sqrt_step`: ``P = S S'`` with ``S`` lower triangular, updated by an
  orthogonal triangularisation of the pre-array
  ``[[sqrt(lambda), phi' S], [0, S]] / sqrt(lambda)``, which gives the
  post-array ``[[sqrt(beta), 0], [K sqrt(beta), S+]]`` with
  ``beta = (lambda + phi' P phi) / lambda`` (equal Gram matrices).
  This is the array form of Peterka's (1975) square-root regression
  (Kailath, Sayed & Hassibi, *Linear Estimation*, 2000, sec. 12.3).
* :func:`ud_step`: ``P = U diag(d) U'`` with ``U`` unit upper triangular,
  Bierman's rank-one measurement update (Bierman 1977, *Factorization
  Methods for Discrete Sequential Estimation*, sec. V.3; Thornton & Bierman
  1978), with the forgetting applied as ``d <- d / lambda``. No square roots.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

__all__ = ["sqrt_step", "ud_step", "ud_factor", "ud_covariance"]


def sqrt_step(theta: np.ndarray, S: np.ndarray, phi: np.ndarray, y: np.ndarray, lam: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One square-root RLS step.

    Parameters
    ----------
    theta : ndarray, shape (n, n_y)
        The estimate, one column per output.
    S : ndarray, shape (n, n)
        Lower-triangular factor, ``P = S S'``.
    phi : ndarray, shape (n,)
        The regressor.
    y : ndarray, shape (n_y,)
        The outputs sharing it.
    lam : float
        Forgetting factor in (0, 1].

    Returns
    -------
    theta : ndarray, shape (n, n_y)
        The updated estimate.
    S : ndarray, shape (n, n)
        The updated factor.
    K : ndarray, shape (n,)
        The gain.
    e : ndarray, shape (n_y,)
        The prediction error ``y - phi' theta`` before the update.
    """
    n = S.shape[0]
    pre = np.zeros((n + 1, n + 1))
    pre[0, 0] = np.sqrt(lam)
    pre[0, 1:] = phi @ S
    pre[1:, 1:] = S
    pre /= np.sqrt(lam)
    # pre @ Theta = post (lower triangular) with Theta orthogonal: post' = R of the QR of pre'.
    r = scipy.linalg.qr(pre.T, mode="r", check_finite=False)[0]
    post = r.T * np.sign(np.diag(r))  # make the diagonal positive (column signs are free)
    gain = post[1:, 0] / post[0, 0]  # (K sqrt(beta)) / sqrt(beta)
    error = y - phi @ theta
    return theta + np.outer(gain, error), post[1:, 1:], gain, error


def ud_step(theta: np.ndarray, U: np.ndarray, d: np.ndarray, phi: np.ndarray, y: np.ndarray, lam: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One UDU' RLS step (Bierman's update with measurement variance ``lambda``, then ``d / lambda``).

    Parameters
    ----------
    theta : ndarray, shape (n, n_y)
        The estimate, one column per output.
    U : ndarray, shape (n, n)
        Unit upper-triangular factor.
    d : ndarray, shape (n,)
        Diagonal factor, positive.
    phi : ndarray, shape (n,)
        The regressor.
    y : ndarray, shape (n_y,)
        The outputs sharing it.
    lam : float
        Forgetting factor in (0, 1].

    Returns
    -------
    theta : ndarray, shape (n, n_y)
        The updated estimate.
    U, d : ndarray
        The updated factors, ``P = U diag(d) U'``.
    K : ndarray, shape (n,)
        The gain.
    e : ndarray, shape (n_y,)
        The prediction error before the update.
    """
    n = d.size
    U = U.copy()
    f = U.T @ phi  # F = U' phi
    v = d * f  # G = D F
    b = np.zeros(n)
    d_new = np.empty(n)
    alpha = lam
    for j in range(n):
        previous = alpha
        alpha = previous + f[j] * v[j]
        d_new[j] = d[j] * previous / alpha
        if j:
            p = -f[j] / previous
            column = U[:j, j].copy()
            U[:j, j] = column + b[:j] * p
            b[:j] = b[:j] + column * v[j]
        b[j] = v[j]
    gain = b / alpha
    error = y - phi @ theta
    return theta + np.outer(gain, error), U, d_new / lam, gain, error


def ud_factor(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``U, d`` with ``P = U diag(d) U'``, U unit upper triangular (P symmetric positive definite)."""
    n = P.shape[0]
    P = np.array(P, dtype=float)
    U = np.eye(n)
    d = np.zeros(n)
    for j in range(n - 1, -1, -1):
        d[j] = P[j, j]
        if j:
            U[:j, j] = P[:j, j] / d[j]
            P[:j, :j] -= d[j] * np.outer(U[:j, j], U[:j, j])
    return U, d


def ud_covariance(U: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``U diag(d) U'``."""
    return (U * d) @ U.T
