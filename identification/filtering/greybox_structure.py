"""The grey-box model structure: any continuous-time CasADi model with constant parameters, and its simulation.

The model is ``dx/dt = f(x, u, theta, s)``, ``y = h(x, u, theta, s)`` (:class:`GreyBoxModel`): ``theta``
are unknown constants, ``s`` measured time-varying parameters (a scheduling signal) that enter like
inputs. The grey-box IEKF (:mod:`vehid.identification.filtering.greybox`) estimates ``theta``;
this module steps, simulates and scores the model for given parameters.

* Discretisation (:func:`transition`): a classical Runge-Kutta step (``rk4``, default) with the input and the
  scheduling signal linear between samples (the first-order hold of the modal filter's ``exact`` form), in
  ``substeps`` steps per sample; ``euler`` is the paper's one-step form.
* Simulation (:func:`simulate_greybox`, :func:`greybox_outputs`) runs that step as compiled code, and
  :func:`simulation_fit_covariance` gives an estimate's covariance as a fit of its simulation errors.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass
from typing import Any, Sequence

import casadi as ca
import numpy as np

from ..compiled import CompiledRecursion
from ..data import IOData, as_records
from ..errors import InputError

__all__ = ["GREYBOX_DISCRETIZATIONS", "GreyBoxModel", "transition", "driving", "simulate_greybox", "greybox_outputs",
    "simulation_fit_covariance", "check_discretization"]


GREYBOX_DISCRETIZATIONS = ("rk4", "euler")


def _as_sx_function(function: ca.Function, name: str, n_in: int) -> ca.Function:
    """An SX function of ``n_in`` inputs (an MX function is expanded), so that it can be called on SX symbols."""
    if not isinstance(function, ca.Function):
        raise InputError(f"the model's {name} must be a casadi.Function")
    if function.n_in() != n_in:
        raise InputError(f"the model's {name} takes {function.n_in()} inputs; (x, u, theta, s) are {n_in}")
    return function.expand() if function.is_a("MXFunction") else function


@dataclass(frozen=True, eq=False)
class GreyBoxModel:
    """A continuous-time model with named constant parameters, as the grey-box IEKF takes it.

    Parameters
    ----------
    dynamics : casadi.Function
        ``(x, u, theta, s) -> dx/dt``, column vectors of sizes ``n_states, n_u, n_theta, n_s``.
    output : casadi.Function
        ``(x, u, theta, s) -> y`` (``n_y``).
    parameter_names, parameter_units : sequence of str
        One per parameter.
    positive : sequence of bool
        Parameters that are positive by nature (estimated as logarithms, so they stay positive).
    state_names, input_names, schedule_names, output_names : sequence of str
        Names of the states, inputs, scheduling signals (none by default) and outputs
        (``y1, ...`` where none are given); their numbers are the model's sizes.
    description : str
        What the model is (for reports); its text enters the cache key.
    parameter_scale : sequence of float
        The typical size of each parameter (for instance a sensor offset's), which sets its scale
        where the start is zero; empty: every start must be non-zero and sets the scale itself.
    """

    dynamics: ca.Function
    output: ca.Function
    parameter_names: tuple[str, ...]
    parameter_units: tuple[str, ...]
    positive: tuple[bool, ...]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    schedule_names: tuple[str, ...] = ()
    output_names: tuple[str, ...] = ()
    description: str = ""
    parameter_scale: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        for name in ("parameter_names", "parameter_units", "positive", "state_names", "input_names",
                     "schedule_names", "output_names", "parameter_scale"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        object.__setattr__(self, "dynamics", _as_sx_function(self.dynamics, "dynamics", 4))
        object.__setattr__(self, "output", _as_sx_function(self.output, "output", 4))
        sizes = (self.n_states, self.n_u, self.n_theta, self.n_s)
        for function, label, n_out in ((self.dynamics, "dynamics", self.n_states), (self.output, "output", None)):
            for i, (size, what) in enumerate(zip(sizes, ("states", "inputs", "parameters", "scheduling signals"))):
                if function.size1_in(i) != size or function.size2_in(i) not in (1, 0 if size == 0 else 1):
                    raise InputError(f"the model's {label} takes {function.size1_in(i)} {what}; "
                                     f"the names give {size}")
            if n_out is not None and function.size1_out(0) != n_out:
                raise InputError(f"the model's dynamics return {function.size1_out(0)} values for {n_out} states")
        if self.output_names and len(self.output_names) != self.output.size1_out(0):
            raise InputError(f"the model's output has {self.output.size1_out(0)} values; "
                             f"{len(self.output_names)} output names were given")
        if not (len(self.parameter_units) == len(self.positive) == self.n_theta):
            raise InputError("give one unit and one positivity flag per parameter")
        if self.parameter_scale and (len(self.parameter_scale) != self.n_theta or not all(
                math.isfinite(v) and v > 0 for v in self.parameter_scale)):
            raise InputError("parameter_scale needs one positive size per parameter")

    @property
    def n_states(self) -> int:
        """Number of states."""
        return len(self.state_names)

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return len(self.input_names)

    @property
    def n_s(self) -> int:
        """Number of scheduling signals."""
        return len(self.schedule_names)

    @property
    def n_theta(self) -> int:
        """Number of parameters."""
        return len(self.parameter_names)

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.output.size1_out(0))

    def cache_key(self) -> str:
        """Name the model exactly, for the compiled-code cache.

        Returns
        -------
        str
            A SHA-256 hex digest of its serialised functions, names and flags.
        """
        digest = hashlib.sha256()
        for part in (self.dynamics.serialize(), self.output.serialize(), repr(self.parameter_names),
                     repr(self.positive), repr(self.state_names), repr(self.input_names),
                     repr(self.schedule_names), self.description, repr(self.parameter_scale)):
            digest.update(part.encode())
            digest.update(b"\0")
        return digest.hexdigest()

    def check_parameters(self, theta: Any) -> np.ndarray:
        """Check a parameter vector against the model.

        Parameters
        ----------
        theta : array_like, shape (n_theta,)
            Parameter values, in the units of ``parameter_units``.

        Returns
        -------
        ndarray, shape (n_theta,)
            ``theta`` as floats.

        Raises
        ------
        InputError
            On a wrong size, a non-finite value, or a positive parameter that is not.
        """
        theta = np.asarray(theta, dtype=float).ravel()
        if theta.size != self.n_theta:
            raise InputError(f"the model has {self.n_theta} parameters ({', '.join(self.parameter_names)}); "
                             f"got {theta.size} values")
        if not np.all(np.isfinite(theta)):
            raise InputError("a parameter value is not finite")
        bad = [name for name, value, positive in zip(self.parameter_names, theta, self.positive)
               if positive and value <= 0]
        if bad:
            raise InputError(f"parameter {bad[0]!r} must be positive")
        return theta


def transition(model: GreyBoxModel, x: Any, u0: Any, u1: Any, theta: Any, dt: float, discretization: str,
                substeps: int) -> Any:
    """The state after one sample (SX): RK4 with inputs and scheduling signals linear over the sample, or Euler."""
    n_u = model.n_u

    def f(state: Any, v: Any) -> Any:
        return model.dynamics(state, v[:n_u], theta, v[n_u:])

    if discretization == "euler":
        return x + dt * f(x, u0)
    h = dt / substeps
    for i in range(substeps):
        begin, middle, end = (u0 + (u1 - u0) * (i + a) / substeps for a in (0.0, 0.5, 1.0))
        k1 = f(x, begin)
        k2 = f(x + 0.5 * h * k1, middle)
        k3 = f(x + 0.5 * h * k2, middle)
        k4 = f(x + h * k3, end)
        x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return x


@functools.lru_cache(maxsize=16)
def _simulator(model_key: str, model: GreyBoxModel, dt: float, discretization: str, substeps: int
               ) -> CompiledRecursion:
    """The compiled recursion ``(x, u_k, u_k+1, theta) -> (x_next, y_k)`` of a model (inputs then schedule)."""
    x = ca.SX.sym("x", model.n_states)
    u0 = ca.SX.sym("u0", model.n_u + model.n_s)
    u1 = ca.SX.sym("u1", model.n_u + model.n_s)
    theta = ca.SX.sym("theta", model.n_theta)
    x_next = transition(model, x, u0, u1, theta, dt, discretization, substeps)
    y = model.output(x, u0[: model.n_u], theta, u0[model.n_u:])
    step = ca.Function(f"greybox_{model_key[:12]}", [x, u0, u1, theta], [x_next, y],
                       ["x", "u0", "u1", "theta"], ["x_next", "y"], {"cse": True})
    return CompiledRecursion(step)


def driving(model: GreyBoxModel, record: IOData) -> np.ndarray:
    """The record's inputs, inputs first and scheduling signals last, as the model takes them (N, n_u + n_s)."""
    if record.n_u != model.n_u + model.n_s:
        raise InputError(f"the model takes {model.n_u} input(s) and {model.n_s} scheduling signal(s) "
                         f"({', '.join(model.input_names + model.schedule_names)}); the record has {record.n_u} inputs")
    if record.n_y != model.n_y:
        raise InputError(f"the model has {model.n_y} outputs; the record has {record.n_y}")
    return record.u


def simulate_greybox(model: GreyBoxModel, theta: Any, record: IOData, *, x0: Any = None, discretization: str = "rk4",
                     substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Simulate the model with parameters ``theta`` over a record's inputs and scheduling signals.

    Parameters
    ----------
    model : GreyBoxModel
        The model.
    theta : array_like (n_theta,)
        Its parameters.
    record : IOData
        ``u`` holds the inputs, then the scheduling signals (``n_u + n_s`` columns); ``y`` sets the size only.
    x0 : array_like, optional
        Initial state (default zero).
    discretization : {"rk4", "euler"}
        The step over a sample: classical Runge-Kutta or Euler.
    substeps : int
        Steps per sample.

    Returns
    -------
    y : ndarray (N, n_y)
        Outputs at the sample times.
    x : ndarray (N, n_states)
        States at the sample times.
    """
    return greybox_outputs(model, theta, driving(model, record), float(record.dt), x0=x0,
                           discretization=discretization, substeps=substeps)


def greybox_outputs(model: GreyBoxModel, theta: Any, u: np.ndarray, dt: float, *, x0: Any = None,
                    discretization: str = "rk4", substeps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """:func:`simulate_greybox` on arrays rather than a record.

    Parameters
    ----------
    model, theta, x0, discretization, substeps
        As :func:`simulate_greybox`.
    u : ndarray (N, n_u + n_s)
        The inputs, then the scheduling signals.
    dt : float
        Sample interval (s).

    Returns
    -------
    y, x : ndarray (N, n_y), (N, n_states)
        Outputs and states at the sample times.
    """
    check_discretization(discretization, substeps)
    theta = model.check_parameters(theta)
    simulator = _simulator(model.cache_key(), model, float(dt), discretization, int(substeps))
    x0 = np.zeros(model.n_states) if x0 is None else np.asarray(x0, dtype=float).ravel()
    if x0.shape != (model.n_states,) or not np.all(np.isfinite(x0)):
        raise InputError(f"x0 must hold {model.n_states} finite entries; got shape {x0.shape}")
    with np.errstate(all="ignore"):
        return simulator(x0, np.asarray(u, dtype=float), theta)


#: Central-difference step of the simulation's Jacobian, relative to each parameter (or to its scale where
#: that is larger): truncation (step^2) and rounding (eps / step) both near 1e-10 of a column
_DIFFERENCE_STEP = 1e-6


def simulation_fit_covariance(model: GreyBoxModel, theta: Any, data: IOData | Sequence[IOData], *,
                              discretization: str = "rk4", substeps: int = 1, jackknife: bool = True,
                              blocks: int | None = None, form: str = "linearised",
                              level: float = 0.95) -> tuple[np.ndarray, Any] | None:
    """The covariance of a grey-box estimate as a fit of its simulation errors, and how it was obtained.

    Each record is simulated from rest with ``theta``; the Jacobian of the outputs is taken by
    central differences (``2 n_theta`` simulations). The covariance is
    :func:`~vehid.identification.assessment.uncertainty.fit_covariance` of those errors: the
    delete-one-block jackknife of the fit where the records allow, which counts coloured
    residuals and model error as much as they move the estimate, else the formal Gauss-Newton
    covariance. Unlike the filter's own covariance pass, it does not take the innovations as
    white. None where the simulation is not finite.

    Parameters
    ----------
    model : GreyBoxModel
    theta : array_like (n_theta,)
        The estimate.
    data : IOData or sequence of IOData
        The records it was identified from (cut into blocks as one record).
    discretization, substeps
        As the identification ran.
    jackknife : bool
        False gives the formal covariance.
    blocks : int, optional
        Most blocks of the jackknife (default
        :data:`~vehid.identification.assessment.segments.DEFAULT_BLOCKS`).
    form : {"linearised", "one-step"}
        The jackknife replicates' curvature (:func:`~vehid.identification.assessment.uncertainty.fit_covariance`).
    level : float
        Level of the intervals the jackknife's degrees of freedom are allowed for at.

    Returns
    -------
    (covariance, UncertaintyMethod) or None
    """
    from ..assessment.uncertainty import difference_fit_covariance

    records = as_records(data)
    theta = model.check_parameters(theta)
    typical = np.asarray(model.parameter_scale, dtype=float) if model.parameter_scale else np.zeros(model.n_theta)
    steps = _DIFFERENCE_STEP * np.maximum(np.abs(theta), typical)
    if np.any(steps == 0):
        raise InputError("a parameter at zero without a scale has no difference step: give the model a parameter_scale")

    def simulated(values: np.ndarray) -> np.ndarray:
        return np.vstack([simulate_greybox(model, values, record, discretization=discretization,
                                           substeps=substeps)[0] for record in records])

    return difference_fit_covariance(simulated, theta, np.vstack([record.y for record in records]), steps=steps,
                                     dt=float(records[0].dt), jackknife=jackknife, form=form, level=level,
                                     **({} if blocks is None else {"blocks": blocks}))


def check_discretization(discretization: str, substeps: int) -> None:
    """Refuse a discretisation other than :data:`GREYBOX_DISCRETIZATIONS` or a step count other than a whole number >= 1."""
    if discretization not in GREYBOX_DISCRETIZATIONS:
        raise InputError(f"unknown discretization {discretization!r}; use one of {', '.join(GREYBOX_DISCRETIZATIONS)}")
    if isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1:
        raise InputError(f"substeps must be a whole number >= 1; got {substeps!r}")
