"""Which model an IEKF run returns, the filter's or its start's, with its margins and notes.

* Open-loop unstable plants (:func:`assume_unstable`): without
  ``allow_unstable`` (``--allow-unstable``), where the data start kept unstable predicts the other
  half of the record clearly better than the best stable start (mean over
  both folds, each fit floored at zero), the plant is treated as open-loop
  unstable, as ``--allow-unstable``.
* The model returned (:func:`returned_model`): where the verdict is a
  simulation (a stable plant, no ``--horizon``), the filter's model refined by
  its simulation error on the estimation records
  (:mod:`vehid.identification.automatic.refinement`), or its start
  refined alike where that cross-validates clearly better; the refinement is
  left out where it predicts the other half of the record clearly worse
  (:func:`~vehid.identification.decisions.choose_refined`). Otherwise the
  filter's model, or its start where the filter's does not cross-validate
  clearly better (:data:`~vehid.identification.decisions.SCHEDULE_MARGIN`),
  or where the start scores clearly better (:data:`WHOLE_RECORD_MARGIN`) on the
  whole estimation record (the filter runs over twice the samples per pass
  there and can move away from a good start, e.g. pull a growing mode into
  the left half-plane). Both models are scored alike: by k-step prediction
  where either is unstable, else by simulation.
* Each of these choices is reported with its margin (:func:`decision_margins`,
  JSON ``decision_margins``): the choice and its score, the runner-up and its
  score. A choice the workbench makes for the user is said once, as a note
  (:func:`decision_notes`, JSON ``notes``), not as a warning.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.decisions import SCHEDULE_MARGIN, choose_refined
from vehid.identification.errors import InputError, WorkbenchError
from vehid.identification.filtering.iekf import IEKFOptions, normalized_data_start, signal_scales
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.uncertainty import with_simulation_error_covariance
from vehid.identification.assessment.validation import UNSTABLE_HORIZON, score
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.scoring import margin_entry, mean_scores
from vehid.identification.automatic.refinement import (REFINED_CV_MEASURE, REFINED_MEASURE, SPLINE_START, refine,
                                                       refinement_note, refines)
from vehid.identification.automatic.tuning import PTuning, P_TOLERANCE, halves

__all__ = ["WHOLE_RECORD_MARGIN", "UNSTABLE_MARGIN", "FIT_FLOOR", "START_RETURNED", "start_model", "returned_start",
    "assume_unstable", "unstable_warning", "START_KEPT", "returned_model", "RefinedCandidates", "refined_candidates",
    "refined_choice", "start_beats_filter", "decision_margins", "decision_notes"]


# points of estimation fit by which the start must beat the filter's model on the whole record to be returned
# in its place. Both models were fitted to that record, the start for its simulation fit, so the start looks
# better there by fitting alone: by up to 3.0 points on the public records where the filter's model validated
# better (heat exchanger, dryer, robot arm at hold-out fractions 0.3-0.4); a run that went wrong on the whole
# record (a growing mode pulled into the left half-plane: the ball and beam) loses 9 to 34 points
WHOLE_RECORD_MARGIN = 5.0
# points of two-fold k-step fit by which the unstable data start must beat the best stable one: well above
# the spread of a fit between halves, so that noise making a stable plant's subspace model unstable does not
# switch the stability requirement off
UNSTABLE_MARGIN = 5.0
# a fit below zero explains less than the output's mean: how far below says nothing more about the model,
# and one fold's runaway prediction (fits of -100 % and less) must not outvote the other fold
FIT_FLOOR = 0.0
START_RETURNED = (f"the filter's model does not beat the data start by more than {SCHEDULE_MARGIN:g} points in "
                  "cross-validation; the start model is returned")


def start_model(result: Any) -> ModalModel:
    """The IEKF run's start model, in the record's units (from its ``start_parameters``)."""
    return ModalModel.from_parameters(result.structure, result.meta["start_parameters"],
                                      meta={"start": result.meta.get("start")},
                                      input_names=getattr(result.model, "input_names", None),
                                      output_names=getattr(result.model, "output_names", None))


def returned_start(result: Any, records: Sequence[IOData]) -> ModalModel:
    """The start model as it is returned in the filter's place: with the covariance a subspace model gets.

    That is the asymptotic covariance of its simulation errors on ``records``
    (:func:`~vehid.identification.assessment.uncertainty.simulation_error_covariance`), as
    ``--method n4sid`` gives; None where its simulation diverges (a growing mode).
    """
    return with_simulation_error_covariance(start_model(result), records)


def _start_fits(fit_on: IOData, score_on: IOData, structure: ModalStructure, options: IEKFOptions
                ) -> tuple[float, float, bool]:
    """k-step fits on ``score_on`` of the data starts found on ``fit_on``, kept stable and left free.

    Both in the normalised problem (the scales of ``fit_on``, time in samples) and scored alike, by
    prediction over the horizon an unstable model's validation uses: simulation would be fair to
    neither (a growing mode's simulation drifts even when its dynamics are right). Returns the
    stable start's fit, the free start's, and whether the free start is unstable.
    """
    stable, free = (normalized_data_start(fit_on, structure, normalize=options.normalize, stable=keep)
                    for keep in (True, False))
    input_scale, output_scale = signal_scales(fit_on, options.normalize)
    test = IOData(t=np.arange(score_on.n_samples, dtype=float), u=score_on.u / input_scale,
                  y=score_on.y / output_scale)
    return (float(np.mean(score(stable, test, horizon=UNSTABLE_HORIZON).fit)),
            float(np.mean(score(free, test, horizon=UNSTABLE_HORIZON).fit)), not free.is_stable())


def assume_unstable(settings: IdentifyOptions, plan: Plan, options: IEKFOptions, order: int
                    ) -> tuple[IEKFOptions, dict[str, Any] | None]:
    """Options allowing unstable modes where the data say the plant is open-loop unstable, and the evidence.

    Only for the default data start without ``--allow-unstable``: there the
    start's unstable subspace modes are reflected into the left half-plane,
    and for an open-loop unstable plant the reflected start (and the filter
    kept stable after it) cannot follow the record. Where the data start left
    free is unstable on the first estimation record, each half of that record
    gives a start kept stable and one left free, each scored on the other half
    by k-step prediction. Where the free start's mean fit beats the stable
    start's by more than :data:`UNSTABLE_MARGIN` points, unstable modes are
    allowed (as ``--allow-unstable``). Each fold's fit is floored at
    :data:`FIT_FLOOR` before the mean, and a half whose free start happens to
    be stable still counts (its free start is then the stable one, scored
    alike): the decision rests on a mean that moves continuously with the
    data, not on every half agreeing, so a slightly different hold-out does
    not switch it.

    Returns the options (changed or not) and None where nothing was weighed
    (the free start is stable, or the record is too short to halve), else the
    JSON entry ``open_loop_unstable``: both cross-validated fits, the horizon
    and whether the plant was assumed unstable.
    """
    if options.allow_unstable or options.start != "data" or settings.pattern is not None:
        return options, None
    first = plan.records[0]
    structure = ModalStructure.from_pattern("default", order, first.n_u, first.n_y)
    try:
        if normalized_data_start(first, structure, normalize=options.normalize, stable=False).is_stable():
            return options, None
        record_halves = [part[0] for part in halves((first,))]
        folds = [_start_fits(a, b, structure, options) for a, b in (record_halves, record_halves[::-1])]
    except (WorkbenchError, np.linalg.LinAlgError):  # too short or too poor a record to weigh: stay stable
        return options, None
    stable_fit = _floored_mean([fold[0] for fold in folds])
    free_fit = _floored_mean([fold[1] for fold in folds])
    assumed = bool(free_fit > stable_fit + UNSTABLE_MARGIN)
    entry = {"assumed": assumed, "unstable_start_cv_fit_percent": free_fit, "stable_start_cv_fit_percent": stable_fit,
             "horizon": UNSTABLE_HORIZON}
    return (dataclasses.replace(options, allow_unstable=True) if assumed else options), entry


def _floored_mean(fits: Sequence[float]) -> float:
    """Mean of fold fits, each floored at :data:`FIT_FLOOR` (a non-finite fit, a diverged prediction, too)."""
    return float(np.mean([max(fit, FIT_FLOOR) if np.isfinite(fit) else FIT_FLOOR for fit in fits]))


def unstable_warning(entry: dict[str, Any]) -> str:
    """The note of a plant treated as open-loop unstable (:func:`assume_unstable`)."""
    return (f"the data start is unstable and predicts the other half of the record clearly better than a stable "
            f"one (two-fold {entry['horizon']}-step fit {entry['unstable_start_cv_fit_percent']:.1f} % against "
            f"{entry['stable_start_cv_fit_percent']:.1f} %): the plant is treated as open-loop unstable, as with "
            "--allow-unstable; give --start band for a stable model")


START_KEPT = "the data start scores better than the filter's model on the estimation data; the start model is returned"


def returned_model(result: Any, plan: Plan, settings: IdentifyOptions, tuning: PTuning,
                   unstable: dict[str, Any] | None) -> tuple[ModalModel, dict[str, Any]]:
    """The model an IEKF run returns (the filter's or its start's, refined or not) and the summary keys.

    A run scored by simulation (:func:`~vehid.identification.automatic.refinement.refines`) with a stable model
    returns a model refined by its simulation error on the estimation records: the
    filter's, unless the start's refined model cross-validates better by more
    than :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points
    (:func:`~vehid.identification.decisions.choose_refined` on
    ``tuning.candidate_fits``). Where p was given (no cross-validation) both
    are refined and compared on the estimation records (:func:`refined_choice`).
    The refinement is left out where the models as filtered cross-validate
    better than the refined ones by more than that margin (it fitted one half
    and predicted the other worse).

    Otherwise (an unstable plant, a k-step score, a refinement left out) the
    start is returned where the filter's chosen p does not beat it by more than
    :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points in cross-validation
    (``tuning.start_wins``, the out-of-sample judgement) or scores better than
    the filter's model on the whole estimation record by more than
    :data:`WHOLE_RECORD_MARGIN` points (:func:`start_beats_filter`, key
    ``start_kept``): one rule at every order and for every start, so that a
    model clearly worse than its start is never returned. Within that margin
    an in-sample gap is what fitting alone gives the start, and the
    cross-validation decides. A run that diverged on the whole record
    returns an interrupted pass, which no cross-validation scored: there the
    start needs to win by :data:`~vehid.identification.automatic.tuning.P_TOLERANCE` only.
    ``open_loop_unstable`` is :func:`assume_unstable`'s entry, where it weighed
    the plant; ``decision_margins`` holds each decision's margin,
    ``model_returned`` says which model it is ("filter" or "start") and
    ``refinement`` how a refined one was found (its note).
    """
    keys: dict[str, Any] = {} if unstable is None else {"open_loop_unstable": unstable}
    model = getattr(result, "model", None)
    if refines(settings, result.options) and isinstance(model, ModalModel) and model.is_stable():
        fits = tuning.candidate_fits
        if fits is None:
            refined = refined_candidates(result, plan, settings)
            if refined is not None:
                return refined_choice(refined, plan, settings, tuning, unstable, keys)
        else:
            which = choose_refined(fits)
            if which is not None:
                chosen = _refined_by_cross_validation(result, plan, settings, tuning, unstable, keys, which)
                if chosen is not None:
                    return chosen
            else:
                keys["refinement"] = {"left_out": True, "fits": dict(fits)}
    comparison = start_beats_filter(result, plan, settings)
    diverged = str(getattr(result, "stop_reason", "")).startswith("diverged")
    margin = P_TOLERANCE if diverged else WHOLE_RECORD_MARGIN
    if comparison is not None:
        comparison["margin"] = margin
    kept = comparison is not None and comparison["start_estimation_fit_percent"] > (
        comparison["filter_estimation_fit_percent"] + margin)
    if kept and not tuning.start_wins:
        keys["start_kept"] = {key: comparison[key] for key in ("start_estimation_fit_percent",
                                                                "filter_estimation_fit_percent")}
    start_returned = tuning.start_wins or kept
    model = returned_start(result, plan.records) if start_returned else result.model
    keys["model_returned"] = "start" if start_returned else "filter"
    keys["decision_margins"] = decision_margins(tuning, unstable, comparison, keys["model_returned"])
    return model, keys


def _refined_by_cross_validation(result: Any, plan: Plan, settings: IdentifyOptions, tuning: PTuning,
                                 unstable: dict[str, Any] | None, keys: dict[str, Any], which: str
                                 ) -> tuple[ModalModel, dict[str, Any]] | None:
    """The model ``which`` ("filter" or "start") refined on the estimation records, with its keys; None where it
    cannot be simulated there (the caller then decides as without refinement)."""
    unrefined = result.model if which == "filter" else start_model(result)
    try:
        refined = refine(unrefined, plan.records, settings)
    except InputError:
        return None
    fits = tuning.candidate_fits
    other = "start" if which == "filter" else "filter"
    keys["model_returned"] = which
    keys["refinement"] = _refinement_entry(which, unrefined, refined, plan, settings, cross_validated=fits)
    keys[SPLINE_START] = unrefined
    margins = decision_margins(tuning, unstable, None, which)
    margins["model_returned"] = margin_entry(
        which, fits[f"{which} refined"], other, fits[f"{other} refined"], measure=REFINED_CV_MEASURE,
        rule=f"the start's where it beats the filter's by more than {SCHEDULE_MARGIN} points; neither where the "
             f"models as they are beat both by more than that")
    keys["decision_margins"] = margins
    model = refined.model
    return with_simulation_error_covariance(model, plan.records), keys


def _estimation_fit(model: ModalModel, plan: Plan, settings: IdentifyOptions) -> float:
    """Mean estimation NRMSE fit % as identify scores it (-inf where not finite)."""
    value = float(np.mean(mean_scores(model, plan.records, initial_state=settings.initial_state).fit))
    return value if np.isfinite(value) else -np.inf


def _refinement_entry(which: str, unrefined: ModalModel, refined: Any, plan: Plan, settings: IdentifyOptions,
                      cross_validated: dict[str, float | None] | None = None) -> dict[str, Any]:
    """What the note of a refined model says: whose model, its estimation fit before and after, the steps."""
    return {"model": which, "fit_before": _estimation_fit(unrefined, plan, settings),
            "fit_after": _estimation_fit(refined.model, plan, settings), "steps": refined.iterations,
            "stop_reason": refined.stop_reason, "fits": dict(cross_validated) if cross_validated else None}


@dataclass(frozen=True)
class RefinedCandidates:
    """The filter's model and its start, each refined by its simulation error on the estimation records."""

    filter: Any  # a Refinement (vehid.identification.classical.simulation_error)
    start: Any  # a Refinement, or None where the start is unknown (a resumed run) or not simulable
    unrefined: dict[str, ModalModel]  # "filter" and (where refined) "start": the models before refinement


def refined_candidates(result: Any, plan: Plan, settings: IdentifyOptions) -> RefinedCandidates | None:
    """The filter's model and its start refined by their simulation errors on the estimation records
    (:func:`~vehid.identification.automatic.refinement.refine`);
    None where the filter's model cannot be simulated there. A start that is unknown (a resumed run), unstable or
    not simulable is left out."""
    try:
        own = refine(result.model, plan.records, settings)
    except InputError:
        return None
    start, unrefined = None, {"filter": result.model}
    if result.meta.get("start_parameters") is not None:
        candidate = start_model(result)
        if candidate.is_stable():
            try:
                start = refine(candidate, plan.records, settings)
                unrefined["start"] = candidate
            except InputError:
                start = None
    return RefinedCandidates(own, start, unrefined)


def refined_choice(refined: RefinedCandidates, plan: Plan, settings: IdentifyOptions, tuning: PTuning,
                   unstable: dict[str, Any] | None, keys: dict[str, Any]) -> tuple[ModalModel, dict[str, Any]]:
    """The better of the refined filter's and the refined start's models on the estimation records, and the keys.

    Without cross-validation (p given) both minimise the same criterion on
    the same records from two starts, and the lower minimum is the better
    estimate: the start's is returned where it fits better by more than
    :data:`~vehid.identification.automatic.tuning.P_TOLERANCE` points (key ``start_kept`` then holds both fits). The
    model returned carries the covariance of a simulation-error estimate
    (:func:`~vehid.identification.assessment.uncertainty.simulation_error_covariance`).
    """
    fits = {"filter": _estimation_fit(refined.filter.model, plan, settings)}
    if refined.start is not None:
        fits["start"] = _estimation_fit(refined.start.model, plan, settings)
    returned = "start" if fits.get("start", -np.inf) > fits["filter"] + P_TOLERANCE else "filter"
    chosen = refined.start if returned == "start" else refined.filter
    if returned == "start":
        keys["start_kept"] = {"start_estimation_fit_percent": fits["start"],
                              "filter_estimation_fit_percent": fits["filter"]}
    keys["model_returned"] = returned
    keys["refinement"] = _refinement_entry(returned, refined.unrefined[returned], chosen, plan, settings)
    keys[SPLINE_START] = refined.unrefined[returned]
    margins = decision_margins(tuning, unstable, None, returned)
    if "start" in fits:
        other = "filter" if returned == "start" else "start"
        margins["model_returned"] = margin_entry(
            returned, fits[returned], other, fits[other], measure=REFINED_MEASURE,
            rule=f"the start where its refined model beats the filter's by more than {P_TOLERANCE} points here")
    keys["decision_margins"] = margins
    model = chosen.model
    return with_simulation_error_covariance(model, plan.records), keys


def start_beats_filter(result: Any, plan: Plan, settings: IdentifyOptions) -> dict[str, Any] | None:
    """The start's and the filter's fits on the estimation records, scored alike; None where the start is unknown.

    The cross-validation that chooses p runs on half records; on the whole
    record the filter runs over twice the samples per pass and can move away
    from a good start (pull a growing mode into the left half-plane, or follow
    noise). Both models are scored on the estimation records as validation
    scores a model, with one horizon for both: k-step prediction
    (:data:`~vehid.identification.assessment.validation.UNSTABLE_HORIZON`, or
    ``--horizon``) where either is unstable, else simulation; a k-step fit of
    one against a simulation fit of the other would favour the unstable one.
    """
    if result.meta.get("start_parameters") is None:
        return None
    start = start_model(result)
    horizon = settings.horizon
    if horizon is None and not (start.is_stable() and result.model.is_stable()):
        horizon = UNSTABLE_HORIZON

    def fit(model: ModalModel) -> float:
        value = float(np.mean(mean_scores(model, plan.records, initial_state=settings.initial_state, horizon=horizon).fit))
        return value if np.isfinite(value) else -np.inf

    return {"start_estimation_fit_percent": fit(start), "filter_estimation_fit_percent": fit(result.model),
            "horizon": horizon}


def decision_margins(tuning: PTuning, unstable: dict[str, Any] | None, comparison: dict[str, Any] | None,
                     returned: str) -> dict[str, dict[str, Any]]:
    """Each choice one IEKF run made by itself, with its score and the runner-up's (JSON ``decision_margins``).

    Keys: ``p`` (where cross-validated), ``open_loop_unstable`` (where weighed),
    ``model_returned`` (where the start is known); :func:`~vehid.identification.automatic.orders.order_margin` adds
    ``order`` to an order search's. Each entry: ``choice``, ``score``,
    ``runner_up``, ``runner_up_score`` (percent, None where not finite),
    ``measure`` and ``rule``.
    """
    margins: dict[str, dict[str, Any]] = {}
    p_margin = tuning.margin()
    if p_margin is not None:
        margins["p"] = p_margin
    if unstable is not None:
        free, stable = unstable["unstable_start_cv_fit_percent"], unstable["stable_start_cv_fit_percent"]
        margins["open_loop_unstable"] = margin_entry(
            *(("unstable", free, "stable", stable) if unstable["assumed"] else ("stable", stable, "unstable", free)),
            measure=f"two-fold {unstable['horizon']}-step fit % of the data starts, each fold floored at {FIT_FLOOR:g}",
            rule=f"unstable where its fit beats the stable start's by more than {UNSTABLE_MARGIN} points")
    if comparison is not None:
        fits = {"start": comparison["start_estimation_fit_percent"], "filter": comparison["filter_estimation_fit_percent"]}
        other = "filter" if returned == "start" else "start"
        how = f"{comparison['horizon']}-step prediction" if comparison.get("horizon") else "simulation"
        margins["model_returned"] = margin_entry(
            returned, fits[returned], other, fits[other], measure=f"estimation NRMSE fit % ({how})",
            rule=f"the start where it beats the filter by more than {comparison.get('margin', WHOLE_RECORD_MARGIN)} "
                 f"points here (the filter's run {'diverged' if comparison.get('margin') == P_TOLERANCE else 'finished'}),"
                 f" or unless the filter beats it by more than {SCHEDULE_MARGIN:g} in cross-validation")
    return margins


def decision_notes(summary: dict[str, Any]) -> list[str]:
    """The choices the workbench made for the user, said once each (JSON ``notes``; not warnings)."""
    notes = []
    if summary.get("open_loop_unstable", {}).get("assumed"):
        notes.append(unstable_warning(summary["open_loop_unstable"]))
    refinement = summary.get("refinement") or {}
    if summary.get("model_returned") == "start" and refinement.get("fits") and not refinement.get("left_out"):
        pass  # chosen among refined models by cross-validation: the refinement's note says how
    elif summary.get("model_returned") == "start":
        if "start_kept" in summary:
            kept = summary["start_kept"]
            notes.append(f"{START_KEPT} (fit {kept['start_estimation_fit_percent']:.2f} % against "
                         f"{kept['filter_estimation_fit_percent']:.2f} %); the linear model's matrices and scores are "
                         "the start model's")
        else:
            chosen = summary.get("filter_cv_fit_percent")
            against = f"{chosen:.2f} % for the filter's p" if chosen is not None else "the filter's, not scored"
            notes.append(f"{START_RETURNED} (fit {summary['start_cv_fit_percent']:.2f} % against {against}); "
                         "the linear model's matrices and scores are the start model's")
    if summary.get("refinement"):
        notes.append(refinement_note(summary["refinement"]))
    return notes
