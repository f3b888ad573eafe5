"""Every identified model class meets one protocol (vehid.identification.models.protocol), checked by behaviour.

Each class is built to stand for a known continuous system whose
eigenvalues are written down by hand (two complex pairs and a real pole, one
input, two outputs; an unstable twin with a pair at +0.8 +/- 6j): directly
(modal, continuous), through its spline form, as a speed-scheduled family whose
middle knot is the system, taken at that speed (scheduled; its other knots a
slower system), as a grey-box model whose system matrix scales with its
schedule and is the system at one value, through the exact first-order-hold
discretisation (discrete, ARX polynomials, singular pencil) or by an
estimator on noise-free samples (subspace). The single-track car stands for
the textbook bicycle at 20 m/s (its matrices written out by hand; an
oversteering twin above its critical speed), both as the identified model
scheduled on speed and as its linearisation at one speed. Independent truth:

* simulations: ``scipy.signal.lsim`` (continuous; inputs linear between
  samples, as the models assume) and ``scipy.signal.dlsim`` (discrete), from
  a non-zero initial state, and the continuous system's own samples for every
  discrete form;
* eigenvalues and modes: the hand-written values, ``z = exp(lambda dt)`` for
  discrete forms, and at another schedule value those of the system there;
  ``is_stable``: the sign of their real parts and whether the free response
  dies out;
* frequency responses: ``scipy.signal.freqresp``/``dfreqresp``; a discrete
  response's periodicity in ``1/dt`` and its symmetry about the Nyquist
  frequency, and its agreement with the continuous one well below it;
* exports: the matrices read back from JSON, MATLAB and CasADi (a nonlinear
  model's CasADi function linearised at rest gives its frequency response);
  the archive round trip reproducing the simulation to 1e-12.

:func:`check_protocol` holds all of these, and the signatures against the
protocol's (``inspect.signature``); models broken on purpose, of every kind,
show that each check can fail.
"""

import dataclasses
import functools
import importlib.util
import json
import math
import subprocess
import sys
import warnings

import casadi as ca
import h5py
import numpy as np
import pytest
import scipy.signal
from scipy.io import loadmat
from scipy.signal import BadCoefficients, dfreqresp, freqresp

from vehid.identification import (ArxModel, DiscreteModel, GreyBoxModel, IdentifiedGreyBox, IdentifiedModel, IOData,
                                  ModalModel, ModalStructure, Mode, SplineModalModel, TimeResponse, estimate_subspace,
                                  identify_with, nrmse_fit, percentage_explanation, read_archive, read_value,
                                  signature_mismatches, write_value)
from vehid.identification.models.discrete import ContinuousModel
from vehid.identification.errors import InputError
from vehid.identification.classical.pencil import PencilModel
from vehid.identification.models.protocol import statespace_response
from vehid.identification.models.scheduled import ScheduledModalModel
from vehid.identification.models.scheduled_gauge import gauge_parameters, input_gauge
from vehid.identification.models.statespace import continuous_to_discrete, hold_state_shift
from vehid.vehicle.single_track import MIN_SPEED, IdentifiedSingleTrack, SingleTrackAtSpeed, SingleTrackConfig

DT = 0.01
# The hand-written systems: (pairs sigma, omega), real poles.
STABLE = ((-1.5, 6.0), (-4.0, 20.0)), (-3.0,)
UNSTABLE = ((0.8, 6.0), (-4.0, 20.0)), (-3.0,)
# Rounding of exact discretisations and eigen-decompositions carried over 400 samples of an O(1) response.
ALGEBRA = 1e-9
# PO-MOESP on noise-free samples recovers the system to rounding of its SVD and least squares; measured
# spreads are ~1e-10 in eigenvalues and simulations, this bound is 100 times that.
SUBSPACE = 1e-8
# An archive stores arrays bit for bit: the round trip may differ by rounding of the rebuild only.
ROUND_TRIP = 1e-12
# Classical Runge-Kutta against the exact hold: its global error is of order (h |lambda|)^4 / 5! of the
# response; h |lambda| = 0.08 for the bicycle at 20 m/s (7.8 1/s, one step per sample), 0.05 for the grey-box
# system (20.4 1/s, four steps per sample), some 3e-7 and 6e-8. Measured: at most 6e-7 and 5e-8 of the largest output.
RUNGE_KUTTA = 1e-5
# The schedule value at which the scheduled kinds are the written system, and another where they are not.
SCHEDULE, ELSEWHERE = 20.0, 10.0
GREYBOX_SUBSTEPS = 4

# The single-track car (Pacejka 2012, chapter 1): mass (kg), CG to axles (m), a steering-wheel input at ratio 15.
CAR = SingleTrackConfig(mass=1500.0, cg_to_front_axle=1.2, cg_to_rear_axle=1.5, steering_ratio=15.0)
# C_f, C_r (N/rad), I_z (kg m^2): understeering, and oversteering with a critical speed of 18 m/s.
UNDERSTEER, OVERSTEER = (80_000.0, 100_000.0, 2500.0), (100_000.0, 40_000.0, 2500.0)


def _knot_parameters(model: ModalModel) -> np.ndarray:
    """One knot of a scheduled family holding ``model``: its modes in the input gauge, output offsets zero."""
    structure = model.structure
    A, B, C = input_gauge(model, list(range(len(structure.mode_states()))))
    modal = np.array([A[s[0], s[0]] if k == 0 else abs(A[s[0], s[1]])
                      for s in structure.mode_states() for k in range(len(s))])
    return np.concatenate([gauge_parameters(modal, B, C, model.D), np.zeros(structure.n_y)])


def _hand_written(system) -> np.ndarray:
    pairs, real = system
    values = [complex(s, w) for s, w in pairs] + [complex(s, -w) for s, w in pairs] + [complex(s, 0) for s in real]
    return np.array(values)


def _scaled(system, factor: float):
    pairs, real = system
    return tuple((factor * s, factor * w) for s, w in pairs), tuple(factor * r for r in real)


def _modal(system) -> ModalModel:
    """The hand-written modes with B, C and D entries drawn once (seeded)."""
    pairs, real = system
    structure = ModalStructure.with_modes(len(pairs), len(real), 1, 2)
    theta = np.random.default_rng(0).uniform(-2.0, 2.0, structure.n_parameters)
    theta[: structure.n] = [value for pair in pairs for value in pair] + list(real)
    return ModalModel.from_parameters(structure, theta)


def _bicycle(speed: float, c_f: float, c_r: float, yaw_inertia: float, ratio: float) -> tuple:
    """The textbook bicycle (states v_y, r; outputs r, a_y = dv_y/dt + V r) per steer angle over ``ratio``.

    ``V`` is the model's stated speed ``sqrt(v^2 + MIN_SPEED^2)`` (1.25e-5 above 20 m/s), its floor at standstill.
    """
    m, lf, lr = CAR.mass, CAR.cg_to_front_axle, CAR.cg_to_rear_axle
    speed = math.hypot(speed, MIN_SPEED)
    A = np.array([[-(c_f + c_r) / (m * speed), (lr * c_r - lf * c_f) / (m * speed) - speed],
                  [(lr * c_r - lf * c_f) / (yaw_inertia * speed), -(lf**2 * c_f + lr**2 * c_r) / (yaw_inertia * speed)]])
    B = np.array([[c_f / m], [lf * c_f / yaw_inertia]]) / ratio
    C = np.array([[0.0, 1.0], A[0] + [0.0, speed]])
    D = np.array([[0.0], B[0]])
    return A, B, C, D


def _greybox(system) -> IdentifiedGreyBox:
    """The modal system as a grey-box model whose system matrix is ``s / SCHEDULE`` times its own."""
    modal = _modal(system)
    structure = modal.structure
    x, u, theta, s = (ca.SX.sym(name, size) for name, size in (("x", 5), ("u", 1), ("theta", structure.n_parameters),
                                                              ("s", 1)))
    A, B, C, D = structure.matrices(theta, backend=ca.SX)
    count = structure.n_parameters
    model = GreyBoxModel(ca.Function("f", [x, u, theta, s], [s / SCHEDULE * ca.mtimes(A, x) + ca.mtimes(B, u)]),
                         ca.Function("h", [x, u, theta, s], [ca.mtimes(C, x) + ca.mtimes(D, u)]),
                         structure.parameter_names(), ("-",) * count, (False,) * count, tuple(f"x{i}" for i in range(5)),
                         ("u",), ("s",), ("y1", "y2"))
    return IdentifiedGreyBox(model, modal.parameters, substeps=GREYBOX_SUBSTEPS,
                             schedule_range=[[ELSEWHERE, 3 * ELSEWHERE]])


def _record(n: int = 400, seed: int = 1) -> IOData:
    t = np.arange(n) * DT
    u = np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sign(np.sin(2 * np.pi * 0.4 * t))
    noise = 0.3 * np.random.default_rng(seed).standard_normal(n)  # rich enough for a subspace fit of order 5
    noise[0] = 0.0  # u(0) = 0: a hold equivalent at rest is then its continuous system at rest
    u = u + noise
    return IOData(t=t, u=u[:, None], y=np.zeros((n, 2)))


@dataclasses.dataclass(frozen=True)
class Truth:
    """What a model stands for: the continuous system, its eigenvalues, its time domain (and schedule)."""

    continuous: tuple  # (A, B, C, D) of the continuous system whose outputs the model reproduces
    eigenvalues: np.ndarray  # continuous-time, hand-written (or of hand-written matrices)
    dt: float | None  # the model's sample interval, None if continuous
    outputs: tuple[int, ...]  # the continuous system's outputs the model has
    tolerance: float  # of eigenvalues, state-space forms and responses
    simulation: float | None = None  # of simulations against scipy's (default: tolerance)
    schedule: float | None = None  # the schedule value at which a scheduled model is the system
    elsewhere: tuple[float, np.ndarray] | None = None  # another schedule value, and the eigenvalues there

    @property
    def stable(self) -> bool:
        return bool(np.all(self.eigenvalues.real < 0))

    @property
    def at(self) -> dict:
        """The keyword that evaluates the model at its schedule value (none for an unscheduled model)."""
        return {} if self.schedule is None else {"schedule": self.schedule}

    def along(self, samples: int) -> dict:
        """The keyword of a simulation along the constant schedule value."""
        return {} if self.schedule is None else {"schedule": np.full(samples, self.schedule)}


def _build(kind: str, system) -> tuple[object, Truth]:
    stable = system is STABLE
    if kind.startswith("single-track"):
        parameters = UNDERSTEER if stable else OVERSTEER
        continuous = _bicycle(SCHEDULE, *parameters, 1.0 if kind == "single-track-at-speed" else CAR.steering_ratio)
        values = np.linalg.eigvals(continuous[0])
        if kind == "single-track-at-speed":  # linear at one speed, the road-wheel angle its input
            return SingleTrackAtSpeed(CAR, np.array(parameters), None, SCHEDULE), Truth(continuous, values, None, (0, 1),
                                                                                        ALGEBRA)
        model = IdentifiedSingleTrack(CAR, parameters, None, (ELSEWHERE, 3 * ELSEWHERE))
        there = np.linalg.eigvals(_bicycle(ELSEWHERE, *parameters, CAR.steering_ratio)[0])
        return model, Truth(continuous, values, None, (0, 1), ALGEBRA, RUNGE_KUTTA, SCHEDULE, (ELSEWHERE, there))

    modal = _modal(system)
    continuous = (modal.A, modal.B, modal.C, modal.D)
    values = _hand_written(system)
    Ad, Bd, Cd, Dd = continuous_to_discrete(*continuous, DT, hold="foh")

    def truth(dt, outputs=(0, 1), tolerance=ALGEBRA, **scheduled):
        return Truth(continuous, values, dt, outputs, tolerance, **scheduled)

    if kind == "modal":
        return modal, truth(None)
    if kind == "spline-modal":  # scales away from 1, so that a slip in the normalisation shows
        return SplineModalModel.from_linear(modal, 5, np.array([2.0]), np.array([0.5, 3.0]), DT), truth(None)
    if kind == "scheduled":  # a family on three speeds whose middle knot is the system, the others 0.7 times it
        slower = _modal(_scaled(system, 0.7))
        grid = np.array([ELSEWHERE, SCHEDULE, 3 * ELSEWHERE])
        theta = np.concatenate([_knot_parameters(slower), _knot_parameters(modal), _knot_parameters(slower)])
        family = ScheduledModalModel.from_parameters(modal.structure, grid, theta)
        return family, truth(None, schedule=SCHEDULE, elsewhere=(ELSEWHERE, 0.7 * values))
    if kind == "grey-box":  # its system matrix scales with the schedule: the system at SCHEDULE, half of it at 10
        return _greybox(system), truth(None, simulation=RUNGE_KUTTA, schedule=SCHEDULE,
                                       elsewhere=(ELSEWHERE, ELSEWHERE / SCHEDULE * values))
    if kind == "continuous":  # the same system in another state basis
        T = np.random.default_rng(2).uniform(-1.0, 1.0, (5, 5)) + 3 * np.eye(5)
        Ti = np.linalg.inv(T)
        return ContinuousModel(T @ modal.A @ Ti, T @ modal.B, modal.C @ Ti, modal.D), truth(None)
    if kind == "discrete":
        return DiscreteModel(Ad, Bd, Cd, Dd, DT), truth(DT)
    if kind == "arx":  # output 1 as polynomials: A(q) = det(I - q^-1 Ad)
        numerator, denominator = scipy.signal.ss2tf(Ad, Bd, Cd[[0]], Dd[[0]])
        model = ArxModel(denominator.reshape(-1, 1, 1), numerator.reshape(-1, 1, 1), DT)
        return model, truth(DT, outputs=(0,), tolerance=1e-7)  # polynomial coefficients lose ~1e-9 in the roots
    if kind == "pencil":
        return PencilModel.from_state_space(Ad, Bd, Cd, Dd, dt=DT), truth(DT)
    if kind == "subspace":
        record = _record(2000)
        x0 = np.zeros(5)
        y = DiscreteModel(Ad, Bd, Cd, Dd, DT).simulate_outputs(record.u, x0=x0)
        return estimate_subspace(record.replace(y=y), order=5), truth(DT, tolerance=SUBSPACE)
    raise ValueError(kind)


MODEL_KINDS = ("modal", "spline-modal", "scheduled", "grey-box", "continuous", "discrete", "arx", "pencil", "subspace",
               "single-track", "single-track-at-speed")


@functools.cache
def _model(kind: str, stable: bool) -> tuple[object, Truth]:
    return _build(kind, STABLE if stable else UNSTABLE)


def _reference_outputs(statespace: tuple, u: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """scipy's simulation of a state-space form from x0: lsim (continuous) or dlsim (discrete)."""
    A, B, C, D, dt = statespace
    t = np.arange(u.shape[0]) * DT
    if dt is None:
        _, y, _ = scipy.signal.lsim((A, B, C, D), u, t, X0=x0, interp=True)
    else:
        _, y, _ = scipy.signal.dlsim((A, B, C, D, dt), u, t=t, x0=x0)
    return np.asarray(y).reshape(u.shape[0], C.shape[0])


def _continuous_eigenvalues(model, at: dict) -> np.ndarray:
    values, dt = np.asarray(model.eigenvalues(**at), dtype=complex), model.to_statespace(**at)[4]
    return values if dt is None else np.log(values) / dt


def _same_values(got: np.ndarray, expected: np.ndarray, tolerance: float, what: str) -> None:
    assert len(got) == len(expected), f"{what}: {len(got)} eigenvalues, expected {len(expected)}"
    for value in expected:  # each expected value has a match (multiset comparison of distinct values)
        assert np.min(np.abs(got - value)) <= tolerance * max(1.0, abs(value)), f"{what}: {value} missing from {got}"


def _record_for(model, truth: Truth, record: IOData) -> IOData:
    """The record as the model takes it: a scheduled model's holds the schedule as its last input column."""
    if truth.schedule is None:
        return record
    return record.replace(u=np.column_stack([record.u, np.full(record.n_samples, truth.schedule)]), input_names=None,
                          input_units=None)


def _linearised_response(function, truth: Truth, n: int, n_u: int, f_hz: np.ndarray) -> np.ndarray:
    """The frequency response of a continuous CasADi model ``(x, u[, s]) -> (xdot, y)`` linearised at rest."""
    x, u = ca.SX.sym("x", n), ca.SX.sym("u", n_u)
    rates, outputs = function(x, u, *([truth.schedule] if function.n_in() == 3 else []))
    jacobians = ca.Function("at_rest", [x, u], [ca.jacobian(rates, x), ca.jacobian(rates, u), ca.jacobian(outputs, x),
                                                ca.jacobian(outputs, u)])
    A, B, C, D = (np.asarray(m, dtype=float) for m in jacobians(np.zeros(n), np.zeros(n_u)))
    return statespace_response((A, B, C, D, None), f_hz).response


def check_protocol(model, truth: Truth, tmp_path) -> None:
    """Every method of the protocol against independent truth; AssertionError naming the first that fails."""
    assert isinstance(model, IdentifiedModel), "protocol: a method or attribute is missing"
    assert signature_mismatches(model) == (), f"signature: {signature_mismatches(model)}"
    assert model.is_scheduled is (truth.schedule is not None), "is_scheduled"
    at = truth.at
    if truth.schedule is not None:  # a scheduled model holds at a schedule value: it does not guess one
        for method in (model.eigenvalues, model.modes, model.to_statespace):
            with pytest.raises(InputError, match="schedule"):
                method()
    n, n_y = truth.eigenvalues.size, len(truth.outputs)
    A, B, C, D, dt = model.to_statespace(**at)
    assert (model.n_states, model.n_u, model.n_y) == (n, 1, n_y), "sizes: n_states, n_u, n_y"
    assert A.shape == (n, n) and B.shape == (n, 1) and C.shape == (n_y, n) and D.shape == (n_y, 1), "to_statespace"
    assert dt == truth.dt, "to_statespace: the time domain"

    _same_values(_continuous_eigenvalues(model, at), truth.eigenvalues, truth.tolerance, "eigenvalues")
    if truth.elsewhere is not None:
        value, there = truth.elsewhere
        _same_values(_continuous_eigenvalues(model, {"schedule": value}), there, truth.tolerance, "eigenvalues elsewhere")
    modes = model.modes(**at)
    written = [value for value in truth.eigenvalues if value.imag >= 0]
    assert len(modes) == len(written), "modes: one per pair and per real pole"
    for mode in modes:
        value = written[int(np.argmin([abs(mode.eigenvalue - w) for w in written]))]
        assert abs(mode.frequency_hz - abs(value) / (2 * np.pi)) <= truth.tolerance * abs(value), "modes: frequency"
        assert abs(mode.damping + value.real / abs(value)) <= truth.tolerance * abs(value), "modes: damping"

    # a scheduled model's stability at every value: each scheduled kind keeps the sign of its real parts throughout
    assert model.is_stable(**at) is truth.stable and model.is_stable() is truth.stable, \
        "is_stable disagrees with the eigenvalues"

    record = _record()
    simulation = truth.simulation or truth.tolerance
    x0 = np.random.default_rng(3).uniform(-1.0, 1.0, n)
    y = model.simulate_outputs(record.u, record.dt, x0=x0, **truth.along(record.n_samples))
    reference = _reference_outputs((A, B, C, D, dt), record.u, x0)
    scale = np.max(np.abs(reference))
    np.testing.assert_allclose(y, reference, rtol=0, atol=simulation * scale,
                               err_msg="simulate_outputs from x0 against scipy")
    # 10 s: e^-15 or e^+8 of the slowest written mode; the oversteering car's pole at +0.47 1/s grows e^4
    free = model.simulate_outputs(np.zeros((1000, 1)), DT, x0=np.ones(n), **truth.along(1000))
    early, late = np.max(np.abs(free[:100])), np.max(np.abs(free[-100:]))
    assert (late < 1e-3 * early) if truth.stable else (late > 10 * early), "is_stable disagrees with the free response"
    # from rest every form gives the continuous system's samples (the discrete forms are its exact equivalents)
    Ac, Bc, Cc, Dc = truth.continuous
    _, samples, _ = scipy.signal.lsim((Ac, Bc, Cc, Dc), record.u, record.t, interp=True)
    samples = samples[:, list(truth.outputs)]
    np.testing.assert_allclose(model.simulate_outputs(record.u, record.dt, **truth.along(record.n_samples)), samples,
                               rtol=0, atol=simulation * np.max(np.abs(samples)),
                               err_msg="simulate_outputs from rest against the continuous system")
    driving = _record_for(model, truth, record)
    simulated = model.simulate(driving)
    assert isinstance(simulated, TimeResponse), "simulate returns a TimeResponse"
    np.testing.assert_array_equal(simulated.u, driving.u, err_msg="simulate keeps the inputs")
    np.testing.assert_array_equal(simulated.y, model.simulate_outputs(driving.u, driving.dt), err_msg="simulate")

    f_hz = np.array([0.05, 0.3, 1.0, 3.2, 10.0, 31.0])
    response = model.frequency_response(f_hz, **at)
    assert response.shape == (f_hz.size, n_y, 1), "frequency response: shape (n_f, n_y, n_u)"
    np.testing.assert_array_equal(response.frequencies_hz, f_hz, err_msg="frequency response: its frequencies")
    for output in range(n_y):
        system = (A, B, C[[output]], D[[output]])
        with warnings.catch_warnings():  # an output without feed-through has a numerator led by zero, which scipy trims
            warnings.simplefilter("ignore", BadCoefficients)
            _, expected = freqresp(system, w=2 * np.pi * f_hz) if dt is None else \
                dfreqresp((*system, dt), w=2 * np.pi * f_hz * dt)
        # scipy goes through transfer-function polynomials, which lose ~1e-10 relative here
        np.testing.assert_allclose(response[:, output, 0], expected, rtol=1e-7,
                                   err_msg="frequency response against scipy")
    if dt is not None:
        np.testing.assert_allclose(model.frequency_response(f_hz + 1 / dt, **at), response, rtol=1e-9,
                                   err_msg="frequency response: a discrete one repeats every 1/dt")
        np.testing.assert_allclose(model.frequency_response(1 / dt - f_hz, **at), np.conj(response), rtol=1e-9,
                                   err_msg="frequency response: a discrete one mirrors about the Nyquist frequency")
    low = f_hz[f_hz * DT <= 0.01]  # far below 1/dt the hold equivalent's response is the continuous one's
    s = 2j * np.pi * low
    exact = np.array([Cc @ np.linalg.solve(p * np.eye(n) - Ac, Bc) + Dc for p in s])[:, list(truth.outputs)]
    # a first-order hold's equivalent departs by O((2 pi f dt)^2) of the response: ~4e-3 at f dt = 0.01
    bound = (2 * np.pi * low * DT) ** 2 * np.max(np.abs(exact)) + truth.tolerance
    assert np.all(np.abs(np.asarray(model.frequency_response(low, **at)) - exact) <= bound[:, None, None]), \
        "frequency response: away from the continuous system's well below 1/dt"

    data = json.loads(model.save_json(tmp_path / "model.json").read_text())
    assert data["time_domain"] == ("continuous" if dt is None else "discrete"), "save_json: the time domain"
    # a nonlinear model's own dt is the interval it runs at; its state-space form is a continuous linearisation
    assert data["dt"] == dt or not model.is_linear, "save_json: dt"
    # the JSON holds the state-space form, or (a spline model) what rebuilds the model: at least one
    assert all(name in data for name in "ABCD") or hasattr(model, "from_dict"), "save_json: no model in the JSON"
    if all(name in data for name in "ABCD"):
        for name, matrix in zip("ABCD", (A, B, C, D)):
            np.testing.assert_array_equal(np.array(data[name]), matrix, err_msg=f"save_json: {name}")
    if hasattr(model, "from_dict"):
        rebuilt = type(model).from_dict(data)
        np.testing.assert_allclose(rebuilt.simulate_outputs(record.u, record.dt, x0=x0, **truth.along(record.n_samples)),
                                   y, rtol=0, atol=ROUND_TRIP * np.max(np.abs(y)), err_msg="save_json: the rebuilt model")
    mat = loadmat(model.save_mat(tmp_path / "model.mat"))
    if truth.schedule is None:
        for name, matrix in zip("ABCD", (A, B, C, D)):
            np.testing.assert_array_equal(mat[name], matrix, err_msg=f"save_mat: {name}")
    else:  # each grid value's state-space form, grid value first
        for k, value in enumerate(np.ravel(mat["grid"])):
            for name, matrix in zip("ABCD", model.to_statespace(schedule=float(value))):
                np.testing.assert_array_equal(mat[name][k], matrix, err_msg=f"save_mat: {name} at {value:g}")
    assert ("Ts" in mat) == (dt is not None) or not model.is_linear, "save_mat: Ts of a discrete model"

    function = model.to_casadi()
    if model.is_linear:  # (x, u) -> (dx/dt or x(k+1), y) of the state-space form
        x, u = np.random.default_rng(4).standard_normal(n), np.array([0.7])
        step, output = (np.asarray(value).ravel() for value in function(x, u))
        np.testing.assert_allclose(step, A @ x + B @ u, rtol=1e-12, atol=1e-12, err_msg="to_casadi: state equation")
        np.testing.assert_allclose(output, C @ x + D @ u, rtol=1e-12, atol=1e-12, err_msg="to_casadi: the output")
    elif function.name_out()[0] in ("xdot", "x_dot"):  # continuous (x, u[, s]) -> (xdot, y), in its own state basis
        np.testing.assert_allclose(_linearised_response(function, truth, n, 1, f_hz), response, rtol=1e-9,
                                   err_msg="to_casadi: its linearisation at rest against the frequency response")
    else:  # a nonlinear model's own step (x, u(k), u(k+1)) -> (x(k+1), y(k)): two steps give its first outputs
        state, outputs = x0, []
        for k in range(2):
            state, output = (np.asarray(value).ravel() for value in function(state, record.u[k], record.u[k + 1]))
            outputs.append(output)
        np.testing.assert_allclose(outputs, y[:2], rtol=1e-9, atol=1e-12, err_msg="to_casadi: the model's step")
    if importlib.util.find_spec("control") is None:
        with pytest.raises(ImportError, match="python-control"):
            model.to_control(**at)
    else:
        assert model.to_control(**at).nstates == n, "to_control"

    with h5py.File(tmp_path / "model.h5", "w") as handle:
        write_value(handle, "model", model)
    with h5py.File(tmp_path / "model.h5", "r") as handle:
        back = read_value(handle, "model")
    assert type(back) is type(model), "archive: the class"
    np.testing.assert_allclose(back.simulate_outputs(record.u, record.dt, x0=x0, **truth.along(record.n_samples)), y,
                               rtol=0, atol=ROUND_TRIP * np.max(np.abs(y)), err_msg="archive: the simulation")
    np.testing.assert_allclose(back.frequency_response(f_hz, **at), response, rtol=ROUND_TRIP,
                               err_msg="archive: response")


# every class stable and unstable; the subspace model only stable (fitting an unstable system's samples tests
# the estimator, not the protocol, and the other classes carry the unstable case)
CASES = [(kind, stable) for kind in MODEL_KINDS for stable in (True, False) if stable or kind != "subspace"]


@pytest.mark.parametrize("kind, stable", CASES, ids=[f"{k}-{'stable' if s else 'unstable'}" for k, s in CASES])
def test_every_model_class_meets_the_protocol(kind, stable, tmp_path):
    model, truth = _model(kind, stable)
    check_protocol(model, truth, tmp_path)


# Broken on purpose, one of each kind: each defect is one a model class could have, and one check names it.

@dataclasses.dataclass(frozen=True, eq=False)
class _ResponseAtS(DiscreteModel):
    """Evaluates a discrete model's response at s = j 2 pi f, ignoring dt (the defect of a plot helper)."""

    def frequency_response(self, f_hz, *, schedule=None):
        return ContinuousModel(self.A, self.B, self.C, self.D).frequency_response(f_hz)


@dataclasses.dataclass(frozen=True, eq=False)
class _IgnoresStart(DiscreteModel):
    def simulate_outputs(self, u, dt=None, *, x0=None, schedule=None):
        return super().simulate_outputs(u, dt)


@dataclasses.dataclass(frozen=True, eq=False)
class _AlwaysStable(DiscreteModel):
    def is_stable(self, *, schedule=None):
        return True


@dataclasses.dataclass(frozen=True, eq=False)
class _NeedsSampleInterval(DiscreteModel):
    """The signature scheduled models had: ``dt`` required, no ``schedule``."""

    def simulate_outputs(self, u, dt, *, x0=None):
        return super().simulate_outputs(u, dt, x0=x0)


@dataclasses.dataclass(frozen=True, eq=False)
class _CanonicalForm(ScheduledModalModel):
    """States the canonical form of ``model_at`` while its simulation runs in the input gauge."""

    def to_statespace(self, *, schedule=None):
        self.linear_at(schedule)  # the schedule checked as the class checks it
        return self.model_at(schedule).to_statespace()


@dataclasses.dataclass(frozen=True, eq=False)
class _FirstKnot(ScheduledModalModel):
    """Describes the family by its first knot at every schedule value."""

    def linear_at(self, schedule):
        if schedule is None:
            raise InputError("give schedule=")
        return super().linear_at(float(self.grid[0]))


@dataclasses.dataclass(frozen=True, eq=False)
class _LinearisedAtOneValue(IdentifiedGreyBox):
    """Linearises the grey-box model at a fixed schedule value, whatever it is asked for."""

    def to_statespace(self, *, schedule=None):
        self._schedule_point(schedule)
        return super().to_statespace(schedule=SCHEDULE)


@dataclasses.dataclass(frozen=True, eq=False)
class _PerRoadWheel(IdentifiedSingleTrack):
    """States the handling linearisation (per road-wheel angle) as the model's, whose input is the steer channel."""

    def to_statespace(self, *, schedule=None):
        super().to_statespace(schedule=schedule)  # the schedule checked as the class checks it
        return self.model_at(schedule).to_statespace()


def _broken(kind: str, cls: type, stable: bool):
    model, truth = _model(kind, stable)
    values = {item.name: getattr(model, item.name) for item in dataclasses.fields(model) if item.init}
    return cls(**values), truth


@pytest.mark.parametrize("kind, broken, stable, defect", [
    ("discrete", _ResponseAtS, True, "frequency response"),
    ("discrete", _IgnoresStart, True, "from x0"),
    ("discrete", _AlwaysStable, False, "is_stable"),
    ("discrete", _NeedsSampleInterval, True, "signature"),
    ("scheduled", _CanonicalForm, True, "from x0"),
    ("scheduled", _FirstKnot, True, "eigenvalues"),
    ("grey-box", _LinearisedAtOneValue, True, "eigenvalues elsewhere"),
    ("single-track", _PerRoadWheel, True, "from x0"),
], ids=lambda value: value.__name__.strip("_") if isinstance(value, type) else None)
def test_the_protocol_check_catches_a_broken_model(kind, broken, stable, defect, tmp_path):
    model, truth = _broken(kind, broken, stable)
    with pytest.raises(AssertionError, match=defect):
        check_protocol(model, truth, tmp_path)


def test_a_model_without_a_schedule_is_the_same_at_every_value():
    """An unscheduled model takes a schedule value or a schedule and is unchanged; a bad one is named."""
    model, _ = _model("modal", True)
    record = _record()
    np.testing.assert_array_equal(model.eigenvalues(schedule=12.5), model.eigenvalues())
    np.testing.assert_array_equal(model.simulate_outputs(record.u, DT, schedule=np.full(record.n_samples, 3.0)),
                                  model.simulate_outputs(record.u, DT))
    with pytest.raises(InputError, match="schedule must be one finite value"):
        model.to_statespace(schedule=np.nan)
    with pytest.raises(InputError, match="schedule must be 400 finite values"):
        model.simulate_outputs(record.u, DT, schedule=np.ones(3))


def test_a_scheduled_simulation_takes_the_schedule_as_a_keyword_or_a_last_column():
    family, truth = _model("scheduled", True)
    record = _record()
    along = np.linspace(ELSEWHERE, 3 * ELSEWHERE, record.n_samples)  # through every knot
    apart = family.simulate_outputs(record.u, DT, schedule=along)
    np.testing.assert_array_equal(family.simulate_outputs(np.column_stack([record.u, along]), DT), apart)
    assert family.n_u == 1 and family.record_inputs == 2
    with pytest.raises(InputError, match="sample interval dt"):
        family.simulate_outputs(record.u, schedule=along)


def test_modes_follow_the_closed_form_in_hertz():
    assert Mode.of(complex(2.0, 0.0)).damping == -1.0  # an unstable real pole
    assert Mode.of(complex(-1.0, -3.0)) == Mode.of(complex(-1.0, 3.0))  # a pair is one mode
    mode = Mode.of(complex(-3.0, 4.0))
    assert mode.frequency_hz == pytest.approx(5.0 / (2 * np.pi), rel=1e-15) and mode.damping == pytest.approx(0.6)


def test_a_continuous_model_needs_a_sample_interval_and_a_discrete_one_its_own():
    record = _record()
    for kind in ("modal", "continuous"):
        with pytest.raises(InputError, match="sample interval dt"):
            _model(kind, True)[0].simulate_outputs(record.u)
    with pytest.raises(InputError, match="dt = 0.01"):
        _model("discrete", True)[0].simulate_outputs(record.u, 0.02)
    with pytest.raises(InputError, match="x0 must hold 5"):
        _model("discrete", True)[0].simulate_outputs(record.u, x0=np.ones(4))


def test_a_hold_equivalent_starts_from_the_continuous_state():
    """x0 of the continuous system is x0 - G2 u(0) in its first-order-hold equivalent (exact)."""
    modal, truth = _model("modal", True)
    record = _record()
    x0 = np.array([0.3, -0.2, 0.5, 0.1, -0.4])
    discrete = DiscreteModel(*continuous_to_discrete(modal.A, modal.B, modal.C, modal.D, DT), DT)
    shifted = x0 - hold_state_shift(modal.A, modal.B, DT) @ record.u[0]
    np.testing.assert_allclose(discrete.simulate_outputs(record.u, x0=shifted),
                               modal.simulate_outputs(record.u, DT, x0=x0), rtol=0, atol=ALGEBRA)


def test_discrete_forms_without_a_sample_interval_say_so():
    with pytest.raises(InputError, match="no sample interval"):
        ArxModel(np.array([1.0, -0.5]).reshape(2, 1, 1), np.ones((2, 1, 1))).modes()


def _alternating_record(n: int = 600) -> IOData:
    """y(k) = -0.6 y(k-1) + u(k-1): a pole on the negative real axis, which no continuous-time model has."""
    u = np.random.default_rng(5).standard_normal(n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = -0.6 * y[k - 1] + u[k - 1]
    return IOData(t=np.arange(n) * DT, u=u[:, None], y=y[:, None], input_names=("u",), output_names=("y",))


def test_an_arx_fit_without_a_continuous_equivalent_is_a_protocol_model():
    data = _alternating_record()
    model = identify_with(data, method="arx", order=1).model
    assert isinstance(model, DiscreteModel) and isinstance(model, IdentifiedModel)
    # noise-free ARX data: least squares recovers the pole to rounding
    assert model.eigenvalues()[0] == pytest.approx(-0.6, abs=1e-9) and model.is_stable() and model.n_states == 1
    np.testing.assert_allclose(model.simulate_outputs(data.u, data.dt), data.y, rtol=0, atol=1e-9)


def test_the_identify_command_archives_a_discrete_model_and_reads_it_back(tmp_path):
    data = _alternating_record()
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack([data.t, data.u, data.y]), delimiter=",", header="t,u,y", comments="")
    out = tmp_path / "arx.h5"
    completed = subprocess.run([sys.executable, "-m", "vehid.scenarios.cli", "identify", str(path), "--inputs", "u",
                                "--outputs", "y", "--method", "arx", "--order", "1", "--out", str(out), "--json"],
                               capture_output=True, text=True, check=False)
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    archive = read_archive(out)
    run = archive.runs["arx"]
    assert isinstance(run.model, DiscreteModel) and archive.config["order"] == 1
    np.testing.assert_array_equal(run.model.A, summary["A"])  # the model the summary reports
    for name in "BCD":
        np.testing.assert_array_equal(getattr(run.model, name), summary[name])
    record = next(iter(archive.records.values()))
    # the archived model on the archived (prepared) record scores what the summary says, to rounding
    simulated = run.model.simulate(record).y
    np.testing.assert_allclose(percentage_explanation(record.y, simulated), summary["R"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(nrmse_fit(record.y, simulated), summary["fit_percent"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.metrics.percentage_explanation, summary["R"], rtol=0, atol=1e-12)


def test_the_uncertainty_band_is_centred_on_the_model_s_own_response():
    """The delta-method band (its own CasADi expression, for Jacobians) is centred on the protocol's response."""
    model = _model("modal", True)[0]
    f_hz = np.array([0.1, 0.95, 3.2, 12.0])
    band = model.frequency_response_band(f_hz)
    response = model.frequency_response(f_hz)
    np.testing.assert_allclose(band.magnitude, np.abs(response), rtol=1e-12)
    np.testing.assert_allclose(np.radians(band.phase_deg), np.unwrap(np.angle(response), axis=0), rtol=0, atol=1e-12)
