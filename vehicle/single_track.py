"""The linear single-track (bicycle) model as a grey-box model, and its handling numbers in closed form.

Axes and signs follow ISO 8855 (docs/conventions.md): x forward, y left, z up; a left turn has road-wheel
angle, yaw rate, lateral acceleration and lateral velocity positive. Cornering stiffnesses are positive
(axle force ``F_y = C alpha`` with the slip angles below), and an understeering car has ``K > 0``.

States ``v_y`` (lateral velocity of the CG, m/s) and ``r`` (yaw rate, rad/s); speed ``v_x`` (m/s) is a
measured time-varying parameter. With road-wheel angle ``delta`` (steering-wheel angle over the steering
ratio):

* slip angles ``alpha_f = delta - (v_y + l_f r) / v_x``, ``alpha_r = -(v_y - l_r r) / v_x``
* ``m (dv_y/dt + v_x r) = F_f + F_r``, ``I_z dr/dt = l_f F_f - l_r F_r``, ``a_y = (F_f + F_r) / m``
* sideslip at the CG ``beta = atan(v_y / v_x)``.

Options: a tyre relaxation length ``sigma`` turns each axle's slip angle into a state lagging the
kinematic one (``d alpha/dt = v_x / sigma (alpha_kinematic - alpha)``, Pacejka 2012, section 7.2.2); a
saturating axle characteristic ``F = mu F_z tanh(C alpha / (mu F_z))`` (``F_z`` the static axle load),
initial slope ``C``, limit ``mu F_z``, adds the axle friction coefficient ``mu`` as a fourth parameter.
With ``offsets`` constant sensor offsets of the steer channel and of each output join the parameters
(``measured = true + offset``). Below :data:`MIN_SPEED` the model is not meant to be used: the speed enters as
``sqrt(v_x^2 + MIN_SPEED^2)``, smooth and never zero.

Handling (Pacejka 2012, chapter 1; Gillespie 1992, chapter 6): understeer gradient
``K = (m / L) (l_r / C_f - l_f / C_r)`` (rad per m/s^2; times ``g 180/pi`` in deg/g), characteristic
speed ``sqrt(L / K)`` for ``K > 0``, critical speed ``sqrt(-L / K)`` for ``K < 0``, steady-state yaw-rate
gain ``r / delta = v / (L + K v^2)``; standard deviations by the delta method with exact CasADi
derivatives.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from vehid.identification.dataio.storage import register_codec
from vehid.identification.errors import InputError
from vehid.identification.filtering.greybox_structure import GreyBoxModel, greybox_outputs
from vehid.identification.filtering.greybox_model import IdentifiedGreyBox, schedule_columns, stable_over
from vehid.identification.models.discrete import ContinuousModel
from vehid.identification.models.protocol import StateSpaceModel, schedule_value, unscheduled

__all__ = [
    "GRAVITY",
    "MIN_SPEED",
    "QUANTITIES",
    "PARAMETER_NAMES",
    "SingleTrackConfig",
    "SingleTrackHandling",
    "HandlingValue",
    "single_track_model",
    "single_track_start",
    "single_track_handling",
    "config_from_vehicle",
    "IdentifiedSingleTrack",
    "SingleTrackAtSpeed",
    "MAX_SUBSTEPS",
    "STEP_PER_TIME_CONSTANT",
]

GRAVITY = 9.81  # m/s^2, as the vehicle parameters use it
MIN_SPEED = 0.1  # m/s: the smooth floor under the speed (module docstring); 5e-5 of the speed at 10 m/s
#: Most Runge-Kutta steps per sample an identified model takes; a record needing more reaches standstill.
MAX_SUBSTEPS = 20
#: A Runge-Kutta step covers at most this fraction of the fastest mode's time constant (RK4 is stable to 2.8).
STEP_PER_TIME_CONSTANT = 0.5

#: The outputs the model offers: name -> unit.
QUANTITIES = {"yaw_rate": "rad/s", "lateral_acceleration": "m/s^2", "sideslip": "rad", "lateral_velocity": "m/s"}

#: The parameters estimated, in order, with their units; ``axle_friction`` only with saturation.
PARAMETER_NAMES = ("cornering_stiffness_front", "cornering_stiffness_rear", "yaw_inertia", "axle_friction")
PARAMETER_UNITS = ("N/rad", "N/rad", "kg m^2", "-")

#: The typical size of a sensor offset (the prior's standard deviation on it): half a degree of
#: road-wheel angle, half a degree per second of yaw rate, 0.1 m/s^2, 0.2 degrees of sideslip.
OFFSET_SIZES = {"steer": 0.0087, "yaw_rate": 0.0087, "lateral_acceleration": 0.1, "sideslip": 0.0035,
                "lateral_velocity": 0.05}


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be a positive number; got {value!r}")
    return float(value)


@dataclass(frozen=True)
class SingleTrackConfig:
    """What is known of the car and how the model is built.

    Parameters
    ----------
    mass : float
        kg.
    cg_to_front_axle, cg_to_rear_axle : float
        ``l_f``, ``l_r`` (m).
    quantities : sequence of str
        The outputs, in order: names of :data:`QUANTITIES`.
    steering_ratio : float
        Steering-wheel angle per road-wheel angle; 1 where the input is the road-wheel angle.
    relaxation_length : float or None
        Tyre relaxation length ``sigma`` (m), the same on both axles; None: no lag.
    saturation : bool
        The saturating (tanh) axle characteristic with the axle friction coefficient as a parameter.
    offsets : bool
        Estimate constant sensor offsets too: of the steer channel (``steer_offset``, in its units) and
        of each quantity (``<quantity>_offset``): ``measured = true + offset``.
    """

    mass: float
    cg_to_front_axle: float
    cg_to_rear_axle: float
    quantities: tuple[str, ...] = ("yaw_rate", "lateral_acceleration")
    steering_ratio: float = 1.0
    relaxation_length: float | None = None
    saturation: bool = False
    offsets: bool = False

    def __post_init__(self) -> None:
        _positive("the mass", self.mass)
        _positive("the CG to front axle distance", self.cg_to_front_axle)
        _positive("the CG to rear axle distance", self.cg_to_rear_axle)
        if isinstance(self.steering_ratio, (int, float)) and self.steering_ratio < 0:
            raise InputError(f"the steering ratio must be positive (flip the channel's sign with 'scale'); "
                             f"got {self.steering_ratio!r}", options=("scale",))
        _positive("the steering ratio", self.steering_ratio)
        if self.relaxation_length is not None:
            _positive("the relaxation length", self.relaxation_length)
        quantities = tuple(str(q).strip() for q in self.quantities)
        unknown = [q for q in quantities if q not in QUANTITIES]
        if unknown:
            raise InputError(f"unknown quantity {unknown[0]!r}; use {', '.join(QUANTITIES)}")
        if not quantities or len(set(quantities)) != len(quantities):
            raise InputError("name each quantity once, at least one")
        object.__setattr__(self, "quantities", quantities)

    @property
    def wheelbase(self) -> float:
        return self.cg_to_front_axle + self.cg_to_rear_axle

    @property
    def axle_loads(self) -> tuple[float, float]:
        """Static front and rear axle loads (N)."""
        weight = self.mass * GRAVITY
        return weight * self.cg_to_rear_axle / self.wheelbase, weight * self.cg_to_front_axle / self.wheelbase

    @property
    def parameter_names(self) -> tuple[str, ...]:
        physical = PARAMETER_NAMES if self.saturation else PARAMETER_NAMES[:3]
        if not self.offsets:
            return physical
        return physical + ("steer_offset",) + tuple(f"{q}_offset" for q in self.quantities)

    @property
    def n_physical(self) -> int:
        """How many of the parameters are the car's (the rest are sensor offsets)."""
        return 4 if self.saturation else 3


def config_from_vehicle(params: Any, **changes: Any) -> SingleTrackConfig:
    """The mass and axle distances of a :class:`~vehicle.parameters.VehicleParameters`, with other fields."""
    chassis = params.chassis
    return SingleTrackConfig(mass=chassis.mass, cg_to_front_axle=chassis.cg_to_front_axle,
                             cg_to_rear_axle=chassis.cg_to_rear_axle, **changes)


def _axle_forces(config: SingleTrackConfig, alpha_f: Any, alpha_r: Any, theta: Any) -> tuple[Any, Any]:
    if not config.saturation:
        return theta[0] * alpha_f, theta[1] * alpha_r
    load_f, load_r = config.axle_loads
    limit_f, limit_r = theta[3] * load_f, theta[3] * load_r
    return limit_f * ca.tanh(theta[0] * alpha_f / limit_f), limit_r * ca.tanh(theta[1] * alpha_r / limit_r)


def single_track_model(config: SingleTrackConfig) -> GreyBoxModel:
    """The single-track model of ``config`` as a :class:`~identification.filtering.greybox_structure.GreyBoxModel`.

    Input: the steer channel (road-wheel angle times the steering ratio, rad); scheduling signal:
    the speed ``v_x`` (m/s); parameters ``C_f``, ``C_r`` (N/rad), ``I_z`` (kg m^2) and, with
    saturation, the axle friction coefficient; outputs: ``config.quantities``.
    """
    lf, lr, mass = config.cg_to_front_axle, config.cg_to_rear_axle, config.mass
    lagged = config.relaxation_length is not None
    n_theta = len(config.parameter_names)
    physical = config.n_physical
    x = ca.SX.sym("x", 4 if lagged else 2)
    u = ca.SX.sym("u", 1)
    theta = ca.SX.sym("theta", n_theta)
    s = ca.SX.sym("s", 1)
    vy, r = x[0], x[1]
    speed = ca.sqrt(s[0] ** 2 + MIN_SPEED**2)
    steer = u[0] - theta[physical] if config.offsets else u[0]
    delta = steer / config.steering_ratio
    kinematic_f = delta - (vy + lf * r) / speed
    kinematic_r = -(vy - lr * r) / speed
    alpha_f, alpha_r = (x[2], x[3]) if lagged else (kinematic_f, kinematic_r)
    force_f, force_r = _axle_forces(config, alpha_f, alpha_r, theta)
    lateral_acceleration = (force_f + force_r) / mass
    rates = [lateral_acceleration - speed * r, (lf * force_f - lr * force_r) / theta[2]]
    if lagged:
        rate = speed / config.relaxation_length
        rates += [rate * (kinematic_f - x[2]), rate * (kinematic_r - x[3])]
    values = {"yaw_rate": r, "lateral_acceleration": lateral_acceleration, "sideslip": ca.atan(vy / speed),
              "lateral_velocity": vy}
    y = ca.vertcat(*[values[q] for q in config.quantities])
    if config.offsets:
        y = y + theta[physical + 1:]
    names = ["x", "u", "theta", "s"]
    dynamics = ca.Function("single_track_dynamics", [x, u, theta, s], [ca.vertcat(*rates)], names, ["xdot"])
    output = ca.Function("single_track_output", [x, u, theta, s], [y], names, ["y"])
    states = ("lateral_velocity", "yaw_rate") + (("slip_angle_front", "slip_angle_rear") if lagged else ())
    units, positive, sizes = PARAMETER_UNITS[:physical], (True,) * physical, ()
    if config.offsets:
        units += ("rad",) + tuple(QUANTITIES[q] for q in config.quantities)
        positive += (False,) * (n_theta - physical)
        start = single_track_start(config)
        sizes = tuple(start[:physical]) + (OFFSET_SIZES["steer"] * config.steering_ratio,) + tuple(
            OFFSET_SIZES[q] for q in config.quantities)
    return GreyBoxModel(
        dynamics=dynamics, output=output, parameter_names=config.parameter_names,
        parameter_units=units, positive=positive, parameter_scale=sizes, state_names=states,
        input_names=("steer",), schedule_names=("speed",), output_names=config.quantities,
        description=f"single-track {config!r}",
    )


def single_track_start(config: SingleTrackConfig) -> np.ndarray:
    """Start values from mass and geometry alone: ``C = 12 F_z`` per axle, ``I_z = m l_f l_r``, ``mu = 1``
    (offsets 0).

    A cornering stiffness of 10-20 times the axle load per radian is the usual range of car tyres;
    ``m l_f l_r`` is the yaw inertia of the two-mass equivalent (a yaw radius of gyration of
    ``sqrt(l_f l_r)``, within some 10 % of measured saloons).
    """
    load_f, load_r = config.axle_loads
    start = [12.0 * load_f, 12.0 * load_r, config.mass * config.cg_to_front_axle * config.cg_to_rear_axle, 1.0]
    offsets = [0.0] * (len(config.parameter_names) - config.n_physical)  # sensor offsets start at none
    return np.array(start[: config.n_physical] + offsets)


@dataclass(frozen=True)
class HandlingValue:
    """One handling number with its standard deviation and unit."""

    value: float
    std: float
    unit: str

    def as_dict(self) -> dict[str, Any]:
        return {"value": self.value, "std": self.std, "unit": self.unit}


@dataclass(frozen=True)
class SingleTrackHandling:
    """Handling numbers of a single-track model (module docstring), each with its standard deviation.

    ``understeer_gradient`` in deg/g; ``limit_speed`` is the characteristic speed where ``K > 0``
    and the critical speed where ``K < 0`` (``limit_speed_kind`` says which; None for a neutral car);
    ``yaw_rate_gains`` maps speed (m/s) to the steady-state ``r / delta`` (1/s, per road-wheel angle).
    """

    understeer_gradient: HandlingValue
    limit_speed: HandlingValue | None
    limit_speed_kind: str | None
    yaw_rate_gains: tuple[tuple[float, HandlingValue], ...]

    def as_dict(self) -> dict[str, Any]:
        """The JSON entry ``handling``: ``understeer_gradient_deg_per_g`` and the limit speed with their std."""
        # each number as {value, std, unit}, as physical_parameters and the handling command give them
        summary: dict[str, Any] = {"understeer_gradient_deg_per_g": self.understeer_gradient.as_dict()}
        if self.limit_speed is not None:
            summary[f"{self.limit_speed_kind}_speed_m_s"] = self.limit_speed.as_dict()
        summary["yaw_rate_gain"] = [{"speed_m_s": speed, "value": gain.value, "std": gain.std, "unit": gain.unit}
                                    for speed, gain in self.yaw_rate_gains]
        return summary


def _delta_method(expression: Any, theta: Any, values: np.ndarray, covariance: np.ndarray) -> tuple[float, float]:
    function = ca.Function("handling_value", [theta], [expression, ca.jacobian(expression, theta)])
    value, gradient = (np.asarray(v, dtype=float) for v in function(values))
    gradient = gradient.ravel()
    variance = float(gradient @ covariance @ gradient)
    return float(value.ravel()[0]), math.sqrt(max(variance, 0.0)) if math.isfinite(variance) else float("nan")


def single_track_handling(config: SingleTrackConfig, parameters: Any, covariance: Any = None,
                          speeds: Sequence[float] = (10.0, 20.0, 30.0)) -> SingleTrackHandling:
    """Understeer gradient, characteristic or critical speed and yaw-rate gains, with the delta method.

    Parameters
    ----------
    config : SingleTrackConfig
    parameters : array_like
        ``C_f``, ``C_r`` (N/rad), ``I_z`` (and ``mu``), as :func:`single_track_model` orders them.
    covariance : array_like, optional
        Their covariance (default: none, std 0).
    speeds : sequence of float
        Speeds (m/s) of the steady-state yaw-rate gains.
    """
    values = np.asarray(parameters, dtype=float).ravel()
    n = len(config.parameter_names)
    if values.size != n:
        raise InputError(f"the single-track model has {n} parameters; got {values.size}")
    covariance = np.zeros((n, n)) if covariance is None else np.asarray(covariance, dtype=float)
    if not np.all(np.isfinite(covariance)):
        covariance = np.full((n, n), np.nan)
    theta = ca.SX.sym("theta", n)
    lf, lr, wheelbase = config.cg_to_front_axle, config.cg_to_rear_axle, config.wheelbase
    gradient = config.mass / wheelbase * (lr / theta[0] - lf / theta[1])  # rad per m/s^2
    per_g = GRAVITY * 180.0 / math.pi
    k_value, k_std = _delta_method(gradient * per_g, theta, values, covariance)
    k_rad = k_value / per_g
    limit, kind = None, None
    if k_rad > 0:
        limit, kind = HandlingValue(*_delta_method(ca.sqrt(wheelbase / gradient), theta, values, covariance), "m/s"), \
            "characteristic"
    elif k_rad < 0:
        limit, kind = HandlingValue(*_delta_method(ca.sqrt(-wheelbase / gradient), theta, values, covariance), "m/s"), \
            "critical"
    gains = tuple((float(v), HandlingValue(*_delta_method(v / (wheelbase + gradient * v**2), theta, values, covariance),
                                           "1/s"))
                  for v in speeds)
    return SingleTrackHandling(HandlingValue(k_value, k_std, "deg/g"), limit, kind, gains)


# ---------------------------------------------------------------------------------------------
# The identified model as a value: saved, loaded, and linear at each speed for the handling metrics
# ---------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=16)
def _linearisation(config: SingleTrackConfig) -> ca.Function:
    """``(theta, speed) -> (A, B, C, D)`` at straight running, B and D per road-wheel angle."""
    model = single_track_model(config)
    x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u", 1)
    theta, speed = ca.SX.sym("theta", model.n_theta), ca.SX.sym("speed", 1)
    rates, outputs = model.dynamics(x, u, theta, speed), model.output(x, u, theta, speed)
    # straight running: no states excited and the steer channel at its offset (zero slip angles), where
    # the saturating axle's slope is its cornering stiffness
    rest = theta[config.n_physical] if config.offsets else 0.0
    at_rest = [ca.substitute(ca.substitute(jacobian, x, ca.DM.zeros(model.n_states)), u, rest)
               for jacobian in (ca.jacobian(rates, x), ca.jacobian(rates, u), ca.jacobian(outputs, x),
                                ca.jacobian(outputs, u))]
    ratio = config.steering_ratio  # the channel is the road-wheel angle times the ratio
    return ca.Function("single_track_linearisation", [theta, speed],
                       [at_rest[0], at_rest[1] * ratio, at_rest[2], at_rest[3] * ratio],
                       ["theta", "speed"], ["A", "B", "C", "D"])


@functools.lru_cache(maxsize=16)
def _structure(config: SingleTrackConfig) -> GreyBoxModel:
    """:func:`single_track_model` of ``config``, built once (its functions key the compiled simulation)."""
    return single_track_model(config)


@dataclass(frozen=True, eq=False)
class SingleTrackAtSpeed(StateSpaceModel):
    """An identified single-track model linearised at one speed: continuous time, input the road-wheel angle.

    A linear model of the protocol (:class:`~vehid.identification.models.protocol.IdentifiedModel`), and
    what :func:`vehid.vehicle.handling.handling_metrics` asks of one (``parameters`` with
    ``parameter_covariance`` and ``with_parameters``), so the handling metrics carry the parameters'
    uncertainty by the delta method.
    """

    config: SingleTrackConfig
    parameters: np.ndarray
    parameter_covariance: np.ndarray | None
    speed: float

    @property
    def input_names(self) -> tuple[str, ...]:
        return ("steer",)

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.config.quantities

    @property
    def n_u(self) -> int:
        """One input: the road-wheel angle."""
        return 1

    @property
    def n_y(self) -> int:
        """The configuration's quantities."""
        return len(self.config.quantities)

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """``(A, B, C, D, None)`` at straight running: states as :func:`single_track_model` names them."""
        unscheduled(schedule)
        A, B, C, D = (np.asarray(m, dtype=float) for m in _linearisation(self.config)(self.parameters, self.speed))
        return A, B, C, D, None

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None,
                         schedule: Any = None) -> np.ndarray:
        """Outputs (N, n_y) for road-wheel angles (N, 1) linear between samples, exact (first-order hold).

        Parameters
        ----------
        u : array_like (N, 1)
        dt : float
            Sample interval (s); required.
        x0 : array_like, optional
            Initial state (default straight running).
        schedule : array_like (N,), optional
            Changes nothing: the model holds at its one speed.

        Returns
        -------
        ndarray (N, n_y)
        """
        return ContinuousModel(*self.to_statespace()[:4]).simulate_outputs(u, dt, x0=x0, schedule=schedule)

    def with_parameters(self, theta: Any) -> "SingleTrackAtSpeed":
        """The same model with parameters ``theta``."""
        return replace(self, parameters=np.asarray(theta, dtype=float).ravel())


@dataclass(frozen=True, eq=False)
class IdentifiedSingleTrack(StateSpaceModel):
    """A single-track model identified from a log: its configuration, parameters and their covariance.

    Speed is a parameter of the model, so it is a family over speed like the scheduled modal models:
    :meth:`model_at` gives the linear model at a speed (input the road-wheel angle), :attr:`grid` the
    speeds the log spans (the handling command's default). Saved as JSON (``kind: single-track``) by
    ``vehid identify --structure single-track --save-model``.

    It meets the model protocol (:class:`~vehid.identification.models.protocol.IdentifiedModel`) as a
    nonlinear model scheduled on speed: its input is the steer channel (road-wheel angle times the
    steering ratio) and a record holds the speed as its last input column (``schedule=`` takes it apart).
    It simulates by the compiled Runge-Kutta recursion the grey-box IEKF used
    (:attr:`greybox`), with as many steps per sample as the record's speeds need
    (:meth:`substeps_for`); at a speed, its state-space form is the linearisation at straight running
    per steer channel. Its extras: the configuration, the named parameters, :meth:`model_at` and the
    closed-form :meth:`handling`.

    Examples
    --------
    >>> import numpy as np
    >>> car = IdentifiedSingleTrack(SingleTrackConfig(mass=1500.0, cg_to_front_axle=1.2, cg_to_rear_axle=1.5),
    ...                             [80_000.0, 100_000.0, 2500.0], None, (10.0, 30.0))
    >>> [f"{mode.frequency_hz:.2f} Hz, damping {mode.damping:.2f}" for mode in car.modes(schedule=20.0)]
    ... # at 20 m/s: det A = 60.5 1/s^2, trace A = -12.8 1/s
    ['1.24 Hz, damping 0.82']
    >>> car.is_stable()  # an understeering car, at every speed of its log
    True

    Parameters
    ----------
    config : SingleTrackConfig
    parameters : array_like (n_theta,)
        In the order of ``config.parameter_names``.
    parameter_covariance : array_like (n_theta, n_theta), optional
    speed_range : (float, float)
        Least and greatest speed of the log (m/s).
    meta : mapping
        What else to keep (fits, the log's name).
    """

    config: SingleTrackConfig
    parameters: np.ndarray
    parameter_covariance: np.ndarray | None
    speed_range: tuple[float, float]
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.config.parameter_names)
        parameters = np.asarray(self.parameters, dtype=float).ravel()
        if parameters.size != n:
            raise InputError(f"the single-track model has {n} parameters; got {parameters.size}")
        object.__setattr__(self, "parameters", parameters)
        if self.parameter_covariance is not None:
            covariance = np.asarray(self.parameter_covariance, dtype=float)
            if covariance.shape != (n, n):
                raise InputError(f"the parameter covariance must be {n} x {n}; got {covariance.shape}")
            object.__setattr__(self, "parameter_covariance", covariance)
        low, high = (float(v) for v in self.speed_range)
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise InputError(f"the speed range must be positive and ordered (m/s); got {self.speed_range}")
        object.__setattr__(self, "speed_range", (low, high))

    @property
    def wheelbase(self) -> float:
        return self.config.wheelbase

    @property
    def grid(self) -> np.ndarray:
        """Three speeds spanning the log (m/s), rounded to whole metres per second where that keeps them inside."""
        low, high = self.speed_range
        rounded = np.unique(np.round(np.linspace(low, high, 3)))
        return rounded if rounded[0] >= low and rounded[-1] <= high else np.unique(np.linspace(low, high, 3))

    def model_at(self, speed: float) -> SingleTrackAtSpeed:
        """The model linearised at ``speed`` (m/s), input the road-wheel angle (for the handling metrics)."""
        return SingleTrackAtSpeed(self.config, self.parameters, self.parameter_covariance, float(speed))

    def handling(self, speeds: Sequence[float] | None = None) -> SingleTrackHandling:
        """The closed-form handling numbers with their standard deviations (:func:`single_track_handling`).

        Parameters
        ----------
        speeds : sequence of float, optional
            Speeds (m/s) of the yaw-rate gains; default :attr:`grid`.

        Returns
        -------
        SingleTrackHandling
        """
        return single_track_handling(self.config, self.parameters, self.parameter_covariance,
                                     tuple(self.grid) if speeds is None else speeds)

    # -- the model protocol ------------------------------------------------------------------

    #: Nonlinear where saturating or lagged, and varying with speed along a record: scored from rest.
    is_linear = False
    #: Scheduled on the speed (m/s).
    is_scheduled = True

    @property
    def n_states(self) -> int:
        """Lateral velocity and yaw rate, and the slip angles with a relaxation length."""
        return 4 if self.config.relaxation_length is not None else 2

    @property
    def n_u(self) -> int:
        """One input: the steer channel."""
        return 1

    @property
    def n_y(self) -> int:
        """The configuration's quantities."""
        return len(self.config.quantities)

    @property
    def record_inputs(self) -> int:
        """Input columns of a record: the steer channel, then the speed."""
        return 2

    @property
    def input_names(self) -> tuple[str, ...]:
        return ("steer",)

    @property
    def output_names(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.config.quantities

    @property
    def schedule_range(self) -> tuple[float, float]:
        """The log's speed range (m/s)."""
        return self.speed_range

    @functools.cached_property
    def greybox(self) -> IdentifiedGreyBox:
        """The model as the grey-box IEKF identified it: :func:`single_track_model` with these parameters."""
        return IdentifiedGreyBox(_structure(self.config), self.parameters, self.parameter_covariance,
                                 schedule_range=np.array([self.speed_range]), meta=dict(self.meta))

    def substeps_for(self, speeds: Any, dt: float) -> int:
        """Runge-Kutta steps per sample that keep every mode well inside RK4's stability region.

        The fastest eigenvalue of the linearisation at the least and at the greatest of ``speeds`` (the
        bicycle's rates fall as ``1 / v``, a relaxation length's rise as ``v / sigma``); a step covers at
        most :data:`STEP_PER_TIME_CONSTANT` of its time constant.

        Parameters
        ----------
        speeds : array_like
            The record's speeds (m/s).
        dt : float
            Its sample interval (s).

        Returns
        -------
        int

        Raises
        ------
        InputError
            Where more than :data:`MAX_SUBSTEPS` would be needed: the record reaches standstill, where the
            model does not hold.
        """
        speeds = np.asarray(speeds, dtype=float)
        low, high = max(float(np.min(speeds)), MIN_SPEED), max(float(np.max(speeds)), MIN_SPEED)
        rate = max(float(np.max(np.abs(np.linalg.eigvals(self.to_statespace(schedule=v)[0]))))
                   for v in (low, high))
        needed = int(np.ceil(rate * dt / STEP_PER_TIME_CONSTANT))
        if needed > MAX_SUBSTEPS:
            raise InputError(f"the record's speed falls to {np.min(speeds):.3g} m/s, where the single-track model's "
                             f"modes are too fast for its {dt:g} s samples: leave out the slow parts")
        return max(needed, 1)

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """``(A, B, C, D, None)`` at straight running at speed ``schedule`` (m/s, required), per steer channel.

        Any positive speed is taken (the model is physical); the log spans :attr:`speed_range`.
        """
        speed = schedule_value(schedule, 0.0, math.inf, "speed")
        A, B, C, D, _ = self.model_at(speed).to_statespace()
        ratio = self.config.steering_ratio  # model_at's input is the road-wheel angle, the channel's is times it
        return A, B / ratio, C, D / ratio, None

    def is_stable(self, *, schedule: float | None = None) -> bool:
        """Stable at speed ``schedule``; without one, at speeds across :attr:`speed_range`
        (:func:`~vehid.identification.filtering.greybox_model.stable_over`)."""
        if schedule is None:
            return stable_over(self, *self.speed_range)
        return super().is_stable(schedule=schedule)

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None, schedule: Any = None,
                         substeps: int | None = None, return_states: bool = False) -> Any:
        """Outputs (N, n_y) driven by the steer channel along the measured speed, compiled (RK4).

        Parameters
        ----------
        u : array_like (N, 1), or (N, 2) with the speed last
        dt : float
            Sample interval (s); required.
        x0 : array_like (n_states,), optional
            Initial state (default straight running).
        schedule : array_like (N,), optional
            The speed (m/s) at each sample; without it, ``u``'s last column.
        substeps : int, optional
            Runge-Kutta steps per sample; default :meth:`substeps_for` the record's speeds.
        return_states : bool
            Also return the states (N, n_states).

        Returns
        -------
        y : ndarray (N, n_y)  (and x, (N, n_states), if asked)
        """
        if dt is None or not (np.isfinite(dt) and dt > 0):
            raise InputError(f"the single-track model needs the sample interval dt (> 0) of its input; got {dt}")
        driving = schedule_columns(u, schedule, 1, 1, "speed")
        steps = self.substeps_for(driving[:, 1], dt) if substeps is None else substeps
        y, x = greybox_outputs(_structure(self.config), self.parameters, driving, float(dt), x0=x0, substeps=steps)
        return (y, x) if return_states else y

    def simulate(self, record: Any, *, x0: Any = None, substeps: int | None = None) -> Any:
        """The model's response to ``record`` (steer channel, then speed) from ``x0`` (default straight running).

        Parameters
        ----------
        record : IOData
        x0 : array_like (n_states,), optional
        substeps : int, optional
            As :meth:`simulate_outputs`.

        Returns
        -------
        TimeResponse
            With the states and, where the record has n_y outputs, them as ``measured``.
        """
        from vehid.identification.models.responses import simulated_response

        y, x = self.simulate_outputs(record.u, record.dt, x0=x0, substeps=substeps, return_states=True)
        return simulated_response(record, y, x=x, output_names=self.output_names,
                                  state_names=_structure(self.config).state_names)

    def to_casadi(self) -> ca.Function:
        """``(x, u, s) -> (xdot, y)``: the continuous-time model, parameters in it, ``s`` the speed (m/s)."""
        return self.greybox.to_casadi()

    def mat_fields(self) -> dict[str, Any]:
        """The parameters (and covariance), the configuration's numbers and, at each speed of :attr:`grid`,
        the state-space form: ``A`` (n_grid, n, n), ``B``, ``C``, ``D`` likewise."""
        config = self.config
        forms = [self.to_statespace(schedule=float(v)) for v in self.grid]
        return {"parameters": self.parameters, "parameter_names": list(config.parameter_names),
                **({} if self.parameter_covariance is None else {"parameter_covariance": self.parameter_covariance}),
                "mass": config.mass, "cg_to_front_axle": config.cg_to_front_axle,
                "cg_to_rear_axle": config.cg_to_rear_axle, "steering_ratio": config.steering_ratio,
                "speed_range": np.array(self.speed_range), "grid": self.grid,
                **{name: np.array([form[i] for form in forms]) for i, name in enumerate("ABCD")}}

    def save_json(self, path: Any) -> Any:
        """Write :meth:`to_dict` (what ``vehid handling`` reads) as JSON, with the time domain first."""
        import json
        from pathlib import Path

        from vehid.identification.jsonable import to_jsonable

        path = Path(path)
        path.write_text(json.dumps(to_jsonable({"time_domain": "continuous", "dt": None, **self.to_dict()}),
                                   indent=2) + "\n")
        return path

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``kind: single-track``): configuration, parameters, covariance, speed range, meta."""
        config = self.config
        return {
            "kind": "single-track",
            "config": {"mass": config.mass, "cg_to_front_axle": config.cg_to_front_axle,
                       "cg_to_rear_axle": config.cg_to_rear_axle, "quantities": list(config.quantities),
                       "steering_ratio": config.steering_ratio, "relaxation_length": config.relaxation_length,
                       "saturation": config.saturation, "offsets": config.offsets},
            "parameter_names": list(config.parameter_names),
            "parameters": self.parameters.tolist(),
            "parameter_covariance": None if self.parameter_covariance is None else self.parameter_covariance.tolist(),
            "speed_range_m_s": list(self.speed_range),
            "meta": dict(self.meta),
        }

    @classmethod
    def from_dict(cls, content: Mapping[str, Any]) -> "IdentifiedSingleTrack":
        """Inverse of :meth:`to_dict` (also reads the model files ``vehid identify --save-model`` wrote)."""
        if content.get("kind") != "single-track":
            raise InputError("not a single-track model (kind single-track)")
        config = SingleTrackConfig(**{**content["config"], "quantities": tuple(content["config"]["quantities"])})
        if list(content.get("parameter_names", config.parameter_names)) != list(config.parameter_names):
            raise InputError(f"the parameters are named {content['parameter_names']}; the configuration's are "
                             f"{list(config.parameter_names)}")
        covariance = content.get("parameter_covariance")
        return cls(config, content["parameters"], None if covariance is None else np.asarray(covariance, dtype=float),
                   tuple(content["speed_range_m_s"]), dict(content.get("meta", {})))


# archived under names that stay as long as such archives exist (results/RESULTS_LAYOUT.md): the model as its
# to_dict, the linearisation at a speed and the configuration one member per field
register_codec(IdentifiedSingleTrack, "single_track_model")
register_codec(SingleTrackAtSpeed, "single_track_at_speed")
register_codec(SingleTrackConfig, "single_track_config")
