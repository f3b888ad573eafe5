"""Scheduled (linear-parameter-varying) modal models: one family from models identified at grid points.

Models of one :class:`~identification.modal.ModalStructure` identified at several values of a
scheduling variable (for a car: its speed) become one family whose modal parameters (sigma, omega,
B, C, D) are interpolated piecewise linearly in that variable; outside the grid the family is not
defined. Entry-by-entry interpolation needs every grid model in the same coordinates, so first

* **gauge**: each model is brought to the input gauge (pairs reflected to ``w > 0``, each pair's
  first-input B entries made ``(1, 0)`` and each real pole's 1), where a mode's C columns are its
  residues for that input and independent of how identification scaled the states;
  :meth:`ScheduledModalModel.model_at` returns the canonical form (fixed C entries 1) again;
* **mode matching**: walking the grid upwards, each model's modes are assigned to its neighbour's by
  the least total relative eigenvalue distance (pairs among pairs, real poles among real poles),
  kept in :attr:`ScheduledModalModel.matching`.
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


def _input_gauge(model: ModalModel, order: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _structure_gauge(structure: ModalStructure, A: Any, B: Any, C: Any) -> tuple[Any, Any, Any]:
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
    A, B, C = _structure_gauge(structure, *_input_gauge(model, order))
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


def _block_eigenvalues(structure: ModalStructure, A: np.ndarray) -> np.ndarray:
    """One eigenvalue per mode read from A's blocks, ``sigma + j|omega|``."""
    return np.array([complex(A[s[0], s[0]], abs(A[s[0], s[1]]) if len(s) == 2 else 0.0)
                     for s in structure.mode_states()])


def _mode_eigenvalues(model: ModalModel) -> np.ndarray:
    return _block_eigenvalues(model.structure, model.A)


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
    modal : ndarray (n_grid, n)
        sigma/omega of every mode at each grid value (theta's modal order, omega > 0).
    B, C, D : ndarray (n_grid, n, n_u), (n_grid, n_y, n), (n_grid, n_y, n_u)
        The matched models in the input gauge (module notes): these are interpolated.
    matching : tuple of ModeMatch
        The mode assignment at each grid value (the first is the identity).
    variable : str
        Name of the scheduling variable (``speed``), for exports and messages.
    """

    structure: ModalStructure
    grid: np.ndarray
    modal: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    matching: tuple[ModeMatch, ...]
    variable: str = "speed"
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s = self.structure
        grid = np.array(self.grid, dtype=float).ravel()
        if grid.size < 2 or np.any(np.diff(grid) <= 0) or not np.all(np.isfinite(grid)):
            raise InputError(f"a scheduled model needs at least two increasing grid values; got {grid.tolist()}")
        object.__setattr__(self, "grid", grid)
        grid.setflags(write=False)
        for name, shape in (("modal", (s.n,)), ("B", (s.n, s.n_u)), ("C", (s.n_y, s.n)), ("D", (s.n_y, s.n_u))):
            array = np.array(getattr(self, name), dtype=float)
            if array.shape != (grid.size, *shape) or not np.all(np.isfinite(array)):
                raise InputError(f"{name} must be finite with shape {(grid.size, *shape)}; got {array.shape}")
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def _weights(self, value: float) -> np.ndarray:
        value = float(value)
        low, high = float(self.grid[0]), float(self.grid[-1])
        if not low <= value <= high:
            raise InputError(f"{self.variable} {value:g} lies outside the scheduled range {low:g}..{high:g}")
        return np.array([np.interp(value, self.grid, np.eye(self.grid.size)[k]) for k in range(self.grid.size)])

    def model_at(self, value: float) -> ModalModel:
        """The modal model at ``value`` of the scheduling variable (within the grid's range), canonical form."""
        w = self._weights(value)
        modal, B, C, D = (np.tensordot(w, array, axes=1) for array in (self.modal, self.B, self.C, self.D))
        A = self.structure.matrices(np.concatenate([modal, np.zeros(self.structure.n_parameters - self.structure.n)]))[0]
        A, B, C = _structure_gauge(self.structure, A, B, C)
        return ModalModel(self.structure, A, B, C, D, input_names=self.input_names, output_names=self.output_names,
                          meta={**self.meta, self.variable: float(value), "scheduled": True})

    def to_casadi(self, name: str = "scheduled_modal_model") -> ca.Function:
        """One CasADi Function ``(x, u, <variable>) -> (xdot, y)`` of the continuous-time family.

        Its states are those of :meth:`model_at` (the structure's canonical
        form). The interpolated entries are piecewise-linear functions of the
        scheduling variable (``casadi.pw_lin``; linear continuation beyond the
        grid, where the family is not validated), so the Function
        differentiates and generates C like any other (for MPC).
        """
        s = self.structure
        x = ca.SX.sym("x", s.n)
        u = ca.SX.sym("u", s.n_u)
        v = ca.SX.sym(self.variable)
        grid = ca.DM(self.grid)

        def interpolated(array: np.ndarray) -> ca.SX:
            flat = array.reshape(array.shape[0], -1)
            values = [ca.pw_lin(v, grid, ca.DM(flat[:, k])) for k in range(flat.shape[1])]
            return ca.reshape(ca.vertcat(*values), array.shape[2], array.shape[1]).T if array.ndim == 3 else ca.vertcat(*values)

        modal = interpolated(self.modal)
        A = ca.SX.zeros(s.n, s.n)
        for states in s.mode_states():
            a = states[0]
            A[a, a] = modal[a]
            if len(states) == 2:
                A[a, a + 1], A[a + 1, a], A[a + 1, a + 1] = modal[a + 1], -modal[a + 1], modal[a]
        B, C = interpolated(self.B), interpolated(self.C)
        D = interpolated(self.D)
        A, B, C = _structure_gauge(s, A, B, C)
        return ca.Function(name, [x, u, v], [ca.mtimes(A, x) + ca.mtimes(B, u), ca.mtimes(C, x) + ca.mtimes(D, u)],
                           ["x", "u", self.variable], ["xdot", "y"])

    def to_dict(self) -> dict[str, Any]:
        return {
            "structure": self.structure.to_dict(), "grid": self.grid, "modal": self.modal, "B": self.B, "C": self.C,
            "D": self.D, "variable": self.variable,
            "matching": [{"value": m.value, "order": list(m.order), "cost": m.cost} for m in self.matching],
            "input_names": self.input_names, "output_names": self.output_names, "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "ScheduledModalModel":
        matching = tuple(ModeMatch(float(m["value"]), tuple(int(o) for o in m["order"]), float(m["cost"]))
                         for m in values["matching"])
        names = {key: tuple(values[key]) if values.get(key) is not None else None
                 for key in ("input_names", "output_names")}
        return cls(ModalStructure.from_dict(values["structure"]), *(np.asarray(values[k]) for k in ("grid", "modal", "B", "C", "D")),
                   matching, str(values["variable"]), **names, meta=dict(values.get("meta") or {}))


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
        Modes matched along the grid, each model in the input gauge (module notes).
    """
    if len(models) < 2:
        raise InputError(f"a scheduled model needs models at two or more {variable} values; got {len(models)}")
    values = sorted(float(v) for v in models)
    ordered = [models[v] for v in sorted(models, key=float)]
    structure = ordered[0].structure
    for value, model in zip(values, ordered):
        if model.structure != structure:
            raise InputError(f"the model at {variable} {value:g} has another structure than the first")
    identity = list(range(len(structure.mode_states())))
    gauged = [_input_gauge(ordered[0], identity)]
    matching = [ModeMatch(values[0], tuple(identity), 0.0)]
    for value, model in zip(values[1:], ordered[1:]):
        order, cost = _match(_block_eigenvalues(structure, gauged[-1][0]), _mode_eigenvalues(model), structure.n_complex_pairs)
        gauged.append(_input_gauge(model, order))
        matching.append(ModeMatch(value, tuple(order), cost))
    modal = np.array([[A[s[0], s[0]] if k == 0 else A[s[0], s[1]] for s in structure.mode_states() for k in range(len(s))]
                      for A, _, _ in gauged])
    return ScheduledModalModel(
        structure, np.array(values), modal, np.array([g[1] for g in gauged]), np.array([g[2] for g in gauged]),
        np.array([m.D for m in ordered]), tuple(matching), variable, ordered[0].input_names, ordered[0].output_names,
    )
