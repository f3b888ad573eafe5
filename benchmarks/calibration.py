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
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

from vehid.scenarios.benchmarking import record_figures
from vehid.vehicle.calibration import calibrate_vehicle, calibration_record, vehicle_with
from vehid.vehicle.manoeuvres import speed_cycle
from vehid.vehicle.parameters import baseline
from vehid.vehicle.replay import replay

QUANTITIES = ("yaw_rate", "lateral_acceleration", "roll_angle")
PARAMETERS = ("tyre.PKY1", "tyre.front_cornering_scale", "chassis.yaw_inertia", "chassis.roll_inertia",
              "suspension.front_anti_roll_bar")
FACTORS = (1.2, 0.85, 1.25, 0.8, 1.15)
DT = 0.01


def _value(params, name: str) -> float:
    section, _, field_name = name.partition(".")
    return float(getattr(getattr(params, section), field_name))


def make_log(truth, minutes: float):
    """Consecutive 40 s speed cycles of different steer seeds, each replayed from straight running."""
    records = []
    rng = np.random.default_rng(0)
    for seed in range(max(1, int(round(minutes * 60 / 40)))):
        cycle = speed_cycle(duration=40.0, dt=DT, amplitude=np.deg2rad(1.0), seed=seed)
        record = replay(truth, cycle.steer, cycle.speed, DT)  # as a log: no hold delay in the record
        clean = np.column_stack([record.y[:, record.output_names.index(q)] for q in QUANTITIES])
        noisy = clean + 0.05 * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
        records.append(calibration_record(record.u[:, 0], record.y[:, record.output_names.index("speed")],
                                          noisy, DT, QUANTITIES))
    return records


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
    main(parser.parse_args().minutes)
