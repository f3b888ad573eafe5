"""The steps of the automatic pipeline around one estimator run: tuning, decisions, scores, warnings.

Each step takes the run's :class:`~vehid.identification.automatic.options.IdentifyOptions`
(of which it reads only the settings it needs) and the run's
:class:`~vehid.identification.automatic.plan.Plan`.

* Validation: a fraction of each record held out at its end
  (``validation=`` or ``--validation FRACTION``), or further records
  (``--validation-file FILE``); both are scored
  (:mod:`vehid.identification.assessment.validation`) by simulation, or by k-step-ahead
  prediction for an unstable model.
* Order: one, a range ``2-8`` or ``auto`` (stopping after two orders in a row
  without gain); the smallest order within :data:`ORDER_TOLERANCE` points of
  the best mean validation fit wins.
* The IEKF's p and Q schedule, unless p is given: two-fold cross-validation
  over :data:`P_GRID`, each p with Q held constant and with Q shrinking from
  pass to pass (:data:`Q_SCHEDULES`, :func:`tune_p`).
* Open-loop unstable plants (:func:`assume_unstable`): without
  ``allow_unstable`` (``--allow-unstable``), where the data start kept unstable predicts the other
  half of the record clearly better than the best stable start (mean over
  both folds, each fit floored at zero), the plant is treated as open-loop
  unstable, as ``--allow-unstable``.
* The model returned (:func:`returned_model`): where the verdict is a
  simulation (a stable plant, no ``--horizon``), the filter's model refined by
  its simulation error on the estimation records
  (:mod:`vehid.identification.classical.simulation_error`), or its start
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
  (JSON ``notes``), not as a warning.
* Warnings (:func:`run_warnings`): one line each on standard error and in the
  JSON ``warnings``, each naming one cause and one remedy (by the command's
  options); ``strict`` (``--strict``) makes them an error, the command's exit status 3.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.decisions import (SCHEDULE_MARGIN, ScheduleCandidate, choose_p_and_schedule,
                                             choose_refined)
from vehid.identification.errors import DivergenceError, InputError, OptionError, WorkbenchError
from vehid.identification.frozen import FrozenDict, freeze
from vehid.identification.filtering.iekf import (INVARIANT_P, INVARIANT_P_DECAY, START_CHOICES, IEKFOptions,
                                                 identify_iekf, invariant_noise_settings, normalized_data_start,
                                                 signal_scales, start_structure)
from vehid.identification.models.modal import ModalModel, ModalStructure
from vehid.identification.assessment.uncertainty import with_simulation_error_covariance
from vehid.identification.automatic.reported_checks import uncertainty_method
from vehid.identification.assessment.validation import UNSTABLE_HORIZON, Scores, default_horizon, score, split_holdout
from vehid.identification.automatic.plan import (AUTO_HOLDOUT, AUTO_MAX_ORDER, Plan, holdout_fraction, make_plan,
                                                 parse_order_option, supported_orders)
from vehid.identification.automatic.options import IdentifyOptions

if TYPE_CHECKING:
    from vehid.identification.filtering.spline_iekf import SplineIEKFResult

__all__ = [
    "START_CHOICES", "Evaluation", "search_orders", "identify_nonlinear", "start_of", "run_iekf_order",
    "last_good_on_divergence", "scores_summary", "AUTO_MAX_ORDER", "AUTO_HOLDOUT", "ORDER_TOLERANCE", "Plan",
    "parse_order_option", "supported_orders", "holdout_fraction", "make_plan", "iekf_options", "choose_order", "evaluate",
    "run_warnings", "pooled_fit_percent", "PCandidate", "PTuning", "tune_p", "tunes_p", "given_p", "q_schedule_of", "P_GRID", "Q_SCHEDULES", "P_TOLERANCE",
    "NONLINEAR_P", "START_RETURNED", "start_model", "returned_start", "returned_model", "NONLINEAR_P_GRID",
    "NonlinearOutcome", "NonlinearScores", "nonlinear_margin", "nonlinear_note",
    "NONLINEAR_MARGIN", "UNSTABLE_MARGIN", "assume_unstable",
    "unstable_warning", "start_beats_filter", "START_KEPT", "decision_margins", "margin_entry", "order_margin",
    "decision_notes", "structure_for", "FIT_FLOOR", "WHOLE_RECORD_MARGIN", "RunDecisions", "decide_run",
    "RefinedCandidates", "refined_candidates", "refined_choice", "refinement_note", "CANDIDATES",
    "refined_cross_validation", "refines", "refine", "REFINED_MEASURE", "REFINED_CV_MEASURE", "SPLINE_START",
]

ORDER_TOLERANCE = 0.5  # points of mean validation fit
MOVED = 1e-3  # relative change of a mode's eigenvalue below which it stayed at its start
NOTHING_TO_GAIN = 99.0  # percent R: a model this good is no warning for staying at its start
# a run stopped by the pass limit whose mean R moved less than SETTLED_FIT points over its last
# SETTLED_PASSES passes has settled in fit: more passes would not change the model's quality
SETTLED_FIT = 0.1
SETTLED_PASSES = 5
P_GRID = (1e-4, 1e-5, 1e-6)  # p per dominant time constant tried by cross-validation, largest first
P_TOLERANCE = 0.1  # points of cross-validated fit within which the largest p is taken
# Q schedules tried at each p, as IEKFOptions.p_decay. A shrinking Q averages the parameters over the whole
# record and stops them chasing sensor noise (it saves 10-36 points on noisy handling records); a constant Q
# keeps following the record's last part, so its hold-out fit moves with the record's length (the heat
# exchanger: 49.5-65.4 % over held-out fractions 0.3-0.4) and it is chosen only where it scores clearly
# better (identification.decisions.SCHEDULE_MARGIN)
Q_SCHEDULES = {"constant": 1.0, "shrinking": INVARIANT_P_DECAY}
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
NONLINEAR_P = 1e-7  # the spline model's p without validation data
# with validation data: no one p suits every sample interval (docs/measurements.md, cascaded tanks)
NONLINEAR_P_GRID = (1e-7, 1e-8, 1e-9)


def q_schedule_of(options: IEKFOptions) -> str:
    """The name in :data:`Q_SCHEDULES` of the options' Q schedule: "constant" or "shrinking"."""
    return "constant" if options.p_decay >= 1 else "shrinking"


@dataclass(frozen=True)
class PCandidate:
    """One p and Q schedule tried by the cross-validation: its two-fold fit (None where it failed) and cost.

    ``q_schedule`` is None in a row archived before schedules were kept (every run's Q was constant then).
    """

    p: float
    q_schedule: str | None
    cv_fit_percent: float | None
    seconds: float
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The row's keys in ``p_tried``."""
        return {"p": self.p, **({} if self.q_schedule is None else {"q_schedule": self.q_schedule}),
                "seconds": self.seconds, "cv_fit_percent": self.cv_fit_percent,
                **({} if self.error is None else {"error": self.error})}

    @classmethod
    def from_dict(cls, row: Mapping[str, Any]) -> "PCandidate":
        """A row as :meth:`as_dict` wrote it (an archived run's)."""
        fit = row.get("cv_fit_percent")
        return cls(p=float(row["p"]), q_schedule=row.get("q_schedule"), cv_fit_percent=None if fit is None else float(fit),
                   seconds=float(row.get("seconds", 0.0)), error=row.get("error"))


@dataclass(frozen=True)
class PTuning:
    """The filter's p and Q schedule chosen by two-fold cross-validation, with each candidate's score and cost."""

    p: float
    tried: tuple[PCandidate, ...]
    seconds: float
    start_fit: float | None = None  # the data start's cross-validated fit, on the same halves
    q_schedule: str = "constant"  # a key of Q_SCHEDULES
    # the chosen candidate's and the start's cross-validated fits, as they are and refined by their simulation
    # errors (keys of CANDIDATES; refined_cross_validation), where the run is one to refine
    candidate_fits: FrozenDict | None = None

    def __post_init__(self) -> None:
        if self.candidate_fits is not None:
            object.__setattr__(self, "candidate_fits", freeze(self.candidate_fits))

    def summary(self) -> dict[str, Any]:
        """The public JSON keys ``p``, ``q_schedule``, ``p_tried``, ``tuning_seconds`` and ``start_cv_fit_percent``."""
        return {"p": self.p, "q_schedule": self.q_schedule, "p_tried": [row.as_dict() for row in self.tried],
                "tuning_seconds": self.seconds, "start_cv_fit_percent": self.start_fit}

    def as_dict(self) -> dict[str, Any]:
        """Every field, as an archive keeps the run's decisions (:meth:`from_dict` reads it back)."""
        return {"p": self.p, "tried": [row.as_dict() for row in self.tried], "seconds": self.seconds,
                "start_fit": self.start_fit, "q_schedule": self.q_schedule,
                "candidate_fits": None if self.candidate_fits is None else dict(self.candidate_fits)}

    @classmethod
    def from_dict(cls, stored: Mapping[str, Any]) -> "PTuning":
        """The tuning :meth:`as_dict` wrote; an archive written before the Q schedule was kept reads as constant Q."""
        return cls(p=float(stored["p"]), tried=tuple(PCandidate.from_dict(row) for row in stored["tried"]),
                   seconds=float(stored["seconds"]), start_fit=stored["start_fit"],
                   q_schedule=stored.get("q_schedule", "constant"), candidate_fits=stored.get("candidate_fits"))

    def applied(self, options: IEKFOptions) -> IEKFOptions:
        """``options`` with the chosen p and Q schedule."""
        shrinks = self.q_schedule != "constant"
        # a shrinking schedule keeps the options' own rate where they have one
        decay = (options.p_decay if options.p_decay < 1 else Q_SCHEDULES[self.q_schedule]) if shrinks else 1.0
        return dataclasses.replace(options, p=self.p, p_decay=decay)

    @property
    def chosen_fit(self) -> float | None:
        """The chosen p and schedule's cross-validated fit (None where it was not scored)."""
        return next((row.cv_fit_percent for row in self.tried if row.p == self.p
                     and (row.q_schedule or self.q_schedule) == self.q_schedule), None)

    @property
    def start_wins(self) -> bool:
        """Whether the filter's chosen candidate fails to beat the data start by more than
        :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points in cross-validation.

        The filter starts from the data start and moves it; a move whose cross-validated lead is
        within the margin is not shown to be a gain (such leads do not rank hold-out fits: on the
        ball and beam the filter led its start by 0.2-0.8 point at orders 2 and 3 and validated
        2.3-3.8 points below it), so the start, the model the data fix most directly, stays.
        """
        fit = self.chosen_fit
        return self.start_fit is not None and (fit is None or fit <= self.start_fit + SCHEDULE_MARGIN)

    def margin(self) -> dict[str, Any] | None:
        """The p decision: the chosen p, its Q schedule and fit, the best other candidate (another p or
        schedule, or the data start)."""
        if not self.tried:
            return None
        scored = {(row.p, row.q_schedule or self.q_schedule): row.cv_fit_percent for row in self.tried
                  if row.cv_fit_percent is not None}
        chosen = (self.p, self.q_schedule)
        others = [(f"p {p:g}, {schedule} Q", fit) for (p, schedule), fit in scored.items() if (p, schedule) != chosen]
        if self.start_fit is not None:
            others.append(("data start", self.start_fit))
        runner_up = max(others, key=lambda item: item[1]) if others else (None, None)
        return {"choice": f"p {self.p:g}", "q_schedule": self.q_schedule, "score": scored.get(chosen),
                "runner_up": runner_up[0], "runner_up_score": runner_up[1],
                "measure": "two-fold cross-validated NRMSE fit %",
                "rule": f"a shrinking Q unless a constant one scores more than {SCHEDULE_MARGIN:g} points better; "
                        f"at that schedule the largest p within {P_TOLERANCE} points of its best"}


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


def given_p(options: IEKFOptions) -> PTuning:
    """No tuning: the p the user gave (or the settings fixed), with the options' Q schedule."""
    return PTuning(options.p, (), 0.0, q_schedule=q_schedule_of(options))


def tunes_p(settings: IdentifyOptions) -> bool:
    """Whether the IEKF's p is chosen by cross-validation: no --p given, on the unit-free time scale."""
    return settings.p is None and settings.timescale == "auto"


def planned_filter_steps(plan: Plan, options: IEKFOptions, tuned: bool) -> int:
    """The most filter steps one order's runs take in all: where p is ``tuned``, the cross-validation's
    candidates (two folds of half the estimation records each, every schedule), and the final run, each
    at most ``options.passes`` passes. A resumed run is tuned where the run it resumes tried candidates.

    Every run of the order is given this figure (``identify_iekf``'s ``planned_steps``): runs of a few
    thousand samples each would otherwise build the compiled pass for a short run (no optimisation),
    while together they make millions of steps; and all of them use the one build, so the run returned
    has the rounding of the cross-validated ones.
    """
    samples = sum(record.n_samples for record in plan.records)
    candidates = len(P_GRID) * len(Q_SCHEDULES) if tuned else 0
    return (candidates + 1) * options.passes * samples


def _halves(records: tuple[IOData, ...]) -> tuple[tuple[IOData, ...], tuple[IOData, ...]]:
    parts = [split_holdout(record, 0.5) for record in records]
    return tuple(part[0] for part in parts), tuple(part[1] for part in parts)


def tune_p(settings: IdentifyOptions, plan: Plan, options: IEKFOptions, structure: ModalStructure) -> PTuning:
    """The IEKF's p and Q schedule by two-fold cross-validation on the estimation records (module docstring).

    Each record is cut in halves; a model identified on the first halves is scored on the second and
    the reverse, and the two NRMSE fits averaged. Each p of the grid :data:`P_GRID` is tried with
    each schedule of :data:`Q_SCHEDULES` (only the constant one where ``options`` keep Q constant).
    The shrinking Q is run unless a constant Q's best candidate beats its best by more than
    :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points: cross-validated fits that
    close do not rank the hold-out fits, and the constant Q's outcome moves with the record
    (:func:`~vehid.identification.decisions.choose_p_and_schedule`). Of that schedule's
    candidates within :data:`P_TOLERANCE` points of its best, the largest p wins: a larger p
    moves the parameters faster, so the run converges in fewer passes, and the difference below
    the tolerance is noise.
    """
    started = time.perf_counter()
    try:
        first, second = _halves(plan.records)
    except InputError:  # too short to halve: the run itself names what the record lacks
        return given_p(options)
    schedules = list(Q_SCHEDULES) if options.p_decay < 1 else ["constant"]

    def held_out_fit(model: ModalModel, records: tuple[IOData, ...]) -> float:
        horizon = settings.horizon if settings.horizon is not None else default_horizon(model)
        return float(np.mean(_mean_scores(model, records, initial_state=settings.initial_state, horizon=horizon).fit))

    planned = planned_filter_steps(plan, options, tuned=True)
    rows = []
    start_fits: dict[int, float] = {}  # per fold: the data start does not depend on p
    folds: dict[tuple[float, str], list] = {}  # per candidate: (model, start, fitted on, scored on) of each fold
    for p, schedule in ((p, schedule) for p in P_GRID for schedule in schedules):
        trial = PTuning(p, (), 0.0, q_schedule=schedule).applied(options)
        began = time.perf_counter()
        fits, errors = [], []
        # the second halves start mid-motion: their start state is unknown, whatever the record's is
        for fold, (fit_on, score_on, settle) in enumerate(((first, second, plan.settle_start), (second, first, True))):
            data = fit_on[0] if len(fit_on) == 1 else fit_on
            try:
                result, _ = last_good_on_divergence(
                    lambda: identify_iekf(data, structure, options=trial, settle_start=settle, parameter_covariance=False,
                                          planned_steps=planned))
            except WorkbenchError as exc:
                errors.append(str(exc))
                continue
            fits.append(held_out_fit(result.model, score_on))
            start = (ModalModel.from_parameters(structure, result.meta["start_parameters"])
                     if result.meta.get("start_parameters") is not None else None)
            if fold not in start_fits and start is not None:
                start_fits[fold] = held_out_fit(start, score_on)
            folds.setdefault((p, schedule), []).append((result.model, start, fit_on, score_on))
        fit = None if errors or not np.all(np.isfinite(fits)) else float(np.mean(fits))
        rows.append(PCandidate(p, schedule, fit, time.perf_counter() - began, "; ".join(errors) if errors else None))
    choice = choose_p_and_schedule([ScheduleCandidate(row.p, row.q_schedule, row.cv_fit_percent)
                                    for row in rows if row.cv_fit_percent is not None], P_TOLERANCE)
    # no candidate scored on the other half: the default, whose own run then says what went wrong
    chosen, schedule = choice if choice is not None else (options.p, q_schedule_of(options))
    start_fit = float(np.mean(list(start_fits.values()))) if len(start_fits) == 2 else None
    candidates = refined_cross_validation(folds.get((chosen, schedule), []), settings, options, held_out_fit)
    return PTuning(chosen, tuple(rows), time.perf_counter() - started,
                   start_fit if start_fit is not None and np.isfinite(start_fit) else None, schedule, candidates)


#: The models the returned-model decision weighs, by name: the filter's and its start's, as they are and refined.
CANDIDATES = ("filter", "start", "filter refined", "start refined")
#: Refinement steps at most on a cross-validation's half: it asks whether refining predicts the other half
#: clearly better or worse (by the schedule margin), which the first steps decide; on the public records the
#: hold-out fits of a refinement stopped after 10, 20 or 40 steps differ by 0.7 point at most.
CROSS_VALIDATION_ITERATIONS = 20


def refined_cross_validation(folds: Sequence[tuple], settings: IdentifyOptions, options: IEKFOptions,
                             held_out_fit: Callable[[ModalModel, tuple[IOData, ...]], float]
                             ) -> dict[str, float | None] | None:
    """Two-fold cross-validated fits of the chosen candidate's model and of its start, as they are and refined.

    ``folds`` holds each fold's ``(model, start, fitted on, scored on)``; each
    stable model is refined by its simulation error on the half it was
    fitted to (:func:`refine`) and scored, as it is and refined, on the other
    half. None where no refinement applies (:func:`refines`) or a fold is
    missing; a model that cannot be scored on both folds gets None.
    """
    if len(folds) != 2 or not refines(settings, options):
        return None
    scores: dict[str, list[float]] = {name: [] for name in CANDIDATES}
    for model, start, fit_on, score_on in folds:
        for name, candidate in (("filter", model), ("start", start)):
            if not isinstance(candidate, ModalModel) or not candidate.is_stable():
                continue
            scores[name].append(held_out_fit(candidate, score_on))
            try:
                refined = refine(candidate, fit_on, settings, max_iterations=CROSS_VALIDATION_ITERATIONS)
                scores[f"{name} refined"].append(held_out_fit(refined.model, score_on))
            except InputError:  # not simulable on its half: no refined score
                pass
    return {name: float(np.mean(values)) if len(values) == 2 and np.all(np.isfinite(values)) else None
            for name, values in scores.items()}


def refines(settings: IdentifyOptions, options: IEKFOptions) -> bool:
    """Whether a run's models are refined by their simulation errors: on the unit-free settings only (the paper's
    absolute ones are its method as published, kept for contrast), and not where the score is a k-step
    prediction (``--horizon``, or a run that allows unstable modes, an open-loop unstable plant's), which a
    simulation error does not measure."""
    return options.timescale == "auto" and settings.horizon is None and not options.allow_unstable


def refine(model: ModalModel, records: Sequence[IOData], settings: IdentifyOptions, **limits: Any) -> Any:
    """``model`` refined by its simulation error on ``records``, each from its own initial state where the scores
    estimate it (:func:`~vehid.identification.classical.simulation_error.refine_simulation_error`, which takes
    ``limits``)."""
    from vehid.identification.classical.simulation_error import refine_simulation_error

    return refine_simulation_error(model, records, initial_state="estimate" if settings.initial_state == "estimate"
                                   else "zero", **limits)


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
        halves = [part[0] for part in _halves((first,))]
        folds = [_start_fits(a, b, structure, options) for a, b in (halves, halves[::-1])]
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

    A run scored by simulation (:func:`refines`) with a stable model returns a
    model refined by its simulation error on the estimation records: the
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
    start needs to win by :data:`P_TOLERANCE` only.
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


REFINED_CV_MEASURE = "two-fold cross-validated NRMSE fit % of each model refined by its simulation error"
# the key of a refined run's linear model before refinement, from which the spline filter (--nonlinear) starts: it
# continues the filter's own estimate, as the paper's spline filter continues its linear one. From the refined
# model of the cascaded tanks it validated at 70.8 % against 75.7 % from the filter's, below its linear start.
SPLINE_START = "spline_start"


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
    value = float(np.mean(_mean_scores(model, plan.records, initial_state=settings.initial_state).fit))
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
    """The filter's model and its start refined by their simulation errors on the estimation records (:func:`refine`);
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


REFINED_MEASURE = "estimation NRMSE fit % of each model refined by its simulation error"


def refined_choice(refined: RefinedCandidates, plan: Plan, settings: IdentifyOptions, tuning: PTuning,
                   unstable: dict[str, Any] | None, keys: dict[str, Any]) -> tuple[ModalModel, dict[str, Any]]:
    """The better of the refined filter's and the refined start's models on the estimation records, and the keys.

    Without cross-validation (p given) both minimise the same criterion on
    the same records from two starts, and the lower minimum is the better
    estimate: the start's is returned where it fits better by more than
    :data:`P_TOLERANCE` points (key ``start_kept`` then holds both fits). The
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
        value = float(np.mean(_mean_scores(model, plan.records, initial_state=settings.initial_state, horizon=horizon).fit))
        return value if np.isfinite(value) else -np.inf

    return {"start_estimation_fit_percent": fit(start), "filter_estimation_fit_percent": fit(result.model),
            "horizon": horizon}


def margin_entry(choice: Any, score: Any, runner_up: Any, runner_up_score: Any, measure: str, rule: str) -> dict[str, Any]:
    """One ``decision_margins`` entry: the choice and its score, the runner-up and its, the measure and the rule."""
    def number(value: Any) -> float | None:
        return float(value) if value is not None and np.isfinite(value) else None

    return {"choice": choice, "score": number(score), "runner_up": runner_up, "runner_up_score": number(runner_up_score),
            "measure": measure, "rule": rule}


def decision_margins(tuning: PTuning, unstable: dict[str, Any] | None, comparison: dict[str, Any] | None,
                     returned: str) -> dict[str, dict[str, Any]]:
    """Each choice one IEKF run made by itself, with its score and the runner-up's (JSON ``decision_margins``).

    Keys: ``p`` (where cross-validated), ``open_loop_unstable`` (where weighed),
    ``model_returned`` (where the start is known); :func:`order_margin` adds
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


def order_margin(rows: list[dict[str, Any]], chosen: int) -> dict[str, Any]:
    """The order decision of an order search: the chosen order's ranking fit and the best other eligible order's."""
    eligible = {row["order"]: row["ranking_fit"] for row in rows if row.get("eligible")}
    others = [(order, fit) for order, fit in eligible.items() if order != chosen]
    runner_up = max(others, key=lambda item: item[1]) if others else (None, None)
    return margin_entry(chosen, eligible.get(chosen), runner_up[0], runner_up[1], measure="mean validation NRMSE fit %",
                   rule=f"the smallest order within {ORDER_TOLERANCE} points of the best")


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


def refinement_note(entry: dict[str, Any]) -> str:
    """The note of a model refined by its simulation error, or of a refinement left out (:func:`returned_model`'s
    ``refinement``)."""
    fits = entry.get("fits") or {}

    def best(*names: str) -> float:
        return max(fits[name] for name in names if fits.get(name) is not None)

    if entry.get("left_out"):
        return (f"the models refined by their simulation errors predict the other half of the record worse than as "
                f"they are (two-fold cross-validated fit {best('filter refined', 'start refined'):.2f} % against "
                f"{best('filter', 'start'):.2f} %): no refinement")
    whose = "the filter's model" if entry["model"] == "filter" else "the data start"
    text = (f"{whose} refined by its simulation error on the estimation data: estimation fit "
            f"{entry['fit_before']:.2f} -> {entry['fit_after']:.2f} % ({entry['steps']} steps, {entry['stop_reason']})")
    if fits.get(f"{entry['model']} refined") is not None and fits.get(entry["model"]) is not None:
        text += (f"; two-fold cross-validated fit {fits[entry['model'] + ' refined']:.2f} % against "
                 f"{fits[entry['model']]:.2f} % as it was")
    if entry["model"] == "start" and fits.get("start refined") is not None and fits.get("filter refined") is not None:
        text += (f"; returned in the filter's place: the filter's model refined alike cross-validates "
                 f"{fits['filter refined']:.2f} %")
    return text


def iekf_options(settings: IdentifyOptions) -> IEKFOptions:
    """The IEKF's settings for these options: the unit-invariant ones unless asked otherwise."""
    p = settings.p if settings.p is not None else (INVARIANT_P if settings.timescale == "auto" else 1.0)
    # the unit-free time scale meets noise as IEKFOptions.invariant does; the paper's settings keep Q and R = I
    noise = invariant_noise_settings() if settings.timescale == "auto" else {}
    return IEKFOptions(
        p=p, passes=settings.passes, discretization=settings.discretization, covariance=settings.covariance,
        start=settings.start, normalize=settings.normalize, timescale=settings.timescale, allow_unstable=settings.allow_unstable,
        **noise,
    )


class _RankedScores:
    """What ranks a model: its ``estimation`` scores and the mean over its ``validation`` scores."""

    @property
    def validation_fit(self) -> np.ndarray | None:
        """NRMSE fit per output, mean over validation records."""
        return np.mean([s.fit for s in self.validation], axis=0) if self.validation else None

    @property
    def validation_R(self) -> np.ndarray | None:
        return np.mean([s.R for s in self.validation], axis=0) if self.validation else None

    def ranking_fit(self) -> float:
        """Mean validation fit (estimation fit without validation data)."""
        return float(np.mean(self.validation_fit if self.validation else self.estimation.fit))


@dataclass(frozen=True, eq=False)
class Evaluation(_RankedScores):
    """Scores of one model on the estimation record and on each validation record."""

    estimation: Scores
    estimation_R_from_rest: np.ndarray
    validation: tuple[Scores, ...]
    horizon: int | None

    def __post_init__(self) -> None:
        object.__setattr__(self, "estimation_R_from_rest", freeze(np.asarray(self.estimation_R_from_rest, dtype=float)))
        object.__setattr__(self, "validation", tuple(self.validation))


def evaluate(model: Any, plan: Plan, settings: IdentifyOptions) -> Evaluation:
    """Score ``model`` on the plan's records (k-step-ahead where asked or where simulation diverges)."""
    horizon = settings.horizon if settings.horizon is not None else default_horizon(model)
    estimation = _mean_scores(model, plan.records, initial_state=settings.initial_state, horizon=horizon)
    from_rest = _mean_scores(model, plan.records, initial_state="zero", horizon=horizon).R
    validation = tuple(score(model, record, initial_state=settings.initial_state, horizon=horizon)
                       for record in plan.validation)
    return Evaluation(estimation, from_rest, validation, horizon)


def _mean_scores(model: Any, records: tuple[IOData, ...], **options: Any) -> Scores:
    """Scores on one record, or their mean per output over several (as validation records are averaged)."""
    scores = [score(model, record, **options) for record in records]
    if len(scores) == 1:
        return scores[0]
    return dataclasses.replace(scores[0], fit=np.mean([s.fit for s in scores], axis=0),
                               R=np.mean([s.R for s in scores], axis=0),
                               n_samples=sum(s.n_samples for s in scores))


def run_warnings(*, model: Any, evaluation: Evaluation, stop_reason: str | None, start_fit: float | None,
                 final_fit: float | None, allow_unstable: bool, label: str = "", start_moved: bool | None = None,
                 p_tuned: bool = False, fit_history: Sequence[float] | None = None,
                 below_zero_remedy: str = "try another order") -> list[str]:
    """One line per problem of the model returned, each naming one cause and one remedy (module docstring).

    A model worse than its start is not among them: the start is then
    returned (:func:`returned_model`). A run stopped by the pass limit warns
    only where its fit was still moving (``fit_history``, the mean R per pass:
    more than :data:`SETTLED_FIT` points over the last :data:`SETTLED_PASSES`
    passes); modes left at their start values warn only where p was given
    (``p_tuned`` False): a cross-validated p already weighed larger ones.
    ``start_fit`` is kept for callers; the comparison with the start is the
    returned model's decision.
    """
    del start_fit  # the start-or-filter decision weighs the start (returned_model)
    prefix = f"{label}: " if label else ""
    lines = []
    if stop_reason is not None and stop_reason.startswith("diverged"):
        lines.append(f"{prefix}the run diverged ({stop_reason}); the last good pass is returned: give a smaller --p")
    elif stop_reason is not None and stop_reason != "converged" and not _fit_settled(fit_history):
        lines.append(f"{prefix}the run did not converge ({stop_reason}): its fit was still changing at the last "
                     "pass; raise --passes")
    if start_moved is False and not p_tuned and final_fit is not None and final_fit < NOTHING_TO_GAIN:
        lines.append(f"{prefix}the model is no better than its start: its modes stayed at their start values "
                     f"(mean R {final_fit:.3f} %); give a larger --p")
    if model is not None and model.is_linear and not allow_unstable and not model.is_stable():
        lines.append(f"{prefix}the model is unstable where stability was asked: lower the order, or give "
                     "--allow-unstable for an open-loop unstable plant")
    scored = [("estimation", evaluation.estimation)] + [("validation", s) for s in evaluation.validation]
    for where, scores in scored:
        bad = np.flatnonzero(~(scores.fit >= 0))
        if bad.size:
            lines.append(f"{prefix}fit below zero on {where} data for output(s) {', '.join(str(i + 1) for i in bad)} "
                         f"({', '.join(f'{scores.fit[i]:.1f} %' for i in bad)}): the model explains less than the "
                         f"output's mean; {below_zero_remedy}, or check that the inputs drive these outputs")
            break
    return lines


def _fit_settled(fit_history: Sequence[float] | None) -> bool:
    """Whether a run's mean R moved less than :data:`SETTLED_FIT` points over its last :data:`SETTLED_PASSES` passes."""
    if fit_history is None or len(fit_history) <= SETTLED_PASSES:
        return False
    tail = np.asarray(fit_history[-SETTLED_PASSES - 1:], dtype=float)
    return bool(np.all(np.isfinite(tail)) and np.ptp(tail) < SETTLED_FIT)


def choose_order(rows: list[dict[str, Any]]) -> int:
    """The smallest order within :data:`ORDER_TOLERANCE` points of the best mean validation fit (eligible rows only)."""
    eligible = [row for row in rows if row.get("eligible")]
    if not eligible:
        raise DivergenceError("no order gave a usable model: " + "; ".join(
            f"n = {row['order']}: {row.get('error') or 'unstable or diverged'}" for row in rows))
    best = max(row["ranking_fit"] for row in eligible)
    return min(row["order"] for row in eligible if row["ranking_fit"] >= best - ORDER_TOLERANCE)


def pooled_fit_percent(R: Any, records: Sequence[IOData]) -> np.ndarray:
    """The NRMSE fit per output of a simulation whose R pooled over ``records`` is ``R`` (both pooled alike)."""
    from vehid.identification.assessment.multirecord import pooled_nrmse_fit_of_R

    return pooled_nrmse_fit_of_R(R, records)


def scores_summary(evaluation: Evaluation, R: Any, records: Sequence[IOData]) -> dict[str, Any]:
    """The public score keys of a model, each ``*fit_percent`` an NRMSE fit and each ``*R`` its eq. 17 twin.

    ``fit_percent`` and ``R`` are the model simulated from rest over the estimation ``records`` (``R``
    given, pooled over them, as the IEKF reports it); the others are by the run's scoring rule:
    ``estimation_*`` on the estimation records, ``validation_*`` the mean over the validation records,
    and ``validation_records`` each of them.
    """
    return {
        "fit_percent": pooled_fit_percent(R, records),
        "R": R,
        "estimation_fit_percent": evaluation.estimation.fit,
        "estimation_R": evaluation.estimation.R,
        "validation_fit_percent": evaluation.validation_fit,
        "validation_R": evaluation.validation_R,
        "validation_records": [s.as_dict() for s in evaluation.validation],
        "initial_state": evaluation.estimation.initial_state,
        "horizon": evaluation.horizon,
    }


def search_orders(plan: Plan, fit_one: Callable[[int], tuple[Any, dict[str, Any]]], settings: IdentifyOptions
                  ) -> tuple[list[dict[str, Any]], dict[int, tuple[Any, dict[str, Any], Evaluation]]]:
    """Identify each order of the plan (``fit_one(order) -> (model, extra)``), score it, stop early for auto."""
    rows: list[dict[str, Any]] = []
    kept: dict[int, tuple[Any, dict[str, Any], Evaluation]] = {}
    best, without_gain = -np.inf, 0
    for order in plan.orders:
        started = time.perf_counter()
        row: dict[str, Any] = {"order": order}
        try:
            model, extra = fit_one(order)
        except WorkbenchError as exc:
            row.update(error=str(exc), eligible=False, seconds=time.perf_counter() - started)
            rows.append(row)
            continue
        evaluation = evaluate(model, plan, settings)
        assumed = (extra.get("open_loop_unstable") or {}).get("assumed", False)  # as --allow-unstable
        stable_enough = settings.allow_unstable or assumed or not model.is_linear or model.is_stable()
        row.update(
            fit_percent=extra.get("fit_percent"),
            estimation_fit_percent=evaluation.estimation.fit,
            validation_fit_percent=evaluation.validation_fit,
            ranking_fit=evaluation.ranking_fit(),
            stop_reason=extra.get("stop_reason"),
            **({"p": extra["p"]} if "p" in extra else {}),
            **({"q_schedule": extra["tuning"].q_schedule} if "tuning" in extra else {}),
            seconds=time.perf_counter() - started,
            eligible=bool(stable_enough and np.isfinite(evaluation.ranking_fit())),
        )
        rows.append(row)
        kept[order] = (model, extra, evaluation)
        if plan.auto:
            if row["eligible"] and row["ranking_fit"] > best + ORDER_TOLERANCE:
                best, without_gain = row["ranking_fit"], 0
            else:
                without_gain += 1
                if without_gain >= 2:
                    break
    return rows, kept


@dataclass(frozen=True, eq=False)
class NonlinearOutcome:
    """The chosen spline model's run, its JSON entry ``nonlinear`` and its scores by the run's rule
    (kept so that nothing simulates it again)."""

    result: SplineIEKFResult
    summary: FrozenDict
    scores: NonlinearScores

    def __post_init__(self) -> None:
        object.__setattr__(self, "summary", freeze(self.summary))


#: points of mean validation fit by which the spline model must beat the model otherwise returned (the same
#: margin as a scheduled family's: it has several times the parameters); without validation data
#: :data:`WHOLE_RECORD_MARGIN` on the estimation fit
NONLINEAR_MARGIN = 0.5


def nonlinear_margin(spline: Any, other: Any, other_name: str) -> dict[str, Any]:
    """The decision ``nonlinear``: the spline model or the model otherwise returned, both scored by the run's rule.

    The spline model is returned where its ranking fit (mean validation fit, else mean estimation fit)
    beats the other's by :data:`NONLINEAR_MARGIN` points (:data:`WHOLE_RECORD_MARGIN` without
    validation data, where both fitted the record they are scored on).
    """
    held_out = bool(spline.validation) and other.validation_fit is not None
    margin = NONLINEAR_MARGIN if held_out else WHOLE_RECORD_MARGIN
    score, runner = spline.ranking_fit(), other.ranking_fit()
    wins = bool(np.isfinite(score) and (not np.isfinite(runner) or score > runner + margin))
    how = (f"{spline.horizon}-step-ahead prediction" if spline.horizon is not None
           else f"simulation, initial state {spline.estimation.initial_state}")
    entry = margin_entry(*(("nonlinear", score, other_name, runner) if wins else (other_name, runner, "nonlinear", score)),
                         measure=("mean validation" if held_out else "mean estimation") + f" NRMSE fit % ({how})",
                         rule=f"the spline model where it beats the model otherwise returned by more than {margin} points")
    return {**entry, "margin": margin}


def nonlinear_note(margin: dict[str, Any]) -> str:
    """The note of the decision ``nonlinear``: the spline model returned in the other's place, or not and why."""
    def shown(value: Any) -> str:
        return "-" if value is None else f"{value:.2f}"

    if margin["choice"] == "nonlinear":
        return (f"the spline-nonlinear model is returned: it beats the {margin['runner_up']} model by more than "
                f"{margin['margin']:g} points ({margin['measure']} {shown(margin['score'])} against "
                f"{shown(margin['runner_up_score'])})")
    return (f"the spline-nonlinear model is not returned: it does not beat the {margin['choice']} model by the margin "
            f"({margin['measure']} {shown(margin['runner_up_score'])} against {shown(margin['score'])}); try a "
            "smaller --nonlinear-p or fewer --nodes")


def identify_nonlinear(linear: ModalModel, plan: Plan, settings: IdentifyOptions) -> NonlinearOutcome:
    """The spline-nonlinear model started from ``linear``, its p chosen on validation data from a small grid."""
    from vehid.identification.filtering.spline_iekf import SplineIEKFOptions, identify_spline_iekf

    if not isinstance(linear, ModalModel):
        raise OptionError("'nonlinear' starts from a continuous-time modal model; this linear model is discrete-time "
                          "(a pole on the negative real axis): use 'method' iekf or another 'order'",
                          "nonlinear", "method", "order")
    if len(plan.records) > 1:
        raise OptionError("'nonlinear' identifies the spline model from one record; give one data file", "nonlinear")
    grid = settings.nonlinear_p or (list(NONLINEAR_P_GRID) if plan.validation else [NONLINEAR_P])
    tried, candidates = [], []
    for p in grid:
        options = SplineIEKFOptions(nodes=settings.nodes, p=p, passes=settings.nonlinear_passes)
        started = time.perf_counter()
        try:
            result = identify_spline_iekf(plan.estimation, linear, options=options)
        except DivergenceError as exc:
            tried.append({"p": p, "error": str(exc), "seconds": time.perf_counter() - started})
            continue
        scores = NonlinearScores.of(result.model, plan, settings)
        row = {"p": p, "estimation_fit_percent": scores.estimation.fit, "validation_fit_percent": scores.validation_fit,
               "seconds": time.perf_counter() - started, "ranking_fit": scores.ranking_fit()}
        tried.append(row)
        if np.isfinite(row["ranking_fit"]):
            candidates.append((result, row, scores))
    if not candidates:
        raise DivergenceError("the spline-nonlinear model diverged at every p tried: " +
                              "; ".join(f"p = {row['p']:g}: {row.get('error', 'no finite fit')}" for row in tried))
    # as for the IEKF's p: the largest within the tolerance of the best (it converges in fewer passes)
    top = max(row["ranking_fit"] for _, row, _ in candidates)
    result, row, scores = max((c for c in candidates if c[1]["ranking_fit"] >= top - P_TOLERANCE),
                              key=lambda c: c[1]["p"])
    from vehid.identification.assessment.metrics import nrmse_fit_of_R
    from vehid.identification.assessment.multirecord import pooled_simulation_fit

    from_rest = pooled_simulation_fit(result.model, plan.records)
    with np.errstate(all="ignore"):  # the spline filter's start R is over the (one) estimation record
        start_fit = nrmse_fit_of_R(result.start_fit, plan.records[0].y)
    summary = {
        "nodes": settings.nodes, "p": row["p"], "p_tried": tried, "passes_run": result.passes_run,
        "stop_reason": result.stop_reason, "fit_percent": pooled_fit_percent(from_rest, plan.records), "R": from_rest,
        "estimation_fit_percent": scores.estimation.fit, "estimation_R": scores.estimation.R,
        "validation_fit_percent": scores.validation_fit, "validation_R": scores.validation_R,
        "initial_state": scores.estimation.initial_state,
        "start_fit_percent": start_fit, "start_R": result.start_fit, "seconds": result.seconds,
        "uncertainty_method": uncertainty_method(result.model),
    }
    return NonlinearOutcome(result, summary, scores)


@dataclass(frozen=True, eq=False)
class NonlinearScores(_RankedScores):
    """Scores of a spline model on the plan's records, by the run's rule (``settings``), as every candidate's.

    The initial state and the records are those of :func:`evaluate`; a spline model is simulated
    (in its own time base) whatever the horizon, since only a linear model predicts k steps ahead.
    """

    estimation: Scores
    validation: tuple[Scores, ...]
    horizon: int | None

    @classmethod
    def of(cls, model: Any, plan: Plan, settings: IdentifyOptions | None = None) -> "NonlinearScores":
        """The scores of ``model`` on ``plan``'s records by the rule of ``settings`` (default: the command's)."""
        scored = evaluate(model, plan, settings if settings is not None else IdentifyOptions())
        return cls(scored.estimation, scored.validation, scored.horizon)


def start_of(result: Any, records: tuple[IOData, ...]) -> tuple[float | None, bool | None]:
    """Mean R (eq. 17) of an IEKF run's start model simulated from rest, and whether the modes moved from it.

    A mode moved when its eigenvalue changed by more than :data:`MOVED` of its magnitude
    (a unit-free test; None where the start is unknown, as on a resumed run).
    """
    theta = result.meta.get("start_parameters") if hasattr(result, "meta") else None
    if theta is None:
        return None, None
    model = ModalModel.from_parameters(result.structure, theta)
    start_modes, final_modes = model.mode_eigenvalues(), result.model.mode_eigenvalues()
    moved = bool(np.max(np.abs(final_modes - start_modes) / np.maximum(np.abs(start_modes), 1e-300)) > MOVED)
    from vehid.identification.assessment.multirecord import pooled_simulation_fit

    fit = pooled_simulation_fit(model, records)
    if not np.all(np.isfinite(fit)):  # the start overflows: no fit to compare with
        return None, moved
    return float(np.mean(fit)), moved


def structure_for(settings: IdentifyOptions, order: int, plan: Plan, options: IEKFOptions) -> ModalStructure:
    """The model structure of an IEKF run: ``--pattern`` where given, else the data start's modes
    (:func:`vehid.identification.filtering.iekf.start_structure`) or, for other starts, the default pattern."""
    first = plan.records[0]
    structure = ModalStructure.from_pattern(settings.pattern or "default", order, first.n_u, first.n_y)
    if settings.pattern is not None:
        return structure
    return start_structure(plan.estimation, structure, options)


def last_good_on_divergence(run: Callable[[], Any]) -> tuple[Any, str | None]:
    """``run()``'s IEKF result, or on a DivergenceError after some good passes the last good one and the message.

    Nothing computed is lost: the caller reports that model with a warning. A divergence at the first
    pass leaves no model and is raised.
    """
    try:
        return run(), None
    except DivergenceError as exc:
        if exc.last_good is None:
            raise
        return exc.last_good, str(exc)


@dataclass(frozen=True)
class RunDecisions:
    """What is decided before an IEKF run of one order: the filter's options (p and Q schedule applied),
    its structure, the p tuning, the open-loop-unstable entry and the filter steps planned for the order."""

    options: IEKFOptions
    structure: ModalStructure
    tuning: PTuning
    unstable: dict[str, Any] | None
    planned_steps: int


def decide_run(settings: IdentifyOptions, plan: Plan, options: IEKFOptions, order: int) -> RunDecisions:
    """The decisions before an IEKF run of ``order``, in their order: the open-loop-unstable treatment
    (:func:`assume_unstable`), the structure (:func:`structure_for`), p and Q schedule (:func:`tune_p`,
    or the p given) and the compiled build's planned steps (:func:`planned_filter_steps`)."""
    options, unstable = assume_unstable(settings, plan, options, order)
    structure = structure_for(settings, order, plan, options)
    tuning = tune_p(settings, plan, options, structure) if tunes_p(settings) else given_p(options)
    planned = planned_filter_steps(plan, options, tuned=bool(tuning.tried))
    return RunDecisions(tuning.applied(options), structure, tuning, unstable, planned)


def run_iekf_order(settings: IdentifyOptions, plan: Plan, options: IEKFOptions, order: int
                   ) -> tuple[ModalModel, dict[str, Any]]:
    """One IEKF run of an order search (no checkpoints, p tuned per order): its model and what the summary needs."""
    decided = decide_run(settings, plan, options, order)
    result, divergence = last_good_on_divergence(
        lambda: identify_iekf(plan.estimation, decided.structure, options=decided.options,
                              settle_start=plan.settle_start, planned_steps=decided.planned_steps))
    stop_reason = f"{result.stop_reason}: {divergence}" if divergence else result.stop_reason
    model, keys = returned_model(result, plan, settings, decided.tuning, decided.unstable)
    return model, {"fit_percent": result.fit_percent, "stop_reason": stop_reason, "result": result,
                   "tuning": decided.tuning, "p": decided.tuning.p, **keys}
