"""The automatic pipeline on a plan: one estimator run or an order search, then the common end.

:func:`identify_plan` takes a :class:`~vehid.identification.automatic.plan.Plan`
and :class:`~vehid.identification.automatic.options.IdentifyOptions` and
returns the typed :class:`~vehid.identification.automatic.result.Identification`.
A caller that keeps the run on disk passes :class:`Checkpoints` (told of the
decisions before the IEKF's passes, of every pass and of the end) and, to go
on with a run it kept, :class:`Resumed`; the pipeline itself writes nothing.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping, Protocol

import numpy as np

from vehid.identification.automatic.scoring import (Evaluation, evaluate, last_good_on_divergence, pooled_fit_percent,
                                                    run_warnings, start_of)
from vehid.identification.automatic.refinement import SPLINE_START
from vehid.identification.automatic.tuning import iekf_options, planned_filter_steps
from vehid.identification.automatic.returned import decision_notes, returned_model
from vehid.identification.automatic.orders import choose_order, order_margin, search_orders
from vehid.identification.automatic.nonlinear import identify_nonlinear, nonlinear_margin, nonlinear_note
from vehid.identification.automatic.iekf_order import decide_run, run_iekf_order
from vehid.identification.automatic.reported_checks import data_warnings, records_summary, returned_checks
from vehid.identification.dataio.cleaning import cleaning_notes
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.result import (Decision, Identification, OrderRow, StabilityDecision, StartKept,
                                                   float_tuple)
from vehid.identification.filtering.iekf import identify_iekf

__all__ = ["Checkpoints", "Resumed", "identify_plan"]


class Checkpoints(Protocol):
    """What a caller keeping the run is told as it goes (a single-order IEKF run only)."""

    def decided(self, options: Any, tuning: Any, unstable: Mapping[str, Any] | None, previous: Any) -> None:
        """The filter's options, p tuning and stability decision, before the first pass is run."""

    def passed(self, record: Any, so_far: Any) -> None:
        """One pass finished (the filter's ``on_pass``)."""

    def finished(self, result: Any) -> None:
        """The run ended (converged, out of passes or diverged)."""


@dataclass(frozen=True)
class Resumed:
    """A kept IEKF run to go on with: its structure, filter options, finished passes and decisions."""

    structure: Any
    options: Any
    previous: Any
    tuning: Any
    open_loop_unstable: Mapping[str, Any] | None


def identify_plan(plan: Plan, options: IdentifyOptions, *, resumed: Resumed | None = None,
                  checkpoints: Checkpoints | None = None) -> Identification:
    """Identify the plan's records as `vehid identify` does (module docstring of :mod:`~.steps`)."""
    if resumed is not None:
        structure, iekf, previous = resumed.structure, resumed.options, resumed.previous
        tuning, unstable = resumed.tuning, resumed.open_loop_unstable
        # the build the interrupted run used
        planned = planned_filter_steps(plan, iekf, tuned=tuning is not None and bool(tuning.tried))
    else:
        if options.method != "iekf":
            return _comparator(plan, options)
        iekf = iekf_options(options)
        if len(plan.orders) > 1:
            return _order_search(plan, options, iekf)
        previous = None
        decided = decide_run(options, plan, iekf, plan.orders[0])
        iekf, structure, tuning = decided.options, decided.structure, decided.tuning
        unstable, planned = decided.unstable, decided.planned_steps
    if checkpoints is not None:
        checkpoints.decided(iekf, tuning, unstable, previous)
    on_pass = checkpoints.passed if checkpoints is not None else None
    result, divergence = last_good_on_divergence(
        lambda: identify_iekf(plan.estimation, structure, options=iekf, resume=previous, on_pass=on_pass,
                              settle_start=plan.settle_start, planned_steps=planned))
    if checkpoints is not None:
        checkpoints.finished(result)
    model, keys = returned_model(result, plan, options, tuning, unstable)
    return _finish(plan, options, model, estimator=result, tuning=tuning, keys=keys, divergence=divergence,
                   seconds=result.seconds)


def _order_search(plan: Plan, options: IdentifyOptions, iekf: Any) -> Identification:
    """Each order of a range identified on the estimation data; one chosen on validation data."""
    rows, kept = search_orders(plan, lambda order: run_iekf_order(options, plan, iekf, order), options)
    chosen = choose_order(rows)
    model, extra, _ = kept[chosen]
    keys = {key: extra[key] for key in ("open_loop_unstable", "start_kept", "decision_margins", "model_returned",
                                        "refinement", SPLINE_START) if key in extra}
    keys["decision_margins"] = {**keys.get("decision_margins", {}), "order": order_margin(rows, chosen)}
    return _finish(plan, options, model, estimator=extra["result"], tuning=extra["tuning"], keys=keys,
                   seconds=sum(row["seconds"] for row in rows), rows=rows)


def _comparator(plan: Plan, options: IdentifyOptions) -> Identification:
    """A classical method on the same plan, searched over orders alike where several are given."""
    from vehid.identification.comparators import identify_with

    outcomes = {}
    extra = {"bootstrap": options.bootstrap} if options.bootstrap is not None else {}

    def fit_one(order):
        outcome = identify_with(plan.estimation, method=options.method, order=order, **extra)
        outcomes[order] = outcome
        return outcome.model, {"fit_percent": outcome.metrics.percentage_explanation}

    rows = None
    keys: dict[str, Any] = {}
    if len(plan.orders) == 1:
        chosen = plan.orders[0]
        fit_one(chosen)  # errors carry their own exit status
    else:
        rows, _ = search_orders(plan, fit_one, options)
        chosen = choose_order(rows)
        keys["decision_margins"] = {"order": order_margin(rows, chosen)}
    outcome = outcomes[chosen]
    return _finish(plan, options, outcome.model, estimator=outcome, keys=keys, seconds=outcome.seconds, rows=rows,
                   order=chosen, fit=outcome.metrics.percentage_explanation,
                   time_domain=outcome.model.meta.get("time_domain", "continuous"))


def _row(row: Mapping[str, Any], records: Any) -> OrderRow:
    """An order search's row as a typed row (its R from rest also as an NRMSE fit over ``records``)."""
    R = row.get("fit_percent")  # the order search keeps each run's R from rest
    return OrderRow(order=int(row["order"]), fit_percent=None if R is None else pooled_fit_percent(R, records),
                    R=R,
                    estimation_fit_percent=row.get("estimation_fit_percent"),
                    validation_fit_percent=row.get("validation_fit_percent"), seconds=float(row["seconds"]),
                    ranking_fit=row.get("ranking_fit"), eligible=row.get("eligible"),
                    stop_reason=row.get("stop_reason"), p=row.get("p"), q_schedule=row.get("q_schedule"),
                    error=row.get("error"), searched=True)


def _finish(plan: Plan, options: IdentifyOptions, model: Any, *, estimator: Any, keys: Mapping[str, Any],
            seconds: float, tuning: Any = None, divergence: str | None = None, rows: Any = None,
            order: int | None = None, fit: Any = None, time_domain: str | None = None) -> Identification:
    """Scores, checks, notes, warnings and the other candidates: the common end of every run.

    The linear model above is the first candidate; the scheduled family and the spline model are
    the others (:func:`_candidates`). Warnings, checks and scores are the returned model's; what
    became of the others, their own problems included, is said in notes.
    """
    from vehid.identification.assessment.multirecord import pooled_simulation_fit

    data = plan.records[0]
    iekf = tuning is not None
    result = estimator if iekf else None
    start_returned = result is not None and keys.get("model_returned") == "start"
    if iekf:
        order = result.structure.n
        # the filter's R unless another model (its start, or either refined) is returned
        fit = pooled_simulation_fit(model, plan.records) if model is not result.model else result.fit_percent
    evaluation = evaluate(model, plan, options)
    if rows is not None:
        orders = tuple(_row(row, plan.records) for row in rows)
    else:
        orders = (OrderRow(order=order, fit_percent=pooled_fit_percent(fit, plan.records), R=fit,
                           estimation_fit_percent=evaluation.estimation.fit,
                           validation_fit_percent=evaluation.validation_fit, seconds=seconds),)
    allow_unstable = options.allow_unstable or (result is not None and result.options.allow_unstable)
    # modes that never left their start are a problem of the run, whichever of the two models is returned
    start_fit, start_moved = start_of(result, plan.records) if result is not None else (None, None)
    notes = decision_notes({
        **{key: keys[key] for key in ("open_loop_unstable", "start_kept", "refinement") if key in keys},
        **({"model_returned": "start"} if start_returned else {}),
        **({"start_cv_fit_percent": tuning.start_fit, "filter_cv_fit_percent": tuning.chosen_fit} if iekf else {})})
    stop_reason = None
    if result is not None and not start_returned:
        stop_reason = f"{result.stop_reason}: {divergence}" if divergence else result.stop_reason
    warnings = run_warnings(
        model=model, evaluation=evaluation, start_fit=start_fit, stop_reason=stop_reason,
        final_fit=float(np.mean(fit)) if result is not None else None,
        allow_unstable=allow_unstable, start_moved=start_moved, p_tuned=bool(iekf and tuning.tried),
        fit_history=[record.mean_fit_continuous for record in result.history] if result is not None else None,
    )
    if result is not None and not start_returned:  # a pass that diverged and ran again with a smaller p
        warnings += list(result.meta.get("notes", ()))
    scoring_note = None
    if evaluation.horizon is not None and options.horizon is None:
        scoring_note = (f"the model is unstable: scored by {evaluation.horizon}-step-ahead prediction, "
                        "since its simulation diverges (--horizon K to choose K)")
    notes += cleaning_notes(plan.records)  # spikes interpolated, samples left out
    decisions = tuple(Decision.from_entry(name, entry) for name, entry in keys.get("decision_margins", {}).items())
    linear = _Candidate("start" if start_returned else ("filter" if iekf else options.method), model, evaluation,
                        warnings, fit, plan.records)
    # the spline model starts from the linear model before any refinement (SPLINE_START): the filter's own
    chosen, others, nonlinear, scheduled, more, said = _candidates(plan, options, linear,
                                                                   spline_start=keys.get(SPLINE_START, model))
    decisions += more
    notes += said
    for other in others:  # what went wrong with a model not returned is no warning about the one returned
        notes += [f"not returned, the {other.label} model: {line.removeprefix(other.name + ': ')}"
                  for line in other.warnings]
    warnings = list(chosen.warnings) + data_warnings(plan.records)
    checks, tests = returned_checks(chosen.model, chosen.first_record(plan),
                                    [record.nis for record in result.history] if result and chosen is linear else None)
    data_keys = records_summary(chosen.model, chosen.records(plan), plan.preparation)
    if chosen is not linear:  # the matrices and eigenvalues stay the linear model's: its modes beside them
        linear_checks, _ = returned_checks(model, data)
        if linear_checks is not None:
            data_keys["linear_modes"] = linear_checks["modes"]
    return Identification(
        model=chosen.model, method=options.method if not iekf else "iekf", order=int(order),
        fit_percent=float_tuple(chosen.fit_percent), R=float_tuple(chosen.R),
        estimation_fit_percent=float_tuple(chosen.evaluation.estimation.fit),
        validation_fit_percent=float_tuple(chosen.evaluation.validation_fit), decisions=decisions, notes=tuple(notes),
        warnings=tuple(warnings), orders=orders, seconds=float(seconds), plan=plan, evaluation=chosen.evaluation,
        estimator=estimator, tuning=tuning, open_loop_unstable=StabilityDecision.from_entry(keys.get("open_loop_unstable")),
        start_kept=StartKept.from_entry(keys.get("start_kept")), start_returned=start_returned, divergence=divergence,
        checks=checks, residual_tests=tests, data=data_keys,
        scoring_note=scoring_note if chosen is linear else None, nonlinear=nonlinear, time_domain=time_domain,
        scheduled=scheduled, unscheduled=model if chosen is not linear else None, returned=chosen.name)


@dataclass(frozen=True, eq=False)
class _Candidate:
    """A model the run may return: its name, scores by the run's rule, own warnings and R from rest."""

    name: str
    model: Any
    evaluation: Any
    warnings: list[str]
    R: Any  # per output, the model simulated from rest over the estimation records, pooled
    estimation_records: tuple

    @property
    def label(self) -> str:
        return {"filter": "linear", "start": "linear (the filter's start)", "scheduled": "scheduled",
                "nonlinear": "spline-nonlinear"}.get(self.name, self.name)

    @property
    def fit_percent(self) -> np.ndarray:
        return pooled_fit_percent(self.R, self.estimation_records)

    def records(self, plan: Plan) -> tuple:
        """The estimation records as this model reads them (a scheduled family's with its schedule last)."""
        if self.name != "scheduled":
            return plan.records
        from vehid.identification.automatic.scheduled import scheduled_records

        return scheduled_records(plan.records, plan.schedule.estimation, plan.schedule.channel)

    def first_record(self, plan: Plan) -> Any:
        return self.records(plan)[0]


def _candidates(plan: Plan, options: IdentifyOptions, linear: _Candidate, *, spline_start: Any = None
                ) -> tuple[_Candidate, list[_Candidate], Any, Any, tuple[Decision, ...], list[str]]:
    """The model returned among the linear one and the others asked for, every one scored by the run's rule.

    The scheduled family (a plan with a schedule) replaces the linear model where it beats it by
    its margin (decision ``schedule``); the spline model (``nonlinear``) replaces whichever of the two
    stands where it beats that by its own (decision ``nonlinear``). Returns the model returned, the
    others, the spline and scheduled outcomes, the decisions and their notes. The spline model starts
    from ``spline_start`` (default: the linear candidate's model).
    """
    chosen, others, decisions, notes = linear, [], (), []
    nonlinear = scheduled = spline = family = None
    if options.nonlinear:
        nonlinear = identify_nonlinear(linear.model if spline_start is None else spline_start, plan, options)
        scores = nonlinear.scores
        scored = Evaluation(scores.estimation, scores.estimation.R, scores.validation, scores.horizon)
        spline = _Candidate("nonlinear", nonlinear.result.model, scored, run_warnings(
            model=nonlinear.result.model, evaluation=scored, stop_reason=nonlinear.result.stop_reason,
            start_fit=float(np.mean(nonlinear.result.start_fit)), final_fit=float(np.mean(nonlinear.result.fit_percent)),
            allow_unstable=True, label="nonlinear"), nonlinear.summary["R"], plan.records)
    if plan.schedule is not None:  # the scheduled family, started from the linear model
        from vehid.identification.automatic.scheduled import NONLINEAR_NOTE, identify_scheduled_model

        scheduled = identify_scheduled_model(linear.model, plan, options, linear.evaluation)
        decisions += (Decision.from_entry("schedule", scheduled.margin),)
        family = _Candidate("scheduled", scheduled.model, scheduled.evaluation, scheduled.warnings,
                            scheduled.scores["R"], plan.records)
        notes += ([NONLINEAR_NOTE] if nonlinear is not None else []) + ([scheduled.note] if scheduled.note else [])
        chosen, others = (family, [linear]) if scheduled.returned else (linear, [family])
    if spline is not None:
        margin = nonlinear_margin(spline.evaluation, chosen.evaluation, chosen.name)
        decisions += (Decision.from_entry("nonlinear", margin),)
        notes.append(nonlinear_note(margin))
        chosen, others = (spline, [chosen, *others]) if margin["choice"] == "nonlinear" else (chosen, [*others, spline])
        if scheduled is not None:
            scheduled = dataclasses.replace(scheduled, summary=scheduled.summary | {"model_returned": {
                "scheduled": "scheduled", "nonlinear": "nonlinear"}.get(chosen.name, "unscheduled")})
    return chosen, others, nonlinear, scheduled, decisions, notes
