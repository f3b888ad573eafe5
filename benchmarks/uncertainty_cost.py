"""What uncertainty adds to an identification's time (target: less than 10 %).

On the 50,000-sample linear example (output 1, 10 % output noise, the
paper's Table 4 setting p = 0.001, 40 passes at most, normalised), and on
the same record by output error (started from the IEKF's model: its ARX
start is biased by the noise and fails): the identification is
timed with its covariance step switched off (the baseline) and as shipped,
plus the delta-method modes and gains, a 200-point frequency response with
bands and the residual tests, i.e. everything `vehid identify` adds.
N4SID's bootstrap re-identifies the record once per replicate, so its cost
is that many subspace fits; it is timed and reported as the ratio it is.
Baseline and shipped runs alternate (7 of each for the IEKF, 3 for output
error, after one warm-up) and the medians are compared. Figures go to ``results/benchmarks.json``
under ``uncertainty_cost``.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

import vehid.identification.comparators as comparators
import vehid.identification.iekf as iekf
from vehid.identification.comparators import identify_with
from vehid.identification.iekf import IEKFOptions, identify_iekf
from vehid.identification.modal import ModalStructure
from vehid.identification.uncertainty import frequency_response
from vehid.scenarios.benchmarking import median_seconds, record_figures
from vehid.scenarios.linear_example import make_data
from vehid.scenarios.model_checks import model_residual_tests

FREQUENCIES = np.logspace(-1, 1.5, 200)


def _extras(model, data) -> None:
    model.uncertainty()
    frequency_response(model, FREQUENCIES)
    model_residual_tests(model, data)


def _alternating(bare, run, repeats: int) -> tuple[float, float]:
    """Medians of the baseline (covariance steps off) and the shipped run, timed in turn so that load drifts hit both."""
    shipped = (iekf.iekf_parameter_covariance, comparators.gauss_newton_covariance)
    times: dict[str, list[float]] = {"bare": [], "run": []}
    run()  # warm-up: compiled pass and CasADi functions
    for _ in range(repeats):
        iekf.iekf_parameter_covariance = lambda *args, **kwargs: None
        comparators.gauss_newton_covariance = lambda *args, **kwargs: None
        try:
            started = time.perf_counter()
            bare()
            times["bare"].append(time.perf_counter() - started)
        finally:
            iekf.iekf_parameter_covariance, comparators.gauss_newton_covariance = shipped
        started = time.perf_counter()
        run()
        times["run"].append(time.perf_counter() - started)
    return statistics.median(times["bare"]), statistics.median(times["run"])


def main() -> dict:
    data = make_data(0, outputs=(0,), noise_ratio=0.1)[0]
    structure = ModalStructure.from_pattern("all-ones", 5, 2, 1)
    options = IEKFOptions(p=1e-3, passes=40, normalize=True)

    def run_iekf():
        result = identify_iekf(data, structure, options=options)
        _extras(result.model, data)

    start = identify_iekf(data, structure, options=options).model.with_parameter_covariance(None)

    def run_output_error():
        _extras(identify_with(data, method="output-error", order=5, start=start).model, data)

    figures = {}
    for name, run, bare, repeats in (
        ("iekf", run_iekf, lambda: identify_iekf(data, structure, options=options), 7),
        ("output-error", run_output_error, lambda: identify_with(data, method="output-error", order=5, start=start), 3),
    ):
        baseline, with_uncertainty = _alternating(bare, run, repeats)
        figures[name] = {"baseline_s": baseline, "with_uncertainty_s": with_uncertainty,
                         "added_percent": 100 * (with_uncertainty / baseline - 1), "repeats": repeats}
    clean = make_data(0, outputs=(0,))[0]  # the subspace fit needs it: it fails on this noisy record
    plain = median_seconds(lambda: identify_with(clean, method="n4sid", order=5, bootstrap=1), repeats=3)
    boot = median_seconds(lambda: identify_with(clean, method="n4sid", order=5), repeats=3)
    figures["n4sid"] = {"one_replicate_s": plain, "bootstrap_30_s": boot, "ratio": boot / plain}
    for name, row in figures.items():
        print(name, {key: round(value, 3) for key, value in row.items()})
    record_figures("uncertainty_cost", figures)
    return figures


if __name__ == "__main__":
    main()
