"""The typed result of one automatic identification, and its summary keyed as `vehid identify --json`.

:class:`Identification` is built by :mod:`vehid.identification.automatic.run`
field by field as the pipeline decides; :meth:`Identification.summary` renders
it to the public JSON keys (the command adds only the files it wrote), so the
command and a Python caller read one result.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Mapping

import numpy as np

__all__ = ["OrderRow", "Decision", "Identification", "float_tuple"]


@dataclass(frozen=True)
class OrderRow:
    """One order tried: its fits (percent, per output), ranking and run time.

    ``fit_percent`` is the NRMSE fit and ``R`` the fit R (eq. 17) of the order's model simulated
    from rest over the estimation records; ``estimation_fit_percent`` and ``validation_fit_percent``
    its NRMSE fits by the run's scoring rule.

    ``ranking_fit``, ``eligible``, ``stop_reason``, ``p`` and ``q_schedule`` are
    those of an order search (None for the one order of a single run, ``p`` and
    ``q_schedule`` also for a classical method); ``error`` says why an order gave
    no model.
    """

    order: int
    fit_percent: Any
    estimation_fit_percent: Any
    validation_fit_percent: Any
    seconds: float
    R: Any = None
    ranking_fit: float | None = None
    eligible: bool | None = None
    stop_reason: str | None = None
    p: float | None = None
    q_schedule: str | None = None
    error: str | None = None
    searched: bool = False  # one of an order search's rows (they carry the ranking and eligibility)

    def as_dict(self) -> dict[str, Any]:
        """The row's keys in ``orders_tried``."""
        if self.error is not None:
            return {"order": self.order, "error": self.error, "eligible": False, "seconds": self.seconds}
        row: dict[str, Any] = {"order": self.order, "fit_percent": self.fit_percent, "R": self.R,
                               "estimation_fit_percent": self.estimation_fit_percent,
                               "validation_fit_percent": self.validation_fit_percent}
        if not self.searched:
            return {**row, "seconds": self.seconds}
        row.update(ranking_fit=self.ranking_fit, stop_reason=self.stop_reason)
        if self.p is not None:
            row["p"] = self.p
        if self.q_schedule is not None:
            row["q_schedule"] = self.q_schedule
        return {**row, "seconds": self.seconds, "eligible": self.eligible}


@dataclass(frozen=True)
class Decision:
    """A choice the pipeline made, with its score and the runner-up's (``measure`` says what the scores are)."""

    name: str
    choice: Any
    score: Any
    runner_up: Any
    runner_up_score: Any
    measure: str
    rule: str
    details: Mapping[str, Any] = field(default_factory=dict)  # what else the decision records (e.g. the Q schedule)

    @classmethod
    def from_entry(cls, name: str, entry: Mapping[str, Any]) -> "Decision":
        """A decision from its margin entry (choice, score, runner_up, runner_up_score, measure, rule, more)."""
        return cls(name=name, choice=entry.get("choice"), score=entry.get("score"), runner_up=entry.get("runner_up"),
                   runner_up_score=entry.get("runner_up_score"), measure=str(entry.get("measure", "")),
                   rule=str(entry.get("rule", "")),
                   details={key: value for key, value in entry.items() if key not in _DECISION_KEYS})

    def as_dict(self) -> dict[str, Any]:
        """The decision's entry in ``decision_margins``."""
        return {"choice": self.choice, **self.details, "score": self.score, "runner_up": self.runner_up,
                "runner_up_score": self.runner_up_score, "measure": self.measure, "rule": self.rule}


_DECISION_KEYS = ("choice", "score", "runner_up", "runner_up_score", "measure", "rule")


def float_tuple(values: Any) -> tuple[float, ...] | None:
    """Numbers (an array, a list or a scalar) as a flat tuple of floats; None stays None."""
    if values is None:
        return None
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


@dataclass(frozen=True, eq=False)
class Identification:
    """One identification run's result.

    Attributes
    ----------
    model : object
        The model returned: the filter's, or its start's where that scores better; the scheduled
        family or the spline model where either scores better by the same rule (``returned``).
    method : str
        The estimator.
    order : int
        The model order.
    fit_percent, R : tuple of float
        NRMSE fit and fit R (eq. 17) per output of the returned model simulated from rest on the
        estimation data (pooled over its records).
    estimation_fit_percent, validation_fit_percent : tuple of float or None
        NRMSE fits per output on the estimation and validation data, by the run's scoring rule.
    decisions : tuple of Decision
        The choices made (p, Q schedule, stability, start or filter, order), each with its margin.
    notes, warnings : tuple of str
        Choices said once, and one line per problem found.
    orders : tuple of OrderRow
        The orders tried.
    seconds : float
        Run time of the estimator(s).
    plan : Plan
        The records identified and validated on.
    evaluation : Evaluation
        The returned model's scores on every record (estimation and validation).
    estimator : object
        The estimator's own result: the IEKF's :class:`~vehid.identification.filtering.iekf.IEKFResult`
        or a classical method's outcome.
    tuning : PTuning or None
        The IEKF's p and Q schedule with every candidate's cross-validated fit.
    open_loop_unstable, start_kept : Mapping or None
        The evidence of the open-loop-unstable treatment, and of a start kept on the estimation data.
    start_returned : bool
        Whether the IEKF's start model is returned in the filter's place.
    divergence : str or None
        How the IEKF's run diverged, where the last good pass is returned.
    checks : Mapping or None
        Modes with standard deviations and residual tests (modal models;
        :mod:`vehid.identification.automatic.reported_checks`).
    residual_tests : ResidualTests or None
        The residual tests behind ``checks``.
    data : Mapping
        The model scored per estimation record and the records' preparation.
    scoring_note : str or None
        How an unstable model was scored, where no horizon was given.
    nonlinear : NonlinearOutcome or None
        The spline-nonlinear model started from the linear one.
    time_domain : str or None
        A classical method's time domain ("continuous" or "discrete").
    scheduled : ScheduledOutcome or None
        The speed-scheduled family started from the unscheduled model (where the plan holds a schedule).
    unscheduled : object or None
        The linear (unscheduled) model, where the scheduled family or the spline model is returned in
        its place; the summary's matrices and eigenvalues are its (JSON ``linear_modes`` its modes),
        the scores, checks and warnings the returned model's.
    returned : str
        Which model is returned: ``filter``, ``start``, ``scheduled``, ``nonlinear`` or a classical
        method's name (JSON ``model_returned``).
    """

    model: Any
    method: str
    order: int
    fit_percent: tuple[float, ...]
    R: tuple[float, ...] | None
    estimation_fit_percent: tuple[float, ...] | None
    validation_fit_percent: tuple[float, ...] | None
    decisions: tuple[Decision, ...]
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    orders: tuple[OrderRow, ...]
    seconds: float
    plan: Any = field(default=None, repr=False)
    evaluation: Any = field(default=None, repr=False)
    estimator: Any = field(default=None, repr=False)
    tuning: Any = None
    open_loop_unstable: Mapping[str, Any] | None = None
    start_kept: Mapping[str, Any] | None = None
    start_returned: bool = False
    divergence: str | None = None
    checks: Mapping[str, Any] | None = field(default=None, repr=False)
    residual_tests: Any = field(default=None, repr=False)
    data: Mapping[str, Any] = field(default_factory=dict, repr=False)
    scoring_note: str | None = None
    nonlinear: Any = field(default=None, repr=False)
    time_domain: str | None = None
    scheduled: Any = field(default=None, repr=False)
    unscheduled: Any = field(default=None, repr=False)
    returned: str = ""

    @property
    def p(self) -> float | None:
        """The IEKF's p (chosen or given); None for a classical method."""
        return None if self.tuning is None else self.tuning.p

    @property
    def is_iekf(self) -> bool:
        return self.method == "iekf"

    @cached_property
    def summary(self) -> Mapping[str, Any]:
        """The run's summary keyed as `vehid identify --json` (without the keys of the files the command writes)."""
        return self.render()

    def render(self) -> dict[str, Any]:
        """A fresh summary dict (:attr:`summary`), for a caller that adds keys of its own."""
        from .steps import pooled_fit_percent, scores_summary  # the public score keys are defined once, beside the scoring

        model = self.unscheduled if self.unscheduled is not None else self.model
        records = self.plan.records
        summary: dict[str, Any] = {"method": self.method, "order": self.order, "eigenvalues": model.eigenvalues()}
        result = self.estimator
        if self.is_iekf:
            filter_R = result.history[-1].fit_filter
            summary.update(fit_percent_filter=pooled_fit_percent(filter_R, records), R_filter=filter_R,
                           passes_run=result.passes_run, stop_reason=result.stop_reason,
                           discretization=result.options.discretization)
        else:
            summary.update(passes_run=0, discretization="exact", time_domain=self.time_domain)
        summary.update(A=model.A, B=model.B, C=model.C, D=model.D, seconds=self.seconds)
        if self.tuning is not None:
            summary.update(self.tuning.summary())
        searched = any(row.searched for row in self.orders)
        if searched:
            summary["orders_tried"] = [row.as_dict() for row in self.orders]
        if self.open_loop_unstable is not None:
            summary["open_loop_unstable"] = dict(self.open_loop_unstable)
        if self.start_kept is not None:
            summary["start_kept"] = dict(self.start_kept)
        if self.is_iekf or self.decisions:  # every IEKF run reports its margins, if only as an empty entry
            summary["decision_margins"] = {decision.name: decision.as_dict() for decision in self.decisions}
        if self.divergence:
            summary["divergence"] = self.divergence
        if self.returned and (self.is_iekf or self.returned != self.method):
            summary["model_returned"] = self.returned
        summary.update(scores_summary(self.evaluation, self.R, records))
        summary.update(self.data)
        if self.checks is not None:
            summary.update(self.checks)
        if not searched:
            summary["orders_tried"] = [row.as_dict() for row in self.orders]
        summary["notes"] = list(self.notes)
        if self.scoring_note is not None:
            summary["scoring_note"] = self.scoring_note
        if self.is_iekf:
            summary["start"] = {k: v for k, v in result.meta.items() if k != "start_parameters"}
        if self.nonlinear is not None:
            summary["nonlinear"] = self.nonlinear.summary
        if self.scheduled is not None:
            summary["scheduled"] = self.scheduled.summary
        summary["warnings"] = list(self.warnings)
        return summary
