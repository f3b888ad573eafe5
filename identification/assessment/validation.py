"""Scoring a model on estimation and held-out data: simulation, initial state, k-step prediction.

Each function takes a model and an :class:`~identification.data.IOData` record, so that any preparation
of the record happens before and outside. :func:`estimate_initial_state` explains a record that starts
mid-motion (``y = y_forced + O x0`` is linear in ``x0``; for a model that is not linear time-invariant, a
scheduled family or a spline model, by Gauss-Newton on ``x0``); :func:`predict` with a horizon ``K`` (from a
steady-state Kalman filter's state) is the score that means something for a model whose simulation
diverges; :func:`score` gives NRMSE fit and the paper's R (eq. 17) per output; :func:`split_holdout`
holds out the last fraction of a record.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..data import IOData
from ..choices import INITIAL_STATES
from ..errors import InputError
from ..frozen import freeze
from .metrics import nrmse_fit, percentage_explanation
from ..models.statespace import continuous_to_discrete, hold_state_shift

__all__ = [
    "INITIAL_STATES",
    "Scores",
    "estimate_initial_state",
    "predict",
    "score",
    "predicted_scores",
    "iterated_initial_state",
    "split_holdout",
    "default_horizon",
    "UNSTABLE_HORIZON",
]


# Steady-state Kalman filter of the k-step predictor, in outputs divided by their RMS:
# process noise this fraction of the input-driven state variance per sample, unit measurement noise.
_PREDICTOR_PROCESS_NOISE = 1e-2
UNSTABLE_HORIZON = 10  # samples, when a model's simulation diverges and no horizon is given
_UNSTABLE_WINDOW = 50  # samples over which an unstable model's initial state is fitted


@dataclass(frozen=True)
class Scores:
    """Per-output scores of a model on one record.

    Attributes
    ----------
    fit : ndarray
        NRMSE fit, percent (``-inf`` where the prediction is not finite).
    R : ndarray
        Percentage explanation (eq. 17), percent.
    initial_state : str
        ``"zero"`` or ``"estimate"``.
    horizon : int or None
        ``K`` of a k-step-ahead prediction, None for a simulation.
    n_samples : int
    """

    fit: np.ndarray
    R: np.ndarray
    initial_state: str
    horizon: int | None
    n_samples: int

    def __post_init__(self) -> None:
        for name in ("fit", "R"):  # a score stays as measured
            object.__setattr__(self, name, freeze(np.asarray(getattr(self, name), dtype=float)))

    @property
    def mean_fit(self) -> float:
        return float(np.mean(self.fit))

    @property
    def mean_R(self) -> float:
        return float(np.mean(self.R))

    def as_dict(self) -> dict[str, Any]:
        return {"fit_percent": self.fit, "R": self.R, "initial_state": self.initial_state,
                "horizon": self.horizon, "n_samples": self.n_samples}


def _check(model: Any, data: IOData) -> None:
    if not isinstance(data, IOData):
        raise InputError("scores need an IOData record")
    # a scheduled model's record holds its schedule as a last input column
    columns = getattr(model, "record_inputs", model.n_u)
    if (data.n_u, data.n_y) != (columns, model.n_y):
        raise InputError(f"the model takes {columns} input columns and has {model.n_y} outputs; "
                         f"the record has {data.n_u} and {data.n_y}")


def estimate_initial_state(model: Any, data: IOData) -> np.ndarray:
    """The initial state ``x0`` (n,) that fits the record best, by least squares on the outputs.

    Each output is weighted by the inverse of its RMS so that units do not
    matter. For a linear model (``is_linear``) the outputs are linear in
    ``x0``: the regressors are the free responses of its states (one
    simulation from each unit state with zero input). A model that is not
    linear time-invariant (a scheduled family, linear along its schedule;
    a spline model) is fitted by Gauss-Newton on ``x0`` from rest
    (:func:`iterated_initial_state`), which for a family linear in its state
    lands on the least-squares state at its first step. ``model`` is any
    :class:`~identification.models.protocol.IdentifiedModel`.
    """
    _check(model, data)
    if not model.is_linear:
        return iterated_initial_state(model, data)
    n = model.n_states
    weights = _output_weights(data)
    window = _free_response_samples(model, data)
    u, y = data.u[:window], data.y[:window]
    with np.errstate(all="ignore"):
        forced = model.simulate_outputs(u, data.dt)
        zero = np.zeros_like(u)
        free = np.column_stack([
            (model.simulate_outputs(zero, data.dt, x0=np.eye(n)[i]) * weights).ravel() for i in range(n)
        ])
    target = ((y - forced) * weights).ravel()
    if not (np.all(np.isfinite(free)) and np.all(np.isfinite(target))):
        return np.zeros(n)
    return np.linalg.lstsq(free, target, rcond=None)[0]


def _output_weights(data: IOData) -> np.ndarray:
    return 1.0 / np.maximum(np.sqrt(np.mean(data.y**2, axis=0)), 1e-300)


#: Gauss-Newton steps of :func:`iterated_initial_state` at most: a model linear in its state needs one (the
#: second finds nothing to gain); a spline model's mild nonlinearity a few more
GAUSS_NEWTON_STEPS = 8
#: finite-difference step of each state, as a fraction of that state's RMS in the forced simulation
_STATE_STEP = 1e-3
#: relative fall of the weighted squared error below which the iteration stops
_SETTLED_COST = 1e-10


def iterated_initial_state(model: Any, data: IOData, *, steps: int = GAUSS_NEWTON_STEPS) -> np.ndarray:
    """``x0`` (n,) of any model whose simulation starts from a given state, by Gauss-Newton from rest.

    The residual is the RMS-weighted output error over the record; its
    Jacobian in ``x0`` is taken by forward differences, each state stepped
    by :data:`_STATE_STEP` of its RMS in the simulation from rest. A step is
    kept only where it lowers the error (halved up to three times
    otherwise), so the state returned never fits worse than rest, which it
    stays at where no step helps or a simulation is not finite.
    """
    n = model.n_states
    weights = _output_weights(data)

    def residual(x0: np.ndarray) -> np.ndarray:
        with np.errstate(all="ignore"):
            return ((data.y - model.simulate_outputs(data.u, data.dt, x0=x0)) * weights).ravel()

    x = np.zeros(n)
    with np.errstate(all="ignore"):
        _, states = model.simulate_outputs(data.u, data.dt, x0=x, return_states=True)
    scale = np.sqrt(np.mean(np.asarray(states, dtype=float) ** 2, axis=0))
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    r = residual(x)
    cost = float(r @ r)
    if not np.isfinite(cost):
        return x
    for _ in range(steps):
        delta = _STATE_STEP * np.maximum(scale, np.abs(x))
        jacobian = np.column_stack([(residual(x + delta[i] * np.eye(n)[i]) - r) / delta[i] for i in range(n)])
        if not np.all(np.isfinite(jacobian)):
            break
        step = -np.linalg.lstsq(jacobian, r, rcond=None)[0]
        for _ in range(4):
            trial = residual(x + step)
            trial_cost = float(trial @ trial)
            if np.isfinite(trial_cost) and trial_cost < cost:
                break
            step = step / 2
        else:
            break
        settled = cost - trial_cost <= _SETTLED_COST * cost
        x, r, cost = x + step, trial, trial_cost
        if settled:
            break
    return x


_FREE_RESPONSE_TIME_CONSTANTS = 10  # e^-10: beyond this the initial state's response is below rounding of the fit


def _free_response_samples(model: Any, data: IOData) -> int:
    """The samples over which the initial state still shows: ten time constants of the slowest stable mode.

    Past them the free responses are below 5e-5 of their start, so the least-squares fit over the
    rest of a long record would only cost memory (an (N n_y, n) regressor). An unstable or
    undamped model keeps the whole record.
    """
    if model.to_statespace()[4] is not None:  # discrete: eigenvalues in the z-plane
        values = np.asarray(model.eigenvalues())
        largest = float(np.max(np.abs(values))) if values.size else 0.0
        if largest >= 1.0:
            return data.n_samples
        samples = _FREE_RESPONSE_TIME_CONSTANTS / max(-np.log(max(largest, 1e-300)), 1e-300)
    else:
        rates = -np.real(model.eigenvalues())
        if rates.size == 0 or np.min(rates) <= 0:
            return data.n_samples
        samples = _FREE_RESPONSE_TIME_CONSTANTS / np.min(rates) / data.dt
    return int(min(data.n_samples, max(np.ceil(samples), 1000)))


def default_horizon(model: Any) -> int | None:
    """None for a stable model (simulate); for an unstable one a short k-step-ahead horizon."""
    if model.is_linear and not model.is_stable():
        return UNSTABLE_HORIZON
    return None


def _k_step(model: Any, data: IOData, horizon: int) -> np.ndarray:
    """Outputs predicted ``horizon`` samples ahead of a steady-state Kalman filter's state; the first ``horizon`` from rest."""
    import scipy.linalg  # half a second to import: paid by a prediction, not at every command's start

    A, B, C, D, model_dt = model.to_statespace()
    continuous = model_dt is None
    Ad, Bd, Cd, Dd = continuous_to_discrete(A, B, C, D, data.dt, hold="foh") if continuous else (A, B, C, D)
    scale = np.maximum(np.sqrt(np.mean(data.y**2, axis=0)), 1e-300)
    Cn, Dn = Cd / scale[:, None], Dd / scale[:, None]
    yn = data.y / scale
    n = Ad.shape[0]
    # the state variance the record's own input drives: each input column at its RMS, so that the predictor,
    # and with it the score, does not depend on the units the input is given in
    input_rms = np.sqrt(np.mean(data.u**2, axis=0)) if data.u.size else np.zeros(Bd.shape[1])
    Bu = Bd * input_rms[None, :]
    driven = scipy.linalg.solve_discrete_lyapunov(Ad * min(1.0, 0.99 / max(np.abs(np.linalg.eigvals(Ad)).max(), 1e-12)),
                                                  Bu @ Bu.T) if n else np.zeros((0, 0))
    Q = _PREDICTOR_PROCESS_NOISE * (driven + 1e-9 * np.trace(driven) * np.eye(n) / max(n, 1))
    R = np.eye(Cn.shape[0])
    try:
        S = scipy.linalg.solve_discrete_are(Ad.T, Cn.T, Q, R)
        gain = Ad @ S @ Cn.T @ np.linalg.inv(Cn @ S @ Cn.T + R)
    except (np.linalg.LinAlgError, ValueError):
        gain = np.zeros((n, Cn.shape[0]))
    u = data.u
    N = u.shape[0]
    states = np.zeros((N, n))
    x = np.zeros(n)
    # Start the observer at the least-squares initial state (foh state xi = x - G2 u): from the whole
    # record for a stable model, from its first samples for an unstable one (whose free responses grow).
    window = data if model.is_stable() else data[: min(N, max(_UNSTABLE_WINDOW, 10 * n))]
    if window.n_samples > n:
        x = estimate_initial_state(model, window)
        if continuous:
            x = x - hold_state_shift(A, B, data.dt) @ u[0]
    observer = Ad - gain @ Cn
    drive = u @ (Bd - gain @ Dn).T + yn @ gain.T
    for k in range(N):  # the one-step predictor's state x(k|k-1)
        states[k] = x
        x = observer @ x + drive[k]
    ahead = states[: N - horizon].copy() if horizon < N else np.zeros((0, n))
    for j in range(min(horizon, N)):
        ahead = ahead @ Ad.T + u[j: j + ahead.shape[0]] @ Bd.T
    predicted = np.empty_like(data.y)
    with np.errstate(all="ignore"):
        predicted[:horizon] = model.simulate_outputs(u[:horizon], data.dt)
        if horizon < N:
            predicted[horizon:] = ahead @ Cd.T + u[horizon:] @ Dd.T
    return predicted


def predict(model: Any, data: IOData, *, initial_state: str = "estimate", horizon: int | None = None) -> np.ndarray:
    """The model's outputs on the record: simulated (from the initial state asked for) or ``horizon`` steps ahead.

    Parameters
    ----------
    model : IdentifiedModel
        A scheduled family (``is_linear`` False) is simulated along the record's last input column,
        its schedule.
    data : IOData
    initial_state : {"zero", "estimate"}
        ``estimate`` by :func:`estimate_initial_state`, for every model.
    horizon : int, optional
        Predict this many samples ahead (linear models only) instead of simulating; a model that is
        not linear is simulated whatever the horizon.
    """
    _check(model, data)
    if initial_state not in INITIAL_STATES:
        raise InputError(f"unknown initial state {initial_state!r}; use one of {', '.join(INITIAL_STATES)}")
    if horizon is not None and model.is_linear:
        if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1:
            raise InputError(f"the prediction horizon must be a whole number of samples >= 1; got {horizon!r}")
        return _k_step(model, data, int(horizon))
    x0 = estimate_initial_state(model, data) if initial_state == "estimate" else None
    with np.errstate(all="ignore"):
        return model.simulate_outputs(data.u, data.dt, x0=x0)


def score(model: Any, data: IOData, *, initial_state: str = "estimate", horizon: int | None = None) -> Scores:
    """NRMSE fit and R per output of :func:`predict` against the record (``-inf`` where not finite)."""
    return predicted_scores(model, data, initial_state=initial_state, horizon=horizon)[1]


def predicted_scores(model: Any, data: IOData, *, initial_state: str = "estimate", horizon: int | None = None
                     ) -> tuple[np.ndarray, Scores]:
    """:func:`predict`'s outputs (N, n_y) and their :func:`score`, from one prediction (for a caller drawing it)."""
    predicted = predict(model, data, initial_state=initial_state, horizon=horizon)
    start = 0 if horizon is None else min(int(horizon), data.n_samples - 2)
    y, y_hat = data.y[start:], predicted[start:]
    with np.errstate(all="ignore"):
        if np.all(np.isfinite(y_hat)) and np.max(np.abs(y_hat)) < 1e150:
            fit, R = nrmse_fit(y, y_hat), percentage_explanation(y, y_hat)
        else:
            fit = R = np.full(data.n_y, -np.inf)
    return predicted, Scores(fit, R, initial_state if horizon is None or not model.is_linear else "zero",
                             horizon, int(y.shape[0]))


def split_holdout(data: IOData, fraction: float) -> tuple[IOData, IOData]:
    """The record without its last ``fraction`` and that last part (held out for validation)."""
    if not (isinstance(fraction, (int, float)) and 0.0 < fraction < 1.0):
        raise InputError(f"the validation fraction must lie strictly between 0 and 1; got {fraction!r}")
    estimation, validation = data.split(1.0 - fraction)
    if min(estimation.n_samples, validation.n_samples) < 10:
        raise InputError(f"holding out {fraction:g} of {data.n_samples} samples leaves too few on one side")
    return estimation, validation
