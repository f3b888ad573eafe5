"""Grey-box identification: the constant parameters of any continuous-time CasADi model, estimated by the IEKF.

The model is ``dx/dt = f(x, u, theta, s)``, ``y = h(x, u, theta, s)``
(:class:`~vehid.identification.filtering.greybox_structure.GreyBoxModel`): ``theta``
are unknown constants, ``s`` measured time-varying parameters (a scheduling signal) that enter like
inputs. As in the modal IEKF (Best & Bogdanski 2017, eq. 7-14) the parameters join the states in the
filter's state vector with zero dynamics, the Jacobians are CasADi's exact ones, the whole pass runs in
compiled code (:mod:`vehid.identification.filtering.iekf_pass`) and the record is rinsed through the filter pass
after pass (:mod:`vehid.identification.filtering.rinse`): each pass starts the true states at zero and carries the
parameters and ``P`` on.

Choices, each stated where it is made:

* Parameters are filtered in scaled form: ``phi = log(theta / theta_0)`` where the model declares a
  parameter positive, ``phi = theta / |theta_0|`` otherwise (``theta_0`` the start). ``phi`` is of order
  one, so ``P0 = prior_std^2 I`` and ``Q = p I`` mean the same for every parameter: relative uncertainty.
* ``Q`` is stated per pass: the random-walk variance a parameter may gather over one pass over all
  records is ``p`` (``q = p / duration``), shrinking by ``p_decay`` per pass down to
  ``P_DECAY_FLOOR`` of ``p``, as the modal IEKF's invariant settings do: the early passes move the
  parameters from the start, the late ones average over the whole record.
* Discretisation: the model's own step (:func:`~vehid.identification.filtering.greybox_structure.transition`),
  RK4 with the input and the scheduling signal linear between samples (default) or Euler.
* ``R`` from the data where not given: ``"residual"`` (default) takes each output's residual variance
  of the frozen model's simulation, of the start model for the first pass and of each pass's model
  after it (the spline filter's rule); ``"data"`` takes each output's white-noise variance from its
  differences (:func:`~vehid.identification.assessment.noise.output_noise_variance`), as the modal filter's
  ``measurement_noise="data"``. Both are floored at :data:`~identification.filtering.iekf.NOISE_FLOOR` of the
  output's power. On a record the model fits to its noise the two agree; where the model cannot
  follow the record (model error), the residual rule counts that error as noise, so the filter
  does not chase it and the standard deviations include it, while the difference rule, seeing a
  smooth record, takes a tiny ``R`` and lets the parameters run after the error.
* Standard deviations. Carried over many passes, ``P`` counts the record once per pass and ends far
  too small. After the rinse one more pass runs from the estimate with ``P0`` and no ``Q``: its ``P``
  is the linearised covariance of one pass's information (with the prior), scaled by the mean
  normalised innovation squared per output where that exceeds one (innovations larger than ``R``
  says: model error or coloured noise). The parameters are not moved by that pass. With
  ``coloured_residuals`` the covariance is scaled also by the innovations' largest integrated
  autocorrelation time (:func:`integrated_correlation_time`): the filter's information counts every
  sample as independent, which coloured residuals are not (the time is kept in the result's ``meta``
  either way).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import casadi as ca
import numpy as np

from ..blas import on_one_blas_thread
from ..data import IOData, as_records, check_channels
from ..errors import DivergenceError, InputError
from ..assessment.noise import output_noise_variance
from .iekf import NOISE_FLOOR, P_DECAY_FLOOR
from .iekf_pass import compiled_pass, pack_covariance, unpack_covariance
from ..assessment.metrics import nrmse_fit, percentage_explanation
from ..assessment.segments import integrated_correlation_time
from .rinse import Assessment, PassHistory, PassRecord, RinseHooks, rinse
from .greybox_structure import GreyBoxModel, check_discretization, driving, simulate_greybox, transition

__all__ = ["GreyBoxOptions", "GreyBoxResult", "identify_greybox"]


MEASUREMENT_NOISE_RULES = ("data", "residual")

# the filter step's name of each discretisation (the compiled pass checks it against the modal forms'):
# the transition itself is the model's (greybox_structure.transition), whatever the label
_FILTER_LABEL = {"rk4": "exact", "euler": "euler"}

# the covariance pass's prior variance, at most this multiple of the carried one (covariance_pass): with some 30
# passes counted the prior is still some 300 times what one pass determines, and moves the result by < 0.5 %
PRIOR_OVER_CARRIED = 1e4

# a simulation beyond this multiple of the largest measured output has blown up: the pass is refused
_BLOW_UP = 1e6


class _GreyBoxFilterModel:
    """The grey-box model as the compiled IEKF pass takes it (:class:`~identification.filtering.filter_models.FilterModel`).

    Filter parameters are the scaled ``phi`` (module docstring); the constants are each parameter's
    scale ``theta_0`` and each output's reciprocal scale, so that a new record or start needs no new code.
    """

    def __init__(self, model: GreyBoxModel, discretization: str, substeps: int):
        self.model = model
        self.discretization = discretization
        self.substeps = substeps

    # An integrator over a physical model's ODE: its step is one large expression graph, which the C
    # compiler optimises at -O3 for minutes (iekf_pass.HUGE_STEP_INSTRUCTIONS)
    model_bound_step = True

    n_constants = property(lambda self: self.model.n_theta + self.model.n_y)
    n_states = property(lambda self: self.model.n_states)
    n_theta = property(lambda self: self.model.n_theta)
    n_u = property(lambda self: self.model.n_u + self.model.n_s)
    n_y = property(lambda self: self.model.n_y)

    def physical(self, phi: Any, constants: Any) -> Any:
        """``theta`` from ``phi`` (SX): ``theta_0 exp(phi)`` for positive parameters, ``theta_0 phi`` else."""
        scale = constants[: self.model.n_theta]
        return ca.vertcat(*[scale[i] * (ca.exp(phi[i]) if positive else phi[i])
                            for i, positive in enumerate(self.model.positive)])

    def transition(self, x, phi, u0, u1, dt, discretization, constants):
        return transition(self.model, x, u0, u1, self.physical(phi, constants), dt, self.discretization,
                           self.substeps)

    def output(self, x, phi, u, constants):
        n_u = self.model.n_u
        y = self.model.output(x, u[:n_u], self.physical(phi, constants), u[n_u:])
        return y * constants[self.model.n_theta:]

    def cache_key(self) -> str:
        return f"greybox:{self.model.cache_key()}:{self.discretization}:{self.substeps}"

    def __hash__(self) -> int:
        return hash(self.cache_key())

    def __eq__(self, other: object) -> bool:
        return isinstance(other, _GreyBoxFilterModel) and other.cache_key() == self.cache_key()


@dataclass(frozen=True)
class GreyBoxOptions:
    """Settings of a grey-box identification (module docstring).

    Parameters
    ----------
    p : float
        Random-walk variance of a scaled parameter over one pass (first pass). The default lets a
        parameter drift by 1 % over the record: enough to leave a start 30 % off within a few passes
        (``P0`` does most of that), small enough that a model which cannot follow every part of a
        record (one lacking a mode the record's fastest part excites) is not dragged by its last
        seconds into an unstable one, as 1e-2 was (measured: a two-state model of a sine sweep whose
        last seconds excite modes the model lacks).
    p_decay : float
        Factor on ``Q`` from one pass to the next, in (0, 1]; never below ``P_DECAY_FLOOR`` of ``p``.
    prior_std : float
        Standard deviation of the scaled parameters at the start (``P0``): 1 allows a factor e
        on a positive parameter.
    passes, min_passes : int
        Largest number of passes; no early stop before ``min_passes``.
    parameter_tolerance : float
        Stop when no parameter changes by more than this fraction of itself (or of its scale, where
        that is larger) from one pass to the next.
    discretization : {"rk4", "euler"}
        The step over a sample: classical Runge-Kutta or Euler.
    substeps : int
        Runge-Kutta steps per sample.
    covariance : {"joseph", "paper"}
        Covariance numerics of the pass (:mod:`vehid.identification.filtering.iekf_pass`).
    measurement_noise : "data", "residual", float or sequence of float
        ``R`` (diagonal, the outputs' units squared) or the rule taking it from the data.
    initial_state_std : sequence of float, optional
        Where records do not start at rest: the standard deviation of each state at a record's
        start. The state rows of ``P`` are set to it at the start of every record (uncorrelated with
        the parameters), so the filter estimates the start. Default: records start at rest.
    parameter_prior_std : sequence of float, optional
        One such standard deviation per parameter, in place of ``prior_std`` (a prior known better for
        some parameters than for others).
    coloured_residuals : bool
        Scale the covariance also by the innovations' integrated autocorrelation time (module
        docstring, "Standard deviations"): where the residuals are coloured (model error, a sensor's
        filter) the samples are fewer independent ones than they count, and the std widens by the
        root of the ratio. Off by default: a white residual leaves it near one anyway.
    held : sequence of bool, optional
        One per parameter: True holds it at its start (no prior variance, no drift; its std is
        NaN). The compiled filter is the same whichever are held, so a staged estimation or one
        that drops a parameter the data do not determine needs no new compilation.
    """

    p: float = 1e-4
    p_decay: float = 0.5
    prior_std: float = 1.0
    passes: int = 30
    min_passes: int = 4
    parameter_tolerance: float = 1e-4
    discretization: str = "rk4"
    substeps: int = 1
    covariance: str = "joseph"
    measurement_noise: Any = "residual"
    initial_state_std: tuple[float, ...] | None = None
    parameter_prior_std: tuple[float, ...] | None = None
    coloured_residuals: bool = False
    held: tuple[bool, ...] | None = None

    def __post_init__(self) -> None:
        for name in ("p", "prior_std", "parameter_tolerance"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number; got {value!r}")
        if not (isinstance(self.p_decay, (int, float)) and 0 < self.p_decay <= 1):
            raise InputError(f"p_decay must be in (0, 1]; got {self.p_decay!r}")
        for name in ("passes", "min_passes"):
            value = getattr(self, name)
            if isinstance(value, bool) or int(value) != value or value < 1:
                raise InputError(f"{name} must be a whole number >= 1; got {value!r}")
        check_discretization(self.discretization, self.substeps)
        if self.covariance not in ("joseph", "paper"):
            raise InputError(f"unknown covariance form {self.covariance!r}; use joseph or paper")
        noise = self.measurement_noise
        if isinstance(noise, str):
            if noise not in MEASUREMENT_NOISE_RULES:
                raise InputError(f"measurement_noise must be {' or '.join(MEASUREMENT_NOISE_RULES)} or variances; "
                                 f"got {noise!r}")
        else:
            values = np.asarray(noise, dtype=float).ravel()
            if values.size == 0 or not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise InputError(f"measurement_noise variances must be positive numbers; got {noise!r}")
            object.__setattr__(self, "measurement_noise", tuple(float(v) for v in values))
        if self.initial_state_std is not None:
            values = np.asarray(self.initial_state_std, dtype=float).ravel()
            if not np.all(np.isfinite(values)) or np.any(values < 0):
                raise InputError("initial_state_std must be non-negative numbers")
            object.__setattr__(self, "initial_state_std", tuple(float(v) for v in values))
        if self.parameter_prior_std is not None:
            values = np.asarray(self.parameter_prior_std, dtype=float).ravel()
            if values.size == 0 or not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise InputError("parameter_prior_std must be positive numbers, one per parameter")
            object.__setattr__(self, "parameter_prior_std", tuple(float(v) for v in values))
        if self.held is not None:
            object.__setattr__(self, "held", tuple(bool(v) for v in self.held))
            if all(self.held):
                raise InputError("every parameter is held: leave at least one free")


@dataclass(frozen=True, eq=False)
class GreyBoxResult(PassHistory):
    """A grey-box identification: parameters with their uncertainty, fits and the passes.

    Attributes
    ----------
    model : GreyBoxModel
        The model identified.
    parameters : ndarray (n_theta,)
        The estimate, in the parameters' units.
    covariance : ndarray (n_theta, n_theta)
        Their covariance (module docstring, "Standard deviations"); NaN where it could not be had.
    start : ndarray (n_theta,)
        The start values.
    fit_percent : ndarray (n_y,)
        R (eq. 17) per output of the model simulated from rest over the records (pooled).
    nrmse_fit_percent : ndarray (n_y,)
        NRMSE fit per output, likewise.
    measurement_noise : ndarray (n_y,)
        ``R``'s diagonal of the last pass, in the outputs' units squared.
    history : tuple of PassRecord
        One per pass (``parameters`` in their units, ``trace_p`` of the scaled filter).
    stop_reason : str
        ``"converged"``, ``"passes"`` or ``"diverged at pass k"`` (on a DivergenceError's ``last_good``).
    dt, seconds : float
        The records' sample interval and the run time (s).
    options : GreyBoxOptions
        The settings used.
    meta : dict
        ``covariance_source`` and the normalised innovation squared of the covariance pass.
    """

    model: GreyBoxModel
    parameters: np.ndarray
    covariance: np.ndarray
    start: np.ndarray
    fit_percent: np.ndarray
    nrmse_fit_percent: np.ndarray
    measurement_noise: np.ndarray
    history: tuple[PassRecord, ...]
    stop_reason: str
    dt: float
    seconds: float
    options: GreyBoxOptions
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of each parameter."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def correlation(self) -> np.ndarray:
        """The parameters' correlation matrix."""
        std = self.std
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.covariance / np.outer(std, std)

    @property
    def trace_p(self) -> np.ndarray:
        """The trace of P of the scaled filter after each pass."""
        return np.array([record.trace_p for record in self.history])

    def parameter(self, name: str) -> tuple[float, float]:
        """Return a parameter's estimate and standard deviation.

        Parameters
        ----------
        name : str
            One of the model's ``parameter_names``.

        Returns
        -------
        tuple of float
            ``(value, std)`` in the parameter's unit.
        """
        try:
            index = self.model.parameter_names.index(name)
        except ValueError:
            raise InputError(f"no parameter {name!r}; the model has {', '.join(self.model.parameter_names)}") from None
        return float(self.parameters[index]), float(self.std[index])

    def simulate(self, record: IOData) -> np.ndarray:
        """Simulate the identified model from rest on a record.

        Parameters
        ----------
        record : IOData
            Inputs then scheduling signals in ``u``.

        Returns
        -------
        ndarray, shape (N, n_y)
            The outputs.
        """
        y, _ = simulate_greybox(self.model, self.parameters, record, discretization=self.options.discretization,
                                substeps=self.options.substeps)
        return y


def _pooled_fits(y_parts: Sequence[np.ndarray], y_hat_parts: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    y, y_hat = np.vstack(y_parts), np.vstack(y_hat_parts)
    return percentage_explanation(y, y_hat), nrmse_fit(y, y_hat)


@on_one_blas_thread
def identify_greybox(
    data: IOData | Sequence[IOData],
    model: GreyBoxModel,
    start: Any,
    *,
    options: GreyBoxOptions | None = None,
    on_pass: Callable[[PassRecord, GreyBoxResult], None] | None = None,
) -> GreyBoxResult:
    """Estimate a grey-box model's parameters with the IEKF (module docstring).

    Parameters
    ----------
    data : IOData or sequence of IOData
        Uniformly sampled records of one ``dt``: ``u`` (N, n_u + n_s) the model's inputs then its
        scheduling signals, ``y`` (N, n_y) its outputs, in the model's units. Each record starts
        from rest unless ``options.initial_state_std`` says otherwise.
    model : GreyBoxModel
        The model, with its parameters' names, units and signs.
    start : array_like (n_theta,)
        Start values of the parameters (non-zero; positive for the positive ones).
    options : GreyBoxOptions, optional
        Settings; the defaults of :class:`GreyBoxOptions` without them.
    on_pass : callable, optional
        Called after every pass with its record and the result so far.

    Returns
    -------
    GreyBoxResult
        The estimate with its covariance, fits and the passes.

    Raises
    ------
    InputError
        Records that do not fit the model, a start of zero, bad options.
    DivergenceError
        Non-finite values, a covariance no longer positive definite or a simulation that blows up;
        its ``last_good`` holds the result up to the last good pass (None before the first).
    """
    options = options or GreyBoxOptions()
    started = time.perf_counter()
    records = as_records(data)
    dt = float(records[0].dt)
    for record in records:
        driving(model, record)
        if not math.isclose(record.dt, dt, rel_tol=1e-9):
            raise InputError(f"every record must have one sample interval; got {dt} and {record.dt} s")
    samples = sum(record.n_samples for record in records)
    if samples <= 2 * model.n_theta:
        raise InputError(f"{samples} samples cannot identify {model.n_theta} parameters")
    check_channels(tuple(IOData(t=r.t, u=r.u[:, : model.n_u], y=r.y, input_names=model.input_names,
                                output_names=r.output_names) for r in records), detrend="none")
    start = model.check_parameters(start)
    typical = np.asarray(model.parameter_scale, dtype=float) if model.parameter_scale else np.zeros(model.n_theta)
    scale = np.where(start != 0, np.abs(start), typical)
    if np.any(scale == 0):
        raise InputError(f"parameter {model.parameter_names[int(np.flatnonzero(scale == 0)[0])]!r} starts at zero: "
                         "give a start of its expected size (it sets the parameter's scale)")
    n, n_theta = model.n_states, model.n_theta
    m = n + n_theta
    if options.parameter_prior_std is not None and len(options.parameter_prior_std) != n_theta:
        raise InputError(f"parameter_prior_std needs {n_theta} values (one per parameter); "
                         f"got {len(options.parameter_prior_std)}")
    prior_variance = np.square(options.parameter_prior_std if options.parameter_prior_std is not None
                               else np.full(n_theta, options.prior_std))
    if options.held is not None and len(options.held) != n_theta:
        raise InputError(f"held needs {n_theta} values (one per parameter); got {len(options.held)}")
    free = np.ones(n_theta, dtype=bool) if options.held is None else ~np.array(options.held, dtype=bool)
    prior_variance = np.where(free, prior_variance, 0.0)  # a held parameter neither starts uncertain nor drifts
    if options.initial_state_std is not None and len(options.initial_state_std) != n:
        raise InputError(f"initial_state_std needs {n} values (one per state); got {len(options.initial_state_std)}")

    positive = np.array(model.positive, dtype=bool)

    def physical(phi: np.ndarray) -> np.ndarray:
        with np.errstate(over="ignore"):  # a runaway parameter becomes inf, which the simulation check names
            return np.where(positive, scale * np.exp(np.where(positive, phi, 0.0)), scale * phi)

    def jacobian(theta: np.ndarray) -> np.ndarray:
        """d theta / d phi (diagonal)."""
        return np.diag(np.where(positive, theta, scale))

    phi_start = np.where(positive, 0.0, start / scale)
    y_all = np.vstack([record.y for record in records])
    power = np.mean(y_all**2, axis=0)
    if np.any(power == 0):
        raise InputError("an output is zero throughout: there is no response to identify")
    output_scale = np.sqrt(power)
    constants = np.concatenate([scale, 1.0 / output_scale])
    drives = [driving(model, record) for record in records]
    outputs = [record.y / output_scale for record in records]
    duration = samples * dt

    filter_model = _GreyBoxFilterModel(model, options.discretization, int(options.substeps))
    run_pass = compiled_pass(filter_model, dt, _FILTER_LABEL[options.discretization], options.covariance)

    def simulate_all(theta: np.ndarray) -> list[np.ndarray]:
        y_hat = []
        for record in records:
            y, _ = simulate_greybox(model, theta, record, discretization=options.discretization,
                                    substeps=options.substeps)
            y_hat.append(y)
        return y_hat

    def residual_variance(y_hat: list[np.ndarray]) -> np.ndarray:
        residual = np.vstack([record.y for record in records]) - np.vstack(y_hat)
        return np.maximum(np.mean(residual**2, axis=0), NOISE_FLOOR * power)

    if isinstance(options.measurement_noise, tuple):
        if len(options.measurement_noise) not in (1, model.n_y):
            raise InputError(f"measurement_noise needs 1 or {model.n_y} variances")
        noise = np.broadcast_to(np.asarray(options.measurement_noise), (model.n_y,)).copy()
    elif options.measurement_noise == "data":
        noise = np.maximum(output_noise_variance(records), NOISE_FLOOR * power)
    else:
        start_fit = simulate_all(start)
        if not all(np.all(np.isfinite(y)) for y in start_fit):
            raise DivergenceError("the start model's simulation is not finite: give other start values")
        noise = residual_variance(start_fit)
    R = np.diag(noise / output_scale**2)

    q_first = np.concatenate([np.zeros(n), np.where(free, options.p / duration, 0.0)])
    q = q_first.copy()

    def shrink(index: int) -> float:
        return max(options.p_decay ** (index - 1), P_DECAY_FLOOR) if options.p_decay < 1 else 1.0

    def prepare_pass(index: int) -> None:
        q[:] = q_first * shrink(index)

    def start_record(state: np.ndarray) -> np.ndarray:
        """Where records do not start at rest: the states' prior at the record's start (class docstring)."""
        if options.initial_state_std is None:
            return state
        P = unpack_covariance(state[m:], m)
        P[:n, :] = 0.0
        P[:, :n] = 0.0
        P[:n, :n] = np.diag(np.square(options.initial_state_std))
        state = state.copy()
        state[m:] = pack_covariance(P)
        return state

    def run_record(state: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        return run_pass(start_record(state), drives[k], outputs[k], q, R, constants)

    last_fit: dict[str, np.ndarray] = {}

    def assess(phi: np.ndarray, P: np.ndarray) -> Assessment:
        nonlocal R
        theta = physical(phi)
        if not np.all(np.isfinite(theta)):
            raise DivergenceError("a parameter ran away to infinity (try a smaller p or a better start)")
        y_hat = simulate_all(theta)
        biggest = float(np.max(np.abs(y_all)))
        if not all(np.all(np.isfinite(y)) and np.max(np.abs(y), initial=0.0) < _BLOW_UP * biggest for y in y_hat):
            values = ", ".join(f"{name} {value:.4g}" for name, value in zip(model.parameter_names, theta))
            raise DivergenceError(f"the identified model's simulation blows up ({values}); try a smaller p or a "
                                  "better start")
        fit, nrmse = _pooled_fits([record.y for record in records], y_hat)
        last_fit.update(R=fit, nrmse=nrmse)
        if options.measurement_noise == "residual":
            R = np.diag(residual_variance(y_hat) / output_scale**2)
        return Assessment(theta, fit, fit, phi, P)

    def settled(previous: PassRecord, current: PassRecord) -> bool:
        # relative to each parameter, or to its scale where it is smaller (an offset near zero)
        change = np.abs(current.parameters - previous.parameters) / np.maximum(np.abs(current.parameters), scale)
        return bool(np.max(change) < options.parameter_tolerance)

    def covariance_pass(phi: np.ndarray, carried: np.ndarray) -> tuple[np.ndarray, float]:
        """The scaled parameters' covariance of one pass from ``phi`` without Q, and its mean NIS per output.

        The prior is ``P0``, but at most :data:`PRIOR_OVER_CARRIED` times the carried variance: far wider
        than what one pass determines (the carried P counts the record about once per pass), so the result
        is the data's, while the first samples cannot throw the parameters across the space (a record
        that does not start at rest would, from the full ``P0``).
        """
        prior = np.minimum(prior_variance, PRIOR_OVER_CARRIED * np.clip(np.diag(carried), 0.0, None))
        P0 = np.diag(np.concatenate([np.zeros(n), prior]))
        state = np.concatenate([np.zeros(n), phi, pack_covariance(P0)])
        no_drift = np.zeros(m)
        nis, count = 0.0, 0
        correlation_time = np.zeros(model.n_y)
        with np.errstate(all="ignore"):
            for k in range(len(records)):
                state[:n] = 0.0
                state, innovations = run_pass(start_record(state), drives[k], outputs[k], no_drift, R, constants)
                if not (np.all(np.isfinite(state)) and np.all(np.isfinite(innovations))):
                    raise DivergenceError("the covariance pass produced non-finite values")
                nis += float(np.sum(innovations * np.linalg.solve(R, innovations.T).T))
                correlation_time += innovations.shape[0] * integrated_correlation_time(innovations)
                count += innovations.shape[0]
        return (unpack_covariance(state[m:], m)[n:, n:], nis / max(count, 1) / model.n_y,
                correlation_time / max(count, 1))

    def result(stop_reason: str, history: tuple[PassRecord, ...], phi: np.ndarray, P: np.ndarray) -> GreyBoxResult:
        theta = physical(phi)
        J = jacobian(theta)
        meta: dict[str, Any] = {}
        if stop_reason in ("converged", "passes"):
            try:
                covariance_phi, nis, correlation_time = covariance_pass(phi, P[n:, n:])
                inflation = max(nis, 1.0)
                meta.update(innovation_correlation_time=correlation_time.tolist())
                if options.coloured_residuals:
                    inflation *= max(float(np.max(correlation_time)), 1.0)
                covariance = J @ covariance_phi @ J.T * inflation
                meta.update(covariance_source="one pass from P0 without Q", nis_per_output=nis,
                            covariance_inflation=inflation)
            except DivergenceError as exc:
                covariance = np.full((n_theta, n_theta), np.nan)
                meta.update(covariance_source=f"none ({exc})")
        else:  # an unfinished run: the carried P (which counts the record once per pass) is all there is
            covariance = J @ P[n:, n:] @ J.T
            meta.update(covariance_source="the filter's carried P (too small: the record counted once per pass)")
        fit = last_fit.get("R", np.full(model.n_y, np.nan))
        nrmse = last_fit.get("nrmse", np.full(model.n_y, np.nan))
        covariance = 0.5 * (covariance + covariance.T)
        covariance[~free, :] = np.nan  # a held parameter was not estimated: it has no std
        covariance[:, ~free] = np.nan
        return GreyBoxResult(
            model=model, parameters=theta, covariance=covariance, start=start.copy(),
            fit_percent=fit, nrmse_fit_percent=nrmse, measurement_noise=np.diag(R) * output_scale**2,
            history=history, stop_reason=stop_reason, dt=dt, seconds=time.perf_counter() - started,
            options=options, meta=meta,
        )

    hooks = RinseHooks(records, run_record, lambda: R, assess, settled, result, n, label="grey-box pass",
                       hint="try a smaller p or a better start", prepare_pass=prepare_pass)
    P_start = np.diag(np.concatenate([np.zeros(n), prior_variance]))
    return rinse(hooks, phi_start, P_start, passes=options.passes, min_passes=options.min_passes,
                 check_covariance=options.covariance != "paper", on_pass=on_pass)
