"""The handling study of Best & Bogdanski 2017, section 6 (Table 5).

The full-vehicle model (:mod:`vehicle`, 23 states, 20 m/s) is driven by the
``identification`` steer input (band-limited noise plus a sweep, to about 90 %
of the grip limit) and, for validation, by the ``validation`` input. Outputs:
lateral acceleration, yaw rate and roll angle; 500 Hz, 30 s each. For each
model order a linear modal model is identified by the IEKF, then a
spline-nonlinear one started from it (paper section 5, eq. 20-22). Every
model is simulated from rest over both records and scored by the mean R
(eq. 17) over the outputs; the identified linear modes are set beside the
vehicle's own linearisation.

No trim is removed: the records start at the straight-running trim, where all
three outputs are zero, which is the models' rest state too. The order is
chosen by :func:`vehid.identification.assessment.order.assess_orders` on the linear runs.

What to expect (paper, Table 5): R rises with the order and the nonlinear
model beats the linear one. The measured results are in docs/measurements.md, the
measurements behind the settings in ``docs/study_measurements.md``.
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, NamedTuple

import numpy as np

from vehid.identification.dataio.archive import RunName, append_history, run_group, write_archive, write_record, write_run
from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
from vehid.identification.data import IOData
from vehid.identification.errors import DivergenceError, InputError
from vehid.identification.filtering.iekf import IEKFOptions, IEKFResult, identify_iekf
from vehid.identification.dataio.iekf_archive import write_iekf_run
from vehid.identification.jsonable import to_jsonable
from vehid.identification.optionspec import renamed_options
from vehid.identification.filtering.spline_iekf import SplineIEKFOptions, identify_spline_iekf
from vehid.identification.assessment.metrics import percentage_explanation
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.models.protocol import Mode as ModelMode
from vehid.identification.assessment.order import AssessedOrder, OrderAssessment, assess_orders
from vehid.identification.dataio.storage import write_value
from vehid.vehicle import DEFAULT_DT, linearize, make_manoeuvre, named_vehicle, simulate
from vehid.vehicle.linearize import VehicleMode

from .paths import results_path
from .study_settings import (HANDLING_AMPLITUDE_SCALE, HANDLING_DURATION, HANDLING_ORDERS, HANDLING_SEED,
                             HANDLING_SPEED, HANDLING_VEHICLE, STUDY_LINEAR_P, STUDY_LINEAR_PASSES)
from .shutdown import run_in_workers


__all__ = [
    "OUTPUTS",
    "COMPARED_MODES",
    "PAPER",
    "HandlingConfig",
    "study_linear_options",
    "spline_options",
    "check_orders",
    "positive_number",
    "whole_number",
    "RecordArrays",
    "OrderJob",
    "OrderOutcome",
    "SplineStudyRun",
    "TableRow",
    "LinearRun",
    "NonlinearRun",
    "ModeComparison",
    "HandlingResult",
    "compare_modes",
    "percent_text",
    "parse_orders",
    "planned_passes",
    "make_records",
    "SENSOR_NOISE",
    "with_sensor_noise",
    "identify_order",
    "run_order",
    "run_study",
    "archive_path",
    "start_archive",
    "write_order",
    "write_archive_for",
    "write_study_archive",
    "main",
]


OUTPUTS = ("lateral_acceleration", "yaw_rate", "roll_angle")
COMPARED_MODES = ("yaw-sideslip", "roll")
MIN_ORDER, MAX_ORDER = 2, 8  # a handling model needs one oscillatory mode; above 8 the spline filter grows unwieldy
MIN_DURATION = 5.0  # [s] the validation input's steps need a few seconds per half
MODE_AMPLITUDES = np.linspace(0.0, 1.0, 11)  # normalised state amplitude for the nonlinear mode curves (Figure 8)

#: Best & Bogdanski 2017, Table 5: mean R over the three outputs in percent (printed as the digits after 99.).
PAPER: dict[int, dict[str, Any]] = {
    2: {"linear_eigenvalues": "-2.3 ± 1.7j", "linear_identification_R": 99.60, "nonlinear_identification_R": 99.73,
        "linear_validation_R": 99.29, "nonlinear_validation_R": 99.56},
    3: {"linear_eigenvalues": "-9.3, -3.3 ± 2.5j", "linear_identification_R": 99.72, "nonlinear_identification_R": 99.92,
        "linear_validation_R": 99.19, "nonlinear_validation_R": 99.59},
    4: {"linear_eigenvalues": "-2.4 ± 2.5j, -13.0 ± 9.3j", "linear_identification_R": 99.79,
        "nonlinear_identification_R": 99.96, "linear_validation_R": 99.37, "nonlinear_validation_R": 99.80},
    5: {"linear_eigenvalues": "-5.3 ± 5.4j, -12.1 ± 8.7j, -4.9", "linear_identification_R": 99.81,
        "nonlinear_identification_R": 99.98, "linear_validation_R": 99.35, "nonlinear_validation_R": 99.53},
    6: {"linear_eigenvalues": "-2.5 ± 2.5j, -3.7 ± 10.0j, -20.7 ± 10.2j", "linear_identification_R": 99.82,
        "nonlinear_identification_R": 99.99, "linear_validation_R": 99.40, "nonlinear_validation_R": 99.88},
}


def planned_passes(config: "HandlingConfig") -> int:
    """The most passes the study can run in all, linear and nonlinear (for progress displays)."""
    spline = config.spline_options
    return (config.linear_options.passes + (0 if spline is None else spline.passes)) * len(config.orders)


def parse_orders(text: str) -> tuple[int, ...]:
    """Model orders from ``"2-6"``, ``"4"`` or ``"2,4-6"``: increasing, each within 2..8.

    Examples
    --------
    >>> parse_orders("2-4,6")
    (2, 3, 4, 6)
    """
    orders: list[int] = []
    for part in str(text).split(","):
        match = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not match:
            raise InputError(f"orders must look like 2-6, 4 or 2,4-6; got {text!r}")
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) else first
        if last < first:
            raise InputError(f"the order range {part.strip()} runs backwards; write {last}-{first}")
        orders.extend(range(first, last + 1))
    return check_orders(orders)


def check_orders(orders: Any) -> tuple[int, ...]:
    """``orders`` as a tuple of whole numbers from 2 to 8, increasing without repeats (else InputError)."""
    values = tuple(orders)
    if not values:
        raise InputError("give at least one model order")
    for value in values:
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not MIN_ORDER <= value <= MAX_ORDER:
            raise InputError(f"model orders must be whole numbers from {MIN_ORDER} to {MAX_ORDER}; got {value!r}")
    if list(values) != sorted(set(values)):
        raise InputError(f"model orders must increase without repeats; got {list(values)}")
    return tuple(int(value) for value in values)


def positive_number(value: Any, name: str, unit: str = "") -> float:
    """``value`` as a float if it is a finite positive number (else an InputError naming ``name``)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive number{unit}; got {value!r}")
    return float(value)


def whole_number(value: Any, name: str, minimum: int, maximum: int | None = None) -> int:
    """``value`` as an int if it is a whole number within the bounds (else an InputError naming ``name``)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum or (
        maximum is not None and value > maximum
    ):
        bound = f"from {minimum} to {maximum}" if maximum is not None else f">= {minimum}"
        raise InputError(f"{name} must be a whole number {bound}; got {value!r}")
    return int(value)


def study_linear_options(p: float = STUDY_LINEAR_P, passes: int = STUDY_LINEAR_PASSES) -> IEKFOptions:
    """The study's linear IEKF options: normalised data, exact (first-order-hold) discretisation."""
    return IEKFOptions(p=p, passes=passes, normalize=True, discretization="exact")


def spline_options(nodes: int | None = None, passes: int | None = None, p: float | None = None) -> SplineIEKFOptions:
    """The spline IEKF's options; settings left at None take its defaults.

    A bad value is named as the study names it (``nonlinear_p``, ``nonlinear_passes``).
    """
    with renamed_options({"p": "nonlinear_p", "passes": "nonlinear_passes"}):
        return SplineIEKFOptions(nodes=SplineIEKFOptions.nodes if nodes is None else nodes,
                                 passes=SplineIEKFOptions.passes if passes is None else passes,
                                 p=SplineIEKFOptions.p if p is None else p)


@dataclass(frozen=True)
class HandlingConfig:
    """Settings of the handling study; every field is checked on construction (InputError).

    Parameters
    ----------
    orders : tuple of int
        Model orders, increasing, each 2..8 (paper: 2..6).
    seed : int
        Seed of the random parts of both steer inputs.
    duration : float
        Length of each record (s); at least 5 s.
    amplitude_scale : float
        Steer amplitude as a fraction of the manoeuvres' defaults (1: the
        nonlinear range of the paper; 0.1 keeps the vehicle linear).
    vehicle : str
        A named vehicle or a vehicle file (:func:`vehid.vehicle.named_vehicle`).
    speed : float
        Trim and reference speed (m/s).
    linear_options : IEKFOptions
        The linear IEKF's (:func:`study_linear_options`); at least 2 passes,
        from which the order choice judges convergence. An archive keeps its
        ``p`` and ``passes``.
    spline_options : SplineIEKFOptions or None
        The spline IEKF's, started from each linear model (paper: 5 nodes);
        None: linear models only.
    workers : int, optional
        Processes running orders at once; default ``min(len(orders), cpu_count)``.
    """

    orders: tuple[int, ...] = HANDLING_ORDERS
    seed: int = HANDLING_SEED
    duration: float = HANDLING_DURATION  # [s]
    amplitude_scale: float = HANDLING_AMPLITUDE_SCALE  # [-]
    vehicle: str = HANDLING_VEHICLE
    speed: float = HANDLING_SPEED  # [m/s]
    dt: float = DEFAULT_DT  # [s]
    linear_options: IEKFOptions = study_linear_options()
    spline_options: SplineIEKFOptions | None = SplineIEKFOptions()
    workers: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "orders", check_orders(self.orders))
        whole_number(self.seed, "seed", 0)
        if positive_number(self.duration, "duration", " of seconds") < MIN_DURATION:
            raise InputError(f"duration must be at least {MIN_DURATION:g} s; got {self.duration!r}")
        if positive_number(self.amplitude_scale, "amplitude_scale") > 1.5:
            raise InputError(f"amplitude_scale above 1.5 takes the car beyond its grip; got {self.amplitude_scale!r}")
        if not isinstance(self.vehicle, str) or not self.vehicle:
            raise InputError(f"vehicle must be a name or a file; got {self.vehicle!r}")
        positive_number(self.speed, "speed", " (m/s)")
        positive_number(self.dt, "dt", " of seconds")
        if not isinstance(self.linear_options, IEKFOptions):
            raise InputError(f"linear_options must be IEKFOptions; got {type(self.linear_options).__name__}")
        whole_number(self.linear_options.passes, "passes", 2)  # the order choice judges convergence from two passes on
        if self.spline_options is not None and not isinstance(self.spline_options, SplineIEKFOptions):
            raise InputError(f"spline_options must be SplineIEKFOptions or None; got {type(self.spline_options).__name__}")
        if self.workers is not None:
            whole_number(self.workers, "workers", 1)

    def worker_count(self) -> int:
        return self.workers or max(1, min(len(self.orders), os.cpu_count() or 1))

    def as_dict(self) -> dict[str, Any]:
        """The settings as an archive keeps them: flat, the spline ones None for a linear-only study."""
        linear, spline = self.linear_options, self.spline_options
        return {"orders": list(self.orders), "seed": self.seed, "duration": self.duration,
                "amplitude_scale": self.amplitude_scale, "vehicle": self.vehicle, "speed": self.speed, "dt": self.dt,
                "p": linear.p, "passes": linear.passes, "nodes": None if spline is None else spline.nodes,
                "nonlinear": spline is not None, "nonlinear_passes": None if spline is None else spline.passes,
                "nonlinear_p": None if spline is None else spline.p, "workers": self.workers}

    @classmethod
    def from_dict(cls, stored: Mapping[str, Any], workers: int | None = None) -> "HandlingConfig":
        """Inverse of :meth:`as_dict`; spline settings stored as None take the spline IEKF's defaults."""
        spline = None
        if stored.get("nonlinear", True):
            spline = spline_options(stored.get("nodes"), stored.get("nonlinear_passes"), stored.get("nonlinear_p"))
        return cls(orders=tuple(stored["orders"]), seed=stored["seed"], duration=stored["duration"],
                   amplitude_scale=stored["amplitude_scale"], vehicle=stored["vehicle"], speed=stored["speed"],
                   dt=stored["dt"], linear_options=study_linear_options(stored["p"], stored["passes"]),
                   spline_options=spline, workers=workers)


@dataclass(frozen=True, eq=False)
class RecordArrays:
    """An IOData as plain arrays and strings, to cross a process boundary (IOData's metadata does not pickle)."""

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_units: tuple[str, ...]
    output_units: tuple[str, ...]
    meta: dict[str, Any]

    @classmethod
    def from_iodata(cls, data: IOData) -> "RecordArrays":
        return cls(np.asarray(data.t), np.asarray(data.u), np.asarray(data.y), data.input_names,
                   data.output_names, data.input_units, data.output_units, dict(data.meta))

    def to_iodata(self) -> IOData:
        return IOData(t=self.t, u=self.u, y=self.y, input_names=self.input_names, output_names=self.output_names,
                      input_units=self.input_units, output_units=self.output_units, meta=self.meta)


def make_records(config: HandlingConfig) -> dict[str, IOData]:
    """The identification and validation records: steer in, the three handling outputs out (states dropped)."""
    params = named_vehicle(config.vehicle)
    records = {}
    for name in ("identification", "validation"):
        manoeuvre = make_manoeuvre(name, seed=config.seed, duration=config.duration, dt=config.dt)
        if config.amplitude_scale != 1.0:
            amplitude = config.amplitude_scale * manoeuvre.meta["amplitude"]
            manoeuvre = make_manoeuvre(name, seed=config.seed, duration=config.duration, dt=config.dt,
                                       amplitude=amplitude)
        record = simulate(params, manoeuvre, speed=config.speed).select_outputs(OUTPUTS)
        records[name] = record.replace(x=None, state_names=None, state_units=None)
    return records


#: White noise (standard deviation) of a vehicle-grade inertial unit and roll estimate, per output:
#: lateral acceleration (m/s^2), yaw rate (rad/s), roll angle (rad, 0.1 deg).
SENSOR_NOISE = (0.05, 0.003, 0.0017)


def with_sensor_noise(records: Mapping[str, IOData], seed: int,
                      noise: tuple[float, ...] = SENSOR_NOISE) -> dict[str, IOData]:
    """The records with white Gaussian noise of standard deviation ``noise`` (one per output) added to the outputs.

    The simulated records are noise-free, so a model's residuals on them are
    model error only; with sensor noise the residual tests can tell an
    adequate model (residuals white, independent of the input) from an
    under-modelled one.

    Parameters
    ----------
    records : mapping of str to IOData
        The records (:func:`make_records`); one generator, seeded with
        ``seed``, serves them in their order.
    seed : int
        Seed of the noise.
    noise : tuple of float
        Standard deviation per output, in the outputs' units.

    Returns
    -------
    dict of str to IOData
        The records under the same names, their outputs noisy.
    """
    rng = np.random.default_rng(seed)
    noisy = {}
    for name, record in records.items():
        if len(noise) != record.n_y:
            raise InputError(f"noise needs one standard deviation per output ({record.n_y}); got {len(noise)}")
        noisy[name] = record.replace(y=record.y + np.asarray(noise, dtype=float) * rng.standard_normal(record.y.shape))
    return noisy


def explained_percent(model: Any, data: IOData) -> np.ndarray:
    """R (eq. 17, percent) per output of ``model`` simulated from rest over ``data``, in original units."""
    return percentage_explanation(data.y, model.simulate_outputs(data.u, data.dt))


class PassEvent(NamedTuple):
    """One finished pass, as a worker reports it: order, ``linear``/``nonlinear``, pass index, mean R (%)."""

    order: int
    stage: str
    index: int
    fit: float


@dataclass(frozen=True)
class OrderJob:
    """Everything one order needs, as picklable values; no spline options: linear only."""

    order: int
    identification: RecordArrays
    validation: RecordArrays
    linear_options: IEKFOptions
    spline_options: SplineIEKFOptions | None


@dataclass(frozen=True, eq=False)
class SplineStudyRun:
    """What the study keeps of a spline-nonlinear IEKF run (plain arrays, so it crosses processes and archives).

    ``fit_filter (n_pass, n_y)`` and ``trace_p (n_pass,)`` per pass;
    ``mode_curves[mode] = (frequency_hz, damping)`` over :data:`MODE_AMPLITUDES`.
    """

    model: Any
    fit_identification: np.ndarray
    fit_validation: np.ndarray
    fit_filter: np.ndarray
    trace_p: np.ndarray
    spline_tables: dict[str, dict[str, np.ndarray]]
    mode_curves: dict[int, tuple[np.ndarray, np.ndarray]]
    stop_reason: str
    seconds: float


@dataclass(frozen=True, eq=False)
class OrderOutcome:
    """One order's linear run and scores, its nonlinear outcome, and why either is missing."""

    order: int
    linear: IEKFResult | None
    linear_fit_identification: np.ndarray | None
    linear_fit_validation: np.ndarray | None
    linear_error: str | None
    nonlinear: SplineStudyRun | None
    nonlinear_error: str | None
    seconds: float


def _nonlinear_outcome(result: Any, identification: IOData, validation: IOData, n_pairs: int) -> SplineStudyRun:
    model = result.model
    curves = {}
    modes = [model.modes(amplitude=amplitude)[:n_pairs] for amplitude in MODE_AMPLITUDES]
    for mode in range(n_pairs):  # frequency and damping curves exist for the complex pairs
        curves[mode] = (np.array([at[mode].frequency_hz for at in modes]), np.array([at[mode].damping for at in modes]))
    tables = {name: {key: value if isinstance(value, str) else np.asarray(value, dtype=float)
                     for key, value in table.items()}
              for name, table in model.spline_tables().items()}
    return SplineStudyRun(
        model=model,
        fit_identification=explained_percent(model, identification),
        fit_validation=explained_percent(model, validation),
        fit_filter=np.array([record.fit_filter for record in result.history], dtype=float),
        trace_p=np.array([record.trace_p for record in result.history], dtype=float),
        spline_tables=tables,
        mode_curves=curves,
        stop_reason=str(result.stop_reason),
        seconds=float(result.seconds),
    )


def identify_order(data: IOData, order: int, linear_options: IEKFOptions, spline_options: SplineIEKFOptions | None,
                   on_pass: Callable[[str], Any] | None = None) -> tuple[Any, str | None, Any, str | None]:
    """The linear IEKF of ``order`` and, started from its model, the spline IEKF (unless ``spline_options`` is None).

    A divergence keeps what finished before it (the filter's ``last_good``) and is returned as text:
    ``(linear, linear_error, nonlinear, nonlinear_error)``. ``on_pass(stage)``, stage ``linear`` or
    ``nonlinear``, gives each filter's ``on_pass``.
    """
    callback = on_pass or (lambda stage: None)
    structure = ModalStructure.default(order, data.n_u, data.n_y)
    linear = nonlinear = linear_error = nonlinear_error = None
    try:
        linear = identify_iekf(data, structure, options=linear_options, on_pass=callback("linear"))
    except DivergenceError as exc:
        linear, linear_error = exc.last_good, str(exc)
    if linear is not None and spline_options is not None:
        try:
            nonlinear = identify_spline_iekf(data, linear.model, options=spline_options, on_pass=callback("nonlinear"))
        except DivergenceError as exc:
            nonlinear_error = str(exc)
            if exc.last_good is not None and exc.last_good.history:  # keep the passes that finished
                nonlinear = exc.last_good
    return linear, linear_error, nonlinear, nonlinear_error


def run_order(job: OrderJob, report: Callable[[PassEvent], None] | None = None) -> OrderOutcome:
    """Identify one order (:func:`identify_order`) and score both models on both records.

    A top-level function of plain values, so that a process pool can run it.
    """
    started = time.perf_counter()
    identification, validation = job.identification.to_iodata(), job.validation.to_iodata()

    def reporter(stage: str) -> Callable[[Any, Any], None] | None:
        """An ``on_pass`` that counts passes itself: the spline IEKF's records promise no ``index``."""
        if report is None:
            return None
        count = iter(range(1, 1 << 62))
        return lambda record, _: report(PassEvent(job.order, stage, next(count), float(record.mean_fit_filter)))

    linear, linear_error, result, nonlinear_error = identify_order(identification, job.order, job.linear_options,
                                                                   job.spline_options, reporter)
    if linear is None:
        return OrderOutcome(job.order, None, None, None, linear_error, None, "no linear model to start from",
                            time.perf_counter() - started)
    fit_identification = explained_percent(linear.model, identification)
    fit_validation = explained_percent(linear.model, validation)
    if job.spline_options is None:
        nonlinear_error = "not asked for"
    elif nonlinear_error is not None:
        nonlinear_error = f"diverged: {nonlinear_error}"
    nonlinear = None if result is None else _nonlinear_outcome(result, identification, validation,
                                                                linear.model.structure.n_complex_pairs)
    return OrderOutcome(job.order, linear, fit_identification, fit_validation, linear_error, nonlinear,
                        nonlinear_error, time.perf_counter() - started)


def _run_orders(jobs: list[OrderJob], workers: int, on_event: Callable[[PassEvent], None] | None,
                on_outcome: Callable[[OrderOutcome], None] | None = None) -> dict[int, OrderOutcome]:
    """Run the jobs: in this process with one worker (or one job), else in spawned worker processes.

    Workers send their PassEvents as they go; ``on_outcome`` is called here
    with each order's outcome as it arrives (checkpoints).
    """
    if workers == 1 or len(jobs) == 1:
        outcomes = {}
        for job in jobs:
            outcomes[job.order] = run_order(job, on_event)
            if on_outcome is not None:
                on_outcome(outcomes[job.order])
        return outcomes
    jobs = sorted(jobs, key=lambda job: -job.order)  # the longest first: the last to finish is a short one
    done = run_in_workers(run_order, jobs, workers, on_message=on_event,
                          on_result=None if on_outcome is None else lambda job, outcome: on_outcome(outcome))
    return {outcome.order: outcome for outcome in done}


@dataclass(frozen=True)
class TableRow:
    """One order's line of Table 5: linear eigenvalues and mean R (%) of both models on both records."""

    order: int
    linear_eigenvalues: tuple[complex, ...]
    linear_identification_R: float | None
    nonlinear_identification_R: float | None
    linear_validation_R: float | None
    nonlinear_validation_R: float | None


@dataclass(frozen=True, eq=False)
class LinearRun:
    """One order's linear run: R per output on both records, how it ran and its convergence (order choice)."""

    order: int
    identification_R: np.ndarray | None
    validation_R: np.ndarray | None
    passes_run: int | None
    stop_reason: str | None
    trace_p: float | None
    trace_growth: float | None
    drift: float | None
    converged: bool | None
    seconds: float | None
    error: str | None


@dataclass(frozen=True, eq=False)
class NonlinearRun:
    """One order's nonlinear run: R per output, per-pass history, mode curves over the amplitudes, or why missing."""

    order: int
    identification_R: np.ndarray | None
    validation_R: np.ndarray | None
    passes_run: int | None
    stop_reason: str | None
    seconds: float | None
    mode_amplitudes: np.ndarray
    mode_frequency_hz: tuple[np.ndarray, ...] | None
    mode_damping: tuple[np.ndarray, ...] | None
    fit_filter_by_pass: np.ndarray | None
    trace_p_by_pass: np.ndarray | None
    missing: str | None


@dataclass(frozen=True)
class ModeComparison:
    """A vehicle mode beside the identified mode of one order nearest to it in the complex plane."""

    order: int
    mode: str
    vehicle_eigenvalue: complex
    vehicle_frequency_hz: float
    vehicle_damping: float
    identified_eigenvalue: complex
    identified_frequency_hz: float
    identified_damping: float
    frequency_ratio: float


@dataclass(frozen=True, eq=False)
class HandlingResult:
    """The study: its records, each order's outcome and rows, the vehicle's modes and the order choice.

    ``vehicle_linearization`` holds the vehicle's A, B and its C, D rows of :data:`OUTPUTS`.
    """

    config: HandlingConfig
    records: dict[str, IOData]
    outcomes: dict[int, OrderOutcome]
    vehicle_modes: dict[str, VehicleMode]
    vehicle_linearization: dict[str, np.ndarray]
    assessment: OrderAssessment
    nonlinear_status: str
    table: tuple[TableRow, ...]
    linear_runs: tuple[LinearRun, ...]
    nonlinear_runs: tuple[NonlinearRun, ...]
    mode_comparison: tuple[ModeComparison, ...]
    seconds: float
    workers: int


def compare_modes(order: int, eigenvalues: Any, vehicle_modes: Mapping[str, VehicleMode]) -> tuple[ModeComparison, ...]:
    """For each vehicle mode, the identified mode of ``order`` nearest to it in the complex plane.

    ``eigenvalues``: one per identified mode (a conjugate counts as its pair).
    """
    candidates = np.asarray(eigenvalues, dtype=complex)
    candidates = np.where(candidates.imag < 0, candidates.conj(), candidates)
    comparison = []
    for label, mode in vehicle_modes.items():
        found = ModelMode.of(candidates[int(np.argmin(np.abs(candidates - mode.eigenvalue)))])
        comparison.append(ModeComparison(order, label, mode.eigenvalue, mode.frequency_hz, mode.damping,
                                         found.eigenvalue, found.frequency_hz, found.damping,
                                         found.frequency_hz / mode.frequency_hz))
    return tuple(comparison)


def percent_text(value: float | None) -> str:
    """A percentage for the text tables: two decimals, ``-`` where there is none."""
    return "-" if value is None else f"{value:.2f}"


def _mean(values: np.ndarray | None) -> float | None:
    return None if values is None else float(np.mean(values))


def _rows(outcome: OrderOutcome, assessed: AssessedOrder | None, vehicle_modes: Mapping[str, VehicleMode]
          ) -> tuple[TableRow, LinearRun, NonlinearRun, tuple[ModeComparison, ...]]:
    """One order's rows of the study's table, runs and mode comparison."""
    order, linear, nonlinear = outcome.order, outcome.linear, outcome.nonlinear
    table = TableRow(order, () if linear is None else tuple(linear.model.eigenvalues()),
                     _mean(outcome.linear_fit_identification), None if nonlinear is None else _mean(nonlinear.fit_identification),
                     _mean(outcome.linear_fit_validation), None if nonlinear is None else _mean(nonlinear.fit_validation))
    linear_run = LinearRun(
        order, outcome.linear_fit_identification, outcome.linear_fit_validation,
        None if linear is None else linear.passes_run, None if linear is None else linear.stop_reason,
        None if assessed is None else assessed.trace_p, None if assessed is None else assessed.trace_growth,
        None if assessed is None else assessed.drift, None if assessed is None else assessed.converged,
        None if linear is None else linear.seconds, outcome.linear_error)
    curves = None if nonlinear is None else tuple(nonlinear.mode_curves.values())
    nonlinear_run = NonlinearRun(
        order, None if nonlinear is None else nonlinear.fit_identification,
        None if nonlinear is None else nonlinear.fit_validation, None if nonlinear is None else len(nonlinear.trace_p),
        None if nonlinear is None else nonlinear.stop_reason, None if nonlinear is None else nonlinear.seconds,
        MODE_AMPLITUDES, None if curves is None else tuple(c[0] for c in curves),
        None if curves is None else tuple(c[1] for c in curves), None if nonlinear is None else nonlinear.fit_filter,
        None if nonlinear is None else nonlinear.trace_p, outcome.nonlinear_error)
    modes = () if linear is None else compare_modes(order, linear.model.mode_eigenvalues(), vehicle_modes)
    return table, linear_run, nonlinear_run, modes


def run_study(
    config: HandlingConfig | None = None,
    *,
    on_event: Callable[[PassEvent], None] | None = None,
    records: Mapping[str, IOData] | None = None,
    finished: Mapping[int, OrderOutcome] | None = None,
    on_outcome: Callable[[OrderOutcome], None] | None = None,
) -> HandlingResult:
    """Run the handling study: data, the linear and nonlinear identifications per order, scores, modes.

    Parameters
    ----------
    on_event : callable, optional
        Called in this process with each :class:`PassEvent` (progress displays).
    records : mapping, optional
        The ``identification`` and ``validation`` records, when already made
        (:func:`make_records`; a resumed study takes them from its archive).
    finished : mapping of int to OrderOutcome, optional
        Orders already done (a resumed study): they are not run again.
    on_outcome : callable, optional
        Called with each order's outcome as it finishes (checkpoints).

    Raises
    ------
    DivergenceError
        When no order gave a linear model.
    """
    config = config or HandlingConfig()
    started = time.perf_counter()
    spline = config.spline_options
    nonlinear_status = "not asked for (linear only)" if spline is None else f"spline IEKF, {spline.nodes} nodes"
    records = dict(records) if records is not None else make_records(config)
    finished = dict(finished or {})
    linearisation = linearize(named_vehicle(config.vehicle), speed=config.speed)
    vehicle_modes = {label: linearisation.modes_labelled(label)[0] for label in COMPARED_MODES}
    arrays = {name: RecordArrays.from_iodata(record) for name, record in records.items()}
    jobs = [
        OrderJob(order, arrays["identification"], arrays["validation"], config.linear_options, spline)
        for order in config.orders if order not in finished
    ]
    workers = max(1, min(config.worker_count(), len(jobs)))
    outcomes = {**finished, **_run_orders(jobs, workers, on_event, on_outcome)}
    outcomes = {order: outcomes[order] for order in config.orders}  # in order, however they were run
    linear = {order: outcome.linear for order, outcome in outcomes.items() if outcome.linear is not None}
    if not linear:
        raise DivergenceError("no order gave a linear model: "
                              + "; ".join(f"n = {o.order}: {o.linear_error}" for o in outcomes.values()))
    assessment = assess_orders(linear)
    seconds = time.perf_counter() - started
    rows = [list(linearisation.output_names).index(name) for name in OUTPUTS]
    steer_to_outputs = {"A": linearisation.A, "B": linearisation.B, "C": linearisation.C[rows], "D": linearisation.D[rows]}
    assessed = {row.order: row for row in assessment.rows}
    table, linear_runs, nonlinear_runs, comparison = zip(*(
        _rows(outcome, assessed.get(order), vehicle_modes) for order, outcome in outcomes.items()))
    return HandlingResult(config, records, outcomes, vehicle_modes, steer_to_outputs, assessment, nonlinear_status,
                          table, linear_runs, nonlinear_runs, tuple(item for items in comparison for item in items),
                          seconds, workers)


NONLINEAR_HISTORY_UNITS = {"fit_filter": "%", "trace_p": "normalised units"}


def _write_nonlinear_run(archive: Any, name: str, outcome: SplineStudyRun) -> None:
    """Store a nonlinear run as ``runs/<name>``: per-pass fit and trace(P), the model, scores,
    spline tables and mode curves (the model alone is enough to redraw or export it)."""
    history_run = run_group(archive, name)
    for fit, trace in zip(outcome.fit_filter, outcome.trace_p):
        append_history(history_run, {"fit_filter": fit, "trace_p": trace}, units=NONLINEAR_HISTORY_UNITS)
    run = write_run(archive, name, model=outcome.model, metrics={"identification_R": outcome.fit_identification,
                                                                 "validation_R": outcome.fit_validation})
    write_value(run, "spline_tables", outcome.spline_tables)
    write_value(run, "mode_amplitudes", MODE_AMPLITUDES)
    for mode, (frequency, damping) in outcome.mode_curves.items():
        write_value(run, f"mode{mode}_frequency", frequency, units="Hz")
        write_value(run, f"mode{mode}_damping", damping, units="-")
    run.attrs["stop_reason"] = outcome.stop_reason
    run.attrs["seconds"] = outcome.seconds


#: Root attribute of a handling-study archive: JSON {order: {linear_error, nonlinear_error, seconds}} of the orders done.
ORDERS_DONE = "orders_done_json"


def archive_path(out: str | Path | None = None) -> Path:
    """The archive file of ``--out``, a relative name from the working directory; by default ``handling_study.h5``
    under the results folder."""
    return results_path(out, "handling_study.h5")


def write_order(archive: Any, order: int, outcome: OrderOutcome) -> None:
    """Store one finished order: its runs and its entry in the root attribute ``orders_done_json``."""
    if outcome.linear is not None:
        write_iekf_run(archive, str(RunName("linear", order)), outcome.linear)
        write_run(archive, str(RunName("linear", order)), metrics={"identification_R": outcome.linear_fit_identification,
                                                       "validation_R": outcome.linear_fit_validation})
    if outcome.nonlinear is not None:
        _write_nonlinear_run(archive, str(RunName("nonlinear", order)), outcome.nonlinear)
    done = json.loads(archive.attrs.get(ORDERS_DONE, "{}"))
    done[str(order)] = {"linear_error": outcome.linear_error, "nonlinear_error": outcome.nonlinear_error,
                        "seconds": outcome.seconds}
    archive.attrs[ORDERS_DONE] = json.dumps(done, sort_keys=True)


@contextmanager
def start_archive(path: str | Path, config: HandlingConfig, records: Mapping[str, IOData], *,
                  run: str | None = None) -> Iterator[Any]:
    """Write a new study archive (a ``with`` block): header, configuration and both records, then the caller's runs.

    ``run`` names the command line that asked for the study (``RUN_ATTRIBUTE``), so that a rerun may replace it.
    """
    with write_archive(path, kind="handling-study", config=config.as_dict(), seeds=[config.seed]) as archive:
        if run is not None:
            archive.attrs[RUN_ATTRIBUTE] = run
        for name, record in records.items():
            write_record(archive, name, record)
        yield archive


def summary_of(result: HandlingResult) -> dict[str, Any]:
    """The study's JSON summary (before :func:`vehid.identification.jsonable.to_jsonable`): its keys are a public contract."""
    return {
        "table": list(result.table),
        "chosen_order": result.assessment.chosen_order,
        "seconds": result.seconds,
        "vehicle_modes": {label: {"eigenvalue": mode.eigenvalue, "frequency_hz": mode.frequency_hz,
                                  "damping": mode.damping, "label": mode.label}
                          for label, mode in result.vehicle_modes.items()},
        "vehicle_linearization": result.vehicle_linearization,
        "mode_comparison": list(result.mode_comparison),
        "linear_runs": list(result.linear_runs),
        "nonlinear_runs": list(result.nonlinear_runs),
        "nonlinear": result.nonlinear_status,
        "order_assessment": [row.as_dict() for row in result.assessment.rows],
        "outputs": list(OUTPUTS),
        "config": result.config.as_dict(),
        "workers": result.workers,
        "paper": {str(order): values for order, values in PAPER.items()},
    }


def write_archive_for(result: HandlingResult, out: str | Path | None = None) -> Path:
    """Write the study's archive (kind ``handling-study``, layout in results/RESULTS_LAYOUT.md) under ``--out``."""
    return write_study_archive(result, archive_path(out))


def write_study_archive(result: HandlingResult, path: str | Path, *, run: str | None = None) -> Path:
    """Write the study's archive to exactly ``path`` (see :func:`write_archive_for`; ``run`` as :func:`start_archive`)."""
    path = Path(path)
    with start_archive(path, result.config, result.records, run=run) as archive:
        for order, outcome in result.outcomes.items():
            write_order(archive, order, outcome)
        archive.attrs["summary_json"] = json.dumps(to_jsonable(summary_of(result)), allow_nan=False)
    return path


def main(config: HandlingConfig | None = None, out: str | Path | None = None) -> Path:
    """Run the study and write its archive; returns the archive's path."""
    return write_archive_for(run_study(config), out)
