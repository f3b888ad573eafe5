"""The operating envelope: models across speeds and a speed-scheduled family, on a process pool or Dask.

A campaign is a set of jobs, one per vehicle, speed, model order and seed,
each a pure function of its settings (:func:`run_job`): it measures the
vehicle's grip limit at its speed on a slow steer ramp, simulates the
identification and validation manoeuvres with the steer that would reach
``amplitude_fraction`` of that limit in steady state if the car stayed
linear (so that every speed is driven equally hard), identifies a linear
modal model by the IEKF (and optionally a spline-nonlinear one started from
it) and scores both on both records. Results go to one archive, one group
per job, written as jobs finish, so that ``--resume`` skips the jobs done.

Speeds between grid speeds (by default the midpoints) are identified too:
there the speed-scheduled model (:mod:`vehid.identification.models.scheduled`) is
validated beside the model identified directly.

Dask reschedules the jobs of a lost worker and a job that raised is retried
once; workers of a remote scheduler need the workbench installed. The
grip-limit measurements are in ``docs/study_measurements.md``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import socket
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from vehid.identification.dataio.archive import open_archive, read_run, update_archive, write_archive, write_run
from vehid.identification.dataio.archive_safety import archive_lock
from vehid.identification.errors import DivergenceError, InputError, SimulationError
from vehid.identification.filtering.iekf import IEKFOptions
from vehid.identification.filtering.spline_iekf import SplineIEKFOptions
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.scheduled import ScheduledModalModel, schedule_models
from vehid.identification.dataio.storage import read_value, write_value
from vehid.vehicle import DEFAULT_DT, linearize, make_manoeuvre, named_vehicle, simulate
from vehid.vehicle.parameters import VehicleParameters

from .handling_study import (COMPARED_MODES, OUTPUTS, check_orders, explained_percent, identify_order, percent_text,
                             positive_number, spline_options, study_linear_options, whole_number)
from .paths import results_path
from .shutdown import run_in_workers
from .study_settings import (ENVELOPE_AMPLITUDE_FRACTION, ENVELOPE_ARCHIVE_KIND, ENVELOPE_DURATION, ENVELOPE_EXECUTORS,
                             ENVELOPE_P, ENVELOPE_PASSES)

__all__ = [
    "EXECUTORS",
    "EnvelopeConfig",
    "EnvelopeJob",
    "JobOutcome",
    "EnvelopeResult",
    "GripLimit",
    "grip_limit",
    "mode_comparison",
    "parse_speeds",
    "plan_jobs",
    "run_job",
    "run_campaign",
]

EXECUTORS = ENVELOPE_EXECUTORS
ARCHIVE_KIND = ENVELOPE_ARCHIVE_KIND
_DEG = math.pi / 180
_RAMP_DURATION = 20.0  # [s] slow enough to be quasi-steady (1 deg/s at 20 m/s)
_RAMP_DT = 0.005  # [s] the ramp only needs the handling curve, not the identification's 500 Hz
_MAX_STEER = 30 * _DEG  # the vehicle model's trim range
_VALIDATION_RATIO = 3.5 / 4.0  # validation to identification amplitude, as the manoeuvres' defaults
_PER_JOB = ("vehicles", "speeds", "orders", "seeds", "off_grid")  # the settings that tell jobs apart


def parse_speeds(text: str, name: str = "speeds") -> tuple[float, ...]:
    """Speeds from ``"10,15,20"``: positive, increasing, no repeats (m/s)."""
    try:
        values = tuple(float(part) for part in str(text).split(",") if part.strip())
    except ValueError:
        raise InputError(f"{name} must be numbers separated by commas (m/s); got {text!r}") from None
    return _check_speeds(values, name)


def _check_speeds(values: Sequence[Any], name: str, minimum: int = 1) -> tuple[float, ...]:
    values = tuple(values)
    if len(values) < minimum:
        raise InputError(f"give at least {minimum} {name}")
    for value in values:
        positive_number(value, name[:-1] if name.endswith("s") else name, " (m/s)")
    values = tuple(float(v) for v in values)
    if list(values) != sorted(set(values)):
        raise InputError(f"{name} must increase without repeats; got {list(values)}")
    return values


@dataclass(frozen=True)
class EnvelopeConfig:
    """Settings of an envelope campaign; every field is checked on construction (InputError).

    Parameters
    ----------
    vehicles : tuple of str
        Named vehicles (``baseline``, ``understeer``) or vehicle files.
    speeds : tuple of float
        Grid speeds (m/s), increasing.
    amplitude_fraction : float
        Steer amplitude as a fraction of each speed's grip limit (module notes).
    nonlinear : bool
        Identify spline-nonlinear models too.
    off_grid : tuple of float or None
        Speeds where the scheduled model is validated (and a model identified
        directly); None: the midpoints of the grid; () none.
    duration, dt : float
        Record length and sample interval (s).
    p, passes : float, int
        Linear IEKF settings (normalised data). Defaults measured in the
        linear regime (the handling study's tenth-amplitude test).
    nodes, nonlinear_passes, nonlinear_p :
        Spline IEKF settings (None: its own defaults).
    """

    vehicles: tuple[str, ...] = ("baseline",)
    speeds: tuple[float, ...] = (10.0, 15.0, 20.0, 25.0, 30.0)
    amplitude_fraction: float = ENVELOPE_AMPLITUDE_FRACTION
    orders: tuple[int, ...] = (2, 3, 4)
    seeds: tuple[int, ...] = (0,)
    nonlinear: bool = True
    off_grid: tuple[float, ...] | None = None
    duration: float = ENVELOPE_DURATION
    dt: float = DEFAULT_DT
    p: float = ENVELOPE_P
    passes: int = ENVELOPE_PASSES
    nodes: int = 5
    nonlinear_passes: int | None = None
    nonlinear_p: float | None = None

    def __post_init__(self) -> None:
        vehicles = tuple(self.vehicles)
        if not vehicles or any(not isinstance(v, str) or not v.strip() for v in vehicles) or len(set(vehicles)) < len(vehicles):
            raise InputError(f"vehicles must be distinct names or files; got {list(vehicles)}")
        object.__setattr__(self, "vehicles", vehicles)
        object.__setattr__(self, "speeds", _check_speeds(self.speeds, "speeds"))
        fraction = positive_number(self.amplitude_fraction, "amplitude_fraction")
        if fraction > 1.0:
            raise InputError(f"amplitude_fraction above 1 drives the car beyond its grip limit; got {fraction!r}")
        object.__setattr__(self, "orders", check_orders(self.orders))
        seeds = tuple(self.seeds)
        if not seeds or len(set(seeds)) < len(seeds):
            raise InputError(f"seeds must be distinct whole numbers; got {list(seeds)}")
        object.__setattr__(self, "seeds", tuple(whole_number(s, "seed", 0) for s in seeds))
        if self.off_grid is None:
            off = tuple((a + b) / 2 for a, b in zip(self.speeds, self.speeds[1:]))
        else:
            off = _check_speeds(self.off_grid, "off-grid speeds", minimum=0) if len(self.off_grid) else ()
        for speed in off:
            if not self.speeds[0] < speed < self.speeds[-1] or speed in self.speeds:
                raise InputError(f"off-grid speed {speed:g} must lie strictly between grid speeds "
                                 f"{self.speeds[0]:g}..{self.speeds[-1]:g}")
        object.__setattr__(self, "off_grid", off)
        if positive_number(self.duration, "duration", " of seconds") < 5.0:
            raise InputError(f"duration must be at least 5 s; got {self.duration!r}")
        positive_number(self.dt, "dt", " of seconds")
        positive_number(self.p, "p")
        whole_number(self.passes, "passes", 2)
        self.spline_options  # checked by its own class, whether or not the campaign runs it

    @property
    def linear_options(self) -> IEKFOptions:
        """The linear IEKF's options (the handling study's, at this campaign's p and passes)."""
        return study_linear_options(self.p, self.passes)

    @property
    def spline_options(self) -> SplineIEKFOptions:
        """The spline IEKF's options: settings left at None take its defaults."""
        return spline_options(self.nodes, self.nonlinear_passes, self.nonlinear_p)

    def as_dict(self) -> dict[str, Any]:
        values = dataclasses.asdict(self)
        for key in _PER_JOB:
            values[key] = list(values[key])
        return values


def _job_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """The settings every job shares: an archive resumed must have been written with the same."""
    return {key: value for key, value in settings.items() if key not in _PER_JOB}


@dataclass(frozen=True)
class GripLimit:
    """A vehicle's grip limit at one speed, measured on a slow steer ramp.

    ``lateral_acceleration`` (m/s^2) the largest reached; ``gain`` (m/s^2 per rad)
    the small-steer gain; ``steer`` (rad) where the limit was reached.
    """

    speed: float
    lateral_acceleration: float
    gain: float
    steer: float

    def amplitude(self, fraction: float) -> float:
        """Steer (rad) that reaches ``fraction`` of the grip limit in steady state if the car stayed linear."""
        return fraction * self.lateral_acceleration / self.gain


def steady_state_gain(linearisation: Any, output: str = "lateral_acceleration") -> float:
    """Steady-state gain of ``output`` per rad of steer from a vehicle linearisation.

    States nothing depends on (the heading: a zero column of A) are left out,
    so that the remaining A is invertible.
    """
    A, B, C, D = linearisation.A, linearisation.B, linearisation.C, linearisation.D
    keep = np.flatnonzero(np.any(A != 0, axis=0))
    gain = D - C[:, keep] @ np.linalg.solve(A[np.ix_(keep, keep)], B[keep])
    return float(gain[list(linearisation.output_names).index(output), 0])


def grip_limit(params: VehicleParameters, speed: float, linearisation: Any = None) -> GripLimit:
    """Measure the grip limit at ``speed`` (module notes); InputError if it lies beyond 30 deg of steer.

    The small-steer gain comes from the vehicle's linearisation at that speed
    (computed unless given).
    """
    amplitude = min(_MAX_STEER, 20 * _DEG * (20.0 / speed) ** 2)
    ramp = make_manoeuvre("ramp", amplitude=amplitude, duration=_RAMP_DURATION, dt=_RAMP_DT)
    left_envelope = None
    try:
        record = simulate(params, ramp, speed=speed)
    except SimulationError as exc:
        if exc.partial is None:
            raise
        # past the peak the ramp drives the tyres beyond their valid slip: the record up to there holds the peak
        record, left_envelope = exc.partial, exc
    steer = np.asarray(ramp.steer, dtype=float).ravel()[:record.n_samples]
    lateral = np.abs(record.y[:, list(record.output_names).index("lateral_acceleration")])
    if not np.all(np.isfinite(lateral)):
        raise DivergenceError(f"the grip ramp at {speed:g} m/s did not stay finite")
    peak = int(np.argmax(lateral))
    if peak >= lateral.size - 1:
        if left_envelope is not None:
            raise InputError(f"at {speed:g} m/s the car leaves its valid range before its grip limit: {left_envelope}")
        raise InputError(f"at {speed:g} m/s the grip limit lies beyond {math.degrees(amplitude):.0f} deg of steer: "
                         "too slow for this campaign")
    gain = steady_state_gain(linearisation if linearisation is not None else linearize(params, speed=speed))
    return GripLimit(float(speed), float(lateral[peak]), abs(gain), float(steer[peak]))


@dataclass(frozen=True)
class EnvelopeJob:
    """Everything one identification needs, as plain picklable values (a pure function of these)."""

    vehicle: str
    params: VehicleParameters
    speed: float
    order: int
    seed: int
    grid: bool
    amplitude_fraction: float
    duration: float
    dt: float
    linear_options: IEKFOptions
    spline_options: SplineIEKFOptions | None  # None: linear only

    @property
    def key(self) -> str:
        """The job's group name in the campaign archive."""
        return f"{self.vehicle}-v{self.speed:g}-n{self.order}-s{self.seed}"


@dataclass(frozen=True, eq=False)
class JobOutcome:
    """What a job returns and the archive keeps (plain values and models).

    ``modes``: (frequency_hz, damping) per identified mode; ``vehicle_modes``:
    label to (frequency_hz, damping) of the vehicle's linearisation at the speed.
    """

    key: str
    vehicle: str
    speed: float
    order: int
    seed: int
    grid: bool
    amplitude: float
    grip_lateral_acceleration: float
    linear_model: ModalModel | None
    linear_identification_R: float | None
    linear_validation_R: float | None
    nonlinear_identification_R: float | None
    nonlinear_validation_R: float | None
    modes: tuple[tuple[float, float], ...]
    vehicle_modes: dict[str, tuple[float, float]]
    error: str | None
    seconds: float
    host: str
    nonlinear_model: Any = None

    def metrics(self) -> dict[str, Any]:
        """Everything but the models, as values the archive stores."""
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                  if f.name not in ("linear_model", "nonlinear_model")}
        values["modes"] = [list(m) for m in self.modes]
        values["vehicle_modes"] = {label: list(v) for label, v in self.vehicle_modes.items()}
        return values

    @classmethod
    def from_metrics(cls, metrics: dict[str, Any], linear_model: Any, nonlinear_model: Any) -> "JobOutcome":
        values = dict(metrics)
        values["modes"] = tuple(tuple(float(x) for x in m) for m in values["modes"])
        values["vehicle_modes"] = {label: tuple(float(x) for x in v) for label, v in values["vehicle_modes"].items()}
        return cls(**values, linear_model=linear_model, nonlinear_model=nonlinear_model)


def _mode_pairs(model: Any) -> tuple[tuple[float, float], ...]:
    return tuple((mode.frequency_hz, mode.damping) for mode in model.modes())


def job_records(params: VehicleParameters, speed: float, seed: int, fraction: float, duration: float, dt: float,
                linearisation: Any = None):
    """The identification and validation records of a job (steer in; the handling outputs out) and the grip limit."""
    grip = grip_limit(params, speed, linearisation)
    amplitude = grip.amplitude(fraction)
    records = {}
    for name, scale in (("identification", 1.0), ("validation", _VALIDATION_RATIO)):
        manoeuvre = make_manoeuvre(name, seed=seed, duration=duration, dt=dt, amplitude=scale * amplitude)
        record = simulate(params, manoeuvre, speed=speed).select_outputs(list(OUTPUTS))
        records[name] = record.replace(x=None, state_names=None, state_units=None)
    return records, grip


def run_job(job: EnvelopeJob) -> JobOutcome:
    """Simulate a job's manoeuvres, identify, score; a divergence is reported in ``error``, not raised."""
    started = time.perf_counter()
    linearisation = linearize(job.params, speed=job.speed)
    records, grip = job_records(job.params, job.speed, job.seed, job.amplitude_fraction, job.duration, job.dt,
                                linearisation)
    identification, validation = records["identification"], records["validation"]
    vehicle_modes = {}
    for label in COMPARED_MODES:
        found = linearisation.modes_labelled(label)
        if found:
            vehicle_modes[label] = (float(found[0].frequency_hz), float(found[0].damping))
    linear, linear_error, nonlinear, nonlinear_error = identify_order(identification, job.order, job.linear_options,
                                                                      job.spline_options)
    errors = [f"{stage}: {error}" for stage, error in (("linear", linear_error), ("nonlinear", nonlinear_error))
              if error is not None]
    linear_model = None if linear is None else linear.model
    nonlinear_model = None if nonlinear is None else nonlinear.model
    fits: dict[str, float | None] = dict.fromkeys(("li", "lv", "ni", "nv"))
    if linear_model is not None:
        fits["li"], fits["lv"] = (float(np.mean(explained_percent(linear_model, r))) for r in (identification, validation))
    if nonlinear_model is not None:
        fits["ni"], fits["nv"] = (float(np.mean(explained_percent(nonlinear_model, r))) for r in (identification, validation))
    return JobOutcome(
        key=job.key, vehicle=job.vehicle, speed=job.speed, order=job.order, seed=job.seed, grid=job.grid,
        amplitude=grip.amplitude(job.amplitude_fraction), grip_lateral_acceleration=grip.lateral_acceleration,
        linear_model=linear_model, linear_identification_R=fits["li"], linear_validation_R=fits["lv"],
        nonlinear_identification_R=fits["ni"], nonlinear_validation_R=fits["nv"],
        modes=() if linear_model is None else _mode_pairs(linear_model),
        vehicle_modes=vehicle_modes, error="; ".join(errors) or None, seconds=time.perf_counter() - started,
        host=socket.gethostname(), nonlinear_model=nonlinear_model,
    )


def _vehicle_label(spec: str, params: VehicleParameters) -> str:
    label = Path(spec).stem if (os.sep in spec or spec.endswith((".toml", ".json"))) else spec
    label = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in label)
    return label or params.name


def plan_jobs(config: EnvelopeConfig) -> list[EnvelopeJob]:
    """Every job of the campaign: grid speeds first, then the off-grid references; per vehicle, order, seed."""
    jobs = []
    labels: dict[str, str] = {}
    for spec in config.vehicles:
        params = named_vehicle(spec)
        label = _vehicle_label(spec, params)
        if label in labels.values():
            raise InputError(f"two vehicles would share the label {label!r}; rename one of the files")
        labels[spec] = label
        for grid, speeds in ((True, config.speeds), (False, config.off_grid)):
            for speed in speeds:
                for order in config.orders:
                    for seed in config.seeds:
                        jobs.append(EnvelopeJob(label, params, speed, order, seed, grid, config.amplitude_fraction,
                                                config.duration, config.dt, config.linear_options,
                                                config.spline_options if config.nonlinear else None))
    return jobs


def _job_cost(job: EnvelopeJob) -> float:
    """Relative expected run time, to start the longest jobs first."""
    return job.order * (1.0 if job.spline_options is None else 20.0)


def _job_in_worker(job: EnvelopeJob, report: Callable[[Any], None]) -> JobOutcome:
    return run_job(job)


def _run_process_pool(jobs: list[EnvelopeJob], workers: int, on_done: Callable[[JobOutcome], None]) -> None:
    """Jobs in the study workers of :func:`vehid.scenarios.shutdown.run_in_workers`, one job each at a time."""
    if workers == 1:
        for job in jobs:
            on_done(run_job(job))
        return
    run_in_workers(_job_in_worker, jobs, workers, on_result=lambda job, outcome: on_done(outcome))


def _run_dask(jobs: list[EnvelopeJob], on_done: Callable[[JobOutcome], None], *, scheduler: str | None,
              workers: int) -> None:
    """The jobs on a Dask cluster: ``scheduler`` an address, else a local cluster of ``workers`` processes.

    Lost workers' jobs are rescheduled by Dask itself; ``retries=1`` reruns a job that raised.
    """
    try:
        from distributed import Client, LocalCluster, as_completed as dask_completed
    except ImportError:
        raise InputError("--executor dask needs dask.distributed: pip install 'vehid[cluster]'") from None
    # Dask logs its cluster's life at INFO, and a local cluster's workers may log a failed heartbeat while
    # it shuts down; the workbench shows them only when asked to be verbose (job failures still raise)
    verbose = logging.getLogger().getEffectiveLevel() <= logging.INFO
    logging.getLogger("distributed").setLevel(logging.INFO if verbose else logging.CRITICAL)
    cluster = None
    if scheduler:
        client = Client(scheduler, timeout=30)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.INFO if verbose else logging.CRITICAL)
        client = Client(cluster)
    try:
        token = os.urandom(4).hex()  # keys unique to this run: a shared scheduler may hold an earlier campaign's
        futures = [client.submit(run_job, job, key=f"vehid-envelope-{job.key}-{token}", pure=False, retries=1,
                                 priority=int(_job_cost(job))) for job in jobs]
        for future in dask_completed(futures):
            on_done(future.result())
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass(frozen=True, eq=False)
class EnvelopeResult:
    """A campaign: its outcomes, the scheduled families, the summary and text."""

    config: EnvelopeConfig
    outcomes: dict[str, JobOutcome]
    scheduled: dict[tuple[str, int, int], ScheduledModalModel]
    summary: dict[str, Any]
    text: str
    archive: Path
    executor: str
    workers: int
    seconds: float
    skipped: int


def _read_done(path: Path, config: EnvelopeConfig) -> dict[str, JobOutcome]:
    """The jobs already in an archive of a campaign with the same job settings (for --resume)."""
    with open_archive(path, kinds=[ARCHIVE_KIND]) as archive:
        stored = json.loads(archive.attrs["config_json"])
        stored_settings = _job_settings(stored)
        settings = json.loads(json.dumps(_job_settings(config.as_dict())))
        if stored_settings != settings:
            differ = sorted(key for key in settings if stored_settings.get(key) != settings[key])
            raise InputError(f"{path} was written with other job settings ({', '.join(differ)}); "
                             "resume with the same settings or write a new archive")
        done = {}
        for name, group in archive["runs"].items():
            run = read_run(group)
            nonlinear = read_value(group, "nonlinear_model") if "nonlinear_model" in group else None
            done[name] = JobOutcome.from_metrics(run.metrics, run.model, nonlinear)
    return done


def _write_outcome(path: Path, outcome: JobOutcome) -> None:
    with update_archive(path, kinds=[ARCHIVE_KIND]) as archive:
        run = write_run(archive, outcome.key, model=outcome.linear_model, metrics=outcome.metrics())
        if outcome.nonlinear_model is not None:
            write_value(run, "nonlinear_model", outcome.nonlinear_model)


def _schedule(config: EnvelopeConfig, outcomes: dict[str, JobOutcome], jobs: list[EnvelopeJob]):
    """Scheduled families per vehicle, order and seed, and their validation at the off-grid speeds."""
    families: dict[tuple[str, int, int], ScheduledModalModel] = {}
    off_grid = []
    params = {job.vehicle: job.params for job in jobs}
    for vehicle in params:
        for order in config.orders:
            for seed in config.seeds:
                grid_models = {o.speed: o.linear_model for o in outcomes.values()
                               if (o.vehicle, o.order, o.seed) == (vehicle, order, seed) and o.grid
                               and o.linear_model is not None}
                if len(grid_models) < 2:
                    continue
                family = schedule_models(grid_models)
                families[(vehicle, order, seed)] = family
                for speed in config.off_grid:
                    records, _ = job_records(params[vehicle], speed, seed, config.amplitude_fraction,
                                             config.duration, config.dt)
                    model = family.model_at(speed)
                    direct = next((o for o in outcomes.values() if (o.vehicle, o.order, o.seed, o.speed)
                                   == (vehicle, order, seed, speed)), None)
                    off_grid.append({
                        "vehicle": vehicle, "order": order, "seed": seed, "speed": speed,
                        "validation_R": float(np.mean(explained_percent(model, records["validation"]))),
                        "identification_R": float(np.mean(explained_percent(model, records["identification"]))),
                        "direct_validation_R": None if direct is None else direct.linear_validation_R,
                        "modes": [{"frequency_hz": f, "damping": d} for f, d in _mode_pairs(model)],
                    })
    return families, off_grid


def _eigenvalue(frequency_hz: float, damping: float) -> complex:
    omega = 2 * math.pi * frequency_hz
    if not math.isfinite(damping):
        return complex(0.0, omega)
    if damping >= 1.0:  # a real pole (or an overdamped pair's slower pole): on the real axis
        return complex(-damping * omega, 0.0)
    return complex(-damping * omega, omega * math.sqrt(1.0 - damping * damping))


def mode_comparison(modes: Sequence[tuple[float, float]], vehicle_modes: dict[str, tuple[float, float]]) -> list[dict]:
    """For each vehicle mode, the identified mode nearest to it in the complex plane, side by side."""
    comparison = []
    if not modes:
        return comparison
    candidates = [_eigenvalue(*mode) for mode in modes]
    for label, (frequency, damping) in vehicle_modes.items():
        target = _eigenvalue(frequency, damping)
        k = int(np.argmin([abs(c - target) for c in candidates]))
        comparison.append({"label": label, "vehicle_frequency_hz": frequency, "vehicle_damping": damping,
                           "identified_frequency_hz": modes[k][0], "identified_damping": modes[k][1],
                           "frequency_error": modes[k][0] / frequency - 1.0, "damping_error": modes[k][1] - damping})
    return comparison


def _rows(config: EnvelopeConfig, outcomes: dict[str, JobOutcome]) -> list[dict[str, Any]]:
    """One row per vehicle, speed and order: R averaged over seeds, modes of the first seed."""
    groups: dict[tuple[str, float, int], list[JobOutcome]] = {}
    for outcome in outcomes.values():
        groups.setdefault((outcome.vehicle, outcome.speed, outcome.order), []).append(outcome)
    rows = []
    for (vehicle, speed, order), members in sorted(groups.items()):
        members.sort(key=lambda o: o.seed)

        def mean(name: str) -> float | None:
            values = [getattr(o, name) for o in members if getattr(o, name) is not None]
            return float(np.mean(values)) if values else None

        first = members[0]
        rows.append({
            "vehicle": vehicle, "speed": speed, "order": order, "grid": first.grid,
            "linear_validation_R": mean("linear_validation_R"),
            "nonlinear_validation_R": mean("nonlinear_validation_R"),
            "linear_identification_R": mean("linear_identification_R"),
            "nonlinear_identification_R": mean("nonlinear_identification_R"),
            "modes": [{"frequency_hz": f, "damping": d} for f, d in first.modes],
            "vehicle_modes": [{"label": label, "frequency_hz": f, "damping": d}
                              for label, (f, d) in first.vehicle_modes.items()],
            "mode_comparison": mode_comparison(first.modes, first.vehicle_modes),
            "amplitude_deg": math.degrees(first.amplitude),
            "seconds": float(np.mean([o.seconds for o in members])),
            "error": "; ".join(o.error for o in members if o.error) or None,
        })
    return rows


def _text(config: EnvelopeConfig, summary: dict[str, Any], result_line: str) -> str:
    lines = [f"Envelope campaign: steer at {config.amplitude_fraction:g} of the grip limit, orders "
             f"{', '.join(map(str, config.orders))}, seeds {', '.join(map(str, config.seeds))}, "
             f"{config.duration:g} s records"]
    for vehicle in dict.fromkeys(row["vehicle"] for row in summary["rows"]):
        lines.append(f"\n{vehicle}")
        lines.append(f"{'v m/s':>6} {'n':>2} {'R val lin':>9} {'R val nl':>9}  identified modes (Hz / damping)"
                     "            vehicle: yaw-sideslip, roll")
        for row in summary["rows"]:
            if row["vehicle"] != vehicle:
                continue
            modes = ", ".join(f"{m['frequency_hz']:.2f}/{m['damping']:.2f}" for m in row["modes"]) or "(failed)"
            own = ", ".join(f"{m['frequency_hz']:.2f}/{m['damping']:.2f}" for m in row["vehicle_modes"])
            mark = "" if row["grid"] else " (off-grid)"
            lines.append(f"{row['speed']:>6g} {row['order']:>2} {percent_text(row['linear_validation_R']):>9} "
                         f"{percent_text(row['nonlinear_validation_R']):>9}  {modes:<40} {own}{mark}")
    scheduled = summary["scheduled"]
    if scheduled["off_grid"]:
        lines.append(f"\nscheduled models (grid {', '.join(f'{v:g}' for v in scheduled['grid_speeds'])} m/s) "
                     "at off-grid speeds: validation R, scheduled against identified there")
        for item in scheduled["off_grid"]:
            lines.append(f"  {item['vehicle']} n = {item['order']} seed {item['seed']} at {item['speed']:g} m/s: "
                         f"{percent_text(item['validation_R'])} against {percent_text(item['direct_validation_R'])}")
    lines.append(result_line)
    return "\n".join(lines)


def run_campaign(
    config: EnvelopeConfig | None = None,
    *,
    out: str | Path | None = None,
    resume: bool = False,
    executor: str = "process",
    workers: int | None = None,
    scheduler: str | None = None,
    on_job: Callable[[JobOutcome, int, int], None] | None = None,
) -> EnvelopeResult:
    """Run an envelope campaign and write its archive (one group per job, as jobs finish).

    Parameters
    ----------
    out : str or Path, optional
        The archive (default ``envelope.h5`` under the results folder).
    resume : bool
        Skip the jobs already in ``out`` (written with the same job settings);
        without it an existing archive is an error.
    executor : {"process", "dask"}
    workers : int, optional
        Processes of the pool or of the local Dask cluster (default: the
        cores, at most the jobs); ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running Dask scheduler (``executor="dask"``).
    on_job : callable, optional
        Called in this process after each job is archived: ``(outcome, done, total)``.
    """
    config = config or EnvelopeConfig()
    if executor not in EXECUTORS:
        raise InputError(f"unknown executor {executor!r}; use one of {', '.join(EXECUTORS)}")
    if scheduler and executor != "dask":
        raise InputError("a scheduler address needs --executor dask")
    if workers is not None:
        whole_number(workers, "workers", 1)
    started = time.perf_counter()
    jobs = plan_jobs(config)
    path = results_path(out, "envelope.h5")
    if path.is_dir():
        raise InputError(f"{path} is a directory: --out names the campaign's archive file")
    with archive_lock(path):  # one writer per campaign archive: a second campaign on it is refused, naming the holder
        if path.exists() and not resume:
            raise InputError(f"{path} exists: pass --resume to continue that campaign, or another --out")
        outcomes = _read_done(path, config) if path.exists() else {}
        if not path.exists():
            with write_archive(path, kind=ARCHIVE_KIND, config=config.as_dict(), seeds=list(config.seeds)):
                pass
        known = {job.key for job in jobs}
        outcomes = {key: outcome for key, outcome in outcomes.items() if key in known}
        skipped = len(outcomes)
        pending = sorted((job for job in jobs if job.key not in outcomes), key=lambda job: -_job_cost(job))
        count = workers or max(1, min(len(pending), os.cpu_count() or 1))

        def done(outcome: JobOutcome) -> None:
            _write_outcome(path, outcome)
            outcomes[outcome.key] = outcome
            if on_job is not None:
                on_job(outcome, len(outcomes), len(jobs))

        if pending:
            if executor == "dask":
                _run_dask(pending, done, scheduler=scheduler, workers=count)
            else:
                _run_process_pool(pending, count, done)
        families, off_grid = _schedule(config, outcomes, jobs)
        seconds = time.perf_counter() - started
        summary = {
            "executor": executor,
            "jobs": len(jobs),
            "seconds": seconds,
            "rows": _rows(config, outcomes),
            "scheduled": {"grid_speeds": list(config.speeds), "off_grid": off_grid},
        }
        where = f"on {scheduler}" if scheduler else f"on {count} worker(s)"
        result_line = (f"\n{len(jobs)} jobs ({skipped} already in the archive) in {seconds:.1f} s, {executor} {where}; "
                       f"wrote {path}")
        return EnvelopeResult(config, outcomes, families, summary, _text(config, summary, result_line), path, executor,
                              count, seconds, skipped)
