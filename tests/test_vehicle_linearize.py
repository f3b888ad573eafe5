"""Linearisation at trim: modes in their expected bands, against closed forms and the nonlinear model."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm

from vehid.vehicle import baseline, simulate
from vehid.vehicle.linearize import linearize
from vehid.vehicle.manoeuvres import step
from vehid.vehicle.parameters import GRAVITY, static_axle_loads
from vehid.vehicle.tyre import cornering_stiffness

SPEED = 20.0


@pytest.fixture(scope="module")
def lin():
    return linearize(baseline(), speed=SPEED)


def _only(lin, label):
    modes = lin.modes_labelled(label)
    assert len(modes) == 1, [m.label for m in lin.modes]
    return modes[0]


def test_shapes_and_one_ignorable_heading(lin):
    assert lin.A.shape == (23, 23) and lin.B.shape == (23, 1)
    assert lin.C.shape == (10, 23) and lin.D.shape == (10, 1)
    # psi appears nowhere in the dynamics: one zero eigenvalue, an all-zero column of A.
    assert np.all(lin.A[:, lin.state_names.index("psi")] == 0)
    assert len(lin.modes_labelled("heading")) == 1
    assert all(m.eigenvalue.real < 0 for m in lin.modes if m.label != "heading")


def test_ride_and_roll_modes_in_band(lin):
    """Heave, pitch and roll near 1.2-1.5 Hz (vehicle spec); the roll mode within 10 % of
    sqrt((K_phi - m g h) / (I_xx + m h^2)) = 1.51 Hz, the roll axis at the ground (its
    coupling with sideslip moves it a few per cent)."""
    params = baseline()
    c, s = params.chassis, params.suspension
    k_phi = (s.front_wheel_rate * c.front_track**2 / 2 + s.front_anti_roll_bar
             + s.rear_wheel_rate * c.rear_track**2 / 2 + s.rear_anti_roll_bar)
    roll_hz = math.sqrt((k_phi - c.mass * GRAVITY * c.cg_height) / (c.roll_inertia + c.mass * c.cg_height**2))
    roll_hz /= 2 * math.pi
    for label in ("heave", "pitch", "roll"):
        mode = _only(lin, label)
        assert 1.1 <= mode.frequency_hz <= 1.6, (label, mode.frequency_hz)
        assert 0.2 <= mode.damping <= 0.7, (label, mode.damping)
    assert _only(lin, "roll").frequency_hz == pytest.approx(roll_hz, rel=0.10)


def test_yaw_sideslip_heavily_damped(lin):
    mode = _only(lin, "yaw-sideslip")
    assert mode.damping > 0.7 and 0.5 < mode.frequency_hz < 3.0


def test_lags_and_wheel_modes(lin):
    """Lateral slip lags near -V/sigma_alpha; wheel spin / longitudinal lag pairs lightly damped near 30 Hz."""
    tyre = baseline().tyre
    targets = [-SPEED / tyre.front_lateral_relaxation, -SPEED / tyre.rear_lateral_relaxation]
    lags = [m.eigenvalue.real for m in lin.modes_labelled("lateral-slip-lag")]
    assert len(lags) == 4
    close = [lag for lag in lags if min(abs(lag / t - 1) for t in targets) < 0.05]
    assert len(close) >= 3  # one front lag couples with roll and sideslip and moves away
    wheels = lin.modes_labelled("wheel")
    assert len(wheels) == 4
    for mode in wheels:
        assert 25 < mode.frequency_hz < 35 and mode.damping < 0.5


def test_yaw_sideslip_tends_to_the_bicycle_model():
    """With a low CG and short relaxation lengths the full model's yaw-sideslip pair approaches
    the eigenvalues of the 2x2 bicycle (beta, r) matrix with cornering stiffness from the tyre
    at static load (5 %: what remains is load transfer and the residual lag)."""
    base = baseline()
    params = dataclasses.replace(
        base,
        chassis=dataclasses.replace(base.chassis, cg_height=0.02),
        tyre=dataclasses.replace(base.tyre, front_lateral_relaxation=0.02, rear_lateral_relaxation=0.02),
    )
    c = params.chassis
    front, rear = static_axle_loads(params)
    cf = -2 * float(cornering_stiffness(front / 2, params.tyre))
    cr = -2 * float(cornering_stiffness(rear / 2, params.tyre))
    a, b, m, iz, v = c.cg_to_front_axle, c.cg_to_rear_axle, c.mass, c.yaw_inertia, SPEED
    bicycle = np.array([
        [-(cf + cr) / (m * v), -1 - (a * cf - b * cr) / (m * v**2)],
        [-(a * cf - b * cr) / iz, -(a**2 * cf + b**2 * cr) / (iz * v)],
    ])
    expected = max(np.linalg.eigvals(bicycle), key=lambda e: e.imag)
    mode = _only(linearize(params, speed=SPEED), "yaw-sideslip")
    assert abs(mode.eigenvalue - expected) < 0.05 * abs(expected)


def test_linear_model_matches_nonlinear_small_step(lin):
    """The A, B, C, D model and the nonlinear simulation agree on a 0.05 deg step (1 % of the peak):
    a check of the Jacobians against the model they come from."""
    delta = math.radians(0.05)
    manoeuvre = step(amplitude=delta, duration=3.0)
    data = simulate(baseline(), manoeuvre)
    dt, n = manoeuvre.dt, lin.A.shape[0]
    # Zero-order-hold discretisation, input held on the interval ending at each sample.
    block = expm(np.block([[lin.A, lin.B], [np.zeros((1, n + 1))]]) * dt)
    ad, bd = block[:n, :n], block[:n, n:]
    dx = np.zeros(n)
    outputs = []
    for k, u in enumerate(manoeuvre.steer):
        if k:
            dx = ad @ dx + bd[:, 0] * u
        outputs.append(lin.C @ dx + lin.D[:, 0] * u)
    linear = np.array(outputs)
    y0 = data.y[0]
    for name in ("lateral_acceleration", "yaw_rate", "roll_angle"):
        i = data.output_names.index(name)
        peak = np.max(np.abs(data.y[:, i] - y0[i]))
        np.testing.assert_allclose(linear[:, i], data.y[:, i] - y0[i], rtol=0, atol=0.01 * peak)
