"""Steer manoeuvres: seeded, starting from zero, shaped as documented."""

import math

import numpy as np
import pytest

from vehid.identification.errors import InputError
from vehid.vehicle.manoeuvres import MANOEUVRES, band_limited_noise, identification, make_manoeuvre, step, validation


@pytest.mark.parametrize("name", sorted(MANOEUVRES))
def test_seeded_and_starting_from_zero(name):
    first = make_manoeuvre(name, seed=3, duration=6.0)
    again = make_manoeuvre(name, seed=3, duration=6.0)
    assert first.steer[0] == 0.0 and first.n_samples == 3001 and first.dt == pytest.approx(0.002)
    np.testing.assert_array_equal(first.steer, again.steer)
    assert first.meta["manoeuvre"] == name


def test_seeds_differ_where_there_is_randomness():
    assert not np.array_equal(identification(seed=1).steer, identification(seed=2).steer)
    assert not np.array_equal(validation(seed=1).steer, validation(seed=2).steer)


def test_noise_is_band_limited_to_25_hz():
    """No spectral content above 25 Hz (ideal filter: round-off only) and unit RMS."""
    noise = band_limited_noise(15001, 0.002, 25.0, np.random.default_rng(0))
    spectrum = np.abs(np.fft.rfft(noise))
    above = np.fft.rfftfreq(noise.size, 0.002) > 25.0
    assert np.max(spectrum[above]) < 1e-10 * np.max(spectrum)
    assert np.sqrt(np.mean(noise**2)) == pytest.approx(1.0, rel=1e-12)


def test_step_shape():
    """ISO 7401 style: zero until 0.5 s, a 0.1 s ramp, then the amplitude held."""
    manoeuvre = step(amplitude=math.radians(2.0), duration=3.0)
    t, steer = manoeuvre.t, manoeuvre.steer
    assert np.all(steer[t <= 0.5] == 0.0)
    np.testing.assert_allclose(steer[t >= 0.6 + 1e-9], math.radians(2.0), rtol=1e-12)


def test_validation_ends_with_growing_steps():
    manoeuvre = validation(amplitude=math.radians(3.0))
    second_half = manoeuvre.steer[manoeuvre.t > 15.0]
    assert np.max(np.abs(second_half)) == pytest.approx(1.3 * math.radians(3.0), rel=1e-12)


@pytest.mark.parametrize("options", [{"duration": 0.0}, {"duration": -2.0}, {"dt": 0.0},
                                     {"amplitude": float("nan")}, {"amplitude": math.radians(40.0)}])
def test_bad_manoeuvre_options(options):
    with pytest.raises(InputError):
        make_manoeuvre("step", **options)


@pytest.mark.parametrize("name", sorted(MANOEUVRES))
@pytest.mark.parametrize("seed", [-1, 1.5, "7", True])
def test_bad_seed_is_named(name, seed):
    """NumPy's generators take non-negative integers only; anything else is bad input, not a crash."""
    with pytest.raises(InputError, match="seed must be a non-negative integer"):
        make_manoeuvre(name, seed=seed)


def test_unknown_manoeuvre():
    with pytest.raises(InputError, match="unknown manoeuvre"):
        make_manoeuvre("slalom")
