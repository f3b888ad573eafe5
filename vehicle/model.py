"""The 23-state full-vehicle handling model as named CasADi SX expressions.

A rigid body free in six degrees of freedom rides on four massless tyre nodes
through quarter-car struts (Best & Bogdanski, section 6). Lateral and
longitudinal tyre forces come from the combined-slip, load-dependent Magic
Formula (:mod:`vehid.vehicle.tyre`) evaluated on first-order relaxation-lagged slips;
each wheel spins; a PI controller holds the forward speed with the drive torque
split equally between the front wheels (or, by ``front_drive_share``, between
the axles).

Modelling choices (documented here once):

* Axes ISO 8855 (x forward, y left, z up), body axes at the CG; Euler angles
  ZYX (yaw psi, pitch theta, roll phi). A left turn gives r > 0, a_y > 0 and
  phi > 0 (the body leans outward: left side up).
* The tyre nodes are massless, so corner deflections are algebraic in the body
  pose and velocity and there are no unsprung states. Each tyre's force acts on
  the body at its contact point, which stays on the road: horizontally it
  follows the body point ``(x_i, y_i, -h)`` (static ground level below the
  strut), so the roll and pitch axes sit at the ground, as in the closed-form
  roll gradient; vertically it is the road, ``h + z`` below the CG. Roll and
  pitch therefore move the struts, not the contact geometry: the lateral
  forces' lever arm about the CG stays ``h + z`` (a contact point fixed in body
  axes would sink below the road on the outside of a turn and lengthen it,
  raising the roll gradient by 6 % at 0.77 g).
* Suspension force = static corner load + k * compression + c * compression
  rate + anti-roll-bar term; the tyre load is a smooth ``max(force, 0)``, so a
  wheel may lift off.
* X and Y positions are dropped (nothing depends on them on a flat road); psi
  is kept, ignorable, and adds one zero eigenvalue to every linearisation.
* Slip lags without division by speed (Pacejka 2012, section 7.2):
  ``sigma_a d(alpha')/dt = V_cy - |V_cx| alpha'`` and
  ``sigma_k d(kappa')/dt = R_e omega - V_cx - |V_cx| kappa'``.
* Wheel spin ``I_w d(omega)/dt = T - R_e F_x``. The wheels' spin angular
  momentum is not fed back to the body: no gyroscopic moment (about 1 % of the
  roll moment at 7 m/s^2) and no reaction to the wheels' spin acceleration.
* Smooth, branch-free: ``|x| ~ sqrt(x^2 + eps^2)``, ``max(x, 0) ~ (x + |x|_eps)/2``.

States (in this order): u, v, w (m/s); p, q, r (rad/s); z (heave of the CG
from its static height, m); phi, theta, psi (rad); omega_fl, omega_fr,
omega_rl, omega_rr (rad/s); alpha_fl ... alpha_rr (lagged lateral slip, -);
kappa_fl ... kappa_rr (lagged slip ratio, -); speed_error_integral (m).
Input: steer (rad): the steering-wheel angle over the steering ratio, which is
the road-wheel angle when the steering is rigid (compliance zero, as in the
baseline). Parameter: reference_speed (m/s).

Steering. With a steering compliance ``c`` (:class:`~vehid.vehicle.parameters.SteeringParameters`), the
road wheels stand at ``delta = steer + c M`` with ``M`` the sum over the two
front wheels of the Magic Formula aligning moment and of ``-t_m F_y``, the
lateral force at the caster trail ``t_m`` (ISO signs: in a left turn ``M`` is
negative and the wheels yield towards straight ahead). The moments depend on
the lagged slips and the loads, which are states or algebraic in states, so
the massless steering needs no state of its own: quasi-static, the state count
stays 23.

Speed hold. The PI law acts on the speed error; a speed profile adds the
reference's rate as feed-forward (:attr:`VehicleModel.tracking_dynamics`,
parameters ``(reference_speed, reference_acceleration)``): the wheel torque
that accelerates the car and its four wheels at that rate,
``(m R_e + 4 I_w / R_e) dV_ref/dt``. Positive demand drives the front wheels.
When the reference falls (this model has no rolling resistance or drag, so a
coasting car keeps its speed and any falling reference needs the brakes), the
braking part of the demand is shared with the rear wheels in proportion to the
static axle loads, blended in over the first 0.5 m/s^2 of deceleration so that
the torques stay continuous in the reference. At a constant reference the rate
is zero, the feed-forward and the rear torque vanish identically and
:attr:`VehicleModel.dynamics` is the plain PI hold on the front wheels.

Slip limiter (``drive.slip_limit`` above zero; none on the named vehicles). A car replayed along a
measured drive is asked for the log's accelerations whatever its torque split: an unloaded inner wheel
spins up under drive torque, a lightly loaded rear wheel locks under braking, and the replay stops
there. With the limiter, as traction control and anti-lock brakes do, each wheel's torque fades once
its lagged slip passes the limit in the torque's direction and a restoring torque brings the wheel
back (:func:`_slip_limited`), and the brakes are shared between the axles in proportion to their loads
as they are (electronic brake-force distribution) rather than the static ones.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from vehid.identification.errors import DivergenceError, InputError

from .choices import DEFAULT_SPEED
from .parameters import GRAVITY, VehicleParameters, has_aerodynamics, static_axle_loads
from .tyre import aligning_moment, combined_forces
from .validity import MAX_SPEED, MAX_SPEED_AERO, check_speed_range

__all__ = [
    "VehicleModel",
    "build_vehicle_model",
    "STATE_NAMES",
    "STATE_UNITS",
    "OUTPUT_NAMES",
    "OUTPUT_UNITS",
    "INPUT_NAMES",
    "INPUT_UNITS",
    "CORNERS",
    "DEFAULT_SPEED",
    "MAX_STEER",
    "check_speed",
    "speed_limit",
    "positive_number",
]

CORNERS = ("fl", "fr", "rl", "rr")
MAX_STEER = np.deg2rad(30.0)  # [rad] road-wheel steer beyond this is rejected as bad input

STATE_NAMES = (
    "u", "v", "w", "p", "q", "r", "z", "phi", "theta", "psi",
    *(f"omega_{c}" for c in CORNERS),
    *(f"alpha_{c}" for c in CORNERS),
    *(f"kappa_{c}" for c in CORNERS),
    "speed_error_integral",
)
STATE_UNITS = (
    "m/s", "m/s", "m/s", "rad/s", "rad/s", "rad/s", "m", "rad", "rad", "rad",
    *("rad/s",) * 4, *("-",) * 4, *("-",) * 4, "m",
)
INPUT_NAMES = ("steer",)
INPUT_UNITS = ("rad",)
OUTPUT_NAMES = (
    "lateral_acceleration",
    "yaw_rate",
    "roll_angle",
    "sideslip",
    "speed",
    *(f"tyre_load_{c}" for c in CORNERS),
    "lateral_acceleration_accelerometer",
)
OUTPUT_UNITS = ("m/s^2", "rad/s", "rad", "rad", "m/s", *("N",) * 4, "m/s^2")

_EPS_SPEED = 0.1  # [m/s] smoothing of |V_cx|: 2.5e-4 relative error at 20 m/s
_EPS_LOAD = 1.0  # [N] smoothing of max(F_z, 0): 6e-5 N bias at a static corner load of ~3-4 kN
_EPS_DEMAND = 0.01  # [m/s^2] smoothing of min(demand, 0): brake torque at zero demand 0.5 % of a 1 m/s^2 stop
_EPS_TORQUE = 1.0  # [N m] a torque's direction, smoothed: the slip limiter's sense at zero torque
_EPS_SLIP = 0.005  # smoothing of the slip limiter's onset: a twentieth of a typical limit of 0.1
_SLIP_RETURN_RATE = 400.0  # [m/s^2] the limiter's pull on a wheel's surface speed per unit of excess slip
_BRAKE_BLEND = 0.5  # [m/s^2] falling reference rate over which the rear brakes take their full share


def _smooth_abs(x, eps):
    return ca.sqrt(x * x + eps * eps)


def _slip_limited(torque, slip, limit, restoring):
    """A wheel's torque as traction control and anti-lock brakes leave it (module notes, "Slip limiter").

    Beyond ``limit`` in the torque's direction (a driven wheel spinning up, a braked one locking)
    the torque fades by ``1 / (1 + (excess / (limit / 2))^2)`` (one up to the limit, a half at 1.5
    times it) and ``restoring`` (N m per unit of excess slip) turns the wheel back towards the
    limit, as a traction control brakes a spinning wheel: a wheel lifted off the road, which no
    tyre force slows, then settles near the limit too. Smooth throughout.
    """
    direction = ca.tanh(torque / _EPS_TORQUE)
    beyond = direction * slip - limit
    excess = (beyond + _smooth_abs(beyond, _EPS_SLIP)) / 2
    return torque / (1 + (2 * excess / limit) ** 2) - direction * restoring * excess


def _rotation_pitch_roll(phi, theta):
    """Body axes to the yaw-aligned road frame: R_y(theta) R_x(phi)."""
    cf, sf, ct, st = ca.cos(phi), ca.sin(phi), ca.cos(theta), ca.sin(theta)
    roll = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, cf, -sf), ca.horzcat(0, sf, cf))
    pitch = ca.vertcat(ca.horzcat(ct, 0, st), ca.horzcat(0, 1, 0), ca.horzcat(-st, 0, ct))
    return ca.mtimes(pitch, roll)


@dataclass(frozen=True, eq=False)
class VehicleModel:
    """The symbolic model and its CasADi functions ``f(x, u, p)`` and ``h(x, u, p)``.

    Attributes
    ----------
    params : VehicleParameters
        What it was built from.
    x, u, p : casadi.SX
        Symbols: states (23,), input steer (1,), parameter reference speed (1,).
    xdot, y : casadi.SX
        State derivative (23,) and outputs (10,).
    dynamics : casadi.Function
        ``dynamics(x, u, p) -> xdot`` at a constant reference speed ``p``.
    outputs : casadi.Function
        ``outputs(x, u, p) -> y``.
    reference_acceleration : casadi.SX
        Symbol of the reference's rate dV_ref/dt (m/s^2), which ``xdot`` does not contain.
    tracking_dynamics : casadi.Function
        ``tracking_dynamics(x, u, p) -> xdot`` with ``p = (V_ref, dV_ref/dt)`` (2,):
        the speed hold with feed-forward and four-wheel braking (module notes).
    state_names, state_units, input_names, input_units, output_names, output_units : tuple of str
        Names and units of the states, the input and the outputs, in their order in ``x``, ``u`` and ``y``.
    """

    params: VehicleParameters
    x: ca.SX
    u: ca.SX
    p: ca.SX
    xdot: ca.SX
    y: ca.SX
    dynamics: ca.Function
    outputs: ca.Function
    reference_acceleration: ca.SX | None = None
    tracking_dynamics: ca.Function | None = None
    state_names: tuple[str, ...] = STATE_NAMES
    state_units: tuple[str, ...] = STATE_UNITS
    input_names: tuple[str, ...] = INPUT_NAMES
    input_units: tuple[str, ...] = INPUT_UNITS
    output_names: tuple[str, ...] = OUTPUT_NAMES
    output_units: tuple[str, ...] = OUTPUT_UNITS

    @property
    def n_states(self) -> int:
        """Number of states (23)."""
        return len(self.state_names)

    @property
    def n_u(self) -> int:
        """Number of inputs (1: the steer)."""
        return len(self.input_names)

    @property
    def n_y(self) -> int:
        """Number of outputs (10)."""
        return len(self.output_names)

    def state_index(self, name: str) -> int:
        """Return the position of a named state in ``x``.

        Parameters
        ----------
        name : str
            One of ``state_names``.

        Returns
        -------
        int
            Its index, 0-based.
        """
        return _index(self.state_names, name, "state")

    def output_index(self, name: str) -> int:
        """Return the position of a named output in ``y``.

        Parameters
        ----------
        name : str
            One of ``output_names``.

        Returns
        -------
        int
            Its index, 0-based.
        """
        return _index(self.output_names, name, "output")

    def straight_running_guess(self, speed: float) -> np.ndarray:
        """Guess the states of straight running on static suspension: the start of the trim at zero steer.

        Parameters
        ----------
        speed : float
            Forward speed (m/s).

        Returns
        -------
        ndarray, shape (23,)
            The forward speed and the wheel spins set, every other state zero.
        """
        x = np.zeros(self.n_states)
        x[self.state_index("u")] = speed
        for corner in CORNERS:
            x[self.state_index(f"omega_{corner}")] = speed / self.params.tyre.rolling_radius
        return x

    def trim(self, speed: float = DEFAULT_SPEED, steer: float = 0.0, *, tolerance: float = 1e-11) -> np.ndarray:
        """Solve for the steady state at ``speed`` (m/s) and constant ``steer`` (rad).

        All derivatives except d(psi)/dt (psi is ignorable) are driven to zero by
        Newton's method with a backtracking line search, starting from straight
        running, and polished by one more step once below ``tolerance``; where that fails (large steer), the steer is raised in eight
        stages, each solve starting from the last.

        Parameters
        ----------
        speed : float, default DEFAULT_SPEED
            Forward speed (m/s), within the model's valid range.
        steer : float, default 0.0
            Road-wheel steer (rad), within +/-30 deg.
        tolerance : float, default 1e-11
            Norm of the derivatives at which Newton's method stops.

        Returns
        -------
        ndarray, shape (23,)
            The steady states (psi = 0).

        Raises
        ------
        InputError
            On a non-positive speed or a steer beyond +/-30 deg.
        DivergenceError
            When no steady state is found (e.g. beyond the grip limit).
        """
        check_speed(speed, self.params)
        steer = float(steer)
        if not np.isfinite(steer) or abs(steer) > MAX_STEER:
            raise InputError(f"trim steer must be finite and within +/-30 deg; got {np.rad2deg(steer):.3g} deg")
        keep = [i for i, name in enumerate(self.state_names) if name != "psi"]
        x = self.straight_running_guess(speed)
        z, norm = _newton(self, x[keep], steer, speed, tolerance)
        if norm >= tolerance:
            z = x[keep]
            for fraction in np.linspace(0.125, 1.0, 8):
                z, norm = _newton(self, z, fraction * steer, speed, tolerance)
        if norm >= tolerance:
            raise DivergenceError(
                f"no steady state found at {speed} m/s and {np.rad2deg(steer):.3g} deg steer "
                f"(residual {norm:.3g}): beyond the grip limit?"
            )
        x[keep] = z
        return x


def _newton(model: VehicleModel, z: np.ndarray, steer: float, speed: float, tolerance: float):
    """Damped Newton iterations on the trim residual; returns (solution, residual norm)."""
    residual, jacobian = _trim_functions(model)

    def size(candidate: np.ndarray) -> tuple[np.ndarray, float]:
        value = np.asarray(residual(candidate, steer, speed)).ravel()
        return value, float(np.linalg.norm(value))

    value, norm = size(z)
    for _ in range(60):
        if norm < tolerance or not np.isfinite(norm):
            break
        try:
            step = np.linalg.solve(np.asarray(jacobian(z, steer, speed)), -value)
        except np.linalg.LinAlgError:
            break
        scale = 1.0
        while True:  # backtrack until the residual falls (or the step is negligible)
            trial = z + scale * step
            trial_value, trial_norm = size(trial)
            if trial_norm < norm or scale < 1e-4:
                break
            scale *= 0.5
        z, value, norm = trial, trial_value, trial_norm
    if norm < tolerance:
        # One more full step: Newton converges quadratically, so this takes a residual
        # that has just passed the tolerance down to round-off (about 1e-14).
        try:
            trial = z + np.linalg.solve(np.asarray(jacobian(z, steer, speed)), -value)
        except np.linalg.LinAlgError:
            return z, norm
        trial_value, trial_norm = size(trial)
        if trial_norm <= norm:
            z, norm = trial, trial_norm
    return z, norm


def _index(names: Sequence[str], name: str, kind: str) -> int:
    try:
        return list(names).index(name)
    except ValueError:
        raise InputError(f"unknown {kind} {name!r}; available: {', '.join(names)}") from None


def positive_number(value: float, name: str, unit: str) -> float:
    """Return ``value`` as a float, or raise InputError if it is not a positive finite number."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number ({unit}); got {value!r}") from None
    if not np.isfinite(number) or number <= 0:
        raise InputError(f"{name} must be positive and finite ({unit}); got {value}")
    return number


def check_speed(speed: float, params: VehicleParameters | None = None) -> float:
    """Return ``speed`` (m/s) as a float, or raise InputError if it is not positive and finite
    or lies outside the model's valid range (:data:`vehid.vehicle.validity.MIN_SPEED` to ``MAX_SPEED``,
    or ``MAX_SPEED_AERO`` for ``params`` with aerodynamic forces)."""
    value, limit = positive_number(speed, "speed", "m/s"), speed_limit(params)
    return check_speed_range(value) if limit == MAX_SPEED else check_speed_range(value, limit)


def speed_limit(params: VehicleParameters | None) -> float:
    """The top of the valid speed range of ``params`` (m/s): higher for a vehicle with aerodynamic forces."""
    return MAX_SPEED_AERO if params is not None and has_aerodynamics(params) else MAX_SPEED


@functools.lru_cache(maxsize=8)
def _trim_functions(model: VehicleModel) -> tuple[ca.Function, ca.Function]:
    keep = [i for i, name in enumerate(model.state_names) if name != "psi"]
    reduced = ca.SX.sym("x_trim", len(keep))
    full = ca.SX.zeros(model.n_states)
    for j, i in enumerate(keep):
        full[i] = reduced[j]
    derivative = model.dynamics(full, model.u, model.p)[keep]
    residual = ca.Function("trim_residual", [reduced, model.u, model.p], [derivative])
    jacobian = ca.Function("trim_jacobian", [reduced, model.u, model.p], [ca.jacobian(derivative, reduced)])
    return residual, jacobian


@functools.lru_cache(maxsize=16)
def build_vehicle_model(params: VehicleParameters) -> VehicleModel:
    """Build the symbolic 23-state model of ``params`` (cached per parameter set).

    Parameters
    ----------
    params : VehicleParameters
        The vehicle.

    Returns
    -------
    VehicleModel
        Named symbols, ``dynamics(x, u, p)`` and ``outputs(x, u, p)``, where
        ``u`` is the road-wheel steer (rad) and ``p`` the reference speed (m/s).
    """
    x, steer, reference_speed, reference_acceleration, xdot, y = vehicle_expressions(params)
    tracking_dynamics = ca.Function(
        "vehicle_tracking_dynamics", [x, steer, ca.vertcat(reference_speed, reference_acceleration)], [xdot],
        ["x", "u", "p"], ["xdot"],
    )
    # At a constant reference the rate is zero: substituting it folds the feed-forward and
    # the rear brake torque away, leaving the plain PI hold the paper's studies ran with.
    xdot = ca.substitute(xdot, reference_acceleration, ca.SX(0))
    dynamics = ca.Function(
        "vehicle_dynamics", [x, steer, reference_speed], [xdot], ["x", "u", "p"], ["xdot"]
    )
    outputs = ca.Function("vehicle_outputs", [x, steer, reference_speed], [y], ["x", "u", "p"], ["y"])
    return VehicleModel(
        params=params, x=x, u=steer, p=reference_speed, xdot=xdot, y=y, dynamics=dynamics, outputs=outputs,
        reference_acceleration=reference_acceleration, tracking_dynamics=tracking_dynamics,
    )


def vehicle_expressions(params: VehicleParameters) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX, ca.SX, ca.SX]:
    """The model's symbols and expressions, before any CasADi function is made of them.

    A numeric field of ``params`` may hold a CasADi symbol instead of a number (one not used in a
    decision: steering compliance, drive share, aerodynamics): it then stays a free symbol of the
    expressions, which is how a calibration makes chosen vehicle parameters unknowns.

    Returns
    -------
    x, steer, reference_speed, reference_acceleration : casadi.SX
        Symbols: states (23,), road-wheel steer, reference speed and its rate.
    xdot, y : casadi.SX
        State derivative with the speed-profile feed-forward (:attr:`VehicleModel.tracking_dynamics`)
        and outputs (:data:`OUTPUT_NAMES`).
    """
    chassis, suspension, tyre, drive = params.chassis, params.suspension, params.tyre, params.drive
    x = ca.SX.sym("x", len(STATE_NAMES))
    steer = ca.SX.sym("steer")
    reference_speed = ca.SX.sym("reference_speed")
    s = {name: x[i] for i, name in enumerate(STATE_NAMES)}

    m, g, h = chassis.mass, GRAVITY, chassis.cg_height
    a, b = chassis.cg_to_front_axle, chassis.cg_to_rear_axle
    tf, tr = chassis.front_track, chassis.rear_track
    velocity = ca.vertcat(s["u"], s["v"], s["w"])
    rates = ca.vertcat(s["p"], s["q"], s["r"])
    phi, theta = s["phi"], s["theta"]
    to_road = _rotation_pitch_roll(phi, theta)

    front_static, rear_static = static_axle_loads(params)
    corner_x = (a, a, -b, -b)
    corner_y = (tf / 2, -tf / 2, tr / 2, -tr / 2)
    static_load = (front_static / 2, front_static / 2, rear_static / 2, rear_static / 2)
    wheel_rate = (suspension.front_wheel_rate,) * 2 + (suspension.rear_wheel_rate,) * 2
    damping = (suspension.front_damping,) * 2 + (suspension.rear_damping,) * 2
    steered = (True, True, False, False)
    lateral_relaxation = (tyre.front_lateral_relaxation,) * 2 + (tyre.rear_lateral_relaxation,) * 2
    longitudinal_relaxation = (tyre.front_longitudinal_relaxation,) * 2 + (tyre.rear_longitudinal_relaxation,) * 2
    cornering_scale = (tyre.front_cornering_scale,) * 2 + (tyre.rear_cornering_scale,) * 2

    # Corner compression (positive in bump) and its rate, from the body pose and velocity.
    compression, compression_rate = [], []
    for i in range(4):
        strut_top = ca.vertcat(corner_x[i], corner_y[i], 0)
        compression.append(-s["z"] - ca.mtimes(to_road[2, :], strut_top))
        strut_velocity = velocity + ca.cross(rates, strut_top)
        compression_rate.append(-ca.mtimes(to_road[2, :], strut_velocity))
    strut_force = [
        static_load[i] + wheel_rate[i] * compression[i] + damping[i] * compression_rate[i] for i in range(4)
    ]
    for left, right, track, bar in ((0, 1, tf, suspension.front_anti_roll_bar), (2, 3, tr, suspension.rear_anti_roll_bar)):
        # Bar moment bar * (axle roll) with axle roll = (compression_L - compression_R) / track.
        bar_force = bar * (compression[left] - compression[right]) / track**2
        strut_force[left] = strut_force[left] + bar_force
        strut_force[right] = strut_force[right] - bar_force
    load = [(f + _smooth_abs(f, _EPS_LOAD)) / 2 for f in strut_force]

    speed_error = reference_speed - s["u"]
    reference_acceleration = ca.SX.sym("reference_acceleration")
    # Demanded acceleration (m/s^2): PI on the speed error, plus the reference's rate scaled
    # so that the torque also spins up the four wheels' inertia.
    wheel_inertia_share = 4 * tyre.wheel_inertia / (m * tyre.rolling_radius**2)
    demand = (
        drive.speed_gain * speed_error + drive.speed_integral_gain * s["speed_error_integral"]
        + (1 + wheel_inertia_share) * reference_acceleration
    )
    aero = params.aerodynamics
    with_aero = has_aerodynamics(params) or aero.front_downforce_area or aero.rear_downforce_area
    if with_aero:
        dynamic_pressure = 0.5 * aero.air_density * s["u"] * _smooth_abs(s["u"], _EPS_SPEED)
        drag = aero.drag_area * dynamic_pressure
        demand = demand + drag / m  # feed-forward of the drag: the PI hold is left the transients
    braking_demand = (demand - _smooth_abs(demand, _EPS_DEMAND)) / 2  # smooth min(demand, 0)
    # Brakes balanced to the static axle loads, blended in as the reference starts to fall:
    # exactly zero rear torque at a constant or rising reference.
    rear_load_share = rear_static / (front_static + rear_static)
    if drive.slip_limit > 0:
        # with the slip limiter comes electronic brake-force distribution: the brakes shared in
        # proportion to the axles' loads as they are, which braking shifts forwards
        rear_load_share = (load[2] + load[3]) / (load[0] + load[1] + load[2] + load[3] + _EPS_LOAD)
    rear_brake_share = rear_load_share * ca.fmin(ca.fmax(-reference_acceleration / _BRAKE_BLEND, 0), 1)
    rear_axle_torque = m * tyre.rolling_radius * rear_brake_share * braking_demand
    if drive.front_drive_share == 1:  # front-wheel drive: the paper's car, its expressions as they were
        drive_torque_front = 0.5 * m * tyre.rolling_radius * demand - 0.5 * rear_axle_torque
    else:
        # The driving part of the demand is split between the axles; braking stays as above.
        rear_drive = (1 - drive.front_drive_share) * m * tyre.rolling_radius * (demand - braking_demand)
        drive_torque_front = 0.5 * m * tyre.rolling_radius * demand - 0.5 * rear_axle_torque - 0.5 * rear_drive
        rear_axle_torque = rear_axle_torque + rear_drive
    drive_torque = (drive_torque_front, drive_torque_front, 0.5 * rear_axle_torque, 0.5 * rear_axle_torque)
    if drive.slip_limit > 0:
        # the wheel's spin returns to the limit in about V / 400 s (0.05 s at 20 m/s): I_w V / (restoring R_e)
        restoring = _SLIP_RETURN_RATE * tyre.wheel_inertia / tyre.rolling_radius
        drive_torque = tuple(_slip_limited(torque, s[f"kappa_{corner}"], drive.slip_limit, restoring)
                             for torque, corner in zip(drive_torque, CORNERS))

    # Tyre forces from the lagged slips and the loads: they do not depend on the steer.
    tyre_forces = [
        combined_forces(s[f"kappa_{corner}"], s[f"alpha_{corner}"], load[i], tyre,
                        scale=cornering_scale[i], mirrored=corner_y[i] < 0)
        for i, corner in enumerate(CORNERS)
    ]
    road_wheel_angle = steer
    if params.steering.compliance > 0:
        # Quasi-static steering compliance: the road wheels yield to the moments about the steering
        # axes, the aligning moment plus the lateral force at the caster trail. Both are functions of
        # the lagged slips (states), so the road-wheel angle is explicit and no state is added.
        kingpin_moment = 0
        for i, corner in enumerate(CORNERS):
            if steered[i]:
                fx, fy = tyre_forces[i]
                moment = aligning_moment(s[f"kappa_{corner}"], s[f"alpha_{corner}"], load[i], tyre,
                                         scale=cornering_scale[i], mirrored=corner_y[i] < 0, lateral_force=fy)
                kingpin_moment = kingpin_moment + moment - params.steering.mechanical_trail * fy
        road_wheel_angle = steer + params.steering.compliance * kingpin_moment

    force_body = ca.SX.zeros(3)
    moment_body = ca.SX.zeros(3)
    lateral_force_road = 0
    slip_lateral_rate, slip_longitudinal_rate, wheel_acceleration = [], [], []
    cos_steer, sin_steer = ca.cos(road_wheel_angle), ca.sin(road_wheel_angle)
    for i, corner in enumerate(CORNERS):
        # The wheel follows the body point at static ground level below its strut
        # (roll and pitch axes at the ground), horizontally only: its contact point
        # stays on the road, h + z below the CG, however the body rolls or pitches.
        ground_point = ca.vertcat(corner_x[i], corner_y[i], -h)
        ground_point_road = ca.mtimes(to_road, ground_point)
        contact_road = ca.vertcat(ground_point_road[0], ground_point_road[1], -(h + s["z"]))
        # The contact point moves horizontally as that body point does; slip needs no more.
        contact_velocity = ca.mtimes(to_road, velocity + ca.cross(rates, ground_point))
        cd, sd = (cos_steer, sin_steer) if steered[i] else (1, 0)
        v_cx = cd * contact_velocity[0] + sd * contact_velocity[1]
        v_cy = -sd * contact_velocity[0] + cd * contact_velocity[1]
        abs_v_cx = _smooth_abs(v_cx, _EPS_SPEED)
        alpha, kappa, omega = s[f"alpha_{corner}"], s[f"kappa_{corner}"], s[f"omega_{corner}"]
        slip_lateral_rate.append((v_cy - abs_v_cx * alpha) / lateral_relaxation[i])
        slip_longitudinal_rate.append(
            (tyre.rolling_radius * omega - v_cx - abs_v_cx * kappa) / longitudinal_relaxation[i]
        )
        fx, fy = tyre_forces[i]
        wheel_acceleration.append((drive_torque[i] - tyre.rolling_radius * fx) / tyre.wheel_inertia)
        force_road = ca.vertcat(cd * fx - sd * fy, sd * fx + cd * fy, load[i])
        lateral_force_road = lateral_force_road + force_road[1]
        force_body = force_body + ca.mtimes(to_road.T, force_road)
        moment_body = moment_body + ca.mtimes(to_road.T, ca.cross(contact_road, force_road))

    if with_aero:
        # Drag at the CG, horizontal (the air meets the car along the road); each axle's downforce
        # presses the body down above that axle.
        force_body = force_body + ca.mtimes(to_road.T, ca.vertcat(-drag, 0, 0))
        for axle_x, area in ((a, aero.front_downforce_area), (-b, aero.rear_downforce_area)):
            if area:
                downforce = ca.mtimes(to_road.T, ca.vertcat(0, 0, -area * dynamic_pressure))
                force_body = force_body + downforce
                moment_body = moment_body + ca.cross(ca.vertcat(axle_x, 0, 0), downforce)
    gravity_body = ca.mtimes(to_road.T, ca.vertcat(0, 0, -g))
    acceleration = force_body / m + gravity_body  # inertial acceleration of the CG in body axes
    velocity_rate = acceleration - ca.cross(rates, velocity)
    # built entry by entry so that an inertia may be a symbol (vehicle_expressions)
    inertia = ca.vertcat(
        ca.horzcat(chassis.roll_inertia, 0, -chassis.roll_yaw_product),
        ca.horzcat(0, chassis.pitch_inertia, 0),
        ca.horzcat(-chassis.roll_yaw_product, 0, chassis.yaw_inertia),
    )
    rate_rate = ca.solve(inertia, moment_body - ca.cross(rates, ca.mtimes(inertia, rates)))
    p_, q_, r_ = s["p"], s["q"], s["r"]
    sin_phi, cos_phi = ca.sin(phi), ca.cos(phi)
    euler_rate = ca.vertcat(
        p_ + (q_ * sin_phi + r_ * cos_phi) * ca.tan(theta),
        q_ * cos_phi - r_ * sin_phi,
        (q_ * sin_phi + r_ * cos_phi) / ca.cos(theta),
    )
    heave_rate = ca.mtimes(to_road[2, :], velocity)

    xdot = ca.vertcat(
        velocity_rate,
        rate_rate,
        heave_rate,
        euler_rate,
        *wheel_acceleration,
        *slip_lateral_rate,
        *slip_longitudinal_rate,
        speed_error,
    )
    velocity_road = ca.mtimes(to_road, velocity)
    y = ca.vertcat(
        lateral_force_road / m,  # road-plane a_y of the CG: gravity has no road-plane component
        s["r"],
        phi,
        ca.atan(velocity_road[1] / velocity_road[0]),
        ca.norm_2(velocity),
        *load,
        force_body[1] / m,  # specific force along body y: what a body-fixed accelerometer reads
    )
    return x, steer, reference_speed, reference_acceleration, xdot, y
