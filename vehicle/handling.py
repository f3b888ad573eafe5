"""Handling characteristics of any linear model of a car, and of the 23-state source model itself.

The metrics follow the open-loop test methods engineers report a car by:

* steady state, in the manner of ISO 4138 (steady-state circular driving):
  yaw-rate gain ``r/delta`` (1/s), lateral-acceleration gain ``a_y/delta``
  (m/s^2 per rad), sideslip gain ``beta/delta`` where sideslip is an output,
  and the understeer gradient ``K`` from ``delta - L r / V = K a_y``
  (Gillespie, Fundamentals of Vehicle Dynamics, 1992, eq. 6-14 with the
  Ackermann angle ``L / R = L r / V``): ``K = (1 - L G_r / V) / G_a`` per unit
  steer, reported in deg/g (``K g 180 / pi``), with the characteristic speed
  ``sqrt(L / K)`` of an understeering car (where the yaw-rate gain peaks) or
  the critical speed ``sqrt(-L / K)`` of an oversteering one;
* step steer, in the manner of ISO 7401 (lateral transient response): time
  origin at 50 % of the steer step, yaw-rate response time to 90 % of its
  steady value, peak response time (first peak; NaN for a response without
  overshoot), overshoot ``(peak - steady) / steady``, and the lateral
  acceleration's response time;
* frequency response, also ISO 7401: yaw-rate gain (1/s) and phase (deg) at
  1 Hz, lateral acceleration's phase at 1 Hz, and the yaw-rate bandwidth, the
  lowest frequency where the gain falls 3 dB below its steady value.

:func:`handling_metrics` computes them from any model meeting the model
protocol (``to_statespace``, continuous or discrete time) whose outputs include
yaw rate, given which output is which and the wheelbase where the understeer
gradient needs it; from a scheduled model (one offering ``model_at(V)``) at
each requested speed. Where the model carries a parameter covariance and can
be rebuilt from its parameters (``parameters``, ``parameter_covariance`` and
either ``with_parameters(theta)`` or the modal models' ``from_parameters``),
each metric's standard deviation follows by the delta method, the Jacobian by
central differences (:func:`vehid.identification.assessment.uncertainty.propagate_by_differences`).

:func:`source_handling` does the same for the source model: its exact
linearisation at each speed (heading, which is ignorable, removed), and its
nonlinear simulation under an ISO 7401 step, a 1 Hz sine dwell and a sine sweep.
:func:`source_steady_state` gives the source model's steady-state gains and
understeer gradient over a stated range of lateral acceleration (ISO 4138,
constant speed with steer steps), the reference for a linear model fitted on
data that reach that range: the linearisation holds at zero lateral
acceleration only, and the tyres' and load transfer's nonlinearity raises the
baseline car's understeer gradient from 0.69 deg/g there to 0.79-0.82 deg/g
over +/-4 m/s^2 (10-30 m/s).

Units: steer in rad at the road wheel, yaw rate rad/s, lateral acceleration
m/s^2, sideslip rad, unless ``scales`` says how a model's channels convert
(e.g. a steering-wheel angle in degrees with ratio 16: ``pi / 180 / 16``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable, Mapping, Sequence

import numpy as np
from scipy.linalg import expm
from scipy.optimize import brentq

from vehid.identification.errors import ConversionError, InputError
from vehid.identification.assessment.uncertainty import propagate_by_differences

from .parameters import GRAVITY, VehicleParameters, named_vehicle

__all__ = [
    "HandlingMetrics",
    "HandlingResponse",
    "PLOTTED_METRICS",
    "METRIC_UNITS",
    "handling_metrics",
    "linear_handling",
    "source_handling",
    "SourceHandling",
    "SteadyStateHandling",
    "ISO_7401_LATERAL_ACCELERATION",
    "source_steady_state",
]

#: Each metric with its unit, in the order they are reported.
METRIC_UNITS: Mapping[str, str] = MappingProxyType({
    "yaw_rate_gain": "1/s",
    "lateral_acceleration_gain": "m/s^2/rad",
    "sideslip_gain": "rad/rad",
    "understeer_gradient_deg_per_g": "deg/g",
    "characteristic_speed_m_s": "m/s",
    "critical_speed_m_s": "m/s",
    "yaw_rate_response_time_s": "s",
    "yaw_rate_peak_response_time_s": "s",
    "yaw_rate_overshoot": "-",
    "lateral_acceleration_response_time_s": "s",
    "yaw_rate_gain_1hz": "1/s",
    "yaw_rate_phase_1hz_deg": "deg",
    "lateral_acceleration_phase_1hz_deg": "deg",
    "yaw_rate_bandwidth_hz": "Hz",
})
_RAD_PER_MPS2_TO_DEG_PER_G = GRAVITY * 180.0 / math.pi
ISO_7401_LATERAL_ACCELERATION = 4.0  # [m/s^2] ISO 7401's steady-state level for the step steer test
_RESPONSE_LEVEL = 0.9  # ISO 7401: response time to 90 % of the steady-state value
_BANDWIDTH_RATIO = 1.0 / math.sqrt(2.0)  # -3 dB
_STEP_POINTS = 20000  # samples of a continuous model's step response: 0.05-1.5 ms apart over its 1-30 s horizon
_OVERSHOOT_FLOOR = 1e-6  # a peak this little above the steady value is round-off, not overshoot


@dataclass(frozen=True)
class HandlingMetrics:
    """Handling metrics of one model at one speed: a frozen value (units in :data:`METRIC_UNITS`).

    Attributes
    ----------
    speed : float
        Speed (m/s) at which they hold.
    source : str
        What they come from: ``model``, ``linearisation`` or ``simulation``.
    yaw_rate_gain ... yaw_rate_bandwidth_hz : float
        The metrics (module notes); NaN where the model cannot give one
        (no sideslip output, no wheelbase for the understeer gradient, no
        overshoot for a peak time).
    std : mapping of str to float
        Standard deviation of each metric by the delta method; NaN without a
        parameter covariance.
    """

    speed: float
    source: str
    yaw_rate_gain: float
    lateral_acceleration_gain: float
    sideslip_gain: float
    understeer_gradient_deg_per_g: float
    characteristic_speed_m_s: float
    critical_speed_m_s: float
    yaw_rate_response_time_s: float
    yaw_rate_peak_response_time_s: float
    yaw_rate_overshoot: float
    lateral_acceleration_response_time_s: float
    yaw_rate_gain_1hz: float
    yaw_rate_phase_1hz_deg: float
    lateral_acceleration_phase_1hz_deg: float
    yaw_rate_bandwidth_hz: float
    std: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        std = {name: float(dict(self.std).get(name, math.nan)) for name in METRIC_UNITS}
        object.__setattr__(self, "std", MappingProxyType(std))

    @property
    def understeer_gradient(self) -> float:
        """K in rad per (m/s^2)."""
        return self.understeer_gradient_deg_per_g / _RAD_PER_MPS2_TO_DEG_PER_G

    def values(self) -> np.ndarray:
        """The metrics as a vector, in :data:`METRIC_UNITS` order."""
        return np.array([getattr(self, name) for name in METRIC_UNITS])

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: ``speed``, ``source`` and each metric as ``{value, std, unit}`` (NaN as None)."""
        def number(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return {"speed": self.speed, "source": self.source,
                **{name: {"value": number(getattr(self, name)), "std": number(self.std[name]), "unit": unit}
                   for name, unit in METRIC_UNITS.items()}}


#: The metrics a handling figure shows unless told otherwise: the steady gains and the understeer gradient.
PLOTTED_METRICS = ("yaw_rate_gain", "lateral_acceleration_gain", "understeer_gradient_deg_per_g")


@dataclass(frozen=True)
class HandlingResponse:
    """Handling metrics of one model at each speed: a frozen value with the data as attributes and ``.plot()``.

    It unpacks, iterates and indexes as the tuple of :class:`HandlingMetrics` it holds (what
    :func:`handling_metrics` returned before it returned this value): ``(at_20,) = handling_metrics(...)``.

    Parameters
    ----------
    metrics : tuple of HandlingMetrics
        One per speed, in the order asked.
    label : str
        How the figure names the model.

    Examples
    --------
    >>> from vehid.identification import ContinuousModel
    >>> bicycle = ContinuousModel([[-6.0, -18.2], [1.08, -6.804]], [[53.33], [38.4]], [[0.0, 1.0]], [[0.0]],
    ...                           input_names=("steer",), output_names=("yaw_rate",))  # at 20 m/s
    >>> response = handling_metrics(bicycle, 20.0, wheelbase=2.7)
    >>> response.speeds, response.value("yaw_rate_gain").round(3)  # V / (L + K V^2) = 20 / (2.7 + 1.5)
    (array([20.]), array([4.762]))
    >>> fig = response.plot()
    """

    metrics: tuple[HandlingMetrics, ...]
    label: str = "model"

    def __post_init__(self) -> None:
        object.__setattr__(self, "metrics", tuple(self.metrics))

    def __iter__(self) -> Any:
        return iter(self.metrics)

    def __len__(self) -> int:
        return len(self.metrics)

    def __getitem__(self, index: Any) -> Any:
        return self.metrics[index]

    @property
    def speeds(self) -> np.ndarray:
        """The speeds (m/s), one per metrics entry."""
        return np.array([m.speed for m in self.metrics])

    def value(self, name: str) -> np.ndarray:
        """One metric (a name of :data:`METRIC_UNITS`) at each speed, in its unit; NaN where the model has none.

        Parameters
        ----------
        name : str

        Returns
        -------
        ndarray (n_speeds,)
        """
        return np.array([getattr(m, _metric_name(name)) for m in self.metrics])

    def std(self, name: str) -> np.ndarray:
        """The standard deviation of one metric at each speed (NaN without a parameter covariance).

        Parameters
        ----------
        name : str

        Returns
        -------
        ndarray (n_speeds,)
        """
        return np.array([m.std[_metric_name(name)] for m in self.metrics])

    def as_dict(self) -> list[dict[str, Any]]:
        """JSON-ready: each speed's :meth:`HandlingMetrics.as_dict`."""
        return [m.as_dict() for m in self.metrics]

    def plot(self, names: Sequence[str] = PLOTTED_METRICS, *, ax: Any = None, label: str | None = None,
             title: str | None = None) -> Any:
        """The metrics against speed with bands of two standard deviations where known.

        Parameters
        ----------
        names : sequence of str
            The metrics (:data:`METRIC_UNITS`), one panel each.
        ax : matplotlib Axes or sequence of Axes, optional
            One per metric (for instance a figure's ``axes`` to draw a second model beside the first).
            Default: a new Figure, leaving out the metrics the model does not have.
        label : str, optional
            The line's legend entry; default :attr:`label`.
        title : str, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from .handling_figure import plot_handling

        return plot_handling({label or self.label: self.metrics}, names, METRIC_UNITS, ax=ax, title=title)


def _metric_name(name: str) -> str:
    if name not in METRIC_UNITS:
        raise InputError(f"unknown handling metric {name!r}; use {', '.join(METRIC_UNITS)}")
    return name


def _metrics_from_vector(speed: float, source: str, vector: np.ndarray, std: np.ndarray | None) -> HandlingMetrics:
    names = list(METRIC_UNITS)
    return HandlingMetrics(speed, source, *(float(v) for v in vector),
                           std={} if std is None else dict(zip(names, (float(s) for s in std))))


# ---------------------------------------------------------------------------------------------
# Linear models
# ---------------------------------------------------------------------------------------------

def _transfer(A, B, C, D, dt, f_hz: np.ndarray) -> np.ndarray:
    """``H(f)`` (n_f, n_y) of the one input B (n,): ``C (sI - A)^-1 B + D``, ``z = exp(s dt)`` if discrete."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    points = s if dt is None else np.exp(s * dt)
    systems = points[:, None, None] * np.eye(A.shape[0])[None] - A[None]  # one batched solve for all frequencies
    right = np.broadcast_to(B.astype(complex), (points.size, B.size))[..., None]
    return np.linalg.solve(systems, right)[..., 0] @ C.T + D[None, :]


def _step_response(A, B, C, D, dt) -> tuple[np.ndarray, np.ndarray]:
    """Unit step response from rest: times (n_t,) and outputs (n_t, n_y), the step at t = 0.

    Continuous time: exact, on a grid of ``_STEP_POINTS`` over ten times the
    slowest time constant (within 1-30 s): by modes, ``x(t) = V diag((exp(l t)
    - 1) / l) V^-1 B``, where A is diagonalisable with a well-conditioned
    eigenvector matrix, else by the exact zero-order-hold step repeated.
    Discrete time: ``x[k] = sum_{j<k} A^j B`` at the model's sample interval,
    by modes likewise.
    """
    eigenvalues, vectors = np.linalg.eig(A)
    if dt is None:
        rates = np.abs(eigenvalues.real)
        rates = rates[rates > 1e-9]
        horizon = float(np.clip(10.0 / rates.min(), 1.0, 30.0)) if rates.size else 30.0
        times = np.linspace(0.0, horizon, _STEP_POINTS + 1)
    else:
        magnitudes = np.abs(eigenvalues)
        slowest = magnitudes[(magnitudes < 1 - 1e-12) & (magnitudes > 0)]
        rate = -np.log(slowest.max()) / dt if slowest.size else 1.0
        times = dt * np.arange(int(math.ceil(float(np.clip(10.0 / rate, 1.0, 30.0)) / dt)) + 1)
    if np.linalg.cond(vectors) < 1e8:
        weights = np.linalg.solve(vectors, B.astype(complex))
        if dt is None:
            exponent = np.outer(times, eigenvalues)
            small = np.abs(eigenvalues) < 1e-12
            with np.errstate(divide="ignore", invalid="ignore"):
                growth = np.where(small, times[:, None], np.expm1(exponent) / np.where(small, 1.0, eigenvalues))
        else:
            steps = np.arange(times.size)[:, None]
            near_one = np.abs(eigenvalues - 1) < 1e-12
            with np.errstate(divide="ignore", invalid="ignore"):
                growth = np.where(near_one, steps, (1 - eigenvalues**steps) / np.where(near_one, 2.0, 1 - eigenvalues))
        states = (growth * weights[None, :]) @ vectors.T
        return times, states.real @ C.T + D[None, :]
    n = A.shape[0]
    if dt is None:
        block = expm(np.block([[A, B[:, None]], [np.zeros((1, n + 1))]]) * (times[1] - times[0]))
        ad, bd = block[:n, :n], block[:n, n]
    else:
        ad, bd = A, B
    states = np.zeros((times.size, n))
    for k in range(times.size - 1):
        states[k + 1] = ad @ states[k] + bd
    return times, states @ C.T + D[None, :]  # the input is 1 from t = 0 on: D acts from the first sample


def _crossing(times: np.ndarray, ratio: np.ndarray, level: float) -> float:
    """First time ``ratio`` reaches ``level`` (linear interpolation between samples), NaN if never."""
    above = np.flatnonzero(ratio >= level)
    if above.size == 0:
        return math.nan
    k = int(above[0])
    if k == 0:
        return float(times[0])
    r0, r1 = ratio[k - 1], ratio[k]
    return float(times[k - 1] + (level - r0) / (r1 - r0) * (times[k] - times[k - 1]))


def _first_peak(times: np.ndarray, ratio: np.ndarray) -> tuple[float, float]:
    """(time, overshoot) of the first local maximum above the steady value; (NaN, 0) without one."""
    interior = (ratio[1:-1] >= ratio[:-2]) & (ratio[1:-1] > ratio[2:]) & (ratio[1:-1] > 1.0 + _OVERSHOOT_FLOOR)
    peaks = np.flatnonzero(interior) + 1
    if peaks.size == 0:
        return math.nan, 0.0
    k = int(peaks[0])
    # a parabola through the three samples places the peak between them
    y0, y1, y2 = ratio[k - 1], ratio[k], ratio[k + 1]
    curvature = y0 - 2 * y1 + y2
    shift = 0.5 * (y0 - y2) / curvature if curvature != 0 else 0.0
    peak = y1 - 0.25 * (y0 - y2) * shift
    return float(times[k] + shift * (times[k + 1] - times[k])), float(peak - 1.0)


def _bandwidth(A, B, C_row, D_row, dt, steady: float) -> float:
    """Lowest frequency (Hz) where ``|H(f)| / |H(0)|`` falls below 1/sqrt(2); NaN if not below 50 Hz (or Nyquist)."""
    top = 50.0 if dt is None else 0.49 / dt
    grid = np.logspace(-2, math.log10(top), 400)
    gain = np.abs(_transfer(A, B, C_row[None, :], np.atleast_1d(D_row), dt, grid)[:, 0]) / abs(steady)
    below = np.flatnonzero(gain < _BANDWIDTH_RATIO)
    if below.size == 0:
        return math.nan
    k = int(below[0])
    if k == 0:
        return float(grid[0])

    def excess(log_f: float) -> float:
        value = _transfer(A, B, C_row[None, :], np.atleast_1d(D_row), dt, np.array([10.0**log_f]))[0, 0]
        return abs(value) / abs(steady) - _BANDWIDTH_RATIO

    return float(10.0 ** brentq(excess, math.log10(grid[k - 1]), math.log10(grid[k]), xtol=1e-10))


def _steady_metrics(speed: float, wheelbase: float | None, yaw_gain: float, lateral_gain: float) -> np.ndarray:
    """Understeer gradient (deg/g), characteristic and critical speeds from the steady gains.

    ``delta - L r / V = K a_y`` per unit steer: ``K = (1 - L G_r / V) / G_a``.
    """
    if wheelbase is None or not math.isfinite(lateral_gain) or lateral_gain == 0:
        return np.full(3, math.nan)
    gradient = (1.0 - wheelbase * yaw_gain / speed) / lateral_gain
    characteristic = math.sqrt(wheelbase / gradient) if gradient > 0 else math.nan
    critical = math.sqrt(-wheelbase / gradient) if gradient < 0 else math.nan
    return np.array([gradient * _RAD_PER_MPS2_TO_DEG_PER_G, characteristic, critical])


def linear_handling(
    A: Any, B: Any, C: Any, D: Any, dt: float | None, *, speed: float, wheelbase: float | None = None,
    yaw_rate: int, lateral_acceleration: int | None = None, sideslip: int | None = None,
) -> np.ndarray:
    """The metrics (vector in :data:`METRIC_UNITS` order) of a one-input linear model.

    Parameters
    ----------
    A, B, C, D : array_like
        State-space matrices, B (n,) or (n, 1) for the steer input, in SI
        units (steer rad, yaw rate rad/s, lateral acceleration m/s^2, sideslip rad).
    dt : float or None
        Sample interval of a discrete model; None for continuous time.
    speed : float
        The speed (m/s) at which the model holds.
    wheelbase : float, optional
        L (m); without it the understeer gradient and the speeds from it are NaN.
    yaw_rate, lateral_acceleration, sideslip : int
        Rows of C for these outputs; without a lateral-acceleration output its
        steady gain is taken as ``V r / delta`` (a steady turn) and its
        transient metrics are NaN.

    An unstable model (an oversteering car above its critical speed) keeps
    its steady-state and frequency-response metrics, those of its unstable
    equilibrium, but has no step metrics (NaN).

    Raises
    ------
    ConversionError
        When the model has a pole at rest (an integrator) or no yaw-rate gain:
        there is no steady state to measure against.
    """
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float).reshape(A.shape[0], -1)[:, 0]
    C = np.asarray(C, dtype=float).reshape(-1, A.shape[0])
    D = np.asarray(D, dtype=float).reshape(C.shape[0], -1)[:, 0]
    rows = [yaw_rate] + [r for r in (lateral_acceleration, sideslip) if r is not None]
    eigenvalues = np.linalg.eigvals(A)
    at_rest = np.abs(eigenvalues if dt is None else eigenvalues - 1)
    if np.any(at_rest < 1e-10 * max(1.0, float(np.max(np.abs(eigenvalues), initial=0.0)))):
        raise ConversionError(f"the model at {speed:g} m/s has a pole at {'zero' if dt is None else 'z = 1'} "
                              "(an integrator): it has no steady state, so no handling metrics")
    steady = _transfer(A, B, C[rows], D[rows], dt, np.array([0.0]))[0].real
    yaw_gain = float(steady[0])
    if yaw_gain == 0 or not math.isfinite(yaw_gain):
        raise ConversionError(f"the model's steady yaw-rate gain at {speed:g} m/s is zero or not finite: "
                              "no handling metrics")
    stable = bool(np.all(eigenvalues.real < 0) if dt is None else np.all(np.abs(eigenvalues) < 1))
    lateral_gain = float(steady[1]) if lateral_acceleration is not None else speed * yaw_gain
    sideslip_gain = float(steady[-1]) if sideslip is not None else math.nan
    steady_metrics = _steady_metrics(speed, wheelbase, yaw_gain, lateral_gain)

    yaw_time = peak_time = overshoot = lateral_time = math.nan  # an unstable model has no step response to time
    if stable:
        times, response = _step_response(A, B, C[rows], D[rows], dt)
        yaw_ratio = response[:, 0] / yaw_gain
        yaw_time = _crossing(times, yaw_ratio, _RESPONSE_LEVEL)
        peak_time, overshoot = _first_peak(times, yaw_ratio)
        lateral_time = (_crossing(times, response[:, 1] / lateral_gain, _RESPONSE_LEVEL)
                        if lateral_acceleration is not None else math.nan)

    one_hz = _transfer(A, B, C[rows], D[rows], dt, np.array([1.0]))[0]
    lateral_phase = math.degrees(np.angle(one_hz[1])) if lateral_acceleration is not None else math.nan
    bandwidth = _bandwidth(A, B, C[yaw_rate], D[yaw_rate], dt, yaw_gain)
    return np.array([
        yaw_gain, lateral_gain, sideslip_gain, *steady_metrics,
        yaw_time, peak_time, overshoot, lateral_time,
        abs(one_hz[0]), math.degrees(np.angle(one_hz[0])), lateral_phase, bandwidth,
    ])


# ---------------------------------------------------------------------------------------------
# Any model meeting the protocol
# ---------------------------------------------------------------------------------------------

def _output_row(names: Sequence[str], wanted: str | None, what: str, required: bool) -> int | None:
    if wanted is None:
        if required:
            raise InputError(f"name the model's {what} output; its outputs are {', '.join(names)}")
        return None
    if wanted not in names:
        raise InputError(f"the model has no output {wanted!r} ({what}); its outputs are {', '.join(names)}")
    return list(names).index(wanted)


def _rebuilder(model: Any) -> Callable[[np.ndarray], Any] | None:
    """theta -> the same model with parameters theta, or None if the model cannot be rebuilt."""
    if getattr(model, "parameter_covariance", None) is None:
        return None
    if hasattr(model, "with_parameters"):
        return model.with_parameters
    if hasattr(type(model), "from_parameters") and hasattr(model, "structure"):
        return lambda theta: type(model).from_parameters(model.structure, theta)
    return None


def _scaled_statespace(model: Any, steer_column: int, rows: dict[str, int | None],
                       scales: Mapping[str, float]) -> tuple:
    A, B, C, D, dt = model.to_statespace()
    A = np.asarray(A, dtype=float)
    steer_scale = float(scales.get("steer", 1.0))
    B = np.asarray(B, dtype=float)[:, steer_column] / steer_scale
    D = np.asarray(D, dtype=float)[:, steer_column] / steer_scale
    C = np.asarray(C, dtype=float).copy()
    D = D.copy()
    for role, row in rows.items():
        if row is not None:
            factor = float(scales.get(role, 1.0))
            C[row] *= factor
            D[row] *= factor
    return A, B, C, D, dt


def handling_metrics(
    model: Any,
    speeds: float | Sequence[float],
    *,
    yaw_rate: str | None = None,
    lateral_acceleration: str | None = None,
    sideslip: str | None = None,
    steer: str | None = None,
    wheelbase: float | None = None,
    scales: Mapping[str, float] | None = None,
) -> HandlingResponse:
    """Handling metrics of an identified model at each speed (module notes).

    Parameters
    ----------
    model : IdentifiedModel or scheduled model
        A linear model meeting :class:`vehid.identification.models.protocol.IdentifiedModel`
        (``to_statespace``), valid at one speed; or a scheduled family offering
        ``model_at(V)``, evaluated at each speed.
    speeds : float or sequence of float
        Speeds (m/s). A model valid at one speed takes exactly one.
    yaw_rate, lateral_acceleration, sideslip : str, optional
        Names of these outputs (default: an output named ``yaw_rate``,
        ``lateral_acceleration``, ``sideslip`` if the model has one).
    steer : str, optional
        Name of the steer input (default: ``steer`` if present, else the first input).
    wheelbase : float, optional
        L (m), for the understeer gradient.
    scales : mapping, optional
        Factors to SI for ``steer`` (model unit to road-wheel rad),
        ``yaw_rate``, ``lateral_acceleration``, ``sideslip``.

    Returns
    -------
    HandlingResponse
        One :class:`HandlingMetrics` per speed, with standard deviations where the model has a parameter
        covariance; it unpacks and indexes as their tuple.
    """
    speeds = [float(v) for v in np.atleast_1d(np.asarray(speeds, dtype=float))]
    if not speeds or not all(math.isfinite(v) and v > 0 for v in speeds):
        raise InputError(f"speeds must be positive and finite (m/s); got {speeds}")
    if wheelbase is not None and not (math.isfinite(wheelbase) and wheelbase > 0):
        raise InputError(f"the wheelbase must be positive and finite (m); got {wheelbase}")
    scales = dict(scales or {})
    for role, factor in scales.items():
        if role not in ("steer", "yaw_rate", "lateral_acceleration", "sideslip"):
            raise InputError(f"unknown scale {role!r}: use steer, yaw_rate, lateral_acceleration or sideslip")
        if not (math.isfinite(factor) and factor != 0):
            raise InputError(f"the {role} scale must be finite and non-zero; got {factor}")
    scheduled = hasattr(model, "model_at")
    if not scheduled and len(speeds) != 1:
        raise InputError(f"this model holds at one speed; give one speed, not {len(speeds)}")
    if not scheduled and not hasattr(model, "to_statespace"):
        raise InputError(f"a {type(model).__name__} has no linear state-space form: no handling metrics")
    results = []
    for speed in speeds:
        local = model.model_at(speed) if scheduled else model
        names = tuple(local.output_names)
        defaults = {role: role if role in names else None
                    for role in ("yaw_rate", "lateral_acceleration", "sideslip")}
        rows = {
            "yaw_rate": _output_row(names, yaw_rate or defaults["yaw_rate"], "yaw rate", True),
            "lateral_acceleration": _output_row(names, lateral_acceleration or defaults["lateral_acceleration"],
                                                "lateral acceleration", False),
            "sideslip": _output_row(names, sideslip or defaults["sideslip"], "sideslip", False),
        }
        inputs = tuple(local.input_names)
        if steer is not None and steer not in inputs:
            raise InputError(f"the model has no input {steer!r}; its inputs are {', '.join(inputs)}")
        column = inputs.index(steer) if steer is not None else (inputs.index("steer") if "steer" in inputs else 0)

        def evaluate(candidate: Any) -> np.ndarray:
            return linear_handling(*_scaled_statespace(candidate, column, rows, scales), speed=speed,
                                   wheelbase=wheelbase, **rows)

        vector = evaluate(local)
        std = None
        rebuild = _rebuilder(local)
        if rebuild is not None:
            covariance = np.asarray(local.parameter_covariance, dtype=float)
            with np.errstate(invalid="ignore"):
                spread = propagate_by_differences(lambda theta: evaluate(rebuild(theta)),
                                                  np.asarray(local.parameters, dtype=float), covariance)
                std = np.sqrt(np.maximum(np.diag(spread), 0.0))
            std[~np.isfinite(vector)] = math.nan
        results.append(_metrics_from_vector(speed, "model", vector, std))
    return HandlingResponse(tuple(results))


# ---------------------------------------------------------------------------------------------
# The source model
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class SourceHandling:
    """The source model's handling: from its linearisation and from its nonlinear simulation.

    Attributes
    ----------
    vehicle : str
    wheelbase : float
        L (m).
    linearisation : tuple of HandlingMetrics
        From the exact linearisation at each speed (steer zero).
    simulation : tuple of HandlingMetrics
        From the nonlinear model: an ISO 7401 step steer to ``step_lateral_acceleration``
        (steady gains, understeer gradient and transient metrics), a 1 Hz
        sine dwell of the same amplitude (gain and phase at 1 Hz) and a sine
        sweep of it, 0.2-6 Hz (bandwidth). Empty if not simulated.
    step_lateral_acceleration : float
        Steady lateral acceleration (m/s^2) the step was sized for by the linear gain.
    """

    vehicle: str
    wheelbase: float
    linearisation: tuple[HandlingMetrics, ...]
    simulation: tuple[HandlingMetrics, ...] = ()
    step_lateral_acceleration: float = ISO_7401_LATERAL_ACCELERATION

    @property
    def speeds(self) -> tuple[float, ...]:
        return tuple(m.speed for m in self.linearisation)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the vehicle, its wheelbase, the step's level and both sets of metrics."""
        return {"vehicle": self.vehicle, "wheelbase": self.wheelbase,
                "step_lateral_acceleration": self.step_lateral_acceleration,
                "linearisation": [m.as_dict() for m in self.linearisation],
                "simulation": [m.as_dict() for m in self.simulation]}

    def plot(self, names: Sequence[str] = PLOTTED_METRICS, *, ax: Any = None, title: str | None = None) -> Any:
        """The linearisation's metrics and, where simulated, the nonlinear model's, against speed.

        Parameters
        ----------
        names : sequence of str
            The metrics (:data:`METRIC_UNITS`), one panel each.
        ax : matplotlib Axes or sequence of Axes, optional
            One per metric; default a new Figure.
        title : str, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from .handling_figure import plot_handling

        curves = {f"{self.vehicle} (linearisation)": self.linearisation,
                  **({f"{self.vehicle} (simulation)": self.simulation} if self.simulation else {})}
        return plot_handling(curves, names, METRIC_UNITS, ax=ax, title=title or f"Handling of {self.vehicle}")


def _source_linearisation(params: VehicleParameters, speed: float) -> np.ndarray:
    from .linearize import linearize

    lin = linearize(params, speed=speed)
    keep = [i for i, name in enumerate(lin.state_names) if name != "psi"]  # ignorable: a zero eigenvalue
    rows = {name: lin.output_names.index(name) for name in ("yaw_rate", "lateral_acceleration", "sideslip")}
    chassis = params.chassis
    return linear_handling(
        lin.A[np.ix_(keep, keep)], lin.B[keep, 0], lin.C[:, keep], lin.D[:, 0], None, speed=speed,
        wheelbase=chassis.cg_to_front_axle + chassis.cg_to_rear_axle, **rows,
    )


def _sine_response(params: VehicleParameters, speed: float, amplitude: float, dt: float) -> np.ndarray:
    """Complex gains at 1 Hz of yaw rate and lateral acceleration from a simulated sine dwell.

    Six periods, faded in over the first; the last three, where the response
    has settled, are fitted by least squares with a sine, a cosine and a constant.
    """
    from .manoeuvres import Manoeuvre
    from .simulation import simulate

    t = dt * np.arange(int(round(6.0 / dt)) + 1)
    fade = np.clip(t, 0.0, 1.0)
    steer = amplitude * (0.5 - 0.5 * np.cos(np.pi * fade)) * np.sin(2 * np.pi * t)
    data = simulate(params, Manoeuvre("sine-dwell", steer, dt, {"frequency_hz": 1.0}), speed=speed)
    tail = t >= 3.0
    basis = np.column_stack([np.sin(2 * np.pi * t[tail]), np.cos(2 * np.pi * t[tail]), np.ones(tail.sum())])

    def phasor(signal: np.ndarray) -> complex:
        s, c, _ = np.linalg.lstsq(basis, signal[tail], rcond=None)[0]
        return complex(s, c)  # s sin + c cos = Im((s + j c) exp(j w t))

    reference = phasor(steer)
    return np.array([phasor(data.output(name)) / reference for name in ("yaw_rate", "lateral_acceleration")])


_SWEEP_HZ = (0.2, 6.0)  # the simulated sweep's band: past the yaw-rate bandwidth of a car at 10-50 m/s
_SWEEP_SECONDS = 40.0  # ~7 s per Hz: each frequency is passed slowly enough to be near its steady response
_SWEEP_SMOOTHING_HZ = 0.1  # half-width of the band over which the sweep's spectra are averaged


def _sweep_bandwidth(params: VehicleParameters, speed: float, amplitude: float, steady_gain: float,
                     dt: float) -> float:
    """Yaw-rate bandwidth (Hz) from a simulated sine sweep: where ``|r/delta|`` falls to 1/sqrt(2) of ``steady_gain``.

    A linear sweep over :data:`_SWEEP_HZ`, faded in and out over 1 s; the
    frequency response is the ratio of cross- to auto-spectrum averaged over
    +/- 0.1 Hz (the empirical transfer function, smoothed), evaluated on a
    0.01 Hz grid and its first crossing interpolated linearly. NaN if the
    gain stays above the level within the band.
    """
    from .manoeuvres import Manoeuvre
    from .simulation import simulate

    t = dt * np.arange(int(round(_SWEEP_SECONDS / dt)) + 1)
    low, high = _SWEEP_HZ
    envelope = np.clip(np.minimum(t, t[-1] - t), 0.0, 1.0)
    steer = amplitude * (0.5 - 0.5 * np.cos(np.pi * envelope)) * np.sin(
        2 * np.pi * (low * t + 0.5 * (high - low) / t[-1] * t**2))
    data = simulate(params, Manoeuvre("sine-sweep", steer, dt, {"sweep_hz": list(_SWEEP_HZ)}), speed=speed)
    yaw = data.output("yaw_rate") - data.output("yaw_rate")[0]
    frequencies = np.fft.rfftfreq(t.size, dt)
    inputs, outputs = np.fft.rfft(steer), np.fft.rfft(yaw)
    cross, power = outputs * np.conj(inputs), np.abs(inputs) ** 2
    grid = np.arange(low + 2 * _SWEEP_SMOOTHING_HZ, high - 2 * _SWEEP_SMOOTHING_HZ, 0.01)
    ratio = np.empty(grid.size)
    for k, f in enumerate(grid):
        band = np.abs(frequencies - f) <= _SWEEP_SMOOTHING_HZ
        ratio[k] = abs(cross[band].sum() / power[band].sum()) / abs(steady_gain)
    below = np.flatnonzero(ratio < _BANDWIDTH_RATIO)
    if below.size == 0 or below[0] == 0:
        return math.nan
    k = int(below[0])
    r0, r1 = ratio[k - 1], ratio[k]
    return float(grid[k - 1] + (_BANDWIDTH_RATIO - r0) / (r1 - r0) * (grid[k] - grid[k - 1]))


def _source_simulation(params: VehicleParameters, speed: float, linear: np.ndarray,
                       lateral_acceleration: float) -> np.ndarray:
    from .manoeuvres import step
    from .model import MAX_STEER
    from .simulation import DEFAULT_DT, simulate

    names = list(METRIC_UNITS)
    amplitude = min(lateral_acceleration / linear[names.index("lateral_acceleration_gain")], 0.5 * MAX_STEER)
    manoeuvre = step(amplitude=amplitude, duration=5.0)
    data = simulate(params, manoeuvre, speed=speed)
    origin = manoeuvre.meta["start"] + manoeuvre.meta["ramp_time"] / 2  # ISO 7401: 50 % of the steer step
    times = data.t - origin
    tail = slice(-int(round(0.5 / data.dt)), None)  # the last 0.5 s: settled (the PI hold too)

    def change(name: str) -> np.ndarray:
        values = data.output(name)
        return values - values[0]

    yaw, lateral, sideslip = change("yaw_rate"), change("lateral_acceleration"), change("sideslip")
    yaw_gain, lateral_gain = yaw[tail].mean() / amplitude, lateral[tail].mean() / amplitude
    sideslip_gain = sideslip[tail].mean() / amplitude
    wheelbase = params.chassis.cg_to_front_axle + params.chassis.cg_to_rear_axle
    after = times >= 0
    yaw_ratio = yaw[after] / yaw[tail].mean()
    peak_time, overshoot = _first_peak(times[after], yaw_ratio)
    one_hz = _sine_response(params, speed, amplitude, DEFAULT_DT)
    bandwidth = _sweep_bandwidth(params, speed, amplitude, yaw_gain, DEFAULT_DT)
    return np.array([
        yaw_gain, lateral_gain, sideslip_gain, *_steady_metrics(speed, wheelbase, yaw_gain, lateral_gain),
        _crossing(times[after], yaw_ratio, _RESPONSE_LEVEL), peak_time, overshoot,
        _crossing(times[after], lateral[after] / lateral[tail].mean(), _RESPONSE_LEVEL),
        abs(one_hz[0]), math.degrees(np.angle(one_hz[0])), math.degrees(np.angle(one_hz[1])), bandwidth,
    ])


def source_handling(
    params: VehicleParameters | str = "baseline",
    speeds: float | Sequence[float] = (10.0, 20.0, 30.0),
    *,
    simulate: bool = True,
    step_lateral_acceleration: float = ISO_7401_LATERAL_ACCELERATION,
) -> SourceHandling:
    """Handling metrics of the 23-state source model at each speed.

    Parameters
    ----------
    params : VehicleParameters or str
        The vehicle, a name or a parameter file.
    speeds : float or sequence of float
        Speeds (m/s) within the model's valid range.
    simulate : bool
        Also run the nonlinear step, sine dwell and sweep at each speed (about 0.5 s together).
    step_lateral_acceleration : float
        Steady lateral acceleration (m/s^2) of the simulated step, reached by
        sizing the steer with the linear gain (ISO 7401: 4 m/s^2). Lower
        values approach the linearisation; higher ones show the tyres'
        saturation.
    """
    from .model import check_speed

    params = named_vehicle(params)
    speeds = [check_speed(v, params) for v in np.atleast_1d(np.asarray(speeds, dtype=float))]
    if not (math.isfinite(step_lateral_acceleration) and step_lateral_acceleration > 0):
        raise InputError(f"the step's lateral acceleration must be positive (m/s^2); got {step_lateral_acceleration}")
    linear = [_source_linearisation(params, v) for v in speeds]
    simulated = ()
    if simulate:
        simulated = tuple(_metrics_from_vector(v, "simulation", _source_simulation(params, v, vector,
                                                                                    step_lateral_acceleration), None)
                          for v, vector in zip(speeds, linear))
    chassis = params.chassis
    return SourceHandling(
        params.name, chassis.cg_to_front_axle + chassis.cg_to_rear_axle,
        tuple(_metrics_from_vector(v, "linearisation", vector, None) for v, vector in zip(speeds, linear)),
        simulated, float(step_lateral_acceleration),
    )


@dataclass(frozen=True)
class SteadyStateHandling:
    """The source model's steady states at one speed over a range of lateral acceleration (ISO 4138).

    Attributes
    ----------
    speed : float
        m/s.
    lateral_acceleration : float
        The range's limit (m/s^2): the steady states span +/- this.
    steer, yaw_rate, lateral_acceleration_values : tuple of float
        Each steady state: road-wheel steer (rad), yaw rate (rad/s), lateral acceleration (m/s^2).
    yaw_rate_gain, lateral_acceleration_gain : float
        Least-squares slopes through the origin of yaw rate and lateral
        acceleration against steer over the range (1/s, m/s^2 per rad).
    understeer_gradient_deg_per_g : float
        Least-squares slope through the origin of ``delta - L r / V`` against
        ``a_y`` over the range (Gillespie 1992, eq. 6-14), in deg/g.
    characteristic_speed_m_s, critical_speed_m_s : float
        ``sqrt(L / K)`` of an understeering car, ``sqrt(-L / K)`` of an oversteering one; NaN otherwise.
    """

    speed: float
    lateral_acceleration: float
    steer: tuple[float, ...]
    yaw_rate: tuple[float, ...]
    lateral_acceleration_values: tuple[float, ...]
    yaw_rate_gain: float
    lateral_acceleration_gain: float
    understeer_gradient_deg_per_g: float
    characteristic_speed_m_s: float
    critical_speed_m_s: float

    @property
    def reached_lateral_acceleration(self) -> float:
        """The largest steady lateral acceleration (m/s^2) of the steps: short of the range where the tyres saturate."""
        return float(np.max(np.abs(self.lateral_acceleration_values)))

    def as_dict(self) -> dict[str, Any]:
        def number(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        return {"speed": self.speed, "lateral_acceleration": self.lateral_acceleration,
                "reached_lateral_acceleration": self.reached_lateral_acceleration,
                "yaw_rate_gain": self.yaw_rate_gain, "lateral_acceleration_gain": self.lateral_acceleration_gain,
                "understeer_gradient_deg_per_g": self.understeer_gradient_deg_per_g,
                "characteristic_speed_m_s": number(self.characteristic_speed_m_s),
                "critical_speed_m_s": number(self.critical_speed_m_s)}


_STEADY_STATES_PER_SIDE = 4  # steer steps on each side of straight running: a least-squares line through 8 points


def source_steady_state(
    params: VehicleParameters | str = "baseline",
    speeds: float | Sequence[float] = (10.0, 20.0, 30.0),
    *,
    lateral_acceleration: float,
) -> tuple[SteadyStateHandling, ...]:
    """Steady-state handling of the 23-state source model over +/- a stated lateral acceleration.

    Constant speed with steer steps, in the manner of ISO 4138: at each
    speed, steer angles in equal steps of ``lateral_acceleration / 4`` on
    each side of straight running (sized by the linearisation's gain), each
    held to the model's exact steady state (its trim, by Newton's method,
    rather than a simulation that approaches it); the gains and the
    understeer gradient are the least-squares lines through the origin over
    these states. That is what a linear model fitted on data spanning the
    range sees of the car's steady state. As the range shrinks they tend to
    the linearisation's values (:func:`source_handling`), the closed form at
    zero lateral acceleration.

    Parameters
    ----------
    params : VehicleParameters or str
        The vehicle, a name or a parameter file.
    speeds : float or sequence of float
        Speeds (m/s) within the model's valid range.
    lateral_acceleration : float
        The range's limit (m/s^2), positive and within the car's grip.

    Returns
    -------
    tuple of SteadyStateHandling
        One per speed.

    Raises
    ------
    InputError
        On a non-positive or non-finite lateral acceleration or a speed outside the valid range.
    DivergenceError
        When a steady state cannot be found (the range reaches beyond the grip limit).
    """
    from .model import build_vehicle_model, check_speed

    params = named_vehicle(params)
    speeds = [check_speed(v) for v in np.atleast_1d(np.asarray(speeds, dtype=float))]
    if not (math.isfinite(lateral_acceleration) and lateral_acceleration > 0):
        raise InputError(f"the lateral acceleration must be positive and finite (m/s^2); got {lateral_acceleration}")
    model = build_vehicle_model(params)
    wheelbase = params.chassis.cg_to_front_axle + params.chassis.cg_to_rear_axle
    gain_index = list(METRIC_UNITS).index("lateral_acceleration_gain")
    yaw_row, lateral_row = model.output_index("yaw_rate"), model.output_index("lateral_acceleration")
    fractions = np.arange(1, _STEADY_STATES_PER_SIDE + 1) / _STEADY_STATES_PER_SIDE
    results = []
    for speed in speeds:
        linear_gain = _source_linearisation(params, speed)[gain_index]
        steers = np.concatenate([-fractions[::-1], fractions]) * lateral_acceleration / linear_gain
        yaw, lateral = np.empty(steers.size), np.empty(steers.size)
        for k, steer in enumerate(steers):
            outputs = np.asarray(model.outputs(model.trim(speed, float(steer)), float(steer), speed)).ravel()
            yaw[k], lateral[k] = outputs[yaw_row], outputs[lateral_row]
        # a line through the origin: straight running is a steady state of a symmetric car
        kinematic_excess = steers - wheelbase * yaw / speed
        gradient = float(lateral @ kinematic_excess / (lateral @ lateral))
        per_steer = float(steers @ steers)
        characteristic = math.sqrt(wheelbase / gradient) if gradient > 0 else math.nan
        critical = math.sqrt(-wheelbase / gradient) if gradient < 0 else math.nan
        results.append(SteadyStateHandling(
            speed, float(lateral_acceleration), tuple(map(float, steers)), tuple(map(float, yaw)),
            tuple(map(float, lateral)), float(steers @ yaw / per_steer), float(steers @ lateral / per_steer),
            gradient * _RAD_PER_MPS2_TO_DEG_PER_G, characteristic, critical))
    return tuple(results)
