"""The default IEKF does not depend on units, scale, time base or record length (issue: unit-invariant defaults).

The same samples with time relabelled (x0.01, x100) or signals rescaled
(1e-6, 1e6) must give the same model (eigenvalues scaled by the time factor)
and the same fit; a 20 s and a one-hour record of the same system the same
model. Tolerances are those of the acceptance: eigenvalues within 1e-3
relative, fits within 0.1 point.
"""

import json

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.data import IOData
from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.validation import score

DT = 0.05  # s
# A pair at -0.5 +/- 2j rad/s and a real pole at -0.3 rad/s, one input, one output.
STRUCTURE = ModalStructure.default(3, 1, 1)
TRUTH = ModalModel(STRUCTURE, [[-0.5, 2.0, 0], [-2.0, -0.5, 0], [0, 0, -0.3]], [[1.0], [0.4], [0.25]],
                   [[1.0, 1.0, 1.0]], [[0.0]])


def _record(duration: float, *, seed: int = 0, noise: float = 0.0) -> IOData:
    """Piecewise-linear random input (points every 0.5 s), the true model's exact output, optional white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(duration / DT))) * DT
    points = rng.standard_normal(int(duration / 0.5) + 2)
    u = np.interp(t, np.arange(points.size) * 0.5, points)[:, None]
    y = TRUTH.simulate_outputs(u, DT)
    if noise:
        y = y + noise * np.sqrt(np.mean(y**2)) * np.random.default_rng(seed + 1).standard_normal(y.shape)
    return IOData(t=t, u=u, y=y)


def _relative_gap(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.sort_complex(a), np.sort_complex(b)
    return float(np.max(np.abs(a - b) / np.abs(b)))


@pytest.fixture(scope="module")
def noisy():
    data = _record(200.0, noise=0.1)
    return data, identify_iekf(data, STRUCTURE, options=IEKFOptions.invariant())


@pytest.mark.parametrize("time_factor, input_factor, output_factor", [
    (0.01, 1.0, 1.0), (100.0, 1.0, 1.0), (1.0, 1.0, 1e-6), (1.0, 1e6, 1e-6), (1.0, 1e-6, 1e6), (100.0, 1e6, 1e-6),
])
def test_relabelled_time_and_rescaled_signals_give_the_same_model(noisy, time_factor, input_factor, output_factor):
    data, base = noisy
    changed = IOData(t=data.t * time_factor, u=data.u * input_factor, y=data.y * output_factor)
    result = identify_iekf(changed, STRUCTURE, options=IEKFOptions.invariant())
    # the filter sees the same normalised problem; only rounding differs (1e-3 is the acceptance's bound)
    assert _relative_gap(result.model.eigenvalues() * time_factor, base.model.eigenvalues()) < 1e-3
    assert np.max(np.abs(result.fit_percent - base.fit_percent)) < 0.1
    assert result.passes_run == base.passes_run and result.stop_reason == base.stop_reason
    # gains scale with the signals: the steady-state gain -C A^-1 B + D by output/input
    gain = lambda m: (-m.C @ np.linalg.solve(m.A, m.B) + m.D).item()  # noqa: E731
    assert gain(result.model) == pytest.approx(gain(base.model) * output_factor / input_factor, rel=1e-3)


def test_the_absolute_settings_fail_on_small_outputs(noisy):
    """The check above can fail: the former defaults on outputs x1e-6 stay near their start values."""
    data, base = noisy
    small = IOData(t=data.t, u=data.u, y=data.y * 1e-6)
    result = identify_iekf(small, STRUCTURE, options=IEKFOptions(passes=10))
    assert _relative_gap(result.model.eigenvalues(), base.model.eigenvalues()) > 0.1


def test_a_short_and_an_hour_long_record_give_the_same_model():
    short = identify_iekf(_record(20.0, seed=3), STRUCTURE, options=IEKFOptions.invariant())
    long = identify_iekf(_record(3600.0, seed=4), STRUCTURE, options=IEKFOptions.invariant())
    assert short.stop_reason == long.stop_reason == "converged"
    for result in (short, long):  # noise-free records of the true model: it is found to 1e-3
        assert _relative_gap(result.model.eigenvalues(), TRUTH.eigenvalues()) < 1e-3
    assert _relative_gap(short.model.eigenvalues(), long.model.eigenvalues()) < 1e-3
    assert abs(short.fit_percent[0] - long.fit_percent[0]) < 0.1


def test_initial_state_estimate_explains_a_record_that_starts_mid_motion():
    """A lightly damped system released from a displaced state: from rest no model explains it."""
    light = ModalModel(ModalStructure.default(2, 1, 1), [[-0.05, 3.0], [-3.0, -0.05]], [[0.2], [0.0]],
                       [[1.0, 1.0]], [[0.0]])
    data = _record(60.0, seed=5)
    y = light.simulate_outputs(data.u, DT, x0=[2.0, -1.0])
    record = IOData(t=data.t, u=data.u, y=y)
    from_rest = score(light, record, initial_state="zero")
    estimated = score(light, record, initial_state="estimate")
    assert from_rest.fit[0] < 50  # the free response dominates
    assert estimated.fit[0] > 99.99  # the true model from its true initial state: exact up to rounding
    assert score(light, record, horizon=5).fit[0] > 99.9  # k-step prediction of the true model


def test_an_unstable_plant_is_kept_and_scored_by_prediction():
    """With --allow-unstable semantics the true unstable pole is identified; simulation diverges, prediction does not."""
    unstable = ModalModel(ModalStructure.default(2, 1, 1), [[0.1, 1.5], [-1.5, 0.1]], [[0.5], [0.2]],
                          [[1.0, 1.0]], [[0.0]])
    data = _record(40.0, seed=6)
    record = IOData(t=data.t, u=data.u, y=unstable.simulate_outputs(data.u, DT))
    result = identify_iekf(record, unstable.structure, options=IEKFOptions.invariant(allow_unstable=True))
    assert _relative_gap(result.model.eigenvalues(), unstable.eigenvalues()) < 1e-3
    assert score(result.model, record, horizon=10).fit[0] > 99


def _write_csv(path, data, *, y_factor=1.0):
    np.savetxt(path, np.column_stack([data.t, data.u, data.y * y_factor]), delimiter=",", header="t,u1,y1", comments="")
    return path


def _cli_identify(record, *extra):
    completed = run_vehid("identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "3",
                          "--validation", "0.3", "--json", *extra)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout)


def _eigenvalues(summary):
    return np.array([complex(*v) for v in summary["eigenvalues"]])


def test_cli_defaults_on_outputs_scaled_by_1e_minus_6(tmp_path):
    """The issue's failure: outputs x1e-6 returned the start values with R = 0 and exit 0.

    The record starts at rest with no offsets, so against the truth the offsets are left in
    (--detrend none: removing the means would add a constant the true model does not have, a
    0.3 % bias on the weak pole). With every default, the scaled record must give the same
    model as the unscaled one (1e-3 relative, the issue's invariance tolerance).
    """
    record = _record(100.0, seed=7)
    small = _write_csv(tmp_path / "small.csv", record, y_factor=1e-6)
    summary = _cli_identify(small, "--detrend", "none")
    assert _relative_gap(_eigenvalues(summary), TRUTH.eigenvalues()) < 1e-3
    assert summary["validation_fit_percent"][0] > 99.9 and summary["estimation_fit_percent"][0] > 99.9
    assert summary["stop_reason"] == "converged" and summary["warnings"] == []
    scaled, unscaled = _cli_identify(small), _cli_identify(_write_csv(tmp_path / "unit.csv", record))
    assert _relative_gap(_eigenvalues(scaled), _eigenvalues(unscaled)) < 1e-3
    assert abs(scaled["validation_fit_percent"][0] - unscaled["validation_fit_percent"][0]) < 0.1
    assert scaled["warnings"] == []


@pytest.mark.slow
def test_cli_warns_and_strict_exits_3_on_a_run_that_did_not_converge(tmp_path):
    record = _write_csv(tmp_path / "r.csv", _record(30.0, seed=8))
    common = ["identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "3",
              "--start", "paper", "--timescale", "seconds", "--no-normalize", "--passes", "2"]
    loose = run_vehid(*common)
    assert loose.returncode == 0 and "NOT converged" in loose.stdout
    warning_lines = [line for line in loose.stderr.splitlines() if line.startswith("vehid: warning:")]
    assert warning_lines and any("did not converge" in line for line in warning_lines)
    strict = run_vehid(*common, "--strict", "--json")
    assert strict.returncode == 3
    summary = json.loads(strict.stdout)
    assert summary["exit_status"] == 3 and any("did not converge" in w for w in summary["warnings"])
    # the case: outputs x1e-6 with the absolute settings leave the modes at their start values
    small = _write_csv(tmp_path / "small.csv", _record(30.0, seed=8), y_factor=1e-6)
    stuck = run_vehid("identify", small, "--inputs", "u1", "--outputs", "y1", "--order", "3",
                      "--start", "default", "--timescale", "seconds", "--no-normalize", "--p", "1", "--json")
    assert stuck.returncode == 0
    assert any("no better than its start" in w for w in json.loads(stuck.stdout)["warnings"])


@pytest.mark.slow
def test_cli_order_range_chooses_on_validation_data(tmp_path):
    record = _write_csv(tmp_path / "r.csv", _record(100.0, seed=9, noise=0.02))
    completed = run_vehid("identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "1-4", "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert [row["order"] for row in summary["orders_tried"]] == [1, 2, 3, 4]
    assert all({"order", "seconds", "validation_fit_percent"} <= set(row) for row in summary["orders_tried"])
    # the true order is 3: lower orders miss a mode by more than the parsimony tolerance, 4 gains nothing
    assert summary["order"] == 3


def test_a_negative_real_discrete_pole_gives_a_labelled_discrete_model():
    """y(k) = -0.6 y(k-1) + u(k-1): no continuous-time equivalent; ARX returns the discrete model, not an error."""
    from vehid.identification.comparators import identify_with
    from vehid.identification.models.discrete import DiscreteModel

    u = np.random.default_rng(11).standard_normal((400, 1))
    y = np.zeros((400, 1))
    for k in range(1, 400):
        y[k] = -0.6 * y[k - 1] + u[k - 1]
    record = IOData(t=np.arange(400) * 0.1, u=u, y=y)
    outcome = identify_with(record, method="arx", order=1)
    assert isinstance(outcome.model, DiscreteModel) and outcome.model.meta["time_domain"] == "discrete"
    assert outcome.model.eigenvalues()[0].real == pytest.approx(-0.6, abs=1e-9)  # exact data: exact pole
    assert score(outcome.model, record).fit[0] > 99.99


@pytest.mark.slow
def test_cli_nonlinear_scores_and_archives_both_models(tmp_path):
    """--nonlinear: the linear start, then the spline model; both scored, both archived (compiles the spline filter)."""
    import h5py

    data = _record(100.0, seed=12)
    record = tmp_path / "nl.csv"
    np.savetxt(record, np.column_stack([data.t, data.u, data.y - 0.2 * data.y**3]), delimiter=",",
               header="t,u1,y1", comments="")
    archive = tmp_path / "run.h5"
    completed = run_vehid("identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "3",
                          "--validation", "0.3", "--nonlinear", "--nonlinear-p", "1e-7", "--nonlinear-passes", "5",
                          "--out", archive, "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    nonlinear = summary["nonlinear"]
    assert {"estimation_fit_percent", "validation_fit_percent", "validation_R", "fit_percent", "p"} <= set(nonlinear)
    assert summary["validation_fit_percent"] is not None and len(nonlinear["validation_fit_percent"]) == 1
    with h5py.File(archive, "r") as handle:
        assert {"iekf", "nonlinear"} <= set(handle["runs"])
    # the report draws both (a spline model keeps its sizes on its linear structure; it used to be an internal error)
    figures = tmp_path / "figures"
    report = run_vehid("report", archive, "--out", figures, "--dpi", "30", "--quiet")
    assert report.returncode == 0, report.stderr
    assert (figures / "residuals_identification_nonlinear.png").exists()


def test_order_parsing_and_the_parsimony_rule():
    from vehid.identification.errors import DivergenceError, InputError
    from vehid.identification.automatic.orders import ORDER_TOLERANCE, choose_order
    from vehid.identification.automatic.plan import AUTO_MAX_ORDER, parse_order_option

    assert parse_order_option("4") == ([4], False)
    assert parse_order_option("2-5") == ([2, 3, 4, 5], False)
    assert parse_order_option("auto") == (list(range(1, AUTO_MAX_ORDER + 1)), True)
    for bad in ("0", "5-2", "four", "2-"):
        with pytest.raises(InputError):
            parse_order_option(bad)
    rows = [{"order": 2, "ranking_fit": 90.0, "eligible": True},
            {"order": 3, "ranking_fit": 97.0 - ORDER_TOLERANCE / 2, "eligible": True},
            {"order": 4, "ranking_fit": 97.0, "eligible": True},
            {"order": 5, "ranking_fit": 99.0, "eligible": False}]  # unstable where stability was asked
    assert choose_order(rows) == 3  # the smallest within the tolerance of the best eligible order
    with pytest.raises(DivergenceError):
        choose_order([{"order": 2, "eligible": False, "error": "diverged"}])


def test_cli_validation_file_is_scored_and_a_mismatched_one_refused(tmp_path):
    record = _write_csv(tmp_path / "estimation.csv", _record(60.0, seed=15))
    other = _write_csv(tmp_path / "other.csv", _record(30.0, seed=16))
    # Both records start at rest with no offsets, so the model explains them exactly only with the offsets
    # left in; removing each record's means adds a constant no linear model from rest has (about 1 point).
    completed = run_vehid("identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "3",
                          "--validation-file", other, "--detrend", "none", "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert len(summary["validation_records"]) == 1 and summary["validation_fit_percent"][0] > 99.9
    assert summary["validation_R"][0] > 99.9 and summary["estimation_fit_percent"][0] > 99.9
    bad = tmp_path / "bad.csv"
    np.savetxt(bad, np.ones((50, 3)), delimiter=",", header="t,u1,y2", comments="")
    refused = run_vehid("identify", record, "--inputs", "u1", "--outputs", "y1", "--order", "3",
                        "--validation-file", bad)
    assert refused.returncode == 2 and "y1" in refused.stderr


def test_a_divergence_after_good_passes_reports_the_last_good_one_with_a_warning():
    from vehid.identification.errors import DivergenceError
    from vehid.identification.automatic.scoring import Evaluation, last_good_on_divergence, run_warnings

    good = identify_iekf(_record(20.0, seed=3), STRUCTURE, options=IEKFOptions.invariant(passes=2))

    def diverging():
        raise DivergenceError("pass 3: the identified model is unstable", last_good=good)

    result, message = last_good_on_divergence(diverging)
    assert result is good and "pass 3" in message
    with pytest.raises(DivergenceError):  # nothing good to report: still an error
        last_good_on_divergence(lambda: (_ for _ in ()).throw(DivergenceError("pass 1: non-finite", last_good=None)))
    evaluation = Evaluation(score(good.model, _record(20.0, seed=3)), good.fit_percent, (), None)
    lines = run_warnings(model=good.model, evaluation=evaluation, stop_reason=f"diverged at pass 3: {message}",
                         start_fit=None, final_fit=None, allow_unstable=False)
    assert len(lines) == 1 and "diverged" in lines[0] and "last good pass" in lines[0]


def test_the_spline_model_is_returned_only_where_it_beats_the_other_model_by_the_margin():
    """Both scored by one rule; the spline model must win by NONLINEAR_MARGIN on validation data, by the
    whole-record margin on the estimation data without them, and its loss is a note, not a warning."""
    from vehid.identification.assessment.validation import Scores
    from vehid.identification.automatic.scoring import Evaluation
    from vehid.identification.automatic.returned import WHOLE_RECORD_MARGIN
    from vehid.identification.automatic.nonlinear import NONLINEAR_MARGIN, nonlinear_margin, nonlinear_note

    def scored(estimation: float, validation: float | None) -> Evaluation:
        def scores(fit: float) -> Scores:
            return Scores(np.array([fit]), np.array([fit]), "estimate", None, 100)

        return Evaluation(scores(estimation), np.array([estimation]),
                          () if validation is None else (scores(validation),), None)

    linear = scored(90.0, 80.0)
    for validation, returned in ((80.0 + NONLINEAR_MARGIN + 0.1, "nonlinear"), (80.0 + NONLINEAR_MARGIN - 0.1, "filter"),
                                 (79.0, "filter")):
        margin = nonlinear_margin(scored(99.0, validation), linear, "filter")
        assert margin["choice"] == returned and margin["margin"] == NONLINEAR_MARGIN
        assert margin["score"] == pytest.approx(validation if returned == "nonlinear" else 80.0)
    margin = nonlinear_margin(scored(79.0, 70.0), linear, "scheduled")
    note = nonlinear_note(margin)
    assert "not returned" in note and "scheduled" in note and "70.00 against 80.00" in note
    note = nonlinear_note(nonlinear_margin(scored(99.0, 85.0), linear, "scheduled"))
    assert note.startswith("the spline-nonlinear model is returned") and "85.00 against 80.00" in note
    # without validation data the estimation fits decide, and the spline model fitted that record too
    alone = scored(90.0, None)
    assert nonlinear_margin(scored(90.0 + WHOLE_RECORD_MARGIN - 0.1, None), alone, "filter")["choice"] == "filter"
    assert nonlinear_margin(scored(90.0 + WHOLE_RECORD_MARGIN + 0.1, None), alone, "filter")["choice"] == "nonlinear"


def test_the_filter_is_returned_in_its_start_s_place_only_where_its_p_beats_the_start_clearly():
    """The chosen candidate must beat the start by more than the margin that ranks cross-validated fits."""
    from vehid.identification.automatic.tuning import PCandidate, PTuning
    from vehid.identification.decisions import SCHEDULE_MARGIN

    rows = (PCandidate(1e-4, None, 75.0, 1.0), PCandidate(1e-5, None, 72.0, 1.0),
            PCandidate(1e-6, None, None, 1.0, error="diverged"))
    assert not PTuning(1e-5, rows, 3.0, 72.0 - 2 * SCHEDULE_MARGIN).start_wins  # a clear lead: the filter's
    assert PTuning(1e-5, rows, 3.0, 72.0 - SCHEDULE_MARGIN / 2).start_wins  # within the margin: the start
    # the chosen p is weighed, not another p's better fit (p 1e-4 leads the start by 3.6 here)
    assert PTuning(1e-5, rows, 3.0, 71.4).start_wins
    assert not PTuning(1e-5, rows, 3.0, None).start_wins  # the start could not be scored
    assert PTuning(1e-6, rows, 1.0, 10.0).start_wins  # the chosen p failed on the halves


def test_a_returned_start_is_what_the_summary_and_the_archive_describe(tmp_path, capsys, monkeypatch):
    """Where cross-validation prefers the start, the command returns it, says so once, and archives it."""
    from vehid.identification.dataio.archive import read_archive
    from vehid.identification.automatic import iekf_order
    from vehid.identification.automatic.tuning import PTuning, tune_p
    from vehid.scenarios.cli import main

    real_tune = tune_p

    def start_preferred(*args, **kwargs):
        tuning = real_tune(*args, **kwargs)
        # beyond any fit: the start as it is, and refined by its simulation error
        fits = {**(tuning.candidate_fits or {}), "start refined": 200.0}
        return PTuning(tuning.p, tuning.tried, tuning.seconds, 200.0, tuning.q_schedule, fits)

    monkeypatch.setattr(iekf_order, "tune_p", start_preferred)  # as the run of one order looks it up
    record = _write_csv(tmp_path / "r.csv", _record(30.0, seed=21, noise=0.05))
    out = tmp_path / "run.h5"
    assert main(["identify", str(record), "--inputs", "u1", "--outputs", "y1", "--order", "3", "--passes", "5",
                 "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)
    assert summary["model_returned"] == "start"
    # said once, as a note: returning the better model is no problem to warn about
    assert sum("the data start" in note and "returned in the filter's place" in note
               for note in summary["notes"]) == 1, summary["notes"]
    assert "the start model is returned" not in captured.err and summary["warnings"] == []
    assert summary["decision_margins"]["model_returned"]["choice"] == "start"
    archived = read_archive(out).runs["start"].model
    np.testing.assert_allclose(np.sort_complex(archived.eigenvalues()),
                               np.sort_complex([complex(*v) for v in summary["eigenvalues"]]), rtol=1e-12)
    # the start carries the covariance a subspace model gets (its simulation errors'), so its modes have error bars
    assert archived.parameter_covariance is not None
    assert np.all(np.linalg.eigvalsh(archived.parameter_covariance) > 0)
    assert all(np.isfinite(mode["frequency_hz_std"]) and mode["frequency_hz_std"] > 0 for mode in summary["modes"])
    filtered = read_archive(out).runs["iekf"].model  # the filter's own model stays in the archive, apart
    assert not np.allclose(np.sort_complex(filtered.eigenvalues()), np.sort_complex(archived.eigenvalues()),
                           rtol=1e-9)
