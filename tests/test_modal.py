"""Modal structures and models: the paper's C patterns, packing, exact simulation against SciPy."""

import json

import numpy as np
import pytest
from scipy.io import loadmat
from scipy.signal import lsim

from vehid.identification.errors import InputError
from vehid.identification.models.modal import ModalModel, phi_functions
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.linear_example import true_model


def _pattern(rows):
    return np.array([list(row.replace(" ", "")) for row in rows], dtype=object)


def _c_pattern(structure: ModalStructure) -> np.ndarray:
    """The structure's C as the paper writes it: '1' fixed, 'c' free."""
    pattern = np.full((structure.n_y, structure.n), "c", dtype=object)
    for i, j in structure.fixed_c:
        pattern[i, j] = "1"
    return pattern


@pytest.mark.parametrize(
    "name, n, expected",
    [
        # Best & Bogdanski 2017, eq. 18 and eq. 19 ('1' fixed, 'c' free)
        ("eq18", 5, ["11ccc", "cc11c", "cccc1"]),
        ("eq19", 3, ["11c", "cc1", "ccc"]),
        ("eq19", 4, ["11cc", "cc11", "cccc"]),
        ("eq19", 6, ["11cccc", "cc11cc", "cccc11"]),
        ("eq19", 7, ["11ccccc", "cc11ccc", "cccc111"]),
        ("all-ones", 5, ["11111", "ccccc", "ccccc"]),
    ],
)
def test_paper_c_patterns(name, n, expected):
    structure = ModalStructure.from_pattern(name, n, 2, 3)
    assert (_c_pattern(structure) == _pattern(expected)).all()


def test_default_pattern_generalises_eq18_and_ties_single_output_to_all_ones():
    assert (_c_pattern(ModalStructure.default(5, 2, 3)) == _pattern(["11ccc", "cc11c", "cccc1"])).all()
    assert (_c_pattern(ModalStructure.default(4, 1, 1)) == _pattern(["1111"])).all()
    # more modes than outputs: assigned in turn, wrapping
    assert (_c_pattern(ModalStructure.default(7, 1, 2)) == _pattern(["11cc11c", "cc11cc1"])).all()


def test_parameter_count_matches_the_paper_filter_sizes():
    # single output, n = 5, two inputs: 5 modal + 10 B + 0 C + 2 D = 17 (22 filter states with x)
    assert ModalStructure.from_pattern("all-ones", 5, 2, 1).n_parameters == 17
    assert ModalStructure.from_pattern("eq18", 5, 2, 3).n_parameters == 5 + 10 + 10 + 6


def test_pack_unpack_round_trip_and_names():
    structure = ModalStructure.from_pattern("eq18", 5, 2, 3)
    theta = np.random.default_rng(0).standard_normal(structure.n_parameters)
    A, B, C, D = structure.matrices(theta)
    assert np.array_equal(structure.pack(A, B, C, D), theta)
    assert A[0, 1] == theta[1] and A[1, 0] == -theta[1] and A[0, 0] == A[1, 1] == theta[0]
    assert len(structure.parameter_names()) == structure.n_parameters
    with pytest.raises(InputError, match="modal block form"):
        structure.pack(A + np.triu(np.ones_like(A), 2), B, C, D)
    with pytest.raises(InputError, match="shape"):
        structure.pack(A, B[:, :1], C, D)


def test_bad_structures_are_refused():
    with pytest.raises(InputError, match="one C entry per state"):
        ModalStructure(1, 1, 1, 1, ((0, 0), (0, 1)))
    with pytest.raises(InputError, match="both its fixed C entries"):
        ModalStructure(1, 0, 1, 2, ((0, 0), (1, 1)))
    with pytest.raises(InputError, match="three outputs"):
        ModalStructure.from_pattern("eq18", 5, 2, 1)
    with pytest.raises(InputError, match="unknown C pattern"):
        ModalStructure.from_pattern("eq20", 5, 2, 3)


def test_eigenvalues_frequency_and_damping_of_eq15():
    model = true_model()
    expected = np.array([-15 + 10j, -15 - 10j, -8 + 40j, -8 - 40j, -4])
    assert np.allclose(model.eigenvalues(), expected, atol=0)
    modes = model.modes()
    natural = np.array([np.hypot(15, 10), np.hypot(8, 40), 4.0])
    assert np.allclose([mode.frequency_hz for mode in modes], natural / (2 * np.pi), rtol=1e-14)
    assert np.allclose([mode.damping for mode in modes], [15 / np.hypot(15, 10), 8 / np.hypot(8, 40), 1.0], rtol=1e-14)


def test_foh_simulation_equals_scipy_lsim():
    # lsim integrates exactly for inputs linear between samples: agreement to rounding (~1e-12 of the signal)
    model = true_model()
    rng = np.random.default_rng(3)
    dt, n = 0.002, 4000
    u = rng.standard_normal((n, 2))
    x0 = rng.standard_normal(5)
    t = np.arange(n) * dt
    _, y_ref, _ = lsim((model.A, model.B, model.C, model.D), u, t, X0=x0)
    y = model.simulate_outputs(u, dt, method="foh", x0=x0)
    assert np.max(np.abs(y - y_ref)) < 1e-11 * np.max(np.abs(y_ref))


def test_zoh_and_euler_simulation_equal_their_recursions():
    model = true_model()
    rng = np.random.default_rng(4)
    dt, n = 0.002, 500
    u = rng.standard_normal((n, 2))
    from scipy.linalg import expm

    big = np.zeros((7, 7))
    big[:5, :5], big[:5, 5:] = model.A * dt, model.B * dt
    block = expm(big)
    x_zoh, x_eul = np.zeros(5), np.zeros(5)
    y_zoh, y_eul = np.empty((n, 3)), np.empty((n, 3))
    for k in range(n):
        y_zoh[k] = model.C @ x_zoh + model.D @ u[k]
        y_eul[k] = model.C @ x_eul + model.D @ u[k]
        x_zoh = block[:5, :5] @ x_zoh + block[:5, 5:] @ u[k]
        x_eul = x_eul + dt * (model.A @ x_eul + model.B @ u[k])
    assert np.allclose(model.simulate_outputs(u, dt, method="zoh"), y_zoh, rtol=0, atol=1e-11)
    assert np.allclose(model.simulate_outputs(u, dt, method="euler"), y_eul, rtol=0, atol=1e-11)


def test_phi_functions_series_and_closed_forms_meet():
    # across the switch at |z| = 1e-3 the two forms agree to ~1e-13 (series truncation z^4/120, cancellation eps/|z|^2)
    for z in (0.999e-3, 1.001e-3, 0.999e-3j, 1.001e-3 * (1 + 1j) / np.sqrt(2)):
        phi1, phi2 = phi_functions(z)
        exact1 = complex(np.expm1(complex(z)) / z)
        exact2 = complex((np.expm1(complex(z)) - z) / z**2)
        assert abs(complex(phi1) - exact1) < 1e-12 and abs(complex(phi2) - exact2) < 1e-9


def test_model_exports_round_trip(tmp_path):
    model = true_model()
    again = ModalModel.from_dict(json.loads(model.save_json(tmp_path / "m.json").read_text()))
    for name in "ABCD":
        assert np.array_equal(getattr(again, name), getattr(model, name))
    assert again.structure == model.structure
    mat = loadmat(model.save_mat(tmp_path / "m.mat"))
    assert np.array_equal(mat["A"], model.A) and mat["C_fixed"].sum() == 5


def test_model_rejects_bad_input():
    model = true_model()
    with pytest.raises(InputError, match=r"u must have shape \(N, 2\)"):
        model.simulate_outputs(np.zeros((10, 3)), 0.01)
    with pytest.raises(InputError, match="non-finite"):
        model.simulate_outputs(np.full((10, 2), np.nan), 0.01)
    with pytest.raises(InputError, match="B has shape"):
        ModalModel(model.structure, model.A, model.B[:, :1], model.C, model.D)


def _two_input_two_output_model() -> ModalModel:
    """Two pairs (one fast: |lambda dt| = 0.25 at dt = 0.01) and a real pole; B, free C and D drawn at random."""
    structure = ModalStructure.default(5, 2, 2)
    theta = np.random.default_rng(3).normal(size=structure.n_parameters)
    theta[:5] = [-2.0, 7.0, -5.0, 25.0, -3.0]
    return ModalModel.from_parameters(structure, theta)


@pytest.mark.parametrize("method", ["foh", "zoh", "euler"])
def test_output_sensitivity_equals_central_differences_of_the_simulation(method):
    """Each column of the exact Jacobian against central differences of :meth:`simulate_outputs`.

    With a step of 1e-5 (relative, at least 1e-5) the central difference
    errs by h^2 y''' / 6 (~1e-10 of the column) plus rounding eps |y| / h
    (~1e-11); 1e-7 of each column's largest value leaves room for both,
    while a missing term of the hold's derivative errs by O(lambda dt), 1e-2 here.
    """
    model = _two_input_two_output_model()
    u = np.random.default_rng(5).normal(size=(400, 2))
    dt = 0.01
    y, sensitivity = model.output_sensitivity(u, dt, method=method)
    assert sensitivity.shape == (400, 2, model.structure.n_parameters)
    np.testing.assert_allclose(y, model.simulate_outputs(u, dt, method=method), rtol=0, atol=1e-12)
    theta = model.parameters
    for index in range(theta.size):
        step = 1e-5 * max(abs(theta[index]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[index] += step
        down[index] -= step
        difference = (ModalModel.from_parameters(model.structure, up).simulate_outputs(u, dt, method=method)
                      - ModalModel.from_parameters(model.structure, down).simulate_outputs(u, dt, method=method)) / (2 * step)
        scale = np.abs(difference).max()
        assert np.abs(sensitivity[:, :, index] - difference).max() < 1e-7 * scale, model.structure.parameter_names()[index]


@pytest.mark.parametrize("method", ["foh", "euler"])
def test_free_response_sensitivity_equals_central_differences_of_the_simulation(method):
    """The free response from x0 is a simulation from x0 less one from rest; its derivatives in the
    parameters and in x0 match central differences (step and tolerance as for the forced response)."""
    model = _two_input_two_output_model()
    x0 = np.random.default_rng(6).normal(size=model.n_states)
    zero, dt = np.zeros((400, 2)), 0.01
    y, by_parameters, by_state = model.free_response_sensitivity(x0, 400, dt, method=method)
    np.testing.assert_allclose(y, model.simulate_outputs(zero, dt, x0=x0, method=method), rtol=0, atol=1e-12)

    def free(theta, state):
        return ModalModel.from_parameters(model.structure, theta).simulate_outputs(zero, dt, x0=state, method=method)

    for point, columns, shift in ((model.parameters, by_parameters, lambda p: free(p, x0)),
                                  (x0, by_state, lambda s: free(model.parameters, s))):
        for index in range(point.size):
            step = 1e-5 * max(abs(point[index]), 1.0)
            up, down = point.copy(), point.copy()
            up[index] += step
            down[index] -= step
            difference = (shift(up) - shift(down)) / (2 * step)
            assert np.abs(columns[:, :, index] - difference).max() <= 1e-7 * max(np.abs(difference).max(), 1e-12), index


def test_output_sensitivity_rejects_bad_input_by_name():
    model = _two_input_two_output_model()
    with pytest.raises(InputError, match="u must have shape"):
        model.output_sensitivity(np.zeros((10, 3)), 0.01)
    with pytest.raises(InputError, match="unknown simulation method"):
        model.output_sensitivity(np.zeros((10, 2)), 0.01, method="rk4")
