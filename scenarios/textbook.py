"""The seed appendix's worked examples, computed by the classical estimators.

Source: the textbook appendix "System identification, state and parameter
estimation techniques" (sections A.2-A.5), whose equations and tables are
images in our copy; every number here is recomputed from the stated data.

* ``kalman_example``: the scalar Kalman filter of A.3 (eq. A.92, phi = 1,
  P0 = 100, Q = 25, R = 15): P(k|k-1), K(k), P(k|k) for the first steps.
  Expected: 125, 0.8929, 13.39 at k = 1, settling at P(k|k) = 10.549.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
import scipy.linalg

from identification.ekf import NonlinearModel, ekf_joint
from identification.kalman import kalman_filter

__all__ = ["kalman_example", "BicycleParameters", "bicycle_model", "bicycle_record", "ekf_bicycle_example"]


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


# --------------------------------------------------------------------------- EKF: a bicycle model
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
