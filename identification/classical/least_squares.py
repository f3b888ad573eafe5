"""Batch least squares and ARX models (seed appendix A.2.1-A.2.2; Ljung 1987, ch. 7.3).

An ARX model (appendix eq. A.38) ``y(k) + A_1 y(k-1) + ... + A_na y(k-na) = sum_j sum_i
b_{j,i} u_j(k - nk_j - i) + e(k)`` has full ``A_i`` (MIMO). All outputs share the regressor
(eq. A.52-A.55), so one QR factorisation of ``Phi`` gives every column of ``Theta`` (eq. A.51).

Excitation is tested on ``Phi`` with unit-norm columns (units do not matter): a condition number above
:data:`CONDITION_LIMIT` raises :class:`ExcitationError`. The limit is high because the solution comes
from the QR factor of ``Phi``, never from ``Phi'Phi``: its relative error is about ``cond(Phi) * eps``,
leaving some six significant digits at the limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import scipy.linalg

from ..argument_checks import finite_matrix, io_arrays, non_negative_int, per_input
from ..errors import ExcitationError, InputError
from ..models.protocol import StateSpaceModel, sample_interval, unscheduled

__all__ = [
    "CONDITION_LIMIT",
    "LeastSquaresResult",
    "least_squares",
    "ArxModel",
    "ArxResult",
    "arx_regressors",
    "stacked_arx_regressors",
    "estimate_arx",
    "observer_form",
]

#: Largest condition number accepted for the column-scaled regressor matrix Phi
#: (its square, 1e20, for Phi'Phi); see the module docstring.
CONDITION_LIMIT = 1e10


@dataclass(frozen=True, eq=False)
class LeastSquaresResult:
    """A linear regression ``Y = Phi Theta + E`` solved by least squares.

    Attributes
    ----------
    theta : ndarray, shape (n_p, n_y)
        Estimates, one column per output (eq. A.51).
    covariance : ndarray, shape (n_y, n_p, n_p)
        ``sigma_i^2 (Phi'Phi)^-1`` per output (eq. A.58), ``sigma_i^2`` the
        residual variance with ``N - n_p`` degrees of freedom.
    noise_variance : ndarray, shape (n_y,)
        ``sigma_i^2``, the residual variance of each output with ``N - n_p`` degrees of freedom.
    residuals : ndarray, shape (N, n_y)
        ``Y - Phi Theta``.
    condition_number : float
        Of the column-scaled ``Phi'Phi`` (the square of Phi's).
    gram_inverse : ndarray, shape (n_p, n_p)
        ``(Phi'Phi)^-1``, from the QR factor (the starting P of RLS, appendix Remark 2).
    """

    theta: np.ndarray
    covariance: np.ndarray
    noise_variance: np.ndarray
    residuals: np.ndarray
    condition_number: float
    gram_inverse: np.ndarray


def least_squares(phi: Any, y: Any, *, names: tuple[str, ...] | None = None,
                  condition_limit: float = CONDITION_LIMIT) -> LeastSquaresResult:
    """Solve ``min ||Y - Phi Theta||^2`` by a QR factorisation of Phi (appendix eq. A.50-A.51).

    Parameters
    ----------
    phi : array_like, shape (N, n_p)
        Regressors, one row per equation.
    y : array_like, shape (N, n_y) or (N,)
        Left-hand sides; each column is an independent regression on ``phi``.
    names : tuple of str, optional
        Names of the regressors, used in error messages.
    condition_limit : float
        Largest condition number of the column-scaled Phi accepted.

    Returns
    -------
    LeastSquaresResult
        Estimates, covariances, residuals and the condition number.

    Raises
    ------
    InputError
        Non-finite values, mismatched lengths, fewer equations than unknowns.
    ExcitationError
        A regressor identically zero, or Phi too badly conditioned.

    Examples
    --------
    >>> r = least_squares([[1.0, 0.0], [1.0, 1.0], [1.0, 2.0]], [1.0, 3.0, 5.0])
    >>> r.theta.ravel().round(12)
    array([1., 2.])
    """
    phi = finite_matrix("phi", phi)
    y = finite_matrix("y", y)
    n, n_p = phi.shape
    names = names or tuple(f"phi{i + 1}" for i in range(n_p))
    if y.shape[0] != n:
        raise InputError(f"phi has {n} rows but y has {y.shape[0]}: lengths must match")
    if n < n_p:
        raise InputError(
            f"{n} equations for {n_p} unknowns: the regression needs at least as many equations as "
            "parameters (shorter orders or more data)"
        )
    norms = np.linalg.norm(phi, axis=0)
    if np.any(norms == 0):
        raise ExcitationError(f"the regressor {names[int(np.argmin(norms))]} is identically zero: "
                              "the input is not persistently exciting")
    scaled = phi / norms
    q, r = scipy.linalg.qr(scaled, mode="economic")
    singular = scipy.linalg.svdvals(r)
    condition = float(singular[0] / singular[-1]) if singular[-1] > 0 else np.inf
    if not condition <= condition_limit:
        raise ExcitationError(
            f"Phi'Phi is singular or badly conditioned (condition number {condition**2:.3g} of the "
            f"column-scaled Phi'Phi, limit {condition_limit**2:.3g}): the input is not persistently "
            "exciting for these orders"
        )
    # np.linalg.solve on the small triangular R: scipy's solve_triangular costs more per call here.
    theta = np.linalg.solve(r, q.T @ y) / norms[:, None]
    residuals = y - phi @ theta
    dof = max(n - n_p, 1)
    variance = np.sum(residuals**2, axis=0) / dof
    r_inverse = np.linalg.inv(r) / norms[:, None]
    unscaled = r_inverse @ r_inverse.T  # (Phi'Phi)^-1
    covariance = variance[:, None, None] * unscaled[None]
    return LeastSquaresResult(theta, covariance, variance, residuals, condition**2, unscaled)


def observer_form(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Discrete state space of ``A(q) y = B(q) u`` in block observer form.

    Parameters
    ----------
    a : ndarray, shape (m + 1, n_y, n_y)
        ``A_0 = I, A_1, ..., A_m``.
    b : ndarray, shape (m + 1, n_y, n_u)
        ``B_0, ..., B_m``, the coefficients of ``u(k - i)``.

    Returns
    -------
    Ad, Bd, Cd, Dd : ndarray
        ``x(k+1) = Ad x + Bd u``, ``y = Cd x + Dd u`` with ``m n_y`` states:
        ``y(k) = x_1(k) + B_0 u(k)``, ``x_i(k+1) = x_{i+1}(k) - A_i y(k) + B_i u(k)``.
    """
    m = a.shape[0] - 1
    n_y, n_u = b.shape[1], b.shape[2]
    if m < 1:
        raise InputError("a realisation needs at least one lag (na or the input lags >= 1)")
    size = m * n_y
    ad = np.zeros((size, size))
    bd = np.zeros((size, n_u))
    for i in range(1, m + 1):
        rows = slice((i - 1) * n_y, i * n_y)
        ad[rows, :n_y] = -a[i]
        if i < m:
            ad[rows, i * n_y:(i + 1) * n_y] = np.eye(n_y)
        bd[rows] = b[i] - a[i] @ b[0]
    cd = np.zeros((n_y, size))
    cd[:, :n_y] = np.eye(n_y)
    return ad, bd, cd, b[0].copy()


@dataclass(frozen=True, eq=False)
class ArxModel(StateSpaceModel):
    """ARX polynomials ``A(q) y = B(q) u`` (eq. A.38), time-major coefficient stacks.

    Attributes
    ----------
    a : ndarray, shape (na + 1, n_y, n_y)
        ``I, A_1, ..., A_na``.
    b : ndarray, shape (nlag + 1, n_y, n_u)
        Coefficient of ``u(k - i)`` at index i (zeros below each input's delay).
    dt : float or None
        Sample interval (s), if known.
    """

    a: np.ndarray
    b: np.ndarray
    dt: float | None = None

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.a.shape[1])

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return int(self.b.shape[2])

    def padded(self) -> tuple[np.ndarray, np.ndarray]:
        """Pad ``a`` and ``b`` with zeros to one common length ``m + 1``.

        Returns
        -------
        tuple of ndarray
            ``a`` (m + 1, n_y, n_y) and ``b`` (m + 1, n_y, n_u).
        """
        m = max(self.a.shape[0], self.b.shape[0])
        a = np.zeros((m, self.n_y, self.n_y))
        b = np.zeros((m, self.n_y, self.n_u))
        a[: self.a.shape[0]] = self.a
        b[: self.b.shape[0]] = self.b
        return a, b

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """Return the discrete state-space form in block observer form (:func:`observer_form`).

        Parameters
        ----------
        schedule : float, optional
            Changes nothing (the model is not scheduled).

        Returns
        -------
        tuple
            ``(Ad, Bd, Cd, Dd, dt)``.
        """
        unscheduled(schedule)
        return (*observer_form(*self.padded()), sample_interval(self.dt, "ARX model"))

    def predict(self, u: Any, y: Any) -> np.ndarray:
        """Predict one step ahead: ``yhat(k) = y(k) - A(q) y(k) + B(q) u(k)``.

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Inputs.
        y : array_like, shape (N, n_y)
            Measured outputs; the samples before the first are taken as zero.

        Returns
        -------
        ndarray, shape (N, n_y)
            The predictions.
        """
        u = finite_matrix("u", u)
        y = finite_matrix("y", y)
        yhat = np.zeros_like(y)
        n = y.shape[0]
        for i in range(1, self.a.shape[0]):
            yhat[i:] -= y[: n - i] @ self.a[i].T
        for i in range(self.b.shape[0]):
            yhat[i:] += u[: n - i] @ self.b[i].T
        return yhat


@dataclass(frozen=True, eq=False)
class ArxResult:
    """An ARX model estimated by least squares, with its statistics.

    Attributes
    ----------
    model : ArxModel
        The estimated polynomials.
    na, nb, nk : int and tuples of int
        The orders used (nb, nk per input).
    fit : LeastSquaresResult
        Parameters (n_p, n_y), covariance ``sigma^2 (Phi'Phi)^-1`` per
        output, residuals (one per equation), condition number.
    regressor_names : tuple of str
        Names of the regressors, ``-y1(k-1)``, ..., ``u2(k-3)``.
    meta : dict
        Provenance (records, sample interval).
    """

    model: ArxModel
    na: int
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    fit: LeastSquaresResult
    regressor_names: tuple[str, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def theta(self) -> np.ndarray:
        """Parameters, shape (n_p, n_y)."""
        return self.fit.theta

    @property
    def covariance(self) -> np.ndarray:
        """Parameter covariance per output, shape (n_y, n_p, n_p)."""
        return self.fit.covariance

    @property
    def residuals(self) -> np.ndarray:
        """Equation errors, shape (N - first usable sample, n_y)."""
        return self.fit.residuals


def arx_orders(n_u: int, n_y: int, na: Any, nb: Any, nk: Any) -> tuple[int, tuple[int, ...], tuple[int, ...]]:
    """``na`` and per-input ``nb`` and ``nk`` of an ARX model, checked (``nb`` defaults to ``na``)."""
    na = non_negative_int(na, "na")
    nb_t = per_input(na if nb is None else nb, n_u, "nb")
    nk_t = per_input(nk, n_u, "nk")
    if na + sum(nb_t) == 0:
        raise InputError("na and nb are all zero: the model has no parameters")
    return na, nb_t, nk_t


def arx_regressors(u: Any, y: Any, *, na: int, nb: Any = None, nk: Any = 0
                   ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], int]:
    """The ARX regression ``Y = Phi theta`` (eq. A.52-A.55).

    Parameters
    ----------
    u : array_like, shape (N, n_u)
        Inputs.
    y : array_like, shape (N, n_y)
        Outputs.
    na : int
        Number of output lags.
    nb : int or sequence of int, optional
        Number of coefficients per input (default ``na``).
    nk : int or sequence of int
        Delay of each input in samples (0: direct feed-through).

    Returns
    -------
    phi : ndarray, shape (N - k0, n_p)
        The regressors, one row per equation.
    Y : ndarray, shape (N - k0, n_y)
        The outputs from sample ``k0`` on.
    names : tuple of str
        ``-y1(k-1)``, ..., ``u2(k-3)``.
    k0 : int
        The first sample with a full regressor: ``max(na, nk_j + nb_j - 1)``.
    """
    u = finite_matrix("u", u)
    y = finite_matrix("y", y)
    if u.shape[0] != y.shape[0]:
        raise InputError(f"u has {u.shape[0]} samples but y has {y.shape[0]}: lengths must match")
    n, n_u = u.shape
    n_y = y.shape[1]
    na, nb, nk = arx_orders(n_u, n_y, na, nb, nk)
    k0 = max([na] + [nk[j] + nb[j] - 1 for j in range(n_u)])
    rows = n - k0
    n_p = na * n_y + sum(nb)
    if rows < n_p:
        raise InputError(
            f"{n} samples leave {max(rows, 0)} equations for {n_p} parameters (na={na}, nb={nb}, nk={nk}): "
            "fewer equations than unknowns"
        )
    columns, names = [], []
    for i in range(1, na + 1):
        for o in range(n_y):
            columns.append(-y[k0 - i: n - i, o])
            names.append(f"-y{o + 1}(k-{i})")
    for j in range(n_u):
        for i in range(nb[j]):
            lag = nk[j] + i
            columns.append(u[k0 - lag: n - lag, j])
            names.append(f"u{j + 1}(k-{lag})" if lag else f"u{j + 1}(k)")
    phi = np.column_stack(columns)
    return phi, y[k0:], tuple(names), k0


def stacked_arx_regressors(experiments: Sequence[tuple[Any, Any]], *, na: int, nb: Any = None, nk: Any = 0
                           ) -> tuple[np.ndarray, np.ndarray, tuple[str, ...], int]:
    """The ARX regression of several experiments: each one's rows, stacked, none across a boundary.

    ``experiments`` is a sequence of ``(u, y)`` pairs; every experiment loses
    its own first ``k0`` samples, whose regressors would reach into another
    record. Returns ``phi``, ``Y``, ``names``, ``k0`` as :func:`arx_regressors`.
    """
    pieces = [arx_regressors(u, y, na=na, nb=nb, nk=nk) for u, y in experiments]
    if len(pieces) == 1:
        return pieces[0]
    return (np.vstack([p[0] for p in pieces]), np.vstack([p[1] for p in pieces]), pieces[0][2], pieces[0][3])


def model_from_theta(theta: np.ndarray, n_u: int, n_y: int, na: int, nb: tuple[int, ...], nk: tuple[int, ...],
                     dt: float | None) -> ArxModel:
    """The :class:`ArxModel` of a parameter array laid out as :func:`arx_regressors` orders it."""
    theta = np.asarray(theta, dtype=float).reshape(-1, n_y)
    a = np.zeros((na + 1, n_y, n_y))
    a[0] = np.eye(n_y)
    for i in range(1, na + 1):
        a[i] = theta[(i - 1) * n_y: i * n_y].T
    lags = max([nk[j] + nb[j] for j in range(n_u)] + [1])
    b = np.zeros((lags, n_y, n_u))
    row = na * n_y
    for j in range(n_u):
        for i in range(nb[j]):
            b[nk[j] + i, :, j] = theta[row]
            row += 1
    return ArxModel(a, b, dt)


def estimate_arx(data_or_arrays: Any, *, na: int, nb: Any = None, nk: Any = 0,
                 condition_limit: float = CONDITION_LIMIT) -> ArxResult:
    """Estimate a MISO or MIMO ARX model by batch least squares (appendix eq. A.51, A.58).

    Parameters
    ----------
    data_or_arrays : IOData, (u, y), or a list of them
        Time-major inputs (N, n_u) and outputs (N, n_y); a list holds
        several experiments, whose regression rows are stacked without
        crossing a record boundary (:func:`stacked_arx_regressors`).
    na : int
        Output lags (the order of A(q)).
    nb : int or sequence of int, optional
        Coefficients per input (default ``na``).
    nk : int or sequence of int
        Input delays in samples (default 0: ``u(k)`` enters, as a sampled
        continuous system with a first-order hold needs).
    condition_limit : float
        See :data:`CONDITION_LIMIT`.

    Returns
    -------
    ArxResult
        With the covariance ``sigma^2 (Phi'Phi)^-1`` (eq. A.58) per output.

    Raises
    ------
    InputError
        Bad shapes, non-finite data, negative orders, fewer equations than unknowns.
    ExcitationError
        The input is not persistently exciting for these orders.
    """
    experiments = [io_arrays(item) for item in data_or_arrays] if isinstance(data_or_arrays, list) \
        else [io_arrays(data_or_arrays)]
    u, y, dt = experiments[0]
    phi, target, names, k0 = stacked_arx_regressors([(e[0], e[1]) for e in experiments], na=na, nb=nb, nk=nk)
    na_i, nb_t, nk_t = arx_orders(u.shape[1], y.shape[1], na, nb, nk)
    fit = least_squares(phi, target, names=names, condition_limit=condition_limit)
    model = model_from_theta(fit.theta, u.shape[1], y.shape[1], na_i, nb_t, nk_t, dt)
    return ArxResult(model, na_i, nb_t, nk_t, fit, names, {"method": "least squares", "first_sample": k0})
