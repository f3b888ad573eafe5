"""Calibration of the 23-state vehicle model to a measured log with the grey-box IEKF.

Chosen numeric fields of a vehicle (``section.field`` as in its TOML file, for instance ``tyre.PKY1``)
become symbols of the full model (:func:`vehid.vehicle.model.vehicle_expressions`), which is then a
:class:`~vehid.identification.filtering.greybox_structure.GreyBoxModel`; :func:`calibrate_vehicle` estimates them from a log
of the steer, the forward speed and measured quantities (yaw rate, lateral acceleration, ...).

Choices, each stated where it is made:

* The measured speed drives the model as the replay does (:mod:`vehid.vehicle.replay`): it is the
  reference of the speed hold, with its rate as feed-forward; both are scheduling signals of the
  grey-box model. The filter therefore never has to estimate the longitudinal motion from the data
  (which the chosen parameters barely touch), and the speed state stays within the hold's small error
  of the log: the lateral parameters are estimated at the speeds actually driven.
* The filter's states are the deviation from straight running at the reference speed
  (``x = dx + S V_ref``, ``S`` the straight-running direction: forward speed and wheel spins), because
  the grey-box filter starts every pass from zero states: zero deviation is the car running straight
  at the log's first speed, not a car at rest. ``S`` is linear in the speed, so ``d(dx)/dt =
  f(dx + S V_ref) - S dV_ref/dt`` exactly.
* Identifiability: after the fit, a parameter whose standard deviation exceeds its own size or
  :data:`PRIOR_SHARE_LIMIT` of its prior standard deviation (the log taught little), or whose
  correlation with another exceeds :data:`CORRELATION_LIMIT` in magnitude (of a correlated pair the
  one less certain relative to its size), is not determined by the log. It is held at its prior and
  the others are estimated again without it, until every remaining one is determined. Each
  parameter may have its own prior std (``prior_std``); the limit is then half of that one.
  An estimate that makes no valid vehicle (the filter's model runs past the vehicle's checks: a grip
  the centre of gravity would tip over at) is held the same way, the free parameter that moved
  furthest from its start, counted in its prior std, first.
* Standard deviations widen by the residuals' correlation time (the grey-box filter's
  ``coloured_residuals``): a model's error on a measured log is coloured, and the filter's own
  covariance, which counts every sample as independent, would be too small by that factor.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.filtering.greybox import GreyBoxOptions, GreyBoxResult, identify_greybox
from vehid.identification.filtering.greybox_structure import GreyBoxModel

from .model import CORNERS, OUTPUT_NAMES, OUTPUT_UNITS, STATE_NAMES, vehicle_expressions
from .parameters import VehicleParameters, static_axle_loads
from .tyre import cornering_stiffness
from .simulation import simulate

__all__ = [
    "CORRELATION_LIMIT",
    "DEFAULT_PARAMETERS",
    "PRIOR_SHARE_LIMIT",
    "ROLL_PARAMETERS",
    "Calibration",
    "calibration_model",
    "check_parameter",
    "held_stiffness_scales",
    "STIFFNESS_SCALES",
    "calibration_record",
    "calibrate_vehicle",
    "simulated_log",
    "speed_schedule",
    "vehicle_toml",
    "vehicle_with",
]

#: Parameters a log of steer, speed, yaw rate and lateral acceleration usually determines: the tyres'
#: cornering stiffness (both axles), the front axle's share of it (the understeer balance) and the
#: yaw inertia (the yaw response's lag).
DEFAULT_PARAMETERS = ("tyre.PKY1", "tyre.front_cornering_scale", "chassis.yaw_inertia")
#: Added to the defaults when the roll angle is measured: what sets the roll response.
ROLL_PARAMETERS = ("chassis.roll_inertia", "suspension.front_anti_roll_bar")

#: |correlation| above which two parameters are not told apart by the log (module docstring).
CORRELATION_LIMIT = 0.95
#: A parameter whose std the log did not bring below this share of its prior std is not determined:
#: with the default prior (std 1 on the logarithm) an unexcited parameter's std is its own size, and a
#: threshold at exactly that size would decide on the rounding of the covariance pass.
PRIOR_SHARE_LIMIT = 0.5

# Fields that steer a decision in the model's construction (a branch, not arithmetic): a symbol there
# has no single model to stand for.
_DECISION_FIELDS = ("steering.compliance", "drive.front_drive_share", "drive.slip_limit", "aerodynamics.drag_area",
                    "aerodynamics.front_downforce_area", "aerodynamics.rear_downforce_area")

# Half-width (s) of the moving average under the measured speed's rate: a 0.1 s window passes the
# speed changes a driver makes (below 2 Hz) and removes most of a speed sensor's white noise.
_RATE_SMOOTHING = 0.05


def _field(params: VehicleParameters, name: str) -> tuple[Any, str, str]:
    """The section object, field name and unit of ``section.field``; InputError naming the problem."""
    section, _, field_name = name.partition(".")
    holder = getattr(params, section, None)
    if holder is None or not dataclasses.is_dataclass(holder) or not field_name:
        raise InputError(f"unknown vehicle parameter {name!r}: give section.field as in a vehicle file "
                         "(for instance tyre.PKY1, chassis.yaw_inertia)")
    fields = {item.name: item for item in dataclasses.fields(holder)}
    if field_name not in fields:
        raise InputError(f"unknown vehicle parameter {name!r}: [{section}] has no field {field_name!r}")
    if name in _DECISION_FIELDS:
        raise InputError(f"vehicle parameter {name!r} selects the model's structure and cannot be calibrated")
    return holder, field_name, str(fields[field_name].metadata.get("unit", "-"))


def check_parameter(params: VehicleParameters, name: str) -> str:
    """The unit of the vehicle field ``name`` (``section.field``), or InputError where it is unknown or
    selects the model's structure (it cannot be calibrated)."""
    return _field(params, name)[2]


def vehicle_with(params: VehicleParameters, names: Sequence[str], values: Sequence[Any]) -> VehicleParameters:
    """``params`` with the named fields set to ``values`` (numbers: validated as a vehicle file is)."""
    changes: dict[str, dict[str, Any]] = {}
    for name, value in zip(names, values):
        _field(params, name)
        section, _, field_name = name.partition(".")
        changes.setdefault(section, {})[field_name] = float(value)
    sections = {section: dataclasses.replace(getattr(params, section), **fields) for section, fields in changes.items()}
    return dataclasses.replace(params, **sections)


def _symbolic_vehicle(params: VehicleParameters, names: Sequence[str], theta: ca.SX) -> VehicleParameters:
    """A copy of ``params`` whose named fields hold the symbols ``theta`` (not validated: symbols have no sign)."""
    by_section: dict[str, dict[str, Any]] = {}
    for i, name in enumerate(names):
        section, _, field_name = name.partition(".")
        by_section.setdefault(section, {})[field_name] = theta[i]
    copy = dataclasses.replace(params)
    for section, fields in by_section.items():
        holder = dataclasses.replace(getattr(params, section))
        for field_name, symbol in fields.items():
            object.__setattr__(holder, field_name, symbol)
        object.__setattr__(copy, section, holder)
    return copy


#: The cornering scales that follow the tyres' load sensitivity where it is calibrated with the axles'
#: static stiffness held (:func:`held_stiffness_scales`).
STIFFNESS_SCALES = ("tyre.front_cornering_scale", "tyre.rear_cornering_scale")


def held_stiffness_scales(params: VehicleParameters, load_sensitivity: Any,
                          scales: tuple[Any, Any] | None = None) -> tuple[Any, Any]:
    """The front and rear cornering scales of ``params`` (or ``scales``) as they are where ``tyre.PKY2`` is
    ``load_sensitivity`` (a number or a CasADi symbol) and each axle's cornering stiffness at its static
    load stays what the scale gives at the PKY2 of ``params``.

    ``PKY2`` sets the load at which a tyre's cornering stiffness stops growing (Pacejka 2012, eq. 4.E25):
    it changes how an axle's stiffness moves with the load, and the stiffness at the static load with
    it. With the static stiffness held, PKY2 is the shape alone and each cornering scale the axle's
    level at the prior's PKY2: the two are then told apart by a drive (the level by the balance, the
    shape by how the balance moves as the load moves across and along the car), which they were not
    otherwise (on simulated drives to 0.8 g the front scale and PKY2 correlated by 0.98-0.99, and -0.64
    with the stiffness held; benchmarks/calibration.py).
    """
    tyre = params.tyre
    scales = (tyre.front_cornering_scale, tyre.rear_cornering_scale) if scales is None else scales
    if isinstance(load_sensitivity, (int, float)):
        shaped = dataclasses.replace(tyre, PKY2=float(load_sensitivity))
    else:
        shaped = dataclasses.replace(tyre)
        object.__setattr__(shaped, "PKY2", load_sensitivity)
    return tuple(scale * cornering_stiffness(load / 2, tyre) / cornering_stiffness(load / 2, shaped)
                 for scale, load in zip(scales, static_axle_loads(params)))


def _straight_direction(params: VehicleParameters) -> np.ndarray:
    """States of straight running per unit speed (forward speed and wheel spins): linear in the speed."""
    direction = np.zeros(len(STATE_NAMES))
    direction[STATE_NAMES.index("u")] = 1.0
    for corner in CORNERS:
        direction[STATE_NAMES.index(f"omega_{corner}")] = 1.0 / float(params.tyre.rolling_radius)
    return direction


def calibration_model(params: VehicleParameters, parameters: Sequence[str], quantities: Sequence[str], *,
                      hold_static_stiffness: bool = False) -> GreyBoxModel:
    """The 23-state model of ``params`` with ``parameters`` symbolic, measuring ``quantities``.

    With ``hold_static_stiffness`` (``tyre.PKY2`` calibrated) the cornering scales, calibrated or not,
    are the axles' levels at the PKY2 of ``params``, and PKY2 moves only how the stiffness changes
    with the load (:func:`held_stiffness_scales`).

    Parameters
    ----------
    params : VehicleParameters
        The vehicle; its values of the chosen fields are the starts.
    parameters : sequence of str
        ``section.field`` names (module docstring).
    quantities : sequence of str
        Model outputs (:data:`vehid.vehicle.model.OUTPUT_NAMES`) the log measures, in its column order.

    Returns
    -------
    GreyBoxModel
        Input ``steer`` (road-wheel, rad); scheduling signals ``reference_speed`` (m/s) and
        ``reference_acceleration`` (m/s^2); states: the deviation from straight running.
    """
    parameters, quantities = tuple(parameters), tuple(quantities)
    if not parameters:
        raise InputError("choose at least one vehicle parameter to calibrate")
    if len(set(parameters)) != len(parameters):
        raise InputError("a vehicle parameter is named twice")
    if not quantities or len(set(quantities)) != len(quantities):
        raise InputError("name each measured quantity once")
    unknown = [q for q in quantities if q not in OUTPUT_NAMES]
    if unknown:
        raise InputError(f"unknown quantity {unknown[0]!r}; the model offers {', '.join(OUTPUT_NAMES)}")
    units, positive, starts = [], [], []
    for name in parameters:
        holder, field_name, unit = _field(params, name)
        value = float(getattr(holder, field_name))
        if value == 0.0:
            raise InputError(f"vehicle parameter {name!r} is zero: give it a non-zero prior (its size sets its scale)")
        units.append(unit)
        positive.append(value > 0)
        starts.append(value)
    theta = ca.SX.sym("theta", len(parameters))
    symbolic = _symbolic_vehicle(params, parameters, theta)
    if hold_static_stiffness:
        if "tyre.PKY2" not in parameters:
            raise InputError("holding the axles' static cornering stiffness needs tyre.PKY2 calibrated")
        levels = tuple(getattr(symbolic.tyre, name.partition(".")[2]) for name in STIFFNESS_SCALES)
        front, rear = held_stiffness_scales(params, theta[parameters.index("tyre.PKY2")], levels)
        object.__setattr__(symbolic.tyre, "front_cornering_scale", front)
        object.__setattr__(symbolic.tyre, "rear_cornering_scale", rear)
    try:
        x, steer, reference_speed, reference_acceleration, xdot, y = vehicle_expressions(symbolic)
    except (RuntimeError, NotImplementedError, TypeError) as exc:  # a symbol met a branch
        raise InputError(f"one of {', '.join(parameters)} cannot be a calibration parameter: {exc}") from None
    deviation = ca.SX.sym("deviation", len(STATE_NAMES))
    straight = ca.DM(_straight_direction(params))
    full = deviation + straight * reference_speed
    rows = [OUTPUT_NAMES.index(q) for q in quantities]
    rate = ca.substitute(xdot, x, full) - straight * reference_acceleration
    measured = ca.substitute(y[rows], x, full)
    schedule = ca.vertcat(reference_speed, reference_acceleration)
    dynamics = ca.Function("calibration_dynamics", [deviation, steer, theta, schedule], [rate])
    output = ca.Function("calibration_output", [deviation, steer, theta, schedule], [measured])
    return GreyBoxModel(
        dynamics=dynamics, output=output, parameter_names=parameters, parameter_units=tuple(units),
        positive=tuple(positive), state_names=tuple(f"d_{name}" for name in STATE_NAMES), input_names=("steer",),
        schedule_names=("reference_speed", "reference_acceleration"), output_names=quantities,
        description=f"23-state vehicle {params.name!r}: {', '.join(parameters)} calibrated"
                    + (", the axles' static cornering stiffness held" if hold_static_stiffness else ""),
    )


def speed_schedule(speed: Any, dt: float, acceleration: Any = None) -> np.ndarray:
    """The scheduling signals of a measured speed: itself and its smoothed rate, (N, 2).

    The rate is the difference quotient of the speed averaged over ``2 * 0.05 s`` (see
    ``_RATE_SMOOTHING``), so that a speed sensor's white noise does not reach the feed-forward;
    or, where the log measures it, the longitudinal acceleration ``acceleration`` (m/s^2, one per
    sample), which needs no differentiating and holds what the speed hold must supply.
    """
    speed = np.asarray(speed, dtype=float).ravel()
    if speed.size < 3 or not np.all(np.isfinite(speed)):
        raise InputError("the speed channel needs at least three finite samples")
    if acceleration is not None:
        acceleration = np.asarray(acceleration, dtype=float).ravel()
        if acceleration.shape != speed.shape or not np.all(np.isfinite(acceleration)):
            raise InputError(f"the acceleration channel needs one finite value per speed sample ({speed.size})")
        return np.column_stack([speed, acceleration])
    half = max(1, int(round(_RATE_SMOOTHING / dt)))
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    padded = np.concatenate([2 * speed[0] - speed[half:0:-1], speed, 2 * speed[-1] - speed[-2:-half - 2:-1]])
    smooth = np.convolve(padded, kernel, mode="valid")
    return np.column_stack([speed, np.gradient(smooth, dt)])


def calibration_record(steer: Any, speed: Any, outputs: Any, dt: float, quantities: Sequence[str],
                       t0: float = 0.0, acceleration: Any = None) -> IOData:
    """A log as the calibration model takes it: road-wheel steer, the speed schedule, the measured quantities.

    ``acceleration``, where the log measures it, is fed forward in place of the speed's rate
    (:func:`speed_schedule`).
    """
    steer = np.asarray(steer, dtype=float).ravel()
    outputs = np.asarray(outputs, dtype=float)
    outputs = outputs.reshape(-1, 1) if outputs.ndim == 1 else outputs
    if not (math.isfinite(dt) and dt > 0):
        raise InputError(f"the sample interval must be a positive number of seconds; got {dt!r}")
    if outputs.shape != (steer.size, len(quantities)) or np.size(speed) != steer.size:
        raise InputError(f"steer ({steer.size}), speed ({np.size(speed)}) and outputs {outputs.shape} "
                         f"do not match {len(quantities)} quantities")
    units = dict(zip(OUTPUT_NAMES, OUTPUT_UNITS))
    return IOData(
        t=t0 + dt * np.arange(steer.size), u=np.column_stack([steer, speed_schedule(speed, dt, acceleration)]),
        y=outputs,
        input_names=("steer", "reference_speed", "reference_acceleration"), input_units=("rad", "m/s", "m/s^2"),
        output_names=tuple(quantities), output_units=tuple(units[q] for q in quantities),
    )


def simulated_log(params: VehicleParameters, steer: Any, speed: Any, dt: float, quantities: Sequence[str], *,
                  substeps: int = 10) -> tuple[IOData, np.ndarray]:
    """What a logger would record of the source model driving a speed trace: a calibration's truth.

    The car follows ``speed`` (its reference, as in a replay) under the road-wheel ``steer``, both
    sampled at ``dt``; the model is integrated on a grid ``substeps`` times finer with steer and speed
    linear between samples, each fine step given their value at its middle, and sampled at ``dt``.
    The fine grid matters: a simulator that holds each sample over a whole interval delays the
    steer by half a sample against the sampled channels (5 ms at 100 Hz), and a calibration, whose
    inputs are linear between samples, takes that delay for dynamics (measured: 5 % of the yaw rate
    and of the lateral acceleration differed from the calibration model's at the true parameters,
    0.02-0.05 % on the fine grid).

    Parameters
    ----------
    params : VehicleParameters
    steer, speed : array_like (N,)
        Road-wheel steer (rad) and the speed trace (m/s), one per sample.
    dt : float
        Sample interval (s).
    quantities : sequence of str
        Outputs to record (:data:`vehid.vehicle.model.OUTPUT_NAMES`).
    substeps : int
        Integration steps per sample.

    Returns
    -------
    record : IOData
        The :func:`calibration_record` of the noise-free outputs, with ``speed`` as the speed channel.
    clean : ndarray (N, len(quantities))
        The outputs (add a sensor's noise to them for a measured log).
    """
    steer = np.asarray(steer, dtype=float).ravel()
    speed = np.asarray(speed, dtype=float).ravel()
    if isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1:
        raise InputError(f"substeps must be a whole number >= 1; got {substeps!r}")
    if steer.size < 2 or speed.shape != steer.shape:
        raise InputError(f"steer ({steer.size}) and speed ({speed.size}) need one value per sample, at least two")
    samples = np.arange(steer.size)
    middles = np.maximum(np.arange((steer.size - 1) * substeps + 1) - 0.5, 0.0) / substeps
    fine = simulate(params, np.interp(middles, samples, steer), dt / substeps, speed=np.interp(middles, samples, speed))
    unknown = [q for q in quantities if q not in fine.output_names]
    if unknown:
        raise InputError(f"unknown quantity {unknown[0]!r}; the model offers {', '.join(OUTPUT_NAMES)}")
    clean = np.column_stack([fine.y[::substeps, fine.output_names.index(q)] for q in quantities])
    return calibration_record(steer, speed, clean, dt, quantities), clean


@dataclass(frozen=True, eq=False)
class Calibration:
    """A calibrated vehicle.

    Attributes
    ----------
    vehicle : VehicleParameters
        The prior vehicle with the determined parameters at their estimates.
    parameter_names, units : tuple of str
        Every parameter asked for, in the order asked.
    values, std : ndarray
        Estimate and standard deviation; a parameter held at its prior has its prior and NaN std.
    correlation : ndarray
        Correlation of the determined parameters' last fit (NaN rows for the held ones).
    held : dict
        Name -> reason, for the parameters the log did not determine (held at the prior).
    result : GreyBoxResult
        The last grey-box fit (of the determined parameters).
    vehicle_values : dict
        Fields whose value in :attr:`vehicle` is not their estimate: the cornering scales where the
        axles' static stiffness is held (``hold_static_stiffness`` of :func:`calibrate_vehicle`).
    """

    vehicle: VehicleParameters
    parameter_names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    correlation: np.ndarray
    held: dict[str, str]
    result: GreyBoxResult | None
    warnings: tuple[str, ...] = field(default_factory=tuple)
    vehicle_values: dict[str, float] = field(default_factory=dict)

    def parameters_dict(self) -> dict[str, dict[str, Any]]:
        """``name -> {value, std, unit}`` (std None where held at the prior), with ``in_vehicle`` where the
        vehicle carries another value (:attr:`vehicle_values`)."""
        return {name: {"value": float(v), "std": None if not math.isfinite(s) else float(s), "unit": unit,
                       **({"in_vehicle": self.vehicle_values[name]} if name in self.vehicle_values else {})}
                for name, v, s, unit in zip(self.parameter_names, self.values, self.std, self.units)}


def _undetermined(names: Sequence[str], values: np.ndarray, std: np.ndarray, correlation: np.ndarray,
                  limit: float, prior_std: np.ndarray) -> tuple[str, str] | None:
    """The first parameter the fit did not determine and why (module docstring), or None.

    ``prior_std`` is each parameter's relative prior standard deviation; the worst is the one whose
    std is the largest share of its limit.
    """
    relative = np.abs(std) / np.abs(values)
    allowed = np.minimum(1.0, PRIOR_SHARE_LIMIT * np.asarray(prior_std, dtype=float))
    share = np.where(np.isfinite(relative), relative / allowed, np.inf)
    worst = int(np.argmax(share))
    if share[worst] > 1.0:
        return names[worst], (f"std {std[worst]:.3g} against its value {values[worst]:.3g}: "
                              "the log hardly narrowed its prior")
    n = len(names)
    pairs = [(abs(correlation[i, j]), i, j) for i in range(n) for j in range(i + 1, n)
             if math.isfinite(correlation[i, j])]
    if pairs:
        rho, i, j = max(pairs)
        if rho > limit:
            drop = i if relative[i] >= relative[j] else j
            return names[drop], f"correlation {correlation[i, j]:+.3f} with {names[j if drop == i else i]}"
    return None


def _invalid_estimate(prior_vehicle: VehicleParameters, parameters: Sequence[str], free: Sequence[str],
                      start: np.ndarray, estimate: np.ndarray, relative_prior: np.ndarray) -> tuple[str, str] | None:
    """Where the free parameters' estimate makes no valid vehicle (a grip the centre of gravity would tip
    over at, say): the free parameter that moved furthest from its start, counted in its prior std, and
    why; else None. The model itself runs beyond those limits, so the filter may end there."""
    values = start.copy()
    index = [parameters.index(name) for name in free]
    values[index] = estimate[index]
    try:
        vehicle_with(prior_vehicle, parameters, values)
    except InputError as exc:
        moved = np.abs(values[index] - start[index]) / (relative_prior[index] * np.abs(start[index]))
        worst = int(np.argmax(moved))
        return free[worst], (f"its estimate {values[index[worst]]:.4g} makes no valid vehicle with the others: "
                             f"{exc}")
    return None


def calibrate_vehicle(params: VehicleParameters, data: IOData | Sequence[IOData], quantities: Sequence[str], *,
                      parameters: Sequence[str] | None = None, priors: Mapping[str, float] | None = None,
                      prior_std: Mapping[str, float] | None = None, correlation_limit: float = CORRELATION_LIMIT,
                      options: GreyBoxOptions | None = None, fixed: Sequence[str] = (),
                      starts: Mapping[str, float] | None = None, hold_static_stiffness: bool = False
                      ) -> Calibration:
    """Calibrate chosen parameters of ``params`` to logs (:func:`calibration_record`).

    Parameters
    ----------
    params : VehicleParameters
        The prior vehicle.
    data : IOData or sequence of IOData
        Logs from :func:`calibration_record` measuring ``quantities``.
    quantities : sequence of str
    parameters : sequence of str, optional
        ``section.field`` names; default :data:`DEFAULT_PARAMETERS`, plus :data:`ROLL_PARAMETERS`
        where the roll angle is measured.
    priors : mapping, optional
        ``name -> value``: prior values replacing the vehicle's (the starts and the values held).
    prior_std : mapping, optional
        ``name -> std`` in the parameter's unit: how well the prior is known. The others take
        ``options``' relative ``prior_std`` (default 1: a factor e either way).
    correlation_limit : float
        |correlation| above which a pair is not told apart.
    options : GreyBoxOptions, optional
        Default: :class:`GreyBoxOptions` with ``coloured_residuals`` (a measured log's residuals are
        rarely white; the std then widens by their correlation time).
    fixed : sequence of str
        Parameters kept at their start in this calibration, not estimated (a stage of a staged
        calibration); they are neither reported as undetermined nor given a std.
    starts : mapping, optional
        ``name -> value``: where the filter starts, in place of the prior value (an earlier stage's
        estimate). The prior std still applies around it.
    hold_static_stiffness : bool
        The cornering scales are the axles' levels at the prior's ``tyre.PKY2``, which moves only how
        the stiffness changes with the load (:func:`calibration_model`): the estimates of the scales
        are those levels, and the calibrated vehicle carries the scales that give them at the
        estimated PKY2 (:attr:`Calibration.vehicle_values`).

    Returns
    -------
    Calibration

    Notes
    -----
    The model is built and compiled once, with every parameter a symbol: a parameter held (fixed,
    or found undetermined) is kept at its value by the filter's ``held`` mask, so dropping one
    costs a run of the filter but no compilation.
    """
    quantities = tuple(quantities)
    if parameters is None:
        parameters = DEFAULT_PARAMETERS + (ROLL_PARAMETERS if "roll_angle" in quantities else ())
    parameters = tuple(parameters)
    if not 0 < correlation_limit < 1:
        raise InputError(f"the correlation limit must be in (0, 1); got {correlation_limit!r}")
    priors = dict(priors or {})
    prior_std = dict(prior_std or {})
    starts = dict(starts or {})
    extra = (set(priors) | set(prior_std) | set(starts) | set(fixed)) - set(parameters)
    if extra:
        raise InputError(f"a prior is given for {sorted(extra)[0]!r}, which is not calibrated")
    for name, value in prior_std.items():
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise InputError(f"the prior std of {name!r} must be a positive number; got {value!r}")
    for name in parameters:
        _field(params, name)
    try:
        prior_vehicle = vehicle_with(params, list(priors), list(priors.values())) if priors else params
        start_vehicle = vehicle_with(prior_vehicle, list(starts), list(starts.values())) if starts else prior_vehicle
    except (ValueError, TypeError) as exc:
        raise InputError(f"a prior makes an invalid vehicle: {exc}") from None
    units = tuple(_field(prior_vehicle, name)[2] for name in parameters)
    prior_values = np.array([float(getattr(*_field(prior_vehicle, name)[:2])) for name in parameters])
    start_values = np.array([float(getattr(*_field(start_vehicle, name)[:2])) for name in parameters])
    options = options or GreyBoxOptions(coloured_residuals=True)
    relative_prior = np.array([prior_std[name] / abs(value) if name in prior_std else options.prior_std
                               for name, value in zip(parameters, prior_values)])
    # built on the prior vehicle whatever the starts: one model (and compilation) for every stage, and the
    # rear axle's stiffness, where held, held at the prior's
    model = calibration_model(prior_vehicle, parameters, quantities, hold_static_stiffness=hold_static_stiffness)
    free = [name for name in parameters if name not in fixed]
    if not free:
        raise InputError("every calibration parameter is fixed: leave at least one to estimate")
    held: dict[str, str] = {}
    result = None
    start = start_values.copy()
    while free:
        mask = tuple(name not in free for name in parameters)
        result = identify_greybox(data, model, start, options=dataclasses.replace(
            options, parameter_prior_std=tuple(relative_prior), held=mask))
        index = [parameters.index(name) for name in free]
        reason = _undetermined(free, result.parameters[index], result.std[index],
                               result.correlation[np.ix_(index, index)], correlation_limit, relative_prior[index])
        if reason is None:
            reason = _invalid_estimate(prior_vehicle, parameters, free, start, result.parameters, relative_prior)
        if reason is None:
            break
        held[reason[0]] = reason[1]
        free.remove(reason[0])
        # the others start again where they started: a parameter running away may have dragged them
        result = None
    values, std = start_values.copy(), np.full(len(parameters), np.nan)
    correlation = np.full((len(parameters), len(parameters)), np.nan)
    if result is not None:
        index = [parameters.index(name) for name in free]
        values[index] = result.parameters[index]
        std[index] = result.std[index]
        correlation[np.ix_(index, index)] = result.correlation[np.ix_(index, index)]
    # a held parameter keeps its start, the value the others were estimated with: the prior, or an
    # earlier stage's estimate
    warnings = tuple(f"{name} not identifiable from this log ({why}): held at its "
                     f"{'prior' if name not in starts else 'start'} {start_values[parameters.index(name)]:.6g}"
                     for name, why in held.items())
    vehicle = vehicle_with(prior_vehicle, parameters, values)
    vehicle_values: dict[str, float] = {}
    if hold_static_stiffness:
        scales = held_stiffness_scales(prior_vehicle, float(values[parameters.index("tyre.PKY2")]),
                                       tuple(float(getattr(vehicle.tyre, n.partition(".")[2])) for n in STIFFNESS_SCALES))
        vehicle_values = dict(zip(STIFFNESS_SCALES, map(float, scales)))
        vehicle = vehicle_with(vehicle, STIFFNESS_SCALES, scales)
    return Calibration(
        vehicle=vehicle, parameter_names=parameters, units=units,
        values=values, std=std, correlation=correlation, held=held, result=result, warnings=warnings,
        vehicle_values=vehicle_values,
    )


def vehicle_toml(params: VehicleParameters, comment: str = "") -> str:
    """The vehicle as a TOML vehicle file (every field of every section; :func:`~vehid.vehicle.load_vehicle` reads it).

    Numbers are written with ``repr``, which reads back to the same float.
    """
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append(f"name = {_toml_string(params.name)}")
    for section in ("chassis", "suspension", "tyre", "drive", "steering", "aerodynamics"):
        holder = getattr(params, section)
        lines.append("")
        lines.append(f"[{section}]")
        for item in dataclasses.fields(holder):
            lines.append(f"{item.name} = {float(getattr(holder, item.name))!r}")
    return "\n".join(lines) + "\n"


def _toml_string(text: str) -> str:
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"') + '"'
