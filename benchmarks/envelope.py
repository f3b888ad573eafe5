"""Benchmark: throughput of the envelope campaign on its executors.

Runs one small campaign (default: baseline, grid 10, 20, 30 m/s and the two
midpoints, orders 2-3, linear only, 30 s records: 10 jobs) as a user would
through ``run_campaign``, in one run:

* the local process pool with 1 and with 2 workers (the 1 -> 2 speed-up);
* a local Dask cluster of 2 workers (against the pool of 2: the price of the
  distributed engine);

and reports wall time, jobs per core-hour and the ratios. With ``--nonlinear``
the spline models join (much longer). Compiled filters are warmed first so
that no variant pays for compilation. Figures are printed and merged into
results/benchmarks.json under "envelope".
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.envelope import EnvelopeConfig, parse_speeds, run_campaign
from vehid.scenarios.handling_study import parse_orders


def measure(config: EnvelopeConfig) -> dict:
    with tempfile.TemporaryDirectory(prefix="vehid-envelope-bench-") as scratch:
        folder = Path(scratch)
        warm = EnvelopeConfig(**{**config.as_dict(), "speeds": (20.0, 30.0), "off_grid": ()})
        run_campaign(warm, out=folder / "warm.h5", workers=1)  # compile once, outside the timings
        figures: dict = {}
        for label, options in (("process_1", dict(executor="process", workers=1)),
                                ("process_2", dict(executor="process", workers=2)),
                                ("dask_local_2", dict(executor="dask", workers=2))):
            started = time.perf_counter()
            result = run_campaign(config, out=folder / f"{label}.h5", **options)
            seconds = time.perf_counter() - started
            jobs = result.summary["jobs"]
            figures[label] = {"seconds": seconds, "jobs": jobs, "workers": options["workers"],
                              "jobs_per_core_hour": jobs / (seconds * options["workers"] / 3600.0),
                              "mean_job_seconds": sum(o.seconds for o in result.outcomes.values()) / jobs}
    figures["speedup_1_to_2_workers"] = figures["process_1"]["seconds"] / figures["process_2"]["seconds"]
    figures["dask_to_pool_time_ratio"] = figures["dask_local_2"]["seconds"] / figures["process_2"]["seconds"]
    figures["campaign"] = config.as_dict()
    figures["load_average_1min_after"] = os.getloadavg()[0]  # the machine may be shared: context for the times
    return figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nonlinear", action="store_true", help="include the spline-nonlinear models")
    parser.add_argument("--duration", type=float, default=30.0)
    parser.add_argument("--speeds", default="10,20,30", help="grid speeds (midpoints join as off-grid jobs)")
    parser.add_argument("--orders", default="2-3")
    args = parser.parse_args(argv)
    config = EnvelopeConfig(speeds=parse_speeds(args.speeds), orders=parse_orders(args.orders),
                            nonlinear=args.nonlinear, duration=args.duration)
    figures = measure(config)
    for label in ("process_1", "process_2", "dask_local_2"):
        f = figures[label]
        print(f"{label:>13}: {f['jobs']} jobs in {f['seconds']:.1f} s on {f['workers']} worker(s), "
              f"{f['jobs_per_core_hour']:.0f} jobs per core-hour (mean job {f['mean_job_seconds']:.1f} s)")
    print(f"speed-up 1 -> 2 workers (process pool): {figures['speedup_1_to_2_workers']:.2f}x")
    print(f"Dask local cluster against the process pool, 2 workers: {figures['dask_to_pool_time_ratio']:.2f}x the time")
    print(f"load average after the runs: {figures['load_average_1min_after']:.1f}")
    path = record_figures("envelope_nonlinear" if args.nonlinear else "envelope", figures)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
