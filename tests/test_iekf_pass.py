"""The filter step and its compiled pass, against independent references.

References: the NumPy pass (textbook forms, full matrices), SciPy's matrix
exponential for the exact first-order-hold discretisation, central finite
differences for the Jacobians, and a plain linear Kalman filter for the
degenerate case with the parameters frozen.
"""

import numpy as np
import pytest
from scipy.linalg import expm

from vehid.identification.filtering.filter_models import LinearModalFilterModel
from vehid.identification.filtering.iekf_pass import (QUICK_COMPILE_STEPS, compiled_pass, numpy_reference_pass, pack_covariance,
                                                    unpack_covariance)
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.linear_example import make_data, true_model

DT = 0.002


def _foh_matrices(A, B, dt):
    """Phi, Gamma0 (on u_k), Gamma1 (on u_k+1) of the exact first-order hold, by one matrix exponential."""
    n, n_u = B.shape
    big = np.zeros((n + 2 * n_u, n + 2 * n_u))
    big[:n, :n] = A * dt
    big[:n, n:n + n_u] = B * dt
    big[n:n + n_u, n + n_u:] = np.eye(n_u)
    block = expm(big)
    phi, m0, m1 = block[:n, :n], block[:n, n:n + n_u], block[:n, n + n_u:]
    return phi, m0 - m1, m1


def _start_state(structure, theta, q):
    return np.concatenate([np.zeros(structure.n), theta, pack_covariance(np.diag(q))])


@pytest.mark.parametrize(
    "pattern, outputs, discretization, covariance",
    [
        ("all-ones", (0,), "euler", "paper"),
        ("all-ones", (0,), "exact", "joseph"),
        ("all-ones", (0,), "exact-zoh", "paper"),
        ("eq18", (0, 1, 2), "exact", "joseph"),
    ],
)
def test_compiled_pass_equals_numpy_reference(pattern, outputs, discretization, covariance):
    # 1,000 steps of the same arithmetic in another order: agreement to 1e-10 (rounding grows slowly over the steps)
    data, _ = make_data(1, outputs=outputs, duration=2.2)
    structure = ModalStructure.from_pattern(pattern, 5, 2, len(outputs))
    run = compiled_pass(LinearModalFilterModel(structure), DT, discretization, covariance)
    q = np.concatenate([np.zeros(5), np.ones(structure.n_parameters)])
    state = _start_state(structure, structure.initial_parameters(sigma=-10, omega=10, omega_spread=0.5), q)
    u, y = data.u[:1000], data.y[:1000]
    compiled_state, compiled_innovations = run(state, u, y, q, np.eye(len(outputs)))
    reference_state, reference_innovations = numpy_reference_pass(run.filter_step, state, u, y, q, np.eye(len(outputs)))
    scale = np.max(np.abs(reference_state))
    assert np.max(np.abs(compiled_state - reference_state)) < 1e-10 * scale
    assert np.max(np.abs(compiled_innovations - reference_innovations)) < 1e-10 * np.max(np.abs(y))
    assert not np.allclose(compiled_state, state)  # the pass did move the parameters


def test_exact_transition_equals_matrix_exponential_foh():
    # closed-form modal gains vs SciPy's expm of the augmented matrix: rounding level (1e-12)
    model = true_model()
    structure = ModalStructure.from_pattern("all-ones", 5, 2, 1)
    filter_model = LinearModalFilterModel(structure)
    run = compiled_pass(filter_model, DT, "exact", "joseph")
    theta = structure.pack(model.A, model.B, model.C[:1], model.D[:1])
    rng = np.random.default_rng(5)
    x, u0, u1 = rng.standard_normal(5), rng.standard_normal(2), rng.standard_normal(2)
    z_next = np.asarray(run.filter_step.model(np.concatenate([x, theta]), u0, u1, np.zeros(0))[0]).ravel()
    phi, gamma0, gamma1 = _foh_matrices(model.A, model.B, DT)
    assert np.allclose(z_next[:5], phi @ x + gamma0 @ u0 + gamma1 @ u1, rtol=0, atol=1e-12)
    assert np.array_equal(z_next[5:], theta)


@pytest.mark.parametrize("discretization", ["exact", "exact-zoh", "euler"])
def test_jacobians_equal_finite_differences(discretization):
    # central differences with step 1e-6: truncation ~1e-12 x curvature, rounding ~1e-10; tolerance 1e-7
    structure = ModalStructure.from_pattern("eq18", 5, 2, 3)
    run = compiled_pass(LinearModalFilterModel(structure), DT, discretization, "joseph")
    rng = np.random.default_rng(6)
    theta = structure.initial_parameters(sigma=-3, omega=20, omega_spread=0.5) + 0.3 * rng.standard_normal(structure.n_parameters)
    z = np.concatenate([rng.standard_normal(5), theta])
    u0, u1 = rng.standard_normal(2), rng.standard_normal(2)
    model = run.filter_step.model
    _, Phi, _, H = (np.asarray(v) for v in model(z, u0, u1, np.zeros(0)))
    step = 1e-6
    for j in range(z.size):
        dz = np.zeros(z.size)
        dz[j] = step
        plus, minus = model(z + dz, u0, u1, np.zeros(0)), model(z - dz, u0, u1, np.zeros(0))
        column_phi = (np.asarray(plus[0]) - np.asarray(minus[0])).ravel() / (2 * step)
        column_h = (np.asarray(plus[2]) - np.asarray(minus[2])).ravel() / (2 * step)
        assert np.allclose(Phi[:, j], column_phi, rtol=1e-7, atol=1e-7)
        assert np.allclose(H[:, j], column_h, rtol=1e-7, atol=1e-7)


def test_with_parameters_frozen_the_iekf_is_a_linear_kalman_filter():
    # zero Q and P0 on the parameters: the filter must equal a plain KF on the same discrete model (1e-10)
    structure = ModalStructure.from_pattern("eq18", 5, 2, 3)
    rng = np.random.default_rng(9)
    theta = structure.initial_parameters(sigma=-5, omega=12, omega_spread=0.5) + 0.5 * rng.standard_normal(structure.n_parameters)
    theta[:5] = [-6.0, 11.0, -9.0, 30.0, -3.0]  # a stable model
    A_, B_, C_, D_ = structure.matrices(theta)
    data, _ = make_data(2, duration=4.0)
    u, y = data.u, data.y + 0.05 * np.random.default_rng(7).standard_normal(data.y.shape)
    q = np.concatenate([np.full(5, 0.5), np.zeros(structure.n_parameters)])
    R = np.diag([0.2, 0.3, 0.4])
    run = compiled_pass(LinearModalFilterModel(structure), DT, "exact", "joseph")
    state = _start_state(structure, theta, q)
    final, innovations = run(state, u, y, q, R)

    phi, gamma0, gamma1 = _foh_matrices(A_, B_, DT)
    x, P = np.zeros(5), np.diag(q[:5])
    expected = np.empty_like(y)
    for k in range(y.shape[0]):
        e = y[k] - C_ @ x - D_ @ u[k]
        expected[k] = e
        S = C_ @ P @ C_.T + R
        K = P @ C_.T @ np.linalg.inv(S)
        x = x + K @ e
        P = (np.eye(5) - K @ C_) @ P
        u_next = u[k + 1] if k + 1 < y.shape[0] else u[k]
        x = phi @ x + gamma0 @ u[k] + gamma1 @ u_next
        P = phi @ P @ phi.T + DT * np.diag(q[:5])
    assert np.allclose(innovations, expected, rtol=0, atol=1e-10)
    assert np.array_equal(final[5:5 + structure.n_parameters], theta)
    assert np.allclose(unpack_covariance(final[5 + structure.n_parameters:], 5 + structure.n_parameters)[:5, :5], P, atol=1e-10)


def test_covariance_packing_round_trip():
    rng = np.random.default_rng(8)
    M = rng.standard_normal((6, 6))
    P = M @ M.T
    assert np.array_equal(unpack_covariance(pack_covariance(P), 6), P)


def test_a_failed_generated_step_is_an_error_naming_the_sample():
    """The C driver returns 1 + the sample at which the generated step failed; that must never pass as a finished pass."""
    from vehid.identification.errors import DivergenceError
    from vehid.identification.filtering.iekf_pass import CompiledPass, build_filter_step

    structure = ModalStructure.default(2, 1, 1)
    step = build_filter_step(LinearModalFilterModel(structure), 0.01, "exact", "joseph")
    failing_at_sample_4 = lambda *args: 5  # noqa: E731  (stands in for the loaded library)
    run = CompiledPass(failing_at_sample_4, step)
    state = np.zeros(step.n_state)
    with pytest.raises(DivergenceError, match="failed at sample 4 of 10"):
        run(state, np.zeros((10, 1)), np.zeros((10, 1)), np.ones(step.n_z), np.eye(1))


def test_code_generation_leaves_the_working_directory_alone(monkeypatch):
    """Changing the process's directory would move every relative path of other threads."""
    import casadi as ca
    import os

    from vehid.identification.compiled import generate_c

    def refuse(path):
        raise AssertionError(f"os.chdir({path!r}) called during code generation")

    monkeypatch.setattr(os, "chdir", refuse)
    x = ca.SX.sym("x")
    assert "generated_twice" in generate_c(ca.Function("generated_twice", [x], [2 * x]))


@pytest.mark.parametrize("covariance", ["joseph", "paper"])
@pytest.mark.parametrize("spline", [False, True])
def test_structured_loops_equal_the_generated_step(covariance, spline):
    # The low-rank prediction and looped Joseph update are the generated step's algebra in another
    # order: 1,000 steps agree to 1e-10 relative (rounding, as against the NumPy reference above).
    from vehid.identification.models.spline_modal import SplineModalFilterModel, SplineModalStructure

    data, _ = make_data(3, outputs=(0, 1, 2), duration=2.2)
    u, y = data.u[:1000, :1], data.y[:1000]
    if spline:  # a spline model of one output: the Jacobian patterns depend on the state
        y = y[:, :1]
        linear = ModalStructure.default(2, 1, 1)
        structure = SplineModalStructure(linear, 3)
        filter_model = SplineModalFilterModel(structure)
        theta = structure.from_linear(linear.initial_parameters(sigma=-10, omega=10)) * np.linspace(0.8, 1.2, 3 * linear.n_parameters)
        constants = structure.constants(structure.default_ranges() * 3.0)
    else:
        linear = ModalStructure.from_pattern("eq18", 5, 1, 3)
        filter_model = LinearModalFilterModel(linear)
        theta = linear.initial_parameters(sigma=-10, omega=10, omega_spread=0.5)
        constants = None
    m = linear.n + theta.size
    q = np.concatenate([np.zeros(linear.n), np.full(theta.size, 0.1)])
    state = np.concatenate([np.zeros(linear.n), theta, pack_covariance(np.diag(q) + 1e-3 * np.eye(m))])
    r = np.diag(np.linspace(0.5, 1.0, y.shape[1]))
    loops = compiled_pass(filter_model, DT, "exact", covariance, kernel="structured")
    generated = compiled_pass(filter_model, DT, "exact", covariance, kernel="generated")
    state_loops, innovations_loops = loops(state, u, y, q, r, constants)
    state_generated, innovations_generated = generated(state, u, y, q, r, constants)
    assert np.max(np.abs(state_loops - state_generated)) < 1e-10 * np.max(np.abs(state_generated))
    assert np.max(np.abs(innovations_loops - innovations_generated)) < 1e-10 * np.max(np.abs(y))
    assert np.max(np.abs(state_generated - state)) > 1e-3  # the pass moved the state: the comparison can fail


def test_unknown_kernel_is_rejected():
    with pytest.raises(ValueError, match="kernel"):
        compiled_pass(LinearModalFilterModel(ModalStructure.default(2, 1, 1)), DT, "exact", "joseph", kernel="fast")


def test_a_short_run_gets_the_quick_build_with_the_same_arithmetic():
    """A run of few filter steps is built at QUICK_COMPILE_FLAGS, a long one fully optimised: two libraries,
    both within 1e-10 of the NumPy reference over 1,000 steps (the tolerance of the full build's test above;
    the two builds differ only in rounding, fused multiply-adds)."""
    data, _ = make_data(1, outputs=(0,), duration=2.2)
    structure = ModalStructure.from_pattern("all-ones", 3, 2, 1)
    filter_model = LinearModalFilterModel(structure)
    quick = compiled_pass(filter_model, DT, "exact", "joseph", expected_steps=1000)
    full = compiled_pass(filter_model, DT, "exact", "joseph", expected_steps=QUICK_COMPILE_STEPS + 1)
    assert quick._function is not full._function
    assert compiled_pass(filter_model, DT, "exact", "joseph")._function is full._function  # unknown length: full
    q = np.concatenate([np.zeros(3), np.ones(structure.n_parameters)])
    state = _start_state(structure, structure.initial_parameters(sigma=-10, omega=10, omega_spread=0.5), q)
    u, y = data.u[:1000], data.y[:1000]
    reference_state, reference_innovations = numpy_reference_pass(quick.filter_step, state, u, y, q, np.eye(1))
    for run in (quick, full):
        compiled_state, compiled_innovations = run(state, u, y, q, np.eye(1))
        assert np.max(np.abs(compiled_state - reference_state)) < 1e-10 * np.max(np.abs(reference_state))
        assert np.max(np.abs(compiled_innovations - reference_innovations)) < 1e-10 * np.max(np.abs(y))
