"""The spline-nonlinear model started from the linear one, and whether it is returned in its place.

* Its p from the small grid :data:`NONLINEAR_P_GRID` on validation data (else :data:`NONLINEAR_P`),
  the largest within the p tuning's tolerance of the best (:func:`identify_nonlinear`).
* It is returned where it beats the model otherwise returned by :data:`NONLINEAR_MARGIN` points of
  mean validation fit (:func:`nonlinear_margin`), scored by the run's one rule; the decision is
  said as a note (:func:`nonlinear_note`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from vehid.identification.errors import DivergenceError, OptionError
from vehid.identification.frozen import FrozenDict, freeze
from vehid.identification.models.modal import ModalModel
from vehid.identification.automatic.reported_checks import uncertainty_method
from vehid.identification.assessment.validation import Scores
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.scoring import RankedScores, evaluate, margin_entry, pooled_fit_percent
from vehid.identification.automatic.tuning import P_TOLERANCE
from vehid.identification.automatic.returned import WHOLE_RECORD_MARGIN

if TYPE_CHECKING:
    from vehid.identification.filtering.spline_iekf import SplineIEKFResult

__all__ = ["NONLINEAR_P", "NONLINEAR_P_GRID", "NonlinearOutcome", "NONLINEAR_MARGIN", "nonlinear_margin",
    "nonlinear_note", "identify_nonlinear", "NonlinearScores"]


NONLINEAR_P = 1e-7  # the spline model's p without validation data
# with validation data: no one p suits every sample interval (docs/measurements.md, cascaded tanks)
NONLINEAR_P_GRID = (1e-7, 1e-8, 1e-9)


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
#: :data:`~vehid.identification.automatic.returned.WHOLE_RECORD_MARGIN` on the estimation fit
NONLINEAR_MARGIN = 0.5


def nonlinear_margin(spline: Any, other: Any, other_name: str) -> dict[str, Any]:
    """The decision ``nonlinear``: the spline model or the model otherwise returned, both scored by the run's rule.

    The spline model is returned where its ranking fit (mean validation fit, else mean estimation fit)
    beats the other's by :data:`NONLINEAR_MARGIN` points
    (:data:`~vehid.identification.automatic.returned.WHOLE_RECORD_MARGIN` without
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
class NonlinearScores(RankedScores):
    """Scores of a spline model on the plan's records, by the run's rule (``settings``), as every candidate's.

    The initial state and the records are those of :func:`~vehid.identification.automatic.scoring.evaluate`; a spline
    model is simulated (in its own time base) whatever the horizon, since only a linear model predicts k steps ahead.
    """

    estimation: Scores
    validation: tuple[Scores, ...]
    horizon: int | None

    @classmethod
    def of(cls, model: Any, plan: Plan, settings: IdentifyOptions | None = None) -> "NonlinearScores":
        """The scores of ``model`` on ``plan``'s records by the rule of ``settings`` (default: the command's)."""
        scored = evaluate(model, plan, settings if settings is not None else IdentifyOptions())
        return cls(scored.estimation, scored.validation, scored.horizon)
