"""The rinse: the IEKF's passes over the record, one loop for the linear and the spline filter.

Best & Bogdanski 2017, sections 2-5: each pass starts the true states of every
record at zero and carries the parameters and ``P`` on; after it the model is
frozen and scored. The loop owns what every IEKF does alike (divergence with
the last good result, one :class:`PassRecord` per pass, callback, stop rule);
a filter supplies :class:`RinseHooks`, among them, optionally, a Q that
changes from pass to pass and a smaller p to restart a diverged pass with.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Generic, TypeVar

import numpy as np

from ..choices import COVARIANCE_FORMS, DISCRETIZATIONS
from ..data import IOData, check_channels
from ..errors import DivergenceError, InputError
from ..optionspec import POSITIVE, Number, OneOf, check_value
from .iekf_pass import pack_covariance, unpack_covariance

__all__ = ["PassRecord", "PassHistory", "Assessment", "RinseHooks", "rinse", "check_filter_options",
           "check_records", "parameters_settled"]

ResultT = TypeVar("ResultT")


# the values every IEKF's options share (check_filter_options)
_FILTER_OPTIONS = {"p": POSITIVE, "passes": Number(low=1, whole=True), "discretization": OneOf(DISCRETIZATIONS),
                   "covariance": OneOf(COVARIANCE_FORMS)}


def check_filter_options(p: float, passes: int, discretization: str, covariance: str) -> None:
    """The checks every IEKF's options share: a positive p, a whole number of passes, known forms.

    Raises :class:`~vehid.identification.errors.OptionError` naming the option.
    """
    for name, value in (("p", p), ("passes", passes), ("discretization", discretization), ("covariance", covariance)):
        check_value(name, value, _FILTER_OPTIONS[name])


@dataclass(frozen=True, eq=False)
class PassRecord:
    """What one pass left: parameters, fits, the covariance's state and the innovations' size.

    Attributes
    ----------
    index : int
        The pass, 1-based.
    parameters : ndarray
        The linear filter's in original units, the spline filter's node ordinates
        (normalised, on the ranges after the pass).
    fit_filter : ndarray, shape (n_y,)
        R per output (percent) of the frozen model simulated with the filter's discretisation.
    fit_continuous : ndarray, shape (n_y,)
        R per output of the continuous model simulated exactly (the spline model is
        its discretisation: the same).
    trace_p, min_eig_p : float
        Trace and least eigenvalue of the filter's P after the pass.
    seconds : float
        Run time of the pass (s).
    nis : float
        Mean ``e' R^-1 e`` over the pass (n_y where innovations are as large as
        assumed; NaN if unknown).
    """

    index: int
    parameters: np.ndarray
    fit_filter: np.ndarray
    fit_continuous: np.ndarray
    trace_p: float
    min_eig_p: float
    seconds: float
    nis: float = float("nan")

    @property
    def mean_fit_filter(self) -> float:
        """The mean over outputs of :attr:`fit_filter`."""
        return float(np.mean(self.fit_filter))

    @property
    def mean_fit_continuous(self) -> float:
        """The mean over outputs of :attr:`fit_continuous`."""
        return float(np.mean(self.fit_continuous))


class PassHistory:
    """What every IEKF result offers on its ``history`` of passes."""

    history: tuple[PassRecord, ...]

    @property
    def passes_run(self) -> int:
        return len(self.history)


@dataclass(frozen=True, eq=False)
class Assessment:
    """A filter's verdict on a pass: the record's parameters and fits, and the theta and P the next pass starts from."""

    parameters: np.ndarray
    fit_filter: np.ndarray
    fit_continuous: np.ndarray
    theta: np.ndarray
    P: np.ndarray


@dataclass(frozen=True, eq=False)
class RinseHooks(Generic[ResultT]):
    """What a filter supplies to :func:`rinse`; ``label`` names its passes and ``hint`` the cure for non-finite values."""

    records: tuple[IOData, ...]  # what a pass runs over, in turn (times and names for messages)
    # (state [x; theta; upper(P)], k) -> (state, innovations (N_k, n_y) of record k's last N_k samples)
    run_record: Callable[[np.ndarray, int], tuple[np.ndarray, np.ndarray]]
    measurement_covariance: Callable[[], np.ndarray]  # R of the coming pass
    assess: Callable[[np.ndarray, np.ndarray], Assessment]  # may refuse the model: DivergenceError
    settled: Callable[[PassRecord, PassRecord], bool]  # the stop rule on the last two passes
    result: Callable[[str, tuple[PassRecord, ...], np.ndarray, np.ndarray], ResultT]  # (stop reason, history, theta, P)
    n_states: int  # true states, reset to zero at the start of each record
    label: str = "pass"
    hint: str = "try a lower p"
    # called with a pass's index before it runs: a filter whose Q changes from pass to pass sets it here
    prepare_pass: Callable[[int], None] | None = None
    # after a divergence, (theta, P, pass index, message) of the last good pass -> the theta and P to restart
    # from with a smaller p, or None where no smaller p is left (the divergence then stands)
    back_off: Callable[[np.ndarray, np.ndarray, int, str], tuple[np.ndarray, np.ndarray] | None] | None = None


def check_records(records: tuple[IOData, ...], n_u: int, n_y: int, n_parameters: int, model: str = "the structure") -> None:
    """Refuse records a filter cannot identify from: other sizes than ``model``'s, too few samples, nothing excited."""
    data = records[0]
    if data.n_u != n_u or data.n_y != n_y:
        raise InputError(f"{model} has {n_u} inputs and {n_y} outputs; the data have {data.n_u} and {data.n_y}")
    samples = sum(record.n_samples for record in records)
    if samples <= n_parameters:
        raise InputError(f"{samples} samples cannot identify {n_parameters} parameters: give more data or a lower order")
    check_channels(records, detrend="none")  # the records' offsets are already removed, or are part of the data


def parameters_settled(previous: np.ndarray, current: np.ndarray, previous_trace: float, current_trace: float,
                       parameter_tolerance: float, trace_tolerance: float) -> bool:
    """Parameter change relative to each parameter (floor 1e-3 in the compared units) and trace(P)'s relative change."""
    scale = np.maximum(np.abs(current), 1e-3)
    parameter_change = float(np.max(np.abs(current - previous) / scale))
    trace_change = abs(current_trace - previous_trace) / max(abs(previous_trace), 1e-300)
    return parameter_change < parameter_tolerance and trace_change < trace_tolerance


def rinse(hooks: RinseHooks[ResultT], theta: np.ndarray, P: np.ndarray, history: tuple[PassRecord, ...] = (), *,
          passes: int, min_passes: int, check_covariance: bool = True,
          on_pass: Callable[[PassRecord, ResultT], None] | None = None) -> ResultT:
    """Pass over the records until ``hooks.settled`` or ``passes`` passes are on record.

    ``theta`` and ``P`` (the filter's units) start the next pass; ``history``
    holds passes already run (a resumed run, counted in ``passes``; one whose
    last two passes are settled returns at once). ``check_covariance`` stops
    when P loses positive definiteness (off for the paper's form, which may
    lose it); ``on_pass`` is called after every pass with its record and the
    result so far. Returns the hooks' result, stopped ``"converged"`` or
    ``"passes"``; raises DivergenceError named by the pass, its ``last_good``
    the result up to the last good pass (None before the first).
    """
    history = list(history)
    n = hooks.n_states
    m = n + theta.size

    def one_pass(index: int) -> tuple[PassRecord, np.ndarray, np.ndarray]:
        """A pass from (theta, P): its record, and the theta and P the next pass starts from."""
        pass_start = time.perf_counter()
        r = hooks.measurement_covariance()
        state = np.concatenate([np.zeros(n), theta, pack_covariance(P)])
        nis_sum, nis_count = 0.0, 0
        for k, experiment in enumerate(hooks.records):
            state[:n] = 0.0  # each record starts from its own rest state; parameters and P carry on
            state, innovations = hooks.run_record(state, k)
            if not (np.all(np.isfinite(state)) and np.all(np.isfinite(innovations))):
                bad = np.flatnonzero(~np.all(np.isfinite(innovations), axis=1))
                head = experiment.n_samples - innovations.shape[0]  # samples the filter used before its innovations
                where = f" from t = {experiment.t[head + bad[0]]:.3f} s" if bad.size else ""
                if len(hooks.records) > 1:
                    where += f" of record {experiment.meta.get('source', k + 1)}"
                raise DivergenceError(f"the filter produced non-finite values{where} ({hooks.hint})")
            nis_sum += float(np.sum(innovations * np.linalg.solve(r, innovations.T).T))
            nis_count += innovations.shape[0]
            del innovations  # (N, n_y): not kept while the model is scored
        filtered_theta, filtered_P = state[n:m], unpack_covariance(state[m:], m)
        min_eig = float(np.linalg.eigvalsh(filtered_P)[0])
        trace = float(np.trace(filtered_P))
        if check_covariance and min_eig < -1e-9 * max(trace, 1.0):
            raise DivergenceError(f"the covariance P lost positive definiteness (smallest eigenvalue {min_eig:.3g}, "
                                  f"trace {trace:.3g})")
        assessment = hooks.assess(filtered_theta, filtered_P)
        if assessment.P is not filtered_P:  # the filter moved P (a change of parameters)
            min_eig, trace = float(np.linalg.eigvalsh(assessment.P)[0]), float(np.trace(assessment.P))
        record = PassRecord(
            index=index, parameters=assessment.parameters, fit_filter=assessment.fit_filter,
            fit_continuous=assessment.fit_continuous, trace_p=trace, min_eig_p=min_eig,
            seconds=time.perf_counter() - pass_start, nis=nis_sum / max(nis_count, 1),
        )
        return record, assessment.theta, assessment.P

    if len(history) >= max(2, min_passes) and hooks.settled(history[-2], history[-1]):
        return hooks.result("converged", tuple(history), theta, P)  # a resumed run had met its stop rule
    stop_reason = "passes"
    while len(history) < passes:
        index = len(history) + 1
        if hooks.prepare_pass is not None:
            hooks.prepare_pass(index)
        try:
            record, theta, P = one_pass(index)
        except DivergenceError as exc:
            restart = hooks.back_off(theta, P, index, str(exc)) if hooks.back_off is not None else None
            if restart is not None:
                theta, P = restart  # the pass runs again from the last good one, with the smaller p
                continue
            last_good = hooks.result(f"diverged at pass {index}", tuple(history), theta, P) if history else None
            raise DivergenceError(f"{hooks.label} {index}: {exc}", last_good=last_good) from exc
        previous = history[-1] if history else None
        history.append(record)
        if on_pass is not None:
            on_pass(record, hooks.result("running", tuple(history), theta, P))
        if previous is not None and len(history) >= min_passes and hooks.settled(previous, record):
            stop_reason = "converged"
            break
    return hooks.result(stop_reason, tuple(history), theta, P)
