"""Simulate the full-vehicle model: compiled fixed-step RK4 lifted over time, with a CVODES cross-check.

The fixed-step path takes one classical Runge-Kutta step per sample. The step
is a CasADi function lifted over a block of samples with ``mapaccum``,
generated to C and compiled once per (vehicle, dt) with
:func:`identification.compiled.compile_function` (cached on disk), so that
no Python runs per time step: a record is a handful of calls, one per block.

At 20 m/s the fastest modes sit near 190 rad/s, so RK4 at 500 Hz
(lambda dt = 0.38) is accurate to about 1e-4 of the outputs; the ``cvodes``
method (BDF, relative tolerance 1e-10) is the reference to check it against.

Timing convention: ``u[k]`` is held on the interval that ends at ``t[k]``, so
``x[k] = step(x[k-1], u[k])``; the record starts at the exact trim of the
first steer sample (zero in every manoeuvre of :mod:`vehicle.manoeuvres`).
"""

from __future__ import annotations

import functools
import math
import time
from typing import Any

import casadi as ca
import numpy as np

from identification.compiled import compile_function
from identification.data import IOData
from identification.errors import DivergenceError, InputError

from .model import DEFAULT_SPEED, MAX_STEER, VehicleModel, build_vehicle_model, check_speed, positive_number
from .parameters import VehicleParameters, named_vehicle

__all__ = [
    "simulate",
    "rk4_simulator",
    "build_rk4_block",
    "COMPILE_FLAGS",
    "DEFAULT_DT",
    "BLOCK_SAMPLES",
    "check_steer",
]

DEFAULT_DT = 1.0 / 500.0  # [s] the paper's output rate
BLOCK_SAMPLES = 1000  # samples per compiled call; any record length runs as whole blocks plus padding
COMPILE_FLAGS = "-O1"  # the generated step is large; -O1 compiles much faster than -O2 at similar speed


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


def _rk4_step(model: VehicleModel, dt: float) -> ca.Function:
    """One RK4 step from ``x[k]`` under ``u[k+1]``, also returning ``y[k] = h(x[k], u[k])``.

    Outputting ``y[k]`` rather than ``y[k+1]`` lets the tyre forces at ``x[k]``
    (which depend on the state only) serve both the output and the first RK4
    stage: common subexpressions are merged, saving a fifth of the work.
    """
    x = ca.SX.sym("x", model.n_x)
    u_now = ca.SX.sym("u_now", model.n_u)
    u_next = ca.SX.sym("u_next", model.n_u)
    p = ca.SX.sym("p", 1)
    f = model.dynamics
    k1 = f(x, u_next, p)
    k2 = f(x + dt / 2 * k1, u_next, p)
    k3 = f(x + dt / 2 * k2, u_next, p)
    k4 = f(x + dt * k3, u_next, p)
    x_next = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    y_now = model.outputs(x, u_now, p)
    return ca.Function(
        "vehicle_rk4_step",
        [x, u_now, u_next, p],
        [x_next, y_now],
        ["x", "u_now", "u_next", "p"],
        ["x_next", "y_now"],
        {"cse": True},
    )


def build_rk4_block(params: VehicleParameters, dt: float = DEFAULT_DT) -> ca.Function:
    """The (uncompiled) block simulator: the RK4 step lifted over ``BLOCK_SAMPLES`` with mapaccum.

    ``vehicle_rk4_block(x0 (23,), u_now (1, B), u_next (1, B), p (1, B)) -> (x (23, B), y (10, B))``
    with ``B = BLOCK_SAMPLES``: ``x[:, k]`` is the state after step k, ``y[:, k]``
    the output before it.
    """
    step = _rk4_step(build_vehicle_model(params), dt)
    return step.mapaccum("vehicle_rk4_block", BLOCK_SAMPLES)


@functools.lru_cache(maxsize=16)
def rk4_simulator(params: VehicleParameters, dt: float = DEFAULT_DT) -> ca.Function:
    """:func:`build_rk4_block` compiled to native code (built once, cached in memory and on disk)."""
    return compile_function(build_rk4_block(params, dt), optimisation=COMPILE_FLAGS)


def _run_rk4(params: VehicleParameters, dt: float, x0: np.ndarray, steer: np.ndarray, speed: float):
    """States x[1:] and outputs y[:-1] of the record (the caller adds x[0] and y[-1]).

    The compiled block writes straight into preallocated NumPy arrays through
    CasADi's function buffer: a column-major ``(n, B)`` block is, byte for byte,
    ``B`` C-ordered rows of a time-major ``(N, n)`` array, so nothing is converted
    or copied. (Converting each block's result to NumPy through CasADi's DM
    instead costs some 40 ms per 30 s record, about as much as the integration.)
    """
    simulator = rk4_simulator(params, dt)
    n_steps = steer.size - 1
    n_blocks = -(-n_steps // BLOCK_SAMPLES)
    padded = np.zeros(n_blocks * BLOCK_SAMPLES + 1)
    padded[: steer.size] = steer
    speeds = np.full(BLOCK_SAMPLES, float(speed))
    states = np.empty((n_blocks * BLOCK_SAMPLES, simulator.size1_out(0)))
    outputs = np.empty((n_blocks * BLOCK_SAMPLES, simulator.size1_out(1)))
    buffer, evaluate = simulator.buffer()
    buffer.set_arg(3, memoryview(speeds))
    state = np.array(x0, dtype=float)  # a contiguous copy: the first block's initial state
    for start in range(0, n_blocks * BLOCK_SAMPLES, BLOCK_SAMPLES):
        stop = start + BLOCK_SAMPLES
        buffer.set_arg(0, memoryview(state))
        buffer.set_arg(1, memoryview(padded[start:stop]))
        buffer.set_arg(2, memoryview(padded[start + 1:stop + 1]))
        buffer.set_res(0, memoryview(states[start:stop]))
        buffer.set_res(1, memoryview(outputs[start:stop]))
        evaluate()
        if buffer.ret() != 0:
            raise RuntimeError(f"the compiled simulator {simulator.name()} failed (status {buffer.ret()})")
        state = states[stop - 1].copy()
    return states[:n_steps], outputs[:n_steps]


@functools.lru_cache(maxsize=8)
def _cvodes_integrator(params: VehicleParameters, dt: float, n_steps: int, tolerance: float) -> ca.Function:
    model = build_vehicle_model(params)
    dae = {"x": model.x, "u": model.u, "p": model.p, "ode": model.xdot}
    grid = [dt * (k + 1) for k in range(n_steps)]
    options = {"abstol": tolerance, "reltol": tolerance, "max_num_steps": 100000}
    return ca.integrator("vehicle_cvodes", "cvodes", dae, 0.0, grid, options)


def _run_cvodes(params, dt, x0, steer, speed, tolerance=1e-10):
    model = build_vehicle_model(params)
    n_steps = steer.size - 1
    integrator = _cvodes_integrator(params, dt, n_steps, tolerance)
    result = integrator(x0=x0, u=steer[None, 1:], p=speed)
    states = np.asarray(result["xf"])
    outputs = np.asarray(model.outputs.map(n_steps)(states, steer[None, 1:], speed))
    return states.T, outputs.T


def simulate(
    params: VehicleParameters | str = "baseline",
    steer: Any = None,
    dt: float | None = None,
    *,
    speed: float = DEFAULT_SPEED,
    method: str = "rk4",
    meta: dict | None = None,
) -> IOData:
    """Simulate the 23-state vehicle from its trim under a road-wheel steer series.

    Parameters
    ----------
    params : VehicleParameters or str
        The vehicle, or a name (``baseline``, ``understeer``) or TOML/JSON file.
    steer : array_like (N,) or (N, 1), Manoeuvre or IOData
        Road-wheel steer angle (rad), positive left. A
        :class:`vehicle.manoeuvres.Manoeuvre` gives its steer, dt and metadata;
        an IOData its input named ``steer`` (or its only input) and its time base.
    dt : float, optional
        Sample interval (s); default that of the IOData, else 1/500 s.
    speed : float
        Reference speed of the PI speed hold and of the initial trim (m/s).
    method : {"rk4", "cvodes"}
        Compiled fixed-step RK4 (one step per sample), or CVODES at relative
        tolerance 1e-10 as a cross-check (much slower).
    meta : dict, optional
        Extra metadata to store with the record (manoeuvre, seed, ...).

    Returns
    -------
    IOData
        ``u`` (N, 1) ``steer``; ``y`` (N, 10) ``lateral_acceleration`` (road
        plane, m/s^2), ``yaw_rate`` (rad/s), ``roll_angle`` (rad), ``sideslip``
        (rad), ``speed`` (m/s), ``tyre_load_fl/fr/rl/rr`` (N),
        ``lateral_acceleration_accelerometer`` (m/s^2); ``x`` (N, 23) all
        states; ``meta`` with ``vehicle``, ``speed``, ``method``, ``seconds``
        (wall time of the integration alone) and ``cpu_seconds`` (its processor
        time, which waiting for a shared core does not inflate).

    Raises
    ------
    InputError
        On non-finite steer, steer beyond +/-30 deg, a non-positive speed or dt.
    DivergenceError
        If the simulation produced non-finite values.
    """
    params = named_vehicle(params)
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
        steer = steer.steer
    if steer is None:
        raise InputError("give a steer series (rad)")
    values = check_steer(steer)
    dt = positive_number(DEFAULT_DT if dt is None else dt, "dt", "s")
    speed = check_speed(speed)
    if method not in ("rk4", "cvodes"):
        raise InputError(f"unknown simulation method {method!r}; use 'rk4' or 'cvodes'")

    model = build_vehicle_model(params)
    x0 = model.trim(speed, values[0])
    if method == "rk4":
        rk4_simulator(params, dt)  # build and compile outside the timed section
    start, cpu_start = time.perf_counter(), time.process_time()
    if method == "rk4":
        states, outputs = _run_rk4(params, dt, x0, values, speed)
    else:
        states, outputs = _run_cvodes(params, dt, x0, values, speed)
    seconds = time.perf_counter() - start
    cpu_seconds = time.process_time() - cpu_start
    states = np.vstack([x0, states])
    if method == "rk4":
        last = np.asarray(model.outputs(states[-1], values[-1], speed)).ravel()
        outputs = np.vstack([outputs, last])
    else:
        first = np.asarray(model.outputs(x0, values[0], speed)).ravel()
        outputs = np.vstack([first, outputs])
    if not (np.all(np.isfinite(states)) and np.all(np.isfinite(outputs))):
        first = int(np.argmax(~np.all(np.isfinite(states), axis=1)))
        raise DivergenceError(
            f"the vehicle simulation diverged at t = {t0 + first * dt:.3f} s (non-finite states)"
        )
    record_meta = {
        **extra,
        **(meta or {}),
        "vehicle": params.name,
        "speed": speed,
        "method": method,
        "seconds": seconds,
        "cpu_seconds": cpu_seconds,
        "source": "vehicle.simulate (23-state full-vehicle model)",
    }
    return IOData(
        t=t0 + dt * np.arange(values.size),
        u=values[:, None],
        y=outputs,
        x=states,
        input_names=model.input_names,
        output_names=model.output_names,
        state_names=model.state_names,
        input_units=model.input_units,
        output_units=model.output_units,
        state_units=model.state_units,
        meta=record_meta,
    )
