"""The coordinates a scheduled modal family is interpolated in, and the family's matrices in them.

Entry-by-entry interpolation between grid models needs every model in the same coordinates:

* **gauge** (:func:`input_gauge`): pairs reflected to ``w > 0``, each pair's first-input B entries
  made ``(1, 0)`` and each real pole's 1, where a mode's C columns are its residues for that input and
  independent of how identification scaled the states; :func:`canonical_modal_model` and
  :func:`structure_gauge` bring a model back to the canonical form (fixed C entries 1).
* **interpolation** (:func:`interpolation_weights`): piecewise linear in the scheduling variable, held
  at the end values beyond the grid, one expression in NumPy and CasADi.

Parameters of a family, grid value by grid value (:func:`knot_size` in all): sigma/omega of every
mode, the input-gauge B without its first column (fixed), C, D (each row-major) and the output
offset (:func:`gauge_parameters`, :func:`gauge_matrices`, :func:`scheduled_matrices`);
:func:`scheduled_step` is the family's step over one sample in those coordinates. The family itself
is :class:`~vehid.identification.models.scheduled.ScheduledModalModel`.
"""

from __future__ import annotations

import functools
from typing import Any

import casadi as ca
import numpy as np

from ..errors import InputError
from .modal import ModalModel
from .modal_structure import ModalStructure

__all__ = ["input_gauge", "structure_gauge", "first_input_column", "gauge_parameters", "gauge_matrices",
    "interpolation_weights", "knot_size", "scheduled_matrices", "scheduled_step", "canonical_function",
    "canonical_modal_model"]


def input_gauge(model: ModalModel, order: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C with the modes in ``order``, omega > 0, and each mode's first-input B entries (1, 0) or 1.

    In this gauge a mode's C columns are its residues for the first input
    (gauge-invariant input-output quantities), which is what interpolation
    between grid points should act on.
    """
    modes = model.structure.mode_states()
    source = [state for mode in order for state in modes[mode]]
    A = model.A[np.ix_(source, source)].copy()
    B = model.B[source, :].copy()
    C = model.C[:, source].copy()
    for states in modes:
        if len(states) == 1:
            (j,) = states
            scale = B[j, 0]
            if scale == 0:
                raise InputError("a real pole is not driven by the first input: its scheduling gauge is undefined")
            B[j, :] /= scale
            C[:, j] *= scale
            continue
        a, b = states
        if A[a, b] < 0:  # omega < 0: the same mode seen through the reflection diag(1, -1)
            A[a, b], A[b, a] = -A[a, b], -A[b, a]
            B[b, :] *= -1
            C[:, b] *= -1
        ba, bb = B[a, 0], B[b, 0]
        if ba == 0 and bb == 0:
            raise InputError("a complex pair is not driven by the first input: its scheduling gauge is undefined")
        T = np.array([[ba, -bb], [bb, ba]])  # a scaled rotation: commutes with the pair's block
        B[[a, b], :] = np.linalg.solve(T, B[[a, b], :])
        C[:, [a, b]] = C[:, [a, b]] @ T
    return A, B, C


def structure_gauge(structure: ModalStructure, A: Any, B: Any, C: Any) -> tuple[Any, Any, Any]:
    """The similarity that makes the structure's fixed C entries 1 again, on B and C in place
    (NumPy arrays or CasADi SX; A commutes with it and is returned as it is)."""
    n_u, n_y = structure.n_u, structure.n_y
    for states in structure.mode_states():
        row = structure.output_of_state(states[0])
        if len(states) == 1:
            (j,) = states
            scale = C[row, j]
            for i in range(n_y):
                C[i, j] = C[i, j] / scale
            for k in range(n_u):
                B[j, k] = B[j, k] * scale
            continue
        a, b = states
        c1, c2 = C[row, a], C[row, b]
        norm = c1 * c1 + c2 * c2
        p, q = (c1 + c2) / norm, (c1 - c2) / norm  # T = [[p, q], [-q, p]] with [c1, c2] T = [1, 1]
        for i in range(n_y):
            ca_, cb_ = C[i, a], C[i, b]
            C[i, a], C[i, b] = ca_ * p - cb_ * q, ca_ * q + cb_ * p
        det = p * p + q * q
        for k in range(n_u):
            ba, bb = B[a, k], B[b, k]
            B[a, k], B[b, k] = (p * ba - q * bb) / det, (q * ba + p * bb) / det
    return A, B, C


def first_input_column(structure: ModalStructure) -> np.ndarray:
    """The input gauge's fixed first column of B: 1 on each mode's first state, 0 on a pair's second."""
    column = np.zeros(structure.n)
    for states in structure.mode_states():
        column[states[0]] = 1.0
    return column


def gauge_parameters(modal: Any, B: Any, C: Any, D: Any) -> np.ndarray:
    """One grid value's parameters in the input gauge: sigma/omega, B without its first column, C, D (row-major)."""
    return np.concatenate([np.ravel(modal), np.asarray(B, dtype=float)[:, 1:].ravel(), np.ravel(C), np.ravel(D)])


def gauge_matrices(structure: ModalStructure, theta: Any, backend: Any = np) -> tuple[Any, Any, Any, Any]:
    """sigma/omega (n,), B (n, n_u), C (n_y, n) and D (n_y, n_u) of one grid value's input-gauge parameters.

    NumPy arrays, or (``backend=casadi.SX``, ``theta`` an SX column) symbolic
    matrices built from its elements, so that derivatives are exact.
    """
    n, n_u, n_y = structure.n, structure.n_u, structure.n_y
    b_start = n
    c_start = b_start + n * (n_u - 1)
    d_start = c_start + n_y * n
    first = first_input_column(structure)
    if backend is np:
        theta = np.asarray(theta, dtype=float).ravel()
        if theta.size != structure.n_parameters:
            raise InputError(f"one grid value takes {structure.n_parameters} parameters; got {theta.size}")
        B = np.column_stack([first, theta[b_start:c_start].reshape(n, n_u - 1)])
        return theta[:n].copy(), B, theta[c_start:d_start].reshape(n_y, n), theta[d_start:].reshape(n_y, n_u)
    B, C, D = backend.zeros(n, n_u), backend.zeros(n_y, n), backend.zeros(n_y, n_u)
    for i in range(n):
        B[i, 0] = float(first[i])
        for j in range(1, n_u):
            B[i, j] = theta[b_start + i * (n_u - 1) + j - 1]
    for i in range(n_y):
        for j in range(n):
            C[i, j] = theta[c_start + i * n + j]
        for j in range(n_u):
            D[i, j] = theta[d_start + i * n_u + j]
    return theta[:n], B, C, D


def interpolation_weights(value: Any, grid: Any) -> Any:
    """Weights of the grid values at ``value``: piecewise linear, held at the end values beyond the grid.

    Written as ``c(s) = c_0 + sum_k t_k(s) (c_k+1 - c_k)`` with
    ``t_k = clip((s - s_k) / (s_k+1 - s_k), 0, 1)``, which needs no interval
    search and is the same expression in NumPy and CasADi.

    Parameters
    ----------
    value : array_like (N,), or casadi.SX scalar
    grid : array_like (K,) increasing, or K CasADi expressions

    Returns
    -------
    ndarray (N, K), or a list of K SX weights
    """
    if isinstance(value, (ca.SX, ca.MX)):
        count = grid.numel() if isinstance(grid, (ca.SX, ca.MX, ca.DM)) else len(grid)
        steps = [ca.fmin(ca.fmax((value - grid[k]) / (grid[k + 1] - grid[k]), 0.0), 1.0) for k in range(count - 1)]
        return [1.0 - steps[0], *[steps[k - 1] - steps[k] for k in range(1, count - 1)], steps[-1]]
    value = np.atleast_1d(np.asarray(value, dtype=float))
    grid = np.asarray(grid, dtype=float)
    steps = np.clip((value[:, None] - grid[None, :-1]) / np.diff(grid)[None, :], 0.0, 1.0)
    weights = np.empty((value.size, grid.size))
    weights[:, 0] = 1.0 - steps[:, 0]
    weights[:, 1:-1] = steps[:, :-1] - steps[:, 1:]
    weights[:, -1] = steps[:, -1]
    return weights


def knot_size(structure: ModalStructure) -> int:
    """Parameters per grid value: the structure's and an offset per output."""
    return structure.n_parameters + structure.n_y


def scheduled_matrices(structure: ModalStructure, theta: Any, weights: list[Any]) -> tuple[Any, Any, Any, Any, Any]:
    """Symbolic sigma/omega, B, C, D (input gauge) and output offset of the family's parameters ``theta``
    (SX, K :func:`knot_size`) at ``weights``."""
    size = knot_size(structure)
    blended = sum(weight * theta[k * size:(k + 1) * size] for k, weight in enumerate(weights))
    return (*gauge_matrices(structure, blended[:structure.n_parameters], ca.SX), blended[structure.n_parameters:])


def scheduled_step(structure: ModalStructure, x: Any, u0: Any, u1: Any, theta: Any, grid: Any, dt: float,
                   discretization: str) -> tuple[Any, Any]:
    """``(x_next, y)`` in SX of the family over one sample, its coefficients frozen at the sample's start.

    ``u0``, ``u1`` hold the inputs and, last, the schedule at the sample's two
    ends; states are the input gauge's (module notes). The family's parameters
    ``theta`` (K m) and ``grid`` (K) may be symbols.
    """
    from .transition import modal_transition

    n_u = structure.n_u
    count = grid.numel() if isinstance(grid, (ca.SX, ca.MX, ca.DM)) else len(grid)
    modal, B, C, D, offset = scheduled_matrices(structure, theta, interpolation_weights(
        u0[n_u], [grid[k] for k in range(count)]))
    drive0 = ca.mtimes(B, u0[:n_u])
    drive1 = ca.mtimes(B, u1[:n_u])
    x_next = modal_transition(structure, modal, x, drive0, drive1, dt, discretization)
    return x_next, ca.mtimes(C, x) + ca.mtimes(D, u0[:n_u]) + offset


@functools.lru_cache(maxsize=16)
def canonical_function(structure: ModalStructure) -> ca.Function:
    """One grid value's input-gauge parameters -> the canonical parameters of
    :meth:`~vehid.identification.models.modal_structure.ModalStructure.pack`, and the Jacobian."""
    q = ca.SX.sym("q", structure.n_parameters)
    modal, B, C, D = gauge_matrices(structure, q, ca.SX)
    A = structure.matrices(ca.vertcat(modal, ca.SX.zeros(structure.n_parameters - structure.n)), backend=ca.SX)[0]
    A, B, C = structure_gauge(structure, A, B, C)
    free_c = [C[i, j] for i, j in structure.free_c]
    theta = ca.vertcat(modal, ca.vec(B.T), *free_c, ca.vec(D.T))
    return ca.Function("vehid_canonical_of_gauge", [q], [theta, ca.jacobian(theta, q)], ["q"], ["theta", "J"])


def canonical_modal_model(model: ModalModel, order: list[int] | None = None) -> ModalModel:
    """The same input-output model with its modes reordered (``order[slot] = mode``), omega > 0 and
    the structure's fixed C entries equal to 1 (a similarity transform).

    Modes keep to their kind: ``order`` permutes pairs among pairs and real
    poles among real poles. The result has the structure of ``model``.
    """
    structure = model.structure
    modes = structure.mode_states()
    order = list(range(len(modes))) if order is None else list(order)
    if sorted(order) != list(range(len(modes))) or any(len(modes[o]) != len(modes[s]) for s, o in enumerate(order)):
        raise InputError(f"a mode order must permute the modes within their kind; got {order}")
    A, B, C = structure_gauge(structure, *input_gauge(model, order))
    return ModalModel(structure, A, B, C, model.D.copy(), model.input_names, model.output_names, dict(model.meta))
