"""The settings of the automatic identification pipeline, each declared and checked once, here.

:class:`IdentifyOptions` declares every setting with its default, the values it
may take and its help (:func:`~vehid.identification.optionspec.option`); a bad
value or combination raises :class:`~vehid.identification.errors.OptionError`
naming the option when the object is built, before any work. `vehid identify`
defines its flags from the same declarations
(:func:`~vehid.identification.optionspec.option_specs`).

This module imports nothing heavy, so that a command line can name the defaults
in its help without loading the numerical stack.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike

from vehid.identification.choices import (C_PATTERNS, COVARIANCE_FORMS, DETREND, DISCRETIZATIONS, ESTIMATORS,
                                          INITIAL_STATES,
                                          SCHEDULE_DEFAULT_KNOTS, SCHEDULE_GRID, SCHEDULE_KNOT_COUNT,
                                          SCHEDULED_DEFAULT_P, SCHEDULED_P_GRID, SPLINE_NODE_COUNT, SPLINE_NODES,
                                          START_CHOICES, TIMESCALES)
from vehid.identification.errors import OptionError
from vehid.identification.optionspec import (BOOLEAN, POSITIVE, Number, Numbers, OneOf, check_options, documented,
                                             option)

__all__ = ["DEFAULT_PASSES", "MIN_PASSES", "DEFAULT_NONLINEAR_PASSES", "DEFAULT_NODES", "IdentifyOptions",
           "Resume", "estimators"]

DEFAULT_PASSES = 50  # the IEKF's largest number of passes
MIN_PASSES = 1  # one pass is a complete (if unconverged) run of the filter
DEFAULT_NONLINEAR_PASSES = 30
DEFAULT_NODES = SPLINE_NODES  # spline nodes per nonlinearity
_PASSES = Number(low=MIN_PASSES, whole=True)


def estimators() -> tuple[str, ...]:
    """The estimators by name: the IEKF and the classical comparators, as registered now.

    A method is registered in :data:`~vehid.identification.comparators.COMPARATORS`, so
    one registered later has loaded that module, and its registry is read; until then the registry
    holds the built-in methods (:data:`~vehid.identification.choices.ESTIMATORS`), named without
    loading it (it loads the numerical stack: 0.4 s of a command that refuses an option).
    """
    import sys

    registry = sys.modules.get("vehid.identification.comparators")
    return ESTIMATORS if registry is None else tuple(registry.COMPARATORS)


def _p_list(values: tuple[float, ...]) -> str:
    return ", ".join(f"{p:g}" for p in values)


@documented
@dataclass(frozen=True)
class IdentifyOptions:
    """Settings of the automatic pipeline; the defaults are those of `vehid identify`.

    Each is checked when the object is built: a value outside those listed below
    raises :class:`~vehid.identification.errors.OptionError` naming it, as does
    ``bootstrap`` with a method other than n4sid.

    Examples
    --------
    >>> from vehid.identification import IdentifyOptions
    >>> options = IdentifyOptions(passes=20, p=1e-5, nonlinear=True)
    >>> options.passes, options.method, options.nodes
    (20, 'iekf', 5)
    >>> IdentifyOptions(start="bogus")
    Traceback (most recent call last):
    ...
    vehid.identification.errors.OptionError: 'start' must be one of data, band, default, paper; got 'bogus'
    """

    p: float | None = option(
        None, POSITIVE,
        help="tuning parameter p of the IEKF, Q = p I' (default: 1e-4, 1e-5 or 1e-6 per dominant time constant, "
             "chosen by two-fold cross-validation on the estimation data; 1 with ``timescale`` seconds)")
    passes: int = option(DEFAULT_PASSES, _PASSES, help="largest number of passes of the IEKF")
    start: str = option(
        "data", OneOf(START_CHOICES),
        help="start values: data (a subspace model of the record), band (modes across the record's band), "
             "default (sigma = -10, omega = 10 rad/s, absolute) or paper (sigma = -1, omega = 1)")
    normalize: bool = option(True, BOOLEAN, help="scale inputs and outputs by their RMS while filtering")
    discretization: str = option("exact", OneOf(DISCRETIZATIONS), help="discretisation of the filter's model")
    covariance: str = option("joseph", OneOf(COVARIANCE_FORMS), help="covariance numerics of the filter")
    pattern: str | None = option(
        None, OneOf(C_PATTERNS),
        help="C pattern, complex pairs first (default: with ``start`` data the start model's complex pairs and "
             "real poles, else the default pattern; either way modes tied to outputs in turn)")
    timescale: str = option(
        "auto", OneOf(TIMESCALES),
        help="the filter's time unit: auto (samples; p per dominant time constant) or seconds (absolute, the "
             "paper's)")
    allow_unstable: bool = option(False, BOOLEAN,
                                  help="keep unstable modes (open-loop unstable plants) instead of stopping")
    initial_state: str = option(
        "estimate", OneOf(INITIAL_STATES),
        help="how linear models are simulated to score them: from a least-squares initial state (estimate) or "
             "from rest (zero)")
    horizon: int | None = option(
        None, Number(low=1, whole=True),
        help="score by K-step-ahead prediction instead of simulation (automatic for unstable models)")
    nonlinear: bool = option(False, BOOLEAN,
                             help="after the linear model, identify the spline-nonlinear model started from it")
    nodes: int = option(DEFAULT_NODES, SPLINE_NODE_COUNT, help="nodes per spline of the nonlinear model")
    nonlinear_p: tuple[float, ...] | None = option(
        None, Numbers(POSITIVE),
        help="tuning parameter(s) of the spline model; several are tried and one chosen on validation data "
             "(default 1e-7, or 1e-7, 1e-8, 1e-9 with validation data)")
    nonlinear_passes: int = option(DEFAULT_NONLINEAR_PASSES, _PASSES,
                                   help="largest number of passes of the spline model")
    detrend: str = option("mean", DETREND,
                          help="offsets removed per record and stored with the model: means, lines or none")
    strict: bool = option(False, BOOLEAN, help="fail a run that ends with warnings (StrictWarningsError, exit status 3)")
    method: str = option(
        "iekf", OneOf(estimators),
        help="estimator: the IEKF, or a classical comparator on the same data, scored and checked alike")
    bootstrap: int | None = option(
        None, Number(low=0, whole=True),
        help="with ``method`` n4sid: residual-bootstrap replicates for its parameter covariance, each one subspace "
             "fit (default: none, the asymptotic covariance of its simulation errors; 0 for no covariance)")
    schedule_knots: int = option(
        SCHEDULE_DEFAULT_KNOTS, SCHEDULE_KNOT_COUNT,
        help="the most knots of a speed-scheduled family, at the schedule channel's quantiles (knots crowded "
             "within a quarter of the even spacing merge)")
    schedule_grid: tuple[float, ...] | None = option(
        None, SCHEDULE_GRID,
        help="the scheduled family's knots themselves, increasing (default: ``schedule_knots`` at evenly spaced "
             "quantiles of the channel)")
    schedule_p: tuple[float, ...] | None = option(
        None, Numbers(POSITIVE),
        help=f"tuning parameter(s) of the scheduled filter, per dominant time constant; several are tried and one "
             f"chosen on validation data (default {SCHEDULED_DEFAULT_P:g}, or {_p_list(SCHEDULED_P_GRID)} with "
             f"validation data)")

    def __post_init__(self) -> None:
        check_options(self)
        if self.bootstrap is not None and self.method != "n4sid":
            raise OptionError("'bootstrap' applies to 'method' n4sid (the other methods' covariances cost no refits)",
                              "bootstrap", "method")


@documented
@dataclass(frozen=True)
class Resume:
    """A checkpointed run to go on with (`vehid identify --resume ARCHIVE`): an archive and a pass budget.

    The archive is the one an identification wrote with ``out``.

    The run goes on with the archive's records, preparation and filter settings, and reaches the
    same parameters as a run that was never interrupted.
    """

    archive: str | PathLike = option(None, help="the archive of the run to go on with")
    passes: int | None = option(None, _PASSES,
                                help="a new budget of passes, all passes counted (default: the run's own)")

    def __post_init__(self) -> None:
        check_options(self)
        if self.archive is None or not str(self.archive):
            raise OptionError("'resume' names the archive of the run to go on with", "resume")
