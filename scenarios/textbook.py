"""The seed appendix's worked examples, computed by the classical estimators.

Source: the textbook appendix "System identification, state and parameter
estimation techniques" (sections A.2-A.5), whose equations and tables are
images in our copy; every number here is recomputed from the stated data.

* ``kalman_example``: the scalar Kalman filter of A.3 (eq. A.92, phi = 1,
  P0 = 100, Q = 25, R = 15): P(k|k-1), K(k), P(k|k) for the first steps.
  Expected: 125, 0.8929, 13.39 at k = 1, settling at P(k|k) = 10.549.
* ``rls_example``: RLS in its three forms started per Remark 2 equals batch
  least squares (A.2.3); expected differences near 1e-15.
* ``gls_example``: least squares is biased under AR(1) equation error
  (a1 near -0.98 for -0.8) and GLS (A.2.5) is not.
* ``positivity_example`` and ``ud_example``: the covariance forms of A.5.
* ``ekf_bicycle_example``: the joint EKF of A.4.1 on a bicycle model recovers
  both cornering stiffnesses within 0.2 %.
* ``pencil_example``: joint Kalman estimation of an ARMAX model in singular
  pencil form (A.4.2); parameters within 0.02 of the truth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import scipy.linalg
from scipy.signal import lfilter

from vehid.identification.classical.ekf import NonlinearModel, ekf_joint
from vehid.identification.classical.gls import estimate_gls
from vehid.identification.classical.kalman import kalman_filter
from vehid.identification.classical.least_squares import arx_regressors, estimate_arx, least_squares
from vehid.identification.classical.pencil import PencilModel, estimate_pencil
from vehid.identification.classical.recursive import recursive_least_squares

__all__ = [
    "kalman_example",
    "BicycleParameters",
    "bicycle_model",
    "bicycle_record",
    "ekf_bicycle_example",
    "positivity_example",
    "ud_example",
    "coloured_noise_record",
    "gls_example",
    "rls_example",
    "pencil_example",
    "run_all",
]


def kalman_example(*, steps: int = 5, phi: float = 1.0, P0: float = 100.0, Q: float = 25.0, R: float = 15.0
                   ) -> list[dict[str, Any]]:
    """P(k|k-1), K(k), P(k|k) of the appendix's scalar example (A.92) for k = 1..steps.

    The covariances do not depend on the measurements, so the filter runs on zeros.
    """
    run = kalman_filter(np.zeros((steps, 1)), A=[[phi]], C=[[1.0]], Q=[[Q]], R=[[R]], x0=[0.0], P0=[[P0]])
    return [
        {"k": k + 1, "P_prior": float(run.P_prior[k, 0, 0]), "K": float(run.gain[k, 0, 0]),
         "P_post": float(run.P_post[k, 0, 0])}
        for k in range(steps)
    ]


@dataclass(frozen=True)
class BicycleParameters:
    """A linear single-track (bicycle) model; illustrative values of a mid-size car."""

    mass: float = 1500.0  # [kg] illustrative
    yaw_inertia: float = 2500.0  # [kg m^2] illustrative
    front_distance: float = 1.2  # [m] centre of gravity to front axle, illustrative
    rear_distance: float = 1.4  # [m] centre of gravity to rear axle, illustrative
    speed: float = 20.0  # [m/s] constant forward speed
    front_stiffness: float = 80_000.0  # [N/rad] front axle cornering stiffness, illustrative
    rear_stiffness: float = 100_000.0  # [N/rad] rear axle cornering stiffness, illustrative


STIFFNESS_SCALE = 1e5  # [N/rad] the EKF estimates stiffness / 1e5, of order one


def bicycle_model(params: BicycleParameters, dt: float) -> NonlinearModel:
    """States (lateral velocity v [m/s], yaw rate r [rad/s]), input steer [rad], outputs (r, a_y).

    Parameters ``p = (C_f, C_r) / 1e5``; slip angles ``alpha_f = delta - (v + a r)/U``,
    ``alpha_r = -(v - b r)/U``; ``m (vdot + U r) = F_f + F_r``, ``I rdot = a F_f - b F_r``,
    ``a_y = (F_f + F_r)/m``. Discretised by one RK4 step per sample.
    """
    x = ca.SX.sym("x", 2)
    u = ca.SX.sym("steer", 1)
    p = ca.SX.sym("stiffness", 2)
    v, r = x[0], x[1]
    a, b, U = params.front_distance, params.rear_distance, params.speed
    front = STIFFNESS_SCALE * p[0] * (u[0] - (v + a * r) / U)
    rear = STIFFNESS_SCALE * p[1] * (-(v - b * r) / U)
    xdot = ca.vertcat((front + rear) / params.mass - U * r, (a * front - b * rear) / params.yaw_inertia)
    y = ca.vertcat(r, (front + rear) / params.mass)
    return NonlinearModel.from_continuous(x, u, p, xdot, y, dt, name="bicycle")


def _bicycle_matrices(params: BicycleParameters) -> tuple[np.ndarray, ...]:
    m, iz, a, b, U = params.mass, params.yaw_inertia, params.front_distance, params.rear_distance, params.speed
    cf, cr = params.front_stiffness, params.rear_stiffness
    A = np.array([[-(cf + cr) / (m * U), -(a * cf - b * cr) / (m * U) - U],
                  [-(a * cf - b * cr) / (iz * U), -(a * a * cf + b * b * cr) / (iz * U)]])
    B = np.array([[cf / m], [a * cf / iz]])
    C = np.array([[0.0, 1.0], A[0] + np.array([0.0, U])])
    D = np.array([[0.0], [cf / m]])
    return A, B, C, D


def bicycle_record(params: BicycleParameters = BicycleParameters(), *, seed: int = 0, duration: float = 20.0,
                   dt: float = 0.01, yaw_noise: float = 0.005, lateral_noise: float = 0.05
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulated steer, clean and noisy outputs (r [rad/s], a_y [m/s^2]) of the linear bicycle model.

    The steer (rad) is held between samples: random levels of about 2 degrees changed every 0.5 s,
    plus a 0.5 Hz sine; the model is discretised exactly for that hold (matrix exponential).
    Noise: white, ``yaw_noise`` and ``lateral_noise`` standard deviations.
    """
    rng = np.random.default_rng(seed)
    samples = int(round(duration / dt))
    t = np.arange(samples) * dt
    levels = rng.normal(0.0, np.radians(2.0), int(np.ceil(duration / 0.5)) + 1)
    steer = levels[(t / 0.5).astype(int)] + np.radians(1.0) * np.sin(2 * np.pi * 0.5 * t)
    A, B, C, D = _bicycle_matrices(params)
    block = scipy.linalg.expm(np.block([[A, B], [np.zeros((1, 3))]]) * dt)
    phi, gamma = block[:2, :2], block[:2, 2:]
    x = np.zeros(2)
    clean = np.zeros((samples, 2))
    for k in range(samples):
        clean[k] = C @ x + D[:, 0] * steer[k]
        x = phi @ x + gamma[:, 0] * steer[k]
    noisy = clean + rng.standard_normal((samples, 2)) * [yaw_noise, lateral_noise]
    return steer[:, None], clean, noisy


def ekf_bicycle_example(*, seed: int = 0, compiled: bool = False) -> dict[str, Any]:
    """Front and rear cornering stiffness of the bicycle model estimated by the joint EKF from noisy data.

    The filter starts at 50,000 N/rad for both, with a standard deviation of 50,000 N/rad, and
    knows the noise levels (R); the parameters are constant (zero process noise on them), the
    states have a small process noise for the RK4 discretisation error.
    """
    params = BicycleParameters()
    dt = 0.01
    steer, _, noisy = bicycle_record(params, seed=seed, dt=dt)
    model = bicycle_model(params, dt)
    result = ekf_joint(model, (steer, noisy), x0=[0.0, 0.0], p0=[0.5, 0.5], P0=[1e-2, 1e-2, 0.25, 0.25],
                       Q=[1e-8, 1e-8, 0.0, 0.0], R=[0.005**2, 0.05**2], compiled=compiled)
    estimate = result.parameters[-1] * STIFFNESS_SCALE
    std = result.parameter_std * STIFFNESS_SCALE
    truth = np.array([params.front_stiffness, params.rear_stiffness])
    return {
        "samples": int(steer.shape[0]),
        "true_N_per_rad": truth.tolist(),
        "estimate_N_per_rad": estimate.tolist(),
        "std_N_per_rad": std.tolist(),
        "relative_error": ((estimate - truth) / truth).tolist(),
    }


POSITIVITY_PHI = (1.7,) + (0.5,) * 9  # regressors of the single-parameter example
POSITIVITY_P0 = 1e7
POSITIVITY_THETA = 2.0


def positivity_example(*, noise: float = 0.1, seed: int = 0) -> dict[str, Any]:
    """The single-parameter model y = theta phi + e (A.110) by the three RLS forms in single precision.

    Float32 stands for the microcontroller arithmetic the appendix has in mind. With P0 = 1e7 and
    phi(1) = 1.7, the plain update (A.111-A.113) rounds K phi to 1 + 1.2e-7 > 1, so P(1) = -1
    (A.114-A.116); with phi = 0.5 afterwards ``1 + P phi^2`` shrinks to 0, K phi < 0 and the
    estimate blows out. The square-root form (P = S^2, S <- S / sqrt(1 + S^2 phi^2)) and the
    UD form (d <- d / (1 + d phi^2)) compute P from positive quantities and stay positive.
    """
    f32 = np.float32
    rng = np.random.default_rng(seed)
    phi = np.array(POSITIVITY_PHI, dtype=f32)
    y = (f32(POSITIVITY_THETA) * phi + rng.normal(0.0, noise, phi.size).astype(f32)).astype(f32)
    one = f32(1.0)
    rows: dict[str, dict[str, list[float]]] = {form: {"P": [], "theta": []} for form in ("plain", "sqrt", "ud")}
    with np.errstate(all="ignore"):  # the plain form is meant to break down here
        P, S, d = f32(POSITIVITY_P0), f32(np.sqrt(POSITIVITY_P0)), f32(POSITIVITY_P0)
        theta = {form: f32(0.0) for form in rows}
        for k in range(phi.size):
            p, target = phi[k], y[k]
            gain = P * p / (one + p * P * p)  # A.112
            theta["plain"] = theta["plain"] + gain * (target - p * theta["plain"])  # A.111
            P = P - gain * p * P  # A.113
            f = S * p
            beta = one + f * f
            theta["sqrt"] = theta["sqrt"] + (S * f / beta) * (target - p * theta["sqrt"])
            S = S / np.sqrt(beta)
            alpha = one + d * p * p
            theta["ud"] = theta["ud"] + (d * p / alpha) * (target - p * theta["ud"])
            d = d / alpha
            for form, value in (("plain", P), ("sqrt", S * S), ("ud", d)):
                rows[form]["P"].append(float(value))
                rows[form]["theta"].append(float(theta[form]))
    return {"phi": [float(v) for v in phi], "P0": POSITIVITY_P0, "theta_true": POSITIVITY_THETA,
            "precision": "float32", **rows}


def ud_example(*, lam: float = 0.98) -> dict[str, Any]:
    """One UDU' RLS step (A.122-A.126) with givens of our own (the appendix's are an image).

    ``U(0) = [[1, 0.5], [0, 1]]``, ``D(0) = diag(4, 2)``, ``phi = (1, 2)``, ``y = 3``, theta(0) = 0:
    prints F = U' phi, G = D F, beta = lambda + F'G, the gain, U(1), D(1), theta(1), and the plain
    form's P(1) for comparison.
    """
    from vehid.identification.classical.factorised import ud_covariance, ud_step
    from vehid.identification.classical.recursive import rls_step

    U = np.array([[1.0, 0.5], [0.0, 1.0]])
    d = np.array([4.0, 2.0])
    phi = np.array([1.0, 2.0])
    y = np.array([3.0])
    F = U.T @ phi
    G = d * F
    theta, U1, d1, gain, _ = ud_step(np.zeros((2, 1)), U, d, phi, y, lam)
    _, P_plain, _, _ = rls_step(np.zeros((2, 1)), ud_covariance(U, d), phi, y, lam)
    return {"lambda": lam, "F": F.tolist(), "G": G.tolist(), "beta": float(lam + F @ G), "K": gain.tolist(),
            "U": U1.tolist(), "D": d1.tolist(), "theta": theta[:, 0].tolist(),
            "P_from_UD": ud_covariance(U1, d1).tolist(), "P_plain": P_plain.tolist()}


GLS_TRUE = (-0.8, 0.5)  # theta = [a1, b1] of y(k) = 0.8 y(k-1) + 0.5 u(k-1) + xi(k)


def coloured_noise_record(seed: int, n: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """An ARX system whose equation error is AR(1) noise, xi = w / (1 - 0.9 q^-1) (A.79), w ~ N(0, 0.25)."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    xi = lfilter([1.0], [1.0, -0.9], 0.5 * rng.standard_normal(n))
    y = lfilter([0.0, 0.5], [1.0, -0.8], u) + lfilter([1.0], [1.0, -0.8], xi)
    return u[:, None], y[:, None]


def gls_example(*, runs: int = 20) -> dict[str, Any]:
    """LS against GLS on ``runs`` seeded records of :func:`coloured_noise_record`: means and spreads."""
    ls, gls, passes = [], [], []
    for seed in range(runs):
        u, y = coloured_noise_record(seed)
        ls.append(estimate_arx((u, y), na=1, nb=1, nk=1).theta[:, 0])
        result = estimate_gls((u, y), na=1, nb=1, nk=1, noise_order=1)
        gls.append(result.theta[:, 0])
        passes.append(result.iterations)
    ls_a, gls_a = np.array(ls), np.array(gls)
    return {"true": list(GLS_TRUE), "runs": runs, "ls_mean": ls_a.mean(axis=0).tolist(),
            "ls_std": ls_a.std(axis=0, ddof=1).tolist(), "gls_mean": gls_a.mean(axis=0).tolist(),
            "gls_std": gls_a.std(axis=0, ddof=1).tolist(), "gls_mean_passes": float(np.mean(passes))}


def rls_example(*, seed: int = 0) -> dict[str, Any]:
    """RLS (plain, square-root, UD) started per Remark 2 against batch LS on one record: largest differences."""
    u, y = coloured_noise_record(seed)
    phi, target, _, _ = arx_regressors(u, y, na=2, nb=2, nk=1)
    batch = least_squares(phi, target)
    start = least_squares(phi[:20], target[:20])
    P0 = start.gram_inverse
    differences = {}
    for form in ("plain", "sqrt", "ud"):
        run = recursive_least_squares(phi[20:], target[20:], P0=P0, theta0=start.theta, form=form)
        differences[form] = float(np.max(np.abs(run.theta - batch.theta)))
    return {"batch_theta": batch.theta[:, 0].tolist(), "max_difference_to_batch": differences}


def pencil_example(*, seed: int = 1) -> dict[str, Any]:
    """Joint Kalman estimation of an ARMAX model in SP form: A = 1 - 1.5 q^-1 + 0.7 q^-2,
    B = q^-1 + 0.5 q^-2, C* = 1 + 0.5 q^-1 (known), e ~ N(0, 0.01), 3000 samples."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(3000)
    e = 0.1 * rng.standard_normal(3000)
    y = lfilter([0.0, 1.0, 0.5], [1.0, -1.5, 0.7], u) + lfilter([1.0, 0.5], [1.0, -1.5, 0.7], e)
    joint = estimate_pencil((u[:, None], y[:, None]), na=2, nb=3, noise=[0.5, 0.0], noise_variance=0.01)
    pencil = PencilModel.from_arx(joint.model)
    return {"true_gamma": [-1.5, 0.7, 0.0, 1.0, 0.5], "gamma": joint.gamma.tolist(),
            "gamma_std": np.sqrt(np.diag(joint.covariance)).tolist(),
            "pencil_shapes": {"E": list(pencil.E.shape), "F": list(pencil.F.shape), "G": list(pencil.G.shape)}}


def run_all(*, compiled: bool = False) -> dict[str, Any]:
    """Every example's figures, JSON-ready (``vehid study textbook``)."""
    return {
        "kalman_example": kalman_example(steps=5),
        "kalman_steady_state_P_post": float((-25.0 + np.sqrt(25.0**2 + 4 * 375.0)) / 2.0),
        "rls_example": rls_example(),
        "gls_example": gls_example(),
        "positivity_example": positivity_example(),
        "ud_example": ud_example(),
        "ekf_bicycle_example": ekf_bicycle_example(compiled=compiled),
        "pencil_example": pencil_example(),
    }
