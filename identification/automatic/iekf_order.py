"""One IEKF run of one order: the decisions before it, in their order, the run and the model it returns.

The decisions (:func:`decide_run`): the open-loop-unstable treatment, the model structure
(:func:`structure_for`), the p and Q schedule and the filter steps planned for the order; then the
run, whose last good pass is kept on a divergence, and the model returned with its keys
(:func:`run_iekf_order`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf, start_structure
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.scoring import last_good_on_divergence
from vehid.identification.automatic.tuning import PTuning, given_p, planned_filter_steps, tune_p, tunes_p
from vehid.identification.automatic.returned import assume_unstable, returned_model

__all__ = ["structure_for", "RunDecisions", "decide_run", "run_iekf_order"]


def structure_for(settings: IdentifyOptions, order: int, plan: Plan, options: IEKFOptions) -> ModalStructure:
    """The model structure of an IEKF run: ``--pattern`` where given, else the data start's modes
    (:func:`vehid.identification.filtering.iekf.start_structure`) or, for other starts, the default pattern."""
    first = plan.records[0]
    structure = ModalStructure.from_pattern(settings.pattern or "default", order, first.n_u, first.n_y)
    if settings.pattern is not None:
        return structure
    return start_structure(plan.estimation, structure, options)


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
    (:func:`~vehid.identification.automatic.returned.assume_unstable`), the structure (:func:`structure_for`), p and Q
    schedule (:func:`~vehid.identification.automatic.tuning.tune_p`,
    or the p given) and the compiled build's planned steps
    (:func:`~vehid.identification.automatic.tuning.planned_filter_steps`)."""
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
