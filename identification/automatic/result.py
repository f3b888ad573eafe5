"""The typed result of one automatic identification, and its summary keyed as `vehid identify --json`.

:class:`Identification` is built by :mod:`vehid.identification.automatic.run`
as the pipeline decides, and is frozen all the way down: its parts are frozen
dataclasses, and the JSON entries other modules write (the records' keys, the
checks, the spline and scheduled runs') are :class:`~vehid.identification.frozen.FrozenDict`.
:meth:`Identification.render` gives the public JSON keys and :meth:`Identification.text`
the text `vehid identify` prints, so the command and a Python caller read one result.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Protocol

import numpy as np

from vehid.identification.frozen import FrozenDict, freeze, freeze_fields, thaw

if TYPE_CHECKING:
    from vehid.identification.assessment.residuals import ResidualTests
    from vehid.identification.automatic.plan import Plan
    from vehid.identification.automatic.scheduled import ScheduledOutcome
    from vehid.identification.automatic.scoring import Evaluation
    from vehid.identification.automatic.tuning import PTuning
    from vehid.identification.automatic.nonlinear import NonlinearOutcome
    from vehid.identification.comparators import ComparatorResult
    from vehid.identification.filtering.iekf import IEKFResult
    from vehid.identification.models.protocol import IdentifiedModel

__all__ = ["OrderRow", "Decision", "StabilityDecision", "StartKept", "Finding", "Identification", "float_tuple"]


@dataclass(frozen=True)
class OrderRow:
    """One order tried: its fits (percent, per output), ranking and run time.

    ``fit_percent`` is the NRMSE fit and ``R`` the fit R (eq. 17) of the order's model simulated
    from rest over the estimation records; ``estimation_fit_percent`` and ``validation_fit_percent``
    its NRMSE fits by the run's scoring rule (each a tuple per output, stored as given in any sequence).

    ``ranking_fit``, ``eligible``, ``stop_reason``, ``p`` and ``q_schedule`` are
    those of an order search (None for the one order of a single run, ``p`` and
    ``q_schedule`` also for a classical method); ``error`` says why an order gave
    no model.
    """

    order: int
    fit_percent: tuple[float, ...] | None
    estimation_fit_percent: tuple[float, ...] | None
    validation_fit_percent: tuple[float, ...] | None
    seconds: float
    R: tuple[float, ...] | None = None
    ranking_fit: float | None = None
    eligible: bool | None = None
    stop_reason: str | None = None
    p: float | None = None
    q_schedule: str | None = None
    error: str | None = None
    searched: bool = False  # one of an order search's rows (they carry the ranking and eligibility)

    def __post_init__(self) -> None:
        for name in ("fit_percent", "estimation_fit_percent", "validation_fit_percent", "R"):
            object.__setattr__(self, name, float_tuple(getattr(self, name)))

    def as_dict(self) -> dict[str, Any]:
        """The row's keys in ``orders_tried``."""
        if self.error is not None:
            return {"order": self.order, "error": self.error, "eligible": False, "seconds": self.seconds}
        row = {"order": self.order, "fit_percent": self.fit_percent, "R": self.R,
               "estimation_fit_percent": self.estimation_fit_percent,
               "validation_fit_percent": self.validation_fit_percent}
        if not self.searched:
            return {**row, "seconds": self.seconds}
        return {**row, "ranking_fit": self.ranking_fit, "stop_reason": self.stop_reason,
                **({} if self.p is None else {"p": self.p}),
                **({} if self.q_schedule is None else {"q_schedule": self.q_schedule}),
                "seconds": self.seconds, "eligible": self.eligible}


@dataclass(frozen=True)
class Decision:
    """A choice the pipeline made, with its score and the runner-up's (``measure`` says what the scores are).

    ``choice`` and ``runner_up`` name the options weighed (an order is a number); ``details``
    holds what else the decision records (the Q schedule of a p, the margin to beat).
    """

    name: str
    choice: str | int | None
    score: float | None
    runner_up: str | int | None
    runner_up_score: float | None
    measure: str
    rule: str
    details: FrozenDict = field(default_factory=FrozenDict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "details", freeze(self.details))

    @classmethod
    def from_entry(cls, name: str, entry: Mapping[str, Any]) -> "Decision":
        """A decision from its margin entry (choice, score, runner_up, runner_up_score, measure, rule, more)."""
        return cls(name=name, choice=entry.get("choice"), score=entry.get("score"), runner_up=entry.get("runner_up"),
                   runner_up_score=entry.get("runner_up_score"), measure=str(entry.get("measure", "")),
                   rule=str(entry.get("rule", "")),
                   details={key: value for key, value in entry.items() if key not in _DECISION_KEYS})

    def as_dict(self) -> dict[str, Any]:
        """The decision's entry in ``decision_margins``."""
        return {"choice": self.choice, **thaw(self.details), "score": self.score, "runner_up": self.runner_up,
                "runner_up_score": self.runner_up_score, "measure": self.measure, "rule": self.rule}


_DECISION_KEYS = ("choice", "score", "runner_up", "runner_up_score", "measure", "rule")


class _Entry:
    """A JSON entry of fixed keys as a frozen dataclass: built from the entry and rendered back, key for key."""

    @classmethod
    def from_entry(cls, entry: Mapping[str, Any] | None) -> Any:
        """The value of an entry (None stays None)."""
        return None if entry is None else cls(**{item.name: entry[item.name] for item in fields(cls)})

    def as_dict(self) -> dict[str, Any]:
        return {item.name: getattr(self, item.name) for item in fields(self)}


@dataclass(frozen=True)
class StabilityDecision(_Entry):
    """Whether the plant was treated as open-loop unstable, and the evidence (JSON ``open_loop_unstable``):
    the two-fold ``horizon``-step fits of the data start left free (unstable) and kept stable."""

    assumed: bool
    unstable_start_cv_fit_percent: float
    stable_start_cv_fit_percent: float
    horizon: int


@dataclass(frozen=True)
class StartKept(_Entry):
    """The data start kept in the filter's place on the estimation data: both fits (JSON ``start_kept``)."""

    start_estimation_fit_percent: float
    filter_estimation_fit_percent: float


class Finding(Protocol):
    """A failed check of the returned model made by the caller's ``checks`` (`vehid identify` checks a car's
    physical plausibility): its JSON entry and its warning."""

    def as_dict(self) -> dict[str, Any]: ...

    def warning(self) -> str: ...


def float_tuple(values: Any) -> tuple[float, ...] | None:
    """Numbers (an array, a list or a scalar) as a flat tuple of floats; None stays None."""
    if values is None:
        return None
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


@dataclass(frozen=True, eq=False)
class Identification:
    """One identification run's result: typed, frozen all the way down.

    Attributes
    ----------
    model : IdentifiedModel
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
        Choices said once, and one line per problem found (the ``checks``' findings among them).
    orders : tuple of OrderRow
        The orders tried.
    seconds : float
        Run time of the estimator(s).
    plan : Plan
        The records identified and validated on.
    evaluation : Evaluation
        The returned model's scores on every record (estimation and validation).
    estimator : IEKFResult or ComparatorResult
        The estimator's own result: the IEKF's :class:`~vehid.identification.filtering.iekf.IEKFResult`
        or a classical method's outcome.
    tuning : PTuning or None
        The IEKF's p and Q schedule with every candidate's cross-validated fit.
    open_loop_unstable : StabilityDecision or None
        The evidence of the open-loop-unstable treatment, where it was weighed.
    start_kept : StartKept or None
        The fits of a start kept on the estimation data.
    start_returned : bool
        Whether the IEKF's start model is returned in the filter's place.
    divergence : str or None
        How the IEKF's run diverged, where the last good pass is returned.
    checks : FrozenDict or None
        Modes with standard deviations and residual tests (JSON entries;
        :mod:`vehid.identification.automatic.reported_checks`).
    residual_tests : ResidualTests or None
        The residual tests behind ``checks``.
    data : FrozenDict
        The model scored per estimation record and the records' preparation (JSON entries).
    scoring_note : str or None
        How an unstable model was scored, where no horizon was given.
    nonlinear : NonlinearOutcome or None
        The spline-nonlinear model started from the linear one.
    time_domain : str or None
        A classical method's time domain ("continuous" or "discrete").
    scheduled : ScheduledOutcome or None
        The speed-scheduled family started from the unscheduled model (where the plan holds a schedule).
    unscheduled : IdentifiedModel or None
        The linear (unscheduled) model, where the scheduled family or the spline model is returned in
        its place; the summary's matrices and eigenvalues are its (JSON ``linear_modes`` its modes),
        the scores, checks and warnings the returned model's.
    returned : str
        Which model is returned: ``filter``, ``start``, ``scheduled``, ``nonlinear`` or a classical
        method's name (JSON ``model_returned``).
    plausibility : tuple of Finding or None
        The failed checks of the caller's ``checks`` (JSON ``plausibility``), each also a warning;
        None where no checks were asked for or they did not apply.
    archive : Path or None
        The HDF5 archive the run was kept in (JSON ``archive``).
    model_file : Path or None
        The model file written (JSON ``model_file``).
    """

    model: IdentifiedModel
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
    plan: Plan = field(repr=False)
    evaluation: Evaluation = field(repr=False)
    estimator: IEKFResult | ComparatorResult = field(repr=False)
    tuning: PTuning | None = None
    open_loop_unstable: StabilityDecision | None = None
    start_kept: StartKept | None = None
    start_returned: bool = False
    divergence: str | None = None
    checks: FrozenDict | None = field(default=None, repr=False)
    residual_tests: ResidualTests | None = field(default=None, repr=False)
    data: FrozenDict = field(default_factory=FrozenDict, repr=False)
    scoring_note: str | None = None
    nonlinear: NonlinearOutcome | None = field(default=None, repr=False)
    time_domain: str | None = None
    scheduled: ScheduledOutcome | None = field(default=None, repr=False)
    unscheduled: IdentifiedModel | None = field(default=None, repr=False)
    returned: str = ""
    plausibility: tuple[Finding, ...] | None = None
    archive: Path | None = None
    model_file: Path | None = None

    def __post_init__(self) -> None:
        for name in ("decisions", "notes", "warnings", "orders"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        if self.plausibility is not None:
            object.__setattr__(self, "plausibility", tuple(self.plausibility))
        # the model, the estimator's run and the records too: the summary is rendered from them
        freeze_fields(self)

    @property
    def p(self) -> float | None:
        """The IEKF's p (chosen or given); None for a classical method."""
        return None if self.tuning is None else self.tuning.p

    @property
    def is_iekf(self) -> bool:
        """Whether the estimator was the IEKF (rather than a classical method)."""
        return self.method == "iekf"

    @property
    def linear_model(self) -> IdentifiedModel:
        """The linear model whose matrices and eigenvalues the summary gives.

        The model returned, or the unscheduled model where the scheduled family
        or the spline model is returned in its place.
        """
        return self.unscheduled if self.unscheduled is not None else self.model

    @cached_property
    def summary(self) -> FrozenDict:
        """The run's summary keyed as `vehid identify --json`, frozen (:meth:`render` gives a fresh dict)."""
        return freeze(self.render())

    def render(self) -> dict[str, Any]:
        """Render the run's public JSON keys (the module docstring of :mod:`vehid.scenarios.commands.identify`).

        Returns
        -------
        dict
            The summary `vehid identify --json` prints, as a fresh dict the caller may change
            (arrays not yet made lists).
        """
        from .scoring import scores_summary  # the public score keys are defined once, beside the scoring

        model = self.linear_model
        searched = any(row.searched for row in self.orders)
        orders_tried = [row.as_dict() for row in self.orders]
        summary = {
            "method": self.method, "order": self.order, "eigenvalues": model.eigenvalues(),
            **self._estimator_keys(),
            "A": model.A, "B": model.B, "C": model.C, "D": model.D, "seconds": self.seconds,
            **(self.tuning.summary() if self.tuning is not None else {}),
            **({"orders_tried": orders_tried} if searched else {}),
            **({"open_loop_unstable": self.open_loop_unstable.as_dict()} if self.open_loop_unstable else {}),
            **({"start_kept": self.start_kept.as_dict()} if self.start_kept else {}),
            # every IEKF run reports its margins, if only as an empty entry
            **({"decision_margins": {decision.name: decision.as_dict() for decision in self.decisions}}
               if self.is_iekf or self.decisions else {}),
            **({"divergence": self.divergence} if self.divergence else {}),
            **({"model_returned": self.returned} if self.returned and (self.is_iekf or self.returned != self.method)
               else {}),
            **scores_summary(self.evaluation, self.R, self.plan.records),
            **self.data,
            **(self.checks or {}),
            **({} if searched else {"orders_tried": orders_tried}),
            "notes": list(self.notes),
            **({"scoring_note": self.scoring_note} if self.scoring_note is not None else {}),
            **({"start": {k: v for k, v in self.estimator.meta.items() if k != "start_parameters"}}
               if self.is_iekf else {}),
            **({"nonlinear": self.nonlinear.summary} if self.nonlinear is not None else {}),
            **({"scheduled": self.scheduled.summary} if self.scheduled is not None else {}),
            "warnings": list(self.warnings),
            **({"plausibility": [finding.as_dict() for finding in self.plausibility]}
               if self.plausibility is not None else {}),
            **({"archive": str(self.archive)} if self.archive is not None else {}),
            **({"model_file": str(self.model_file)} if self.model_file is not None else {}),
        }
        return thaw(summary)

    def _estimator_keys(self) -> dict[str, Any]:
        """The estimator's run: the IEKF's filter fit, passes and stop reason, or a direct method's."""
        from .scoring import pooled_fit_percent

        if not self.is_iekf:
            return {"passes_run": 0, "discretization": "exact", "time_domain": self.time_domain}
        result = self.estimator
        filter_R = result.history[-1].fit_filter
        return {"fit_percent_filter": pooled_fit_percent(filter_R, self.plan.records), "R_filter": filter_R,
                "passes_run": result.passes_run, "stop_reason": result.stop_reason,
                "discretization": result.options.discretization}

    def text(self) -> str:
        """Render the run as `vehid identify` prints it without ``--json``.

        Returns
        -------
        str
            The text (:mod:`vehid.identification.automatic.text`).
        """
        from .text import identification_text

        return identification_text(self.render(), self.plan)
