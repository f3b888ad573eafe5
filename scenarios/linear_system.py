"""The paper's linear test system (Best & Bogdanski 2017, eq. 15) and its input (eq. 16).

The system has five states: a real pole at -4 and complex pairs
-15 +/- 10j and -8 +/- 40j, two inputs and three outputs. The identification
input (eq. 16) is, per input, 5,000 N(0, 1) samples taken as 50 Hz points over
100 s, linearly interpolated to 500 Hz, plus an offset (+0.1 on input 1,
-0.1 on input 2). Outputs come from the exact simulation of the continuous
model for inputs linear between samples (first-order hold), from rest.

The true model is written in the workbench's pairs-first modal form: the
paper lists the real pole first, so its states are reordered (pairs, then the
real pole); the first row of C stays all ones. With one output this is
``ModalStructure.default(5, 2, 1)``; with three, the ``all-ones`` pattern
(the first row of C fixed, Table 2 of the paper).

Used by the classical comparators' tests and benchmark; it reproduces no
table by itself.
"""

from __future__ import annotations

import numpy as np

from identification.data import IOData
from identification.errors import InputError
from identification.modal import ModalModel, ModalStructure

__all__ = ["PAPER_A", "PAPER_B", "PAPER_C", "PAPER_D", "true_model", "identification_input", "linear_example_data"]

# Eq. 15, in the paper's state order (real pole first).
PAPER_A = np.array([
    [-4.0, 0, 0, 0, 0],
    [0, -15, 10, 0, 0],
    [0, -10, -15, 0, 0],
    [0, 0, 0, -8, 40],
    [0, 0, 0, -40, -8],
])
PAPER_B = np.array([[0.1, 0.1], [0.3, -3], [1.5, 0], [10, -0.5], [0.7, 1]])
PAPER_C = np.array([
    [1, 1, 1, 1, 1],
    [2, 0.3, 0.35, -1.35, -0.06],
    [2.75, -1.3, 3.6, 1.4, 0.77],
])
PAPER_D = np.array([[0, 0], [1.5, 0.67], [-0.2, 1.4]])

_PAIRS_FIRST = [1, 2, 3, 4, 0]  # the paper's states in the workbench's order

SAMPLE_RATE = 500.0  # [Hz] the paper's T = 0.002 s
KNOT_RATE = 50.0  # [Hz] the N(0, 1) points, interpolated linearly (eq. 16)
OFFSETS = (0.1, -0.1)  # eq. 16


def true_model(n_outputs: int = 1) -> ModalModel:
    """The eq. 15 system in pairs-first modal form, with its first ``n_outputs`` outputs (1 or 3)."""
    if n_outputs not in (1, 3):
        raise InputError(f"the linear example has 1 or 3 outputs; got {n_outputs}")
    order = _PAIRS_FIRST
    structure = (ModalStructure.default(5, 2, 1) if n_outputs == 1
                 else ModalStructure.from_pattern("all-ones", 5, 2, 3))
    return ModalModel(
        structure,
        PAPER_A[np.ix_(order, order)],
        PAPER_B[order],
        PAPER_C[:n_outputs][:, order],
        PAPER_D[:n_outputs],
        meta={"source": "Best & Bogdanski 2017, eq. 15"},
    )


def identification_input(seed: int = 0, *, duration: float = 100.0) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 16: times (N,) and inputs (N, 2) at 500 Hz from N(0, 1) points at 50 Hz plus offsets."""
    if not duration > 0:
        raise InputError(f"duration must be positive; got {duration}")
    rng = np.random.default_rng(seed)
    n_knots = int(round(duration * KNOT_RATE))
    knots = rng.standard_normal((n_knots, 2))
    t_knots = np.arange(n_knots) / KNOT_RATE
    t = np.arange(int(round(duration * SAMPLE_RATE))) / SAMPLE_RATE
    u = np.column_stack([np.interp(t, t_knots, knots[:, j]) + OFFSETS[j] for j in range(2)])
    return t, u


def linear_example_data(seed: int = 0, *, n_outputs: int = 1, duration: float = 100.0) -> IOData:
    """Noise-free identification record of the eq. 15 system driven by the eq. 16 input."""
    t, u = identification_input(seed, duration=duration)
    model = true_model(n_outputs)
    y = model.simulate(u, 1.0 / SAMPLE_RATE, method="foh")
    return IOData(t=t, u=u, y=y, meta={"source": "Best & Bogdanski 2017, eq. 15-16", "seed": seed})
