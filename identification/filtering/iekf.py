"""The Identifying Extended Kalman Filter (Best & Bogdanski 2017, sections 2-4).

The parameters of a modal state-space model join its states in the filter's
state vector (eq. 7-8); the filter rinses over the record again and again
(:mod:`vehid.identification.filtering.rinse`), each pass scored by R (eq. 17) of the
frozen model simulated from rest. Tuning (section 3): ``Q = p I'`` with
zeros for the true states, ``R = I`` unless given, ``P0 = Q``.

Units. The fixed starts (:data:`START_VALUES`), ``p`` and ``R = I`` are
absolute and suit only records like the paper's. :meth:`IEKFOptions.invariant`
removes the units: signals divided by their RMS, the start from the data
(:mod:`vehid.identification.filtering.start`), time in samples inside the filter
(``timescale="auto"``) and ``p`` per dominant time constant ``tau`` of the
start, carried to the filtered parameters by congruence (under which the
Kalman filter is exact). The field defaults stay the paper's, so that stored
runs and the paper's studies are unchanged.

Noise. A constant ``Q`` models parameters that drift: at the end of the last
pass the filter's parameters are an average over a window whose length ``Q``
sets, and on a noisy record they follow its noise. The invariant settings
therefore shrink ``Q`` from pass to pass (``p_decay``, down to
:data:`P_DECAY_FLOOR` of ``p``): the early passes move the parameters from the
start, the late ones average over the whole record. ``R`` is taken per output
from the record's white noise (:func:`~vehid.identification.assessment.noise.output_noise_variance`), so that a noisy
output weighs less than a clean one (the noisiest keeping R = I's weight, on
which p is tuned), and a pass that diverges runs again from
the last good pass with a tenth of ``p`` (``back_off`` times at most), noted
in the result's ``meta["notes"]``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..blas import on_one_blas_thread
from ..data import IOData, as_records
from ..choices import START_CHOICES, START_VALUES, TIMESCALES
from ..errors import DivergenceError, InputError
from ..optionspec import OneOf, check_value
from .filter_models import LinearModalFilterModel
from .iekf_pass import compiled_pass, pack_covariance, unpack_covariance
from ..models.modal import ModalModel
from ..models.modal_structure import ModalStructure
from ..assessment.multirecord import pooled_simulation_fit
from ..assessment.noise import output_noise_variance
from .rinse import (Assessment, PassHistory, PassRecord, RinseHooks, check_filter_options, check_records,
                    parameters_settled, rinse)
from .start import DATA_STARTS, data_start
from ..assessment.uncertainty import iekf_parameter_covariance

__all__ = [
    "IEKFOptions",
    "PassRecord",
    "IEKFResult",
    "FilterState",
    "identify_iekf",
    "START_VALUES",
    "START_CHOICES",
    "TIMESCALES",
    "start_structure",
    "normalized_data_start",
    "signal_scales",
    "data_measurement_noise",
    "invariant_noise_settings",
]


#: The relative tuning parameter of :meth:`IEKFOptions.invariant`: Q = p I per dominant time
#: constant of the start model, on parameters of order 1 (chosen by measurement: docs/iekf_tuning.md).
INVARIANT_P = 1e-4

#: The invariant settings' factor on Q from one pass to the next (module docstring, "Noise"): after
#: 26 passes Q is below 1e-4 of p's, where it stays (:data:`P_DECAY_FLOOR`).
INVARIANT_P_DECAY = 0.7

#: The smallest fraction of p's Q that ``p_decay`` leaves: Q never vanishes, so that P stays positive
#: definite and the stop rule, which compares trace(P) from pass to pass, can be met.
P_DECAY_FLOOR = 1e-4

#: Restarts with a tenth of p after a divergence in the invariant settings: two take p from the top of
#: the tuning grid to below its bottom.
INVARIANT_BACK_OFF = 2

#: The factor on p of each restart after a divergence: on Q, and on P0, from which P starts again.
BACK_OFF_FACTOR = 0.1

#: Smallest R per output of ``measurement_noise="data"`` (in units of the output's power) against the
#: noisiest output's 1: an output whose relative noise variance is below a hundredth of the noisiest
#: one's weighs a hundred times as much, no more, so that a noise-free output beside noisy ones does
#: not get a gain that only the rounding of its samples would limit.
NOISE_WEIGHT_FLOOR = 1e-2

#: Relative noise variance below which ``measurement_noise="data"`` counts an output as noise-free: a
#: noise below 1 % of the output's RMS. Outputs all below it keep R = I, whatever their samples' rounding.
NOISE_FLOOR = 1e-4

#: Points of the extra pass at which the filter's parameters are sampled for their covariance
#: (:func:`~identification.assessment.uncertainty.iekf_parameter_covariance`): the sample covariance of 200
#: points has a relative standard error of about 10 % where they are independent.
PASS_SAMPLES = 200


@dataclass(frozen=True)
class IEKFOptions:
    """Settings of an IEKF identification.

    Parameters
    ----------
    p : float
        The tuning parameter: ``Q = p I'`` and ``P0 = Q`` (paper: 1 for the linear example).
    passes : int
        The largest number of passes over the record.
    discretization : {"exact", "euler", "exact-zoh"}
        ``exact`` (first-order hold) converges to the true continuous model;
        ``euler`` is the paper's and converges to its Euler equivalent.
    covariance : {"joseph", "paper"}
        Covariance numerics (see :mod:`vehid.identification.filtering.iekf_pass`).
    measurement_noise : float, "data" or None
        ``R = measurement_noise * I`` in (normalised) output units; default 1
        (the paper's R = I); ``"data"``: ``R`` diagonal, in units of each
        output's power the ratio of its white noise's variance
        (:func:`~vehid.identification.assessment.noise.output_noise_variance`) to the noisiest output's, at least
        :data:`NOISE_WEIGHT_FLOOR`: the noisiest output keeps R = I's weight.
    start : {"default", "paper", "data", "band"}
        Start values: fixed sigma/omega (:data:`START_VALUES`) or taken from
        the data (:mod:`vehid.identification.filtering.start`).
    normalize : bool
        Scale each input and output by its RMS before filtering (the model is
        returned in the original units, with its fixed C entries still 1).
    parameter_tolerance, trace_tolerance : float
        Stop early when, from one pass to the next, the largest relative
        parameter change and the relative change of trace(P) are both below these.
    min_passes : int
        Never stop early before this many passes.
    timescale : {"seconds", "auto"}
        Time unit of the filter and of p (module docstring, "Units").
    allow_unstable : bool
        Keep unstable modes (open-loop unstable plants) instead of stopping
        with a DivergenceError; the start is then not reflected into the
        left half-plane either.
    p_decay : float
        Factor on Q from one pass to the next, in (0, 1]; Q never falls below
        :data:`P_DECAY_FLOOR` of p's. 1 (default, the paper's): Q constant.
    back_off : int
        How many times a diverged pass runs again from the last good pass
        with p times :data:`BACK_OFF_FACTOR` (Q, and P afresh from its P0);
        0 (default): the divergence stops the run.
    """

    p: float = 1.0
    passes: int = 50
    discretization: str = "exact"
    covariance: str = "joseph"
    measurement_noise: float | None = None
    start: str = "default"
    normalize: bool = False
    parameter_tolerance: float = 1e-6
    trace_tolerance: float = 1e-4
    min_passes: int = 2
    timescale: str = "seconds"
    allow_unstable: bool = False
    p_decay: float = 1.0
    back_off: int = 0

    @classmethod
    def invariant(cls, **changes: Any) -> "IEKFOptions":
        """Make settings independent of units, scale, sample interval and record length (module docstring).

        Normalised signals, the start from the data, time in samples,
        ``p = INVARIANT_P`` per dominant time constant, shrinking by ``INVARIANT_P_DECAY``
        per pass, R from the data's noise and :data:`INVARIANT_BACK_OFF` restarts after a
        divergence.

        Parameters
        ----------
        **changes
            Fields of :class:`IEKFOptions` that override these settings.

        Returns
        -------
        IEKFOptions
            The settings.
        """
        settings: dict[str, Any] = {"normalize": True, "start": "data", "timescale": "auto", "p": INVARIANT_P,
                                    **invariant_noise_settings()}
        settings.update(changes)
        return cls(**settings)

    def __post_init__(self) -> None:
        check_filter_options(self.p, self.passes, self.discretization, self.covariance)
        if self.measurement_noise is not None and self.measurement_noise != "data" and not (
                isinstance(self.measurement_noise, (int, float)) and math.isfinite(self.measurement_noise)
                and self.measurement_noise > 0):
            raise InputError(f"measurement_noise must be positive or 'data'; got {self.measurement_noise!r}")
        if not (isinstance(self.p_decay, (int, float)) and 0 < self.p_decay <= 1):
            raise InputError(f"p_decay must be in (0, 1]; got {self.p_decay!r}")
        if isinstance(self.back_off, bool) or not isinstance(self.back_off, int) or self.back_off < 0:
            raise InputError(f"back_off must be a whole number >= 0; got {self.back_off!r}")
        check_value("start", self.start, OneOf(START_CHOICES))
        check_value("timescale", self.timescale, OneOf(TIMESCALES))

    @property
    def simulation_method(self) -> str:
        """How the frozen model is simulated to score it "with the filter's discretisation"."""
        return {"euler": "euler", "exact": "foh", "exact-zoh": "zoh"}[self.discretization]


@dataclass(frozen=True, eq=False)
class FilterState:
    """The filter's state between passes, in normalised units: parameters and P (what a resume needs).

    Attributes
    ----------
    theta : ndarray, shape (n_theta,)
        The parameters, normalised.
    P : ndarray, shape (n_theta, n_theta)
        Their covariance in the filter.
    input_scale, output_scale : ndarray, shapes (n_u,) and (n_y,)
        The normalisation of the signals.
    time_unit : float, default 1.0
        The filter's time unit (s): 1 s, or the sample interval with ``timescale="auto"``.
    time_constant : float, default 1.0
        The unit of time in which p is stated (s; module docstring, "Units").
    """

    theta: np.ndarray
    P: np.ndarray
    input_scale: np.ndarray
    output_scale: np.ndarray
    time_unit: float = 1.0
    time_constant: float = 1.0


@dataclass(frozen=True, eq=False)
class IEKFResult(PassHistory):
    """An IEKF identification: the final model, one record per pass, and the filter state.

    Attributes
    ----------
    model : ModalModel
        The final model, in original units.
    structure : ModalStructure
        Its structure.
    options : IEKFOptions
        The settings used.
    history : tuple of PassRecord
        One record per pass.
    state : FilterState
        The filter's state after the last pass (what a resume needs).
    dt : float
        The records' sample interval (s).
    stop_reason : str
        ``"converged"``, ``"passes"`` (the pass limit) or ``"diverged: ..."`` (only
        on the result carried by a DivergenceError).
    seconds : float
        Run time (s).
    meta : dict
        Provenance and the run's notes (scales, start, tuning).
    """

    model: ModalModel
    structure: ModalStructure
    options: IEKFOptions
    history: tuple[PassRecord, ...]
    state: FilterState
    dt: float
    stop_reason: str
    seconds: float
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def fit_percent(self) -> np.ndarray:
        """R per output of the final continuous model simulated exactly."""
        return self.history[-1].fit_continuous


def invariant_noise_settings() -> dict[str, Any]:
    """The fields by which the invariant settings meet noise (module docstring, "Noise")."""
    return {"measurement_noise": "data", "p_decay": INVARIANT_P_DECAY, "back_off": INVARIANT_BACK_OFF}


def data_measurement_noise(records: IOData | tuple[IOData, ...]) -> np.ndarray:
    """The diagonal of R of ``measurement_noise="data"``, in the outputs' units squared.

    In units of each output's power (its mean square over all records): the
    noisiest output's 1, R = I's on normalised signals, so that p keeps the
    meaning the tuning grid gives it; every other output the ratio of its
    relative noise variance (:func:`~vehid.identification.assessment.noise.output_noise_variance`) to the noisiest
    one's, at least :data:`NOISE_WEIGHT_FLOOR`. Noise below :data:`NOISE_FLOOR`
    counts as that floor, so that outputs all free of noise keep R = I.
    """
    records = as_records(records)
    power = np.sum([np.sum(record.y**2, axis=0) for record in records], axis=0) / sum(
        record.n_samples for record in records)
    relative = np.maximum(output_noise_variance(records) / power, NOISE_FLOOR)
    return np.clip(relative / np.max(relative), NOISE_WEIGHT_FLOOR, 1.0) * power


def signal_scales(data: IOData | tuple[IOData, ...], normalize: bool) -> tuple[np.ndarray, np.ndarray]:
    """The RMS of each input and output over all records (ones without ``normalize``): the filter's units."""
    records = as_records(data)
    if not normalize:
        return np.ones(records[0].n_u), np.ones(records[0].n_y)
    samples = sum(record.n_samples for record in records)
    return tuple(np.sqrt(np.sum([np.sum(getattr(record, key) ** 2, axis=0) for record in records], axis=0) / samples)
                 for key in ("u", "y"))


def start_structure(data: IOData | tuple[IOData, ...], structure: ModalStructure,
                    options: IEKFOptions | None = None) -> ModalStructure:
    """The structure of ``structure``'s order whose complex pairs and real poles are the data start's.

    Each subspace candidate of the data start keeps its own eigenvalues; the
    best one's structure is returned. Other starts have no eigenvalues of
    their own: ``structure`` comes back unchanged.
    """
    options = options or IEKFOptions()
    if options.start != "data":
        return structure
    return normalized_data_start(data, structure, normalize=options.normalize, stable=not options.allow_unstable).structure


def normalized_data_start(data: IOData | tuple[IOData, ...], structure: ModalStructure, *, normalize: bool,
                          stable: bool) -> ModalModel:
    """The data start (:func:`~identification.filtering.start.data_start`, modes free) of the first record, in the filter's units.

    Signals divided by :func:`signal_scales` of all records, time in samples.
    """
    input_scale, output_scale = signal_scales(data, normalize)
    first = as_records(data)[0]
    return data_start(first.u / input_scale, first.y / output_scale, structure, method="data", stable=stable,
                      free_modes=True).model


def _settle_states(state, u, y, structure: ModalStructure, run_pass, q, r, dt: float):
    """Run the head of a record with the parameters held, so that its unknown start state settles.

    Over five time constants of the slowest mode (at most a quarter of the
    record) the filter estimates the states alone, from a prior as large as
    the output power; then the parameters' covariance is restored,
    uncorrelated with the settled states.
    """
    n = structure.n
    m = n + structure.n_parameters
    theta = state[n:m]
    slowest = float(np.min(-ModalModel.from_parameters(structure, theta).eigenvalues().real))
    head = min(y.shape[0] // 4, int(np.ceil(5.0 / max(slowest, 1e-9) / dt)))
    if head < 2:
        return state, u, y
    P = unpack_covariance(state[m:], m)
    held = np.zeros_like(P)
    power = np.mean(y**2, axis=0)
    held[np.arange(n), np.arange(n)] = [power[structure.output_of_state(j)] for j in range(n)]
    q_states = q.copy()
    q_states[n:] = 0.0
    settled, _ = run_pass(np.concatenate([state[:m], pack_covariance(held)]), u[:head], y[:head], q_states, r)
    settled = settled.copy()
    settled[n:m] = theta
    P_next = P.copy()
    P_next[:n, :] = 0.0
    P_next[:, :n] = 0.0
    P_next[:n, :n] = unpack_covariance(settled[m:], m)[:n, :n]
    settled[m:] = pack_covariance(P_next)
    return settled, u[head:], y[head:]


@on_one_blas_thread
def identify_iekf(
    data: IOData,
    structure: ModalStructure,
    *,
    options: IEKFOptions | None = None,
    initial_model: ModalModel | None = None,
    resume: IEKFResult | None = None,
    on_pass: Callable[[PassRecord, "IEKFResult"], None] | None = None,
    settle_start: bool | None = None,
    parameter_covariance: bool = True,
    planned_steps: int | None = None,
) -> IEKFResult:
    """Identify a linear modal model with the IEKF.

    Parameters
    ----------
    data : IOData or sequence of IOData
        The record; ``u`` (N, n_u), ``y`` (N, n_y), uniform ``dt``. Several
        records of one ``dt`` identify one model: each pass runs over them in
        turn, each from a zero state, parameters and P carried on, and the
        fits pool all records (:func:`~identification.assessment.multirecord.pooled_percentage_explanation`).
    structure : ModalStructure
        Order, modes and fixed C entries.
    options : IEKFOptions, optional
        Settings; :class:`IEKFOptions`' defaults without them.
    initial_model : ModalModel, optional
        Start from these parameters instead of the named start values.
    resume : IEKFResult, optional
        Continue a previous run on the same data: its parameters, P and
        history are carried on, and ``options.passes`` counts all passes. A
        run whose last two passes already meet the stop rule returns at once,
        converged, as the uninterrupted run would have.
    on_pass : callable, optional
        Called after every pass with the new record and the result so far
        (for progress displays and checkpoints).
    settle_start : bool, optional
        Whether each record's start state is unknown (a record of a campaign,
        or one whose offsets were removed, is not at rest at its start): then
        the head of each record settles the states with the parameters held
        (:func:`_settle_states`). Default: when there are several records.
    parameter_covariance : bool
        Leave the model its parameter covariance
        (:func:`~identification.assessment.uncertainty.iekf_parameter_covariance`, which
        costs one more pass and the fit's sensitivity); False for fits whose
        covariance nobody reads (cross-validation folds).
    planned_steps : int, optional
        The filter steps (samples times passes) the caller will run on this
        structure in all, this run's included: a cross-validation's runs
        together. It chooses the compiled pass's build
        (:func:`~identification.filtering.iekf_pass.compiled_pass`), so that
        runs which together repay a full optimisation share it, and share its
        rounding; by default this run's own steps.

    Returns
    -------
    IEKFResult
        The final model, one record per pass and the filter's state.

    Raises
    ------
    InputError, ExcitationError
        Bad data: wrong sizes, fewer samples than parameters, a constant input.
    DivergenceError
        Non-finite values, a covariance that lost positive definiteness beyond
        repair, or an unstable model; its ``last_good`` is the result up to
        the last good pass.
    """
    options = options or IEKFOptions()
    records = as_records(data)
    data = records[0]
    check_records(records, structure.n_u, structure.n_y, structure.n_parameters)
    settle = len(records) > 1 if settle_start is None else bool(settle_start)
    started = time.perf_counter()
    dt = data.dt
    n = structure.n

    start_meta: dict[str, Any] = {}
    if resume is not None:
        if resume.structure != structure:
            raise InputError("the run to resume has a different model structure")
        if not math.isclose(resume.dt, dt, rel_tol=1e-9):
            raise InputError(f"the run to resume used dt = {resume.dt} s; these data have {dt} s")
        input_scale, output_scale = resume.state.input_scale, resume.state.output_scale
        time_unit, time_constant = resume.state.time_unit, resume.state.time_constant
        theta = resume.state.theta.copy()
        P = resume.state.P.copy()
        history = list(resume.history)
        start_meta = dict(resume.meta)
    else:
        input_scale, output_scale = signal_scales(records, options.normalize)
        time_unit = dt if options.timescale == "auto" else 1.0
        if initial_model is not None:
            if initial_model.structure != structure:
                raise InputError("the initial model has a different structure")
            theta_seconds = structure.normalize_parameters(initial_model.parameters, input_scale, output_scale)
            start_meta = {"start": "given model"}
        elif options.start in DATA_STARTS:
            found = data_start(data.u / input_scale, data.y / output_scale, structure, method=options.start,
                               stable=not options.allow_unstable)
            theta_seconds = structure.rescale_time(found.model.parameters, 1.0 / dt)
            start_meta = {"start": found.source, **({"start_note": found.note} if found.note else {})}
        else:
            sigma, omega, spread = START_VALUES[options.start]
            theta_seconds = structure.initial_parameters(sigma=sigma, omega=omega, omega_spread=spread)
            start_meta = {"start": options.start}
        time_constant = 1.0
        if options.timescale == "auto":
            rates = np.abs(ModalModel.from_parameters(structure, theta_seconds).mode_eigenvalues())
            # the start's dominant time constant, each mode's rate clipped to the band a sampled record
            # shows well (up to a quarter of the Nyquist frequency), so that a spurious fast mode does not set it
            time_constant = float(1.0 / np.median(np.clip(rates, 1e-6 / dt, (np.pi / 4) / dt)))
        theta = structure.rescale_time(theta_seconds, time_unit)
        P = None
        history = []
    start_meta.update(time_unit=time_unit, time_constant=time_constant)

    # Q = p I and P0 = p I on the parameters in time unit time_constant (module docstring), carried to
    # the filter's time unit by the congruence of that change of parameters.
    ratio = time_unit / time_constant
    weights = structure.time_weights(ratio)
    q_first = np.concatenate([np.zeros(n), weights**2 * ratio * options.p])  # Q of pass 1
    # restarts after a divergence so far (module docstring, "Noise"): a run resumed from its result keeps
    # its smaller p; an archive does not store it, and a run resumed from one takes up options.p again
    backed_off = int(start_meta.get("backed_off", 0))
    notes: list[str] = list(start_meta.get("notes", ()))
    q = q_first * BACK_OFF_FACTOR**backed_off

    def shrink(index: int) -> float:
        """The factor on p's Q of pass ``index`` (``p_decay``; restarts aside)."""
        return max(options.p_decay ** (index - 1), P_DECAY_FLOOR) if options.p_decay < 1 else 1.0

    def prepare_pass(index: int) -> None:
        """Q of pass ``index``: shrunk ``index - 1`` times by ``p_decay``, and by every restart."""
        q[:] = q_first * shrink(index) * BACK_OFF_FACTOR**backed_off

    def back_off(theta: np.ndarray, P: np.ndarray, index: int, message: str):
        """The last good pass's theta with P0 of the smaller p, or None where no restart is left.

        P starts afresh rather than from the last good pass's: where Q has
        shrunk over many passes that P is nearly singular, and a divergence
        of the covariance would repeat from it.
        """
        nonlocal backed_off
        if backed_off >= options.back_off:
            return None
        backed_off += 1
        P = np.diag(np.concatenate([np.zeros(n), weights**2 * options.p * BACK_OFF_FACTOR**backed_off]))
        notes.append(f"pass {index} diverged ({message}): run again from "
                     f"{f'pass {index - 1}' if index > 1 else 'the start'} with p = "
                     f"{options.p * BACK_OFF_FACTOR**backed_off:.3g}")
        return theta, P

    if P is None:
        P = np.diag(np.concatenate([np.zeros(n), weights**2 * options.p]))
    if options.measurement_noise == "data":
        r = np.diag(data_measurement_noise(records) / output_scale**2)
    else:
        r = np.eye(structure.n_y) * (1.0 if options.measurement_noise is None else options.measurement_noise)
    start_meta["measurement_noise"] = np.diag(r) * output_scale**2  # R's diagonal in the outputs' units squared
    # unscaled data are passed as they are: a copy of a long record per channel is memory for nothing
    u_scaled = [record.u if np.all(input_scale == 1) else record.u / input_scale for record in records]
    y_scaled = [record.y if np.all(output_scale == 1) else record.y / output_scale for record in records]
    # at most every pass over every record (the settling heads and the covariance's sampled pass aside)
    run_pass = compiled_pass(LinearModalFilterModel(structure), dt / time_unit, options.discretization, options.covariance,
                             expected_steps=max(options.passes * sum(record.n_samples for record in records),
                                                planned_steps or 0))

    def original_units(theta_filter: np.ndarray) -> np.ndarray:
        return structure.denormalize(structure.rescale_time(theta_filter, 1.0 / time_unit), input_scale, output_scale)

    def relative_units(theta_original: np.ndarray) -> np.ndarray:
        """Parameters as the stop rule compares them (absolute settings: original units, as stored runs did)."""
        if options.timescale == "seconds":
            return theta_original
        return structure.rescale_time(structure.normalize_parameters(theta_original, input_scale, output_scale),
                            time_constant)

    if resume is None:
        start_meta["start_parameters"] = original_units(theta)

    def result(stop_reason: str, history: tuple[PassRecord, ...], theta: np.ndarray, P: np.ndarray) -> IEKFResult:
        last = history[-1].parameters if history else original_units(theta)
        covariance, how = None, {}
        if parameter_covariance and history and np.isfinite(history[-1].nis):
            # the fit's sensitivity costs n_u + 1 simulations and the sampled pass one pass: for the
            # finished run, not every checkpoint
            finished = stop_reason != "running"
            covariance, method = iekf_parameter_covariance(
                structure, P[n:, n:], input_scale, output_scale, history[-1].nis / structure.n_y, time_unit=time_unit,
                estimate=ModalModel.from_parameters(structure, last), records=records if finished else None,
                pass_parameters=sampled_pass(theta, P) if finished else None, with_method=True)
            how = {"uncertainty_method": method.as_dict()}
        return IEKFResult(
            model=ModalModel.from_parameters(
                structure, last, input_names=data.input_names, output_names=data.output_names,
                meta={"estimator": "iekf", "discretization": options.discretization, "passes": len(history), **how},
                parameter_covariance=covariance,
            ),
            structure=structure, options=options, history=history,
            state=FilterState(theta.copy(), P.copy(), input_scale.copy(), output_scale.copy(), time_unit, time_constant),
            dt=dt, stop_reason=stop_reason, seconds=time.perf_counter() - started,
            meta={**start_meta, "backed_off": backed_off, "notes": list(notes)},
        )

    def sampled_pass(theta: np.ndarray, P: np.ndarray) -> np.ndarray:
        """The parameters (original units) at :data:`PASS_SAMPLES` even points of one more pass from ``theta``, ``P``.

        The pass runs as :func:`~identification.filtering.rinse.rinse` runs one, in
        pieces; its result feeds only the covariance, which leaves it out
        where it diverged (non-finite) or holds fewer than two points.
        """
        m = n + structure.n_parameters
        state = np.concatenate([np.zeros(n), theta, pack_covariance(P)])
        total = sum(y.shape[0] for y in y_scaled)
        samples = []
        with np.errstate(all="ignore"):
            for k in range(len(records)):
                state[:n] = 0.0
                state, u_k, y_k = prepared_record(state, k)
                pieces = max(1, round(PASS_SAMPLES * y_k.shape[0] / total))
                edges = np.linspace(0, y_k.shape[0], pieces + 1).astype(int)
                for begin, end in zip(edges[:-1], edges[1:]):
                    if end > begin:
                        state, _ = run_pass(state, u_k[begin:end], y_k[begin:end], q, r)
                        samples.append(original_units(state[n:m].copy()))
        return np.array(samples)

    def prepared_record(state: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The state and record ``k`` as a pass takes them: its head spent settling the states where asked."""
        u_k, y_k = u_scaled[k], y_scaled[k]
        if settle:
            return _settle_states(state, u_k, y_k, structure, run_pass, q, r, dt / time_unit)
        return state, u_k, y_k

    def run_record(state: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        return run_pass(*prepared_record(state, k), q, r)

    def assess(theta_filter: np.ndarray, P_filter: np.ndarray) -> Assessment:
        theta_original = original_units(theta_filter)
        model = ModalModel.from_parameters(structure, theta_original)
        if not options.allow_unstable and not model.is_stable():
            raise DivergenceError(
                f"the identified model is unstable (eigenvalues {np.round(model.eigenvalues(), 4).tolist()}; "
                "for an open-loop unstable plant allow unstable modes: 'allow_unstable')", options=("allow_unstable",))
        fit_filter = pooled_simulation_fit(model, records, options.simulation_method)
        fit_exact = fit_filter if options.simulation_method == "foh" else pooled_simulation_fit(model, records)
        return Assessment(theta_original, fit_filter, fit_exact, theta_filter, P_filter)

    def settled(previous: PassRecord, current: PassRecord) -> bool:
        # while Q shrinks, P has no steady state to reach: parameters that no longer move decide alone
        trace_tolerance = options.trace_tolerance if shrink(current.index) == shrink(previous.index) else math.inf
        return parameters_settled(relative_units(previous.parameters), relative_units(current.parameters),
                                  previous.trace_p, current.trace_p, options.parameter_tolerance, trace_tolerance)

    hooks = RinseHooks(records, run_record, lambda: r, assess, settled, result, n,
                       hint="try a lower p, the joseph covariance form, or a lower order",
                       prepare_pass=prepare_pass, back_off=back_off)
    return rinse(hooks, theta, P, tuple(history), passes=options.passes, min_passes=options.min_passes,
                 check_covariance=options.covariance != "paper", on_pass=on_pass)
