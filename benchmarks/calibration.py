"""Calibrating the full vehicle to a whole drive (vehid.vehicle.drive_calibration): time and acceptance.

Three measurements, each from the plain prior a new user has: the baseline car with the car's mass
and axle positions (982 kg, 1.33 / 1.07 m from the centre of gravity, the race car's published
values), and nothing else.

* ``drive`` (default): a simulated 10-minute drive from rest to 60 m/s at 100 Hz
  (:func:`vehid.vehicle.drives.drive_from_rest`: braking at 0.8 g, corners to about 0.9 g, a stop midway:
  the load moving across the car enough to tell the tyres' load sensitivity from the front scale; the
  simulated car's centre of gravity is where the calibration's start puts it for such a drive)
  of a car built on that prior with aerodynamics (drag 0.7 m², downforce 0.2 / 0.3 m², which the
  prior file carries like the mass) and the parameters the calibration estimates set away from the
  start; yaw rate and lateral acceleration measured with white noise (0.005 rad/s, 0.3 m/s^2), the
  sideslip (0.0005 rad) scored but never fitted. Timed apart: ``compile_seconds``, the whole
  calibration of a 1-minute drive of the same car into an empty compile cache (the filter, its
  simulators and the scoring simulators, built and compiled, and the passes over 1 minute), and
  ``calibrate_seconds``, the 10-minute drive's calibration with the cache warm (wall and processor
  time, the C compiler's included). Figures: the prior, start and calibrated cars' hold-out NRMSE fits with the sideslip check,
  each parameter with its std, its error in std against the truth, and their correlations, the
  halves' estimates.
* ``--race-car``: the committed 80 s track log ``tests/data/race_car_250lm`` (its SOURCE.md names
  source and licence), its last 40 % held out, as ``vehid calibrate`` runs it.
* ``--log PATH``: any drive with the committed log's columns (``t,delta,vx,yawRate,ayCG,beta_true``
  and optionally ``axCG``, fed forward), e.g. the 550 s upstream record of the committed log.

Figures go to ``results/benchmarks.json`` under ``calibration_drive``, ``calibration_race_car`` and
``calibration_log``. ``--minutes M`` shortens the simulated drive.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from vehid.scenarios.benchmarking import record_figures
from vehid.vehicle.calibration import STIFFNESS_SCALES, held_stiffness_scales, vehicle_with
from vehid.vehicle.drive_calibration import DriveLog, calibrate_drive
from vehid.vehicle.drives import drive_from_rest, simulated_drive
from vehid.vehicle.parameters import vehicle_from_mapping

PLAIN_PRIOR = {"base": "baseline", "name": "race car prior",
               "chassis": {"mass": 982.0, "cg_to_front_axle": 1.33, "cg_to_rear_axle": 1.07}}
AERODYNAMICS = {"drag_area": 0.7, "front_downforce_area": 0.2, "rear_downforce_area": 0.3}
# The simulated car: what the calibration estimates set away from where it starts (the baseline's tyres,
# the yaw inertia m a b of the start) by 10-40 %, the tyres' curvature from the base tyre's -0.82 to -2.0
# (a tyre that stays nearly linear up to its grip): an understeering car (this rear-heavy car with equal
# tyres, near neutral, spins in the drive's hardest corners), the cornering scales the axles' levels at
# the start's PKY2 as the calibration has them, and the slip limiter the start gives a car.
TRUTH = {"tyre.front_cornering_scale": 0.6, "tyre.PKY2": 1.3, "tyre.friction_scale": 1.3,
         "chassis.yaw_inertia": 1250.0, "tyre.PEY1": -2.0}
QUANTITIES = ("yaw_rate", "lateral_acceleration")
NOISE = {"yaw_rate": 0.005, "lateral_acceleration": 0.3, "sideslip": 0.0005}
DT = 0.01
RACE_LOG = Path(__file__).resolve().parents[1] / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"


def _simulated_log(truth, minutes: float, seed: int) -> DriveLog:
    drive = drive_from_rest(duration=60.0 * minutes, dt=DT, top_speed=60.0, lateral_acceleration=8.5, braking=8.0,
                            wheelbase=truth.chassis.wheelbase, seed=seed)
    clean = simulated_drive(truth, drive, QUANTITIES + ("sideslip",))
    rng = np.random.default_rng(seed + 100)
    noisy = clean + np.array([NOISE[q] for q in QUANTITIES + ("sideslip",)]) * rng.standard_normal(clean.shape)
    return DriveLog(t=drive.t, steer=drive.steer, speed=drive.speed, outputs=noisy[:, :2],
                    channels=("yawRate", "ayCG"), quantities=QUANTITIES, acceleration=drive.acceleration,
                    checks={"beta_true": ("sideslip", noisy[:, 2])})


def _start_height(prior, log: DriveLog, validation: float = 0.4) -> float:
    """The centre-of-gravity height the calibration's start gives ``prior`` on ``log``."""
    from vehid.vehicle.drive_calibration import MIN_RUN_SECONDS, speed_runs, start_vehicle
    from vehid.vehicle.model import speed_limit

    runs = speed_runs(log.speed, 3.0, speed_limit(prior), int(round(MIN_RUN_SECONDS / log.dt)))
    split = int(round(log.n_samples * (1 - validation)))
    rows = np.concatenate([np.arange(a, min(b, split)) for a, b in runs if a < split])
    return start_vehicle(prior, log, rows, runs)[0].chassis.cg_height


def _figures(result, seconds: float, cpu_seconds: float, truth=None) -> dict:
    calibration = result.calibration
    figures: dict = {"calibrate_seconds": seconds, "calibrate_cpu_seconds": cpu_seconds,
                     "samples": int(result.predictions["start"].shape[0]), "samples_driven":
                     int(sum(b - a for a, b in result.runs)), "substeps": result.substeps,
                     "notes": list(result.notes), "warnings": list(result.warnings), "failure": result.failure,
                     "stages": [(label, len(stage.result.history)) for label, stage in result.stages]}
    for label, fits in result.fits.items():
        figures[f"{label}_holdout_nrmse_percent"] = None if not fits or not fits["validation"] else {
            **dict(zip(QUANTITIES, map(float, fits["validation"]["nrmse"]))),
            **{f"{channel} (not fitted)": value for channel, value in fits["validation"]["checks"].items()}}
    if calibration is not None:
        figures["parameters"] = calibration.parameters_dict()
        figures["correlation"] = calibration.correlation.tolist()
        figures["held"] = dict(calibration.held)
        meta = getattr(calibration.result, "meta", None) or {}
        figures["covariance"] = {key: meta.get(key) for key in
                                 ("covariance_inflation", "nis_per_output", "innovation_correlation_time")}
        if truth is not None:
            true = np.array([truth[name] for name in calibration.parameter_names])
            figures["truth"] = dict(zip(calibration.parameter_names, true.tolist()))
            figures["error_sigma"] = dict(zip(calibration.parameter_names,
                                              ((calibration.values - true) / calibration.std).tolist()))
    figures["halves"] = dict(result.halves)
    return figures


def _print(title: str, figures: dict) -> None:
    print(title)
    for line in figures["notes"]:
        print(f"  note: {line}")
    print(f"  {figures['samples_driven']} of {figures['samples']} samples driven, {figures['substeps']} RK4 "
          f"steps per sample; stages {figures['stages']}; {figures['calibrate_seconds']:.0f} s wall, "
          f"{figures['calibrate_cpu_seconds']:.0f} s CPU")
    print("  hold-out NRMSE fit (%):   " + "  ".join(f"{name:>22}" for name in
                                                     (figures.get("calibrated_holdout_nrmse_percent") or {})))
    for label in ("prior", "start", "calibrated"):
        row = figures.get(f"{label}_holdout_nrmse_percent")
        print(f"  {label:>10} car          " + ("not scored (its simulation is not finite)" if row is None else
                                               "  ".join(f"{value:22.1f}" for value in row.values())))
    names = list(figures.get("parameters", {}))
    for i, (name, row) in enumerate(figures.get("parameters", {}).items()):
        std = "held" if row["std"] is None else f"+/- {row['std']:.3g}"
        extra = ""
        if "truth" in figures:
            extra = f"  (true {figures['truth'][name]:.5g}, {figures['error_sigma'][name]:+.2f} std)"
        correlation = ", ".join(f"{value:+.2f}" for j, value in enumerate(figures["correlation"][i]) if j != i
                                and np.isfinite(value))
        print(f"  {name} = {row['value']:.5g} {std}{extra}; correlations {correlation or '-'}")
    for name, row in figures["halves"].items():
        shown = [f"{row[h][0]:.5g} +/- {row[h][1]:.2g}" if row[h] else "not determined" for h in ("first", "second")]
        apart = "" if row["difference_sigma"] is None else f" ({row['difference_sigma']:.1f} std apart)"
        print(f"  halves: {name} {shown[0]} | {shown[1]}{apart}")
    for line in figures["warnings"]:
        print(f"  warning: {line}")


def _cpu_seconds() -> float:
    """This process's processor time and that of its children waited for (the C compiler's)."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def _timed(prior, log):
    began, cpu = time.perf_counter(), _cpu_seconds()
    result = calibrate_drive(prior, log)
    return result, time.perf_counter() - began, _cpu_seconds() - cpu


def drive(minutes: float = 10.0, seed: int = 0) -> dict:
    """The simulated drive from rest (module notes): compile and calibration timed apart."""
    prior = vehicle_from_mapping({**PLAIN_PRIOR, "aerodynamics": AERODYNAMICS})
    start_like = dataclasses.replace(prior, drive=dataclasses.replace(prior.drive, slip_limit=0.1))
    truth = vehicle_with(start_like, list(TRUTH), list(TRUTH.values()))
    # the cornering scales are the axles' levels at the start's PKY2 (held_stiffness_scales), as the
    # calibration estimates them: the simulated car carries the scales that give them at its own PKY2
    scales = held_stiffness_scales(start_like, TRUTH["tyre.PKY2"], (TRUTH["tyre.front_cornering_scale"], 1.0))
    truth = vehicle_with(truth, STIFFNESS_SCALES, [float(scale) for scale in scales])
    began = time.perf_counter()
    log = _simulated_log(truth, minutes, seed)
    # the start lowers the centre of gravity of a car that needs more grip than the prior's: the truth
    # sits where the start will put it (a fixed point: the drive's accelerations hardly move with it)
    for _ in range(3):
        height = _start_height(prior, log)
        if abs(height - truth.chassis.cg_height) < 1e-6:
            break
        truth = dataclasses.replace(truth, chassis=dataclasses.replace(truth.chassis, cg_height=height))
        log = _simulated_log(truth, minutes, seed)
    simulate_seconds = time.perf_counter() - began
    previous = os.environ.get("VEHID_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="vehid-bench-") as cache:
        os.environ["VEHID_CACHE_DIR"] = cache
        try:
            short = _simulated_log(truth, 1.0, seed)
            _, compile_seconds, compile_cpu = _timed(prior, short)
            result, seconds, cpu = _timed(prior, log)
        finally:
            if previous is None:
                del os.environ["VEHID_CACHE_DIR"]
            else:
                os.environ["VEHID_CACHE_DIR"] = previous
    figures = {**_figures(result, seconds, cpu, TRUTH), "minutes": float(log.t[-1] - log.t[0]) / 60,
               "simulate_seconds": simulate_seconds, "compile_seconds": compile_seconds,
               "compile_cpu_seconds": compile_cpu}
    _print(f"simulated drive from rest: {figures['minutes']:.1f} min at {1 / DT:g} Hz; compile (1 min drive, empty "
           f"cache) {compile_seconds:.0f} s wall, {compile_cpu:.0f} s CPU", figures)
    print(f"figures in {record_figures('calibration_drive', figures)}")
    return figures


def _table_log(path: Path, skip: int) -> DriveLog:
    table = np.genfromtxt(path, delimiter=",", skip_header=skip, names=None)
    with open(path) as handle:
        columns = handle.readline().strip().split(",")
    column = {name: table[:, i] for i, name in enumerate(columns)}
    return DriveLog(t=column["t"], steer=column["delta"], speed=column["vx"],
                    outputs=np.column_stack([column["yawRate"], column["ayCG"]]), channels=("yawRate", "ayCG"),
                    quantities=QUANTITIES, acceleration=column.get("axCG"),
                    checks={"beta_true": ("sideslip", column["beta_true"])})


def real_log(path: Path, section: str, skip: int) -> dict:
    """A measured drive from the plain prior, as ``vehid calibrate`` runs it."""
    prior = vehicle_from_mapping(PLAIN_PRIOR)
    log = _table_log(path, skip)
    result, seconds, cpu = _timed(prior, log)
    figures = {**_figures(result, seconds, cpu), "log": path.name}
    _print(f"{path.name}: {log.n_samples} samples at {1 / log.dt:g} Hz from the plain prior", figures)
    print(f"figures in {record_figures(section, figures)}")
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="length of the simulated drive (default 10)")
    parser.add_argument("--race-car", action="store_true", help="calibrate to the committed race-car log instead")
    parser.add_argument("--log", type=Path, default=None, help="calibrate to this drive log instead")
    arguments = parser.parse_args()
    if arguments.race_car:
        real_log(RACE_LOG, "calibration_race_car", 2)
    elif arguments.log is not None:
        real_log(arguments.log, "calibration_log", 1)
    else:
        drive(arguments.minutes)
