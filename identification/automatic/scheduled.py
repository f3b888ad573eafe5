"""The speed-scheduled variant of the pipeline: a family of modal models whose coefficients vary with a channel.

Started from the unscheduled model the pipeline returns, the scheduled IEKF
(:mod:`vehid.identification.filtering.scheduled_iekf`) fits the family on the
estimation record with the schedule channel beside its inputs; p is chosen on
validation data from a small grid, the family is scored by the run's one rule
(initial state, horizon, records: :func:`~vehid.identification.automatic.scoring.evaluate`),
as the unscheduled model is, and it is returned in the unscheduled model's
place only where it validates better by :data:`VALIDATION_MARGIN` (the
decision ``schedule``). What became of the model not returned is said in
notes, never in warnings: those concern the model returned. The channel is
data (a car's speed, never offset), held by the plan
(:class:`~vehid.identification.automatic.plan.ScheduleData`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from vehid.identification.automatic.scoring import (Evaluation, evaluate, last_good_on_divergence, margin_entry,
                                                    pooled_fit_percent, run_warnings, scores_summary)
from vehid.identification.automatic.tuning import P_TOLERANCE
from vehid.identification.automatic.returned import WHOLE_RECORD_MARGIN
from vehid.identification.automatic.reported_checks import records_summary, uncertainty_method
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.plan import ScheduleData
from vehid.identification.choices import SCHEDULED_DEFAULT_P, SCHEDULED_P_GRID
from vehid.identification.data import IOData
from vehid.identification.errors import DivergenceError, OptionError
from vehid.identification.frozen import FrozenDict, freeze
from vehid.identification.models.modal import ModalModel

if TYPE_CHECKING:
    from vehid.identification.filtering.scheduled_iekf import ScheduledIEKFResult
    from vehid.identification.models.scheduled import ScheduledModalModel

__all__ = ["NONLINEAR_NOTE", "VALIDATION_MARGIN", "OUTPUT_MAP_NODES", "ScheduledOutcome", "schedule_margin",
           "identify_scheduled_model", "with_output_map", "unscheduled_fit", "scheduled_records"]

# said where --nonlinear and --schedule are given together (JSON ``notes``)
NONLINEAR_NOTE = ("--nonlinear with --schedule: the scheduled family may gain a static output map (speed-scheduled "
                  "linear dynamics, then a piecewise-linear map of each output; scheduled.output_map), kept where it "
                  "validates better; the spline-nonlinear model ('nonlinear') of the unscheduled model is beside it")


@dataclass(frozen=True, eq=False)
class ScheduledOutcome:
    """The scheduled family, its summary entry, the score keys it replaces, its warnings and the decision's note.

    ``warnings`` are the family's own problems (they become the run's warnings where the family is
    returned, notes where it is not); ``note`` says why the family was not returned. ``summary``
    (JSON ``scheduled``), ``scores`` and ``margin`` are JSON entries, frozen.
    """

    model: ScheduledModalModel
    summary: FrozenDict
    scores: FrozenDict
    warnings: tuple[str, ...]
    result: ScheduledIEKFResult
    returned: bool  # the scheduled family is the model returned (else the unscheduled start)
    margin: FrozenDict  # the decision, as an entry of ``decision_margins``
    evaluation: Evaluation  # the family's scores by the run's rule
    note: str | None = None

    def __post_init__(self) -> None:
        for name in ("summary", "scores", "margin", "warnings"):
            object.__setattr__(self, name, freeze(getattr(self, name)))


#: points of mean validation fit by which the scheduled family must beat the unscheduled model to be returned:
#: as a larger order must beat a smaller one (it has several times the parameters)
VALIDATION_MARGIN = 0.5


def schedule_margin(evaluation: Any, unscheduled: Any) -> dict[str, Any]:
    """The scheduled family's and the unscheduled model's ranking fits, the measure and the margin to beat.

    Both evaluations are by the run's one rule (:func:`~vehid.identification.automatic.scoring.evaluate`).

    On validation data the mean validation fit with :data:`VALIDATION_MARGIN`; without, the estimation
    fit, where the family fitted its own record with many more parameters, so it must win by the
    start-or-filter rule's :data:`~vehid.identification.automatic.returned.WHOLE_RECORD_MARGIN`.
    """

    def number(value: Any) -> float | None:
        return float(value) if value is not None and np.isfinite(value) else None

    held_out = bool(evaluation.validation) and unscheduled.validation_fit is not None
    margin = VALIDATION_MARGIN if held_out else WHOLE_RECORD_MARGIN
    return {"score": number(evaluation.ranking_fit()), "runner_up_score": number(unscheduled.ranking_fit()),
            "margin": margin,
            "measure": ("mean validation" if held_out else "mean estimation") + f" NRMSE fit % ({rule_text(evaluation)})",
            "rule": f"the scheduled model where it beats the unscheduled one by more than {margin} points"}


def rule_text(evaluation: Any) -> str:
    """How an evaluation scored its model: ``simulation, initial state estimate`` or ``10-step-ahead prediction``."""
    if evaluation.horizon is not None:
        return f"{evaluation.horizon}-step-ahead prediction"
    return f"simulation, initial state {evaluation.estimation.initial_state}"


def identify_scheduled_model(start: Any, plan: Any, options: IdentifyOptions, unscheduled: Any) -> ScheduledOutcome:
    """The scheduled family started from ``start`` (the unscheduled model returned), scored on the plan's records.

    ``unscheduled`` is the start's :class:`~vehid.identification.automatic.scoring.Evaluation`.
    """
    from vehid.identification.filtering.scheduled_iekf import ScheduledIEKFOptions, identify_scheduled

    if not isinstance(start, ModalModel):
        raise OptionError("'schedule' starts from a continuous-time modal model; this unscheduled model is "
                          "discrete-time (a pole on the negative real axis): use 'method' iekf or another 'order'",
                          "schedule", "method", "order")

    schedule = plan.schedule
    scheduled_plan = dataclasses.replace(
        plan, records=scheduled_records(plan.records, schedule.estimation, schedule.channel),
        validation=scheduled_records(plan.validation, schedule.validation, schedule.channel))
    grid = options.schedule_p or (list(SCHEDULED_P_GRID) if plan.validation else [SCHEDULED_DEFAULT_P])
    tried, candidates = [], []
    for p in grid:
        filter_options = ScheduledIEKFOptions(knots=options.schedule_knots, grid=options.schedule_grid, p=p,
                                              discretization=options.discretization, stable=not options.allow_unstable)
        stops: list[tuple[float, int, Any]] = []  # (held-out ranking fit, steps, family) of each refinement step

        def on_refine(candidate: Any, refine_steps: int) -> None:
            if plan.validation:
                stops.append((evaluate(candidate, scheduled_plan, options).ranking_fit(), refine_steps,
                              candidate))

        try:
            result, divergence = last_good_on_divergence(
                lambda: identify_scheduled(plan.records, schedule.estimation, start, variable=schedule.channel,
                                           options=filter_options, on_refine=on_refine))
        except DivergenceError as exc:
            tried.append({"p": p, "error": str(exc)})
            continue
        result = _stopped_early(result, stops, plan, schedule)
        evaluation = evaluate(result.model, scheduled_plan, options)
        row = {"p": p, "estimation_fit_percent": evaluation.estimation.fit,
               "validation_fit_percent": evaluation.validation_fit, "ranking_fit": evaluation.ranking_fit(),
               "seconds": result.seconds}
        tried.append(row)
        if np.isfinite(row["ranking_fit"]):
            candidates.append((result, divergence, evaluation, row))
    if not candidates:
        raise DivergenceError("the scheduled model diverged at every p tried: " + "; ".join(
            f"p = {row['p']:g}: {row.get('error', 'no finite fit')}" for row in tried) + " (give a smaller 'schedule_p')",
            options=("schedule_p",))
    # as for the IEKF's p: the largest within the tolerance of the best
    top = max(c[3]["ranking_fit"] for c in candidates)
    result, divergence, evaluation, chosen = max(
        (c for c in candidates if c[3]["ranking_fit"] >= top - P_TOLERANCE), key=lambda c: c[3]["p"])
    family = result.model
    output_map = None
    if options.nonlinear:
        family, evaluation, output_map = with_output_map(family, evaluation, plan, scheduled_plan, options)
    fit_percent = result.fit_percent if output_map is None or output_map["nodes"] is None else \
        output_map["R"]
    scores = {**scores_summary(evaluation, fit_percent, plan.records[:1]),
              **records_summary(family, scheduled_plan.records, plan.preparation)}
    scores.pop("preparation", None)  # the unscheduled preparation stands: the schedule is never offset
    coverage = list(family.meta.get("knot_coverage") or [])
    sparse = {float(knot["value"]) for knot in coverage if knot["extrapolated"]}
    entry = {
        "channel": schedule.channel, "grid": family.grid,
        "modes_at": [{"value": at["value"], "modes": at["modes"], "extrapolated": float(at["value"]) in sparse}
                     for at in family.modes_at(family.grid)],
        "knot_coverage": coverage,
        "uncertainty_method": uncertainty_method(family),
        "knots": int(family.grid.size), "p": chosen["p"], "p_tried": tried, "passes_run": result.passes_run,
        "stop_reason": result.stop_reason if divergence is None else f"{result.stop_reason}: {divergence}",
        **_percent_and_R("start_", result.start_fit, plan.records[0].y), "seconds": result.seconds,
        "refined_from": result.meta.get("refined_from"), "refine_steps": result.meta.get("refine_steps"),
        "refine_steps_run": result.meta.get("refine_steps_run", result.meta.get("refine_steps")),
        **({} if output_map is None else {"output_map": output_map}),
        "unscheduled": {**_pooled_percent_and_R(unscheduled_fit(plan, start), plan.records),
                        "estimation_fit_percent": unscheduled.estimation.fit,
                        "estimation_R": unscheduled.estimation.R,
                        "validation_fit_percent": unscheduled.validation_fit,
                        "validation_R": unscheduled.validation_R},
    }
    # where the refinement started from the unscheduled start, how far the filter's passes got does not matter
    filtered = result.meta.get("refined_from") != "start"
    warnings = run_warnings(
        model=family, evaluation=evaluation, stop_reason=entry["stop_reason"] if filtered else None, start_fit=None,
        final_fit=float(np.mean(result.fit_percent)), allow_unstable=True, label="scheduled",
        fit_history=[record.mean_fit_continuous for record in result.history] if filtered else None)
    stable = options.allow_unstable or family.is_stable()
    if not family.is_stable() and options.allow_unstable:  # allowed, and said: a family is judged at every knot
        warnings.append("scheduled: the model is unstable at some grid value (--allow-unstable); its simulation "
                        "grows wherever the schedule dwells there")
    # both models are scored by the run's one rule (their initial states estimated alike, by default); the
    # start's fits from rest stay in the summary for callers that read them
    from_rest = evaluate(start, plan, dataclasses.replace(options, initial_state="zero"))
    entry["unscheduled"].update(estimation_fit_percent_from_rest=from_rest.estimation.fit,
                                validation_fit_percent_from_rest=from_rest.validation_fit)
    margin = schedule_margin(evaluation, unscheduled)
    returned = stable and margin["score"] is not None and (
        margin["runner_up_score"] is None or margin["score"] > margin["runner_up_score"] + margin["margin"])
    margin = margin_entry(*(("scheduled", margin["score"], "unscheduled", margin["runner_up_score"]) if returned
                                else ("unscheduled", margin["runner_up_score"], "scheduled", margin["score"])),
                              measure=margin["measure"], rule=margin["rule"])
    entry.update(model_returned="scheduled" if returned else "unscheduled",
                 estimation_fit_percent=evaluation.estimation.fit, validation_fit_percent=evaluation.validation_fit)
    note = None
    if returned:
        warnings += [f"scheduled: the knot at {schedule.channel} = {knot['value']:.4g} rests on {knot['seconds']:.3g} s "
                     f"of the record with the first input at {knot['excitation']:.2f} of its RMS: too little to say "
                     "its modes, which are extrapolated from its neighbours' data" for knot in coverage
                     if knot["extrapolated"]]
    else:
        scheduled_fit, other_fit = margin["runner_up_score"], margin["score"]
        note = ("the scheduled model " + ("is unstable at some grid value where stability was asked" if not stable
                                          else (f"does not beat the unscheduled one by the margin ({margin['measure']} "
                                                f"{_or_nan(scheduled_fit):.2f} against {_or_nan(other_fit):.2f})"))
                + ": the unscheduled model is returned; the schedule does not explain these data better (try fewer "
                "--schedule-knots or another --schedule-p)")
    return ScheduledOutcome(family, entry, scores, warnings, result, returned, margin, evaluation, note)


def _percent_and_R(prefix: str, R: Any, y: np.ndarray) -> dict[str, Any]:
    """``<prefix>fit_percent`` (NRMSE) and ``<prefix>R`` (eq. 17) of a fit stored as R over the outputs ``y``."""
    from vehid.identification.assessment.metrics import nrmse_fit_of_R

    with np.errstate(all="ignore"):
        return {f"{prefix}fit_percent": nrmse_fit_of_R(R, y), f"{prefix}R": np.asarray(R, dtype=float)}


def _pooled_percent_and_R(R: Any, records: Sequence[IOData]) -> dict[str, Any]:
    """``fit_percent`` (NRMSE) and ``R`` of a fit pooled over records (:func:`pooled_fit_percent`)."""
    return {"fit_percent": pooled_fit_percent(R, records), "R": np.asarray(R, dtype=float)}


def _stopped_early(result: Any, stops: list[tuple[float, Any, Any]], plan: Any, schedule: ScheduleData) -> Any:
    """The result with the refinement stopped at the step that validates best (the most steps on a tie).

    The simulation-error refinement fits its record ever closer; on a race car's log five steps
    validated better than ten and twenty-five worse still, so held-out data say when to stop, as
    they choose p. Without validation data every step stands.
    """
    from vehid.identification.filtering.scheduled_iekf import HOLD_OF, Runs, with_simulation_covariance

    finite = [stop for stop in stops if np.isfinite(stop[0])]
    if not finite or "refine_steps" not in result.meta:
        return result
    top = max(stop[0] for stop in finite)
    fit, refine_steps, family = max((stop for stop in finite if stop[0] >= top - 1e-9), key=lambda stop: stop[1])
    if refine_steps == result.meta["refine_steps"]:
        return result
    method = HOLD_OF[result.options.discretization]
    runs = Runs.of(plan.records, schedule.estimation)
    family = with_simulation_covariance(family, runs, None, method)
    from vehid.identification.assessment.metrics import percentage_explanation

    with np.errstate(all="ignore"):
        fit_percent = percentage_explanation(runs.y, runs.simulate(family, method))
    return dataclasses.replace(result, model=family, meta={**result.meta, "refine_steps": refine_steps, "fit_percent": fit_percent,
                                                            "refine_steps_run": result.meta["refine_steps"]})


def _or_nan(value: float | None) -> float:
    return float("nan") if value is None else value


#: nodes per output of the static output map tried with --nonlinear (fewest first): a record's
#: amplitudes rarely support more; on a race car's log 7 nodes fitted its estimation half better and
#: validated worse than 3
OUTPUT_MAP_NODES = (3, 5)


def with_output_map(family: Any, evaluation: Any, plan: Any, scheduled_plan: Any, options: IdentifyOptions
                    ) -> tuple[Any, Any, dict[str, Any]]:
    """The family with a static output map (``--nonlinear``) where one validates better, and the map's entry.

    A Wiener model: the speed-scheduled linear dynamics, then per output a piecewise-linear map of the
    linear output (:class:`~vehid.identification.models.scheduled.OutputMap`) fitted by least squares to the
    estimation record, the nodes at the linear output's quantiles. It bends the outputs where the
    linear part overshoots them (a lateral acceleration at the grip limit) whatever the speed. Each
    node count of :data:`OUTPUT_MAP_NODES` is scored like every model; the best is kept only where it
    beats the linear family by :data:`VALIDATION_MARGIN` (on the estimation fit by the whole-record
    margin without validation data).
    """
    from vehid.identification.assessment.metrics import percentage_explanation
    from vehid.identification.models.scheduled import OutputMap
    from vehid.identification.filtering.scheduled_iekf import HOLD_OF, Runs

    runs = Runs.of(plan.records, plan.schedule.estimation)
    method = HOLD_OF[options.discretization]
    with np.errstate(all="ignore"):
        linear_outputs = runs.simulate(family, method)
    rows, best = [], None
    if np.all(np.isfinite(linear_outputs)):
        for count in OUTPUT_MAP_NODES:
            mapped = dataclasses.replace(family, output_map=OutputMap.fit(linear_outputs, runs.y, count))
            scored = evaluate(mapped, scheduled_plan, options)
            rows.append({"nodes": count, "estimation_fit_percent": scored.estimation.fit,
                         "validation_fit_percent": scored.validation_fit, "ranking_fit": scored.ranking_fit()})
            if np.isfinite(rows[-1]["ranking_fit"]) and (best is None or rows[-1]["ranking_fit"] > best[2]["ranking_fit"]):
                best = (mapped, scored, rows[-1])
    margin = schedule_margin(best[1], evaluation)["margin"] if best is not None else VALIDATION_MARGIN
    entry: dict[str, Any] = {"nodes": None, "tried": rows, "linear_ranking_fit": evaluation.ranking_fit(),
                             "rule": f"the map where it beats the linear family by more than {margin} points"}
    if best is None or not best[2]["ranking_fit"] > evaluation.ranking_fit() + margin:
        return family, evaluation, entry
    mapped, scored, row = best
    with np.errstate(all="ignore"):
        fit = percentage_explanation(runs.y, runs.simulate(mapped, method))
    entry.update(nodes=row["nodes"], **_percent_and_R("", fit, runs.y), map=mapped.output_map.to_dict())
    return mapped, scored, entry


def unscheduled_fit(plan: Any, start: Any) -> Any:
    """R per output of the unscheduled model from rest on the estimation records (as ``fit_percent``)."""
    from vehid.identification.assessment.multirecord import pooled_simulation_fit

    return pooled_simulation_fit(start, plan.records)


def scheduled_records(records: Sequence[IOData], schedules: Sequence[np.ndarray], channel: str) -> tuple[IOData, ...]:
    """The records with their schedule as a last input column, as a scheduled model simulates them."""
    return tuple(record.replace(u=np.column_stack([record.u, schedule]), input_names=record.input_names + (channel,),
                                input_units=record.input_units + ("-",))
                 for record, schedule in zip(records, schedules))
