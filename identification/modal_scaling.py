"""Modal parameters under a change of units: scaled signals and a rescaled time.

The filters identify on scaled signals and in their own time unit; these
maps carry a modal structure's parameter vector between those units and the
original ones (each parameter is scaled alone, so every map is diagonal).
"""

from __future__ import annotations

import numpy as np

from .modal import ModalStructure

__all__ = ["denormalize", "normalize_parameters", "rescale_time", "time_weights"]


def denormalize(structure: ModalStructure, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
    """Parameters in original units from those identified on scaled data.

    With ``u = Su u_n`` and ``y = Sy y_n`` and the state basis rescaled by the
    scale of the output each state is tied to, ``A`` is unchanged, the fixed
    C entries stay 1, ``B -> S B Su^-1``, ``C -> Sy C S^-1``, ``D -> Sy D Su^-1``.
    """
    A, B, C, D = structure.matrices(theta)
    state_scale = np.array([output_scale[structure.output_of_state(j)] for j in range(structure.n)])
    B = state_scale[:, None] * B / input_scale[None, :]
    C = output_scale[:, None] * C / state_scale[None, :]
    D = output_scale[:, None] * D / input_scale[None, :]
    return structure.pack(A, B, C, D)


def normalize_parameters(structure: ModalStructure, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
    """Inverse of :func:`denormalize`."""
    return denormalize(structure, theta, 1.0 / input_scale, 1.0 / output_scale)


def rescale_time(structure: ModalStructure, theta: np.ndarray, factor: float) -> np.ndarray:
    """Parameters in a time unit ``factor`` times the present one: sigma, omega and B times ``factor``.

    ``xdot = A x + B u`` in time ``t' = t / factor`` reads ``dx/dt' = factor A x + factor B u``;
    C and D are unchanged.
    """
    return np.array(theta, dtype=float) * time_weights(structure, factor)


def time_weights(structure: ModalStructure, ratio: float) -> np.ndarray:
    """Per parameter: ``ratio`` for sigma, omega and B, 1 for C and D (the change of time unit)."""
    weights = np.ones(structure.n_parameters)
    slices = structure.slices()
    weights[slices["modal"]] = ratio
    weights[slices["B"]] = ratio
    return weights
