"""Generalised least squares (seed appendix A.2.5; Clarke 1967; Soderstrom 1974).

The equation error of an ARX model is coloured, ``A(q) y = B(q) u + xi``,
with ``C(q) xi(k) = w(k)`` white (appendix eq. A.79-A.80) and
``C(q) = 1 + c_1 q^-1 + ... + c_p q^-p``. Filtering both signals by
``C(q)`` whitens the error: ``A(q) y* = B(q) u* + w`` with ``y* = C(q) y``,
``u* = C(q) u`` (eq. A.81-A.83), where plain least squares is unbiased
again. C is unknown, so the appendix iterates (steps 1-6):

1. set ``C = 1`` and estimate A, B by least squares;
2. form the residuals ``xi(k) = A(q) y(k) - B(q) u(k)`` on the raw data;
3. estimate C by least squares on the AR model ``C(q) xi = w``;
4. filter ``y* = C(q) y``, ``u* = C(q) u``;
5. estimate A, B by least squares on ``(u*, y*)``;
6. stop when A, B changed by less than the tolerance, else go to 2.

GLS can converge to a wrong stationary point at low signal-to-noise ratios
(Soderstrom 1974); the result says whether the iteration converged.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..argument_checks import io_arrays, positive_int
from ..errors import InputError
from .least_squares import ArxResult, estimate_arx, least_squares

__all__ = ["GlsResult", "estimate_gls"]


@dataclass(frozen=True, eq=False)
class GlsResult:
    """Generalised least-squares estimate.

    Attributes
    ----------
    arx : ArxResult
        The final A, B fit on the filtered data (its covariance is the
        least-squares one of that whitened regression).
    c : ndarray, shape (p + 1,)
        Noise filter ``1, c_1, ..., c_p``.
    iterations : int
        Passes through steps 2-5.
    converged : bool
        Whether the tolerance was met before the iteration limit.
    history : ndarray, shape (iterations + 1, n_p)
        A, B parameters after step 1 and after each pass.
    """

    arx: ArxResult
    c: np.ndarray
    iterations: int
    converged: bool
    history: np.ndarray

    @property
    def theta(self) -> np.ndarray:
        """Final A, B parameters, shape (n_p, 1)."""
        return self.arx.theta


def estimate_gls(data_or_arrays: Any, *, na: int, nb: Any = None, nk: Any = 0, noise_order: int = 1,
                 iterations: int = 100, tolerance: float = 1e-6) -> GlsResult:
    """Estimate a MISO ARX model with an autoregressive noise filter by generalised least squares.

    Parameters
    ----------
    data_or_arrays : IOData or (u, y)
        One output.
    na : int
        Output lags, as for :func:`~identification.classical.least_squares.estimate_arx`.
    nb : int or sequence of int, optional
        Coefficients per input (default ``na``).
    nk : int or sequence of int, default 0
        Input delays in samples.
    noise_order : int
        The order p of ``C(q)``.
    iterations : int
        Most passes through steps 2-5.
    tolerance : float
        Step 6: stop when ``max |theta_new - theta_old| <= tolerance (1 + max |theta|)``.

    Returns
    -------
    GlsResult
        The final ARX fit, the noise filter and the iterations.

    Raises
    ------
    InputError
        More than one output, bad orders or data.
    ExcitationError
        From the least-squares steps.
    """
    u, y, dt = io_arrays(data_or_arrays)
    if y.shape[1] != 1:
        raise InputError(f"GLS is implemented for one output; got {y.shape[1]} (fit each output alone)")
    p = positive_int(noise_order, "noise_order")
    passes = positive_int(iterations, "iterations")
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"tolerance must be positive; got {tolerance}")
    from scipy.signal import lfilter  # a second to import: paid on first use

    fit = estimate_arx((u, y), na=na, nb=nb, nk=nk)  # step 1
    history = [fit.theta[:, 0].copy()]
    c = np.ones(1)
    converged = False
    done = 0
    for done in range(1, passes + 1):
        xi = y[:, 0] - fit.model.predict(u, y)[:, 0]  # step 2, on the raw data
        xi = xi[fit.meta["first_sample"]:]
        lags = np.column_stack([-xi[p - i: xi.size - i] for i in range(1, p + 1)])
        c = np.concatenate([[1.0], least_squares(lags, xi[p:]).theta[:, 0]])  # step 3
        y_star = lfilter(c, [1.0], y, axis=0)[p:]  # step 4; the first p samples lack history
        u_star = lfilter(c, [1.0], u, axis=0)[p:]
        fit = estimate_arx((u_star, y_star), na=na, nb=nb, nk=nk)  # step 5
        history.append(fit.theta[:, 0].copy())
        change = np.max(np.abs(history[-1] - history[-2]))
        if change <= tolerance * (1.0 + np.max(np.abs(history[-1]))):  # step 6
            converged = True
            break
    model = fit.model.__class__(fit.model.a, fit.model.b, dt)
    arx = ArxResult(model, fit.na, fit.nb, fit.nk, fit.fit, fit.regressor_names,
                    {**fit.meta, "method": "generalised least squares"})
    return GlsResult(arx, c, done, converged, np.array(history))
