"""Start models from the data (identification.start)."""

import numpy as np

from vehid.identification.models.modal import ModalStructure
from vehid.identification.filtering.start import data_start


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
