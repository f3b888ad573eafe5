"""Start models from the data (identification.start)."""

import numpy as np
import pytest

from vehid.identification.models.modal import ModalStructure
from vehid.identification.filtering.start import damped_beyond_band, data_start, input_band_edge


def _unstable_record():
    """x(k+1) = 1.01 x(k) + u(k), y = x, from x(0) = 1, under feedback u = -0.05 y + w (w white).

    The plant is open-loop unstable; the feedback keeps the record bounded (closed-loop pole 0.96).
    """
    rng = np.random.default_rng(3)
    samples = 1500
    w = rng.standard_normal(samples)
    x, u, y = 1.0, np.zeros(samples), np.zeros(samples)
    for k in range(samples):
        y[k] = x
        u[k] = -0.05 * x + w[k]
        x = 1.01 * x + u[k]
    return u[:, None] / np.sqrt(np.mean(u**2)), y[:, None] / np.sqrt(np.mean(y**2))


def test_an_unstable_start_is_scored_from_its_estimated_initial_state():
    """Where unstable modes are allowed, the subspace model (the true unstable pole) wins the start.

    Noise-free data of order 1: the subspace model is the plant up to rounding and the hold's conversion, so its
    continuous pole is log(1.01) per sample to 1e-6. Simulated from rest it misses the record's start x(0) = 1,
    whose error grows by 1 % a sample, and a stable band start would be taken; from the least-squares initial
    state it is exact.
    """
    u, y = _unstable_record()
    structure = ModalStructure.default(1, 1, 1)
    found = data_start(u, y, structure, stable=False)
    assert found.source == "subspace"
    assert abs(found.model.mode_eigenvalues()[0] - np.log(1.01)) < 1e-6 * np.log(1.01)


def test_the_input_band_edge_of_sines_is_their_highest_frequency_and_of_white_noise_the_nyquist_frequency():
    # tapered, a sine's power stays within a few bins of its frequency (a bin is pi/2000 rad/sample here)
    t = np.arange(4000)
    sines = np.column_stack([np.sin(0.05 * t) + 0.5 * np.sin(0.3 * t), np.sin(0.1 * t)])
    assert 0.3 <= input_band_edge(sines) <= 0.3 + 0.02
    white = np.random.default_rng(0).standard_normal((4000, 1))
    assert input_band_edge(white) > 3.0  # all but 1e-4 of white noise's power lies below pi (1 - 1e-4) on average
    assert input_band_edge(np.ones((100, 1))) == np.pi  # no variance: the input bounds nothing


def test_lightly_damped_modes_beyond_the_limit_move_to_it_with_the_band_damping():
    values = np.array([-0.01 + 1j, -0.01 - 1j, -0.02 + 0.1j, -0.02 - 0.1j, 0.5, -0.9 + 0.5j, -0.9 - 0.5j])
    moved, count = damped_beyond_band(values, 0.3)
    assert count == 2  # the resonance beyond the limit and the growing real pole; a pair counts once
    np.testing.assert_allclose(moved[:2], 0.3 * (-0.5 + np.array([1j, -1j]) * np.sqrt(0.75)), rtol=1e-12)
    assert moved[4] == -0.3
    np.testing.assert_array_equal(moved[[2, 3, 5, 6]], values[[2, 3, 5, 6]])  # in the band, or well damped


@pytest.mark.parametrize("excitation_seed, noise_seed, order, p", [(2, 12, 6, 1e-5), (0, 11, 7, 1e-4)])
def test_sensor_noise_on_the_handling_records_costs_little_at_high_orders(excitation_seed, noise_seed, order, p):
    """The handling study's record with its sensor noise, at orders above what the dynamics need.

    Before the start's band limit, the subspace start put a resonance of the noise (damping 0.006, three
    times the steer's band) into the model: the first case diverged (last good pass 11.3 points below the
    noise-free run), the second lost 54 points. The issue's target is at most 3 points lost against the
    same record without noise, scored on the noise-free validation record; measured 0.0 and 1.7 points.
    """
    from vehid.identification.assessment.validation import score
    from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
    from vehid.scenarios.handling_study import HandlingConfig, make_records, with_sensor_noise

    records = make_records(HandlingConfig(duration=10.0, amplitude_scale=0.1, seed=excitation_seed))
    noisy = with_sensor_noise(records, noise_seed)["identification"]
    structure = ModalStructure.default(order, noisy.n_u, noisy.n_y)
    options = IEKFOptions.invariant(p=p, passes=50)
    fits = [float(np.mean(score(identify_iekf(data, structure, options=options, parameter_covariance=False).model,
                                records["validation"]).fit))
            for data in (records["identification"], noisy)]  # a DivergenceError fails the test
    assert fits[0] - fits[1] < 3.0
