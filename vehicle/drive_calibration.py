"""Calibrating the vehicle to a whole measured drive: what the log allows, a start from the data, stages.

:func:`calibrate_drive` takes a drive as it was recorded (:class:`DriveLog`) and a prior vehicle that
may be no more than a base car with the right mass and axle positions, and returns a
:class:`DriveCalibration`: the calibrated car, the prior and the calibrated car scored alike on the
held-out end of the log, channels scored that were never fitted, the estimates of the two halves
of the estimation part set side by side, and what was left out or changed on the way.

Choices, each stated where it is made:

* **What the model can drive.** The model holds between :data:`~vehid.vehicle.validity.MIN_SPEED`
  and the vehicle's own top speed (:func:`~vehid.vehicle.model.speed_limit`: higher with
  aerodynamics). Samples outside are left out, not refused: each contiguous stretch inside that
  lasts at least :data:`MIN_RUN_SECONDS` becomes its own record, which the model drives from
  straight running at its first speed (a stretch begins where the car has just left a straight or
  a standstill). How many samples went, and why, is a note.
* **A start from the data** (:func:`start_vehicle`). A base car's tyres may hold less than the log
  shows (a road tyre's 0.9 g against a race car's 1.4 g), its inertia may be that of another car,
  and its balance one that spins where the driver did not. Before any filtering: a yaw inertia far
  from ``m a b`` (a dynamic index outside 0.7-1.3: a prior whose mass or axles changed and its
  inertia not) becomes ``m a b``; the friction is raised to what the whole log's largest
  accelerations need (a lower bound that every car driving the log must meet, not a fit to its
  outputs), and a car with that grip sits lower, its centre of gravity keeping the prior's margin
  against tipping; the car gets the slip limiter of :mod:`vehid.vehicle.model` (traction control,
  anti-lock brakes, brakes shared by the axles' loads), so that it neither spins a wheel nor locks
  one; and its front cornering scale is set to the understeer gradient of the log's quasi-steady
  cornering (stage 1, below). Each change is a note; none touches what the user fixed by ``priors``.
* **Stages.** (1) Steady-state balance, in closed form: the understeer gradient of the single-track
  model, ``K = (m / L) (l_r / C_f - l_f / C_r)``, is regressed from the quasi-steady samples of the
  estimation part (``delta - L r / V = K a_y + offset``: a slowly changing yaw rate, a lateral
  acceleration within the tyres' linear range) and the front axle's cornering scale set to give it,
  the rear's kept (the front scale stands for what the tyre data leave out at the front, the
  steering's compliance above all). The regression's offset is the steer sensor's zero error; where it
  stands more than 3 of its std from zero it is taken out of the steer that every car drives. (2) From
  that start the filter estimates the steady-state part
  (:data:`STEADY_PARAMETERS`: the balance and the tyres' load sensitivity) with the yaw dynamics and
  the grip held at the start, then (3) the yaw dynamics and the grip (the yaw inertia, the friction, the
  tyres' curvature, any relaxation length asked for) with everything else from stage 2's estimates;
  (4) roll, where it is measured. The order matters: with
  the balance held instead, the yaw inertia made up for it on the committed race-car log (2539
  against a start of 1397 kg m^2) and all four free at once left the front scale undetermined (a
  std of half its value) and the car no better than its start. One model is compiled for all stages
  (:func:`~vehid.vehicle.calibration.calibrate_vehicle`'s ``fixed``); a stage that determines nothing
  is a note and the next starts where it did. Each parameter's prior is centred on the start with
  the spread of :data:`PLAUSIBLE_SPREAD` unless the user gives one.
* **Scoring.** Every car is scored the same way: driven over each record of the whole log from its
  start, its outputs compared with the measured channels on the held-out samples by the NRMSE fit
  (:func:`~vehid.identification.assessment.metrics.nrmse_fit`), R of eq. 17 kept beside it.
* **Halves.** The estimation part is split into two halves of about equal samples, where the car
  runs straightest near the middle (a record starts from straight running), and each is
  calibrated again from the whole part's estimate; an estimate whose halves differ by more than
  :data:`HALVES_LIMIT` times the root sum of their variances is named: the log's parts tell
  different stories about it (a model error, or a car that changed).
* **Late failure.** A stage that diverges, or whose estimate the vehicle's own checks still refuse
  (:func:`~vehid.vehicle.calibration.calibrate_vehicle` first holds the parameter that ran furthest),
  ends the calibration with the last stage that finished: its car, scores and the failure
  (:attr:`DriveCalibration.failure`) are kept, not lost.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from vehid.identification.assessment.metrics import nrmse_fit, percentage_explanation
from vehid.identification.assessment.segments import (block_jackknife, block_plan, integrated_correlation_time,
                                                      refit_replicates)
from vehid.identification.data import IOData
from vehid.identification.errors import DivergenceError, InputError
from vehid.identification.filtering.greybox import GreyBoxOptions
from vehid.identification.filtering.greybox_structure import simulate_greybox

from . import calibration as _calibration
from .calibration import Calibration, calibration_record, vehicle_with
from .model import MAX_STEER, OUTPUT_NAMES, speed_limit
from .parameters import GRAVITY, VehicleParameters, peak_lateral_friction, static_axle_loads, static_stability_factor
from .replay import replay_substeps
from .tyre import cornering_stiffness
from .validity import MIN_SPEED

__all__ = [
    "BALANCE_PARAMETERS",
    "STEADY_PARAMETERS",
    "DRIVE_PARAMETERS",
    "SIDESLIP_PARAMETERS",
    "DRIVE_ROLL_PARAMETERS",
    "PLAUSIBLE_SPREAD",
    "HALVES_LIMIT",
    "DRIVE_PARAMETER_TOLERANCE",
    "MIN_RUN_SECONDS",
    "DEFAULT_SLIP_LIMIT",
    "DriveLog",
    "DriveCalibration",
    "Balance",
    "speed_runs",
    "steady_balance",
    "start_vehicle",
    "calibrate_drive",
    "drive_records",
    "drive_scores",
]

#: The steady-state balance: set in stage 1 (the front's), estimated first in the filter (stage 2).
BALANCE_PARAMETERS = ("tyre.front_cornering_scale", "tyre.rear_cornering_scale")
#: What the filter's first stage estimates, the yaw dynamics and the grip held: the balance and how it
#: moves with the load (PKY2), properties of the steady state below the limit. The grip comes with the
#: yaw dynamics: free from the start, it ran off to a friction scale of 0.2 on the committed race-car
#: log's 48 s (the filter's corrected states need no grip) and took the balance with it.
STEADY_PARAMETERS = BALANCE_PARAMETERS + ("tyre.PKY2",)
#: What a drive calibrates by default: the front cornering scale (the balance), the load at which the
#: tyres' cornering stiffness stops growing (``PKY2``: how the balance shifts as the load moves across
#: the car in a corner), the grip, the yaw inertia (the yaw response's lag) and the curvature of the
#: tyres' lateral characteristic (``PEY1``: how the force bends from its slope towards its peak). The
#: base car's tyre bends early; a car's tyres may stay nearly linear up to their grip. Held at the base
#: tyre's, the curvature took the friction with it: on a 550 s drive of a race car the filter ran the
#: friction scale to 3.2 (a car that would tip before it slides) to straighten the tyres, and the
#: calibrated car overstated the sideslip by 28-41 % in the corners over 0.6 g.
DRIVE_PARAMETERS = ("tyre.front_cornering_scale", "tyre.PKY2", "tyre.friction_scale", "chassis.yaw_inertia",
                    "tyre.PEY1")
#: Added where the sideslip is fitted: yaw rate and lateral acceleration alone do not tell the rear
#: axle's cornering stiffness from the front's (measured on the committed race-car log: correlation
#: 0.95-0.99 between the two scales), the sideslip does (``beta = b r / V - alpha_r``).
SIDESLIP_PARAMETERS = ("tyre.rear_cornering_scale",)
#: Added where the roll angle is measured (the last stage).
DRIVE_ROLL_PARAMETERS = ("chassis.roll_inertia", "suspension.front_anti_roll_bar")

#: The relative standard deviation of each default parameter's prior around the start: how far the
#: cars the start stands for spread (a factor exp(spread) either way at one std).
#: The curvature may change sign, so its spread is an absolute one of its start's size (a negative
#: parameter is estimated on a linear scale): one std takes the base tyre's -0.82 to 0 or to -1.6.
PLAUSIBLE_SPREAD = MappingProxyType({
    "tyre.front_cornering_scale": 0.3, "tyre.rear_cornering_scale": 0.3, "tyre.PKY2": 0.5,
    "tyre.friction_scale": 0.2, "chassis.yaw_inertia": 0.3, "tyre.PEY1": 1.0,
})
#: A stretch of the log inside the model's speed range shorter than this is left out: the model
#: starts each record from straight running, and a shorter record is mostly that start's transient.
MIN_RUN_SECONDS = 2.0
#: The filter stops when no parameter moves by more than this share of itself from one pass to the next:
#: a tenth of a per cent, ten times the grey-box default and far below the std a real drive leaves (2-8 %
#: of the value on the committed race-car log).
DRIVE_PARAMETER_TOLERANCE = 1e-3
#: Halves of the estimation part whose estimates differ by more than this many standard deviations
#: of the difference disagree (about 5 % of the time by chance where the model is right).
HALVES_LIMIT = 2.0
#: The slip limiter a start car gets when its vehicle has none: near where a tyre's longitudinal
#: force peaks (0.1 for the baseline tyre), where anti-lock brakes and traction control hold a wheel.
DEFAULT_SLIP_LIMIT = 0.1

# The filter's RK4 steps are at most this share of the largest step stable at the drive's top speed at
# straight running: the modes speed up where the slip limiter holds a wheel or the load moves (a 10-minute
# drive's filter diverged in its first pass at the replay's 0.8, one step per sample at 60 m/s and 100 Hz).
_STEP_MARGIN = 0.5
# The start's friction: the log's largest acceleration (of the 0.2 s mean, its 99.5th percentile:
# an accelerometer's vibration and single spikes excluded) is taken to use this share of the grip.
_GRIP_USED = 0.85
_PEAK_PERCENTILE = 99.5
_SMOOTHING = 0.2  # [s]
# The dynamic index I_z / (m a b) of road and race cars (Milliken & Milliken, Race Car Vehicle
# Dynamics, 1995, section 5.8: about 0.8-1.2); a prior outside it has kept a base car's inertia.
_DYNAMIC_INDEX = (0.7, 1.3)
# The start's centre of gravity: its static stability factor at least this far above the friction.
_TIP_MARGIN = 1.1
# Quasi-steady samples for the balance: the yaw rate's 0.5 s mean changing by less than this ...
_STEADY_YAW_ACCELERATION = 0.1  # [rad/s^2]
_STEADY_WINDOW = 0.5  # [s]
# ... with the lateral acceleration between these shares of the log's peak (the tyres' linear range)
_LINEAR_RANGE = (0.05, 0.6)
_STEADY_MIN_SPEED = 10.0  # [m/s] below, kinematic steer dominates and the gradient is poorly resolved
_STEADY_MIN_SECONDS = 2.0  # of quasi-steady samples needed for the balance
# the halves' split is sought among this share of the calibrating samples about their middle (each half then
# holds 30-70 % of them): the committed race-car log's middle 20 % lies in one long corner
_HALVES_WINDOW = 0.4
# The balance's steer at zero lateral acceleration is a steer sensor's zero error, removed from the steer
# before the car drives the log where it stands this many std from zero: at speed the model's lateral
# response to a steady steer is large (a_y = delta / (L / V^2 + K)), and an offset of 0.07 deg turns a
# straight at 30 m/s into a 0.03 g corner that no cornering stiffness can take out.
_OFFSET_SIGMA = 3.0


@dataclass(frozen=True, eq=False)
class DriveLog:
    """A measured drive as the calibration takes it (SI units, one row per sample).

    Attributes
    ----------
    t : ndarray (N,)
        Time (s), uniform.
    steer : ndarray (N,)
        Road-wheel steer (rad, positive left).
    speed : ndarray (N,)
        Forward speed (m/s).
    outputs : ndarray (N, n_y)
        Measured channels the calibration fits, standing for ``quantities``.
    channels, quantities : tuple of str
        The channels' names and the model quantities they measure.
    acceleration : ndarray (N,) or None
        Measured longitudinal acceleration (m/s^2), fed forward to the speed hold where given.
    checks : mapping of str to (str, ndarray (N,))
        Channels scored but never fitted: ``channel -> (quantity, values)``.
    """

    t: np.ndarray
    steer: np.ndarray
    speed: np.ndarray
    outputs: np.ndarray
    channels: tuple[str, ...]
    quantities: tuple[str, ...]
    acceleration: np.ndarray | None = None
    checks: Mapping[str, tuple[str, np.ndarray]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float).ravel()
        n = t.size
        object.__setattr__(self, "t", t)
        for name in ("steer", "speed"):
            values = np.asarray(getattr(self, name), dtype=float).ravel()
            if values.size != n:
                raise InputError(f"the {name} has {values.size} samples, the time {n}")
            object.__setattr__(self, name, values)
        outputs = np.asarray(self.outputs, dtype=float)
        outputs = outputs.reshape(-1, 1) if outputs.ndim == 1 else outputs
        object.__setattr__(self, "outputs", outputs)
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "quantities", tuple(self.quantities))
        if outputs.shape != (n, len(self.quantities)) or len(self.channels) != len(self.quantities):
            raise InputError(f"{outputs.shape[1]} output columns, {len(self.channels)} channels and "
                             f"{len(self.quantities)} quantities: give one channel per quantity, one row per sample")
        if n < 3:
            raise InputError("a drive needs at least three samples")
        steps = np.diff(t)
        if not (np.all(np.isfinite(t)) and np.all(steps > 0)):
            raise InputError("the drive's time must be finite and increasing")
        if self.acceleration is not None:
            acceleration = np.asarray(self.acceleration, dtype=float).ravel()
            if acceleration.size != n:
                raise InputError(f"the acceleration has {acceleration.size} samples, the time {n}")
            object.__setattr__(self, "acceleration", acceleration)
        checks = {}
        for channel, (quantity, values) in dict(self.checks).items():
            values = np.asarray(values, dtype=float).ravel()
            if values.size != n:
                raise InputError(f"the check channel {channel!r} has {values.size} samples, the time {n}")
            if quantity not in OUTPUT_NAMES:
                raise InputError(f"unknown quantity {quantity!r} for the check channel {channel!r}; "
                                 f"the model offers {', '.join(OUTPUT_NAMES)}")
            checks[channel] = (str(quantity), values)
        object.__setattr__(self, "checks", MappingProxyType(checks))
        used = set(self.channels) | set(checks)
        if len(used) != len(self.channels) + len(checks):
            raise InputError("a channel is both fitted and checked, or named twice")
        for name, values in (("steer", self.steer), ("speed", self.speed), ("outputs", self.outputs)):
            bad = np.flatnonzero(~np.all(np.isfinite(values.reshape(n, -1)), axis=1))
            if bad.size:
                raise InputError(f"the {name} is not finite at t = {t[bad[0]]:.6g} s ({bad.size} samples)")
        beyond = np.flatnonzero(np.abs(self.steer) > MAX_STEER)
        if beyond.size:
            raise InputError(f"the steer reaches {math.degrees(self.steer[beyond[0]]):.4g} deg at t = "
                             f"{t[beyond[0]]:.6g} s, beyond the model's +/-{math.degrees(MAX_STEER):g} deg at the road "
                             "wheel: is it a road-wheel angle in rad? (a steering-wheel angle: divide by the ratio "
                             "with 'scale')", options=("scale",))

    @property
    def dt(self) -> float:
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    @property
    def n_samples(self) -> int:
        return int(self.t.size)

    def record(self, first: int, stop: int, *, with_checks: bool = False) -> IOData:
        """Samples ``first:stop`` as the calibration model takes them (:func:`calibration_record`)."""
        outputs, quantities = self.outputs[first:stop], self.quantities
        if with_checks and self.checks:
            outputs = np.column_stack([outputs] + [values[first:stop] for _, values in self.checks.values()])
            quantities = quantities + tuple(quantity for quantity, _ in self.checks.values())
        acceleration = None if self.acceleration is None else self.acceleration[first:stop]
        return calibration_record(self.steer[first:stop], self.speed[first:stop], outputs, self.dt, quantities,
                                  t0=float(self.t[first]), acceleration=acceleration)


def speed_runs(speed: np.ndarray, low: float, high: float, min_samples: int) -> tuple[tuple[int, int], ...]:
    """The contiguous stretches ``(first, stop)`` of at least ``min_samples`` with ``low <= speed <= high``."""
    inside = (speed >= low) & (speed <= high)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], inside.astype(np.int8), [0]])))
    return tuple((int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= min_samples)


def _moving_mean(values: np.ndarray, samples: int) -> np.ndarray:
    samples = max(1, int(samples))
    if samples == 1 or values.size < samples:
        return values.copy()
    kernel = np.ones(samples) / samples
    padded = np.concatenate([np.full(samples // 2, values[0]), values, np.full(samples - 1 - samples // 2, values[-1])])
    return np.convolve(padded, kernel, mode="valid")


def _quantity(log: DriveLog, quantity: str) -> np.ndarray | None:
    """A measured quantity among the fitted channels (or None)."""
    return log.outputs[:, log.quantities.index(quantity)] if quantity in log.quantities else None


def _measured_motion(log: DriveLog, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Speed, yaw rate and lateral acceleration on ``rows`` (smoothed), from what the log measures."""
    window = int(round(_STEADY_WINDOW / log.dt))
    speed = _moving_mean(log.speed, window)
    yaw = _quantity(log, "yaw_rate")
    lateral = _quantity(log, "lateral_acceleration")
    if lateral is None:
        lateral = _quantity(log, "lateral_acceleration_accelerometer")
    if yaw is None and lateral is None:
        return None
    if yaw is None:
        yaw = lateral / np.maximum(log.speed, MIN_SPEED)  # a steady turn: a_y = V r
    if lateral is None:
        lateral = log.speed * yaw
    return speed[rows], _moving_mean(yaw, window)[rows], _moving_mean(lateral, window)[rows]


@dataclass(frozen=True)
class Balance:
    """The understeer gradient of a log's quasi-steady cornering (stage 1).

    Attributes
    ----------
    gradient : float
        ``K`` (rad per m/s^2) of ``delta - L r / V = K a_y + offset``; ``gradient_deg_per_g`` in deg/g.
    std : float
        Its standard deviation (rad per m/s^2): a delete-one-block jackknife over the quasi-steady
        samples (:func:`~vehid.identification.assessment.segments.block_jackknife`).
    offset : float
        The steer at zero lateral acceleration (rad): a steer sensor's zero error.
    offset_std : float
        Its standard deviation (rad), by the same jackknife.
    samples : int
        Quasi-steady samples used.
    front_scale, rear_scale : float
        The cornering scales that give the vehicle this gradient: the front's set, the rear's kept.
    """

    gradient: float
    std: float
    offset: float
    samples: int
    front_scale: float
    rear_scale: float
    offset_std: float = math.nan

    @property
    def offset_determined(self) -> bool:
        """The zero error stands out of its std by :data:`_OFFSET_SIGMA` (the calibration then removes it)."""
        return math.isfinite(self.offset_std) and abs(self.offset) > _OFFSET_SIGMA * self.offset_std

    @property
    def gradient_deg_per_g(self) -> float:
        return math.degrees(self.gradient) * GRAVITY

    def as_dict(self) -> dict[str, Any]:
        return {"understeer_gradient_deg_per_g": self.gradient_deg_per_g,
                "understeer_gradient_std_deg_per_g": math.degrees(self.std) * GRAVITY,
                "steer_offset_deg": math.degrees(self.offset),
                "steer_offset_std_deg": math.degrees(self.offset_std) if math.isfinite(self.offset_std) else None,
                "steer_offset_removed": self.offset_determined, "samples": self.samples,
                "front_cornering_scale": self.front_scale, "rear_cornering_scale": self.rear_scale}


def _axle_stiffness(params: VehicleParameters) -> tuple[float, float]:
    """Each axle's cornering stiffness at static load without the scales (N/rad, both tyres)."""
    front, rear = static_axle_loads(params)
    return tuple(float(-2 * cornering_stiffness(load / 2, params.tyre)) for load in (front, rear))


def steady_balance(params: VehicleParameters, log: DriveLog, rows: np.ndarray) -> Balance | None:
    """Stage 1: the log's understeer gradient and the cornering scales of ``params`` that give it.

    ``rows`` selects the samples to use (the estimation part inside the speed range). None where the
    log has too few quasi-steady samples or measures neither yaw rate nor lateral acceleration.
    """
    motion = _measured_motion(log, rows)
    if motion is None:
        return None
    speed, yaw, lateral = motion
    steer = _moving_mean(log.steer, int(round(_STEADY_WINDOW / log.dt)))[rows]
    peak = float(np.percentile(np.abs(lateral), _PEAK_PERCENTILE))
    yaw_acceleration = np.gradient(yaw, log.dt)
    steady = ((np.abs(yaw_acceleration) < _STEADY_YAW_ACCELERATION) & (speed > _STEADY_MIN_SPEED)
              & (np.abs(lateral) > _LINEAR_RANGE[0] * peak) & (np.abs(lateral) < _LINEAR_RANGE[1] * peak))
    if np.count_nonzero(steady) * log.dt < _STEADY_MIN_SECONDS:
        return None
    chassis = params.chassis
    wheelbase = chassis.wheelbase
    target = steer[steady] - wheelbase * yaw[steady] / speed[steady]
    design = np.column_stack([lateral[steady], np.ones(np.count_nonzero(steady))])
    (gradient, offset), *_ = np.linalg.lstsq(design, target, rcond=None)
    # the error bars are the workbench's delete-one-block jackknife over the quasi-steady samples in time
    # order, each block longer than the residuals' correlation time and than one 0.5 s window: a drive's
    # corners differ by more than the residuals' scatter says (camber, wind, a tyre warming), and counting
    # one independent value per window understated the spread of a 550 s drive's parts 1.5-2.6 times
    residual = target - design @ np.array([gradient, offset])
    correlation = float(integrated_correlation_time(residual[:, None])[0])
    edges = block_plan(design.shape[0], min_length=math.ceil(max(correlation, _STEADY_WINDOW / log.dt)))
    if edges is None:
        return None
    replicates, _ = refit_replicates(
        lambda kept: np.linalg.lstsq(np.concatenate([design[part] for part in kept]),
                                     np.concatenate([target[part] for part in kept]), rcond=None)[0], edges)
    std = block_jackknife(replicates, edges, form="refit", dt=log.dt, correlation_time=correlation).std
    front_base, rear_base = _axle_stiffness(params)
    rear = params.tyre.rear_cornering_scale * rear_base
    a, b, m = chassis.cg_to_front_axle, chassis.cg_to_rear_axle, chassis.mass
    # K L / m = b / C_f - a / C_r, solved for the front axle's C_f with the rear's kept: the front scale
    # stands for what the tyres' data leave out at the front, the steering's compliance above all
    # (vehid.vehicle.parameters); a balance past neutral beyond what the rear can carry has no solution
    slack = gradient * wheelbase / m + a / rear
    if slack <= 0:
        return None
    return Balance(gradient=float(gradient), std=float(std[0]), offset=float(offset), offset_std=float(std[1]),
                   samples=int(np.count_nonzero(steady)), front_scale=b / slack / front_base,
                   rear_scale=params.tyre.rear_cornering_scale)


def _peak_acceleration(log: DriveLog, rows: np.ndarray) -> float:
    """The log's largest horizontal acceleration (m/s^2): lateral and longitudinal combined, 0.2 s means."""
    window = int(round(_SMOOTHING / log.dt))
    lateral = _quantity(log, "lateral_acceleration")
    if lateral is None:
        lateral = _quantity(log, "lateral_acceleration_accelerometer")
    if lateral is None:
        yaw = _quantity(log, "yaw_rate")
        lateral = np.zeros(log.n_samples) if yaw is None else log.speed * yaw
    longitudinal = log.acceleration if log.acceleration is not None else np.gradient(log.speed, log.dt)
    total = np.hypot(_moving_mean(lateral, window), _moving_mean(longitudinal, window))[rows]
    return float(np.percentile(total, _PEAK_PERCENTILE)) if total.size else 0.0


def start_vehicle(prior: VehicleParameters, log: DriveLog, rows: np.ndarray, runs: Sequence[tuple[int, int]], *,
                  keep: Sequence[str] = (), slip_limit: float | None = None
                  ) -> tuple[VehicleParameters, Balance | None, tuple[str, ...]]:
    """The car the calibration starts from: ``prior`` made able to drive the log (module notes).

    Parameters
    ----------
    prior : VehicleParameters
    log : DriveLog
    rows : ndarray of int
        The samples the balance may look at (the estimation part inside the speed range).
    runs : sequence of (int, int)
        The stretches of the whole log the car must drive: their accelerations size its grip.
    keep : sequence of str
        ``section.field`` names the user fixed (``--prior``): left as they are.
    slip_limit : float, optional
        The slip limiter's limit; default the vehicle's own, else :data:`DEFAULT_SLIP_LIMIT`.
        Zero leaves the car without one.

    Returns
    -------
    vehicle : VehicleParameters
    balance : Balance or None
        Stage 1's result (None where the log did not allow it).
    notes : tuple of str
        One line per change.
    """
    notes: list[str] = []
    vehicle = prior
    if slip_limit is None:
        slip_limit = prior.drive.slip_limit or DEFAULT_SLIP_LIMIT
    if slip_limit != prior.drive.slip_limit:
        vehicle = dataclasses.replace(vehicle, drive=dataclasses.replace(vehicle.drive, slip_limit=float(slip_limit)))
        if slip_limit:
            notes.append(f"the car drives the log with a slip limiter at slip {slip_limit:g} (traction control, "
                         "anti-lock brakes, brakes shared by the axles' loads): a replay's wheels then neither "
                         "spin up nor lock where the prior's torque split would")
    # the grip must hold the whole log's accelerations, the held-out part's too: a car that cannot
    # drive the log cannot be scored on it (a lower bound on the friction, not a fit to the outputs)
    chassis = vehicle.chassis
    index = chassis.yaw_inertia / (chassis.mass * chassis.cg_to_front_axle * chassis.cg_to_rear_axle)
    if "chassis.yaw_inertia" not in keep and not _DYNAMIC_INDEX[0] <= index <= _DYNAMIC_INDEX[1]:
        inertia = chassis.mass * chassis.cg_to_front_axle * chassis.cg_to_rear_axle
        notes.append(f"the prior's yaw inertia {chassis.yaw_inertia:.4g} kg m^2 gives a dynamic index "
                     f"I_z / (m a b) of {index:.2f}, outside the {_DYNAMIC_INDEX[0]:g}-{_DYNAMIC_INDEX[1]:g} of cars "
                     f"(a prior whose mass or axles changed, not its inertia): m a b = {inertia:.4g} kg m^2 "
                     "to start from")
        vehicle = dataclasses.replace(vehicle, chassis=dataclasses.replace(chassis, yaw_inertia=inertia))
    peak = _peak_acceleration(log, np.concatenate([np.arange(a, b) for a, b in runs]))
    friction = peak_lateral_friction(vehicle)
    needed = peak / GRAVITY / _GRIP_USED
    if "tyre.friction_scale" not in keep and needed > friction:
        scale = vehicle.tyre.friction_scale * needed / friction
        notes.append(f"the log reaches {peak / GRAVITY:.3g} g (99.5th percentile of 0.2 s means) where the prior's "
                     f"tyres hold {friction:.3g}: friction scale {vehicle.tyre.friction_scale:.4g} -> {scale:.4g} "
                     f"to start from (the log then uses {_GRIP_USED:.0%} of the grip)")
        tyre = dataclasses.replace(vehicle.tyre, friction_scale=scale)
        chassis = vehicle.chassis
        # a car built for more grip sits lower: the prior's margin of the static stability factor over
        # the friction is kept (at least _TIP_MARGIN, the model's own tip check with a margin)
        margin = max(static_stability_factor(vehicle) / friction, _TIP_MARGIN)
        if "chassis.cg_height" not in keep and static_stability_factor(vehicle) < margin * needed:
            height = min(chassis.front_track, chassis.rear_track) / (2 * margin * needed)
            notes.append(f"a car with that grip sits lower: centre of gravity {chassis.cg_height:.3g} -> "
                         f"{height:.3g} m, keeping the prior's static stability factor of {margin:.3g} times the "
                         "friction (the model has no rollover)")
            chassis = dataclasses.replace(chassis, cg_height=height)
        vehicle = dataclasses.replace(vehicle, tyre=tyre, chassis=chassis)
    balance = steady_balance(vehicle, log, rows)
    scales = ("tyre.front_cornering_scale", "tyre.rear_cornering_scale")
    if balance is None:
        notes.append("too few quasi-steady corners for the steady-state balance: the cornering scales start "
                     "at the prior's")
    elif not any(name in keep for name in scales):
        old = (vehicle.tyre.front_cornering_scale, vehicle.tyre.rear_cornering_scale)
        vehicle = vehicle_with(vehicle, scales, (balance.front_scale, balance.rear_scale))
        notes.append(f"steady-state balance from {balance.samples * log.dt:.0f} s of quasi-steady cornering: "
                     f"understeer gradient {balance.gradient_deg_per_g:.3g} +/- "
                     f"{math.degrees(balance.std) * GRAVITY:.2g} deg/g; cornering scales front/rear "
                     f"{old[0]:.3g}/{old[1]:.3g} -> {balance.front_scale:.3g}/{balance.rear_scale:.3g} to start from")
    return vehicle, balance, tuple(notes)


def drive_records(log: DriveLog, runs: Sequence[tuple[int, int]], stop: int | None = None,
                  first: int = 0, min_samples: int = 1, with_checks: bool = False) -> list[IOData]:
    """The runs cut to samples ``first:stop``, those still ``min_samples`` long, as calibration records."""
    stop = log.n_samples if stop is None else stop
    records = []
    for a, b in runs:
        a, b = max(a, first), min(b, stop)
        if b - a >= min_samples:
            records.append(log.record(a, b, with_checks=with_checks))
    return records


@dataclass(frozen=True, eq=False)
class DriveCalibration:
    """A drive's calibration (:func:`calibrate_drive`).

    Attributes
    ----------
    calibration : Calibration or None
        The last stage that finished (None if none did).
    prior, start : VehicleParameters
        The vehicle given and the one the filter started from (:func:`start_vehicle`).
    balance : Balance or None
        Stage 1.
    stages : tuple of (str, Calibration)
        Every stage that finished, named.
    runs : tuple of (int, int)
        The log's stretches the model drove.
    n_estimation : int
        Samples ``0:n_estimation`` of the log calibrate; the rest is held out.
    fits : mapping
        ``label -> {"estimation": (nrmse, R), "validation": (nrmse, R), "checks": {channel: nrmse}}``
        for ``prior``, ``start`` and ``calibrated`` (None where that car's simulation was not finite).
    predictions : mapping of str to ndarray (N, n_y + n_checks)
        Each car's outputs over the whole log (NaN outside the runs), fitted channels then checks.
    halves : mapping
        ``parameter -> {"first": (value, std) or None, "second": ..., "difference_sigma": float or None,
        "not_determined": {half: why}}`` for each parameter the whole part determined (None where a half
        did not, and why in ``not_determined``).
    substeps : int
        RK4 steps per sample.
    notes, warnings : tuple of str
    failure : str or None
        What stopped a stage (the calibration holds the last stage that finished).
    """

    calibration: Calibration | None
    prior: VehicleParameters
    start: VehicleParameters
    balance: Balance | None
    stages: tuple[tuple[str, Calibration], ...]
    runs: tuple[tuple[int, int], ...]
    n_estimation: int
    fits: Mapping[str, Any]
    predictions: Mapping[str, np.ndarray]
    halves: Mapping[str, Any]
    substeps: int
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    failure: str | None = None

    @property
    def vehicle(self) -> VehicleParameters:
        """The calibrated car, or the start where no stage finished."""
        return self.calibration.vehicle if self.calibration is not None else self.start


def _score(log: DriveLog, runs: Sequence[tuple[int, int]], vehicle: VehicleParameters, n_estimation: int,
           substeps: int, parameters: Sequence[str] = ("chassis.yaw_inertia",),
           values: Sequence[float] | None = None) -> tuple[np.ndarray, dict[str, Any] | None]:
    """A car driven over every run from its start, scored on the estimation and the held-out samples.

    The car is ``vehicle`` with ``parameters`` at ``values`` (default: the vehicle's own): cars that
    differ only there share one compiled simulator.
    """
    quantities = log.quantities + tuple(quantity for quantity, _ in log.checks.values())
    parameters = tuple(parameters)
    model = _calibration.calibration_model(vehicle, parameters, quantities)
    theta = list(_field_values(vehicle, parameters).values()) if values is None else list(values)
    predicted = np.full((log.n_samples, len(quantities)), np.nan)
    for a, b in runs:
        y, _ = simulate_greybox(model, theta, log.record(a, b, with_checks=True), substeps=substeps)
        predicted[a:b] = y
    return predicted, drive_scores(log, runs, predicted, n_estimation)


def drive_scores(log: DriveLog, runs: Sequence[tuple[int, int]], predicted: np.ndarray,
                 n_estimation: int) -> dict[str, Any] | None:
    """A car's outputs over the log (``predicted``, fitted channels then checks) scored on the driven samples.

    Returns ``{"estimation": ..., "validation": ...}``, each ``{"nrmse", "R", "checks", "checks_R"}`` (NRMSE
    fit and R of eq. 17 per fitted channel, ``{channel: value}`` per check) over the samples of ``runs``
    before and from ``n_estimation`` (None for a part with fewer than two), or None where the car's
    outputs are not finite on every driven sample.
    """
    measured = np.column_stack([log.outputs] + [values for _, values in log.checks.values()])
    driven = np.zeros(log.n_samples, dtype=bool)
    for a, b in runs:
        driven[a:b] = True
    if not np.all(np.isfinite(predicted[driven])):
        return None
    n_y = len(log.quantities)
    scores: dict[str, Any] = {}
    for part, rows in (("estimation", driven[:n_estimation]), ("validation", driven[n_estimation:])):
        offset = 0 if part == "estimation" else n_estimation
        index = offset + np.flatnonzero(rows)
        if index.size < 2:
            scores[part] = None
            continue
        y, y_hat = measured[index], predicted[index]
        nrmse, explained = nrmse_fit(y, y_hat), percentage_explanation(y, y_hat)
        scores[part] = {"nrmse": nrmse[:n_y], "R": explained[:n_y],
                        "checks": dict(zip(log.checks, map(float, nrmse[n_y:]))),
                        "checks_R": dict(zip(log.checks, map(float, explained[n_y:])))}
    return scores


def _compare_halves(whole: Calibration, first: Calibration, second: Calibration) -> tuple[dict[str, Any], list[str]]:
    """Each parameter the whole part determined, as each half found it (None where a half did not
    determine it), and how many std of their difference apart; warnings where beyond :data:`HALVES_LIMIT`."""
    rows: dict[str, Any] = {}
    warnings = []
    for i, name in enumerate(whole.parameter_names):
        if not math.isfinite(whole.std[i]):
            continue
        found = [(float(half.values[i]), float(half.std[i])) if math.isfinite(half.std[i]) else None
                 for half in (first, second)]
        sigma = None
        if found[0] is not None and found[1] is not None:
            (v1, s1), (v2, s2) = found
            sigma = abs(v1 - v2) / math.hypot(s1, s2) if (s1 or s2) else math.inf
            if sigma > HALVES_LIMIT:
                warnings.append(f"{name}: the halves of the estimation part disagree, {v1:.5g} +/- {s1:.2g} against "
                                f"{v2:.5g} +/- {s2:.2g} ({sigma:.1f} std of the difference): the log's parts tell "
                                "different stories about it (a model error or a car that changed)")
        why = {label: half.held.get(name, "not estimated") for label, half, value in
               (("first", first, found[0]), ("second", second, found[1])) if value is None}
        rows[name] = {"first": found[0], "second": found[1], "difference_sigma": sigma, "not_determined": why}
    return rows, warnings


def calibrate_drive(
    prior: VehicleParameters,
    log: DriveLog,
    *,
    validation: float = 0.4,
    parameters: Sequence[str] | None = None,
    priors: Mapping[str, float] | None = None,
    prior_std: Mapping[str, float] | None = None,
    options: GreyBoxOptions | None = None,
    slip_limit: float | None = None,
    halves: bool = True,
    relative_prior_std: float | None = None,
) -> DriveCalibration:
    """Calibrate ``prior`` to a whole drive (module notes).

    Parameters
    ----------
    prior : VehicleParameters
    log : DriveLog
    validation : float
        Share of the log, at its end, held out and predicted.
    parameters : sequence of str, optional
        Default :data:`DRIVE_PARAMETERS`, with :data:`SIDESLIP_PARAMETERS` where the sideslip is fitted and
        :data:`DRIVE_ROLL_PARAMETERS` where the roll angle is measured.
    priors, prior_std : mapping, optional
        As :func:`~vehid.vehicle.calibration.calibrate_vehicle`'s; a parameter given a prior value is
        left alone by the start.
    options : GreyBoxOptions, optional
        The filter's settings; ``substeps`` is raised to what the drive's top speed needs.
    slip_limit : float, optional
        The start car's slip limiter (:func:`start_vehicle`).
    halves : bool
        Compare the estimates of the estimation part's halves.
    relative_prior_std : float, optional
        The relative prior std of every parameter ``prior_std`` leaves out; default the plausible spread
        of :data:`PLAUSIBLE_SPREAD` where it names the parameter, else ``options.prior_std``.

    Raises
    ------
    InputError
        Before any work: nothing of the log inside the vehicle's speed range, too few samples to
        calibrate or to validate, unknown parameters.
    """
    if not (math.isfinite(validation) and 0 <= validation < 1):
        raise InputError(f"the held-out share is in [0, 1); got {validation}")
    quantities = log.quantities
    if parameters is None:
        parameters = (DRIVE_PARAMETERS + (SIDESLIP_PARAMETERS if "sideslip" in quantities else ())
                      + (DRIVE_ROLL_PARAMETERS if "roll_angle" in quantities else ()))
    parameters = tuple(parameters)
    priors = dict(priors or {})
    for name in parameters:
        _calibration.check_parameter(prior, name)  # unknown or structural: bad input, before any work
    extra = (set(priors) | set(prior_std or {})) - set(parameters)
    if extra:
        raise InputError(f"a prior is given for {sorted(extra)[0]!r}, which is not calibrated")
    dt = log.dt
    top = speed_limit(prior)
    min_samples = max(3, int(math.ceil(MIN_RUN_SECONDS / dt)))
    runs = speed_runs(log.speed, MIN_SPEED, top, min_samples)
    notes: list[str] = []
    driven = sum(b - a for a, b in runs)
    if not runs:
        raise InputError(f"no stretch of {MIN_RUN_SECONDS:g} s of the log lies inside the vehicle's speed range "
                         f"({MIN_SPEED:g}-{top:g} m/s; the log's speed runs {log.speed.min():.3g}-"
                         f"{log.speed.max():.3g} m/s)")
    if driven < log.n_samples:
        below = int(np.count_nonzero(log.speed < MIN_SPEED))
        above = int(np.count_nonzero(log.speed > top))
        short = log.n_samples - driven - below - above
        parts = [f"{below} below {MIN_SPEED:g} m/s (standstill or too slow for the tyre model)" if below else "",
                 f"{above} above the vehicle's {top:g} m/s" + ("" if top > 50 else
                                                               " (give it its aerodynamics to reach further)")
                 if above else "",
                 f"{short} in stretches shorter than {MIN_RUN_SECONDS:g} s" if short else ""]
        notes.append(f"{log.n_samples - driven} of {log.n_samples} samples left out: "
                     + ", ".join(part for part in parts if part) + f"; the model drives {len(runs)} stretch(es)")
    n_estimation = int(round(log.n_samples * (1 - validation)))
    estimation_rows = np.concatenate([np.arange(a, min(b, n_estimation)) for a, b in runs if a < n_estimation] or
                                     [np.zeros(0, dtype=int)])
    validation_rows = sum(max(0, b - max(a, n_estimation)) for a, b in runs)
    if estimation_rows.size < 50 or (validation > 0 and validation_rows < 50):
        raise InputError(f"the log leaves {estimation_rows.size} samples inside the speed range to calibrate and "
                         f"{validation_rows} to validate; each needs at least 50")
    start, balance, start_notes = start_vehicle(prior, log, estimation_rows, runs, keep=tuple(priors),
                                                 slip_limit=slip_limit)
    notes.extend(start_notes)
    if balance is not None and balance.offset_determined:
        # every car drives the corrected steer: the prior, the start and the calibrated car alike
        log = dataclasses.replace(log, steer=log.steer - balance.offset)
        notes.append(f"the steer reads {math.degrees(balance.offset):+.3g} +/- {math.degrees(balance.offset_std):.2g} "
                     "deg when the car runs straight (the quasi-steady corners' steer at zero lateral acceleration): "
                     "a steer sensor's zero error, removed from the steer every car drives")
    speeds = log.speed[np.concatenate([np.arange(a, b) for a, b in runs])]
    substeps = replay_substeps(start, dt, float(speeds.max()), margin=_STEP_MARGIN)
    options = options or GreyBoxOptions(coloured_residuals=True, parameter_tolerance=DRIVE_PARAMETER_TOLERANCE)
    if options.substeps < substeps:
        options = dataclasses.replace(options, substeps=substeps)
    substeps = options.substeps
    records = drive_records(log, runs, stop=n_estimation, min_samples=min_samples)
    if not records:
        raise InputError("no stretch of the estimation part is long enough to calibrate")
    starts = {name: value for name, value in _field_values(start, parameters).items() if name not in priors}
    # how well the start knows each parameter: the user's std, else the plausible spread of such cars
    prior_std = dict(prior_std or {})
    for name, value in _field_values(start, parameters).items():
        spread = PLAUSIBLE_SPREAD.get(name) if relative_prior_std is None else relative_prior_std
        if name not in prior_std and spread is not None:
            prior_std[name] = spread * abs(priors.get(name, value))
    stage_plan = _stage_plan(parameters, quantities)
    # where the tyres' load sensitivity is calibrated it moves the shape of the stiffness against the load,
    # and the cornering scales the axles' levels: a level yaw rate and lateral acceleration do not tell
    # (the rear's, without the sideslip) stays where the start has it (held_stiffness_scales)
    hold = "tyre.PKY2" in parameters
    if hold:
        notes.append("tyre.PKY2 moves how the tyres' cornering stiffness changes with the load, each axle's "
                     "stiffness at its static load held at the cornering scale's (the scales are the axles' levels "
                     "at the start's PKY2; the vehicle file carries the scales that give them)")
    # the start and the calibrated car differ only in these fields: one compiled simulator scores both
    scored = tuple(dict.fromkeys(parameters + _calibration.STIFFNESS_SCALES))
    stages: list[tuple[str, Calibration]] = []
    failure = None
    calibration: Calibration | None = None
    warnings: list[str] = []
    fits: dict[str, Any] = {}
    predictions: dict[str, np.ndarray] = {}
    predictions["start"], fits["start"] = _score(log, runs, start, n_estimation, substeps, scored)
    if fits["start"] is None:
        notes.append("the start car's simulation of the log is not finite: it is not scored")
    # a stage earns its place by its car's simulation of the calibrating part (the filter's estimate
    # follows the states it corrects, and may land where the car alone drives worse): mean NRMSE fit
    best_fit = (float(np.mean(fits["start"]["estimation"]["nrmse"]))
                if fits["start"] and fits["start"]["estimation"] else -math.inf)
    for label, fixed in stage_plan:
        stage_starts = dict(starts)
        if calibration is not None:
            stage_starts.update({name: float(value) for name, value in
                                 zip(calibration.parameter_names, calibration.values) if name not in priors})
        try:
            result = _calibration.calibrate_vehicle(start, records, quantities, parameters=parameters, priors=priors,
                                                    prior_std=prior_std, options=options, fixed=fixed,
                                                    starts=stage_starts, hold_static_stiffness=hold)
        except DivergenceError as exc:
            failure = f"stage '{label}' diverged: {exc}"
            break
        except InputError as exc:  # the inputs were checked before any work: what remains is the stage's result
            failure = f"stage '{label}' left no valid vehicle: {exc}"
            break
        if result.result is None:  # nothing this stage frees is determined: the next starts where this one did
            notes.append(f"stage '{label}': the log determines none of its parameters ({'; '.join(result.warnings)})")
            continue
        fit = float(np.mean(result.result.nrmse_fit_percent))
        if not fit > best_fit:
            notes.append(f"stage '{label}' did not leave a car that drives the calibrating part better (mean NRMSE fit "
                         f"{fit:.1f} against {best_fit:.1f} %): the car before it is kept"
                         + ("" if calibration is not None else " (the start)"))
            continue
        best_fit = fit
        calibration = result
        stages.append((label, result))
    if calibration is None and failure is None:
        failure = "no stage determined its parameters and drove the calibrating part better than the start"
    if calibration is not None:
        warnings.extend(calibration.warnings)
    cars = [("prior", prior, ("chassis.yaw_inertia",))]
    if calibration is not None:
        cars.append(("calibrated", calibration.vehicle, scored))
    for label, vehicle, names in cars:
        predictions[label], fits[label] = _score(log, runs, vehicle, n_estimation, substeps, names)
        if fits[label] is None:
            notes.append(f"the {label} car's simulation of the log is not finite: it is not scored")
    halves_rows: dict[str, Any] = {}
    if halves and calibration is not None and failure is None:
        halves_rows, more = _halves(start, log, runs, n_estimation, min_samples, calibration, parameters, priors,
                                    prior_std, options, hold)
        warnings.extend(more)
    warnings.extend(_not_ahead(log, fits))
    if failure is not None:
        warnings.append(f"the calibration stopped early ({failure}); the car is that of the last stage that "
                        "finished" if calibration is not None else f"the calibration failed: {failure}")
    return DriveCalibration(
        calibration=calibration, prior=prior, start=start, balance=balance, stages=tuple(stages), runs=runs,
        n_estimation=n_estimation, fits=MappingProxyType(fits), predictions=MappingProxyType(predictions),
        halves=MappingProxyType(halves_rows), substeps=substeps, notes=tuple(notes), warnings=tuple(warnings),
        failure=failure,
    )


def _field_values(params: VehicleParameters, names: Sequence[str]) -> dict[str, float]:
    values = {}
    for name in names:
        section, _, field_name = name.partition(".")
        values[name] = float(getattr(getattr(params, section), field_name))
    return values


def _stage_plan(parameters: Sequence[str], quantities: Sequence[str]) -> list[tuple[str, tuple[str, ...]]]:
    """``(label, fixed)`` per filter stage (module notes): the steady-state balance with the yaw dynamics
    held, then the yaw dynamics with everything else, then roll where it is measured; a stage with nothing
    to estimate, or nothing held, is left out."""
    roll = tuple(name for name in parameters if name in DRIVE_ROLL_PARAMETERS) if "roll_angle" in quantities else ()
    steady = tuple(name for name in parameters if name in STEADY_PARAMETERS)
    plan = []
    if steady and len(steady) < len(parameters):
        plan.append(("balance", tuple(name for name in parameters if name not in steady)))
    if roll and len(roll) < len(parameters):
        plan.append(("yaw dynamics", roll))
    plan.append(("roll" if roll else "yaw dynamics", ()))
    return plan


def _halves(start: VehicleParameters, log: DriveLog, runs: Sequence[tuple[int, int]], n_estimation: int,
            min_samples: int, calibration: Calibration, parameters: Sequence[str], priors: Mapping[str, float],
            prior_std: Mapping[str, float] | None, options: GreyBoxOptions,
            hold_static_stiffness: bool) -> tuple[dict[str, Any], list[str]]:
    """Calibrate each half of the estimation part from the whole part's estimate and compare them."""
    rows = np.concatenate([np.arange(a, min(b, n_estimation)) for a, b in runs if a < n_estimation])
    # the second half is a record that starts from straight running, as every record does: it begins
    # where the car runs straightest near the middle (the smallest 0.5 s mean steer among the middle
    # _HALVES_WINDOW of the samples), not mid-corner (the committed race-car log's second half, begun at
    # 0.8 g, drove its front scale to 5e8)
    steer = _moving_mean(np.abs(log.steer), int(round(_STEADY_WINDOW / log.dt)))
    reach = max(1, int(_HALVES_WINDOW * rows.size / 2))
    candidates = rows[max(0, rows.size // 2 - reach):rows.size // 2 + reach]
    middle = int(candidates[np.argmin(steer[candidates])])
    fixed = tuple(calibration.held)
    starts = {name: float(value) for name, value in zip(calibration.parameter_names, calibration.values)
              if name not in priors}
    found = []
    for first, stop in ((0, middle), (middle, n_estimation)):
        records = drive_records(log, runs, first=first, stop=stop, min_samples=min_samples)
        if not records:
            return {}, [f"a half of the estimation part has no stretch of {MIN_RUN_SECONDS:g} s: halves not compared"]
        try:
            found.append(_calibration.calibrate_vehicle(start, records, log.quantities, parameters=parameters,
                                                        priors=priors, prior_std=prior_std, options=options,
                                                        fixed=fixed, starts=starts,
                                                        hold_static_stiffness=hold_static_stiffness))
        except (DivergenceError, InputError) as exc:
            return {}, [f"a half of the estimation part was not calibrated ({exc}): halves not compared"]
    return _compare_halves(calibration, *found)


def _not_ahead(log: DriveLog, fits: Mapping[str, Any]) -> list[str]:
    """Warnings where the calibrated car does not predict the held-out part better than the prior car."""
    calibrated = fits.get("calibrated")
    warnings = []
    if not calibrated or not calibrated.get("validation"):
        return warnings
    for label in ("prior", "start"):
        other = fits.get(label)
        if not other or not other.get("validation"):
            continue
        ahead = calibrated["validation"]["nrmse"] - other["validation"]["nrmse"]
        if not np.any(ahead > 0):
            shown = ", ".join(f"{channel} {value:+.1f}" for channel, value in zip(log.channels, ahead))
            warnings.append(f"the calibrated car does not predict the held-out part better than the {label} car "
                            f"(NRMSE fit change {shown} points)")
        worse = [channel for channel in log.checks
                 if calibrated["validation"]["checks"][channel] < other["validation"]["checks"][channel]]
        for channel in worse:
            warnings.append(f"the calibration makes the unfitted {channel} worse than the {label} car's: "
                            f"{calibrated['validation']['checks'][channel]:.1f} against "
                            f"{other['validation']['checks'][channel]:.1f} % NRMSE fit on the held-out part")
    return warnings
