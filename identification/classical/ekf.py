"""Extended Kalman filter for joint state and parameter estimation (seed appendix A.4.1).

The user gives a discrete-time nonlinear model as CasADi SX expressions
(appendix eq. A.93, A.98)::

    x(k+1) = f(x(k), u(k), p) + w(k),   y(k) = h(x(k), u(k), p) + v(k)

(:meth:`NonlinearModel.from_continuous` builds ``f`` from ``xdot`` by
Runge-Kutta steps with the input held). The unknown parameters ``p`` join
the state as constants, ``p(k+1) = p(k)`` (eq. A.99-A.100), and the EKF
(eq. A.94-A.97) runs on ``z = [x; p]`` with the exact Jacobians
``F = d[f; p]/dz`` and ``H = dh/dz`` from ``casadi.jacobian``::

    z(k|k-1) = [f(x(k-1|k-1), u(k-1), p); p]
    P(k|k-1) = F P(k-1|k-1) F' + Q
    K(k)     = P(k|k-1) H' (H P(k|k-1) H' + R)^-1
    z(k|k)   = z(k|k-1) + K(k) (y(k) - h(z(k|k-1), u(k)))
    P(k|k)   = (I - K H) P (I - K H)' + K R K'      (Joseph form)

One step is a named CasADi function; runs of :data:`CHUNK` steps are lifted
with ``mapaccum`` and, optionally, compiled to C by
:func:`vehid.identification.compiled.compile_function`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import casadi as ca
import numpy as np

from ..argument_checks import finite_matrix, io_arrays
from ..compiled import compile_function
from ..errors import DivergenceError, InputError

__all__ = ["NonlinearModel", "EkfResult", "ekf_joint", "CHUNK"]

CHUNK = 256  # steps per lifted CasADi call


@dataclass(frozen=True, eq=False)
class NonlinearModel:
    """A discrete-time model ``x(k+1) = f(x, u, p)``, ``y = h(x, u, p)`` in CasADi SX.

    Attributes
    ----------
    x, u, p : casadi.SX
        Column symbols of the states (n_states), inputs (n_u) and parameters (n_p).
    x_next, y : casadi.SX
        ``f(x, u, p)`` (n_states) and ``h(x, u, p)`` (n_y).
    name : str
        Names the generated functions.
    """

    x: ca.SX
    u: ca.SX
    p: ca.SX
    x_next: ca.SX
    y: ca.SX
    name: str = "model"

    def __post_init__(self) -> None:
        for attribute in ("x", "u", "p", "x_next", "y"):
            value = getattr(self, attribute)
            if not isinstance(value, ca.SX) or value.size2() != 1:
                raise InputError(f"{attribute} must be a CasADi SX column; got {type(value).__name__}")
        for attribute in ("x", "u", "p"):
            if not getattr(self, attribute).is_valid_input():
                raise InputError(f"{attribute} must be made of pure symbols (casadi.SX.sym)")
        if self.x_next.size1() != self.x.size1():
            raise InputError(f"x_next has {self.x_next.size1()} entries but x has {self.x.size1()}")
        free = set(ca.symvar(ca.vertcat(self.x_next, self.y)))
        known = {str(s) for s in ca.symvar(ca.vertcat(self.x, self.u, self.p))}
        unknown = sorted(str(s) for s in free if str(s) not in known)
        if unknown:
            raise InputError(f"the model uses symbols that are not states, inputs or parameters: {', '.join(unknown)}")

    @property
    def n_states(self) -> int:
        """Number of states."""
        return int(self.x.size1())

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return int(self.u.size1())

    @property
    def n_p(self) -> int:
        """Number of parameters."""
        return int(self.p.size1())

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.y.size1())

    @classmethod
    def from_continuous(cls, x: ca.SX, u: ca.SX, p: ca.SX, xdot: ca.SX, y: ca.SX, dt: float, *,
                        steps: int = 1, name: str = "model") -> "NonlinearModel":
        """Discretise ``xdot = f(x, u, p)`` by ``steps`` classical Runge-Kutta steps over ``dt``, u held.

        Parameters
        ----------
        x, u, p : casadi.SX
            Column symbols of the states, inputs and parameters.
        xdot : casadi.SX
            The state derivative, an expression of them.
        y : casadi.SX
            The outputs, an expression of them.
        dt : float
            Sample interval (s).
        steps : int, default 1
            Runge-Kutta steps per sample.
        name : str, default "model"
            Prefix of the CasADi Functions' names.

        Returns
        -------
        NonlinearModel
            The discrete transition and output Functions.
        """
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be positive; got {dt}")
        if steps < 1:
            raise InputError(f"steps must be >= 1; got {steps}")
        rate = ca.Function(f"{name}_rate", [x, u, p], [xdot])
        h = dt / steps
        state = x
        for _ in range(steps):
            k1 = rate(state, u, p)
            k2 = rate(state + h / 2 * k1, u, p)
            k3 = rate(state + h / 2 * k2, u, p)
            k4 = rate(state + h * k3, u, p)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return cls(x, u, p, state, y, name)


@dataclass(frozen=True, eq=False)
class EkfResult:
    """A joint EKF run.

    Attributes
    ----------
    states : ndarray, shape (N, n_states)
        ``x(k|k)``.
    parameters : ndarray, shape (N, n_p)
        ``p(k|k)``.
    covariance : ndarray, shape (n_states + n_p, n_states + n_p)
        Final ``P(k|k)``.
    innovations : ndarray, shape (N, n_y)
        ``y(k) - h(z(k|k-1))``.
    trace : ndarray, shape (N,)
        trace P(k|k).
    meta : dict
        ``method`` and ``compiled``; on a divergence, ``diverged_at`` (the sample).
    """

    states: np.ndarray
    parameters: np.ndarray
    covariance: np.ndarray
    innovations: np.ndarray
    trace: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def parameter_std(self) -> np.ndarray:
        """Final standard deviations of the parameters."""
        n_p = self.parameters.shape[1]
        return np.sqrt(np.diag(self.covariance)[-n_p:])


def _step_function(model: NonlinearModel) -> ca.Function:
    z = ca.vertcat(model.x, model.p)
    m = z.size1()
    P = ca.SX.sym("P", m, m)
    u_prev = ca.SX.sym("u_prev", model.n_u)
    u_now = ca.SX.sym("u_now", model.n_u)
    y = ca.SX.sym("y", model.n_y)
    Q = ca.SX.sym("Q", m, m)
    R = ca.SX.sym("R", model.n_y, model.n_y)
    f = ca.vertcat(model.x_next, model.p)
    f_prev = ca.substitute(f, model.u, u_prev)
    F = ca.substitute(ca.jacobian(f, z), model.u, u_prev)
    z_prior = f_prev
    P_prior = F @ P @ F.T + Q
    h = ca.substitute(model.y, ca.vertcat(model.x, model.p, model.u), ca.vertcat(z_prior, u_now))
    H = ca.substitute(ca.jacobian(model.y, z), ca.vertcat(model.x, model.p, model.u), ca.vertcat(z_prior, u_now))
    PH = P_prior @ H.T
    S = H @ PH + R
    S = 0.5 * (S + S.T)
    K = ca.solve(S, PH.T).T
    innovation = y - h
    z_post = z_prior + K @ innovation
    factor = ca.SX.eye(m) - K @ H
    P_post = factor @ P_prior @ factor.T + K @ R @ K.T
    P_post = 0.5 * (P_post + P_post.T)
    return ca.Function(
        f"{model.name}_ekf_step",
        [z, P, u_prev, u_now, y, Q, R],
        [z_post, P_post, innovation],
        ["z", "P", "u_prev", "u", "y", "Q", "R"],
        ["z_post", "P_post", "innovation"],
    )


def _square(name: str, value: Any, size: int) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 1:
        array = np.diag(array)
    array = finite_matrix(name, array)
    if array.shape != (size, size):
        raise InputError(f"{name} must be ({size}, {size}) or a diagonal of {size} entries; got {np.shape(value)}")
    return array


def ekf_joint(model: NonlinearModel, data_or_arrays: Any, *, x0: Sequence[float], p0: Sequence[float],
              P0: Any, Q: Any, R: Any, compiled: bool = False) -> EkfResult:
    """Estimate the states and parameters of ``model`` from a record by an EKF on ``z = [x; p]``.

    Parameters
    ----------
    model : NonlinearModel
        The discrete model, its parameters among its inputs.
    data_or_arrays : IOData or (u, y)
        Inputs (N, n_u) and measured outputs (N, n_y); row k is sample k.
    x0, p0 : sequence of float
        Initial state and parameter guesses ``z(0|0)``; the first update
        uses ``y`` at row 0 after one prediction from row -1 with ``u(-1) = u(0)``.
    P0, Q : array_like
        Initial covariance and process noise of z, ``(m, m)`` or a diagonal of
        m = n_states + n_p entries. A zero parameter block in Q keeps the
        parameters constant; a small one lets them drift.
    R : array_like
        Measurement noise, ``(n_y, n_y)`` or a diagonal.
    compiled : bool
        Compile the lifted step to C (worth it for long records).

    Returns
    -------
    EkfResult
        Filtered states and parameters at every sample, and the final covariance.

    Raises
    ------
    InputError
        Wrong sizes or non-finite data.
    DivergenceError
        A non-finite state or covariance; ``last_good`` holds the result so far.
    """
    u, y, _ = io_arrays(data_or_arrays)
    if u.shape[1] != model.n_u or y.shape[1] != model.n_y:
        raise InputError(f"the model has {model.n_u} inputs and {model.n_y} outputs; the data "
                         f"{u.shape[1]} and {y.shape[1]}")
    m = model.n_states + model.n_p
    z = np.concatenate([finite_matrix("x0", np.ravel(x0), ndim=1), finite_matrix("p0", np.ravel(p0), ndim=1)])
    if z.size != m:
        raise InputError(f"x0 and p0 must hold {model.n_states} and {model.n_p} values")
    P = _square("P0", P0, m)
    Qm = _square("Q", Q, m)
    Rm = _square("R", R, model.n_y)
    step = _step_function(model)
    chunk = step.mapaccum(f"{model.name}_ekf_chunk", CHUNK, [0, 1], [0, 1])
    if compiled:
        chunk = compile_function(chunk)
    samples = y.shape[0]
    u_prev = np.vstack([u[:1], u[:-1]])
    states = np.zeros((samples, m))
    innovations = np.zeros((samples, model.n_y))
    trace = np.zeros(samples)
    q_tiled = np.tile(Qm, (1, CHUNK))
    r_tiled = np.tile(Rm, (1, CHUNK))
    start = 0
    while start < samples:
        stop = min(start + CHUNK, samples)
        if stop - start == CHUNK:
            zs, Ps, innov = chunk(z, P, u_prev[start:stop].T, u[start:stop].T, y[start:stop].T, q_tiled, r_tiled)
            zs, Ps, innov = np.array(zs), np.array(Ps), np.array(innov)
            states[start:stop] = zs.T
            innovations[start:stop] = innov.T
            blocks = Ps.reshape(m, CHUNK, m)
            trace[start:stop] = np.einsum("iki->k", blocks)
            z, P = zs[:, -1], blocks[:, -1, :]
        else:
            for k in range(start, stop):
                z_k, P_k, innov = step(z, P, u_prev[k], u[k], y[k], Qm, Rm)
                z, P = np.array(z_k).ravel(), np.array(P_k)
                states[k], innovations[k], trace[k] = z, np.array(innov).ravel(), np.trace(P)
        if not (np.all(np.isfinite(states[start:stop])) and np.all(np.isfinite(P))):
            partial = EkfResult(states[:start, : model.n_states], states[:start, model.n_states:], P, innovations[:start],
                                trace[:start], {"diverged_at": start})
            raise DivergenceError(f"the EKF diverged between samples {start} and {stop}", last_good=partial)
        start = stop
    return EkfResult(states[:, : model.n_states], states[:, model.n_states:], P, innovations, trace,
                     {"method": "extended Kalman filter", "compiled": compiled})
