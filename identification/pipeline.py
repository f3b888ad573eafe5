"""The options and the typed result of the automatic identification pipeline.

:class:`IdentifyOptions` holds every setting of the automatic pipeline (the
defaults of `vehid identify`), each number checked once, here.
:class:`Identification` is what one run gives: the model returned, its
scores per data set, the decisions taken with their margins, the warnings,
the order-search rows and the run time. :meth:`Identification.from_summary`
reads the same run's JSON summary (the command's public keys) into it, so
that the command and a Python caller share one result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from vehid.identification.errors import InputError

__all__ = ["DEFAULT_PASSES", "MIN_PASSES", "DEFAULT_NONLINEAR_PASSES", "DEFAULT_NODES", "IdentifyOptions",
           "OrderRow", "Decision", "Identification"]

DEFAULT_PASSES = 50  # the IEKF's largest number of passes
MIN_PASSES = 1  # one pass is a complete (if unconverged) run of the filter
DEFAULT_NONLINEAR_PASSES = 30
DEFAULT_NODES = 5  # spline nodes per nonlinearity


def _positive_number(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be a positive finite number; got {value!r}")


def _whole_at_least(name: str, value: Any, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise InputError(f"{name} must be a whole number >= {low}; got {value!r}")


@dataclass(frozen=True)
class IdentifyOptions:
    """Settings of the automatic pipeline; the defaults are those of `vehid identify`.

    Parameters
    ----------
    p : float or None
        The IEKF's tuning parameter; None chooses it by two-fold cross-validation.
    passes : int
        Largest number of IEKF passes (at least :data:`MIN_PASSES`).
    start : str
        Start values: "data", "band", "default" or "paper".
    normalize : bool
        Scale inputs and outputs by their RMS while filtering.
    discretization, covariance : str
        The filter's discretisation and covariance numerics.
    pattern : str or None
        The C pattern; None lets the start model choose.
    timescale : str
        "auto" (time in samples, p per dominant time constant) or "seconds".
    allow_unstable : bool
        Keep unstable modes (an open-loop unstable plant).
    initial_state : str
        How linear models are simulated for scoring: "estimate" or "rest".
    horizon : int or None
        Score by this many steps of prediction instead of simulation.
    nonlinear : bool
        Identify the spline-nonlinear model started from the linear one.
    nodes : int
        Spline nodes per nonlinearity.
    nonlinear_p : tuple of float or None
        The spline model's p values; None takes the command's default.
    nonlinear_passes : int
        Largest number of passes of the spline model.
    detrend : str
        Offsets removed from each record: "mean", "linear" or "none".
    strict : bool
        Raise :class:`~vehid.identification.errors.StrictWarningsError` when the run ends with warnings.
    """

    p: float | None = None
    passes: int = DEFAULT_PASSES
    start: str = "data"
    normalize: bool = True
    discretization: str = "exact"
    covariance: str = "joseph"
    pattern: str | None = None
    timescale: str = "auto"
    allow_unstable: bool = False
    initial_state: str = "estimate"
    horizon: int | None = None
    nonlinear: bool = False
    nodes: int = DEFAULT_NODES
    nonlinear_p: tuple[float, ...] | None = None
    nonlinear_passes: int = DEFAULT_NONLINEAR_PASSES
    detrend: str = "mean"
    strict: bool = False

    def __post_init__(self) -> None:
        if self.p is not None:
            _positive_number("p", self.p)
        _whole_at_least("passes", self.passes, MIN_PASSES)
        if self.horizon is not None:
            _whole_at_least("horizon", self.horizon, 1)
        _whole_at_least("nodes", self.nodes, 2)
        _whole_at_least("nonlinear_passes", self.nonlinear_passes, MIN_PASSES)
        if self.nonlinear_p is not None:
            if not self.nonlinear_p:
                raise InputError("nonlinear_p must name at least one value (or be None for the default)")
            for value in self.nonlinear_p:
                _positive_number("nonlinear_p", value)


@dataclass(frozen=True)
class OrderRow:
    """One order of an order search: its fits (percent, per output) and run time."""

    order: int
    fit_percent: tuple[float, ...]
    estimation_fit_percent: tuple[float, ...] | None
    validation_fit_percent: tuple[float, ...] | None
    seconds: float


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


_DECISION_KEYS = ("choice", "score", "runner_up", "runner_up_score", "measure", "rule")


def _floats(values: Any) -> tuple[float, ...] | None:
    if values is None:
        return None
    return tuple(float(v) for v in np.ravel(np.asarray(values, dtype=float)))


@dataclass(frozen=True)
class Identification:
    """One identification run's result.

    Attributes
    ----------
    model : object
        The model returned (the filter's, its start's where that scores better, or a scheduled family).
    method : str
        The estimator.
    order : int
        The model order.
    fit_percent : tuple of float
        Fit R (eq. 17) per output of the model simulated on the estimation data.
    estimation_fit_percent, validation_fit_percent : tuple of float or None
        NRMSE fits per output on the estimation and validation data.
    decisions : tuple of Decision
        The choices made (p, Q schedule, stability, start or filter, order), each with its margin.
    notes, warnings : tuple of str
        Choices said once, and one line per problem found.
    orders : tuple of OrderRow
        The orders tried.
    seconds : float
        Run time of the estimator(s).
    summary : Mapping
        The complete summary, keyed as the command's JSON.
    """

    model: Any
    method: str
    order: int
    fit_percent: tuple[float, ...]
    estimation_fit_percent: tuple[float, ...] | None
    validation_fit_percent: tuple[float, ...] | None
    decisions: tuple[Decision, ...]
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    orders: tuple[OrderRow, ...]
    seconds: float
    summary: Mapping[str, Any] = field(repr=False)

    @classmethod
    def from_summary(cls, summary: Mapping[str, Any], model: Any) -> "Identification":
        """The result of a run from its JSON summary (the command's keys) and the model returned."""
        decisions = tuple(Decision(name=name, choice=entry.get("choice"), score=entry.get("score"),
                                   runner_up=entry.get("runner_up"), runner_up_score=entry.get("runner_up_score"),
                                   measure=str(entry.get("measure", "")), rule=str(entry.get("rule", "")),
                                   details={key: value for key, value in entry.items() if key not in _DECISION_KEYS})
                          for name, entry in summary.get("decision_margins", {}).items())
        rows = tuple(OrderRow(order=int(row["order"]), fit_percent=_floats(row.get("fit_percent")) or (),
                              estimation_fit_percent=_floats(row.get("estimation_fit_percent")),
                              validation_fit_percent=_floats(row.get("validation_fit_percent")),
                              seconds=float(row["seconds"]))
                     for row in summary.get("orders_tried", ()))
        return cls(model=model, method=str(summary["method"]), order=int(summary["order"]),
                   fit_percent=_floats(summary["fit_percent"]) or (),
                   estimation_fit_percent=_floats(summary.get("estimation_fit_percent")),
                   validation_fit_percent=_floats(summary.get("validation_fit_percent")),
                   decisions=decisions, notes=tuple(summary.get("notes", ())),
                   warnings=tuple(summary.get("warnings", ())), orders=rows, seconds=float(summary["seconds"]),
                   summary=dict(summary))
