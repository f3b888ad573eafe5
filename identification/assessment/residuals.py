"""Residual analysis: is what the model leaves unexplained white and independent of the input?

The output-error residuals ``e = y - y_hat`` of a model that captures the system are the measurement
noise: white and uncorrelated with the input (Ljung 1999, sec. 16.6; MATLAB's ``resid``).

* Whiteness: the autocorrelation at lags 1..L against the band ``+/- z / sqrt(N)`` and the Ljung-Box
  statistic, chi-square with L degrees of freedom: ``residual_whiteness_p``.
* Independence: the input-residual cross-correlation at lags -L..L against the same band
  (``input_correlation_max``). Neighbouring lags are correlated, so the verdict is the portmanteau
  ``N r' R_u^-1 r`` over the 2L + 1 lags (Ljung 1999, eq. 16.68) per input, Bonferroni-corrected over
  the inputs: ``input_correlation_p``.
* Innovation consistency of a Kalman filter: the mean normalised innovation squared against the
  chi-square band of ``N n_y`` degrees of freedom over N (Bar-Shalom et al. 2001, sec. 5.4).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
# scipy.stats's chi2.sf, chi2.ppf and norm.ppf are these special functions; importing scipy.stats costs most
# of a second of every command's start-up

from ..errors import InputError
from ..frozen import freeze

__all__ = [
    "DEFAULT_LAGS",
    "EXACT_FIT",
    "ResidualTests",
    "autocorrelation",
    "cross_correlation",
    "residual_tests",
    "nis_band",
]

DEFAULT_LAGS = 25  # lags of the tests, MATLAB's resid default
#: Residual RMS, relative to the output's, below which a fit counts as exact (rounding, not noise).
EXACT_FIT = 1e-9


def _columns(name: str, values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2 or array.shape[0] < 2:
        raise InputError(f"{name} must be a (N, columns) array with N >= 2; got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise InputError(f"{name} holds a non-finite value (NaN or inf)")
    return array


def autocorrelation(residuals: Any, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation of each column at lags 0..max_lag, shape (max_lag + 1, n_y).

    ``r(k) / r(0)`` of the mean-removed columns (1 at lag 0).
    """
    e = _columns("residuals", residuals)
    e = e - e.mean(axis=0)
    n = e.shape[0]
    if not (isinstance(max_lag, (int, np.integer)) and 0 < max_lag < n):
        raise InputError(f"max_lag must be an integer in 1..{n - 1}; got {max_lag!r}")
    energy = np.sum(e**2, axis=0)
    if np.any(energy == 0):
        raise InputError("a residual is constant: its autocorrelation is undefined")
    return np.array([np.sum(e[: n - k] * e[k:], axis=0) for k in range(max_lag + 1)]) / energy


def cross_correlation(u: Any, residuals: Any, max_lag: int) -> np.ndarray:
    """Normalised cross-correlation ``r_ue(k)`` at lags -max_lag..max_lag, shape (2 max_lag + 1, n_u, n_y).

    ``r_ue(k) = sum_t u(t - k) e(t) / sqrt(sum u^2 sum e^2)`` of mean-removed
    signals: positive k pairs the residual with past inputs.
    """
    u = _columns("u", u)
    e = _columns("residuals", residuals)
    if u.shape[0] != e.shape[0]:
        raise InputError(f"u has {u.shape[0]} samples but the residuals {e.shape[0]}")
    n = e.shape[0]
    if not (isinstance(max_lag, (int, np.integer)) and 0 < max_lag < n):
        raise InputError(f"max_lag must be an integer in 1..{n - 1}; got {max_lag!r}")
    u = u - u.mean(axis=0)
    e = e - e.mean(axis=0)
    scale = np.sqrt(np.sum(u**2, axis=0)[:, None] * np.sum(e**2, axis=0)[None, :])
    if np.any(scale == 0):
        raise InputError("an input or residual is constant: the cross-correlation is undefined")
    values = np.empty((2 * max_lag + 1, u.shape[1], e.shape[1]))
    for index, k in enumerate(range(-max_lag, max_lag + 1)):
        if k >= 0:
            values[index] = u[: n - k].T @ e[k:]
        else:
            values[index] = u[-k:].T @ e[: n + k]
    return values / scale


@dataclass(frozen=True, eq=False)
class ResidualTests:
    """Whiteness and input-independence tests of residuals, per output.

    Attributes
    ----------
    output_names, input_names : tuple of str
        The channels tested.
    samples, lags : int
        Number of residual samples N, and the largest lag.
    level : float
        Confidence level of the bands (0.99 by default).
    bound : float
        ``z / sqrt(N)``: the band of both correlations.
    autocorrelation : ndarray, shape (lags + 1, n_y)
        ``r_ee(k)`` of each output's residual, lags 0 to ``lags``.
    cross_correlation : ndarray, shape (2 lags + 1, n_u, n_y)
        ``r_ue(k)``, lags ``-lags`` to ``lags``.
    ljung_box : ndarray, shape (n_y,)
        The portmanteau statistic Q.
    residual_whiteness_p : ndarray, shape (n_y,)
        Its p-value (chi-square, ``lags`` degrees of freedom).
    input_correlation_max : ndarray, shape (n_y,)
        Largest ``|r_ue(k)|`` over inputs and lags.
    input_correlation_p : ndarray, shape (n_y,)
        p-value of the cross-correlation portmanteau (smallest over the
        inputs times their number, at most 1).
    exact : ndarray of bool, shape (n_y,)
        Outputs fitted to rounding (residual RMS below :data:`EXACT_FIT` of
        the output's): nothing is left to test; both p-values are 1, the
        largest cross-correlation 0, the correlations and Q NaN.
    """

    output_names: tuple[str, ...]
    input_names: tuple[str, ...]
    samples: int
    lags: int
    level: float
    bound: float
    autocorrelation: np.ndarray
    cross_correlation: np.ndarray
    ljung_box: np.ndarray
    residual_whiteness_p: np.ndarray
    input_correlation_max: np.ndarray
    input_correlation_p: np.ndarray
    exact: np.ndarray

    def __post_init__(self) -> None:
        for name in ("autocorrelation", "cross_correlation", "ljung_box", "residual_whiteness_p",
                     "input_correlation_max", "input_correlation_p", "exact"):
            object.__setattr__(self, name, freeze(np.asarray(getattr(self, name))))  # a test's result stays as found

    @property
    def white(self) -> np.ndarray:
        """Per output: the whiteness test passes (p above ``1 - level``)."""
        return self.residual_whiteness_p >= 1 - self.level

    @property
    def independent(self) -> np.ndarray:
        """Per output: the cross-correlation portmanteau passes (p above ``1 - level``)."""
        return self.input_correlation_p >= 1 - self.level

    @property
    def adequate(self) -> bool:
        """Both tests pass on every output."""
        return bool(np.all(self.white) and np.all(self.independent))

    def as_dict(self) -> dict[str, Any]:
        """Describe the tests for JSON.

        Returns
        -------
        dict
            One object per output with ``residual_whiteness_p`` and ``input_correlation_max``.
        """
        return {
            "lags": self.lags,
            "level": self.level,
            "bound": self.bound,
            "outputs": [
                {
                    "output": name,
                    "residual_whiteness_p": float(self.residual_whiteness_p[i]),
                    "ljung_box": float(self.ljung_box[i]),
                    "input_correlation_max": float(self.input_correlation_max[i]),
                    "input_correlation_p": float(self.input_correlation_p[i]),
                    "white": bool(self.white[i]),
                    "independent": bool(self.independent[i]),
                    "exact": bool(self.exact[i]),
                }
                for i, name in enumerate(self.output_names)
            ],
        }


def residual_tests(
    u: Any,
    residuals: Any,
    *,
    lags: int = DEFAULT_LAGS,
    level: float = 0.99,
    input_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
    output_scale: Any = None,
) -> ResidualTests:
    """Whiteness (autocorrelation, Ljung-Box) and input cross-correlation tests of residuals.

    Parameters
    ----------
    u : array_like, shape (N, n_u)
        The inputs of the record.
    residuals : array_like, shape (N, n_y)
        Measured minus modelled outputs.
    lags : int
        Largest lag in samples (default 25).
    level : float
        Confidence level of the bands (default 0.99).
    input_names, output_names : sequence of str, optional
        Channel names; ``u1, ...`` and ``y1, ...`` by default.
    output_scale : array_like, shape (n_y,), optional
        RMS of each measured output: an output whose residual RMS is below
        :data:`EXACT_FIT` of it is fitted exactly (noise-free data and the
        right model), and its rounding-level residuals are not tested.

    Returns
    -------
    ResidualTests
        Correlations, bands and p-values per output.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> tests = residual_tests(rng.standard_normal((5000, 1)), rng.standard_normal((5000, 1)))
    >>> bool(tests.adequate)
    True
    """
    from scipy.special import chdtrc, ndtri  # imported where used: scipy's start costs half a second
    if not 0 < level < 1:
        raise InputError(f"level must lie between 0 and 1; got {level!r}")
    e = _columns("residuals", residuals)
    u = _columns("u", u)
    n = e.shape[0]
    if n <= 2 * lags:
        raise InputError(f"{n} samples are too few for residual tests at {lags} lags")
    exact = np.zeros(e.shape[1], dtype=bool)
    if output_scale is not None:
        exact = np.sqrt(np.mean(e**2, axis=0)) < EXACT_FIT * np.asarray(output_scale, dtype=float).ravel()
    tested = ~exact
    r_e = np.full((lags + 1, e.shape[1]), np.nan)
    r_ue = np.full((2 * lags + 1, u.shape[1], e.shape[1]), np.nan)
    statistic = np.full(e.shape[1], np.nan)
    whiteness_p = np.ones(e.shape[1])
    correlation_p = np.ones(e.shape[1])
    if np.any(tested):
        r_e[:, tested] = autocorrelation(e[:, tested], lags)
        r_ue[:, :, tested] = cross_correlation(u, e[:, tested], lags)
        k = np.arange(1, lags + 1)
        statistic[tested] = n * (n + 2) * np.sum(r_e[1:, tested] ** 2 / (n - k)[:, None], axis=0)
        whiteness_p[tested] = chdtrc(lags, statistic[tested])
        correlation_p[tested] = _cross_correlation_p(u, r_ue[:, :, tested], n)
    return ResidualTests(
        output_names=tuple(output_names) if output_names else tuple(f"y{i + 1}" for i in range(e.shape[1])),
        input_names=tuple(input_names) if input_names else tuple(f"u{i + 1}" for i in range(u.shape[1])),
        samples=n,
        lags=lags,
        level=level,
        bound=float(ndtri(0.5 + level / 2) / np.sqrt(n)),
        autocorrelation=r_e,
        cross_correlation=r_ue,
        ljung_box=statistic,
        residual_whiteness_p=whiteness_p,
        input_correlation_max=np.where(exact, 0.0, np.abs(np.nan_to_num(r_ue)).max(axis=(0, 1))),
        input_correlation_p=correlation_p,
        exact=exact,
    )


def _cross_correlation_p(u: np.ndarray, r_ue: np.ndarray, samples: int) -> np.ndarray:
    """p-value per output of ``N r' R_u^-1 r`` over the lags, Bonferroni over the inputs.

    ``R_u`` (the input's normalised autocorrelation as a Toeplitz matrix) is
    inverted on its well-determined subspace (eigenvalues above 1e-8 of the
    largest): a smooth input sampled fast makes neighbouring lags nearly
    equal, and the degrees of freedom are the directions kept.
    """
    from scipy.special import chdtrc  # imported where used: scipy's start costs half a second
    import scipy.linalg  # half a second to import: paid where used, not at every command's start
    width = r_ue.shape[0]
    p_values = np.ones((u.shape[1], r_ue.shape[2]))
    for j in range(u.shape[1]):
        r_u = autocorrelation(u[:, [j]], width - 1)[:, 0]
        values, vectors = scipy.linalg.eigh(scipy.linalg.toeplitz(r_u))  # numpy's took 0.2 s at 51 x 51 under load
        kept = values > 1e-8 * values[-1]
        projected = vectors[:, kept].T @ r_ue[:, j, :]  # (kept, n_y)
        statistic = samples * np.sum(projected**2 / values[kept][:, None], axis=0)
        p_values[j] = chdtrc(int(kept.sum()), statistic)
    return np.minimum(p_values.min(axis=0) * u.shape[1], 1.0)


def nis_band(samples: int, n_y: int, *, level: float = 0.99) -> tuple[float, float]:
    """The two-sided band of the mean normalised innovation squared over ``samples`` steps.

    For a consistent filter ``sum_k e_k' S_k^-1 e_k`` is chi-square with
    ``samples n_y`` degrees of freedom; the band of its mean is that
    distribution's ``(1 - level)/2`` and ``(1 + level)/2`` quantiles over ``samples``.
    """
    dof = samples * n_y
    return _chi2_quantile((1 - level) / 2, dof) / samples, _chi2_quantile((1 + level) / 2, dof) / samples


def _chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square distribution's ``probability`` quantile (``scipy.stats.chi2.ppf``)."""
    from scipy.special import gammaincinv  # imported where used: scipy's start costs half a second
    return 2.0 * float(gammaincinv(dof / 2.0, probability))
