"""Simulate the full-vehicle model: compiled fixed-step RK4 lifted over time, with a CVODES cross-check.

The fixed-step path takes one classical Runge-Kutta step per sample. The step
is a CasADi function lifted over a block of samples with ``mapaccum``,
generated to C and compiled once per (vehicle, dt) with
:func:`vehid.identification.compiled.compile_function` (cached on disk), so that
no Python runs per time step: a record is a handful of calls, one per block.

At 20 m/s the fastest modes sit near 190 rad/s, so RK4 at 500 Hz
(lambda dt = 0.38) is accurate to about 1e-4 of the outputs; the ``cvodes``
method (BDF at tolerance 1e-12) is the reference to check it against. CVODES
is restarted at every sample, where the held steer jumps: a multistep method
carried across such a jump (as CasADi's integrator does with a control grid:
it stops there but keeps its history) misjudges its error, which left it
3e-5 m/s^2 off IDAS and RK4 at tolerance 1e-10 (30 times RK4's own error) and
failing at 1e-12. Restarted, it agrees with RK4 at 1/16 of the step
(:func:`reference_outputs`) some 400 times more closely than the 500 Hz RK4
it checks (5.7e-9 against 2.3e-6 m/s^2 over the 30 s identification record;
``benchmarks/vehicle_sim.py``).

Every record is checked against the physical envelope of
:mod:`vehid.vehicle.validity` block by block as it is computed; the first sample
outside ends the run with a :class:`~identification.errors.SimulationError`
that carries the record up to it. The speed, the step and the memory a record
needs are checked before any work.

Timing convention: ``u[k]`` is held on the interval that ends at ``t[k]``, so
``x[k] = step(x[k-1], u[k])``; the record starts at the exact trim of the
first steer sample (zero in every manoeuvre of :mod:`vehid.vehicle.manoeuvres`).

Speed profiles: a reference speed given per sample (a manoeuvre's ``speed``
or an array) is tracked by the PI hold with the reference's rate as
feed-forward (:attr:`vehid.vehicle.model.VehicleModel.tracking_dynamics`); the
rate is the profile's central difference, and both are held on the interval
ending at their sample, as the steer is. A constant reference runs the plain
hold, as before.
"""

from __future__ import annotations

import functools
import math
import time
from typing import Any

import casadi as ca
import numpy as np

from vehid.identification.compiled import compile_function
from vehid.identification.data import IOData
from vehid.identification.errors import InputError, SimulationError

from .linearize import linearization_function
from .model import DEFAULT_SPEED, MAX_STEER, VehicleModel, build_vehicle_model, check_speed, positive_number
from .parameters import VehicleParameters, named_vehicle
from .validity import Violation, check_memory, check_rk4_step, first_violation

__all__ = [
    "simulate",
    "rk4_simulator",
    "build_rk4_block",
    "COMPILE_FLAGS",
    "DEFAULT_DT",
    "BLOCK_SAMPLES",
    "check_steer",
    "check_speed_profile",
    "check_record_memory",
    "CROSS_CHECK_TOLERANCE",
    "reference_outputs",
]

DEFAULT_DT = 1.0 / 500.0  # [s] the paper's output rate
BLOCK_SAMPLES = 1000  # samples per compiled call; any record length runs as whole blocks plus padding
COMPILE_FLAGS = "-O1"  # the generated step is large; -O1 compiles much faster than -O2 at similar speed
CROSS_CHECK_TOLERANCE = 1e-12  # CVODES relative and absolute tolerance: ~400x closer to the truth than RK4
_RECORD_COLUMNS = 23 + 10 + 1 + 1  # states, outputs, steer and time of one sample


def check_record_memory(n_samples: int) -> int:
    """Refuse a record of ``n_samples`` that would not fit in memory (InputError); return its estimate in bytes."""
    return check_memory(n_samples, _RECORD_COLUMNS)


def check_steer(steer: Any) -> np.ndarray:
    """Return the steer series as a float array (N,), or raise InputError naming the problem."""
    values = np.asarray(steer, dtype=float)
    if values.ndim == 2 and values.shape[1] == 1:
        values = values[:, 0]
    if values.ndim != 1:
        raise InputError(f"steer must be a series of shape (N,) or (N, 1); got shape {values.shape}")
    if values.size < 2:
        raise InputError(f"steer needs at least 2 samples; got {values.size}")
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(f"steer contains a non-finite value (NaN or inf) at sample {bad[0]}")
    worst = int(np.argmax(np.abs(values)))
    if abs(values[worst]) > MAX_STEER:
        raise InputError(
            f"steer of {np.rad2deg(values[worst]):.4g} deg at sample {worst} is beyond the "
            "+/-30 deg road-wheel limit (steer is given in rad)"
        )
    return values


def check_speed_profile(speed: Any, n_samples: int, params: VehicleParameters | None = None) -> np.ndarray:
    """Return a reference speed series (m/s) as a float array (N,), or raise InputError naming the problem.

    The valid range is that of ``params`` (:func:`vehid.vehicle.model.check_speed`)."""
    values = np.asarray(speed, dtype=float)
    if values.ndim == 2 and values.shape[1] == 1:
        values = values[:, 0]
    if values.shape != (n_samples,):
        raise InputError(f"a speed profile needs one reference speed per steer sample ({n_samples}); "
                         f"got shape {values.shape}")
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(f"the speed profile contains a non-finite value (NaN or inf) at sample {bad[0]}")
    for index in (int(np.argmin(values)), int(np.argmax(values))):
        try:
            check_speed(values[index], params)
        except InputError as exc:
            raise InputError(f"the speed profile at sample {index}: {exc}") from None
    return values


def _rk4_step(model: VehicleModel, dt: float, tracking: bool = False) -> ca.Function:
    """One RK4 step from ``x[k]`` under ``u[k+1]``, also returning ``y[k] = h(x[k], u[k])``.

    Outputting ``y[k]`` rather than ``y[k+1]`` lets the tyre forces at ``x[k]``
    (which depend on the state only) serve both the output and the first RK4
    stage: common subexpressions are merged, saving a fifth of the work.
    With ``tracking``, ``p`` is ``(V_ref, dV_ref/dt)`` of the interval and the
    speed hold follows it (:attr:`VehicleModel.tracking_dynamics`).
    """
    x = ca.SX.sym("x", model.n_states)
    u_now = ca.SX.sym("u_now", model.n_u)
    u_next = ca.SX.sym("u_next", model.n_u)
    p = ca.SX.sym("p", 2 if tracking else 1)
    f = model.tracking_dynamics if tracking else model.dynamics
    k1 = f(x, u_next, p)
    k2 = f(x + dt / 2 * k1, u_next, p)
    k3 = f(x + dt / 2 * k2, u_next, p)
    k4 = f(x + dt * k3, u_next, p)
    x_next = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    y_now = model.outputs(x, u_now, p[0])
    return ca.Function(
        "vehicle_rk4_tracking_step" if tracking else "vehicle_rk4_step",
        [x, u_now, u_next, p],
        [x_next, y_now],
        ["x", "u_now", "u_next", "p"],
        ["x_next", "y_now"],
        {"cse": True},
    )


def build_rk4_block(params: VehicleParameters, dt: float = DEFAULT_DT, *, tracking: bool = False) -> ca.Function:
    """The (uncompiled) block simulator: the RK4 step lifted over ``BLOCK_SAMPLES`` with mapaccum.

    ``vehicle_rk4_block(x0 (23,), u_now (1, B), u_next (1, B), p (1, B)) -> (x (23, B), y (10, B))``
    with ``B = BLOCK_SAMPLES``: ``x[:, k]`` is the state after step k, ``y[:, k]``
    the output before it. With ``tracking`` (``vehicle_rk4_tracking_block``),
    ``p`` is ``(2, B)``: reference speed and its rate on each interval.
    """
    step = _rk4_step(build_vehicle_model(params), dt, tracking)
    return step.mapaccum("vehicle_rk4_tracking_block" if tracking else "vehicle_rk4_block", BLOCK_SAMPLES)


def reference_outputs(params: VehicleParameters, steer: np.ndarray, dt: float = DEFAULT_DT, *,
                      speed: float = DEFAULT_SPEED, substeps: int = 16) -> np.ndarray:
    """Outputs (N - 1, 10) of samples 1 ... N - 1 by RK4 with ``substeps`` steps per sample, uncompiled.

    The truth the simulators are measured against: RK4's error falls as the
    fourth power of its step, so 16 substeps leave 1/65 536 of the 500 Hz
    RK4's error (about 1e-11 m/s^2 in lateral acceleration).
    """
    model = build_vehicle_model(params)
    steer = check_steer(steer)
    substep = _rk4_step(model, dt / substeps)
    x, u, p = ca.SX.sym("x", model.n_states), ca.SX.sym("u", model.n_u), ca.SX.sym("p")
    x_next = x
    for _ in range(substeps):
        x_next = substep(x_next, u, u, p)[0]
    sample = ca.Function("vehicle_rk4_reference_step", [x, u, p], [x_next])
    x0 = model.trim(check_speed(speed, params), steer[0])
    states = sample.mapaccum("vehicle_rk4_reference", steer.size - 1)(x0, steer[None, 1:], speed)
    return np.asarray(model.outputs.map(steer.size - 1)(states, steer[None, 1:], speed)).T


@functools.lru_cache(maxsize=16)
def rk4_simulator(params: VehicleParameters, dt: float = DEFAULT_DT, tracking: bool = False) -> ca.Function:
    """Compile :func:`build_rk4_block` to native code, built once and cached in memory and on disk.

    Parameters
    ----------
    params : VehicleParameters
        The vehicle.
    dt : float, default DEFAULT_DT
        The RK4 step and sample interval (s).
    tracking : bool, default False
        Track a speed reference with feed-forward of its rate (else hold a constant speed).

    Returns
    -------
    casadi.Function
        The compiled block of RK4 steps.
    """
    return compile_function(build_rk4_block(params, dt, tracking=tracking), optimisation=COMPILE_FLAGS)


def _run_rk4(params: VehicleParameters, dt: float, x0: np.ndarray, steer: np.ndarray, speed: float,
             monitor=None, reference: np.ndarray | None = None):
    """States x[1:] and outputs y[:-1] of the record (the caller adds x[0] and y[-1]), and the
    first envelope violation found by ``monitor(states, outputs, start)`` after each block (or None);
    the run stops at the block holding it.

    The compiled block writes straight into preallocated NumPy arrays through
    CasADi's function buffer: a column-major ``(n, B)`` block is, byte for byte,
    ``B`` C-ordered rows of a time-major ``(N, n)`` array, so nothing is converted
    or copied. (Converting each block's result to NumPy through CasADi's DM
    instead costs some 40 ms per 30 s record, about as much as the integration.)
    ``reference`` (N, 2), if given, is the speed profile and its rate per sample;
    step k runs under row k + 1, as under steer k + 1.
    """
    simulator = rk4_simulator(params, dt, reference is not None)
    n_steps = steer.size - 1
    n_blocks = -(-n_steps // BLOCK_SAMPLES)
    padded = np.zeros(n_blocks * BLOCK_SAMPLES + 1)
    padded[: steer.size] = steer
    speeds = np.full(BLOCK_SAMPLES, float(speed))
    if reference is not None:
        profile = np.empty((n_blocks * BLOCK_SAMPLES + 1, 2))
        profile[: steer.size] = reference
        profile[steer.size:] = reference[-1]  # padding: steps past the record, never returned
    states = np.empty((n_blocks * BLOCK_SAMPLES, simulator.size1_out(0)))
    outputs = np.empty((n_blocks * BLOCK_SAMPLES, simulator.size1_out(1)))
    buffer, evaluate = simulator.buffer()
    if reference is None:
        buffer.set_arg(3, memoryview(speeds))
    state = np.array(x0, dtype=float)  # a contiguous copy: the first block's initial state
    for start in range(0, n_blocks * BLOCK_SAMPLES, BLOCK_SAMPLES):
        stop = start + BLOCK_SAMPLES
        buffer.set_arg(0, memoryview(state))
        buffer.set_arg(1, memoryview(padded[start:stop]))
        buffer.set_arg(2, memoryview(padded[start + 1:stop + 1]))
        if reference is not None:
            buffer.set_arg(3, memoryview(profile[start + 1:stop + 1]))
        buffer.set_res(0, memoryview(states[start:stop]))
        buffer.set_res(1, memoryview(outputs[start:stop]))
        evaluate()
        if buffer.ret() != 0:
            raise RuntimeError(f"the compiled simulator {simulator.name()} failed (status {buffer.ret()})")
        if monitor is not None:
            violation = monitor(states[start:min(stop, n_steps)], outputs[start:min(stop, n_steps)], start)
            if violation is not None:
                return states[:min(stop, n_steps)], outputs[:min(stop, n_steps)], violation
        state = states[stop - 1].copy()
    return states[:n_steps], outputs[:n_steps], None


@functools.lru_cache(maxsize=8)
def _cvodes_interval(params: VehicleParameters, dt: float, tolerance: float, tracking: bool = False) -> ca.Function:
    """CVODES over one sample interval at constant steer: each call starts afresh (CVodeReInit)."""
    model = build_vehicle_model(params)
    if tracking:
        p = ca.vertcat(model.p, model.reference_acceleration)
        dae = {"x": model.x, "u": model.u, "p": p, "ode": model.tracking_dynamics(model.x, model.u, p)}
    else:
        dae = {"x": model.x, "u": model.u, "p": model.p, "ode": model.xdot}
    options = {"abstol": tolerance, "reltol": tolerance, "max_num_steps": 100000}
    return ca.integrator("vehicle_cvodes", "cvodes", dae, 0.0, dt, options)


def _run_cvodes(params, dt, x0, steer, speed, tolerance=CROSS_CHECK_TOLERANCE, reference=None):
    """States x[1:] and outputs y[1:]: the interval integrator chained over the record by mapaccum."""
    model = build_vehicle_model(params)
    n_steps = steer.size - 1
    interval = _cvodes_interval(params, dt, tolerance, reference is not None)
    chain = interval.mapaccum("vehicle_cvodes_record", n_steps, ["x0"], ["xf"])
    p = speed if reference is None else reference[1:].T
    try:
        states = np.asarray(chain(x0=x0, u=steer[None, 1:], p=p)["xf"])
    except RuntimeError as exc:
        raise SimulationError(f"the CVODES cross-check failed: {str(exc).splitlines()[-1]}") from None
    outputs = np.asarray(model.outputs.map(n_steps)(states, steer[None, 1:], p if reference is None else p[:1]))
    return states.T, outputs.T


def simulate(
    params: VehicleParameters | str = "baseline",
    steer: Any = None,
    dt: float | None = None,
    *,
    speed: Any = None,
    method: str = "rk4",
    meta: dict | None = None,
    t0: float | None = None,
    acceleration: Any = None,
) -> IOData:
    """Simulate the 23-state vehicle from its trim under a road-wheel steer series.

    Parameters
    ----------
    params : VehicleParameters or str
        The vehicle, or a name (``baseline``, ``understeer``, ``saloon``) or TOML/JSON file.
    steer : array_like (N,) or (N, 1), Manoeuvre or IOData
        Steer (rad), positive left: the steering-wheel angle over the steering
        ratio, which is the road-wheel angle of a rigid steering (the
        baseline's; see :mod:`vehid.vehicle.model`). A
        :class:`vehid.vehicle.manoeuvres.Manoeuvre` gives its steer, dt and metadata;
        an IOData its input named ``steer`` (or its only input) and its time base.
    dt : float, optional
        Sample interval (s); default that of the IOData, else 1/500 s.
    speed : float or array_like (N,), optional
        Reference speed of the PI speed hold and of the initial trim (m/s),
        default 20; or a speed profile, one reference per steer sample,
        tracked with feed-forward of its rate (module notes). A manoeuvre with
        its own profile (``Manoeuvre.speed``) takes no ``speed``.
    method : {"rk4", "cvodes"}
        Compiled fixed-step RK4 (one step per sample), or CVODES at tolerance
        1e-12, restarted at every sample, as a cross-check (much slower).
    meta : dict, optional
        Extra metadata to store with the record (manoeuvre, seed, ...).
    t0 : float, optional
        Time of the first sample (s), default 0 (an IOData's own first time).
    acceleration : array_like (N,), optional
        With a speed profile: the longitudinal acceleration the speed hold feeds forward (m/s^2),
        one per sample, in place of the profile's central difference (a measured acceleration,
        which needs no differentiating of a noisy speed).

    Returns
    -------
    IOData
        ``u`` (N, 1) ``steer``; ``y`` (N, 10) ``lateral_acceleration`` (road
        plane, m/s^2), ``yaw_rate`` (rad/s), ``roll_angle`` (rad), ``sideslip``
        (rad), ``speed`` (m/s), ``tyre_load_fl/fr/rl/rr`` (N),
        ``lateral_acceleration_accelerometer`` (m/s^2); ``x`` (N, 23) all
        states; ``meta`` with ``vehicle``, ``speed`` (the initial reference
        under a profile, with ``speed_profile_range`` its least and greatest), ``method``, ``seconds``
        (wall time of the integration alone) and ``cpu_seconds`` (its processor
        time, which waiting for a shared core does not inflate).

    Raises
    ------
    InputError
        Before any work: on non-finite steer, steer beyond +/-30 deg, a speed
        outside the model's valid range (:mod:`vehid.vehicle.validity`), a
        non-positive dt or one too long for RK4 at this speed, or a record
        too large for the memory available.
    SimulationError
        If the states leave the physical envelope of
        :data:`vehid.vehicle.validity.ENVELOPE` (roll, pitch, sideslip, tyre slip,
        speed departure, heave, non-finite or exploding values): the message
        names the quantity, its value and the time; ``partial`` holds the
        record up to that sample (meta ``partial`` and ``stop_reason``).

    Examples
    --------
    A 0.01 rad step of steer at 20 m/s: the yaw rate settles near the linearisation's
    gain (6.27 1/s, :func:`vehid.vehicle.linearize`) times the step, and the lateral
    acceleration at the speed times the yaw rate:

    >>> from vehid.vehicle import make_manoeuvre, simulate
    >>> record = simulate("baseline", make_manoeuvre("step", amplitude=0.01, duration=3.0), speed=20.0)
    >>> record.n_samples, record.u.shape, record.y.shape, record.x.shape
    (1501, (1501, 1), (1501, 10), (1501, 23))
    >>> yaw_rate = float(record.output("yaw_rate")[-1])
    >>> round(yaw_rate / 0.01, 1), round(float(record.output("lateral_acceleration")[-1]) / yaw_rate, 1)
    (6.2, 20.0)
    """
    params = named_vehicle(params)
    start_time = t0
    t0 = 0.0
    extra: dict[str, Any] = {}
    if isinstance(steer, IOData):
        names = steer.input_names
        column = names.index("steer") if "steer" in names else (0 if steer.n_u == 1 else None)
        if column is None:
            raise InputError(f"the record has inputs {', '.join(names)} but none named 'steer'")
        if dt is not None and not math.isclose(float(dt), steer.dt, rel_tol=1e-9):
            raise InputError(f"dt {dt} s contradicts the record's sample interval {steer.dt} s")
        dt, t0 = steer.dt, float(steer.t[0])
        extra = dict(steer.meta)
        steer = steer.u[:, column]
    elif hasattr(steer, "steer") and hasattr(steer, "dt"):  # a vehicle.manoeuvres.Manoeuvre
        if dt is not None and not math.isclose(float(dt), steer.dt, rel_tol=1e-9):
            raise InputError(f"dt {dt} s contradicts the manoeuvre's sample interval {steer.dt} s")
        dt = steer.dt
        extra = dict(steer.meta)
        if getattr(steer, "speed", None) is not None:
            if speed is not None:
                raise InputError(f"the {steer.name} manoeuvre carries its own speed profile: give no speed")
            speed = steer.speed
        steer = steer.steer
    if steer is None:
        raise InputError("give a steer series (rad)")
    if start_time is not None:
        t0 = float(start_time)
        if not math.isfinite(t0):
            raise InputError(f"the start time must be finite; got {start_time}")
    values = check_steer(steer)
    dt = positive_number(DEFAULT_DT if dt is None else dt, "dt", "s")
    reference = None
    if speed is None:
        speed = DEFAULT_SPEED
    if acceleration is not None and not np.ndim(speed):
        raise InputError("an acceleration goes with a speed profile (one speed per sample)")
    if np.ndim(speed):
        profile = check_speed_profile(speed, values.size, params)
        if acceleration is None:
            rate = np.gradient(profile, dt, edge_order=2) if profile.size > 2 else np.gradient(profile, dt)
        else:
            rate = np.asarray(acceleration, dtype=float).ravel()
            if rate.shape != profile.shape or not np.all(np.isfinite(rate)):
                raise InputError(f"the acceleration needs one finite value per sample ({profile.size}); "
                                 f"got {rate.size}" + ("" if rate.shape != profile.shape else " with a non-finite one"))
        reference = np.column_stack([profile, rate])
        speed = float(profile[0])
    speed = check_speed(speed, params)
    if method not in ("rk4", "cvodes"):
        raise InputError(f"unknown simulation method {method!r}; use 'rk4' or 'cvodes'")

    check_record_memory(values.size)

    model = build_vehicle_model(params)
    x0 = model.trim(speed, values[0])
    if method == "rk4":
        state_matrix = np.asarray(linearization_function(model)(x0, values[0], speed)[0])
        check_rk4_step(np.linalg.eigvals(state_matrix), dt, speed)
        if reference is not None and reference[:, 0].max() > speed:
            # the fastest modes (slip lags, -V/sigma) grow with speed: check the step at the top too
            top = float(reference[:, 0].max())
            fastest = np.asarray(linearization_function(model)(model.trim(top), 0.0, top)[0])
            check_rk4_step(np.linalg.eigvals(fastest), dt, top)
        rk4_simulator(params, dt, reference is not None)  # build and compile outside the timed section

    def target(first: int, count: int) -> float | np.ndarray:
        return speed if reference is None else reference[first:first + count, 0]

    def monitor(state_block: np.ndarray, output_block: np.ndarray, first_step: int) -> Violation | None:
        # Step k (from 0) ends at sample k + 1; the output beside it belongs to sample k.
        return first_violation(state_block, model.state_names, output_block, model.output_names,
                               target(first_step, output_block.shape[0]),
                               state_offset=first_step + 1, output_offset=first_step)

    start, cpu_start = time.perf_counter(), time.process_time()
    if method == "rk4":
        states, outputs, violation = _run_rk4(params, dt, x0, values, speed, monitor, reference)
    else:
        states, outputs = _run_cvodes(params, dt, x0, values, speed, reference=reference)
        # States and outputs both of samples 1 ... N - 1 here.
        violation = first_violation(states, model.state_names, outputs, model.output_names,
                                    target(1, outputs.shape[0]), state_offset=1, output_offset=1)
    seconds = time.perf_counter() - start
    cpu_seconds = time.process_time() - cpu_start
    states = np.vstack([x0, states])
    if method == "rk4":
        last = np.asarray(model.outputs(states[-1], values[states.shape[0] - 1], speed)).ravel()
        outputs = np.vstack([outputs, last])
        if violation is None:  # the last output is the one the blocks did not see
            violation = monitor(states[:0], outputs[-1:], states.shape[0] - 1)
    else:
        first = np.asarray(model.outputs(x0, values[0], speed)).ravel()
        outputs = np.vstack([first, outputs])
    record_meta = {
        **extra,
        **(meta or {}),
        "vehicle": params.name,
        "speed": speed,
        **({} if reference is None else {"speed_profile_range": [float(reference[:, 0].min()),
                                                                 float(reference[:, 0].max())]}),
        "method": method,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "source": "vehicle.simulate (23-state full-vehicle model)",
    }

    def record(n_samples: int, extra_meta: dict) -> IOData:
        return IOData(
            t=t0 + dt * np.arange(n_samples),
            u=values[:n_samples, None],
            y=outputs[:n_samples],
            x=states[:n_samples],
            input_names=model.input_names,
            output_names=model.output_names,
            state_names=model.state_names,
            input_units=model.input_units,
            output_units=model.output_units,
            state_units=model.state_units,
            meta={**record_meta, **extra_meta},
        )

    if violation is not None:
        message = violation.message(t0, dt)
        kept = violation.sample + 1
        if not (np.all(np.isfinite(states[violation.sample])) and np.all(np.isfinite(outputs[violation.sample]))):
            kept -= 1  # a record holds finite values only: it ends just before
        partial = record(kept, {"partial": True, "stop_reason": message}) if kept >= 2 else None
        raise SimulationError(message, partial, quantity=violation.quantity, value=violation.value,
                              time=t0 + violation.sample * dt)
    return record(values.size, {})
