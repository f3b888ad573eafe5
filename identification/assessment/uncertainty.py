"""How sure is a modal model? Parameter covariances and what follows from them.

Every estimator leaves a covariance of the modal parameter vector
(:attr:`ModalModel.parameter_covariance`): the IEKF its fit's asymptotic
covariance plus the spread of its parameters along one more pass
(:func:`iekf_parameter_covariance`); output error the Gauss-Newton covariance
(:func:`gauss_newton_covariance`); ARX the least-squares covariance carried
through the conversion (:func:`propagate_by_differences`); N4SID the
simulation-error bound (:func:`simulation_error_covariance`; too narrow where
its block rows miss the slow modes) or a residual bootstrap on request
(:func:`bootstrap_covariance`).

Where the record allows, the covariance of a fit of simulation errors is not
the curvature's ``(J' W J)^-1``, which assumes white residuals and a model
that holds the system, but the delete-one-block jackknife of the fit
(:func:`fit_covariance`; :mod:`vehid.identification.assessment.segments`): one
Gauss-Newton step per deleted block of the record, so that coloured
residuals and model error count as much as they move the estimate. The
model's ``meta["uncertainty_method"]`` says which
(:class:`~vehid.identification.assessment.segments.UncertaintyMethod`).

What follows from a covariance (modes, gains, the frequency response) is
propagated by the delta method in :mod:`vehid.identification.models.delta_method`.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ..errors import InputError
from .segments import (DEFAULT_BLOCKS, UncertaintyMethod, block_jackknife, block_plan, formal_method, gram_matrix,
                       integrated_correlation_time, one_step_replicates)

__all__ = [
    "iekf_parameter_covariance",
    "gauss_newton_covariance",
    "fit_covariance",
    "difference_fit_covariance",
    "simulation_error_covariance",
    "with_covariance",
    "with_simulation_error_covariance",
    "upper_envelope",
    "propagate_by_differences",
    "bootstrap_covariance",
]


def iekf_parameter_covariance(
    structure: Any,
    P_parameters: np.ndarray,
    input_scale: np.ndarray,
    output_scale: np.ndarray,
    noise_ratio: float,
    *,
    time_unit: float = 1.0,
    estimate: Any = None,
    records: Any = None,
    pass_parameters: np.ndarray | None = None,
    with_method: bool = False,
) -> Any:
    """The IEKF's parameter covariance in original units: its fit's covariance plus its measured fluctuation.

    Parameters
    ----------
    structure : ModalStructure
    P_parameters : ndarray, shape (n_theta, n_theta)
        The parameter block of the filter's ``P`` after the last pass, in the
        normalised units the filter ran in.
    input_scale, output_scale : ndarray
        The normalisation (``u = input_scale u_n``, ``y = output_scale y_n``).
    noise_ratio : float
        Measured innovation variance over the variance the filter assumed:
        the mean normalised innovation squared ``e' R^-1 e`` of the last
        pass divided by the number of outputs.
    time_unit : float
        The filter's unit of time in seconds (the sample interval when it
        counts time in samples): sigma, omega and B are rescaled to 1/s.
    estimate : ModalModel, optional
        The model at the estimate (original units); with ``records``, the
        covariance of the fit at it enters (Notes).
    records : sequence of IOData, optional
        The records the filter ran over.
    pass_parameters : ndarray, shape (n_samples, n_theta), optional
        The filter's parameters (original units) at evenly spaced points of
        one more pass over ``records`` from its final state: with
        ``estimate`` and ``records``, the covariance is the fit's plus
        their mean square deviation from the fit's minimiser (Notes).
    with_method : bool
        Return the pair of the covariance and how it was obtained
        (:class:`~vehid.identification.assessment.segments.UncertaintyMethod`).

    Notes
    -----
    After many passes the filter runs periodically over the record, and
    the estimate it returns (its parameters at the end of a pass) is one
    point of that cycle. Its error ``e_k`` at sample ``k`` splits into the
    mean over the pass and the deviation from it; averaged over the pass,
    ``E[e_k e_k'] = Cov(mean) + E[S]`` with ``S`` the covariance of the
    parameters about their mean along the pass (the law of total variance
    over the position in the record). To first order the mean weights every
    sample of the record alike: it is the point that minimises the
    simulation error (the states carry no process noise, so the filter
    predicts by simulation), whose covariance is
    :func:`simulation_error_covariance` at the estimate. So the covariance
    is that (:func:`simulation_error_covariance`: the fit's delete-one-block
    jackknife where the record allows) plus ``S``, measured on the pass itself. ``S`` is taken about
    that minimiser (one Gauss-Newton step from the estimate) rather than
    about the samples' own mean: where a filter of high gain does not
    average to the minimiser, the offset (a bias the fit does not have) is
    counted with the fluctuation. Both parts are
    measured in the noise the data carry; neither depends on the filter's
    tuning model. At a small ``p`` the filter barely moves within a pass
    (``S`` vanishes, the estimate is the minimiser); at a large ``p`` it
    forgets within a pass and ``S`` dominates.

    Without ``pass_parameters`` (a checkpoint of a running filter) or where
    the fit cannot be simulated, the filter's own ``P`` stands in:
    ``noise_ratio P / 2``, the steady-state error of a filter tracking a
    constant under a random-walk model (the Lyapunov equation
    ``V M P + P M V = P M P``, ``M = H' R^-1 H``, of its error recursion
    gives ``V = P / 2``), its noise rescaled to the measured innovations;
    with the fit's covariance but no pass, the larger of the two direction
    by direction (:func:`upper_envelope`). That reasoning holds for a filter
    of the parameters alone; for the joint filter of states and parameters
    it overstates the spread of the estimates, the more so the larger ``p``
    (measured on the calibration system: README, "How sure is the model?").

    The map to original units is the Jacobian of
    :meth:`~identification.models.modal_structure.ModalStructure.rescale_time` and
    :meth:`~identification.models.modal_structure.ModalStructure.denormalize`, a diagonal matrix since both
    scale each parameter alone: ``cov = J P J'``.
    """
    if not (np.isfinite(noise_ratio) and noise_ratio > 0):
        raise InputError(f"the measured noise ratio must be positive; got {noise_ratio!r}")
    n_theta = structure.n_parameters
    jacobian = np.column_stack([
        structure.denormalize(structure.rescale_time(unit, 1.0 / time_unit), input_scale, output_scale)
        for unit in np.eye(n_theta)
    ])
    P_parameters = np.asarray(P_parameters, dtype=float)
    covariance = 0.5 * noise_ratio * jacobian @ P_parameters @ jacobian.T
    covariance = 0.5 * (covariance + covariance.T)

    def answer(value: np.ndarray, method: UncertaintyMethod) -> Any:
        return (value, method) if with_method else value

    filter_only = formal_method("the filter's P (half of it, scaled by the measured innovations): no finished "
                                "run's fit to measure the spread on")
    if estimate is None or records is None:
        return answer(covariance, filter_only)
    found = simulation_error_covariance(estimate, records, with_step=True, with_method=True)
    if found is None:
        return answer(covariance, filter_only)
    fit, step, method = found
    if pass_parameters is not None:
        samples = np.asarray(pass_parameters, dtype=float)
        if samples.ndim == 2 and samples.shape[0] >= 2 and samples.shape[1] == n_theta and np.all(np.isfinite(samples)):
            deviations = samples - (estimate.parameters + step)
            total = fit + deviations.T @ deviations / samples.shape[0]
            return answer(0.5 * (total + total.T), method.with_note("plus the filter's spread along one more pass"))
    return answer(upper_envelope(covariance, fit),
                  method.with_note("at least half the filter's P, direction by direction"))


def upper_envelope(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """The covariance at least as large as each of two, and no larger than it must be, direction by direction.

    With ``W`` such that ``W' first W = I`` and ``W' second W = diag(d)``
    (the generalised eigenvectors), it is ``W^-T diag(max(1, d)) W^-1``.
    ``first`` must be positive definite; where it is not, the sum stands in.
    """
    try:
        import scipy.linalg  # half a second to import: paid where it is used, not by every command's start
        values, vectors = scipy.linalg.eigh(second, first)
    except (np.linalg.LinAlgError, ValueError):
        return first + second
    back = first @ vectors  # W^-T, since W' first W = I
    envelope = back @ np.diag(np.maximum(values, 1.0)) @ back.T
    return 0.5 * (envelope + envelope.T)


def gauss_newton_covariance(jacobian: np.ndarray, residuals: np.ndarray, *, overwrite_jacobian: bool = False) -> np.ndarray:
    """The covariance ``(J' W J)^-1`` of a least-squares fit of several outputs' errors.

    Parameters
    ----------
    jacobian : ndarray, shape (N n_y, n_theta)
        Derivatives of the (weighted) errors, rows time-major (sample k,
        output i at row ``k n_y + i``), as the output-error fit stacks them.
    residuals : ndarray, shape (N, n_y)
        The (weighted) errors at the solution.
    overwrite_jacobian : bool
        Where the normal equations are too ill conditioned and the Jacobian
        is factorised, weight and factorise it in place (its contents are
        then lost): for a long record this spares two copies of the
        largest array of the computation.

    Notes
    -----
    Each output's error variance ``s_i^2`` is measured from its residuals
    (``N n_y - n_theta`` degrees of freedom shared in proportion), and ``W``
    weights its rows by ``1 / s_i^2``: the covariance of the weighted
    least-squares estimate with white errors, which is the output-error
    model's noise assumption (Ljung 1999, eq. 9.17).
    """
    residuals = np.asarray(residuals, dtype=float)
    samples, n_y = residuals.shape
    n_theta = jacobian.shape[1]
    variance = _error_variances(residuals, n_theta)
    jacobian = np.asarray(jacobian, dtype=float)
    blocks = jacobian.reshape(samples, n_y, n_theta)
    # the normal equations, equilibrated, where they are well conditioned: a Gram product costs a
    # fraction of a QR factorisation of the long Jacobian; their rounding (about sqrt(N) eps of each
    # entry, relative) then moves the covariance by less than 1e-5 relative below condition 1e6
    gram = sum(gram_matrix(blocks[:, i, :]) / variance[i] for i in range(n_y))
    scale = np.sqrt(np.diag(gram))
    if np.all(scale > 0) and np.all(np.isfinite(gram)):
        values, vectors = np.linalg.eigh(gram / np.outer(scale, scale))
        if values[0] > 1e-6 * values[-1]:
            covariance = (vectors / values) @ vectors.T / np.outer(scale, scale)
            return 0.5 * (covariance + covariance.T)
    # ill conditioned: the orthogonal factorisation, whose R carries no squared condition number
    in_place = overwrite_jacobian and jacobian.flags.f_contiguous and jacobian.flags.writeable
    if in_place:
        blocks /= np.sqrt(variance)[None, :, None]  # a view: the weights land in the caller's array
        weighted = blocks
    else:
        weighted = blocks / np.sqrt(variance)[None, :, None]
    stacked = weighted.reshape(samples * n_y, n_theta)
    # only R is needed: LAPACK's Householder QR leaves it in the top rows, without forming Q or
    # copying out the full (N n_y, n_theta) triangle as scipy.linalg.qr(mode="r") does
    import scipy.linalg  # half a second to import: paid where it is used, not by every command's start
    factored = scipy.linalg.lapack.dgeqrf(stacked, overwrite_a=int(in_place))[0]
    upper = np.triu(factored[: min(stacked.shape)])
    inverse = scipy.linalg.pinv(upper)
    covariance = inverse @ inverse.T
    return 0.5 * (covariance + covariance.T)


def _error_variances(residuals: np.ndarray, n_theta: int) -> np.ndarray:
    """Each output's error variance, its ``N n_y - n_theta`` degrees of freedom shared in proportion."""
    samples, n_y = residuals.shape
    dof = max(samples * n_y - n_theta, 1) / (samples * n_y)
    # an exact fit (noise-free data) has no spread: the floor makes its covariance vanish, not divide by zero
    return np.maximum(np.mean(residuals**2, axis=0) / dof, 1e-300)


#: Why a fit's covariance stays formal where the record cannot be cut into enough blocks.
SHORT_RECORD_REASON = ("the record holds fewer than {fewest} blocks longer than its residuals' correlation time "
                       "({tau:.3g} samples): the intervals assume white residuals")


def fit_covariance(jacobian: np.ndarray, residuals: np.ndarray, *, dt: float | None = None, jackknife: bool = True,
                   blocks: int = DEFAULT_BLOCKS, form: str = "linearised", level: float = 0.95,
                   overwrite_jacobian: bool = False) -> tuple[np.ndarray, UncertaintyMethod]:
    """The covariance of a weighted least-squares fit of several outputs' errors, and how it was obtained.

    Parameters
    ----------
    jacobian : ndarray, shape (N n_y, n_theta)
        Derivatives of the errors, rows time-major (sample k, output i at row ``k n_y + i``).
    residuals : ndarray, shape (N, n_y)
        The errors at the estimate.
    dt : float, optional
        Sample interval (s), to state the blocks in seconds.
    jackknife : bool
        Measure the covariance by the delete-one-block jackknife where the record allows (default);
        False gives the formal :func:`gauss_newton_covariance`.
    blocks : int
        Most blocks (fewer where they would be shorter than the correlation time).
    form : {"linearised", "one-step"}
        The replicates' curvature (:func:`~vehid.identification.assessment.segments.one_step_replicates`):
        the whole record's (default) or the one without the block.
    level : float
        Level at which the jackknife's few degrees of freedom are allowed for
        (:func:`~vehid.identification.assessment.segments.interval_scale`).
    overwrite_jacobian : bool
        As :func:`gauss_newton_covariance`, for the formal covariance.

    Returns
    -------
    covariance : ndarray (n_theta, n_theta)
    method : UncertaintyMethod

    Notes
    -----
    Each output weighed by ``1 / s_i^2`` as :func:`gauss_newton_covariance` weighs it, the record
    is cut into at most :data:`~vehid.identification.assessment.segments.DEFAULT_BLOCKS` contiguous
    blocks, each longer than the residuals' integrated correlation time; the replicate without
    block ``k`` is one Gauss-Newton step from the estimate on the other blocks, with the whole
    record's curvature (:func:`~vehid.identification.assessment.segments.one_step_replicates`):
    the jackknife linearised, whose covariance is the block sandwich ``H^-1 S H^-1`` with ``S``
    the spread of the blocks' scores. Coloured residuals
    and model error move those steps as much as they move the estimate, which the curvature
    alone cannot see; on white residuals of a model that holds, the jackknife's variance agrees
    with the curvature's on average (before the factor ``(t(K - 1) / z)^2`` for its few degrees
    of freedom). Where no such blocks fit, or a parameter is determined by one block alone, the
    formal covariance stands and the method says why.
    """
    residuals = np.asarray(residuals, dtype=float)
    samples, n_y = residuals.shape
    n_theta = jacobian.shape[1]
    method = formal_method("asked for the formal covariance of white residuals")
    if jackknife:
        tau = float(np.max(integrated_correlation_time(residuals)))
        edges = block_plan(samples, min_length=np.ceil(tau), most=blocks)
        if edges is None:
            from .segments import MIN_BLOCKS

            method = formal_method(SHORT_RECORD_REASON.format(fewest=MIN_BLOCKS, tau=tau))
        else:
            weights = 1.0 / np.sqrt(_error_variances(residuals, n_theta))
            blocks = np.asarray(jacobian, dtype=float).reshape(samples, n_y, n_theta)
            weighted_errors = residuals * weights**2
            spans = list(zip(edges[:-1], edges[1:]))
            pieces = [(blocks[a:b] * weights[None, :, None]).reshape(-1, n_theta) for a, b in spans]
            gradients = [blocks[a:b].reshape(-1, n_theta).T @ weighted_errors[a:b].ravel() for a, b in spans]
            try:
                replicates = one_step_replicates(np.zeros(n_theta), pieces, gradients, form=form)
            except InputError as exc:
                method = formal_method(f"no jackknife: {exc}")
            else:
                found = block_jackknife(replicates, edges, form=form, level=level, dt=dt, correlation_time=tau)
                return found.covariance, found.method
    return gauss_newton_covariance(jacobian, residuals, overwrite_jacobian=overwrite_jacobian), method


def simulation_error_covariance(model: Any, records: Any, *, with_step: bool = False, with_method: bool = False,
                                jackknife: bool = True) -> Any:
    """The covariance of a modal model's parameters as a fit of its simulation errors.

    Parameters
    ----------
    model : ModalModel
        The estimate; its parameters need not minimise the simulation error
        (an N4SID estimate does not).
    records : sequence of IOData
        The records it was identified from, each simulated from rest
        (first-order hold), as output error fits them.
    with_step : bool
        Also return the Gauss-Newton step from the model's parameters towards
        the minimiser of the weighted simulation error.
    with_method : bool
        Also return how the covariance was obtained
        (:class:`~vehid.identification.assessment.segments.UncertaintyMethod`).
    jackknife : bool
        The delete-one-block jackknife of the fit where the records allow
        (:func:`fit_covariance`, default); False: the formal covariance.

    Returns
    -------
    ndarray, shape (n_theta, n_theta), or None
        :func:`fit_covariance` of the errors' exact Jacobian
        (:meth:`~identification.models.modal.ModalModel.output_sensitivity`); None
        where the model cannot be simulated to finite values (an unstable
        estimate over a long record). With ``with_step`` or ``with_method``, a
        tuple of the covariance, then the step, then the method, as asked (or None).

    Notes
    -----
    The formal covariance is the one a prediction-error (output-error) estimate would
    have at this point with white output noise of the measured variance
    (Ljung 1999, eq. 9.17); for a consistent estimator that does not
    minimise that criterion (subspace methods) it is the efficient bound.
    The records are cut into blocks as one record (a block may span two).
    """
    errors, jacobians = [], []
    with np.errstate(all="ignore"):
        for record in records:
            simulated, sensitivity = model.output_sensitivity(record.u, record.dt, method="foh")
            errors.append(simulated - record.y)
            jacobians.append(sensitivity.reshape(-1, sensitivity.shape[-1]))
    # one record's Jacobian is already the column-major array the QR factorises in place: no copy
    base = errors[0] if len(errors) == 1 else np.concatenate(errors)
    jacobian = jacobians[0] if len(jacobians) == 1 else np.concatenate(jacobians)
    if not (np.all(np.isfinite(jacobian)) and np.all(np.isfinite(base))):
        return None
    step = None
    if with_step:
        # the step -(J' W J)^-1 J' W e with the covariance's weights W (1 / each output's error variance),
        # its gradient taken before the formal covariance may overwrite J
        gradient = jacobian.T @ (base / _error_variances(base, jacobian.shape[1])).ravel()
    covariance, method = fit_covariance(jacobian, base, dt=float(records[0].dt), jackknife=jackknife,
                                        overwrite_jacobian=not with_step)
    if with_step:
        formal = covariance if method.name == "formal" else gauss_newton_covariance(jacobian, base,
                                                                                     overwrite_jacobian=True)
        step = -formal @ gradient
    if not (with_step or with_method):
        return covariance
    return (covariance, *((step,) if with_step else ()), *((method,) if with_method else ()))


def difference_fit_covariance(simulate: Callable[[np.ndarray], np.ndarray], theta: Any, measured: Any, *,
                              steps: Any, dt: float | None = None, **options: Any) -> tuple | None:
    """:func:`fit_covariance` of a model's simulation errors, the Jacobian by central differences.

    Parameters
    ----------
    simulate : callable
        ``simulate(theta) -> y (N, n_y)``, the model's outputs over the record(s) with parameters ``theta``.
    theta : array_like (n_theta,)
        The estimate.
    measured : array_like (N, n_y)
        The measured outputs.
    steps : array_like (n_theta,)
        The difference step of each parameter (``2 n_theta`` simulations).
    dt : float, optional
        Sample interval (s), to state the blocks in seconds.
    **options
        Passed to :func:`fit_covariance` (``jackknife``, ``blocks``, ``form``, ``level``).

    Returns
    -------
    (covariance, UncertaintyMethod) or None
        None where a simulation is not finite.
    """
    theta = np.asarray(theta, dtype=float).ravel()
    steps = np.broadcast_to(np.asarray(steps, dtype=float), theta.shape)
    if not np.all(steps > 0):
        raise InputError("every parameter needs a positive difference step")
    with np.errstate(all="ignore"):
        base = np.asarray(simulate(theta), dtype=float)
        jacobian = np.empty(base.shape + (theta.size,))
        for i in range(theta.size):
            shift = np.zeros(theta.size)
            shift[i] = steps[i]
            jacobian[:, :, i] = (simulate(theta + shift) - simulate(theta - shift)) / (2 * steps[i])
    residuals = base - np.asarray(measured, dtype=float)
    if not (np.all(np.isfinite(jacobian)) and np.all(np.isfinite(residuals))):
        return None
    return fit_covariance(jacobian.reshape(-1, theta.size), residuals, dt=dt, **options)


def with_covariance(model: Any, covariance: Any, method: UncertaintyMethod) -> Any:
    """``model`` (a frozen dataclass with ``meta``) carrying ``covariance`` and ``meta["uncertainty_method"]``."""
    import dataclasses

    return dataclasses.replace(model, parameter_covariance=covariance,
                               meta={**model.meta, "uncertainty_method": method.as_dict()})


def with_simulation_error_covariance(model: Any, records: Any) -> Any:
    """``model`` carrying :func:`simulation_error_covariance` on ``records`` and how it was obtained
    (without a covariance where the model's simulation is not finite)."""
    found = simulation_error_covariance(model, records, with_method=True)
    return model.with_parameter_covariance(None) if found is None else with_covariance(model, *found)


def propagate_by_differences(
    function: Callable[[np.ndarray], np.ndarray],
    point: np.ndarray,
    covariance: np.ndarray,
    *,
    relative_step: float = 1e-6,
) -> np.ndarray:
    """``J cov J'`` for a function without symbolic form, ``J`` by central differences.

    Used for conversions that pass through eigen-decompositions and
    similarity transforms (ARX polynomials to a modal model): the step in
    each direction is ``relative_step`` times that direction's standard
    deviation, which keeps it inside the region the delta method assumes
    linear and far from rounding.
    """
    point = np.asarray(point, dtype=float)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    columns = []
    for index in range(point.size):
        step = relative_step * max(std[index], 1e-12 * max(abs(point[index]), 1.0))
        forward, backward = point.copy(), point.copy()
        forward[index] += step
        backward[index] -= step
        columns.append((function(forward) - function(backward)) / (2 * step))
    jacobian = np.column_stack(columns)
    result = jacobian @ covariance @ jacobian.T
    return 0.5 * (result + result.T)


def bootstrap_covariance(
    estimate: Callable[[np.ndarray], np.ndarray | None],
    fitted: np.ndarray,
    residuals: np.ndarray,
    *,
    samples: int,
    rng: np.random.Generator,
    block: int | None = None,
) -> tuple[np.ndarray, int]:
    """Covariance of an estimator by a moving-block residual bootstrap.

    Parameters
    ----------
    estimate : callable
        ``estimate(y) -> theta`` re-identifies from outputs ``y`` (N, n_y),
        or returns ``None`` when a replicate cannot be put in the reference
        structure (it is then left out).
    fitted, residuals : ndarray, shape (N, n_y)
        The model's simulated output and the measured-minus-simulated residuals.
    samples : int
        Number of replicates.
    rng : numpy.random.Generator
    block : int, optional
        Block length in samples (default ``round(N ** (1/3))``): blocks keep
        the residuals' short-range correlation, as the bootstrap of
        dependent data requires (Kuensch 1989).

    Returns
    -------
    covariance : ndarray (n_theta, n_theta)
    used : int
        Replicates that entered it.
    """
    length = residuals.shape[0]
    block = max(1, int(round(length ** (1 / 3)))) if block is None else int(block)
    centred = residuals - residuals.mean(axis=0)
    thetas = []
    blocks_needed = -(-length // block)
    for _ in range(samples):
        starts = rng.integers(0, length - block + 1, size=blocks_needed)
        index = (starts[:, None] + np.arange(block)[None, :]).ravel()[:length]
        theta = estimate(fitted + centred[index])
        if theta is not None:
            thetas.append(theta)
    if len(thetas) < 2:
        raise InputError("fewer than two bootstrap replicates could be identified: no covariance follows")
    return np.cov(np.array(thetas), rowvar=False), len(thetas)
