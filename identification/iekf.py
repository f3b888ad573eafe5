"""The Identifying Extended Kalman Filter (Best & Bogdanski 2017, sections 2-4).

The parameters of a modal state-space model join its states in the filter's
state vector (eq. 7-8); the filter passes over the record again and again
("rinsing"): at the start of each pass the true states are reset to zero and
the parameters and the covariance ``P`` are carried over. After each pass the
parameters are frozen, the model is simulated from rest over the record and
scored by the percentage explanation R (eq. 17).

Tuning (section 3): ``Q = p I'`` with ``I'`` the identity with zeros for the
true states (the fixed C entries are not in the state at all), ``R = I``
unless given, ``P0 = Q``.

Start values. The paper starts every sigma at -1 (omega likewise). Measured
on the three-output, eq. 18 case of the linear example (exact
discretisation, 30 passes, seeds 0-4): that start found all five
eigenvalues within 2 % on 1 of 5 seeds, while faster oscillatory start modes
(sigma = -10, omega = 10, the pairs' omegas spread apart so that the filter
does not start symmetric in them) found them on 5 of 5, by pass 4 or 5. The
workbench's default start is therefore ``sigma = -10, omega = 10 (1 + 0.5 i)``
for pair i; the paper's start is ``start="paper"``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .data import IOData
from .errors import DivergenceError, ExcitationError, InputError
from .filter_models import LinearModalFilterModel, check_discretization
from .iekf_pass import COVARIANCE_FORMS, compiled_pass, pack_covariance, unpack_covariance
from .metrics import percentage_explanation
from .modal import ModalModel, ModalStructure
from .uncertainty import iekf_parameter_covariance

__all__ = [
    "IEKFOptions",
    "PassRecord",
    "IEKFResult",
    "FilterState",
    "identify_iekf",
    "START_VALUES",
]

#: Named start values: (sigma, omega, omega spread between pairs).
START_VALUES = {
    "default": (-10.0, 10.0, 0.5),
    "paper": (-1.0, 1.0, 0.0),
}


def check_filter_options(p: Any, passes: Any, discretization: str, covariance: str) -> None:
    """The checks every IEKF's options share: a positive p, a whole number of passes, known forms."""
    if not (isinstance(p, (int, float)) and math.isfinite(p) and p > 0):
        raise InputError(f"the tuning parameter p must be a positive number; got {p!r}")
    if isinstance(passes, bool) or int(passes) != passes or passes < 1:
        raise InputError(f"passes must be a whole number >= 1; got {passes!r}")
    check_discretization(discretization)
    if covariance not in COVARIANCE_FORMS:
        raise InputError(f"unknown covariance form {covariance!r}; use one of {', '.join(COVARIANCE_FORMS)}")


@dataclass(frozen=True)
class IEKFOptions:
    """Settings of an IEKF identification.

    Parameters
    ----------
    p : float
        The tuning parameter: ``Q = p I'`` and ``P0 = Q`` (paper: 1 for the linear example).
    passes : int
        The largest number of passes over the record.
    discretization : {"exact", "euler", "exact-zoh"}
        ``exact`` (first-order hold) converges to the true continuous model;
        ``euler`` is the paper's and converges to its Euler equivalent.
    covariance : {"joseph", "paper"}
        Covariance numerics (see :mod:`identification.iekf_pass`).
    measurement_noise : float or None
        ``R = measurement_noise * I`` in (normalised) output units; default 1 (the paper's R = I).
    start : {"default", "paper"}
        Start values of sigma/omega, see :data:`START_VALUES`.
    normalize : bool
        Scale each input and output by its RMS before filtering (the model is
        returned in the original units, with its fixed C entries still 1).
    parameter_tolerance, trace_tolerance : float
        Stop early when, from one pass to the next, the largest relative
        parameter change and the relative change of trace(P) are both below these.
    min_passes : int
        Never stop early before this many passes.
    """

    p: float = 1.0
    passes: int = 50
    discretization: str = "exact"
    covariance: str = "joseph"
    measurement_noise: float | None = None
    start: str = "default"
    normalize: bool = False
    parameter_tolerance: float = 1e-6
    trace_tolerance: float = 1e-4
    min_passes: int = 2

    def __post_init__(self) -> None:
        check_filter_options(self.p, self.passes, self.discretization, self.covariance)
        if self.measurement_noise is not None and not (math.isfinite(self.measurement_noise) and self.measurement_noise > 0):
            raise InputError(f"measurement_noise must be positive; got {self.measurement_noise!r}")
        if self.start not in START_VALUES:
            raise InputError(f"unknown start {self.start!r}; use one of {', '.join(START_VALUES)}")

    @property
    def simulation_method(self) -> str:
        """How the frozen model is simulated to score it "with the filter's discretisation"."""
        return {"euler": "euler", "exact": "foh", "exact-zoh": "zoh"}[self.discretization]


@dataclass(frozen=True, eq=False)
class PassRecord:
    """What one pass left: parameters (original units), fits, and the covariance's state.

    ``fit_filter``: R per output of the frozen model simulated with the
    filter's own discretisation; ``fit_continuous``: R per output of the
    continuous model simulated exactly (inputs linear between samples);
    ``nis``: the pass's mean normalised innovation squared ``e' R^-1 e``
    (n_y for innovations as large as the filter assumes; NaN where unknown).
    """

    index: int
    parameters: np.ndarray
    fit_filter: np.ndarray
    fit_continuous: np.ndarray
    trace_p: float
    min_eig_p: float
    seconds: float
    nis: float = float("nan")

    @property
    def mean_fit_filter(self) -> float:
        return float(np.mean(self.fit_filter))

    @property
    def mean_fit_continuous(self) -> float:
        return float(np.mean(self.fit_continuous))


@dataclass(frozen=True, eq=False)
class FilterState:
    """The filter's state between passes, in normalised units: parameters and P (what a resume needs)."""

    theta: np.ndarray
    P: np.ndarray
    input_scale: np.ndarray
    output_scale: np.ndarray


@dataclass(frozen=True, eq=False)
class IEKFResult:
    """An IEKF identification: the final model, one record per pass, and the filter state.

    ``stop_reason`` is ``"converged"``, ``"passes"`` (the pass limit) or
    ``"diverged: ..."`` (only on the result carried by a DivergenceError).
    """

    model: ModalModel
    structure: ModalStructure
    options: IEKFOptions
    history: tuple[PassRecord, ...]
    state: FilterState
    dt: float
    stop_reason: str
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def passes_run(self) -> int:
        return len(self.history)

    @property
    def fit_percent(self) -> np.ndarray:
        """R per output of the final continuous model simulated exactly."""
        return self.history[-1].fit_continuous

    def parameter_history(self) -> np.ndarray:
        """Parameters after each pass, shape (passes, n_theta)."""
        return np.array([record.parameters for record in self.history])


def _check_data(data: IOData, structure: ModalStructure) -> None:
    if data.n_u != structure.n_u or data.n_y != structure.n_y:
        raise InputError(
            f"the structure has {structure.n_u} inputs and {structure.n_y} outputs; "
            f"the data have {data.n_u} and {data.n_y}"
        )
    if data.n_samples <= structure.n_parameters:
        raise InputError(
            f"{data.n_samples} samples cannot identify {structure.n_parameters} parameters: "
            "give more data or a lower order"
        )
    spread = data.u.std(axis=0)
    for name, value in zip(data.input_names, spread):
        if not value > 1e-12 * max(1.0, float(np.abs(data.u).max())):
            raise ExcitationError(f"input {name!r} is constant: nothing is excited, the model cannot be identified")
    energy = np.sum(data.y**2, axis=0)
    for name, value in zip(data.output_names, energy):
        if value == 0:
            raise ExcitationError(f"output {name!r} is identically zero: nothing to identify")


def _scales(data: IOData, normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    if not normalize:
        return np.ones(data.n_u), np.ones(data.n_y)
    return np.sqrt(np.mean(data.u**2, axis=0)), np.sqrt(np.mean(data.y**2, axis=0))


def denormalize(structure: ModalStructure, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
    """Parameters in original units from those identified on scaled data.

    With ``u = Su u_n`` and ``y = Sy y_n`` and the state basis rescaled by the
    scale of the output each state is tied to, ``A`` is unchanged, the fixed
    C entries stay 1, ``B -> S B Su^-1``, ``C -> Sy C S^-1``, ``D -> Sy D Su^-1``.
    """
    A, B, C, D = structure.matrices(theta)
    state_scale = np.array([output_scale[structure.output_of_state(j)] for j in range(structure.n)])
    B = state_scale[:, None] * B / input_scale[None, :]
    C = output_scale[:, None] * C / state_scale[None, :]
    D = output_scale[:, None] * D / input_scale[None, :]
    return structure.pack(A, B, C, D)


def normalize_parameters(structure: ModalStructure, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
    """Inverse of :func:`denormalize`."""
    return denormalize(structure, theta, 1.0 / input_scale, 1.0 / output_scale)


def identify_iekf(
    data: IOData,
    structure: ModalStructure,
    *,
    options: IEKFOptions | None = None,
    initial_model: ModalModel | None = None,
    resume: IEKFResult | None = None,
    on_pass: Callable[[PassRecord, "IEKFResult"], None] | None = None,
) -> IEKFResult:
    """Identify a linear modal model with the IEKF.

    Parameters
    ----------
    data : IOData
        The record; ``u`` (N, n_u), ``y`` (N, n_y), uniform ``dt``.
    structure : ModalStructure
        Order, modes and fixed C entries.
    options : IEKFOptions, optional
    initial_model : ModalModel, optional
        Start from these parameters instead of the named start values.
    resume : IEKFResult, optional
        Continue a previous run on the same data: its parameters, P and
        history are carried on, and ``options.passes`` counts all passes. A
        run whose last two passes already meet the stop rule returns at once,
        converged, as the uninterrupted run would have.
    on_pass : callable, optional
        Called after every pass with the new record and the result so far
        (for progress displays and checkpoints).

    Returns
    -------
    IEKFResult

    Raises
    ------
    InputError, ExcitationError
        Bad data: wrong sizes, fewer samples than parameters, a constant input.
    DivergenceError
        Non-finite values, a covariance that lost positive definiteness beyond
        repair, or an unstable model; its ``last_good`` is the result up to
        the last good pass.
    """
    options = options or IEKFOptions()
    _check_data(data, structure)
    started = time.perf_counter()
    dt = data.dt
    n, m_theta = structure.n, structure.n_parameters
    m = n + m_theta

    if resume is not None:
        if resume.structure != structure:
            raise InputError("the run to resume has a different model structure")
        if not math.isclose(resume.dt, dt, rel_tol=1e-9):
            raise InputError(f"the run to resume used dt = {resume.dt} s; these data have {dt} s")
        input_scale, output_scale = resume.state.input_scale, resume.state.output_scale
        theta = resume.state.theta.copy()
        P = resume.state.P.copy()
        history = list(resume.history)
    else:
        input_scale, output_scale = _scales(data, options.normalize)
        if initial_model is not None:
            if initial_model.structure != structure:
                raise InputError("the initial model has a different structure")
            theta = normalize_parameters(structure, initial_model.parameters, input_scale, output_scale)
        else:
            sigma, omega, spread = START_VALUES[options.start]
            theta = structure.initial_parameters(sigma=sigma, omega=omega, omega_spread=spread)
        P = None
        history = []

    q = np.concatenate([np.zeros(n), np.full(m_theta, options.p)])
    if P is None:
        P = np.diag(q)
    r = np.eye(structure.n_y) * (1.0 if options.measurement_noise is None else options.measurement_noise)
    u_scaled = data.u / input_scale
    y_scaled = data.y / output_scale
    run_pass = compiled_pass(LinearModalFilterModel(structure), dt, options.discretization, options.covariance)

    def result(stop_reason: str) -> IEKFResult:
        last = history[-1].parameters if history else denormalize(structure, theta, input_scale, output_scale)
        covariance = None
        if history and np.isfinite(history[-1].nis):
            covariance = iekf_parameter_covariance(
                structure, P[n:, n:], input_scale, output_scale, history[-1].nis / structure.n_y)
        return IEKFResult(
            model=ModalModel.from_parameters(
                structure, last, input_names=data.input_names, output_names=data.output_names,
                meta={"estimator": "iekf", "discretization": options.discretization, "passes": len(history)},
                parameter_covariance=covariance,
            ),
            structure=structure,
            options=options,
            history=tuple(history),
            state=FilterState(theta.copy(), P.copy(), input_scale.copy(), output_scale.copy()),
            dt=dt,
            stop_reason=stop_reason,
            seconds=time.perf_counter() - started,
        )

    if len(history) >= max(2, options.min_passes) and _settled(history[-2], history[-1], options):
        return result("converged")  # a resumed run had met its stop rule (perhaps killed before it said so)
    stop_reason = "passes"
    while len(history) < options.passes:
        pass_index = len(history) + 1
        pass_start = time.perf_counter()
        state = np.concatenate([np.zeros(n), theta, pack_covariance(P)])
        try:
            state, innovations = run_pass(state, u_scaled, y_scaled, q, r)
        except DivergenceError as exc:
            raise DivergenceError(
                f"pass {pass_index}: {exc}", last_good=result(f"diverged at pass {pass_index}") if history else None
            ) from exc
        new_theta = state[n:m]
        new_P = unpack_covariance(state[m:], m)
        if not (np.all(np.isfinite(state)) and np.all(np.isfinite(innovations))):
            bad = np.flatnonzero(~np.all(np.isfinite(innovations), axis=1))
            where = f" from t = {data.t[bad[0]]:.3f} s" if bad.size else ""
            raise DivergenceError(
                f"pass {pass_index}: the filter produced non-finite values{where} "
                f"(try a lower p, the joseph covariance form, or a lower order)",
                last_good=result(f"diverged at pass {pass_index}") if history else None,
            )
        min_eig = float(np.linalg.eigvalsh(new_P)[0])
        trace = float(np.trace(new_P))
        if options.covariance != "paper" and min_eig < -1e-9 * max(trace, 1.0):
            raise DivergenceError(
                f"pass {pass_index}: the covariance P lost positive definiteness "
                f"(smallest eigenvalue {min_eig:.3g}, trace {trace:.3g})",
                last_good=result(f"diverged at pass {pass_index}") if history else None,
            )
        theta_original = denormalize(structure, new_theta, input_scale, output_scale)
        model = ModalModel.from_parameters(structure, theta_original)
        if not model.is_stable():
            raise DivergenceError(
                f"pass {pass_index}: the identified model is unstable "
                f"(eigenvalues {np.round(model.eigenvalues(), 4).tolist()})",
                last_good=result(f"diverged at pass {pass_index}") if history else None,
            )
        y_filter = model.simulate(data.u, dt, method=options.simulation_method)
        y_exact = y_filter if options.simulation_method == "foh" else model.simulate(data.u, dt, method="foh")
        previous = history[-1] if history else None
        record = PassRecord(
            index=pass_index,
            parameters=theta_original,
            fit_filter=percentage_explanation(data.y, y_filter),
            fit_continuous=percentage_explanation(data.y, y_exact),
            trace_p=trace,
            min_eig_p=min_eig,
            seconds=time.perf_counter() - pass_start,
            nis=float(np.mean(np.sum(innovations * np.linalg.solve(r, innovations.T).T, axis=1))),
        )
        theta, P = new_theta, new_P
        history.append(record)
        if on_pass is not None:
            on_pass(record, result("running"))
        if previous is not None and len(history) >= options.min_passes and _settled(previous, record, options):
            stop_reason = "converged"
            break
    return result(stop_reason)


def _settled(previous: PassRecord, record: PassRecord, options: IEKFOptions) -> bool:
    scale = np.maximum(np.abs(record.parameters), 1e-3)
    parameter_change = float(np.max(np.abs(record.parameters - previous.parameters) / scale))
    trace_change = abs(record.trace_p - previous.trace_p) / max(abs(previous.trace_p), 1e-300)
    return parameter_change < options.parameter_tolerance and trace_change < options.trace_tolerance
