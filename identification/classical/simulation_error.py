"""A linear modal model refined by its simulation error: the criterion a hold-out fit scores, minimised.

The IEKF minimises one-step prediction errors of a joint filter of states and
parameters, and with a shrinking or constant Q its parameters at the end of a
pass are an average over a window of the record; a subspace start minimises
no error of the model at all. The workbench's verdict on a linear model is
its simulation from the least-squares initial state (MATLAB ``compare``).
:func:`refine_simulation_error` closes that gap: from a given model it
minimises, by Levenberg-Marquardt with the exact Jacobian
(:meth:`~vehid.identification.models.modal.ModalModel.output_sensitivity` and
:meth:`~vehid.identification.models.modal.ModalModel.free_response_sensitivity`:
a few first-order recursions per iteration, no finite differences), the
weighted sum of squared simulation errors over the records, each record
simulated from its own initial state, estimated jointly with the parameters
(or from rest). It descends from where it starts, so it returns the local
minimum of the start's basin, no worse than the start on the records it fits.

Scales (:func:`simulation_error_weights`): each output's error is divided by
the RMS of its noise-free part, the output's power less its white noise's
variance (:func:`~vehid.identification.assessment.noise.output_noise_variance`),
so that an output made noisy keeps the scale its noise-free record gives it
and sensor noise does not move the optimum from one output to another.

Criterion: the verdict scores each output by its NRMSE fit, ``100 (1 - r)``
with ``r`` the RMS error over the RMS signal, and weighs the outputs' fits
alike. A sum of squared scaled errors, ``sum r**2``, is not that: it trades
an output fitted well for the worst one (of three noise-free handling
outputs at order 2, the yaw rate's validation fit fell from 98.3 to 96.2 %
for 0.6 and 0.4 point on the other two). The default criterion
(``"fits"``) is the sum of the outputs' ``rho(r)`` (``r``: each RMS error
over its noise-free RMS signal), where ``rho`` grows as ``r`` between
:data:`ERROR_FLOOR` and :data:`ERROR_CEILING` and as a parabola of the same
slope outside, from zero at an exact fit. It is minimised by the same Levenberg-Marquardt
steps on squares whose output weights are renewed at every accepted point
as ``scale / sqrt(clip(r, ERROR_FLOOR, ERROR_CEILING))`` (iteratively
reweighted least squares: ``rho`` is concave in ``r**2``, so each step
lowers a quadratic that lies above the criterion and touches it there, and
so lowers the criterion).

The ceiling: an error above a tenth of an output's signal may be mostly
sensor noise (the roll angle's on the noisy handling records is half its
signal), which says nothing of the model; a weight lowered by it would let
the noise move the optimum from one output to another (on those records
the noisy runs' roll angle lost up to 2.3 points of noise-free fit). Such
outputs keep their squares' weights. The floor: an output fitted exactly
keeps a bounded weight. One output's criterion is a function of its squares
alone: the same minimum, by the same steps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..blas import on_one_blas_thread
from ..data import IOData, as_records
from ..errors import InputError
from ..assessment.noise import output_noise_variance
from ..models.modal import ModalModel

__all__ = ["Refinement", "refine_simulation_error", "simulation_error_weights", "MAX_ITERATIONS",
           "COST_TOLERANCE", "SIGNAL_FLOOR", "ERROR_FLOOR", "ERROR_CEILING", "CRITERIA"]

#: Levenberg-Marquardt iterations at most (each costs one Jacobian: about ``n_u + 2`` simulations).
MAX_ITERATIONS = 40
#: Relative decrease of the cost in an accepted step below which the refinement has converged: a fit
#: of F % then moves by about ``(100 - F) * 5e-6`` points a step, far below what the scores resolve.
COST_TOLERANCE = 1e-5
#: The noise-free power is taken as at least this share of an output's power: the k-th-difference noise
#: estimate is an upper bound, which a record sampled slowly against its dynamics fills with signal.
SIGNAL_FLOOR = 0.5
#: The ``"fits"`` criterion weighs an output's relative error ``r`` as its fit does between these (fits of 99 and
#: 90 %), and as its square outside (module docstring): an output fitted exactly keeps a bounded weight, and an
#: error that may be mostly sensor noise does not lower its output's weight.
ERROR_FLOOR, ERROR_CEILING = 0.01, 0.1
#: What the refinement minimises (module docstring): the sum of the outputs' relative errors, or of their squares.
CRITERIA = ("fits", "squares")
_DAMPING_START = 1e-3  # on the normal equations scaled to a unit diagonal
_DAMPING_LIMIT = 1e10  # no step this short lowers the cost: the start is a minimum to rounding
_ROUNDING = 1e-14  # of the start's cost: a gain below it is rounding


@dataclass(frozen=True, eq=False)
class Refinement:
    """A model refined by its simulation error (:func:`refine_simulation_error`).

    Attributes
    ----------
    model : ModalModel
        The refined model (the start's structure, its ``meta`` and names; no covariance).
    start_cost, cost : float
        The criterion at the start and at the end: the sum over outputs of ``rho`` of the relative RMS
        errors (``"fits"``, module docstring), or half the weighted sum of squared simulation errors
        (``"squares"``).
    iterations : int
        Accepted steps.
    stop_reason : str
        ``"converged"``, ``"iterations"`` (the limit) or ``"no descent"`` (no step lowered the cost).
    initial_states : tuple of ndarray
        Each record's initial state at the end (zeros from rest).
    weights : ndarray
        The weight of each output's error at the end (its scale for ``"squares"``).
    seconds : float
    """

    model: ModalModel
    start_cost: float
    cost: float
    iterations: int
    stop_reason: str
    initial_states: tuple[np.ndarray, ...]
    weights: np.ndarray
    seconds: float


def simulation_error_weights(records: IOData | Sequence[IOData]) -> np.ndarray:
    """One over the RMS of each output's noise-free part, over all records (module docstring)."""
    records = as_records(records)
    power = np.sum([np.sum(record.y**2, axis=0) for record in records], axis=0) / sum(
        record.n_samples for record in records)
    signal = np.maximum(power - output_noise_variance(records), SIGNAL_FLOOR * power)
    return 1.0 / np.sqrt(np.maximum(signal, np.finfo(float).tiny))


@on_one_blas_thread
def refine_simulation_error(model: ModalModel, records: IOData | Sequence[IOData], *,
                            initial_state: str = "estimate", weights: Any = None,
                            max_iterations: int = MAX_ITERATIONS, tolerance: float = COST_TOLERANCE,
                            keep_stable: bool = True, criterion: str = "fits") -> Refinement:
    """``model`` refined by Levenberg-Marquardt on its weighted simulation errors over ``records``.

    Parameters
    ----------
    model : ModalModel
        The start; with ``keep_stable`` it must be stable, and every step keeps it so.
    records : IOData or sequence of IOData
        The records it is fitted to (prepared: offsets removed), of its inputs and outputs.
    initial_state : {"estimate", "zero"}
        Each record simulated from its own initial state, refined with the parameters from the
        least-squares one (as the scores simulate), or from rest.
    weights : array_like, optional
        The scale of each output's error; default :func:`simulation_error_weights`.
    max_iterations : int
    tolerance : float
        Relative decrease of the cost in a step below which the refinement stops, converged.
    keep_stable : bool
        Refuse every step to an unstable model (a stable plant's model stays stable).
    criterion : {"fits", "squares"}
        Minimise the sum of the outputs' relative errors, as their fits weigh them (between the floor
        and the ceiling), or the sum of their squared scaled errors (module docstring).

    Returns
    -------
    Refinement

    Notes
    -----
    The normal equations are scaled to a unit diagonal (Marquardt's
    scaling), so that parameters of every size take part in a step; the
    damping shrinks tenfold after a step that lowers the cost and grows
    tenfold after one that does not (or leaves the model unstable or its
    simulation non-finite). With ``"fits"`` a step is judged on the squares
    weighted at the point it leaves, and the weights are renewed at the point
    it reaches.
    """
    from ..assessment.validation import estimate_initial_state

    started = time.perf_counter()
    records = as_records(records)
    if initial_state not in ("estimate", "zero"):
        raise InputError(f"initial_state must be 'estimate' or 'zero'; got {initial_state!r}")
    if criterion not in CRITERIA:
        raise InputError(f"criterion must be one of {', '.join(CRITERIA)}; got {criterion!r}")
    if keep_stable and not model.is_stable():
        raise InputError("the model to refine is unstable; refine it with keep_stable=False")
    structure = model.structure
    n, n_theta = structure.n, structure.n_parameters
    scales = simulation_error_weights(records) if weights is None else np.asarray(weights, dtype=float)
    samples = sum(record.n_samples for record in records)

    def relative_errors(squares: np.ndarray) -> np.ndarray:
        """Each output's RMS error over its noise-free RMS signal (``r`` of the module docstring)."""
        return scales * np.sqrt(squares / samples)

    def weights_at(squares: np.ndarray) -> np.ndarray:
        if criterion == "squares":
            return scales
        return scales / np.sqrt(np.clip(relative_errors(squares), ERROR_FLOOR, ERROR_CEILING))

    def criterion_of(squares: np.ndarray) -> float:
        if criterion == "squares":
            return 0.5 * float(np.sum(scales**2 * squares))
        r = relative_errors(squares)
        bound = np.clip(r, ERROR_FLOOR, ERROR_CEILING)  # rho's slope is 1 there, a parabola's of the same slope beyond
        return float(np.sum(np.where(r == bound, r, 0.5 * (r**2 / bound + bound)) - 0.5 * ERROR_FLOOR))

    estimate = initial_state == "estimate"
    states = [estimate_initial_state(model, record) if estimate else np.zeros(n) for record in records]
    point = np.concatenate([model.parameters, *states]) if estimate else model.parameters.copy()
    size = point.size

    def state_slice(index: int) -> slice:
        return slice(n_theta + index * n, n_theta + (index + 1) * n)

    def evaluate(z: np.ndarray, with_jacobian: bool, weights: np.ndarray
                 ) -> tuple[float, np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Half the sum of squares at ``z`` weighted by ``weights`` (inf where unusable), each output's unweighted
        sum of squares, and the normal equations' G and g."""
        trial = ModalModel.from_parameters(structure, z[:n_theta])
        squares = np.zeros(len(weights))
        if keep_stable and not trial.is_stable():
            return np.inf, squares, None, None
        cost = 0.0
        gram, gradient = (np.zeros((size, size)), np.zeros(size)) if with_jacobian else (None, None)
        for index, record in enumerate(records):
            state = z[state_slice(index)] if estimate else None
            with np.errstate(all="ignore"):
                if not with_jacobian:
                    simulated = trial.simulate_outputs(record.u, record.dt, x0=state)
                else:
                    simulated, by_theta = trial.output_sensitivity(record.u, record.dt)
                    if estimate:  # the simulation from the state: from rest plus the state's free response
                        free, free_by_theta, by_state = trial.free_response_sensitivity(state, record.n_samples,
                                                                                         record.dt)
                        simulated = simulated + free
                residual = simulated - record.y
                error = (residual * weights).ravel()
            if not np.all(np.isfinite(error)):
                return np.inf, squares, None, None
            squares += np.sum(residual**2, axis=0)
            cost += 0.5 * float(error @ error)
            if with_jacobian:
                blocks = [by_theta + free_by_theta, by_state] if estimate else [by_theta]
                jacobian = (np.concatenate(blocks, axis=2) * weights[None, :, None]).reshape(error.size, -1)
                if not np.all(np.isfinite(jacobian)):
                    return np.inf, squares, None, None
                index_of = np.r_[0:n_theta, state_slice(index)] if estimate else np.arange(n_theta)
                gram[np.ix_(index_of, index_of)] += jacobian.T @ jacobian
                gradient[index_of] += jacobian.T @ error
        return cost, squares, gram, gradient

    squares = evaluate(point, False, scales)[1]
    start_squares = squares
    weights = weights_at(squares)
    cost, squares, gram, gradient = evaluate(point, True, weights)
    if not np.isfinite(cost):
        raise InputError("the model to refine cannot be simulated on these records (non-finite outputs)")
    damping, accepted, stop_reason = _DAMPING_START, 0, "iterations"
    while accepted < max_iterations:
        scale = np.sqrt(np.maximum(np.diag(gram), np.finfo(float).tiny))
        scaled_gram, scaled_gradient = gram / np.outer(scale, scale), gradient / scale
        while damping <= _DAMPING_LIMIT:
            try:
                step = -np.linalg.solve(scaled_gram + damping * np.eye(size), scaled_gradient) / scale
            except np.linalg.LinAlgError:
                damping *= 10.0
                continue
            trial_cost, trial_squares, _, _ = evaluate(point + step, False, weights)
            if trial_cost < cost:
                break
            damping *= 10.0
        else:
            stop_reason = "no descent"
            break
        # converged where a step gains little against the cost, or next to nothing against the start's (an
        # exact fit's cost falls without end, by a constant factor a step, down to rounding)
        small = (cost - trial_cost < tolerance * cost
                 or cost - trial_cost < _ROUNDING * 0.5 * float(np.sum(weights**2 * start_squares)))
        point = point + step
        weights = weights_at(trial_squares)
        cost, squares, gram, gradient = evaluate(point, True, weights)
        accepted += 1
        damping = max(damping / 10.0, 1e-12)
        if small:
            stop_reason = "converged"
            break
    refined = ModalModel.from_parameters(structure, point[:n_theta], input_names=model.input_names,
                                         output_names=model.output_names, meta=dict(model.meta))
    final_states = tuple(point[state_slice(i)].copy() if estimate else np.zeros(n) for i in range(len(records)))
    return Refinement(refined, criterion_of(start_squares), criterion_of(squares), accepted, stop_reason,
                      final_states, weights, time.perf_counter() - started)
