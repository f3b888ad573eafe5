"""Singular pencil (SP) models and their joint state and parameter estimation (seed appendix A.4.2).

An SP model (Aplevich 1981, 1991) relates an internal variable ``x (n)`` and the external variables
``w = [u; y]`` by ``E x(k+1) = F x(k) + G w(k)`` (eq. A.101); state space and ARX are special cases
(eq. A.102-A.105). In the ARX observer form the parameters ``gamma`` multiply measured signals only, so
state and parameters evolve linearly with known time-varying matrices (eq. A.106-A.109) and an
ordinary Kalman filter on ``z = [x; gamma]`` estimates both, with no linearisation. The noise entering
both equations is decorrelated by substituting ``e(k) = y(k) - H(k) z(k)`` (Anderson & Moore 1979,
sec. 5.5).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from ..argument_checks import finite_matrix, io_arrays, non_negative_int, per_input
from ..errors import InputError
from .kalman import KalmanResult, kalman_filter
from .least_squares import ArxModel, observer_form
from ..models.protocol import StateSpaceModel, sample_interval, unscheduled

__all__ = ["PencilModel", "PencilEstimate", "estimate_pencil"]


@dataclass(frozen=True, eq=False)
class PencilModel(StateSpaceModel):
    """``E x(k+1) = F x(k) + G [u(k); y(k)]``.

    Attributes
    ----------
    E, F : ndarray, shape (n + n_y, n)
        The pencil's matrices on ``x(k+1)`` and ``x(k)``.
    G : ndarray, shape (n + n_y, n_u + n_y)
        The matrix on the external variables ``[u(k); y(k)]``.
    n_u, n_y : int
        Numbers of inputs and outputs.
    dt : float or None
        Sample interval (s), if known.
    """

    E: np.ndarray
    F: np.ndarray
    G: np.ndarray
    n_u: int
    n_y: int
    dt: float | None = None

    def __post_init__(self) -> None:
        E, F, G = (finite_matrix(name, getattr(self, name)) for name in "EFG")
        n = E.shape[1]
        rows = n + self.n_y
        for name, m, shape in (("E", E, (rows, n)), ("F", F, (rows, n)), ("G", G, (rows, self.n_u + self.n_y))):
            if m.shape != shape:
                raise InputError(f"{name} has shape {m.shape}; a pencil with n={n}, n_u={self.n_u}, "
                                 f"n_y={self.n_y} needs {shape}")
        for name, m in (("E", E), ("F", F), ("G", G)):
            m.setflags(write=False)
            object.__setattr__(self, name, m)

    @property
    def n(self) -> int:
        """Number of internal variables."""
        return int(self.E.shape[1])

    @classmethod
    def from_state_space(cls, A: Any, B: Any, C: Any, D: Any, dt: float | None = None) -> "PencilModel":
        """Make the SP form of ``x(k+1) = A x + B u``, ``y = C x + D u`` (appendix eq. A.102-A.103).

        Parameters
        ----------
        A, B, C, D : array_like
            Discrete model, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
        dt : float, optional
            Sample interval (s).

        Returns
        -------
        PencilModel
            ``E = [I; 0]``, ``F = [A; C]``, ``G = [[B, 0], [D, -I]]``.
        """
        A, B, C, D = (finite_matrix(name, m) for name, m in zip("ABCD", (A, B, C, D)))
        n, n_u, n_y = A.shape[0], B.shape[1], C.shape[0]
        E = np.vstack([np.eye(n), np.zeros((n_y, n))])
        F = np.vstack([A, C])
        G = np.block([[B, np.zeros((n, n_y))], [D, -np.eye(n_y)]])
        return cls(E, F, G, n_u, n_y, dt)

    @classmethod
    def from_arx(cls, model: ArxModel) -> "PencilModel":
        """Make the observer-form SP model of an ARX model (appendix eq. A.104-A.105).

        Parameters
        ----------
        model : ArxModel
            The ARX polynomials.

        Returns
        -------
        PencilModel
            The pencil of its block observer form.
        """
        return cls.from_state_space(*observer_form(*model.padded()), dt=model.dt)

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """Return the state-space form of this pencil.

        A row transformation ``T`` (from the QR factorisation of E) brings E
        to ``[I; 0]``; the last ``n_y`` rows then read
        ``0 = F2 x + G2u u + G2y y``, solved for y, which is substituted into
        the first n rows. Needs E of full column rank and ``G2y`` invertible
        (y determined by x and u).

        Parameters
        ----------
        schedule : float, optional
            Changes nothing (the model is not scheduled).

        Returns
        -------
        tuple
            ``(A, B, C, D, dt)``, discrete time.
        """
        unscheduled(schedule)
        dt = sample_interval(self.dt, "pencil model")
        n, n_u, n_y = self.n, self.n_u, self.n_y
        q, r = scipy.linalg.qr(self.E)
        top = r[:n, :n]
        if np.linalg.matrix_rank(top) < n:
            raise InputError("E is rank deficient: this pencil is not a state-space system in x")
        transform = np.vstack([np.linalg.solve(top, q[:, :n].T), q[:, n:].T])
        F = transform @ self.F
        G = transform @ self.G
        F1, F2 = F[:n], F[n:]
        G1u, G1y, G2u, G2y = G[:n, :n_u], G[:n, n_u:], G[n:, :n_u], G[n:, n_u:]
        if np.linalg.matrix_rank(G2y) < n_y:
            raise InputError("the outputs are not determined by the pencil's algebraic rows (G2y singular)")
        C = -np.linalg.solve(G2y, F2)
        D = -np.linalg.solve(G2y, G2u)
        return F1 + G1y @ C, G1u + G1y @ D, C, D, dt

    def to_arx(self) -> ArxModel:
        """Convert to an ARX model ``a(q) y = B(q) u`` with the scalar denominator ``a(q) = det(I - q^-1 A)``.

        Exact for any number of outputs (for several outputs the common
        scalar denominator is not the smallest MIMO ARX form).

        Returns
        -------
        ArxModel
            The polynomials, ``a`` a multiple of the identity at each lag.
        """
        from scipy.signal import ss2tf  # a second to import: paid on first use

        A, B, C, D, dt = self.to_statespace()
        n = A.shape[0]
        b = np.zeros((n + 1, self.n_y, self.n_u))
        a_poly = np.poly(A) if n else np.ones(1)
        for j in range(self.n_u):
            numerator, denominator = ss2tf(A, B, C, D, input=j)
            b[:, :, j] = np.atleast_2d(numerator).T
            a_poly = denominator
        a = np.zeros((n + 1, self.n_y, self.n_y))
        for i in range(n + 1):
            a[i] = a_poly[i] * np.eye(self.n_y)
        return ArxModel(a, b, dt)


@dataclass(frozen=True, eq=False)
class PencilEstimate:
    """Joint state and parameter estimate of a MISO ARX/ARMAX model in SP form.

    Attributes
    ----------
    model : ArxModel
        From the final parameter estimate.
    gamma : ndarray
        ``[a_1..a_na, b_{1,0..nb_1-1}, b_{2,...}, ...]`` (the coefficients of
        ``u_j(k - i)`` from ``i = 0``).
    gamma_history : ndarray, shape (N, n_gamma)
        The parameters' filtered estimate after each sample.
    states : ndarray, shape (N, n)
        Filtered ``x(k|k)``.
    covariance : ndarray
        Final ``P(k|k)`` of the parameters.
    filter : KalmanResult
        The whole Kalman filter run on ``z = [x; gamma]``.
    """

    model: ArxModel
    gamma: np.ndarray
    gamma_history: np.ndarray
    states: np.ndarray
    covariance: np.ndarray
    filter: KalmanResult


def estimate_pencil(data_or_arrays: Any, *, na: int, nb: Any = None, noise: Any = None,
                    noise_variance: float = 1.0, P0: float = 1e4, parameter_drift: float = 0.0) -> PencilEstimate:
    """Estimate the states and parameters of ``A(q) y = B(q) u + C(q) e`` jointly by a Kalman filter (eq. A.106-A.109).

    Parameters
    ----------
    data_or_arrays : IOData or (u, y)
        One output.
    na : int
        Order of A(q) (and the number of internal variables).
    nb : int or sequence of int, optional
        Coefficients per input, lags ``0 .. nb_j - 1`` (default ``na + 1``,
        at most ``na + 1``).
    noise : array_like (na,), optional
        Known noise parameters ``c_1..c_na`` (``C*``); default zero (ARX).
    noise_variance : float
        Variance of e.
    P0 : float
        Initial variance of every state and parameter (prior mean zero).
    parameter_drift : float
        Random-walk variance of the parameters per sample (0: constant).

    Returns
    -------
    PencilEstimate
        The final ARX model, the parameters' history and the filtered states.
    """
    u, y, dt = io_arrays(data_or_arrays)
    if y.shape[1] != 1:
        raise InputError(f"the SP joint estimator is implemented for one output; got {y.shape[1]}")
    n = non_negative_int(na, "na")
    if n < 1:
        raise InputError("na must be >= 1 for the SP form")
    n_u = u.shape[1]
    nb_t = per_input(n + 1 if nb is None else nb, n_u, "nb")
    if max(nb_t) > n + 1:
        raise InputError(f"nb may be at most na + 1 = {n + 1} in the observer form; got {nb_t}")
    c = np.zeros(n) if noise is None else finite_matrix("noise", np.ravel(noise), ndim=1)
    if c.size != n:
        raise InputError(f"noise needs na = {n} parameters c_1..c_na; got {c.size}")
    for name, value in (("noise_variance", noise_variance), ("P0", P0)):
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"{name} must be positive; got {value}")
    if not (np.isfinite(parameter_drift) and parameter_drift >= 0):
        raise InputError(f"parameter_drift must be >= 0; got {parameter_drift}")
    n_gamma = n + sum(nb_t)
    size = n + n_gamma
    samples = y.shape[0]
    b_index = []  # (input, lag) of each b parameter, in gamma order after the a's
    for j in range(n_u):
        b_index += [(j, i) for i in range(nb_t[j])]
    # Time-varying matrices: z(k+1) = F(k) z(k) + G_e e(k), y(k) = H(k) z(k) + e(k).
    F = np.zeros((samples, size, size))
    H = np.zeros((samples, 1, size))
    F[:, :n, :n] = np.eye(n, k=1)
    F[:, n:, n:] = np.eye(n_gamma)
    H[:, 0, 0] = 1.0
    for i in range(n):
        F[:, i, n + i] = -y[:, 0]  # -a_{i+1} y(k) into x_{i+1}(k+1)
    for p, (j, lag) in enumerate(b_index):
        column = n + n + p
        if lag == 0:
            H[:, 0, column] = u[:, j]
        else:
            F[:, lag - 1, column] = u[:, j]
    g_e = np.concatenate([c, np.zeros(n_gamma)])
    decorrelated = F - g_e[None, :, None] * H  # F - G_e H: the noise then enters only through y
    A = np.empty_like(F)
    A[0] = np.eye(size)  # the prior is on z at the first sample
    A[1:] = decorrelated[:-1]
    Q = np.zeros((size, size))
    Q[n:, n:] = parameter_drift * np.eye(n_gamma)
    run = kalman_filter(y, A=A, C=H, Q=Q, R=[[noise_variance]], x0=np.zeros(size), P0=P0 * np.eye(size),
                        B=g_e[:, None], u=y)
    gamma = run.x_post[-1, n:]
    a = np.zeros((n + 1, 1, 1))
    a[0] = 1.0
    a[1:, 0, 0] = gamma[:n]
    b = np.zeros((n + 1, 1, n_u))
    for p, (j, lag) in enumerate(b_index):
        b[lag, 0, j] = gamma[n + p]
    return PencilEstimate(ArxModel(a, b, dt), gamma, run.x_post[:, n:], run.x_post[:, :n],
                          run.P_post[-1, n:, n:], run)

