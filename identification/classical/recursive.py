"""Recursive least squares (seed appendix A.2.3-A.2.4; Ljung 1987, sec. 11.2).

Plain form with a forgetting factor ``lambda`` (appendix eq. A.76-A.78)::

    K(k)     = P(k-1) phi(k) / (lambda + phi(k)' P(k-1) phi(k))
    theta(k) = theta(k-1) + K(k) (y(k) - phi(k)' theta(k-1))
    P(k)     = (P(k-1) - K(k) phi(k)' P(k-1)) / lambda

``lambda = 1`` started from a batch fit reproduces batch least squares (appendix Remark 2). A
rectangular window of ``L`` samples (appendix A.2.4; Goodwin & Payne 1977) also removes the sample
``L`` back by a down-date. ``form="sqrt"`` and ``form="ud"`` propagate factors of P
(:mod:`vehid.identification.classical.factorised`). Several outputs share one regressor and one P.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..argument_checks import finite_matrix, forgetting_factor, io_arrays, non_negative_int
from ..errors import InputError
from .factorised import sqrt_step, ud_covariance, ud_factor, ud_step
from .least_squares import ArxModel, arx_orders, arx_regressors, least_squares, model_from_theta

__all__ = ["FORMS", "RecursiveResult", "rls_step", "recursive_least_squares", "estimate_arx_recursive"]

FORMS = ("plain", "sqrt", "ud")
DEFAULT_P0 = 1e6  # appendix Remark 2: P0 = rho^2 I with rho large
_SYMMETRISE_EVERY = 64  # the plain update is symmetric up to rounding; re-symmetrise now and then


@dataclass(frozen=True, eq=False)
class RecursiveResult:
    """The run of a recursive estimator over a record.

    Attributes
    ----------
    theta : ndarray, shape (n_p, n_y)
        Final estimate.
    covariance : ndarray, shape (n_p, n_p)
        Final P (scaled by the noise variance it is the parameter covariance).
    history : ndarray, shape (N, n_p, n_y)
        Estimate after each sample.
    errors : ndarray, shape (N, n_y)
        Prediction errors ``y(k) - phi(k)' theta(k-1)``.
    trace : ndarray, shape (N,)
        trace(P) after each sample.
    form : str
        The covariance propagation: ``"plain"``, ``"sqrt"`` or ``"ud"``.
    forgetting : float
        The forgetting factor lambda.
    window : int or None
        The rectangular window's length, if one was used.
    model : ArxModel or None
        For :func:`estimate_arx_recursive`, the final ARX model.
    meta : dict
        Provenance (method, first usable sample, regressor names).
    """

    theta: np.ndarray
    covariance: np.ndarray
    history: np.ndarray
    errors: np.ndarray
    trace: np.ndarray
    form: str
    forgetting: float
    window: int | None
    model: ArxModel | None = None
    meta: dict[str, Any] = field(default_factory=dict)


def rls_step(theta: np.ndarray, P: np.ndarray, phi: np.ndarray, y: np.ndarray, lam: float = 1.0
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Take one plain RLS step (appendix eq. A.76-A.78).

    Parameters
    ----------
    theta : ndarray, shape (n, n_y)
        The estimate, one column per output.
    P : ndarray, shape (n, n)
        Its covariance factor.
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
    P : ndarray, shape (n, n)
        The updated covariance, symmetrised.
    K : ndarray, shape (n,)
        The gain.
    e : ndarray, shape (n_y,)
        The prediction error before the update.
    """
    p_phi = P @ phi
    gain = p_phi / (lam + phi @ p_phi)
    error = y - phi @ theta
    P = (P - np.outer(gain, p_phi)) / lam
    return theta + np.outer(gain, error), 0.5 * (P + P.T), gain, error


def _downdate(theta: np.ndarray, P: np.ndarray, phi: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    p_phi = P @ phi
    denominator = 1.0 - phi @ p_phi
    if denominator <= 0:
        raise InputError("the sliding window lost the excitation it needs (down-date would make P indefinite)")
    P = P + np.outer(p_phi, p_phi) / denominator
    theta = theta - np.outer(P @ phi, y - phi @ theta)
    return theta, 0.5 * (P + P.T)


def recursive_least_squares(phi: Any, y: Any, *, forgetting: float = 1.0, window: int | None = None,
                            form: str = "plain", P0: Any = None, theta0: Any = None,
                            keep_history: bool = True) -> RecursiveResult:
    """Run RLS over a regression ``y(k) = phi(k)' theta + e(k)``.

    Parameters
    ----------
    phi : array_like, shape (N, n_p)
        The regressors, one row per sample.
    y : array_like, shape (N, n_y) or (N,)
        The outputs, sharing the regressor.
    forgetting : float
        The factor lambda, in (0, 1] (appendix eq. A.75); 1 gives ordinary RLS.
    window : int, optional
        Rectangular window length L (plain form, lambda = 1 only). The first
        L samples are fitted in one batch (giving theta0 and P0), then each
        new sample is added and the oldest removed.
    form : {"plain", "sqrt", "ud"}
        Covariance propagation (module docstring).
    P0 : float or array_like (n_p, n_p), optional
        Initial covariance; a number means that times I. Default 1e6 I.
    theta0 : array_like (n_p,) or (n_p, n_y), optional
        Initial estimate; default zero.
    keep_history : bool
        Keep the estimate after every sample (N n_p n_y floats).

    Returns
    -------
    RecursiveResult
        The final estimate and P, the history and the prediction errors.

    Raises
    ------
    InputError
        A forgetting factor outside (0, 1], an unknown form, a bad window,
        a P0 that is not symmetric positive definite, bad shapes.
    """
    phi = finite_matrix("phi", phi)
    y = finite_matrix("y", y)
    n, n_p = phi.shape
    n_y = y.shape[1]
    if y.shape[0] != n:
        raise InputError(f"phi has {n} rows but y has {y.shape[0]}: lengths must match")
    lam = forgetting_factor(forgetting)
    if form not in FORMS:
        raise InputError(f"unknown RLS form {form!r}; use one of {', '.join(FORMS)}")
    theta = np.zeros((n_p, n_y)) if theta0 is None else finite_matrix("theta0", theta0).reshape(n_p, n_y).copy()
    if P0 is None or np.isscalar(P0):
        scale = DEFAULT_P0 if P0 is None else float(P0)
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"P0 must be positive; got {P0!r}")
        P = scale * np.eye(n_p)
    else:
        P = finite_matrix("P0", P0).copy()
        if P.shape != (n_p, n_p):
            raise InputError(f"P0 has shape {P.shape}; expected {(n_p, n_p)}")
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        raise InputError("P0 must be symmetric positive definite") from None
    start = 0
    if window is not None:
        window = non_negative_int(window, "window")
        if form != "plain" or lam != 1.0:
            raise InputError("the rectangular window is implemented for the plain form with forgetting = 1")
        if not n_p <= window <= n:
            raise InputError(f"the window must hold between {n_p} (the parameters) and {n} (the record) samples; got {window}")
        first = least_squares(phi[:window], y[:window])
        theta = first.theta.copy()
        P = first.gram_inverse.copy()
        start = window
    history = np.zeros((n, n_p, n_y)) if keep_history else np.zeros((0, n_p, n_y))
    errors = np.zeros((n, n_y))
    trace = np.zeros(n)
    dot, outer = np.dot, np.outer
    if form == "sqrt":
        factor = np.linalg.cholesky(P)
    elif form == "ud":
        U, d = ud_factor(P)
    for k in range(start, n):
        if form == "plain":
            # rls_step inlined, updating in place: the per-call overhead dominates at these sizes
            f = phi[k]
            p_phi = dot(P, f)
            gain = p_phi / (lam + dot(f, p_phi))
            errors[k] = y[k] - dot(f, theta)
            theta += outer(gain, errors[k])
            P -= outer(gain, p_phi)
            if lam != 1.0:
                P /= lam
            if k % _SYMMETRISE_EVERY == 0:
                P = 0.5 * (P + P.T)
            if window is not None:
                theta, P = _downdate(theta, P, phi[k - window], y[k - window])
            trace[k] = P.trace()
        elif form == "sqrt":
            theta, factor, _, errors[k] = sqrt_step(theta, factor, phi[k], y[k], lam)
            trace[k] = np.sum(factor**2)
        else:
            theta, U, d, _, errors[k] = ud_step(theta, U, d, phi[k], y[k], lam)
            trace[k] = np.sum(U**2 @ d)
        if keep_history:
            history[k] = theta
    if keep_history and start:
        history[:start] = theta if window is None else first.theta
    if form == "plain":
        P = 0.5 * (P + P.T)
    elif form == "sqrt":
        P = factor @ factor.T
    elif form == "ud":
        P = ud_covariance(U, d)
    return RecursiveResult(theta, P, history, errors, trace, form, lam, window)


def estimate_arx_recursive(data_or_arrays: Any, *, na: int, nb: Any = None, nk: Any = 0,
                           forgetting: float = 1.0, window: int | None = None, form: str = "plain",
                           P0: Any = None, theta0: Any = None, keep_history: bool = True) -> RecursiveResult:
    """Estimate an ARX model (orders as :func:`~identification.classical.least_squares.estimate_arx`) by RLS.

    Parameters
    ----------
    data_or_arrays : IOData, (u, y)
        Time-major inputs (N, n_u) and outputs (N, n_y).
    na : int
        Output lags.
    nb : int or sequence of int, optional
        Coefficients per input (default ``na``).
    nk : int or sequence of int, default 0
        Input delays in samples.
    forgetting : float, default 1.0
        The forgetting factor, as for :func:`recursive_least_squares`.
    window : int, optional
        A rectangular window's length.
    form : {"plain", "sqrt", "ud"}, default "plain"
        The covariance propagation.
    P0 : float or array_like, optional
        Initial covariance.
    theta0 : array_like, optional
        Initial estimate.
    keep_history : bool, default True
        Keep the estimate after every sample.

    Returns
    -------
    RecursiveResult
        With ``model`` set to the final ARX model.
    """
    u, y, dt = io_arrays(data_or_arrays)
    phi, target, names, k0 = arx_regressors(u, y, na=na, nb=nb, nk=nk)
    na_i, nb_t, nk_t = arx_orders(u.shape[1], y.shape[1], na, nb, nk)
    result = recursive_least_squares(phi, target, forgetting=forgetting, window=window, form=form,
                                     P0=P0, theta0=theta0, keep_history=keep_history)
    model = model_from_theta(result.theta, u.shape[1], y.shape[1], na_i, nb_t, nk_t, dt)
    meta = {"method": "recursive least squares", "first_sample": k0, "regressors": list(names)}
    return RecursiveResult(result.theta, result.covariance, result.history, result.errors, result.trace,
                           form, result.forgetting, window, model, meta)
