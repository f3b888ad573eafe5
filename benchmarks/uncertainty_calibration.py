"""Calibration of the 95 % intervals of mode frequency and damping (IEKF, output error, N4SID).

On the known system of :mod:`vehid.scenarios.calibration` (two modes, one output,
60 s at 100 Hz), for each noise level (10 % and 30 % of the output's RMS)
and each of ``REALISATIONS`` seeds, a new input and noise are drawn and the
methods identify the true structure (the IEKF as `vehid identify` runs it by
default: means removed, p by cross-validation; how often each p was taken is
listed under the table); the table gives the share of
realisations whose 95 % interval (estimate +/- 1.96 std by the delta
method) holds the true value, per mode, with the ratio of the empirical
spread over realisations to the mean reported standard deviation (1 when
calibrated) and the bias over the spread.

With 50 realisations a calibrated 95 % interval covers 43-50 of them
(binomial 99 % range), i.e. 86-100 %.

Last row sets run the IEKF at 30 % noise across p: the paper's absolute
settings (time in seconds, normalised signals) at p = 1e-3 (40 passes) and
p = 1, and the default unit-invariant ones at p = 1e-6, 1e-4 and 1e-2.

``python uncertainty_calibration.py [REALISATIONS [WORKERS]]``: the
realisations run in WORKERS processes (default 1).

Writes ``results/uncertainty_calibration.json`` and ``.md`` and the section
``uncertainty_calibration`` of ``results/benchmarks.json``.
"""

from __future__ import annotations

import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor

from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.calibration import (COMMAND_LINE_SETTINGS, IEKF_SETTINGS, coverage, identify_realisation,
                                        make_record)
from vehid.scenarios.paths import results_directory

NOISE_RATIOS = (0.1, 0.3)
REALISATIONS = 50
#: The p sweep at 30 % noise: label -> IEKF settings.
P_SWEEP = {
    "iekf p = 1e-3 (seconds)": IEKF_SETTINGS,
    "iekf p = 1 (seconds)": {**IEKF_SETTINGS, "p": 1.0},
    "iekf p = 1e-6 (invariant)": {**COMMAND_LINE_SETTINGS, "p": 1e-6},
    "iekf p = 1e-4 (invariant)": {**COMMAND_LINE_SETTINGS, "p": 1e-4},
    "iekf p = 1e-2 (invariant)": {**COMMAND_LINE_SETTINGS, "p": 1e-2},
}


def table(figures: dict) -> str:
    lines = [
        "| noise | method | realisations | quantity | mode 1 coverage | mode 2 coverage | spread / reported (1, 2) | bias / spread (1, 2) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for level, methods in figures["levels"].items():
        for method, result in methods.items():
            for name in ("frequency_hz", "damping"):
                row = result[name]
                lines.append(
                    f"| {level} | {method} | {result['realisations']} | {name} | {100 * row['coverage'][0]:.0f} % | {100 * row['coverage'][1]:.0f} % | "
                    f"{row['spread_over_reported'][0]:.2f}, {row['spread_over_reported'][1]:.2f} | "
                    f"{row['bias_over_spread'][0]:+.2f}, {row['bias_over_spread'][1]:+.2f} |"
                )
    return "\n".join(lines)


def _level(seed: int, ratio: float) -> dict:
    data, _ = make_record(seed, ratio)
    return identify_realisation(data)


def _sweep(seed: int) -> dict:
    data, _ = make_record(seed, 0.3)
    return {label: identify_realisation(data, iekf_settings=settings, iekf_only=True)["iekf"]
            for label, settings in P_SWEEP.items()}


def main(realisations: int = REALISATIONS, workers: int = 1) -> dict:
    started = time.perf_counter()
    levels = {}
    seeds = list(range(realisations))
    with ProcessPoolExecutor(workers) as pool:
        for ratio in NOISE_RATIOS:
            runs: dict[str, list] = {"iekf": [], "output-error": [], "n4sid": []}
            for result in pool.map(_level, seeds, [ratio] * realisations):
                for method, realisation in result.items():
                    runs[method].append(realisation)
            levels[f"{int(round(100 * ratio))} %"] = {method: coverage(values) for method, values in runs.items() if values}
        runs = {label: [] for label in P_SWEEP}
        for result in pool.map(_sweep, seeds):
            for label, realisation in result.items():
                runs[label].append(realisation)
    levels["30 %"].update({label: coverage(values) for label, values in runs.items()})
    figures = {"realisations": realisations, "iekf_settings": COMMAND_LINE_SETTINGS, "p_sweep": P_SWEEP, "levels": levels,
               "seconds": time.perf_counter() - started}
    chosen = "; ".join(f"{level}: {levels[level]['iekf'].get('p_counts')}" for level in levels)
    text = table(figures) + f"\n\nIEKF p chosen by cross-validation (p: realisations): {chosen}"
    print(text)
    directory = results_directory()
    (directory / "uncertainty_calibration.json").write_text(json.dumps(figures, indent=2) + "\n")
    (directory / "uncertainty_calibration.md").write_text(
        f"95 % interval coverage over {realisations} realisations per noise level\n\n{text}\n")
    record_figures("uncertainty_calibration", figures)
    return figures


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else REALISATIONS, int(sys.argv[2]) if len(sys.argv) > 2 else 1)
