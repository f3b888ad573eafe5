"""Start models from the data (vehid.identification.filtering.start)."""

import numpy as np
import pytest

from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.filtering.start import (data_start, input_band_edge, lightly_damped_beyond,
                                                   reals_made_into_pairs)


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


def test_an_unstable_start_is_ranked_by_prediction():
    """Where unstable modes are allowed, the subspace model (the true unstable pole) wins the start.

    Noise-free data of order 1: the subspace model is the plant up to rounding and the hold's conversion, so its
    continuous pole is log(1.01) per sample to 1e-6. Simulated from rest it misses the record's start x(0) = 1,
    whose error grows by 1 % a sample, and a stable band start would be taken; predicted 10 samples ahead, as
    its validation scores it, it is exact.
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
    # an input held constant beside one that varies: the edge is the varying one's, not pi
    assert input_band_edge(np.column_stack([np.sin(0.1 * t), np.ones(t.size)])) == input_band_edge(sines[:, 1:])


def test_lightly_damped_modes_beyond_the_limit_are_counted_a_pair_once():
    values = np.array([-0.01 + 1j, -0.01 - 1j, -0.02 + 0.1j, -0.02 - 0.1j, 0.5, -0.9 + 0.5j, -0.9 - 0.5j])
    # the resonance beyond the limit and the growing real pole; not the one in the band, nor the damped one
    # (damping 0.9 / |-0.9 + 0.5j| = 0.87 against the band start's 0.5)
    assert lightly_damped_beyond(values, 0.3) == 2
    assert lightly_damped_beyond(values, 1.1) == 0  # every fast one within the limit
    assert lightly_damped_beyond(np.array([-0.6 + 0.8j, -0.6 - 0.8j]), 0.3) == 0  # damping 0.6: well damped
    assert lightly_damped_beyond(np.array([-0.4 + 0.9165j, -0.4 - 0.9165j]), 0.3) == 1  # damping 0.4


def test_the_real_poles_made_into_pairs_are_the_slowest_two_per_missing_pair():
    values = np.array([-0.5, -0.01 + 0.02j, -0.01 - 0.02j, -0.03, 0.02, -0.9])
    # one complex pair; a structure of two pairs makes its second from the two slowest real poles
    assert sorted(reals_made_into_pairs(values, ModalStructure.with_modes(2, 2, 1, 1))) == [-0.03, 0.02]
    # three pairs: two made, from the four real poles in order of magnitude
    assert list(reals_made_into_pairs(values, ModalStructure.with_modes(3, 0, 1, 1))) == [0.02, -0.03, -0.5, -0.9]
    assert reals_made_into_pairs(values, ModalStructure.with_modes(1, 4, 1, 1)).size == 0  # its pair is there
    # one real pole left cannot make a pair: place_eigenvalues repeats a pair instead
    assert reals_made_into_pairs(np.array([-0.1 + 0.1j, -0.1 - 0.1j, -0.2]),
                                 ModalStructure.with_modes(2, 0, 1, 1)).size == 0


def test_a_subspace_candidate_with_a_resonance_beyond_the_band_is_no_start():
    """A record whose input holds all its power below 0.05 rad/sample, and whose output adds a lightly damped
    resonance at 1 rad/sample that the input cannot have driven (an output disturbance): a second-order
    subspace model fits that resonance, and the start must not be it (the band start is taken, with a note)."""
    rng = np.random.default_rng(5)
    samples = 4000
    t = np.arange(samples)
    u = np.sin(0.01 * t) + 0.5 * np.sin(0.03 * t)
    y = np.zeros(samples)
    for k in range(1, samples):  # a first-order lag of the input, pole 0.98
        y[k] = 0.98 * y[k - 1] + 0.02 * u[k - 1]
    disturbance = np.zeros(samples)
    drive = rng.standard_normal(samples)
    radius, angle = np.exp(-0.005), 1.0  # damping 0.005 at 1 rad/sample: 32 times the input's edge (0.031)
    for k in range(2, samples):
        disturbance[k] = 2 * radius * np.cos(angle) * disturbance[k - 1] - radius**2 * disturbance[k - 2] + drive[k]
    y = y / np.std(y) + 2.0 * disturbance / np.std(disturbance)
    structure = ModalStructure.with_modes(1, 0, 1, 1)
    found = data_start(u[:, None] / np.std(u), y[:, None] / np.std(y), structure)
    assert "beyond the input's band" in found.note and "left out" in found.note, found.note
    assert found.source == "band"


@pytest.mark.parametrize("excitation_seed, noise_seed, order, p",
                         [(2, 12, 6, 1e-5), (0, 11, 7, 1e-4), (1, 11, 5, 1e-5), (4, 12, 4, 1e-4)])
def test_sensor_noise_on_the_handling_records_costs_little(excitation_seed, noise_seed, order, p):
    """The handling study's record with its sensor noise.

    Before the start's band limit, the subspace start put a resonance of the noise (damping 0.006, three
    times the steer's band) into the model: the first case diverged (last good pass 11.3 points below the
    noise-free run), the second lost 54 points. With that mode moved into the band the third lost 3.9
    points: the subspace model had merged the two pairs in the band into one. At n = 4 every subspace
    candidate of the fourth case has one pair and two real poles, one of them the noise's beyond the
    band; the pair the structure needs, made of the two, diverged at the first pass and its restarts down
    to p 1e-6 did not recover. The issue's target is at most 3 points lost against the same record without
    noise, scored on the noise-free validation record; measured with such candidates left out: -0.4, 1.7,
    2.0 and 0.5 points (over the 30 runs each at n = 4 and n = 5 of ``benchmarks/noisy_handling.py``: at
    most 0.9 and 2.6).
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
