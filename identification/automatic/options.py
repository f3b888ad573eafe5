"""The settings of the automatic identification pipeline, each defined and checked once, here.

This module imports nothing heavy, so that a command line can name the defaults
in its help without loading the numerical stack.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vehid.identification.choices import SCHEDULE_DEFAULT_KNOTS, SCHEDULE_MIN_KNOTS
from vehid.identification.errors import InputError

__all__ = ["DEFAULT_PASSES", "MIN_PASSES", "DEFAULT_NONLINEAR_PASSES", "DEFAULT_NODES", "IdentifyOptions"]

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
    method : str
        The estimator: "iekf" (the automatic pipeline above) or a classical comparator
        (:data:`~vehid.identification.classical.comparators.COMPARATORS`) scored and checked alike.
    bootstrap : int or None
        With ``method="n4sid"``: residual-bootstrap replicates for its parameter covariance
        (None: the asymptotic covariance of its simulation errors; 0: no covariance).
    schedule_knots : int
        Knots of the speed-scheduled family at the schedule channel's quantiles (where a schedule is given).
    schedule_grid : tuple of float or None
        The family's knots themselves, increasing (None: ``schedule_knots`` at quantiles).
    schedule_p : tuple of float or None
        The scheduled filter's p values, one chosen on validation data (None: the default grid).
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
    method: str = "iekf"
    bootstrap: int | None = None
    schedule_knots: int = SCHEDULE_DEFAULT_KNOTS
    schedule_grid: tuple[float, ...] | None = None
    schedule_p: tuple[float, ...] | None = None

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
        if not isinstance(self.method, str) or not self.method:
            raise InputError(f"method must name an estimator; got {self.method!r}")
        _whole_at_least("schedule_knots", self.schedule_knots, SCHEDULE_MIN_KNOTS)
        for name in ("schedule_grid", "schedule_p"):
            values = getattr(self, name)
            if values is not None and not values:
                raise InputError(f"{name} must name at least one value (or be None for the default)")
        for value in self.schedule_p or ():
            _positive_number("schedule_p", value)
        if self.bootstrap is not None:
            _whole_at_least("bootstrap", self.bootstrap, 0)
            if self.method != "n4sid":
                raise InputError("--bootstrap applies to --method n4sid (the other methods' covariances cost no refits)")
