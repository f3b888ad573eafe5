"""Fit metrics, per output and averaged over outputs.

``percentage_explanation`` is the paper's R (Best & Bogdanski, eq. 17), ``100 (1 - sum (y - yhat)^2 / sum y^2)``:
the residual against the signal's raw energy, mean included. ``nrmse_fit`` is MATLAB ``compare``'s
``100 (1 - ||y - yhat|| / ||y - mean(y)||)``; ``r_squared`` is ``1 - sum (y - yhat)^2 / sum (y - mean(y))^2``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["percentage_explanation", "nrmse_fit", "nrmse_fit_of_R", "r_squared", "FitMetrics", "fit_metrics"]


def _pair(y: np.ndarray, y_hat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if y_hat.ndim == 1:
        y_hat = y_hat[:, None]
    if y.shape != y_hat.shape:
        raise InputError(f"measured outputs have shape {y.shape} but predictions {y_hat.shape}")
    return y, y_hat


def percentage_explanation(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """The paper's percentage explanation R per output (eq. 17), in percent.

    Parameters
    ----------
    y, y_hat : array_like, shape (N, n_y) or (N,)
        Measured and modelled outputs.

    Returns
    -------
    ndarray, shape (n_y,)
        ``100 (1 - sum (y - y_hat)^2 / sum y^2)`` per output.

    Examples
    --------
    >>> percentage_explanation([1.0, -1.0], [1.0, -0.9]).round(3)
    array([99.5])
    """
    y, y_hat = _pair(y, y_hat)
    energy = np.sum(y**2, axis=0)
    if np.any(energy == 0):
        raise InputError("an output is identically zero: R (eq. 17) is undefined")
    return (1.0 - np.sum((y - y_hat) ** 2, axis=0) / energy) * 100.0


def nrmse_fit(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Compute the NRMSE fit in percent per output, as MATLAB's ``compare`` reports it.

    Parameters
    ----------
    y, y_hat : array_like, shape (N, n_y) or (N,)
        Measured and modelled outputs.

    Returns
    -------
    ndarray, shape (n_y,)
        ``100 (1 - ||y - y_hat|| / ||y - mean(y)||)`` per output.

    Raises
    ------
    InputError
        For a constant output (the fit is undefined).
    """
    y, y_hat = _pair(y, y_hat)
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    if np.any(spread == 0):
        raise InputError("an output is constant: the NRMSE fit is undefined")
    return (1.0 - np.linalg.norm(y - y_hat, axis=0) / spread) * 100.0


def nrmse_fit_of_R(R: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The NRMSE fit (percent, per output) of a prediction whose R (eq. 17) against ``y`` is ``R``.

    Both measure the same squared error, ``(1 - R/100) sum y^2``, against the
    output's energy and its spread about its mean: the identity converts a
    stored R (a filter's pass, a start's fit) to the fit without the
    prediction, provided ``y`` (N, n_y) are the very samples R was taken over.

    Examples
    --------
    >>> y, y_hat = np.array([[1.0], [2.0], [4.0]]), np.array([[1.5], [2.0], [3.5]])
    >>> bool(np.allclose(nrmse_fit_of_R(percentage_explanation(y, y_hat), y), nrmse_fit(y, y_hat)))
    True
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    if np.any(spread == 0):
        raise InputError("an output is constant: the NRMSE fit is undefined")
    error = np.maximum(1.0 - np.asarray(R, dtype=float) / 100.0, 0.0) * np.sum(y**2, axis=0)
    return (1.0 - np.sqrt(error) / spread) * 100.0


def r_squared(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """Compute the coefficient of determination per output.

    Parameters
    ----------
    y, y_hat : array_like, shape (N, n_y) or (N,)
        Measured and modelled outputs.

    Returns
    -------
    ndarray, shape (n_y,)
        ``1 - sum (y - y_hat)^2 / sum (y - mean(y))^2`` per output.
    """
    y, y_hat = _pair(y, y_hat)
    spread = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
    if np.any(spread == 0):
        raise InputError("an output is constant: R^2 is undefined")
    return 1.0 - np.sum((y - y_hat) ** 2, axis=0) / spread


@dataclass(frozen=True)
class FitMetrics:
    """All three metrics per output, with their means over outputs.

    Parameters
    ----------
    percentage_explanation : ndarray, shape (n_y,)
        R (eq. 17), percent.
    nrmse_fit : ndarray, shape (n_y,)
        NRMSE fit, percent.
    r_squared : ndarray, shape (n_y,)
        Coefficient of determination.
    """

    percentage_explanation: np.ndarray
    nrmse_fit: np.ndarray
    r_squared: np.ndarray

    @property
    def mean_percentage_explanation(self) -> float:
        """Mean R over outputs, percent (the handling study's figure)."""
        return float(np.mean(self.percentage_explanation))

    @property
    def mean_nrmse_fit(self) -> float:
        """Mean NRMSE fit over outputs, percent."""
        return float(np.mean(self.nrmse_fit))

    @property
    def mean_r_squared(self) -> float:
        """Mean R^2 over outputs."""
        return float(np.mean(self.r_squared))

    def as_dict(self) -> dict[str, object]:
        """Describe the metrics for JSON.

        Returns
        -------
        dict
            The three metrics per output as lists, and their means.
        """
        return {
            "percentage_explanation": self.percentage_explanation.tolist(),
            "nrmse_fit": self.nrmse_fit.tolist(),
            "r_squared": self.r_squared.tolist(),
            "mean_percentage_explanation": self.mean_percentage_explanation,
            "mean_nrmse_fit": self.mean_nrmse_fit,
            "mean_r_squared": self.mean_r_squared,
        }


def fit_metrics(y: np.ndarray, y_hat: np.ndarray) -> FitMetrics:
    """Compute R (eq. 17), NRMSE fit and R^2 per output.

    Parameters
    ----------
    y, y_hat : array_like, shape (N, n_y) or (N,)
        Measured and modelled outputs.

    Returns
    -------
    FitMetrics
        The three metrics per output.
    """
    return FitMetrics(
        percentage_explanation=percentage_explanation(y, y_hat),
        nrmse_fit=nrmse_fit(y, y_hat),
        r_squared=r_squared(y, y_hat),
    )
