"""What uncertainty adds to an identification's time (target: less than 10 %).

On the 50,000-sample linear example (output 1, 10 % output noise, the
paper's Table 4 setting p = 0.001, 40 passes at most, normalised), and on
the same record by output error (started from the IEKF's model: its ARX
start is biased by the noise and fails): the identification is
timed with its covariance step switched off (the baseline) and as shipped,
plus the delta-method modes and gains, a 200-point frequency response with
bands and the residual tests: everything `vehid identify` adds, and the band
that reports add on top of it.
N4SID (on the noise-free record: the subspace fit fails on the noisy one)
is timed without a covariance (``bootstrap=0``) as the baseline and with
its default asymptotic covariance plus the same extras; its residual
bootstrap (on request) re-identifies the record once per replicate: 30
replicates are timed for the ratio they cost. N4SID's added seconds are also
given as a share of the whole `vehid identify --method n4sid` command on the
same record (read from CSV, identified, scored, summarised; in process).
Since a difference of two medians is as noisy as what it measures where the
fit's run-to-run spread is large, each step that output error's and N4SID's
uncertainty adds is also timed itself where it runs, right after the fit
(``output-error_steps``, ``n4sid_steps``): what `vehid identify` adds
(covariance, modes, residual tests) apart from the band that reports draw.
Baseline and shipped runs alternate (7 of each for the IEKF and output
error, 21 for N4SID, after one warm-up) and the medians are compared.
Figures go to ``results/benchmarks.json`` under ``uncertainty_cost``.
"""

from __future__ import annotations

import contextlib
import io
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import vehid.identification.comparators as comparators
import vehid.identification.filtering.iekf as iekf
from vehid.identification.comparators import identify_with
from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.segments import formal_method
from vehid.identification.models.delta_method import frequency_response_band
from vehid.scenarios.benchmarking import median_seconds, record_figures
from vehid.scenarios.cli import main as cli_main
from vehid.scenarios.linear_example import make_data
from vehid.scenarios.model_checks import model_residual_tests

FREQUENCIES = np.logspace(-1, 1.5, 200)


def _extras(model, data) -> None:
    model.uncertainty()
    frequency_response_band(model, FREQUENCIES)
    model_residual_tests(model, data)


def _alternating(bare, run, repeats: int) -> tuple[float, float, float]:
    """Medians of the baseline (covariance steps off) and the shipped run, timed in turn so that load drifts hit both.

    Also the baseline's interquartile range over its median: the run-to-run spread against which
    a difference of the two medians is read.
    """
    shipped = (iekf.iekf_parameter_covariance, comparators.fit_covariance)
    times: dict[str, list[float]] = {"bare": [], "run": []}
    run()  # warm-up: compiled pass and CasADi functions
    for _ in range(repeats):
        iekf.iekf_parameter_covariance = lambda *args, **kwargs: (None, None)
        comparators.fit_covariance = lambda *args, **kwargs: (None, formal_method("switched off"))
        try:
            started = time.perf_counter()
            bare()
            times["bare"].append(time.perf_counter() - started)
        finally:
            iekf.iekf_parameter_covariance, comparators.fit_covariance = shipped
        started = time.perf_counter()
        run()
        times["run"].append(time.perf_counter() - started)
    quartiles = statistics.quantiles(times["bare"], n=4)
    baseline = statistics.median(times["bare"])
    return baseline, statistics.median(times["run"]), (quartiles[2] - quartiles[0]) / baseline


def _added_steps(identify, covariance: str, record, repeats: int) -> dict:
    """The seconds of each step uncertainty adds, timed where it runs (right after the fit), medians.

    ``identify()`` returns the model with its covariance, which the
    comparators' function named ``covariance`` computes (output error's
    ``fit_covariance``, the delete-one-block jackknife of its fit; N4SID's
    ``with_simulation_error_covariance``, the same of its simulation errors). A difference of two
    medians of whole runs carries the noise of two fits (their run-to-run
    spread, ``baseline_iqr_percent``, is as large as what is measured);
    the steps timed themselves do not. ``identify_s`` is what `vehid
    identify` adds (the covariance, the modes and gains, the residual tests);
    the frequency-response band is drawn by reports only, so it is given
    apart.
    """
    shipped = getattr(comparators, covariance)
    spent: dict[str, list[float]] = {"covariance": [], "modes": [], "residual_tests": [], "band": []}

    def timed(*args, **kwargs):
        started = time.perf_counter()
        try:
            return shipped(*args, **kwargs)
        finally:
            spent["covariance"].append(time.perf_counter() - started)

    def step(name, function) -> None:
        started = time.perf_counter()
        function()
        spent[name].append(time.perf_counter() - started)

    setattr(comparators, covariance, timed)
    try:
        for _ in range(repeats + 1):
            model = identify()
            step("modes", model.uncertainty)
            step("residual_tests", lambda: model_residual_tests(model, record))
            step("band", lambda: frequency_response_band(model, FREQUENCIES))
    finally:
        setattr(comparators, covariance, shipped)
    medians = {f"{name}_s": statistics.median(values[1:]) for name, values in spent.items()}  # first: warm-up
    medians["identify_s"] = medians["covariance_s"] + medians["modes_s"] + medians["residual_tests_s"]
    return medians


def _command_share(record, estimator: dict) -> dict:
    """What N4SID's uncertainty adds, as a share of the `vehid identify --method n4sid` command that a user runs.

    The command (in process, after a warm-up; interpreter start-up excluded) reads the record from a
    CSV file, identifies, scores and summarises; the added seconds are the estimator-level difference
    measured above, since the command cannot switch its residual tests off.
    """
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "record.csv"
        np.savetxt(path, np.column_stack([record.t, record.u, record.y]), delimiter=",",
                   header="t,u1,u2,y1", comments="")
        arguments = ["identify", str(path), "--inputs", "u1,u2", "--outputs", "y1", "--method", "n4sid", "--order", "5",
                     "--json", "--quiet"]

        def command() -> None:
            with contextlib.redirect_stdout(io.StringIO()):
                if cli_main(arguments) != 0:
                    raise RuntimeError("the identify command failed on the benchmark record")

        seconds = median_seconds(command, repeats=7)
    added = estimator["with_uncertainty_s"] - estimator["baseline_s"]
    return {"seconds": seconds, "added_s": added, "added_percent_of_command": 100 * added / seconds,
            "steps_identify_percent_of_command": 100 * estimator["steps"]["identify_s"] / seconds}


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

    clean = make_data(0, outputs=(0,))[0]

    def run_n4sid():
        _extras(identify_with(clean, method="n4sid", order=5).model, clean)

    figures = {}
    for name, run, bare, repeats in (
        ("iekf", run_iekf, lambda: identify_iekf(data, structure, options=options, parameter_covariance=False), 7),
        ("output-error", run_output_error, lambda: identify_with(data, method="output-error", order=5, start=start), 7),
        ("n4sid", run_n4sid, lambda: identify_with(clean, method="n4sid", order=5, bootstrap=0), 21),
    ):
        baseline, with_uncertainty, spread = _alternating(bare, run, repeats)
        figures[name] = {"baseline_s": baseline, "with_uncertainty_s": with_uncertainty,
                         "added_percent": 100 * (with_uncertainty / baseline - 1), "repeats": repeats,
                         "baseline_iqr_percent": 100 * spread}
    for name, identify, covariance, record, repeats in (
        ("output-error", lambda: identify_with(data, method="output-error", order=5, start=start).model,
         "fit_covariance", data, 7),
        ("n4sid", lambda: identify_with(clean, method="n4sid", order=5).model, "with_simulation_error_covariance",
         clean, 21),
    ):
        steps = _added_steps(identify, covariance, record, repeats)
        baseline = figures[name]["baseline_s"]
        figures[f"{name}_steps"] = {**steps, "identify_percent": 100 * steps["identify_s"] / baseline,
                                    "band_percent": 100 * steps["band_s"] / baseline}
    figures["n4sid_command"] = _command_share(clean, {**figures["n4sid"], "steps": figures["n4sid_steps"]})
    boot = median_seconds(lambda: identify_with(clean, method="n4sid", order=5, bootstrap=30), repeats=3)
    figures["n4sid_bootstrap_30"] = {"seconds": boot, "ratio": boot / figures["n4sid"]["baseline_s"]}
    for name, row in figures.items():
        print(name, {key: round(value, 4) for key, value in row.items()})
    record_figures("uncertainty_cost", figures)
    return figures


if __name__ == "__main__":
    main()
