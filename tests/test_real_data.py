"""Identification on public measured records (tests/data), scored on held-out data.

The raw published files go straight to ``vehid identify`` with default
options and ``--validation 0.3`` (the cascaded tanks: their published
validation record through ``--validation-file``), exactly as
``benchmarks/real_data.py`` runs them (its modules are loaded here), and the
command's own ``validation_fit_percent`` is checked: MATLAB ``compare``'s
NRMSE fit on the held-out samples, simulated from the least-squares initial
state. Floors are measured hold-out fits minus a margin stated below.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import load_benchmark_module, run_vehid

from vehid.identification import IOData
from vehid.identification.assessment.metrics import nrmse_fit

ROOT = Path(__file__).resolve().parent.parent


records = load_benchmark_module("_real_records")
baselines = load_benchmark_module("_baselines")
benchmark = load_benchmark_module("real_data")

# Sizes stated by the publishers (DaISy descriptions; the cascaded tanks' 2 x 1024 samples).
PUBLISHED_SHAPES = {"ballbeam": (1000, 1, 1), "dryer": (1000, 1, 1), "robot_arm": (1024, 1, 1),
                    "exchanger": (4000, 1, 1), "cd_player_arm": (2048, 2, 2), "cascaded_tanks": (2048, 1, 1)}


@pytest.mark.parametrize("entry", records.RECORD_SETS, ids=lambda e: e.name)
def test_committed_record_is_the_published_file(entry):
    """Each raw file is byte for byte the one its SOURCE.md names (SHA-256), with the published size."""
    folder = entry.file.parent
    source = (folder / "SOURCE.md").read_text()
    for data_file in sorted(p for p in folder.iterdir() if p.name != "SOURCE.md"):
        digest = hashlib.sha256(data_file.read_bytes()).hexdigest()
        assert re.search(rf"`{re.escape(data_file.name)}`[^\n]*\n?[^\n]*{digest}", source), data_file.name
    (u_est, y_est), (u_val, y_val) = records.load(entry)
    samples, n_u, n_y = PUBLISHED_SHAPES[entry.name]
    assert len(u_est) + len(u_val) == samples and u_est.shape[1] == n_u and y_est.shape[1] == n_y
    assert np.all(np.isfinite(u_est)) and np.all(np.isfinite(y_val))


def test_score_is_matlab_fit_and_recovers_the_initial_state():
    """The benchmark's fit equals the workbench's NRMSE fit, and the least-squares x0 of a known system is exact."""
    rng = np.random.default_rng(0)
    A = np.array([[0.9, 0.2], [-0.2, 0.9]])
    B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, -1.0]]), np.array([[0.1]])
    u = rng.standard_normal((200, 1))
    x0 = np.array([3.0, -2.0])
    forced, free = records.discrete_responses(A, B, C, D, u)
    y = forced + free @ x0
    fits, x0_hat = records.fit_from_estimated_state(forced, free, y)
    np.testing.assert_allclose(x0_hat, x0, rtol=1e-10)  # noise-free: exact up to rounding
    assert fits == pytest.approx([100.0], abs=1e-9)
    y_noisy = y + 0.3 * rng.standard_normal(y.shape)
    assert records.nrmse_fit(y_noisy, y) == pytest.approx(list(nrmse_fit(y_noisy, y)), rel=1e-12)


SPLIT_SETS = [entry for entry in records.RECORD_SETS if entry.validation_path_columns is None]


@pytest.mark.parametrize("entry", SPLIT_SETS, ids=lambda e: e.name)
def test_peers_and_identify_hold_out_the_same_samples(entry):
    """The benchmark's split is identify's (``IOData.split``), so peers and workbench validate on the same samples."""
    (u_est, _), (u_val, _) = records.load(entry)
    n = len(u_est) + len(u_val)
    data = IOData(t=np.arange(n, dtype=float), u=np.zeros((n, 1)), y=np.zeros((n, 1)))
    estimation, validation = data.split(1.0 - records.HOLDOUT)
    assert (estimation.n_samples, validation.n_samples) == (len(u_est), len(u_val))


def test_the_perturbation_summary_names_a_switched_decision_and_only_that():
    """A decision whose choice differs between two perturbed runs is named with both choices; an agreeing one not."""
    def run(fraction, fit, returned, schedule):
        margins = {"model_returned": {"choice": returned}, "p": {"choice": "p 1e-05", "q_schedule": schedule}}
        return {"perturbation": f"fraction {fraction}", "fraction": fraction, "validation_fit_percent": [fit],
                "decisions": benchmark.decisions_of({"decision_margins": margins})}

    summary = benchmark.perturbation_summary([run("0.3", 89.2, "start", "shrinking"),
                                              run("0.4", 84.7, "start", "constant")], {})
    assert summary["switched_decisions"] == {"p": ["p 1e-05, shrinking Q", "p 1e-05, constant Q"]}
    assert summary["default_range"] == pytest.approx(4.5, abs=1e-12)  # algebra on the two fits
    same = benchmark.perturbation_summary([run("0.3", 89.2, "start", "shrinking")] * 2, {})
    assert same["switched_decisions"] == {}


def test_each_peer_is_held_to_the_defaults_goals_at_the_same_fractions():
    """Range and worst gap to the best peer per peer, by hand. The best peers are C (85) at 0.3 and B (87)
    at 0.4: A 80/86 has range 6 and gaps -5/-1, B 79/87 range 8 and gaps -6/0; C has no fit at 0.4 and no
    verdict."""
    def row(fit):
        return {"validation_fit_percent": [fit]}

    peers = {"0.3": {"A": row(80.0), "B": row(79.0), "C": row(85.0)}, "0.4": {"A": row(86.0), "B": row(87.0)}}
    verdicts = benchmark.peers_against_the_goal(peers)
    assert verdicts["A"]["range"] == pytest.approx(6.0) and verdicts["A"]["worst_minus_best_peer"] == pytest.approx(-5.0)
    assert verdicts["B"]["range"] == pytest.approx(8.0) and verdicts["B"]["worst_minus_best_peer"] == pytest.approx(-6.0)
    assert verdicts["C"] == {"range": None, "worst_minus_best_peer": None, "meets_both": False}
    assert not any(v["meets_both"] for v in verdicts.values())
    close = {"0.3": {"A": row(80.0), "B": row(81.5)}, "0.4": {"A": row(81.0), "B": row(80.0)}}
    assert benchmark.peers_against_the_goal(close)["A"]["meets_both"]  # range 1, worst gap -1.5
    assert benchmark.peers_against_the_goal({"published": {"A": row(80.0)}}) == {}  # one split: nothing to hold


def test_the_best_peer_at_the_defaults_order_is_read_from_each_peers_fits_by_order():
    peers = {"A": {"fit_by_order": {"2": 90.0, "4": 80.0}}, "B": {"fit_by_order": {"4": 82.0, "6": None}},
             "C": {"validation_fit_percent": [95.0]}}  # C: no models kept (a NARX peer), so no fit at an order
    assert benchmark.best_peer_at_order(peers, 4) == ("B", 82.0)
    assert benchmark.best_peer_at_order(peers, 2) == ("A", 90.0)
    assert benchmark.best_peer_at_order(peers, 6) == (None, None)  # B's order-6 model had no finite fit
    assert benchmark.best_peer_at_order(peers, None) == (None, None)


def _identify(entry, scratch: Path, *options: str) -> tuple[int, dict]:
    """``vehid identify`` on the raw file with the benchmark's arguments; exit status and JSON summary."""
    done = run_vehid("identify", *benchmark.data_args(entry, scratch), *options, "--json", "--quiet", cwd=ROOT)
    assert done.returncode in (0, 3), done.stderr[-500:]
    return done.returncode, json.loads(done.stdout.strip().splitlines()[-1])


# Hold-out fit per output of `vehid identify` with default options (p chosen by cross-validation),
# measured on the raw files (benchmarks/real_data.py, same commands). Floors are these less MARGIN.
# Spread measured by running the same command on copies of the records with every sample perturbed
# by 1e-6 relative noise (two seeds) and in a bare environment: at most 0.77 point (cascaded tanks,
# 71.76 -> 71.79, 71.98 and 71.21; the same p chosen each time), 0.04 on the heat exchanger (one
# seed), the others below 0.01. Two unperturbed runs agree exactly (no random numbers). The
# ball-and-beam plant is open-loop unstable (the ball rolls off a tilted beam): its data start, left
# unstable, predicts each half of the record from the other far better than a stable one (two-fold
# 10-step fit 71.2 against 5.9 %), so the default run allows unstable modes, says so, and returns that
# start, found by N4SID's state sequence, because the filter's model predicts the estimation part worse
# (10-step fit 69.9 against 42.3 %); it is scored by 10-step prediction, as every unstable model is.
# Measured 84.44 (the same under both perturbation seeds and the Sandybridge, Nehalem and Core2 kernels;
# 83.1-85.1 over held-out fractions 0.3-0.4). It read 76.66 while the unstable start was PO-MOESP's, whose
# B and D were fitted to simulated outputs that the growing mode swamps. (Until the predictor's process
# noise followed the record's input, that score depended on the input's units and read 89.18 with the
# published ones; the peers' models score 88.0-90.9 by simulation.) The test checks that the run's note says
# why the model is unstable. On the CD player arm cross-validation prefers the data start, which is returned.
DEFAULT_FITS = {
    "ballbeam": [84.44],
    "dryer": [85.31],
    "robot_arm": [96.87],
    # 63.36 until the schedule margin: a constant Q, whose parameters follow the estimation part's last
    # stretch, gave 49.5-65.4 % over held-out fractions 0.3-0.4; the shrinking Q run now gives 59.79 at 0.3
    # (57.6-59.8 over the fractions; the best peer 58.2 %, SIPPY CVA), docs/iekf_tuning.md "Schedule margin"
    "exchanger": [59.79],
    "cd_player_arm": [73.43, 78.96],
    "cascaded_tanks": [71.76],
}
# 2 points: more than twice the largest spread under perturbation, and the same
# yardstick as the benchmark's goal (within 2 points of the best peer).
MARGIN = 2.0
# The cascaded tanks' default fit moves more than that with rounding alone: 71.76 with OpenBLAS's Haswell
# kernel (one thread or two, and on a byte-faithful copy of the record), 70.54 with the Sandybridge and Prescott
# kernels (cross-validation chooses p 1e-4 instead of 1e-5), 65.25 with every sample perturbed by 1e-9 relative
# (p 1e-4). The committed record stays above its floor on every kernel measured (0.78 point to spare); the
# 6.5-point spread under perturbation is the method's fragility (the p decision and the filter run from it), to
# be fixed in the method rather than by lowering this floor. Its cause, measured: the cross-validated fit of
# p 1e-4 is 38.6 % with the Haswell kernel and 71.5 % with Sandybridge (p 1e-5: 67.2 and 69.1 %), so the
# filter run at that p, not a near tie, decides. With the Sandybridge kernel every other record gives its
# figure above to 0.01 point (ball-and-beam 89.18 as then scored, dryer 85.31, robot arm 96.87, exchanger 63.36, CD player
# arm 73.43 and 78.96), and so do the comparators below (N4SID 96.80, ARX 69.58).


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """``name -> summary`` of the default run on a record, each run once for the module.

    On the nonlinear records (SPLINE_BEST_PEERS) the run is the spline test's ``--nonlinear`` run: it finishes
    the default linear run first and only then refines its model (identification/automatic/run.py), so its
    order, preparation, linear model and linear scores are the default run's, and the linear model is not
    identified a second time.
    """
    summaries: dict[str, dict] = {}

    def run(name: str) -> dict:
        if name not in summaries:
            options = ("--nonlinear",) if name in {record for record, _ in SPLINE_BEST_PEERS} else ()
            summaries[name] = _identify(records.record_set(name), tmp_path_factory.mktemp(name), *options)[1]
        return summaries[name]

    return run


@pytest.mark.parametrize("name", list(DEFAULT_FITS))
def test_default_identify_holdout_fit_on_raw_record(name, default_run):
    summary = default_run(name)
    # the default linear model's (a --nonlinear run returns its spline model where that validates better)
    fits = np.array(summary["orders_tried"][0]["validation_fit_percent"], dtype=float)
    assert summary["order"] == 4 and summary["preparation"]["detrend"] == "mean"
    assert np.all(fits >= np.array(DEFAULT_FITS[name]) - MARGIN), (fits, DEFAULT_FITS[name])
    if name == "ballbeam":
        assert summary["open_loop_unstable"]["assumed"] and summary["model_returned"] == "start" and "start_kept" in summary
        assert any("treated as open-loop unstable" in line for line in summary["notes"]), summary["notes"]
        assert summary["horizon"] == 10  # an unstable model is scored by k-step prediction


def test_a_loss_of_more_than_the_tolerance_on_any_output_is_named_and_nothing_else():
    """The benchmarks' regression check on plain figures: per output, against the tolerance, cases run only."""
    before = {"a | default | 0.3": [80.0, 70.0], "b | default | 0.3": [60.0], "c | default | 0.3": [50.0],
              "d | default | 0.3": [40.0, 30.0]}
    after = {"a | default | 0.3": [85.0, 70.0 - 1.5], "b | default | 0.3": [60.0 - 0.9],
             "d | default | 0.3": [], "e | default | 0.3": [10.0]}  # c not run, d failed, e new
    lines = baselines.regressions(before, after, tolerance=1.0)
    assert len(lines) == 2 and lines[0].startswith("a | default | 0.3, output 2: 68.50 % against 70.00 %")
    assert lines[1].startswith("d | default | 0.3: 0 outputs scored")
    assert baselines.regressions(before, {"a | default | 0.3": [float("nan"), 70.0]}) == [
        "a | default | 0.3, output 1: no finite fit (baseline 80.00 %)"]


@pytest.mark.parametrize("name", list(DEFAULT_FITS))
def test_default_identify_keeps_the_committed_benchmark_figures(name, default_run):
    """The default run of each record (the run above, not run again) against benchmarks/baselines/real_data.json,
    the figures the real-data benchmark guards: no output may fall more than MARGIN below them here (the
    benchmark itself, on one machine, allows a point; MARGIN covers the spread between BLAS kernels above)."""
    entry = records.record_set(name)
    case = f"{name} | {benchmark.DEFAULT_ROW} | {benchmark._fraction(entry, records.HOLDOUT)}"
    committed = baselines.load("real_data")["figures"]
    assert case in committed
    summary = default_run(name)
    assert baselines.regressions({case: committed[case]}, {case: summary["validation_fit_percent"]},
                                 tolerance=MARGIN) == []


# Comparators on the raw files, measured the same way (direct least squares: under the
# perturbation above they move by less than 0.01 point); same MARGIN.
COMPARATOR_FITS = [("robot_arm", "n4sid", [96.80]), ("cascaded_tanks", "arx", [69.58])]


@pytest.mark.parametrize("name, method, measured", COMPARATOR_FITS, ids=[f"{c[0]}-{c[1]}" for c in COMPARATOR_FITS])
def test_comparator_holdout_fit_on_raw_record(name, method, measured, tmp_path):
    _, summary = _identify(records.record_set(name), tmp_path, "--method", method)
    assert np.all(np.array(summary["validation_fit_percent"]) >= np.array(measured) - MARGIN), summary


# The spline model (``--nonlinear``, p chosen on the held-out data from 1e-7, 1e-8, 1e-9) on the nonlinear
# records, and the best peer's hold-out fit (benchmarks/real_data.py). Its own figure is not asserted: it moves
# with the BLAS kernel's rounding, through the linear start it refines (the tanks' default run chooses p 1e-5 or
# 1e-4 by cross-validation depending on the kernel). Measured on the tanks (spline / linear start, hold-out %):
# OpenBLAS Haswell kernel 75.69 / 71.76 with one thread and two, Sandybridge and Prescott 79.43 / 70.54, every
# sample perturbed by 1e-9 relative 76.52 / 65.25, an AVX-512 machine 73.5; on the exchanger 77.46 / 63.36.
# What holds across all of them, and is the claim: the spline model beats its linear start (by 3.9 to 14.1
# points where the start was recorded; asserted by half the smallest gap) and every peer (the lowest spline
# fit, 73.5, is 4.8 points above the best peer's 68.7), so that it is the model returned. Those figures
# simulate the spline model from rest; scored as its linear start is, from an estimated initial state, it
# gains (the exchanger: 81.3 % here, its start 63.4 %), which leaves the floors below standing.
SPLINE_BEST_PEERS = [("exchanger", 58.2), ("cascaded_tanks", 68.7)]


@pytest.mark.slow  # the spline filter's first compilation takes up to ~30 s on a fresh cache
@pytest.mark.parametrize("name, best_peer", SPLINE_BEST_PEERS, ids=[c[0] for c in SPLINE_BEST_PEERS])
def test_spline_model_holdout_fit_on_raw_nonlinear_records(name, best_peer, default_run):
    """``--nonlinear`` on a raw nonlinear record: the spline model beats its linear start and every peer held out."""
    summary = default_run(name)  # on these records, the --nonlinear run
    spline = summary["nonlinear"]["validation_fit_percent"]
    start = summary["orders_tried"][0]["validation_fit_percent"]  # the linear model it refined (one order)
    assert spline[0] > start[0] + (75.69 - 71.76) / 2, summary["nonlinear"]
    assert spline[0] > best_peer, summary["nonlinear"]
    assert summary["model_returned"] == "nonlinear" and summary["validation_fit_percent"] == spline


def test_a_validation_file_holding_the_estimation_samples_is_refused():
    """The tanks' .mat holds both records; given again as a validation file it would be read under the
    estimation record's names and score the model on its own data (it did, with exit 0)."""
    mat = ROOT / "tests" / "data" / "cascaded_tanks" / "dataBenchmark.mat"
    command = ["identify", str(mat), "--inputs", "uEst", "--outputs", "yEst", "--dt", "4",
               "--validation-file", str(mat), "--method", "arx", "--json", "--quiet"]
    done = run_vehid(*command, cwd=ROOT)
    assert done.returncode == 2
    assert "same samples as the estimation record" in json.loads(done.stdout)["error"]
    named = run_vehid(*command, "--validation-inputs", "uVal", "--validation-outputs", "yVal", cwd=ROOT)
    assert named.returncode == 0, named.stderr[-500:]
    summary = json.loads(named.stdout)
    # ARX is deterministic: the published validation record scores 69.58 % (benchmarks/real_data.py,
    # 69.6 %), the estimation record 74.65 %; 0.5 point allows rounding across BLAS builds only
    assert abs(summary["validation_fit_percent"][0] - 69.58) < 0.5
    assert abs(summary["estimation_fit_percent"][0] - 74.65) < 0.5
