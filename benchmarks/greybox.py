"""Speed and accuracy of the grey-box IEKF: the single-track model on a 10-minute log at 100 Hz.

The log is simulated by the single-track model itself (speed 10 -> 40 m/s, 0-2 Hz random steer,
3 % white noise per output); the estimate starts 30 % off. Measures:
- compile: seconds to build and compile the filter pass and the simulator (into an empty cache);
- identify: median seconds of a whole identification (passes until the stop rule, the covariance
  pass), with the number of passes; target: below TARGET_SECONDS, so that a calibration of a
  full vehicle model on such a log, some ten times the parameters and states, stays within minutes;
- per_sample_us: the identification's time per sample and pass;
- errors: each parameter's error in reported standard deviations and relatively.
Figures go to ``results/benchmarks.json`` under ``greybox``.
"""

from __future__ import annotations

import os
import tempfile
import time

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.filtering.greybox import identify_greybox
from vehid.identification.filtering.greybox_structure import simulate_greybox
from vehid.scenarios.benchmarking import median_seconds, record_figures
from vehid.vehicle.manoeuvres import band_limited_noise
from vehid.vehicle.single_track import SingleTrackConfig, single_track_model

TARGET_SECONDS = 10.0
TRUTH = np.array([80_000.0, 100_000.0, 2500.0])


def make_log(config: SingleTrackConfig, minutes: float = 10.0, dt: float = 0.01) -> IOData:
    rng = np.random.default_rng(0)
    n = int(round(minutes * 60.0 / dt))
    t = dt * np.arange(n)
    steer = 0.02 * band_limited_noise(n, dt, 2.0, rng)
    speed = 10.0 + 30.0 * t / t[-1]
    record = IOData(t=t, u=np.column_stack([steer, speed]), y=np.zeros((n, 2)))
    y, _ = simulate_greybox(single_track_model(config), TRUTH, record)
    return record.replace(y=y + 0.03 * np.std(y, axis=0) * rng.standard_normal(y.shape))


def main() -> dict:
    config = SingleTrackConfig(1500.0, 1.2, 1.5)
    model = single_track_model(config)
    log = make_log(config)
    start = TRUTH * np.array([1.3, 0.7, 1.3])
    previous = os.environ.get("VEHID_CACHE_DIR")
    with tempfile.TemporaryDirectory(prefix="vehid-bench-") as cache:
        os.environ["VEHID_CACHE_DIR"] = cache
        began = time.perf_counter()
        identify_greybox(log.split(0.01)[0], model, start)  # builds and compiles the pass and the simulator
        compile_seconds = time.perf_counter() - began
        if previous is None:
            del os.environ["VEHID_CACHE_DIR"]
        else:
            os.environ["VEHID_CACHE_DIR"] = previous
    result = identify_greybox(log, model, start)
    seconds = median_seconds(lambda: identify_greybox(log, model, start), repeats=3)
    passes = result.passes_run + 1  # the covariance pass
    figures = {
        "samples": log.n_samples,
        "compile_seconds": compile_seconds,
        "identify_seconds": seconds,
        "target_seconds": TARGET_SECONDS,
        "passes": passes,
        "per_sample_us": seconds / (passes * log.n_samples) * 1e6,
        "error_sigma": ((result.parameters - TRUTH) / result.std).tolist(),
        "error_relative": (result.parameters / TRUTH - 1).tolist(),
    }
    print(f"greybox: {log.n_samples} samples, {passes} passes in {seconds:.2f} s (target {TARGET_SECONDS:g} s), "
          f"{figures['per_sample_us']:.2f} us per sample and pass; compile {compile_seconds:.1f} s")
    print("errors (sigma): " + ", ".join(f"{v:+.2f}" for v in figures["error_sigma"]))
    path = record_figures("greybox", figures)
    print(f"figures in {path}")
    return figures


if __name__ == "__main__":
    main()
