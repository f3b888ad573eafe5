"""Scheduled (linear-parameter-varying) modal models: one family from models identified at grid points.

Models of one :class:`~identification.modal.ModalStructure` identified at
several values of a scheduling variable (for a car: its speed) become one
family whose modal parameters (sigma, omega, B, C, D) are interpolated
piecewise linearly in that variable. Interpolating entry by entry is only
meaningful when every grid model labels its modes alike and fixes each
mode's state coordinates alike, so before interpolating:

* **canonical form.** A complex pair's block ``[[s, w], [-w, s]]`` commutes
  with every scaled rotation ``T = [[p, q], [-q, p]]``, so ``x -> T x``
  leaves A unchanged and moves only B and C; and ``w < 0`` is the same mode
  as ``w > 0`` seen through the reflection ``diag(1, -1)``. Each pair is
  reflected to ``w > 0`` and rotated and scaled so that its C entries on its
  reference output (the structure's fixed entries) are ``(1, 1)`` again; a
  real pole is scaled so that its fixed C entry is 1. The input-output
  behaviour is unchanged (a similarity transform).
* **mode matching**, made explicit: walking the grid in increasing order,
  the modes of each model are assigned to those of its neighbour by the
  least total relative eigenvalue distance (pairs among pairs, real poles
  among real poles; the assignment problem, solved exactly), permuted into
  the neighbour's slots and brought to the canonical form of their new slot.
  The permutation and its cost at every grid point are kept
  (:attr:`ScheduledModalModel.matching`).

Between grid points the parameters are interpolated linearly; outside the
grid the family is not defined (an error names the range).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import casadi as ca
import numpy as np
from scipy.optimize import linear_sum_assignment

from .errors import InputError
from .modal import ModalModel, ModalStructure

__all__ = ["ModeMatch", "ScheduledModalModel", "canonical_modal_model", "schedule_models"]


def _pair_transform(c_ref: np.ndarray) -> np.ndarray:
    """The scaled rotation ``T`` with ``c_ref T = (1, 1)`` (``c_ref`` the pair's C entries on its reference row)."""
    c1, c2 = c_ref
    if c1 * c1 + c2 * c2 == 0:
        raise InputError("a complex pair has no output on its reference row: it cannot be put in canonical form")
    p, q = np.linalg.solve(np.array([[c1, -c2], [c2, c1]]), np.ones(2))
    return np.array([[p, q], [-q, p]])


def _canonical_mode(A: np.ndarray, B: np.ndarray, C: np.ndarray, states: tuple[int, ...], row: int) -> None:
    """Bring one mode (its states' rows of A, B and columns of C) to canonical form, in place."""
    if len(states) == 1:
        (j,) = states
        if C[row, j] == 0:
            raise InputError("a real pole has no output on its reference row: it cannot be put in canonical form")
        scale = C[row, j]
        C[:, j] /= scale
        B[j, :] *= scale
        return
    a, b = states
    if A[a, b] < 0:  # omega < 0: reflect the second coordinate
        A[a, b], A[b, a] = -A[a, b], -A[b, a]
        B[b, :] *= -1
        C[:, b] *= -1
    T = _pair_transform(C[row, [a, b]])
    C[:, [a, b]] = C[:, [a, b]] @ T
    B[[a, b], :] = np.linalg.solve(T, B[[a, b], :])


def canonical_modal_model(model: ModalModel, order: list[int] | None = None) -> ModalModel:
    """The same input-output model with its modes reordered (``order[slot] = mode``) and in canonical form.

    Modes keep to their kind: ``order`` permutes pairs among pairs and real
    poles among real poles. The result has the structure of ``model``.
    """
    structure = model.structure
    modes = structure.mode_states()
    order = list(range(len(modes))) if order is None else list(order)
    if sorted(order) != list(range(len(modes))) or any(len(modes[o]) != len(modes[s]) for s, o in enumerate(order)):
        raise InputError(f"a mode order must permute the modes within their kind; got {order}")
    source = [state for mode in order for state in modes[mode]]
    A = model.A[np.ix_(source, source)].copy()
    B = model.B[source, :].copy()
    C = model.C[:, source].copy()
    for slot, states in enumerate(modes):
        _canonical_mode(A, B, C, states, structure.output_of_state(states[0]))
    return ModalModel(structure, A, B, C, model.D.copy(), model.input_names, model.output_names, dict(model.meta))


@dataclass(frozen=True)
class ModeMatch:
    """How the modes of the model at one grid point were assigned to the slots of the family.

    ``order[slot]`` is the index of the model's own mode placed in ``slot``;
    ``cost`` the sum over slots of ``|lambda - lambda_neighbour| / |lambda_neighbour|``.
    """

    value: float
    order: tuple[int, ...]
    cost: float


def _mode_eigenvalues(model: ModalModel) -> np.ndarray:
    """One eigenvalue per mode read from A's blocks (whatever the model's C gauge), ``sigma + j|omega|``."""
    A = model.A
    return np.array([complex(A[s[0], s[0]], abs(A[s[0], s[1]]) if len(s) == 2 else 0.0)
                     for s in model.structure.mode_states()])


def _match(reference: np.ndarray, candidate: np.ndarray, n_pairs: int) -> tuple[list[int], float]:
    """Assign candidate modes to reference slots (pairs among pairs, reals among reals), least relative distance."""
    order: list[int] = []
    total = 0.0
    for lo, hi in ((0, n_pairs), (n_pairs, reference.size)):
        if hi <= lo:
            continue
        ref, cand = reference[lo:hi], candidate[lo:hi]
        cost = np.abs(ref[:, None] - cand[None, :]) / np.maximum(np.abs(ref[:, None]), 1e-12)
        rows, cols = linear_sum_assignment(cost)
        order += [lo + int(c) for c in cols[np.argsort(rows)]]
        total += float(cost[rows, cols].sum())
    return order, total


@dataclass(frozen=True, eq=False)
class ScheduledModalModel:
    """A family of modal models scheduled on one variable (e.g. speed): a frozen value.

    Parameters
    ----------
    structure : ModalStructure
    grid : ndarray (n_grid,)
        The scheduling variable's grid values, increasing.
    theta : ndarray (n_grid, n_parameters)
        The matched, canonical parameters at each grid value.
    matching : tuple of ModeMatch
        The mode assignment at each grid value (the first is the identity).
    variable : str
        Name of the scheduling variable (``speed``), for exports and messages.
    """

    structure: ModalStructure
    grid: np.ndarray
    theta: np.ndarray
    matching: tuple[ModeMatch, ...]
    variable: str = "speed"
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        grid = np.array(self.grid, dtype=float).ravel()
        theta = np.array(self.theta, dtype=float)
        if grid.size < 2 or np.any(np.diff(grid) <= 0) or not np.all(np.isfinite(grid)):
            raise InputError(f"a scheduled model needs at least two increasing grid values; got {grid.tolist()}")
        if theta.shape != (grid.size, self.structure.n_parameters) or not np.all(np.isfinite(theta)):
            raise InputError(f"theta must be finite with shape {(grid.size, self.structure.n_parameters)}; got {theta.shape}")
        for name, array in (("grid", grid), ("theta", theta)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def parameters_at(self, value: float) -> np.ndarray:
        """theta at ``value``, interpolated linearly between the grid values."""
        value = float(value)
        low, high = float(self.grid[0]), float(self.grid[-1])
        if not low <= value <= high:
            raise InputError(f"{self.variable} {value:g} lies outside the scheduled range {low:g}..{high:g}")
        return np.array([np.interp(value, self.grid, column) for column in self.theta.T])

    def model_at(self, value: float) -> ModalModel:
        """The modal model at ``value`` of the scheduling variable (within the grid's range)."""
        return ModalModel.from_parameters(
            self.structure, self.parameters_at(value), input_names=self.input_names, output_names=self.output_names,
            meta={**self.meta, self.variable: float(value), "scheduled": True},
        )

    def to_casadi(self, name: str = "scheduled_modal_model") -> ca.Function:
        """One CasADi Function ``(x, u, <variable>) -> (xdot, y)`` of the continuous-time family.

        The parameters are piecewise-linear functions of the scheduling
        variable (``casadi.pw_lin``; linear continuation beyond the grid, where
        the family is not validated), so the Function differentiates and
        generates C like any other (for MPC).
        """
        s = self.structure
        x = ca.SX.sym("x", s.n)
        u = ca.SX.sym("u", s.n_u)
        v = ca.SX.sym(self.variable)
        grid = ca.DM(self.grid)
        theta = ca.vertcat(*[ca.pw_lin(v, grid, ca.DM(column)) for column in self.theta.T])
        A, B, C, D = s.matrices(theta, backend=ca.SX)
        return ca.Function(name, [x, u, v], [ca.mtimes(A, x) + ca.mtimes(B, u), ca.mtimes(C, x) + ca.mtimes(D, u)],
                           ["x", "u", self.variable], ["xdot", "y"])

    def to_dict(self) -> dict[str, Any]:
        return {
            "structure": self.structure.to_dict(), "grid": self.grid, "theta": self.theta, "variable": self.variable,
            "matching": [{"value": m.value, "order": list(m.order), "cost": m.cost} for m in self.matching],
        }

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "ScheduledModalModel":
        matching = tuple(ModeMatch(float(m["value"]), tuple(int(o) for o in m["order"]), float(m["cost"]))
                         for m in values["matching"])
        return cls(ModalStructure.from_dict(values["structure"]), np.asarray(values["grid"]), np.asarray(values["theta"]),
                   matching, str(values["variable"]))


def schedule_models(models: Mapping[float, ModalModel], *, variable: str = "speed") -> ScheduledModalModel:
    """The scheduled family through models identified at grid values of ``variable``.

    Parameters
    ----------
    models : mapping of float to ModalModel
        At least two models of one structure, keyed by the scheduling value.
    variable : str

    Returns
    -------
    ScheduledModalModel
        Modes matched along the grid and in canonical form (module notes).
    """
    if len(models) < 2:
        raise InputError(f"a scheduled model needs models at two or more {variable} values; got {len(models)}")
    values = sorted(float(v) for v in models)
    ordered = [models[v] for v in sorted(models, key=float)]
    structure = ordered[0].structure
    for value, model in zip(values, ordered):
        if model.structure != structure:
            raise InputError(f"the model at {variable} {value:g} has another structure than the first")
    first = canonical_modal_model(ordered[0])
    matched = [first]
    matching = [ModeMatch(values[0], tuple(range(len(structure.mode_states()))), 0.0)]
    for value, model in zip(values[1:], ordered[1:]):
        order, cost = _match(_mode_eigenvalues(matched[-1]), _mode_eigenvalues(model), structure.n_complex_pairs)
        matched.append(canonical_modal_model(model, order))
        matching.append(ModeMatch(value, tuple(order), cost))
    theta = np.array([model.parameters for model in matched])
    return ScheduledModalModel(structure, np.array(values), theta, tuple(matching), variable,
                               first.input_names, first.output_names)
