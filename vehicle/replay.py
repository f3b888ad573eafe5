"""Replaying a measured drive through the source model: measured steer, measured speed, sample for sample.

The model follows the log's forward speed as a speed profile (feed-forward of
its rate plus the PI hold, :mod:`vehid.vehicle.model`) under the log's steer,
and its outputs land on the log's own time base, so that each can be set
beside the channel that measured it.

What the steer channel carries decides how it enters:

* ``"road"``: a measured road-wheel angle. It already holds whatever the
  steering's compliance took away, so the car is simulated with a rigid
  steering (compliance zero) and the angle drives the wheels directly.
* ``"wheel"``: a steering-wheel angle. It is divided by the steering ratio and
  the steering's compliance stays, so the aligning moments turn the wheels back.

Step size. A log's sample rate is rarely one the fixed-step RK4 can take: the
slip lags' modes run at ``-V / sigma`` (about -380 1/s for the rear
longitudinal lag at 60 m/s), beyond RK4's stability at 100 Hz. The replay
integrates on a finer grid of ``substeps`` steps per sample, steer and speed
interpolated linearly between samples, the fewest substeps that keep every mode
stable at the top speed of the log (with a margin), and keeps every
``substeps``-th sample. The simulator holds each input over the step that ends
at its sample; each step is given the log interpolated at its middle, which
follows the log's continuous-time signals to second order in the step where a
hold of the sample itself would lead them by half a step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.errors import InputError, SimulationError
from vehid.identification.assessment.metrics import nrmse_fit

from .choices import STEER_KINDS
from .linearize import linearization_function
from .model import build_vehicle_model, speed_limit
from .parameters import VehicleParameters, has_aerodynamics, named_vehicle
from .simulation import check_speed_profile, simulate
from .validity import MIN_SPEED, largest_stable_step

__all__ = ["STEER_KINDS", "ReplayFit", "replay", "replay_substeps", "channel_fits"]

_STEP_MARGIN = 0.8  # substeps no longer than 80 % of the largest stable RK4 step: modes shift along a drive
_MAX_SUBSTEPS = 50  # beyond this the log's rate is too coarse to interpolate the steer within a sample


def _vehicle_for(params: VehicleParameters, steer_is: str) -> VehicleParameters:
    if steer_is not in STEER_KINDS:
        raise InputError(f"the steer is a 'road'-wheel or a steering-'wheel' angle; got {steer_is!r}")
    if steer_is == "road" and params.steering.compliance:
        # The measured road-wheel angle already includes the compliance's deflection.
        return replace(params, steering=replace(params.steering, compliance=0.0))
    return params


def replay_substeps(params: VehicleParameters, dt: float, top_speed: float, margin: float = _STEP_MARGIN) -> int:
    """The fewest RK4 steps per sample of ``dt`` (s) that keep every mode of ``params`` stable up to ``top_speed``.

    The fastest modes (the slip lags, ``-V / sigma``) grow with speed, so the
    step is sized at the top speed; each step is at most ``margin`` of the
    largest stable one (default ``_STEP_MARGIN``), clear of the edge of RK4's
    stability region.
    """
    model = build_vehicle_model(params)
    x = model.trim(top_speed)
    eigenvalues = np.linalg.eigvals(np.asarray(linearization_function(model)(x, 0.0, top_speed)[0]))
    # the margin applies to a log's own step too: a step stable only at the edge is stable, not accurate
    stable = largest_stable_step(eigenvalues, dt / margin)
    substeps = max(1, math.ceil(dt / (margin * stable) - 1e-12))
    if substeps > _MAX_SUBSTEPS:
        raise InputError(f"the log's sample interval {dt:g} s needs {substeps} RK4 steps per sample at "
                         f"{top_speed:g} m/s; resample it to at least {substeps / _MAX_SUBSTEPS / dt:.3g} Hz first")
    return substeps


def replay(
    params: VehicleParameters | str,
    steer: Any,
    speed: Any,
    dt: float,
    *,
    steer_is: str = "road",
    t0: float = 0.0,
    method: str = "rk4",
    meta: Mapping[str, Any] | None = None,
    acceleration: Any = None,
    slip_limit: float | None = None,
) -> IOData:
    """Simulate the source model under a measured steer while it follows a measured speed trace.

    Parameters
    ----------
    params : VehicleParameters or str
        The vehicle (or a name or file, see :func:`vehid.vehicle.parameters.named_vehicle`).
    steer : array_like (N,)
        The measured steer (rad, positive left): a road-wheel or a steering-wheel angle, as ``steer_is`` says.
    speed : array_like (N,)
        The measured forward speed (m/s), one per steer sample.
    dt : float
        The log's sample interval (s), uniform.
    steer_is : {"road", "wheel"}
        What the steer is (module notes).
    t0 : float
        Time of the first sample (s), kept on the record.
    method : {"rk4", "cvodes"}
        The simulator's (:func:`vehid.vehicle.simulation.simulate`); CVODES, a
        cross-check, takes the same substeps.
    meta : mapping, optional
        Extra metadata for the record.
    acceleration : array_like (N,), optional
        The measured longitudinal acceleration (m/s^2): fed forward to the speed hold in place of the
        speed's rate, so that the drive and brake torques need not wait for a speed error.
    slip_limit : float, optional
        The car's slip limiter (:class:`~vehid.vehicle.parameters.DriveParameters`): traction control,
        anti-lock brakes and brakes shared by the axles' loads, which keep a replay's wheels from
        spinning up or locking where the vehicle's own torque split would. Default: the vehicle's.

    Returns
    -------
    IOData
        The simulated record on the log's time base (``t0 + k dt``): input
        ``steer`` (the model's input, the steering-wheel angle over the ratio
        or the road-wheel angle), the model's outputs and states; ``meta``
        adds ``replay_substeps`` and ``steer_is``.

    Raises
    ------
    InputError
        On mismatched lengths, a non-positive dt, a speed outside the model's
        range, steer beyond +/-30 deg at the road wheel, or a rate too coarse.
    SimulationError
        When the car leaves the model's valid envelope (the partial record is kept).
    """
    params = _vehicle_for(named_vehicle(params), steer_is)
    if slip_limit is not None and slip_limit != params.drive.slip_limit:
        params = replace(params, drive=replace(params.drive, slip_limit=float(slip_limit)))
    steer = np.asarray(steer, dtype=float).ravel()
    if steer.size < 2:
        raise InputError("a replay needs at least two samples")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise InputError(f"the sample interval must be a positive number of seconds; got {dt!r}")
    measured = np.asarray(speed, dtype=float).ravel()
    top = speed_limit(params)
    outside = np.flatnonzero((measured < MIN_SPEED) | (measured > top))
    if outside.size and measured.shape == steer.shape:
        first = int(outside[0])
        raise InputError(
            f"the log's speed leaves the model's valid range ({MIN_SPEED:g}-{top:g} m/s) at "
            f"t = {t0 + first * dt:.6g} s ({measured[first]:.4g} m/s; {outside.size} of {measured.size} samples): "
            "replay a segment inside it"
            + ("" if has_aerodynamics(params) else " or give the vehicle its aerodynamics ([aerodynamics] drag_area)")
        )
    profile = check_speed_profile(measured, steer.size, params)
    if steer_is == "wheel":
        steer = steer / params.steering.ratio
    substeps = replay_substeps(params, float(dt), float(profile.max()))
    samples = np.arange(steer.size)
    # simulate() holds each value over the step that ends at its sample: feed it the log at the middle
    # of that step (the first value is the trim's), so no half-step advance enters the record.
    fine = np.maximum(np.arange((steer.size - 1) * substeps + 1) - 0.5, 0.0) / substeps
    fine_steer = np.interp(fine, samples, steer)
    fine_speed = np.interp(fine, samples, profile)
    fine_acceleration = None
    if acceleration is not None:
        acceleration = np.asarray(acceleration, dtype=float).ravel()
        if acceleration.shape != steer.shape or not np.all(np.isfinite(acceleration)):
            raise InputError(f"the longitudinal acceleration needs one finite value per steer sample ({steer.size})")
        fine_acceleration = np.interp(fine, samples, acceleration)
    try:
        record = simulate(params, fine_steer, dt / substeps, speed=fine_speed, t0=t0, method=method,
                          acceleration=fine_acceleration,
                          meta={**(meta or {}), "replay_substeps": substeps, "steer_is": steer_is})
    except SimulationError as exc:
        # the partial record on the log's samples, when it reaches two of them (the message names the
        # time, the quantity and, for a tyre's slip, the wheel)
        partial = exc.partial
        partial = _on_log_grid(partial, substeps, t0, dt) if partial is not None and partial.n_samples > substeps else None
        raise SimulationError(str(exc), partial, quantity=exc.quantity, value=exc.value, time=exc.time) from None
    return _on_log_grid(record, substeps, t0, dt)


def _on_log_grid(record: IOData, substeps: int, t0: float, dt: float) -> IOData:
    """Every ``substeps``-th sample of a record integrated on the finer grid: the log's own samples."""
    kept = slice(None, None, substeps)
    n = record.u[kept].shape[0]
    return IOData(
        t=t0 + dt * np.arange(n), u=record.u[kept], y=record.y[kept], x=record.x[kept],
        input_names=record.input_names, output_names=record.output_names, state_names=record.state_names,
        input_units=record.input_units, output_units=record.output_units, state_units=record.state_units,
        meta=dict(record.meta),
    )


@dataclass(frozen=True)
class ReplayFit:
    """How a replay matches the log, one measured channel at a time.

    Attributes
    ----------
    fit_percent : mapping of str to float
        NRMSE fit (%) of each model output against the channel that measured it
        (100 is exact, 0 no better than the channel's mean, negative worse).
    rms_error : mapping of str to float
        Root-mean-square difference (SI units of the output).
    channels : mapping of str to str
        Which log channel each output was compared with.
    """

    fit_percent: Mapping[str, float]
    rms_error: Mapping[str, float]
    channels: Mapping[str, str]

    def as_dict(self) -> dict[str, Any]:
        return {name: {"channel": self.channels[name], "fit_percent": self.fit_percent[name],
                       "rms_error": self.rms_error[name]} for name in self.channels}


def channel_fits(record: IOData, measured: Mapping[str, tuple[str, np.ndarray]]) -> ReplayFit:
    """Compare a replay with the log: ``measured`` maps a model output to ``(channel name, values (N,))``."""
    fits, errors, channels = {}, {}, {}
    for output, (channel, values) in measured.items():
        simulated = record.output(output)
        values = np.asarray(values, dtype=float).ravel()
        if values.shape != simulated.shape:
            raise InputError(f"channel {channel!r} has {values.size} samples, the replay {simulated.size}")
        fits[output] = float(nrmse_fit(values[:, None], simulated[:, None])[0])
        errors[output] = float(np.sqrt(np.mean((values - simulated) ** 2)))
        channels[output] = channel
    return ReplayFit(MappingProxyType(fits), MappingProxyType(errors), MappingProxyType(channels))
