"""The spline-nonlinear IEKF (Best & Bogdanski 2017, section 5).

The rinse (:mod:`vehid.identification.filtering.rinse`) and the compiled pass run on the spline-modal model of
:mod:`vehid.identification.models.spline_modal`, with the paper's differences: the start is the linear model
identified on the same data (every node at its linear value); ``R`` is the residual covariance of the
frozen model, recomputed after every pass; ``p`` is much lower, so that ``P`` and ``K`` adapt slowly.
Signals are normalised by their largest magnitude (not the RMS of the linear filter), because the B and
D nodes over -1..1 must hold every input sample. After each pass the A and C node ranges move to the
range their variable reached, the splines re-sampled at the new nodes and ``P`` mapped alike.

The finished model's covariance is that of its node ordinates as a fit of its simulation errors
(:func:`~vehid.identification.assessment.uncertainty.difference_fit_covariance`, the Jacobian by central
differences; the delete-one-block jackknife where the record allows), in the normalised units ``P``
holds; the filter's ``P`` stands for a checkpoint of a running filter. ``meta["uncertainty_method"]``
says which.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..blas import on_one_blas_thread
from ..data import IOData
from ..choices import SPLINE_NODE_COUNT, SPLINE_NODES, SPLINE_P, SPLINE_PASSES
from ..errors import DivergenceError
from .iekf_pass import compiled_pass
from ..optionspec import check_value
from ..assessment.metrics import percentage_explanation
from ..models.modal import ModalModel
from .rinse import Assessment, PassHistory, PassRecord, RinseHooks, check_filter_options, check_records, rinse
from ..models.spline_modal import SplineModalFilterModel, SplineModalModel, SplineModalStructure
from ..assessment.segments import formal_method
from ..assessment.uncertainty import difference_fit_covariance, with_covariance

__all__ = [
    "SplineIEKFOptions",
    "SplineIEKFResult",
    "identify_spline_iekf",
    "covering_ranges",
    "residual_covariance",
]

_RANGE_PERCENTILES = (0.5, 99.5)
#: Central-difference step of the node ordinates, relative to each (truncation and rounding near 1e-10),
#: and its floor relative to the largest ordinate (a node at zero still moves the simulation)
_DIFFERENCE_STEP = 1e-6
_STEP_FLOOR = 1e-3
_RANGE_MARGIN = 0.1  # widen each moving range by this fraction of its span at each end
_R_FLOOR = 1e-9  # relative floor on R's diagonal (a perfect fit must not make R singular)


@dataclass(frozen=True)
class SplineIEKFOptions:
    """Settings of the spline-nonlinear IEKF.

    Parameters
    ----------
    nodes : int
        Nodes per spline, 3..9 (paper: 5).
    p : float
        Tuning parameter: ``Q = p I'`` on the node ordinates, ``P0 = Q``; the
        default is measured best on the handling study (docs/iekf_tuning.md).
        The filter minimises one-step prediction errors; a larger p lets the
        ordinates follow them away from the model that simulates best.
    passes : int
        Largest number of passes.
    discretization, covariance : str
        As for the linear filter.
    redistribute : bool
        Move the A and C node ranges between passes.
    fit_tolerance : float
        Stop when the mean R (percent) changes by less than this from one pass to the next.
    min_passes : int
        Never stop earlier than this.
    """

    nodes: int = SPLINE_NODES
    p: float = SPLINE_P
    passes: int = SPLINE_PASSES
    discretization: str = "exact"
    covariance: str = "joseph"
    redistribute: bool = True
    fit_tolerance: float = 1e-4
    min_passes: int = 3

    def __post_init__(self) -> None:
        check_value("nodes", self.nodes, SPLINE_NODE_COUNT)
        check_filter_options(self.p, self.passes, self.discretization, self.covariance)


@dataclass(frozen=True, eq=False)
class SplineIEKFResult(PassHistory):
    """The identified nonlinear model, one record per pass, the filter state and the start.

    Attributes
    ----------
    model : SplineModalModel
        The identified model.
    start : SplineModalModel
        The model the filter started from (equal to the linear start).
    options : SplineIEKFOptions
        The settings used.
    history : tuple of PassRecord
        One record per pass.
    P : ndarray, shape (n_parameters, n_parameters)
        The filter's final covariance of the ordinates (normalised units).
    R : ndarray, shape (n_y, n_y)
        The measurement noise covariance of the residuals (normalised outputs).
    start_fit : ndarray, shape (n_y,)
        R (eq. 17) per output of the start model, percent.
    stop_reason : str
        ``"converged"``, ``"passes"`` or ``"diverged: ..."``.
    seconds : float
        Run time (s).
    meta : dict
        Provenance, ``uncertainty_method`` among it.
    """

    model: SplineModalModel
    start: SplineModalModel
    options: SplineIEKFOptions
    history: tuple[PassRecord, ...]
    P: np.ndarray
    R: np.ndarray
    start_fit: np.ndarray
    stop_reason: str
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def fit_percent(self) -> np.ndarray:
        """R per output of the final model (percent)."""
        return self.history[-1].fit_filter if self.history else self.start_fit


def covering_ranges(structure: SplineModalStructure, states: np.ndarray, previous: np.ndarray) -> np.ndarray:
    """Node ranges covering what the states (normalised, (N, n)) reached; inputs keep ``previous``."""
    linear = structure.linear
    ranges = np.array(previous, dtype=float)
    low, high = _RANGE_PERCENTILES
    for pair in range(linear.n_complex_pairs):
        amplitude = np.hypot(states[:, 2 * pair], states[:, 2 * pair + 1])
        top = float(np.percentile(amplitude, high))
        ranges[structure.amplitude_variable(pair)] = [0.0, max(top * (1 + _RANGE_MARGIN), 1e-6)]
    for state in range(linear.n):
        lower, upper = np.percentile(states[:, state], [low, high])
        span = max(upper - lower, 1e-6)
        ranges[structure.state_variable(state)] = [lower - _RANGE_MARGIN * span, upper + _RANGE_MARGIN * span]
    return ranges


def residual_covariance(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """``1/N sum (y - y_hat)(y - y_hat)'`` with a tiny floor on the diagonal, so that a perfect fit stays invertible."""
    residual = y - y_hat
    R = residual.T @ residual / residual.shape[0]
    floor = _R_FLOOR * np.mean(y**2, axis=0)
    return R + np.diag(floor)


@on_one_blas_thread
def identify_spline_iekf(
    data: IOData,
    linear: ModalModel,
    *,
    options: SplineIEKFOptions | None = None,
    on_pass: Callable[[PassRecord, SplineIEKFResult], None] | None = None,
) -> SplineIEKFResult:
    """Identify a spline-nonlinear modal model, starting from a linear one identified on the same data.

    Parameters
    ----------
    data : IOData
        The identification record (original units).
    linear : ModalModel
        The linear model to start from (its structure fixes the modes and C pattern).
    options : SplineIEKFOptions, optional
        Settings; :class:`SplineIEKFOptions`' defaults without them.
    on_pass : callable, optional
        Called after every pass with the new record and the result so far.

    Returns
    -------
    SplineIEKFResult
        The identified model, one record per pass and the filter's final P.

    Raises
    ------
    InputError
        On data that do not match the linear model's inputs and outputs.
    DivergenceError
        On non-finite values, a P no longer positive definite or a model whose
        simulation blows up; ``last_good`` holds the result up to the last
        good pass (None before the first).
    """
    options = options or SplineIEKFOptions()
    structure = SplineModalStructure(linear.structure, options.nodes)
    check_records((data,), linear.structure.n_u, linear.structure.n_y, structure.n_parameters, "the linear model")
    started = time.perf_counter()
    input_scale = np.abs(data.u).max(axis=0)
    output_scale = np.abs(data.y).max(axis=0)
    u_n = data.u / input_scale
    y_n = data.y / output_scale

    model = SplineModalModel.from_linear(linear, options.nodes, input_scale, output_scale, data.dt, options.discretization)
    y_hat, states = model.simulate_normalised(u_n)
    if not np.all(np.isfinite(y_hat)):
        raise DivergenceError("the linear start model's simulation is not finite")
    model, _ = model.resampled(covering_ranges(structure, states, model.ranges))  # constant splines: exact
    start = model
    start_fit = percentage_explanation(y_n, y_hat)
    R = residual_covariance(y_n, y_hat)

    n = structure.linear.n
    q = np.concatenate([np.zeros(n), np.full(structure.n_parameters, options.p)])
    run_pass = compiled_pass(SplineModalFilterModel(structure), data.dt, options.discretization, options.covariance)

    def result(stop_reason: str, history: tuple[PassRecord, ...], theta: np.ndarray, P: np.ndarray) -> SplineIEKFResult:
        finished = model
        if history:
            # R is the measured residual covariance, so P needs no rescaling (see vehid.identification.assessment.uncertainty)
            covariance, method = P[n:, n:], formal_method("the filter's P of a running filter")
            found = None if stop_reason == "running" else difference_fit_covariance(
                lambda values: model.with_parameters(values).simulate_normalised(u_n)[0], model.theta, y_n,
                steps=_DIFFERENCE_STEP * np.maximum(np.abs(model.theta), _STEP_FLOOR * np.max(np.abs(model.theta))),
                dt=float(data.dt))
            if found is not None:
                covariance, method = found
            finished = with_covariance(model, covariance, method)
        return SplineIEKFResult(
            model=finished, start=start,
            options=options, history=history, P=P.copy(), R=R.copy(), start_fit=start_fit, stop_reason=stop_reason,
            seconds=time.perf_counter() - started,
        )

    def assess(theta: np.ndarray, P: np.ndarray) -> Assessment:
        """Score the frozen model, take R from its residuals and move the node ranges (module docstring)."""
        nonlocal model, R
        candidate = model.with_parameters(theta)
        y_hat, states = candidate.simulate_normalised(u_n)
        if not (np.all(np.isfinite(y_hat)) and np.max(np.abs(y_hat)) < 1e6):
            raise DivergenceError("the identified model's simulation blows up (try a lower p)")
        fit = percentage_explanation(y_n, y_hat)
        model, R = candidate, residual_covariance(y_n, y_hat)
        if options.redistribute:
            model, transform = model.resampled(covering_ranges(structure, states, model.ranges))
            full = np.eye(P.shape[0])
            full[n:, n:] = transform
            P = full @ P @ full.T
        return Assessment(model.theta, fit, fit, model.theta, P)

    hooks = RinseHooks(
        (data,), lambda state, _: run_pass(state, u_n, y_n, q, R, model.constants), lambda: R, assess,
        lambda previous, current: abs(current.mean_fit_filter - previous.mean_fit_filter) < options.fit_tolerance,
        result, n, label="nonlinear pass",
    )
    return rinse(hooks, model.theta, np.diag(q), passes=options.passes, min_passes=options.min_passes,
                 check_covariance=options.covariance != "paper", on_pass=on_pass)
