"""State-space conversions: hold equivalents, modal form, balanced truncation, subspace identification."""

import numpy as np
import pytest

from vehid.identification import ExcitationError, InputError
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.models.statespace import (balanced_truncation, continuous_to_discrete, discrete_to_continuous,
                                             modal_structure_for, to_modal)
from vehid.identification.classical.subspace import estimate_subspace, estimate_subspace_states
from vehid.scenarios.linear_example import identification_input, true_model

ALGEBRA = 1e-9  # matrix exponentials and eigen-decompositions of 5-state models


def _frequency_response(A, B, C, D, frequencies=(0.1, 3.0, 40.0)):
    return np.array([C @ np.linalg.solve(1j * w * np.eye(A.shape[0]) - A, B) + D for w in frequencies])


@pytest.mark.parametrize("hold", ["foh", "zoh"])
def test_hold_equivalent_round_trip(hold):
    model = true_model(3)
    discrete = continuous_to_discrete(model.A, model.B, model.C, model.D, 0.002, hold=hold)
    back = discrete_to_continuous(*discrete, 0.002, hold=hold)
    np.testing.assert_allclose(_frequency_response(*back), _frequency_response(model.A, model.B, model.C, model.D),
                               atol=ALGEBRA)


def test_first_order_hold_equivalent_equals_the_exact_simulation():
    """The discrete FOH model reproduces ModalModel.simulate_outputs(method='foh') sample by sample.

    Its state is xi = x - G2 u, so from rest it starts at -G2 u(0): the input starts at 0 here.
    """
    model = true_model(3)
    _, u = identification_input(1, duration=2.0)
    u[0] = 0.0
    Ad, Bd, Cd, Dd = continuous_to_discrete(model.A, model.B, model.C, model.D, 0.002)
    x = np.zeros(5)
    y = np.zeros((u.shape[0], 3))
    for k in range(u.shape[0]):
        y[k] = Cd @ x + Dd @ u[k]
        x = Ad @ x + Bd @ u[k]
    np.testing.assert_allclose(y, model.simulate_outputs(u, 0.002, method="foh"), atol=ALGEBRA)


def _random_continuous(seed, n_y=3):
    rng = np.random.default_rng(seed)
    blocks = np.diag([-4.0, -2.0, -1.0, -7.0, -0.5])
    blocks[0, 1], blocks[1, 0] = 9.0, -9.0
    blocks[2, 3], blocks[3, 2] = 3.0, -3.0  # pairs -3 +/- 9j and -4 +/- 3j (diagonals fixed below)
    blocks[2, 2] = blocks[3, 3] = -4.0
    blocks[0, 0] = blocks[1, 1] = -3.0
    basis = rng.standard_normal((5, 5)) + 2 * np.eye(5)
    A = basis @ blocks @ np.linalg.inv(basis)
    return A, rng.standard_normal((5, 2)), rng.standard_normal((n_y, 5)), rng.standard_normal((n_y, 2))


@pytest.mark.parametrize("n_y", [1, 3])
def test_to_modal_keeps_the_transfer_function_and_fixes_c(n_y):
    system = _random_continuous(0, n_y)
    model = to_modal(*system)
    assert model.structure == ModalStructure.default(5, 2, n_y)
    for i, j in model.structure.fixed_c:
        assert model.C[i, j] == 1.0
    np.testing.assert_allclose(_frequency_response(model.A, model.B, model.C, model.D),
                               _frequency_response(*system), atol=ALGEBRA)
    np.testing.assert_allclose(np.sort_complex(model.eigenvalues()), np.sort_complex(np.linalg.eigvals(system[0])),
                               atol=ALGEBRA)


def test_to_modal_explains_what_it_cannot_do():
    A, B, C, D = _random_continuous(1, 1)
    model = to_modal(A, B, C, D)
    hidden = model.C.copy()
    hidden[0, 4] = 0.0  # the real mode no longer reaches output 1, to which it is tied
    with pytest.raises(InputError, match="unobservable from output 1"):
        to_modal(model.A, model.B, hidden, model.D)
    with pytest.raises(InputError, match="2 complex pairs and 1 real poles but the structure 1 and 3"):
        to_modal(A, B, C, D, ModalStructure(1, 3, 2, 1, tuple((0, j) for j in range(5))))
    jordan = np.array([[-1.0, 1.0], [0.0, -1.0]])
    with pytest.raises(InputError, match="not diagonalisable"):
        to_modal(jordan, np.ones((2, 1)), np.ones((1, 2)), np.zeros((1, 1)))
    with pytest.raises(InputError, match="negative real axis"):
        discrete_to_continuous([[-0.5]], [[1.0]], [[1.0]], [[0.0]], 0.01)


def test_structure_follows_the_eigenvalues():
    four_real = np.diag([-1.0, -2.0, -3.0, -4.0, -5.0])
    structure = modal_structure_for(four_real, 1, 2)
    assert (structure.n_complex_pairs, structure.n_real) == (0, 5)
    assert structure.fixed_c[:2] == ((0, 0), (0, 2))  # modes tied to outputs in turn


def test_balanced_truncation_removes_duplicated_states():
    model = true_model(1)
    Ad, Bd, Cd, Dd = continuous_to_discrete(model.A, model.B, model.C, model.D, 0.01)
    doubled = (np.kron(np.eye(2), Ad), np.vstack([Bd, Bd]), np.hstack([Cd, Cd]) / 2, Dd)
    reduced = balanced_truncation(*doubled, 5)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(reduced[0])), np.sort_complex(np.linalg.eigvals(Ad)),
                               atol=1e-8)  # Lyapunov solutions at 1e-12, amplified by the pole spread
    assert reduced[4][5] < 1e-10 * reduced[4][0]
    with pytest.raises(InputError, match="fewer than 6"):
        balanced_truncation(*doubled, 6)


def test_subspace_rejects_too_high_an_order_and_too_short_records():
    model = true_model(1)
    _, u = identification_input(2, duration=4.0)
    y = model.simulate_outputs(u, 0.002)
    fit = estimate_subspace((u, y), order=5)
    assert fit.singular_values[5] < 1e-9 * fit.singular_values[0]  # five states, no more
    with pytest.raises(ExcitationError, match="fewer than 7 states"):
        estimate_subspace((u, y), order=7)
    with pytest.raises(InputError, match="too few"):
        estimate_subspace((u[:30], y[:30]), order=5)


def test_subspace_model_does_not_depend_on_signal_units():
    """Channels rescaled by 1e-6 ... 1e6 give the same eigenvalues and the model's gains scaled by the factors.

    Each column is divided by its RMS before the subspace steps, so the scaled and unscaled problems are the
    same numbers up to rounding: 1e-8 relative leaves room for its amplification through the SVD and the
    least-squares solves (about the condition number of the B, D regression times 1e-16).
    """
    model = true_model(3)
    _, u = identification_input(3, duration=4.0)
    y = model.simulate_outputs(u, 0.002)
    y = y + 1e-3 * np.std(y, axis=0) * np.random.default_rng(0).standard_normal(y.shape)
    input_factor = np.geomspace(1e-6, 1e6, u.shape[1])
    output_factor = np.geomspace(1e6, 1e-6, y.shape[1])
    plain = estimate_subspace((u, y), order=5)
    scaled = estimate_subspace((u * input_factor, y * output_factor), order=5)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(scaled.A)),
                               np.sort_complex(np.linalg.eigvals(plain.A)), rtol=1e-8)
    np.testing.assert_allclose(scaled.A, plain.A, rtol=1e-8, atol=1e-8)
    np.testing.assert_allclose(scaled.B * input_factor, plain.B, rtol=1e-8, atol=1e-8 * np.abs(plain.B).max())
    np.testing.assert_allclose(scaled.C / output_factor[:, None], plain.C, rtol=1e-8,
                               atol=1e-8 * np.abs(plain.C).max())
    np.testing.assert_allclose(scaled.residuals / output_factor, plain.residuals, rtol=1e-6,
                               atol=1e-8 * np.abs(plain.residuals).max())


def test_subspace_recovers_an_open_loop_unstable_plant_from_a_closed_loop_record():
    """Noise-free record of a plant with a pole at z = 1.03 under output feedback: exact eigenvalues and response.

    One simulation over 1000 samples weights the last by 1.03^1000 (7e12): B and D could not be solved
    for at all ("rank-deficient regression"). Over segments with their own initial states they are exact
    up to rounding: measured 1e-11 relative on the frequency response, 2e-14 on the eigenvalues; the
    bounds leave a hundredfold for other BLAS builds.
    """
    dt, samples = 0.1, 1000
    A = np.zeros((4, 4))
    A[0, 0], A[1, 1], A[2:, 2:] = 0.3, -0.5, [[-1.0, 3.0], [-3.0, -1.0]]
    B, C = np.array([[1.0], [1.0], [0.0], [2.0]]), np.array([[1.0, -0.6, 1.0, 0.0]])
    Ad, Bd, Cd, Dd = continuous_to_discrete(A, B, C, np.zeros((1, 1)), dt, hold="zoh")
    assert np.max(np.abs(np.linalg.eigvals(Ad))) > 1.03  # open-loop unstable
    assert np.max(np.abs(np.linalg.eigvals(Ad - Bd @ Cd))) < 1.0  # u = r - y keeps the loop stable
    reference = np.repeat(np.random.default_rng(0).standard_normal(samples // 10), 10)
    x, u, y = np.zeros(4), np.zeros((samples, 1)), np.zeros((samples, 1))
    for k in range(samples):
        y[k] = Cd @ x
        u[k] = reference[k] - y[k]
        x = Ad @ x + Bd @ u[k]
    fit = estimate_subspace((u, y), order=4)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)), np.sort_complex(np.linalg.eigvals(Ad)),
                               atol=2e-12)
    z = np.exp(1j * np.array([0.1, 0.3, 1.0, 3.0]) * dt)
    response = lambda a, b, c, d: np.array([c @ np.linalg.solve(v * np.eye(4) - a, b) + d for v in z])  # noqa: E731
    truth = response(Ad, Bd, Cd, Dd)
    np.testing.assert_allclose(response(fit.A, fit.B, fit.C, fit.D), truth, atol=1e-9 * np.abs(truth).min())
    # from rest and noise-free: the first segment's initial state is zero and every segment's residual vanishes
    # (measured 2e-15 and 7e-14 of an output up to 2.4; each segment's state is eliminated from its own rows)
    assert np.abs(fit.x0).max() < 1e-12
    assert np.abs(fit.residuals).max() < 1e-11 * np.abs(y).max()


def _closed_loop_unstable_record(seed: int, samples: int = 1000):
    """The plant of the test above (a pole at z = 1.03) under u = r - y, noise-free; and its discrete model."""
    dt = 0.1
    A = np.zeros((4, 4))
    A[0, 0], A[1, 1], A[2:, 2:] = 0.3, -0.5, [[-1.0, 3.0], [-3.0, -1.0]]
    B, C = np.array([[1.0], [1.0], [0.0], [2.0]]), np.array([[1.0, -0.6, 1.0, 0.0]])
    Ad, Bd, Cd, Dd = continuous_to_discrete(A, B, C, np.zeros((1, 1)), dt, hold="zoh")
    reference = np.repeat(np.random.default_rng(seed).standard_normal(samples // 10), 10)
    x, u, y = np.zeros(4), np.zeros((samples, 1)), np.zeros((samples, 1))
    for k in range(samples):
        y[k] = Cd @ x
        u[k] = reference[k] - y[k]
        x = Ad @ x + Bd @ u[k]
    return (u, y), (Ad, Bd, Cd, Dd), dt


def test_the_state_sequence_recovers_an_open_loop_unstable_plant_from_a_closed_loop_record():
    """N4SID's state sequence on the same noise-free closed-loop record: exact eigenvalues and response.

    Noise-free, the oblique projection is exactly the observability matrix times the states, so the
    one-step regression is exact up to rounding (measured at most 4e-15 on the eigenvalues, 4e-13
    relative on the frequency response and 2e-15 of the output in the residuals, by default, under the
    Sandybridge kernel and with one BLAS thread; the bounds leave a hundredfold and more). Two records
    joined give the same model.
    """
    (u, y), (Ad, Bd, Cd, Dd), dt = _closed_loop_unstable_record(0)
    z = np.exp(1j * np.array([0.1, 0.3, 1.0, 3.0]) * dt)
    response = lambda a, b, c, d: np.array([c @ np.linalg.solve(v * np.eye(4) - a, b) + d for v in z])  # noqa: E731
    truth = response(Ad, Bd, Cd, Dd)
    second, _, _ = _closed_loop_unstable_record(1, samples=600)
    for data in ((u, y), [(u, y), second]):
        fit = estimate_subspace_states(data, order=4, block_rows=10)
        np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(fit.A)),
                                   np.sort_complex(np.linalg.eigvals(Ad)), atol=4e-12)
        np.testing.assert_allclose(response(fit.A, fit.B, fit.C, fit.D), truth, atol=1e-10 * np.abs(truth).min())
        assert np.abs(fit.residuals).max() < 1e-10 * np.abs(y).max()
    assert fit.residuals.shape == (1000 - 2 * 10 + 1 + 600 - 2 * 10 + 1, 1)  # from sample s of each record


def test_the_state_sequence_does_not_depend_on_signal_units_and_names_what_it_cannot_do():
    """Columns rescaled by 1e-6 and 1e6 give the same eigenvalues and the gains scaled back (each column is
    divided by its RMS first: the same numbers up to rounding); too high an order or too short a record is
    refused with the reason."""
    (u, y), _, _ = _closed_loop_unstable_record(2)
    y = y + 1e-3 * np.std(y) * np.random.default_rng(3).standard_normal(y.shape)
    plain = estimate_subspace_states((u, y), order=4, block_rows=10)
    scaled = estimate_subspace_states((u * 1e-6, y * 1e6), order=4, block_rows=10)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(scaled.A)),
                               np.sort_complex(np.linalg.eigvals(plain.A)), rtol=1e-8)
    np.testing.assert_allclose(scaled.D * 1e-6 / 1e6, plain.D, atol=1e-8 * max(np.abs(plain.D).max(), 1e-3))
    with pytest.raises(InputError, match="cannot reveal"):
        estimate_subspace_states((u, y), order=12, block_rows=10)
    with pytest.raises(InputError, match="too few"):
        estimate_subspace_states((u[:40], y[:40]), order=4, block_rows=10)
