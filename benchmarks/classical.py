"""Speed of the classical estimators, measured in one run on the same data.

- RLS updates per second, for the plain, square-root and UD' forms, on the ARX regression of the
  paper's linear example (17 parameters: na = 5, nb = 6 per input);
- seconds of the IEKF and the comparators ``arx``, ``rls``, ``n4sid`` and ``output-error`` (started from ARX)
  on the 50,000-sample linear example (100 s at 500 Hz, output 1, noise-free), with their fit R
  (eq. 17) to the record; medians of 3 runs after one warm-up.
The IEKF runs with its defaults (exact discretisation, up to 50 passes, stopping when settled).
Figures go to ``results/benchmarks.json`` under ``classical``.
"""

from __future__ import annotations

import os
import time

from vehid.identification.comparators import identify_with
from vehid.identification.classical.least_squares import arx_regressors
from vehid.identification.classical.recursive import recursive_least_squares
from vehid.scenarios.benchmarking import median_seconds, record_figures
from vehid.scenarios.linear_example import make_data

RLS_UPDATES = {"plain": 20_000, "sqrt": 5_000, "ud": 5_000}  # samples timed per form


def main() -> dict:
    data = make_data(0, outputs=(0,))[0]
    phi, target, _, _ = arx_regressors(data.u, data.y, na=5, nb=6)
    phi = phi / abs(phi).max(axis=0)
    updates_per_second = {}
    for form, count in RLS_UPDATES.items():
        seconds = median_seconds(lambda: recursive_least_squares(phi[:count], target[:count], form=form,
                                                                 keep_history=False), repeats=3)
        updates_per_second[form] = count / seconds
    methods = {}
    for method in ("iekf", "arx", "rls", "n4sid", "output-error"):
        results = []
        seconds = median_seconds(lambda: results.append(identify_with(data, method=method, order=5)), repeats=3)
        methods[method] = {"seconds": seconds, "fit_R_percent": float(results[-1].metrics.percentage_explanation[0])}
    figures = {
        "samples": data.n_samples,
        "rls_parameters": int(phi.shape[1]),
        "rls_updates_per_second": updates_per_second,
        "comparators": methods,
        "load_average_1min": os.getloadavg()[0],
    }
    print(f"classical estimators on the linear example ({data.n_samples} samples, output 1)")
    print("  RLS updates per second (17 parameters): "
          + ", ".join(f"{form} {rate:,.0f}" for form, rate in updates_per_second.items()))
    for method, values in methods.items():
        print(f"  {method:<13} {values['seconds']:7.3f} s   R = {values['fit_R_percent']:.4f} %")
    print(f"  (load average {figures['load_average_1min']:.2f} at {time.strftime('%H:%M:%S')})")
    path = record_figures("classical", figures)
    print(f"  figures written to {path}")
    return figures


if __name__ == "__main__":
    main()
