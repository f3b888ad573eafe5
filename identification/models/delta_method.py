"""What a model's parameter covariance says of its modes, gains and frequency response: the delta method.

A model carries the covariance of its parameter vector (``parameter_covariance``; how each estimator
finds it: :mod:`vehid.identification.assessment.uncertainty`). The quantities that follow from the
parameters, each mode's eigenvalue, natural frequency and damping, the steady-state gain and the
frequency response, get standard deviations from the first-order propagation ``J P J'`` with the exact
CasADi Jacobian ``J`` of the quantity, and intervals from the normal quantile of their level.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..errors import InputError

__all__ = [
    "ModeEstimate",
    "ModelUncertainty",
    "FrequencyResponseBand",
    "checked_covariance",
    "normal_quantile",
    "model_uncertainty",
    "frequency_response_band",
    "sample_parameters",
]


def normal_quantile(level: float) -> float:
    """``z`` of a two-sided interval ``+/- z sigma`` holding ``level`` of a normal distribution."""
    if not 0 < level < 1:
        raise InputError(f"a confidence level lies between 0 and 1; got {level!r}")
    from scipy.special import ndtri  # scipy.stats.norm.ppf, without scipy.stats's import time
    return float(ndtri(0.5 + level / 2))


def checked_covariance(covariance: Any, size: int) -> np.ndarray:
    """A finite, symmetric (size, size) covariance, read-only; InputError otherwise."""
    array = np.array(covariance, dtype=float)
    if array.shape != (size, size):
        raise InputError(f"the parameter covariance has shape {array.shape}; the model has {size} parameters")
    if not np.all(np.isfinite(array)):
        raise InputError("the parameter covariance holds a non-finite value")
    scale = max(float(np.abs(array).max()), 1e-300)
    if not np.allclose(array, array.T, rtol=0, atol=1e-8 * scale):
        raise InputError("the parameter covariance is not symmetric")
    array = 0.5 * (array + array.T)
    array.setflags(write=False)
    return array


def _spread(jacobian: np.ndarray, covariance: np.ndarray | None) -> np.ndarray:
    """Standard deviations of ``g`` by the delta method (NaN without a covariance)."""
    if covariance is None:
        return np.full(jacobian.shape[0], np.nan)
    variance = np.einsum("ij,jk,ik->i", jacobian, covariance, jacobian)
    return np.sqrt(np.maximum(variance, 0.0))


@functools.lru_cache(maxsize=64)
def _mode_function(structure: Any) -> ca.Function:
    """theta -> [re, im, frequency (Hz), damping] of every mode, and their exact Jacobian."""
    theta = ca.SX.sym("theta", structure.n_parameters)
    re, im = [], []
    for pair in range(structure.n_complex_pairs):
        re.append(theta[2 * pair])
        im.append(ca.fabs(theta[2 * pair + 1]))
    for pole in range(structure.n_real):
        re.append(theta[2 * structure.n_complex_pairs + pole])
        im.append(ca.SX(0))
    re, im = ca.vertcat(*re), ca.vertcat(*im)
    natural = ca.sqrt(re**2 + im**2)
    values = ca.vertcat(re, im, natural / (2 * np.pi), -re / natural)
    return ca.Function("vehid_modes", [theta], [values, ca.jacobian(values, theta)], ["theta"], ["g", "J"])


@functools.lru_cache(maxsize=64)
def _gain_function(structure: Any) -> ca.Function:
    """theta -> the steady-state gain ``D - C A^-1 B`` (column-major) and its exact Jacobian."""
    theta = ca.SX.sym("theta", structure.n_parameters)
    A, B, C, D = structure.matrices(theta, backend=ca.SX)
    gain = ca.vec(D - ca.mtimes(C, ca.solve(A, B)))
    return ca.Function("vehid_gain", [theta], [gain, ca.jacobian(gain, theta)], ["theta"], ["g", "J"])


@functools.lru_cache(maxsize=64)
def _response_function(structure: Any) -> ca.Function:
    """(theta, w) -> magnitude and phase (rad) of ``G(j w)`` (column-major) and their exact Jacobians.

    ``(j w I - A) X = B`` is solved in real arithmetic as the 2n system
    ``[[-A, -w I], [w I, -A]] [Re X; Im X] = [B; 0]``.
    """
    n = structure.n
    theta = ca.SX.sym("theta", structure.n_parameters)
    w = ca.SX.sym("w")
    A, B, C, D = structure.matrices(theta, backend=ca.SX)
    eye = ca.SX.eye(n)
    system = ca.vertcat(ca.horzcat(-A, -w * eye), ca.horzcat(w * eye, -A))
    solution = ca.solve(system, ca.vertcat(B, ca.SX.zeros(n, structure.n_u)))
    real = ca.vec(ca.mtimes(C, solution[:n, :]) + D)
    imag = ca.vec(ca.mtimes(C, solution[n:, :]))
    magnitude = ca.sqrt(real**2 + imag**2)
    phase = ca.atan2(imag, real)
    return ca.Function(
        "vehid_response", [theta, w],
        [magnitude, phase, ca.jacobian(magnitude, theta), ca.jacobian(phase, theta)],
        ["theta", "w"], ["magnitude", "phase", "J_magnitude", "J_phase"],
    )


@functools.lru_cache(maxsize=64)
def _mapped_response_function(structure: Any, count: int) -> ca.Function:
    """:func:`_response_function` evaluated at ``count`` frequencies in one call."""
    return _response_function(structure).map(count)


@dataclass(frozen=True, eq=False)
class ModeEstimate:
    """One mode's eigenvalue, natural frequency and damping with their standard deviations.

    Attributes
    ----------
    eigenvalue : complex
        ``sigma + j|omega|`` (1/s) for a pair (the upper one), real for a real pole.
    eigenvalue_std : tuple of float
        Standard deviations of its real and imaginary parts.
    eigenvalue_covariance : ndarray, shape (2, 2)
        Covariance of its real and imaginary parts (for the pole map's ellipses).
    frequency_hz, frequency_hz_std : float
        Natural frequency (Hz) and its standard deviation.
    damping, damping_std : float
        Damping ratio and its standard deviation.
    level : float
        Confidence level of :meth:`interval`.
    """

    eigenvalue: complex
    eigenvalue_std: tuple[float, float]
    eigenvalue_covariance: np.ndarray
    frequency_hz: float
    frequency_hz_std: float
    damping: float
    damping_std: float
    level: float

    def interval(self, name: str) -> tuple[float, float]:
        """Return the confidence interval of the frequency or the damping at :attr:`level`.

        Parameters
        ----------
        name : {"frequency_hz", "damping"}
            The quantity.

        Returns
        -------
        tuple of float
            ``(value - z std, value + z std)``.
        """
        if name not in ("frequency_hz", "damping"):
            raise InputError(f"intervals are given for frequency_hz and damping; got {name!r}")
        value, std = getattr(self, name), getattr(self, f"{name}_std")
        z = normal_quantile(self.level)
        return value - z * std, value + z * std

    def as_dict(self) -> dict[str, Any]:
        """Describe the mode for JSON.

        Returns
        -------
        dict
            ``eigenvalue`` and ``eigenvalue_std`` as [re, im], frequency and damping with their std.
        """
        return {
            "eigenvalue": [float(self.eigenvalue.real), float(self.eigenvalue.imag)],
            "eigenvalue_std": [float(v) for v in self.eigenvalue_std],
            "frequency_hz": float(self.frequency_hz),
            "frequency_hz_std": float(self.frequency_hz_std),
            "damping": float(self.damping),
            "damping_std": float(self.damping_std),
        }


@dataclass(frozen=True, eq=False)
class ModelUncertainty:
    """Modes and steady-state gains of a model with standard deviations (delta method).

    Attributes
    ----------
    modes : tuple of ModeEstimate
        Pairs first, then real poles, as the structure orders its modes.
    gain, gain_std : ndarray, shape (n_y, n_u)
        Steady-state gain ``D - C A^-1 B`` and its standard deviation.
    level : float
        Confidence level of the intervals.
    """

    modes: tuple[ModeEstimate, ...]
    gain: np.ndarray
    gain_std: np.ndarray
    level: float


@dataclass(frozen=True, eq=False)
class FrequencyResponseBand:
    """A frequency response with delta-method bands.

    Attributes
    ----------
    frequencies_hz : ndarray, shape (F,)
        Frequencies (Hz).
    magnitude, magnitude_std : ndarray, shape (F, n_y, n_u)
        Magnitude, linear (output units per input unit), and its standard deviation.
    phase_deg, phase_deg_std : ndarray, shape (F, n_y, n_u)
        Phase in degrees, unwrapped along frequency, and its standard deviation.
    level : float
        Confidence level of the bands.
    """

    frequencies_hz: np.ndarray
    magnitude: np.ndarray
    magnitude_std: np.ndarray
    phase_deg: np.ndarray
    phase_deg_std: np.ndarray
    level: float

    def normal_quantile(self) -> float:
        """Return the normal quantile ``z`` of the bands.

        Returns
        -------
        float
            ``z`` such that ``value +/- z std`` holds :attr:`level`.
        """
        return normal_quantile(self.level)

    def magnitude_band(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the magnitude band at :attr:`level`.

        Returns
        -------
        tuple of ndarray
            Lower and upper magnitude, shape (F, n_y, n_u); the lower one floored just above zero for log axes.
        """
        z = normal_quantile(self.level)
        lower = np.maximum(self.magnitude - z * self.magnitude_std, 1e-3 * self.magnitude)
        return lower, self.magnitude + z * self.magnitude_std


def model_uncertainty(model: Any, *, level: float = 0.95) -> ModelUncertainty:
    """Estimate the modes and steady-state gains of ``model`` with their standard deviations by the delta method.

    Parameters
    ----------
    model : ModalModel
        Its :attr:`~identification.models.modal.ModalModel.parameter_covariance` is
        propagated; without one every standard deviation is NaN.
    level : float
        Confidence level of the intervals (default 0.95).

    Returns
    -------
    ModelUncertainty
        The modes (pairs first) and the gain ``D - C A^-1 B``, with standard deviations.
    """
    normal_quantile(level)
    structure = model.structure
    theta = model.parameters
    covariance = model.parameter_covariance
    values, jacobian = (np.asarray(v) for v in _mode_function(structure)(theta))
    values = values.ravel()
    std = _spread(jacobian, covariance)
    count = structure.n_complex_pairs + structure.n_real
    modes = []
    for mode in range(count):
        rows = [mode, count + mode]
        if covariance is None:
            block = np.full((2, 2), np.nan)
        else:
            block = jacobian[rows] @ covariance @ jacobian[rows].T
        modes.append(ModeEstimate(
            eigenvalue=complex(values[mode], values[count + mode]),
            eigenvalue_std=(float(std[mode]), float(std[count + mode])),
            eigenvalue_covariance=block,
            frequency_hz=float(values[2 * count + mode]),
            frequency_hz_std=float(std[2 * count + mode]),
            damping=float(values[3 * count + mode]),
            damping_std=float(std[3 * count + mode]),
            level=level,
        ))
    shape = (structure.n_y, structure.n_u)
    gain, gain_jacobian = (np.asarray(v) for v in _gain_function(structure)(theta))
    gain_std = _spread(gain_jacobian, covariance)  # a pole at the origin leaves both non-finite
    return ModelUncertainty(
        modes=tuple(modes),
        gain=np.asarray(gain).ravel().reshape(shape, order="F"),
        gain_std=gain_std.reshape(shape, order="F"),
        level=level,
    )


def frequency_response_band(model: Any, frequencies_hz: Any, *, level: float = 0.95) -> FrequencyResponseBand:
    """Magnitude and phase of ``model`` at ``frequencies_hz`` with delta-method standard deviations.

    Parameters
    ----------
    model : ModalModel
    frequencies_hz : array_like, shape (n_f,)
        Frequencies in Hz (non-negative).
    level : float
        Confidence level of the bands.

    Returns
    -------
    FrequencyResponseBand
    """
    normal_quantile(level)
    frequencies = np.asarray(frequencies_hz, dtype=float).ravel()
    if frequencies.size == 0 or not np.all(np.isfinite(frequencies)) or np.any(frequencies < 0):
        raise InputError("frequencies must be finite, non-negative and at least one")
    structure = model.structure
    function = _mapped_response_function(structure, frequencies.size)
    magnitude, phase, j_magnitude, j_phase = (np.asarray(v) for v in function(model.parameters, 2 * np.pi * frequencies))
    n_g, n_theta = structure.n_y * structure.n_u, structure.n_parameters
    shape = (frequencies.size, structure.n_y, structure.n_u)
    covariance = model.parameter_covariance

    def spread(jacobian: np.ndarray) -> np.ndarray:
        # the map lays each frequency's (n_g, n_theta) Jacobian side by side: rows (frequency, gain) at once
        rows = jacobian.reshape(n_g, frequencies.size, n_theta).transpose(1, 0, 2).reshape(-1, n_theta)
        return _spread(rows, covariance).reshape(frequencies.size, n_g)

    magnitude_std, phase_std = spread(j_magnitude), spread(j_phase)
    phase = np.unwrap(phase.T, axis=0)

    def arranged(values: np.ndarray) -> np.ndarray:
        return values.reshape(frequencies.size, structure.n_u, structure.n_y).transpose(0, 2, 1).reshape(shape)

    return FrequencyResponseBand(
        frequencies_hz=frequencies,
        magnitude=arranged(magnitude.T),
        magnitude_std=arranged(magnitude_std),
        phase_deg=arranged(np.degrees(phase)),
        phase_deg_std=arranged(np.degrees(phase_std)),
        level=level,
    )


def sample_parameters(model: Any, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` parameter vectors drawn from N(parameters, parameter_covariance), shape (count, n_theta)."""
    if model.parameter_covariance is None:
        raise InputError("the model carries no parameter covariance to sample")
    import scipy.linalg  # half a second to import: paid where it is used, not by every command's start
    values, vectors = scipy.linalg.eigh(model.parameter_covariance)
    root = vectors * np.sqrt(np.maximum(values, 0.0))
    return model.parameters + rng.standard_normal((count, values.size)) @ root.T
