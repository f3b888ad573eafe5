"""`vehid identify --schedule CHANNEL`: a speed-scheduled modal model from one varying-schedule record.

The scheduling channel (a car's speed) is read beside the inputs, scaled by ``--scale`` where one names
it and never offset (the model's coefficients are functions of its measured value). The unscheduled
model of the default pipeline starts the scheduled IEKF
(:mod:`vehid.identification.filtering.scheduled_iekf`) at every knot; the family returned is a
:class:`~vehid.identification.models.scheduled.ScheduledModalModel`, scored like every model on the
estimation and held-out data, simulated from rest along their measured schedules.

The family is returned only where it validates better than the unscheduled model by
:data:`VALIDATION_MARGIN` points of mean fit (without validation data: its estimation fit by the
start-or-filter rule's whole-record margin), and never where a knot is unstable unless that was
allowed; otherwise the unscheduled model is returned with a warning. With ``--nonlinear`` the family
may gain a static output map (:func:`with_output_map`).

JSON (public): the score keys (``fit_percent``, ``estimation_fit_percent``, ``validation_fit_percent``,
``validation_R``, ``records``) describe the model returned; ``decision_margins.schedule`` the decision;
``scheduled`` holds ``model_returned`` ("scheduled" or "unscheduled"), the family's own
``estimation_fit_percent`` and ``validation_fit_percent``, the refinement (``refined_from``,
``refine_steps``, ``refine_steps_run``), ``output_map`` (with ``--nonlinear``), ``channel``, ``grid``,
``modes_at`` (per grid value ``value`` and its ``modes``, each with ``frequency_hz``,
``frequency_hz_std``, ``damping``, ``damping_std``), the run (``passes_run``, ``stop_reason``,
``p`` and ``p_tried``, chosen on validation data as the IEKF's p is, ``seconds``) and ``unscheduled``: the scores of the start
(also from rest, ``*_from_rest``, as the family is scored and the decision weighs them), whose matrices, eigenvalues and
modes are the summary's other keys.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Sequence

import numpy as np

from vehid.identification.errors import InputError
from vehid.identification.models.modal import ModalModel

from .schedule_channel import ScheduleData, parse_schedule_grid, scheduled_records

# said where --nonlinear and --schedule are given together (JSON ``notes``)
NONLINEAR_NOTE = ("--nonlinear with --schedule: the scheduled family may gain a static output map (speed-scheduled "
                  "linear dynamics, then a piecewise-linear map of each output; scheduled.output_map), kept where it "
                  "validates better; the spline-nonlinear model ('nonlinear') of the unscheduled model is beside it")

__all__ = ["NONLINEAR_NOTE",
           "identify_scheduled_model", "ScheduledOutcome", "text_lines"]


#: p of the scheduled filter tried on validation data, largest first (the default alone without them)
from vehid.identification.choices import SCHEDULED_P_GRID as P_GRID  # noqa: E402


@dataclass
class ScheduledOutcome:
    """The scheduled family, its summary entry, the score keys it replaces and its warnings."""

    model: Any
    summary: dict[str, Any]
    scores: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    result: Any = None
    returned: bool = True  # the scheduled family is the model returned (else the unscheduled start)
    margin: dict[str, Any] | None = None  # the decision, as an entry of ``decision_margins``


#: points of mean validation fit by which the scheduled family must beat the unscheduled model to be returned:
#: as a larger order must beat a smaller one (it has several times the parameters)
VALIDATION_MARGIN = 0.5


def schedule_margin(evaluation: Any, unscheduled: Any) -> dict[str, Any]:
    """The scheduled family's and the unscheduled model's ranking fits, the measure and the margin to beat.

    On validation data the mean validation fit with :data:`VALIDATION_MARGIN`; without, the estimation
    fit, where the family fitted its own record with many more parameters, so it must win by the
    start-or-filter rule's :data:`~vehid.scenarios.identify_workflow.WHOLE_RECORD_MARGIN`.
    """
    from vehid.scenarios import identify_workflow as workflow

    def number(value: Any) -> float | None:
        return float(value) if value is not None and np.isfinite(value) else None

    held_out = bool(evaluation.validation) and unscheduled.validation_fit is not None
    margin = VALIDATION_MARGIN if held_out else workflow.WHOLE_RECORD_MARGIN
    return {"score": number(evaluation.ranking_fit()), "runner_up_score": number(unscheduled.ranking_fit()),
            "margin": margin,
            "measure": ("mean validation" if held_out else "mean estimation") + " NRMSE fit % (simulation from rest)",
            "rule": f"the scheduled model where it beats the unscheduled one by more than {margin} points"}


def identify_scheduled_model(start: Any, plan: Any, args: Any, unscheduled: Any) -> ScheduledOutcome:
    """The scheduled family started from ``start`` (the unscheduled model returned), scored on the plan's records.

    ``unscheduled`` is the start's :class:`~vehid.scenarios.identify_workflow.Evaluation`.
    """
    from vehid.identification.errors import DivergenceError
    from vehid.identification.filtering.scheduled_iekf import DEFAULT_P, ScheduledIEKFOptions, identify_scheduled
    from vehid.scenarios import identify_workflow as workflow
    from vehid.scenarios.data_options import records_summary

    if not isinstance(start, ModalModel):
        raise InputError("--schedule starts from a continuous-time modal model; this unscheduled model is "
                         "discrete-time (a pole on the negative real axis): use --method iekf or another order")

    schedule = plan.schedule
    scheduled_plan = dataclasses.replace(
        plan, records=scheduled_records(plan.records, schedule.estimation, schedule.channel),
        validation=scheduled_records(plan.validation, schedule.validation, schedule.channel))
    grid = args.schedule_p or (list(P_GRID) if plan.validation else [DEFAULT_P])
    tried, candidates = [], []
    for p in grid:
        options = ScheduledIEKFOptions(knots=args.schedule_knots, grid=parse_schedule_grid(args.schedule_grid), p=p,
                                       discretization=args.discretization, stable=not args.allow_unstable)
        stops: list[tuple[float, int, Any]] = []  # (held-out ranking fit, steps, family) of each refinement step

        def on_refine(candidate: Any, steps: int) -> None:
            if plan.validation:
                stops.append((workflow.evaluate(candidate, scheduled_plan, args).ranking_fit(), steps, candidate))

        try:
            result, divergence = workflow.last_good_on_divergence(
                lambda: identify_scheduled(plan.records[0], schedule.estimation[0], start, variable=schedule.channel,
                                           options=options, on_refine=on_refine))
        except DivergenceError as exc:
            tried.append({"p": p, "error": str(exc)})
            continue
        result = _stopped_early(result, stops, plan, schedule)
        evaluation = workflow.evaluate(result.model, scheduled_plan, args)
        row = {"p": p, "estimation_fit_percent": evaluation.estimation.fit,
               "validation_fit_percent": evaluation.validation_fit, "ranking_fit": evaluation.ranking_fit(),
               "seconds": result.seconds}
        tried.append(row)
        if np.isfinite(row["ranking_fit"]):
            candidates.append((result, divergence, evaluation, row))
    if not candidates:
        raise DivergenceError("the scheduled model diverged at every p tried: " + "; ".join(
            f"p = {row['p']:g}: {row.get('error', 'no finite fit')}" for row in tried) + " (give a smaller --schedule-p)")
    # as for the IEKF's p: the largest within the tolerance of the best
    top = max(c[3]["ranking_fit"] for c in candidates)
    result, divergence, evaluation, chosen = max(
        (c for c in candidates if c[3]["ranking_fit"] >= top - workflow.P_TOLERANCE), key=lambda c: c[3]["p"])
    family = result.model
    output_map = None
    if args.nonlinear:
        family, evaluation, output_map = with_output_map(family, evaluation, plan, scheduled_plan, args)
    fit_percent = result.fit_percent if output_map is None or output_map["nodes"] is None else \
        output_map["fit_percent"]
    scores = {**workflow.scores_summary(evaluation, fit_percent),
              **records_summary(family, scheduled_plan.records, plan.preparation)}
    scores.pop("preparation", None)  # the unscheduled preparation stands: the schedule is never offset
    entry = {
        "channel": schedule.channel, "grid": family.grid,
        "modes_at": [{"value": at["value"], "modes": at["modes"]} for at in family.modes_at(family.grid)],
        "knots": int(family.grid.size), "p": chosen["p"], "p_tried": tried, "passes_run": result.passes_run,
        "stop_reason": result.stop_reason if divergence is None else f"{result.stop_reason}: {divergence}",
        "start_fit_percent": result.start_fit, "seconds": result.seconds,
        "refined_from": result.meta.get("refined_from"), "refine_steps": result.meta.get("refine_steps"),
        "refine_steps_run": result.meta.get("refine_steps_run", result.meta.get("refine_steps")),
        **({} if output_map is None else {"output_map": output_map}),
        "unscheduled": {"fit_percent": unscheduled_fit(plan, start),
                        "estimation_fit_percent": unscheduled.estimation.fit,
                        "validation_fit_percent": unscheduled.validation_fit},
    }
    # where the refinement started from the unscheduled start, how far the filter's passes got does not matter
    filtered = result.meta.get("refined_from") != "start"
    warnings = workflow.run_warnings(
        model=family, evaluation=evaluation, stop_reason=entry["stop_reason"] if filtered else None, start_fit=None,
        final_fit=float(np.mean(result.fit_percent)), allow_unstable=True, label="scheduled",
        fit_history=[record.mean_fit_continuous for record in result.history] if filtered else None)
    stable = args.allow_unstable or family.is_stable()
    if not family.is_stable() and args.allow_unstable:  # allowed, and said: a family is judged at every knot
        warnings.append("scheduled: the model is unstable at some grid value (--allow-unstable); its simulation "
                        "grows wherever the schedule dwells there")
    # the family is simulated from rest (its initial state is not estimated), so the unscheduled model is
    # weighed alike: a record cut mid-drive costs a start from rest several points of fit
    # (a car whose dynamics ignore the speed: 92 % from rest against 99 % from an estimated state)
    from_rest = workflow.evaluate(start, plan, SimpleNamespace(**{**vars(args), "initial_state": "zero"}))
    entry["unscheduled"].update(estimation_fit_percent_from_rest=from_rest.estimation.fit,
                                validation_fit_percent_from_rest=from_rest.validation_fit)
    margin = schedule_margin(evaluation, from_rest)
    returned = stable and margin["score"] is not None and (
        margin["runner_up_score"] is None or margin["score"] > margin["runner_up_score"] + margin["margin"])
    margin = workflow.margin_entry(*(("scheduled", margin["score"], "unscheduled", margin["runner_up_score"]) if returned
                                else ("unscheduled", margin["runner_up_score"], "scheduled", margin["score"])),
                              measure=margin["measure"], rule=margin["rule"])
    entry.update(model_returned="scheduled" if returned else "unscheduled",
                 estimation_fit_percent=evaluation.estimation.fit, validation_fit_percent=evaluation.validation_fit)
    if not returned:
        scheduled_fit, other_fit = margin["runner_up_score"], margin["score"]
        warnings.append(
            "scheduled: the scheduled model " + ("is unstable at some grid value where stability was asked" if not
                                                 stable else (
                f"does not beat the unscheduled one by the margin ({margin['measure']} "
                f"{_or_nan(scheduled_fit):.2f} against {_or_nan(other_fit):.2f})"))
            + ": the unscheduled model is returned; the schedule does not explain these data better (try fewer "
            "--schedule-knots or another --schedule-p)")
    return ScheduledOutcome(family, entry, scores, warnings, result, returned, margin)


def _stopped_early(result: Any, stops: list[tuple[float, Any, Any]], plan: Any, schedule: ScheduleData) -> Any:
    """The result with the refinement stopped at the step that validates best (the most steps on a tie).

    The simulation-error refinement fits its record ever closer; on a race car's log five steps
    validated better than ten and twenty-five worse still, so held-out data say when to stop, as
    they choose p. Without validation data every step stands.
    """
    from vehid.identification.filtering.scheduled_iekf import HOLD_OF, scheduled_simulation_covariance

    finite = [stop for stop in stops if np.isfinite(stop[0])]
    if not finite or "refine_steps" not in result.meta:
        return result
    top = max(stop[0] for stop in finite)
    fit, steps, family = max((stop for stop in finite if stop[0] >= top - 1e-9), key=lambda stop: stop[1])
    if steps == result.meta["refine_steps"]:
        return result
    method = HOLD_OF[result.options.discretization]
    covariance = scheduled_simulation_covariance(family, plan.records[0], schedule.estimation[0], method)
    family = family.with_parameters(family.parameters, covariance)
    from vehid.identification.assessment.metrics import percentage_explanation

    data = plan.records[0]
    with np.errstate(all="ignore"):
        fit_percent = percentage_explanation(data.y, family.simulate_outputs(
            data.u, data.dt, schedule=schedule.estimation[0], method=method))
    return dataclasses.replace(result, model=family, meta={**result.meta, "refine_steps": steps, "fit_percent": fit_percent,
                                                            "refine_steps_run": result.meta["refine_steps"]})


def _or_nan(value: float | None) -> float:
    return float("nan") if value is None else value


#: nodes per output of the static output map tried with --nonlinear (fewest first): a record's
#: amplitudes rarely support more; on a race car's log 7 nodes fitted its estimation half better and
#: validated worse than 3
OUTPUT_MAP_NODES = (3, 5)


def with_output_map(family: Any, evaluation: Any, plan: Any, scheduled_plan: Any, args: Any
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
    from vehid.identification.filtering.scheduled_iekf import HOLD_OF
    from vehid.scenarios import identify_workflow as workflow

    data, schedule = plan.records[0], plan.schedule.estimation[0]
    method = HOLD_OF[args.discretization]
    with np.errstate(all="ignore"):
        linear_outputs = family.simulate_outputs(data.u, data.dt, schedule=schedule, method=method)
    rows, best = [], None
    if np.all(np.isfinite(linear_outputs)):
        for count in OUTPUT_MAP_NODES:
            mapped = dataclasses.replace(family, output_map=OutputMap.fit(linear_outputs, data.y, count))
            scored = workflow.evaluate(mapped, scheduled_plan, args)
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
        fit = percentage_explanation(data.y, mapped.simulate_outputs(data.u, data.dt, schedule=schedule, method=method))
    entry.update(nodes=row["nodes"], fit_percent=fit, map=mapped.output_map.to_dict())
    return mapped, scored, entry


def unscheduled_fit(plan: Any, start: Any) -> Any:
    """R per output of the unscheduled model from rest on the estimation records (as ``fit_percent``)."""
    from vehid.identification.assessment.multirecord import pooled_simulation_fit

    return pooled_simulation_fit(start, plan.records)


def text_lines(entry: dict[str, Any], output_names: Sequence[str]) -> list[str]:
    """The text face of the ``scheduled`` entry: the run, the unscheduled scores and the modes at each grid value."""
    unscheduled = entry["unscheduled"]
    validation = unscheduled.get("validation_fit_percent")
    lines = [
        f"scheduled on {entry['channel']} ({entry['knots']} knots, p {entry['p']:g}, {entry['passes_run']} passes, "
        f"{'converged' if entry['stop_reason'] == 'converged' else 'NOT converged'}): "
        + ("the scores above are its own; unscheduled start: estimation " if entry.get("model_returned") != "unscheduled"
           else "NOT returned (the scores above are the unscheduled model's); unscheduled: estimation ")
        + ", ".join(f"{n} {v:.2f}" for n, v in zip(output_names, unscheduled["estimation_fit_percent"]))
        + ("" if validation is None else "; validation " + ", ".join(
            f"{n} {v:.2f}" for n, v in zip(output_names, validation))),
        f"modes at {entry['channel']} (frequency Hz, damping; +/- 2 sigma):",
    ]
    for row in entry["modes_at"]:
        modes = "; ".join(f"{mode['frequency_hz']:.4g} +/- {2 * mode['frequency_hz_std']:.2g} Hz, "
                          f"{mode['damping']:.3f} +/- {2 * mode['damping_std']:.2g}" for mode in row["modes"])
        lines.append(f"  {entry['channel']} = {row['value']:.4g}: {modes}")
    return lines
