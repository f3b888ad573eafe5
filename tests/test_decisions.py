"""The choices `vehid identify` makes by itself: one rule each, reported with their margins, stable.

Properties checked: the model returned is the better scoring of the filter's
model and its start at every order, each refined by its simulation error
where that means something (a stable run scored by simulation); each entry of ``decision_margins``
agrees with the choice the run made and with its own rule; a healthy run
warns of nothing; the data start's note names no library call; and on the
public ball-and-beam record a slightly different hold-out fraction or a
1e-6 relative perturbation of the samples does not switch the model class
(the issue's case: 90.6 % at a fraction of 0.3, 23.2 % at 0.3333).
"""

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.data import IOData
from vehid.identification.decisions import SCHEDULE_MARGIN, ScheduleCandidate, choose_p_and_schedule, choose_refined
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.automatic.refinement import REFINED_MEASURE
from vehid.identification.automatic.tuning import PTuning, P_TOLERANCE
from vehid.identification.automatic.returned import (RefinedCandidates, UNSTABLE_MARGIN, WHOLE_RECORD_MARGIN,
                                                     refined_choice, returned_model)
from vehid.identification.automatic.orders import ORDER_TOLERANCE

ROOT = Path(__file__).resolve().parent.parent
BALLBEAM = ROOT / "tests" / "data" / "ballbeam" / "ballbeam.dat"
DRYER = ROOT / "tests" / "data" / "dryer" / "dryer.dat"


def _record(model: ModalModel, samples: int = 600, seed: int = 0) -> IOData:
    """A random piecewise-linear input (a point every 10 samples) and the model's exact output, dt = 1."""
    rng = np.random.default_rng(seed)
    t = np.arange(samples, dtype=float)
    u = np.interp(t, np.arange(samples // 10 + 2) * 10.0, rng.standard_normal(samples // 10 + 2))[:, None]
    return IOData(t=t, u=u, y=model.simulate_outputs(u, 1.0))


def _truth(order: int) -> ModalModel:
    structure = ModalStructure.default(order, 1, 1)
    # modes decaying over 5 samples, well inside the band a 600-sample record shows, each driven by the input
    modes = ModalModel.from_parameters(structure, structure.initial_parameters(sigma=-0.2, omega=0.5, omega_spread=0.4))
    return ModalModel(structure, modes.A, np.linspace(1.0, 0.3, order)[:, None], modes.C, modes.D)


def _run(start: ModalModel, final: ModalModel, *, refined: bool = True) -> SimpleNamespace:
    """What :func:`returned_model` reads of an IEKF result: its structure, start and final model.

    ``refined=False`` makes it a run that allows unstable modes, where no simulation-error refinement runs
    and the start is weighed against the filter's model as they are (both models here are stable, so both
    are still scored by simulation).
    """
    return SimpleNamespace(structure=start.structure, model=final, meta={"start_parameters": start.parameters},
                           options=SimpleNamespace(allow_unstable=not refined, timescale="auto"))


def _spoiled(model: ModalModel, factor: float = 1.3) -> ModalModel:
    """The model with every parameter 30 % off: a clearly worse fit of the model's own record."""
    return ModalModel.from_parameters(model.structure, model.parameters * factor)


def _fit(model: ModalModel, record: IOData) -> float:
    from vehid.identification.assessment.validation import score

    return float(np.mean(score(model, record).fit))


@pytest.mark.parametrize("order", [1, 2, 3])
def test_both_models_refined_the_filters_is_returned_and_fits_at_least_as_well_as_either(order):
    """Filter's model 20 % off one way, start 20 % off the other, noise-free truth: both refine to the truth,
    so they tie and the filter's model is returned, refined: better than either unrefined model, and the truth
    to rounding of the refinement (its tolerance leaves the parameters within 1e-4 of it)."""
    truth = _truth(order)
    record = _record(truth)
    plan = SimpleNamespace(records=(record,))
    args = SimpleNamespace(horizon=None, initial_state="estimate", timescale="auto")
    start, final = _spoiled(truth, 1.2), _spoiled(truth, 0.8)
    model, keys = returned_model(_run(start, final), plan, args, PTuning(1e-5, (), 0.0), None)
    margin = keys["decision_margins"]["model_returned"]
    assert keys["model_returned"] == margin["choice"] == "filter" and "start_kept" not in keys
    assert margin["measure"] == REFINED_MEASURE and abs(margin["score"] - margin["runner_up_score"]) <= 0.1
    assert _fit(model, record) > max(_fit(start, record), _fit(final, record))
    np.testing.assert_allclose(model.parameters, truth.parameters, rtol=1e-4, atol=1e-6)
    assert model.parameter_covariance is not None  # a simulation-error estimate's
    assert keys["refinement"]["model"] == "filter" and keys["refinement"]["fit_after"] > keys["refinement"]["fit_before"]


def test_the_refined_start_is_returned_only_where_it_fits_clearly_better():
    """The rule on refined candidates: the start's refined model wins by more than the tolerance, or not at all."""
    from vehid.identification.classical.simulation_error import Refinement

    truth = _truth(3)
    record = _record(truth)
    plan = SimpleNamespace(records=(record,))
    args = SimpleNamespace(horizon=None, initial_state="estimate", timescale="auto")

    def refinement(model):
        return Refinement(model, 1.0, 0.5, 3, "converged", (np.zeros(3),), np.ones(1), 0.0)

    def choose(filter_model, start_model):
        candidates = RefinedCandidates(refinement(filter_model), refinement(start_model),
                                       {"filter": filter_model, "start": start_model})
        return refined_choice(candidates, plan, args, PTuning(1e-5, (), 0.0), None, {})

    model, keys = choose(_spoiled(truth), truth)
    margin = keys["decision_margins"]["model_returned"]
    assert keys["model_returned"] == margin["choice"] == "start" and "start_kept" in keys
    np.testing.assert_allclose(model.parameters, truth.parameters, rtol=1e-12)  # algebra: the start's model itself
    assert margin["score"] > margin["runner_up_score"] + P_TOLERANCE
    _, keys = choose(truth, _spoiled(truth))
    assert keys["model_returned"] == "filter" and "start_kept" not in keys
    _, keys = choose(truth, truth)  # a tie keeps the filter's
    assert keys["model_returned"] == "filter"


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_without_refinement_the_better_of_filter_and_start_is_returned_at_every_order(order):
    """A filter's model worse than its start returns the start; a better one is returned itself (noise-free truth)."""
    truth = _truth(order)
    plan = SimpleNamespace(records=(_record(truth),))
    args = SimpleNamespace(horizon=None, initial_state="estimate", timescale="auto")
    no_tuning = PTuning(1e-5, (), 0.0)

    model, keys = returned_model(_run(truth, _spoiled(truth), refined=False), plan, args, no_tuning, None)
    margin = keys["decision_margins"]["model_returned"]
    assert margin["choice"] == "start" and "start_kept" in keys
    np.testing.assert_allclose(model.parameters, truth.parameters, rtol=1e-12)  # algebra: the start itself
    # the truth explains its own noise-free record (algebra and simulation rounding: above 99.9 %)
    assert margin["score"] > 99.9 and margin["score"] > margin["runner_up_score"] + WHOLE_RECORD_MARGIN

    model, keys = returned_model(_run(_spoiled(truth), truth, refined=False), plan, args, no_tuning, None)
    assert keys["decision_margins"]["model_returned"]["choice"] == "filter" and "start_kept" not in keys
    assert model is not None and np.allclose(model.parameters, truth.parameters, rtol=1e-12)


def test_a_run_that_diverged_gives_way_to_a_slightly_better_start():
    """An interrupted pass is no cross-validated result: the start wins it by the small tolerance."""
    truth = _truth(3)
    plan = SimpleNamespace(records=(_record(truth),))
    args = SimpleNamespace(horizon=None, initial_state="estimate", timescale="auto")
    slightly = ModalModel.from_parameters(truth.structure, truth.parameters * 1.01)
    finished, interrupted = _run(truth, slightly, refined=False), _run(truth, slightly, refined=False)
    interrupted.stop_reason = "diverged at pass 2"
    _, kept = returned_model(finished, plan, args, PTuning(1e-5, (), 0.0), None)
    margin = kept["decision_margins"]["model_returned"]
    gap = margin["runner_up_score"] - margin["score"]
    # 1 % off every parameter: the truth fits its noise-free record better, by less than the finished run's margin
    assert margin["choice"] == "filter" and P_TOLERANCE < gap < WHOLE_RECORD_MARGIN, gap
    _, kept = returned_model(interrupted, plan, args, PTuning(1e-5, (), 0.0), None)
    assert kept["decision_margins"]["model_returned"]["choice"] == "start"


def test_a_decision_within_its_margin_keeps_the_filter():
    """Equal fits: the filter's model stands (the start must win by more than the margin)."""
    truth = _truth(3)
    plan = SimpleNamespace(records=(_record(truth),))
    args = SimpleNamespace(horizon=None, initial_state="estimate", timescale="auto")
    _, keys = returned_model(_run(truth, truth, refined=False), plan, args, PTuning(1e-5, (), 0.0), None)
    margin = keys["decision_margins"]["model_returned"]
    assert margin["choice"] == "filter" and margin["score"] == margin["runner_up_score"]


def test_the_refined_models_are_weighed_by_their_cross_validated_fits():
    """choose_refined on plain values: the refined filter's model unless the refined start's leads it by more than
    the margin, and no refinement where a model as it is leads every refined one by more than the margin."""
    m = SCHEDULE_MARGIN

    def fits(filter_, start, filter_refined, start_refined):
        return {"filter": filter_, "start": start, "filter refined": filter_refined, "start refined": start_refined}

    assert choose_refined(fits(80.0, 79.0, 81.0, 81.0 + 0.9 * m)) == "filter"  # a lead within the margin
    assert choose_refined(fits(80.0, 79.0, 81.0, 81.0 + 1.1 * m)) == "start"
    assert choose_refined(fits(80.0 + 1.1 * m, 70.0, 80.0, 79.0)) is None  # the refinement predicts worse
    assert choose_refined(fits(80.0 + 0.9 * m, 70.0, 80.0, 79.0)) == "filter"
    assert choose_refined(fits(80.0, None, 81.0, None)) == "filter"  # no start scored
    assert choose_refined(fits(80.0, 79.0, None, 81.0)) == "start"  # the filter's refinement not scored
    assert choose_refined(fits(80.0, 79.0, None, None)) is None


def test_the_data_start_note_names_no_library_call():
    """A subspace model whose modes do not fit the structure is described in the model's terms."""
    from vehid.identification.filtering.start import _subspace_start

    # two well separated real poles asked to fit one complex pair: the conversion to the structure fails
    structure = ModalStructure.default(2, 1, 1)
    real = ModalModel(ModalStructure.with_modes(0, 2, 1, 1), [[-0.05, 0.0], [0.0, -0.5]], [[1.0], [0.5]],
                      [[1.0, 1.0]], [[0.0]])
    record = _record(real, samples=800, seed=3)
    found = _subspace_start(record.u, record.y, structure, stable=True)
    assert found.source == "subspace eigenvalues"
    assert "modal_structure_for" not in found.note and "(" in found.note and "real poles" in found.note


def _check_margins(summary: dict) -> None:
    """Every decision_margins entry agrees with the run's choice and with its own rule."""
    margins = summary["decision_margins"]
    for name, entry in margins.items():
        assert {"choice", "score", "runner_up", "runner_up_score", "measure", "rule"} <= set(entry), name
        assert entry["choice"] != entry["runner_up"], name
    if "p" in margins:
        assert margins["p"]["choice"] == f"p {summary['p']:g}"
        if margins["p"]["runner_up_score"] is not None and margins["p"]["runner_up"].startswith("p "):
            # a candidate of the same schedule may beat the choice by the p tolerance, the other schedule's
            # by the schedule margin where the choice is the shrinking Q (by the tolerance where it is constant)
            same = margins["p"]["runner_up"].endswith(f"{margins['p']['q_schedule']} Q")
            allowed = (P_TOLERANCE if same or margins["p"]["q_schedule"] == "constant"
                       else SCHEDULE_MARGIN + P_TOLERANCE)
            assert margins["p"]["score"] >= margins["p"]["runner_up_score"] - allowed
    returned = margins.get("model_returned")
    if returned is not None:
        assert returned["choice"] == summary.get("model_returned", "filter")
        if returned["choice"] == "filter":  # else the cross-validation may have decided
            assert not returned["runner_up_score"] > returned["score"] + WHOLE_RECORD_MARGIN
    unstable = margins.get("open_loop_unstable")
    if unstable is not None:
        assert (unstable["choice"] == "unstable") == summary["open_loop_unstable"]["assumed"]
        gap = unstable["score"] - unstable["runner_up_score"]
        assert gap > UNSTABLE_MARGIN if unstable["choice"] == "unstable" else gap >= -UNSTABLE_MARGIN
    if "order" in margins:
        assert margins["order"]["choice"] == summary["order"]
        if margins["order"]["runner_up_score"] is not None:
            assert margins["order"]["score"] >= margins["order"]["runner_up_score"] - ORDER_TOLERANCE


@pytest.mark.slow
def test_a_healthy_run_warns_of_nothing_and_reports_its_margins(tmp_path):
    """A stable third-order system, 2 % output noise, default options with a hold-out: no warning at all."""
    truth = ModalModel(ModalStructure.default(3, 1, 1), [[-0.05, 0.2, 0], [-0.2, -0.05, 0], [0, 0, -0.03]],
                       [[1.0], [0.4], [0.25]], [[1.0, 1.0, 1.0]], [[0.0]])
    record = _record(truth, samples=2000, seed=5)
    y = record.y + 0.02 * np.sqrt(np.mean(record.y**2)) * np.random.default_rng(6).standard_normal(record.y.shape)
    path = tmp_path / "healthy.csv"
    np.savetxt(path, np.column_stack([record.t, record.u, y]), delimiter=",", header="t,u,y", comments="")
    done = run_vehid("identify", path, "--inputs", "u", "--outputs", "y", "--order", "2-4", "--validation", "0.3",
                     "--json", "--quiet")
    assert done.returncode == 0, done.stderr[-500:]
    summary = json.loads(done.stdout)
    assert summary["warnings"] == [], summary["warnings"]
    assert summary["order"] == 3 and {"p", "model_returned", "order"} <= set(summary["decision_margins"])
    _check_margins(summary)


def _ballbeam(tmp_path: Path, fraction: float, *, perturbed: bool = False) -> dict:
    file = BALLBEAM
    if perturbed:  # every sample times (1 + 1e-6 N(0, 1)): far below the record's own noise
        table = np.loadtxt(BALLBEAM, ndmin=2)
        table = table * (1.0 + 1e-6 * np.random.default_rng(1).standard_normal(table.shape))
        file = tmp_path / "ballbeam_perturbed.dat"
        np.savetxt(file, table, fmt="%.17g")
    done = run_vehid("identify", file, "--inputs", "1", "--outputs", "2", "--dt", "0.1", "--order", "2",
                     "--validation", repr(fraction), "--json", "--quiet")
    assert done.returncode == 0, done.stderr[-500:]
    return json.loads(done.stdout)


# Measured hold-out fits of order 2 (10-step prediction, the predictor's process noise following the
# record's input): 78.01 % at a fraction of 0.3, 78.01 % with every sample perturbed, 87.10 % at 0.3333
# (90.55, 90.55 and 93.01 % when that noise depended on the input's units; before this rule 90.6 and
# 23.2 %: the stability treatment and the returned model switched). A perturbation far below the record's noise may move the fit by rounding only; 2 points is
# the acceptance's bound. Another fraction scores another stretch of the record, which alone moves the
# fit by a few points either way; a switched decision costs tens of points, so the test asks that the
# fit not fall by more than the same 2 points and that the model class and the returned model be the same.
FLIP_BOUND = 2.0


@pytest.mark.slow
def test_ballbeam_decisions_do_not_flip_with_the_holdout_fraction_or_a_perturbation(tmp_path):
    runs = [_ballbeam(tmp_path, 0.3), _ballbeam(tmp_path, 0.3333), _ballbeam(tmp_path, 0.3, perturbed=True)]
    for summary in runs:
        _check_margins(summary)
        assert summary["open_loop_unstable"]["assumed"], summary["decision_margins"]
    base, moved, perturbed = (summary["validation_fit_percent"][0] for summary in runs)
    assert abs(perturbed - base) <= FLIP_BOUND and moved >= base - FLIP_BOUND, (base, moved, perturbed)
    choices = [{name: entry["choice"] for name, entry in summary["decision_margins"].items()} for summary in runs]
    assert choices[2] == choices[0]  # the perturbation changes no choice
    assert all(choices[1][name] == choices[0][name] for name in ("open_loop_unstable", "model_returned"))


def _candidates(fits: dict) -> list[ScheduleCandidate]:
    return [ScheduleCandidate(p, schedule, fit) for (p, schedule), fit in fits.items()]


def test_a_constant_Q_is_chosen_only_where_it_scores_clearly_better():
    """Below the margin the shrinking Q's best candidate runs; above it the constant Q's."""
    shrinking = {(1e-4, "shrinking"): 80.0, (1e-5, "shrinking"): 80.5, (1e-6, "shrinking"): 80.45}
    close = {**shrinking, (1e-4, "constant"): 80.5 + 0.9 * SCHEDULE_MARGIN}
    clear = {**shrinking, (1e-4, "constant"): 80.5 + 1.1 * SCHEDULE_MARGIN}
    # within the tolerance of the schedule's own best (80.5): 1e-5 and 1e-6; the larger p is taken
    assert choose_p_and_schedule(_candidates(close), p_tolerance=0.1) == (1e-5, "shrinking")
    assert choose_p_and_schedule(_candidates(clear), p_tolerance=0.1) == (1e-4, "constant")


def test_the_largest_p_is_taken_within_the_tolerance_of_its_schedules_best():
    """Not within the tolerance of another schedule's best: a p is compared with its own schedule's candidates."""
    fits = {(1e-4, "shrinking"): 79.0, (1e-5, "shrinking"): 79.95, (1e-6, "shrinking"): 80.0,
            (1e-4, "constant"): 80.5}
    assert choose_p_and_schedule(_candidates(fits), p_tolerance=0.1) == (1e-5, "shrinking")
    assert choose_p_and_schedule(_candidates(fits), p_tolerance=0.01) == (1e-6, "shrinking")


def test_a_single_schedule_or_none_is_taken_as_it_is():
    constant_only = {(1e-4, "constant"): 70.0, (1e-5, "constant"): 75.0}
    assert choose_p_and_schedule(_candidates(constant_only), p_tolerance=0.1) == (1e-5, "constant")
    assert choose_p_and_schedule([], p_tolerance=0.1) is None


def _dryer(tmp_path: Path, fraction: float, *, perturbed: bool = False) -> dict:
    file = DRYER
    if perturbed:  # every number times (1 + 1e-6 N(0, 1)): far below the record's own noise
        table = np.loadtxt(DRYER, ndmin=2)
        table = table * (1.0 + 1e-6 * np.random.default_rng(2).standard_normal(table.shape))
        file = tmp_path / "dryer_perturbed.dat"
        np.savetxt(file, table, fmt="%.17g")
    done = run_vehid("identify", file, "--inputs", "1", "--outputs", "2", "--dt", "0.08",
                     "--validation", repr(fraction), "--json", "--quiet")
    assert done.returncode == 0, done.stderr[-500:]
    return json.loads(done.stdout)


# The default's hold-out fit on the public hair-dryer record. Before the schedule rule a constant Q was run
# wherever it tied: 85.3 % at a held-out fraction of 0.3 and 90.7 % at 0.3333 with the same p and schedule
# (its parameters follow the record's last part, and where that part ends moved them). A fixed model scores
# within 0.6 point on the held-out parts of every fraction 0.3-0.4, so a larger move is the method's. With
# the shrinking Q: 86.4 and 85.8 %, 85.1-86.4 over fractions 0.3-0.4. 2 points is the acceptance's bound.
@pytest.mark.slow
def test_dryer_holdout_fit_does_not_move_with_the_holdout_fraction_or_a_perturbation(tmp_path):
    runs = [_dryer(tmp_path, 0.3), _dryer(tmp_path, 0.3333), _dryer(tmp_path, 0.3, perturbed=True)]
    for summary in runs:
        _check_margins(summary)
    fits = [summary["validation_fit_percent"][0] for summary in runs]
    assert max(fits) - min(fits) <= FLIP_BOUND, fits
