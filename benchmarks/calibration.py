"""Time of a full-vehicle calibration (vehid.vehicle.calibration) of a 10-minute log at 100 Hz.

The log is the source model's own: the baseline car with five parameters 15-25 % off drives repeated
speed cycles (20 -> 30 -> 12 -> 20 m/s) under 1 deg RMS random steer, measured as yaw rate, lateral
acceleration and roll angle with 5 % white noise; the calibration starts from the nominal car.
Measures:
- compile_seconds: building and compiling the filter pass and simulator into an empty cache (on a
  record of a few samples);
- calibrate_seconds: the whole calibration (passes to the stop rule, covariance pass, identifiability
  check), with the passes run; goal: minutes on two cores;
- per_sample_us: time per sample and pass;
- error_sigma, error_relative: each parameter's error in reported standard deviations and relatively.
Figures go to ``results/benchmarks.json`` under ``calibration``. ``--minutes M`` shortens the log.

``--race-car`` calibrates instead a race car to the committed track log ``tests/data/race_car_250lm``
(80 s at 100 Hz, 16-60 m/s, to 1.38 g; its SOURCE.md names source and licence), its last 40 % held
out as in ``benchmarks/real_car.py``. The car's mass and geometry are not published: the vehicle
below is assumed (stated in :func:`race_car`); the calibration estimates its tyres' cornering
stiffness, front share and friction and its yaw inertia. Figures (``calibration_race_car``): the
hold-out NRMSE fit of yaw rate and lateral acceleration (the single-track and scheduled models'
measure in ``real_car``) and of the measured sideslip, which the calibration never sees.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from vehid.scenarios.benchmarking import record_figures
from vehid.vehicle.calibration import calibrate_vehicle, simulated_log, vehicle_with
from vehid.vehicle.manoeuvres import speed_cycle
from vehid.vehicle.parameters import baseline

QUANTITIES = ("yaw_rate", "lateral_acceleration", "roll_angle")
PARAMETERS = ("tyre.PKY1", "tyre.front_cornering_scale", "chassis.yaw_inertia", "chassis.roll_inertia",
              "suspension.front_anti_roll_bar")
FACTORS = (1.2, 0.85, 1.25, 0.8, 1.15)
DT = 0.01


def _value(params, name: str) -> float:
    section, _, field_name = name.partition(".")
    return float(getattr(getattr(params, section), field_name))


def make_log(truth, minutes: float):
    """Consecutive 40 s speed cycles of different steer seeds, each from straight running (simulated_log)."""
    records = []
    rng = np.random.default_rng(0)
    for seed in range(max(1, int(round(minutes * 60 / 40)))):
        cycle = speed_cycle(duration=40.0, dt=DT, amplitude=np.deg2rad(1.0), seed=seed)
        record, clean = simulated_log(truth, cycle.steer, cycle.speed, DT, QUANTITIES)
        noisy = clean + 0.05 * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
        records.append(dataclasses.replace(record, y=noisy))
    return records


RACE_LOG = Path(__file__).resolve().parents[1] / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
RACE_PARAMETERS = ("tyre.PKY1", "tyre.front_cornering_scale", "tyre.friction_scale", "chassis.yaw_inertia")
RACE_VALIDATION = 0.4
RACE_HANDLING_SPEEDS = (20.0, 30.0, 40.0)  # within the log's 16-61 m/s


def race_car():
    """A rear-driven race car: every value assumed (none is published for the logged car).

    1100 kg and 1.2 m from the centre of gravity to each axle, as the single-track runs of
    ``benchmarks/real_car.py`` assume; yaw inertia ``m a b`` (radius of gyration sqrt(ab)); a low
    centre of gravity (0.35 m) on 1.6 m tracks; sticky tyres (friction scale 1.5: about 1.3 g
    without downforce); drag area 0.8 m^2 and downforce areas 0.6 / 0.9 m^2 (some 30 % of the
    weight at 60 m/s); a rigid steering, since the log measures the road-wheel angle.
    """
    base = baseline()
    chassis = dataclasses.replace(base.chassis, mass=1100.0, cg_to_front_axle=1.2, cg_to_rear_axle=1.2,
                                  yaw_inertia=1100.0 * 1.2 * 1.2, roll_inertia=300.0, pitch_inertia=1300.0,
                                  cg_height=0.35, front_track=1.6, rear_track=1.6)
    return dataclasses.replace(
        base, name="race car (assumed)", chassis=chassis,
        tyre=dataclasses.replace(base.tyre, friction_scale=1.5),
        drive=dataclasses.replace(base.drive, front_drive_share=0.0),
        steering=dataclasses.replace(base.steering, compliance=0.0),
        aerodynamics=dataclasses.replace(base.aerodynamics, drag_area=0.8, front_downforce_area=0.6,
                                         rear_downforce_area=0.9),
    )


def race(substeps: int = 0) -> dict:
    """Calibrate :func:`race_car` to the track log; hold-out fits of the measured channels."""
    from vehid.identification.assessment.metrics import nrmse_fit
    from vehid.identification.filtering.greybox import GreyBoxOptions, simulate_greybox
    from vehid.vehicle.calibration import calibration_model, calibration_record
    from vehid.vehicle.handling import source_handling
    from vehid.vehicle.replay import replay_substeps

    table = np.genfromtxt(RACE_LOG, delimiter=",", skip_header=2)
    dt = float(np.median(np.diff(table[:, 0])))
    steer, speed, measured, sideslip = table[:, 1], table[:, 2], table[:, [3, 4]], table[:, 5]
    quantities = ("yaw_rate", "lateral_acceleration")
    prior = race_car()
    substeps = substeps or replay_substeps(prior, dt, float(speed.max()))  # RK4 stable at the top speed
    record = calibration_record(steer, speed, measured, dt, quantities)
    n_estimation = int(round((1 - RACE_VALIDATION) * record.n_samples))
    estimation = dataclasses.replace(record, t=record.t[:n_estimation], u=record.u[:n_estimation],
                                     y=record.y[:n_estimation])
    began = time.perf_counter()
    calibration = calibrate_vehicle(prior, estimation, quantities, parameters=RACE_PARAMETERS,
                                    options=GreyBoxOptions(substeps=substeps, coloured_residuals=True))
    seconds = time.perf_counter() - began
    # the held-out part, with the sideslip among the outputs (never fitted): simulated from straight running
    held = calibration_record(steer[n_estimation:], speed[n_estimation:],
                              np.column_stack([measured[n_estimation:], sideslip[n_estimation:]]), dt,
                              quantities + ("sideslip",))
    figures: dict = {"substeps": substeps, "calibrate_seconds": seconds, "held": dict(calibration.held),
                     "parameters": calibration.parameters_dict(), "warnings": list(calibration.warnings)}
    for label, vehicle in (("prior", prior), ("calibrated", calibration.vehicle)):
        model = calibration_model(vehicle, ("chassis.yaw_inertia",), quantities + ("sideslip",))
        predicted, _ = simulate_greybox(model, [vehicle.chassis.yaw_inertia], held, substeps=substeps)
        fits = nrmse_fit(held.y, predicted)
        figures[f"{label}_holdout_nrmse_percent"] = dict(zip(("yaw_rate", "lateral_acceleration", "sideslip"),
                                                             map(float, fits)))
    # the calibrated car's own handling (its linearisation, ISO 4138 quantities) where the log drove
    handling = source_handling(calibration.vehicle, RACE_HANDLING_SPEEDS, simulate=False)
    figures["handling"] = {
        f"{metrics.speed:g}": {"understeer_gradient_deg_per_g": metrics.understeer_gradient_deg_per_g,
                               "characteristic_speed_m_s": metrics.characteristic_speed_m_s,
                               "yaw_rate_gain_per_s": metrics.yaw_rate_gain}
        for metrics in handling.linearisation}
    print(f"race car: {n_estimation} samples calibrated in {seconds:.1f} s ({substeps} RK4 steps per sample)")
    for speed, row in figures["handling"].items():
        print(f"  calibrated car at {speed} m/s: understeer gradient {row['understeer_gradient_deg_per_g']:.2f} deg/g, "
              f"characteristic speed {row['characteristic_speed_m_s']:.1f} m/s, "
              f"yaw-rate gain {row['yaw_rate_gain_per_s']:.2f} 1/s")
    for name, row in figures["parameters"].items():
        print(f"  {name} = {row['value']:.5g} +/- {row['std'] if row['std'] is None else format(row['std'], '.3g')}")
    for label in ("prior", "calibrated"):
        row = figures[f"{label}_holdout_nrmse_percent"]
        print(f"  {label}: hold-out NRMSE fit yaw rate {row['yaw_rate']:.1f} %, lateral acceleration "
              f"{row['lateral_acceleration']:.1f} %, sideslip (not fitted) {row['sideslip']:.1f} %")
    print(f"figures in {record_figures('calibration_race_car', figures)}")
    return figures


def main(minutes: float = 10.0) -> dict:
    nominal = baseline()
    truth = vehicle_with(nominal, PARAMETERS, [_value(nominal, n) * f for n, f in zip(PARAMETERS, FACTORS)])
    began = time.perf_counter()
    records = make_log(truth, minutes)
    simulate_seconds = time.perf_counter() - began
    samples = sum(r.n_samples for r in records)
    previous = os.environ.get("VEHID_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="vehid-bench-") as cache:
        os.environ["VEHID_CACHE_DIR"] = cache
        began = time.perf_counter()
        calibrate_vehicle(nominal, records[0].split(0.01)[0], QUANTITIES, parameters=PARAMETERS)
        compile_seconds = time.perf_counter() - began
        if previous is None:
            del os.environ["VEHID_CACHE_DIR"]
        else:
            os.environ["VEHID_CACHE_DIR"] = previous
    began = time.perf_counter()
    calibration = calibrate_vehicle(nominal, records, QUANTITIES, parameters=PARAMETERS)
    seconds = time.perf_counter() - began
    passes = len(calibration.result.history) + 1
    true_values = np.array([_value(truth, n) for n in PARAMETERS])
    figures = {
        "minutes": samples * DT / 60,
        "samples": samples,
        "simulate_seconds": simulate_seconds,
        "compile_seconds": compile_seconds,
        "calibrate_seconds": seconds,
        "passes": passes,
        "per_sample_us": seconds / (passes * samples) * 1e6,
        "held": sorted(calibration.held),
        "error_sigma": ((calibration.values - true_values) / calibration.std).tolist(),
        "error_relative": (calibration.values / true_values - 1).tolist(),
    }
    print(f"calibration: {samples} samples ({figures['minutes']:.1f} min), {passes} passes in {seconds:.1f} s, "
          f"{figures['per_sample_us']:.1f} us per sample and pass; compile {compile_seconds:.1f} s")
    print("errors (sigma): " + ", ".join(f"{v:+.2f}" for v in figures["error_sigma"]))
    print(f"figures in {record_figures('calibration', figures)}")
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="length of the log (default 10)")
    parser.add_argument("--race-car", action="store_true", help="calibrate the race car to the track log instead")
    arguments = parser.parse_args()
    if arguments.race_car:
        race()
    else:
        main(arguments.minutes)
