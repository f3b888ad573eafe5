"""How the automatic pipeline scores a model and words its warnings: one rule for every candidate.

Each function takes the run's :class:`~vehid.identification.automatic.options.IdentifyOptions`
(of which it reads only the settings it needs) and the run's
:class:`~vehid.identification.automatic.plan.Plan`.

* Validation: a fraction of each record held out at its end
  (``validation=`` or ``--validation FRACTION``), or further records
  (``--validation-file FILE``); both are scored
  (:mod:`vehid.identification.assessment.validation`) by simulation, or by k-step-ahead
  prediction for an unstable model (:func:`evaluate`).
* Each choice the pipeline makes is reported with its margin (:func:`margin_entry`, JSON
  ``decision_margins``): the choice and its score, the runner-up and its score.
* Warnings (:func:`run_warnings`): one line each on standard error and in the
  JSON ``warnings``, each naming one cause and one remedy (by the command's
  options); ``strict`` (``--strict``) makes them an error, the command's exit status 3.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.errors import DivergenceError
from vehid.identification.frozen import freeze
from vehid.identification.models.modal import ModalModel
from vehid.identification.assessment.validation import Scores, default_horizon, score
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions

__all__ = ["MOVED", "NOTHING_TO_GAIN", "SETTLED_FIT", "SETTLED_PASSES", "margin_entry", "RankedScores", "Evaluation",
    "evaluate", "mean_scores", "run_warnings", "pooled_fit_percent", "scores_summary", "start_of",
    "last_good_on_divergence"]


MOVED = 1e-3  # relative change of a mode's eigenvalue below which it stayed at its start
NOTHING_TO_GAIN = 99.0  # percent R: a model this good is no warning for staying at its start
# a run stopped by the pass limit whose mean R moved less than SETTLED_FIT points over its last
# SETTLED_PASSES passes has settled in fit: more passes would not change the model's quality
SETTLED_FIT = 0.1
SETTLED_PASSES = 5


def margin_entry(choice: Any, score: Any, runner_up: Any, runner_up_score: Any, measure: str, rule: str) -> dict[str, Any]:
    """One ``decision_margins`` entry: the choice and its score, the runner-up and its, the measure and the rule."""
    def number(value: Any) -> float | None:
        return float(value) if value is not None and np.isfinite(value) else None

    return {"choice": choice, "score": number(score), "runner_up": runner_up, "runner_up_score": number(runner_up_score),
            "measure": measure, "rule": rule}


class RankedScores:
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
class Evaluation(RankedScores):
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
    estimation = mean_scores(model, plan.records, initial_state=settings.initial_state, horizon=horizon)
    from_rest = mean_scores(model, plan.records, initial_state="zero", horizon=horizon).R
    validation = tuple(score(model, record, initial_state=settings.initial_state, horizon=horizon)
                       for record in plan.validation)
    return Evaluation(estimation, from_rest, validation, horizon)


def mean_scores(model: Any, records: tuple[IOData, ...], **options: Any) -> Scores:
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
    returned (:func:`~vehid.identification.automatic.returned.returned_model`). A run stopped by the pass limit warns
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
