"""Classical identification methods as comparators beside the IEKF, all ending in the same modal form.

Every comparator takes one :class:`~identification.data.IOData` record or
several of one ``dt`` and a model order and returns a continuous-time
:class:`~identification.models.modal.ModalModel` (or, where a discrete pole lies on
the negative real axis and no continuous equivalent exists, the labelled
:class:`~identification.models.discrete.DiscreteModel`), so that
:func:`identify_with` scores all methods alike. Methods (:data:`COMPARATORS`;
more join with :func:`register_comparator`):

``arx``
    Least-squares ARX per output (``na = order``, ``nb = order + 1`` lags
    from 0: a first-order hold has direct feed-through), realised, converted
    to continuous time for a first-order hold; several outputs' realisations
    stacked and reduced to ``order`` states by balanced truncation.
``rls``
    The same ARX model by recursive least squares, started from a batch fit
    of the first ``10 n_p`` samples (appendix A.2.3, Remark 2), on
    differenced and normalised regressors: at high sample rates the raw
    lagged regressors are too collinear for the plain covariance update
    (docs/identification_notes.md).
``n4sid``
    PO-MOESP (:mod:`vehid.identification.classical.subspace`).
``output-error``
    Nonlinear least squares on each output's RMS-scaled simulation error,
    started from ``arx`` (one output) or ``n4sid`` (several, where stacked
    ARX realisations are only approximate and the fit converges far slower).

Each leaves a parameter covariance on its model
(:mod:`vehid.identification.assessment.uncertainty`). Several records identify one
model: least-squares rows never span a record boundary, N4SID estimates one
initial state per record, output error simulates each record from rest.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import scipy.linalg
import scipy.optimize
from scipy.special import comb

from .argument_checks import non_negative_int, positive_int
from .blas import on_one_blas_thread
from .data import IOData, as_records
from .models.discrete import DiscreteModel, has_no_continuous_equivalent
from .errors import ConversionError, ExcitationError, InputError, WorkbenchError
from .classical.least_squares import estimate_arx, least_squares, model_from_theta, stacked_arx_regressors
from .assessment.metrics import FitMetrics, fit_metrics
from .models.modal import ModalModel
from .models.modal_structure import ModalStructure
from .classical.recursive import recursive_least_squares
from .models.statespace import balanced_truncation, discrete_to_continuous, modal_structure_for, to_modal
from .classical.subspace import estimate_subspace
from .assessment.segments import UncertaintyMethod, formal_method
from .assessment.uncertainty import (
    bootstrap_covariance,
    fit_covariance,
    propagate_by_differences,
    with_covariance,
    with_simulation_error_covariance,
)

__all__ = [
    "ComparatorResult",
    "Comparator",
    "COMPARATORS",
    "register_comparator",
    "identify_with",
    "arx_comparator",
    "rls_comparator",
    "n4sid_comparator",
    "output_error_comparator",
]

Comparator = Callable[..., ModalModel]


@dataclass(frozen=True, eq=False)
class ComparatorResult:
    """One method's identified model, its fit to the record and its run time.

    Attributes
    ----------
    method : str
        The method's name in :data:`COMPARATORS`.
    model : ModalModel
        The identified model, in modal form.
    metrics : FitMetrics
        Of the model simulated exactly (first-order hold) against the record.
    seconds : float
        Wall time of the identification (the scoring simulation excluded).
    meta : dict
        The method's own notes (orders, options).
    """

    method: str
    model: ModalModel
    metrics: FitMetrics
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Summarise the result for JSON.

        Returns
        -------
        dict
            Method, fits, run time, eigenvalues and the method's notes.
        """
        return {
            "method": self.method,
            "seconds": self.seconds,
            "metrics": self.metrics.as_dict(),
            "eigenvalues": [[float(v.real), float(v.imag)] for v in self.model.eigenvalues()],
            "model": self.model.to_dict(),
        }


def _check_data(data: Any) -> tuple[IOData, ...]:
    if not isinstance(data, (IOData, list, tuple)):
        raise InputError("the comparators take an IOData record or a sequence of them")
    return as_records(data)


def _experiments(records: tuple[IOData, ...], output: int) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(record.u, record.y[:, [output]]) for record in records]


def _discrete_to_modal(Ad: np.ndarray, Bd: np.ndarray, Cd: np.ndarray, Dd: np.ndarray, dt: float,
                       meta: dict[str, Any]) -> ModalModel | DiscreteModel:
    if has_no_continuous_equivalent(Ad):  # the discrete model itself, labelled, rather than no model
        return DiscreteModel(Ad, Bd, Cd, Dd, dt, meta={
            **meta, "reason": "a discrete pole on the negative real axis has no continuous-time equivalent"})
    try:
        A, B, C, D = discrete_to_continuous(Ad, Bd, Cd, Dd, dt, hold="foh")
        structure = modal_structure_for(A, B.shape[1], C.shape[0])
        return to_modal(A, B, C, D, structure, meta=meta)
    except InputError as exc:  # the data were accepted: the estimate, not the input, has no modal form
        raise ConversionError(f"{meta.get('method', 'the')} model has no continuous modal form: {exc}") from None


def _stack_and_reduce(realisations: list[tuple[np.ndarray, ...]], order: int) -> tuple[np.ndarray, ...]:
    """Block-diagonal stack of per-output realisations, reduced to ``order`` states if larger."""
    Ad = scipy.linalg.block_diag(*[r[0] for r in realisations])
    Bd = np.vstack([r[1] for r in realisations])
    Cd = scipy.linalg.block_diag(*[r[2] for r in realisations])
    Dd = np.vstack([r[3] for r in realisations])
    if Ad.shape[0] == order:
        return Ad, Bd, Cd, Dd
    return balanced_truncation(Ad, Bd, Cd, Dd, order)[:4]


def _arx_orders(order: int, options: dict[str, Any]) -> tuple[int, Any, Any]:
    na = options.pop("na", order)
    nb = options.pop("nb", na + 1)
    nk = options.pop("nk", 0)
    return na, nb, nk


def _reject_unknown(options: dict[str, Any], method: str) -> None:
    if options:
        raise InputError(f"unknown option(s) for {method}: {', '.join(sorted(options))}")


def arx_comparator(data: IOData, *, order: int, **options: Any) -> ModalModel:
    """ARX by batch least squares, to modal form (module docstring). Options: ``na``, ``nb``, ``nk``."""
    records = _check_data(data)
    data = records[0]
    order = positive_int(order, "order")
    na, nb, nk = _arx_orders(order, options)
    _reject_unknown(options, "arx")
    fits = [estimate_arx(_experiments(records, output), na=na, nb=nb, nk=nk) for output in range(data.n_y)]
    return _arx_modal(data, order, [fit.theta.ravel() for fit in fits], [fit.covariance[0] for fit in fits],
                      (fits[0].na, fits[0].nb, fits[0].nk), {"method": "arx", "na": na, "nb": nb, "nk": nk})


def _arx_modal(data: IOData, order: int, thetas: list[np.ndarray], covariances: list[np.ndarray],
               orders: tuple[int, tuple[int, ...], tuple[int, ...]], meta: dict[str, Any]) -> ModalModel | DiscreteModel:
    """The modal model of per-output ARX coefficients, with their covariance carried through the conversion.

    The outputs' regressions are separate, so their coefficients are taken
    as independent (a block-diagonal covariance). A model with no
    continuous-time equivalent comes back discrete, without a covariance.
    """
    na, nb, nk = orders

    def modal(theta: np.ndarray, structure: ModalStructure | None = None) -> ModalModel | DiscreteModel:
        realisations = [model_from_theta(piece, data.n_u, 1, na, nb, nk, data.dt).to_statespace()
                        for piece in np.split(theta, data.n_y)]
        Ad, Bd, Cd, Dd = _stack_and_reduce(realisations, order)
        if structure is None:
            return _discrete_to_modal(Ad, Bd, Cd, Dd, data.dt, meta)
        return to_modal(*discrete_to_continuous(Ad, Bd, Cd, Dd, data.dt, hold="foh"), structure, meta=meta)

    theta = np.concatenate(thetas)
    model = modal(theta)
    if isinstance(model, DiscreteModel):
        return model
    try:
        covariance = propagate_by_differences(lambda value: modal(value, model.structure).parameters, theta,
                                              scipy.linalg.block_diag(*covariances))
    except InputError:  # a mode on the edge of real and complex: no smooth map, the model stands without
        return model
    return with_covariance(model, covariance, formal_method(
        "the least-squares covariance of the ARX coefficients (white equation errors), carried through the conversion"))


def _difference_matrix(size: int) -> np.ndarray:
    """Row i takes the i-th backward difference of a block of consecutive lags."""
    matrix = np.zeros((size, size))
    for i in range(size):
        for j in range(i + 1):
            matrix[i, j] = (-1) ** j * comb(i, j, exact=True)
    return matrix


def rls_comparator(data: IOData, *, order: int, **options: Any) -> ModalModel:
    """ARX by recursive least squares, to modal form. Options: ``na``, ``nb``, ``nk``, ``forgetting``."""
    records = _check_data(data)
    data = records[0]
    order = positive_int(order, "order")
    na, nb, nk = _arx_orders(order, options)
    forgetting = options.pop("forgetting", 1.0)
    _reject_unknown(options, "rls")
    thetas, covariances = [], []
    nb_t = (nb,) * data.n_u if np.isscalar(nb) else tuple(nb)
    nk_t = (nk,) * data.n_u if np.isscalar(nk) else tuple(nk)
    for output in range(data.n_y):
        phi, target, _, _ = stacked_arx_regressors(_experiments(records, output), na=na, nb=nb, nk=nk)
        blocks = [na] + ([nb] * data.n_u if np.isscalar(nb) else list(nb))
        transform = scipy.linalg.block_diag(*[_difference_matrix(size) for size in blocks if size])
        scaled = phi @ transform.T
        scale = np.sqrt(np.mean(scaled**2, axis=0))
        scale[scale == 0] = 1.0
        scaled /= scale
        start = min(10 * scaled.shape[1], scaled.shape[0])
        first = least_squares(scaled[:start], target[:start])
        run = recursive_least_squares(scaled[start:], target[start:], forgetting=forgetting, P0=first.gram_inverse,
                                      theta0=first.theta, keep_history=False)
        back = transform.T / scale[None, :]  # theta = back @ theta_scaled
        thetas.append((back @ run.theta).ravel())
        # P times the prediction errors' variance is the scaled coefficients' covariance (appendix A.2.3)
        noise = float(np.mean(run.errors[len(run.errors) // 2:] ** 2))
        covariances.append(noise * back @ run.covariance @ back.T)
    return _arx_modal(data, order, thetas, covariances, (na, nb_t, nk_t),
                      {"method": "rls", "na": na, "nb": nb, "nk": nk, "forgetting": forgetting})


def n4sid_comparator(data: IOData, *, order: int, **options: Any) -> ModalModel:
    """Subspace identification (PO-MOESP), to modal form.

    Options: ``block_rows``; ``bootstrap`` (None, the default: the asymptotic
    covariance of the simulation errors at the estimate,
    :func:`~identification.assessment.uncertainty.simulation_error_covariance`; N > 0:
    a residual bootstrap of N replicates, one subspace fit each; 0: no
    covariance) and ``seed`` (of the bootstrap).
    """
    records = _check_data(data)
    data = records[0]
    order = positive_int(order, "order")
    block_rows = options.pop("block_rows", None)
    replicates = options.pop("bootstrap", None)
    replicates = None if replicates is None else non_negative_int(replicates, "bootstrap")
    seed = options.pop("seed", 0)
    _reject_unknown(options, "n4sid")
    fit = estimate_subspace(data if len(records) == 1 else list(records), order=order, block_rows=block_rows)
    model = _discrete_to_modal(fit.A, fit.B, fit.C, fit.D, data.dt,
                               {"method": "n4sid (PO-MOESP)", "block_rows": fit.block_rows})
    if replicates == 0 or isinstance(model, DiscreteModel):  # asked for none, or no modal parameters to cover
        return model
    if replicates is None:
        return with_simulation_error_covariance(model, records)

    def replicate(y: np.ndarray) -> np.ndarray | None:
        try:
            with warnings.catch_warnings(), np.errstate(all="ignore"):
                warnings.simplefilter("ignore", RuntimeWarning)  # a replicate with an unstable mode overflows
                again = estimate_subspace((data.u, y), order=order, block_rows=fit.block_rows)
                continuous = discrete_to_continuous(again.A, again.B, again.C, again.D, data.dt, hold="foh")
                return to_modal(*continuous, model.structure).parameters
        except (InputError, ExcitationError, np.linalg.LinAlgError):  # left out, and counted
            return None

    if len(records) > 1:  # the residual bootstrap resamples one record's residuals
        raise InputError("the n4sid residual bootstrap takes one record; leave bootstrap unset for several")
    try:
        covariance, used = bootstrap_covariance(replicate, data.y - fit.residuals, fit.residuals,
                                                samples=replicates, rng=np.random.default_rng(seed))
    except InputError:  # no replicate fits the structure: the model stands, without a covariance
        covariance, used = None, 0
    model = dataclasses.replace(model, meta={**model.meta, "bootstrap_replicates": used})
    if covariance is None:
        return model
    return with_covariance(model, covariance, UncertaintyMethod(
        name="residual-block-bootstrap", note=f"{used} of {replicates} replicates, one subspace fit each"))


def output_error_comparator(data: IOData, *, order: int, **options: Any) -> ModalModel:
    """The modal model fitted by nonlinear least squares on the simulation error.

    Options: ``start`` (``"auto"``: ``"arx"`` for one output, ``"n4sid"`` for
    several; ``"arx"``, ``"n4sid"`` or a ModalModel of this order),
    ``max_evaluations`` (most evaluations of the error, not counting the
    finite-difference Jacobian's, default 50: each iteration also costs
    one simulation per parameter),
    ``tolerance`` (``ftol``/``xtol``/``gtol``, default 1e-10).
    """
    records = _check_data(data)
    data = records[0]
    order = positive_int(order, "order")
    start = options.pop("start", "auto")
    if isinstance(start, str) and start == "auto":
        start = "arx" if data.n_y == 1 else "n4sid"
    tolerance = float(options.pop("tolerance", 1e-10))
    max_evaluations = options.pop("max_evaluations", None)
    _reject_unknown(options, "output-error")
    if isinstance(start, ModalModel):
        initial = start
    elif start in ("arx", "n4sid"):
        initial = _start_model(start, records, order)
        if isinstance(initial, DiscreteModel):
            initial = _continuous_start(initial, start, records, order)
    else:
        raise InputError(f"start must be 'arx', 'n4sid' or a ModalModel; got {start!r}")
    if initial.structure.n != order or (initial.structure.n_u, initial.structure.n_y) != (data.n_u, data.n_y):
        raise InputError("the starting model's order, inputs or outputs differ from the request")
    structure = initial.structure
    size = sum(record.y.size for record in records)
    weights = 1.0 / np.sqrt(sum(np.sum(record.y**2, axis=0) for record in records) / (size / data.n_y))
    dt = data.dt
    limit = 1e6 * np.sqrt(size)

    def residuals(theta: np.ndarray) -> np.ndarray:
        A, B, C, D = structure.matrices(theta)
        try:  # each record simulated from rest
            model = ModalModel(structure, A, B, C, D)
            with np.errstate(over="ignore", invalid="ignore"):
                error = np.concatenate([((model.simulate_outputs(record.u, dt) - record.y)
                                         * weights).ravel() for record in records])
        except InputError:
            return np.full(size, limit)
        # an unstable trial step can overflow (silenced above): a large finite error sends the optimiser back
        return np.where(np.isfinite(error), np.clip(error, -limit, limit), limit)

    solution = scipy.optimize.least_squares(
        residuals, initial.parameters, method="trf", x_scale="jac", ftol=tolerance, xtol=tolerance,
        gtol=tolerance, max_nfev=int(max_evaluations or 50),
    )
    meta = {"method": "output-error", "start": initial.meta.get("method", "given"),
            "evaluations": int(solution.nfev), "cost": float(solution.cost), "status": int(solution.status)}
    return with_covariance(ModalModel.from_parameters(structure, solution.x, meta=meta),
                           *fit_covariance(solution.jac, solution.fun.reshape(-1, data.n_y), dt=dt))


def _start_model(method: str, records: list[IOData], order: int) -> ModalModel | DiscreteModel:
    """The ``arx`` or ``n4sid`` model that starts output-error (no bootstrap: a start needs no covariance)."""
    options = {"bootstrap": 0} if method == "n4sid" else {}
    return COMPARATORS[method](records, order=order, **options)


def _continuous_start(discrete: DiscreteModel, method: str, records: list[IOData], order: int) -> ModalModel:
    """A continuous start where ``method``'s model has a discrete pole on the negative real axis.

    The other linear method's model, if it is continuous; else ``method``'s
    model with each negative real pole ``z`` moved to ``|z|``: the same
    decay per sample without the sign flip, which a continuous mode can
    represent (such a pole mostly fits noise; the fit moves B, C, D and the
    modes from there).
    """
    other = "n4sid" if method == "arx" else "arx"
    try:
        alternative = _start_model(other, records, order)
    except WorkbenchError:
        alternative = None
    if isinstance(alternative, ModalModel):
        return alternative
    values, vectors = np.linalg.eig(discrete.A)
    negative = (np.abs(values.imag) <= 1e-9 * np.abs(values)) & (values.real < 0)
    moved = (vectors @ np.diag(np.where(negative, np.abs(values), values)) @ np.linalg.inv(vectors)).real
    model = _discrete_to_modal(moved, discrete.B, discrete.C, discrete.D, discrete.dt,
                               {"method": f"{method}, negative real poles moved to the positive axis"})
    if isinstance(model, DiscreteModel):  # a pole at zero: no continuous mode decays that fast
        raise ConversionError(f"the {method} and {other} start models have no continuous-time equivalent: "
                              "give output-error a start ModalModel, or another order")
    return model


def iekf_comparator(data: IOData, *, order: int, **options: Any) -> ModalModel:
    """The IEKF with the workbench's default settings (exact discretisation), C pattern ``default``.

    Options are those of :class:`vehid.identification.filtering.iekf.IEKFOptions` (``p``, ``passes``, ...).
    """
    from .filtering.iekf import IEKFOptions, identify_iekf

    try:
        settings = IEKFOptions(**options)
    except TypeError as exc:
        raise InputError(f"unknown option for the iekf method: {exc}") from None
    records = _check_data(data)
    structure = ModalStructure.default(order, records[0].n_u, records[0].n_y)
    return identify_iekf(records, structure, options=settings).model


#: The comparators by name; ``identify_with(data, method=name, order=n)`` dispatches here.
COMPARATORS: dict[str, Comparator] = {
    "iekf": iekf_comparator,
    "arx": arx_comparator,
    "rls": rls_comparator,
    "n4sid": n4sid_comparator,
    "output-error": output_error_comparator,
}


def register_comparator(name: str, function: Comparator, *, replace: bool = False) -> None:
    """Add a method to :data:`COMPARATORS`.

    Parameters
    ----------
    name : str
        The method's name, as ``method=`` takes it.
    function : callable
        ``function(data, *, order, **options) -> ModalModel``.
    replace : bool, default False
        Replace a method already registered under ``name`` (else that is an error).
    """
    if not callable(function):
        raise InputError(f"the comparator {name!r} must be callable")
    if name in COMPARATORS and not replace:
        raise InputError(f"a comparator named {name!r} exists; pass replace=True to replace it")
    COMPARATORS[name] = function


@on_one_blas_thread
def identify_with(data: IOData, *, method: str, order: int, **options: Any) -> ComparatorResult:
    """Identify a modal model of ``order`` states from ``data`` by ``method`` and score it.

    Parameters
    ----------
    data : IOData or sequence of IOData
        One record, or several records of one experiment campaign (one ``dt``).
    method : str
        A key of :data:`COMPARATORS`: ``iekf``, ``arx``, ``rls``, ``n4sid``,
        ``output-error`` (and whatever :func:`register_comparator` added).
    order : int
        Model order n.
    **options
        Passed to the method; unknown options raise :class:`InputError`.

    Returns
    -------
    ComparatorResult
        The model, its fit metrics (exact first-order-hold simulation from
        rest against ``data.y``: R of eq. 17, NRMSE fit, R^2) and the run time.

    Examples
    --------
    >>> from vehid.identification import IOData, identify_with
    >>> import numpy as np
    >>> t = np.arange(400) * 0.01
    >>> u = np.sin(3 * t) + np.sin(11 * t)
    >>> y = np.zeros_like(u)
    >>> for k in range(1, t.size):
    ...     y[k] = 0.95 * y[k - 1] + 0.05 * u[k - 1]
    >>> result = identify_with(IOData(t=t, u=u, y=y), method="n4sid", order=1)
    >>> bool(result.metrics.mean_percentage_explanation > 99)
    True
    """
    records = _check_data(data)
    if method not in COMPARATORS:
        raise InputError(f"unknown method {method!r}; use one of {', '.join(sorted(COMPARATORS))}")
    start = time.perf_counter()
    model = COMPARATORS[method](data if isinstance(data, IOData) else records, order=order, **options)
    seconds = time.perf_counter() - start
    if len(records) == 1:
        metrics = fit_metrics(records[0].y, model.simulate_outputs(records[0].u, records[0].dt))
    else:  # each record from rest, all records scored together
        simulated = [model.simulate_outputs(record.u, record.dt) for record in records]
        metrics = fit_metrics(np.vstack([record.y for record in records]), np.vstack(simulated))
    return ComparatorResult(method, model, metrics, seconds, {"order": order, "records": len(records)})
