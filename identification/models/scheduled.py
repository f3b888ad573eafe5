"""Scheduled (linear-parameter-varying) modal models: one family from models identified at grid points.

Models of one :class:`~identification.models.modal_structure.ModalStructure` identified at several values of a
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

The family's coefficients are piecewise linear in the scheduling variable and held at the end values
beyond the grid. For a record whose schedule varies, :meth:`ScheduledModalModel.simulate_outputs`
runs the family in the input gauge: each mode's state is driven by the first input at unit gain at
every schedule value, so the coefficients that are interpolated are the ones the states see, and a
family identified from one varying-schedule record (:mod:`vehid.identification.filtering.scheduled_iekf`)
simulates as it was identified. At a frozen schedule value the input gauge and the canonical form of
:meth:`ScheduledModalModel.model_at` are one model.

Each grid value also has an output offset, added to the outputs (zero for models identified at fixed
operating points): the operating point of a linear-parameter-varying system moves with its schedule,
so a record whose means were removed keeps an offset that depends on it (a steering offset passes
through a gain that changes with speed).

Parameters of the family (:attr:`ScheduledModalModel.parameters`, the layout of its covariance), grid
value by grid value: sigma/omega of every mode, the input-gauge B without its first column (fixed),
C, D (each row-major) and the output offset
(:func:`~vehid.identification.models.scheduled_gauge.knot_size` in all; the gauge and these
coordinates are :mod:`vehid.identification.models.scheduled_gauge`'s).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any, Mapping

import casadi as ca
import numpy as np

from ..errors import InputError
from .modal import ModalModel
from .modal_structure import ModalStructure
from .scheduled_gauge import (canonical_function, first_input_column, gauge_matrices, gauge_parameters, input_gauge,
                              interpolation_weights, knot_size, scheduled_matrices, scheduled_step, structure_gauge)

__all__ = ["ModeMatch", "OutputMap", "ScheduledModalModel", "schedule_models"]


_HOLDS = {"foh": "exact", "zoh": "exact-zoh", "euler": "euler"}


@functools.lru_cache(maxsize=16)
def _simulator(structure: ModalStructure, count: int, discretization: str) -> Any:
    """Compiled simulation of a family of ``count`` grid values: params = [theta; grid; dt].

    The sample time is a parameter rather than a constant of the code, so that one library serves
    every record of the family's shape."""
    from ..compiled import CompiledRecursion

    x = ca.SX.sym("x", structure.n)
    u0 = ca.SX.sym("u0", structure.n_u + 1)
    u1 = ca.SX.sym("u1", structure.n_u + 1)
    size = count * knot_size(structure)
    params = ca.SX.sym("params", size + count + 1)
    theta, grid, dt = params[:size], params[size:-1], params[-1]
    x_next, y = scheduled_step(structure, x, u0, u1, theta, grid, dt, discretization)
    step = ca.Function("scheduled_modal_step", [x, u0, u1, params], [x_next, y], ["x", "u0", "u1", "params"],
                       ["x_next", "y"], {"cse": True})
    return CompiledRecursion(step, optimisation="-O1")


@dataclass(frozen=True)
class ModeMatch:
    """How the modes of the model at one grid point were assigned to the slots of the family.

    Parameters
    ----------
    value : float
        The grid value of the scheduling variable.
    order : tuple of int
        ``order[slot]`` is the index of the model's own mode placed in ``slot``.
    cost : float
        The sum over slots of ``|lambda - lambda_neighbour| / |lambda_neighbour|``.
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
    from scipy.optimize import linear_sum_assignment  # 0.4 s to import: paid here, not at every command's start

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
class OutputMap:
    """A static piecewise-linear map of each output of a linear model: ``y_i = g_i(z_i)`` (a Wiener model).

    ``g_i`` interpolates ``ordinates[i]`` linearly between ``nodes[i]`` and continues its end segments
    beyond them, so an output the linear model overshoots (a lateral acceleration at the grip limit)
    is bent back wherever it lands. The identity map has its ordinates at its nodes.

    Parameters
    ----------
    nodes, ordinates : ndarray (n_y, n_nodes)
        Per output, strictly increasing nodes (in the linear output's units) and the map's values there.
    """

    nodes: np.ndarray
    ordinates: np.ndarray

    def __post_init__(self) -> None:
        nodes, ordinates = (np.array(getattr(self, name), dtype=float) for name in ("nodes", "ordinates"))
        if nodes.ndim != 2 or nodes.shape != ordinates.shape or nodes.shape[1] < 2:
            raise InputError(f"an output map needs nodes and ordinates of one shape (n_y, >= 2); got {nodes.shape} "
                             f"and {ordinates.shape}")
        if not (np.all(np.isfinite(nodes)) and np.all(np.isfinite(ordinates)) and np.all(np.diff(nodes, axis=1) > 0)):
            raise InputError("an output map's nodes must be finite and strictly increasing, its ordinates finite")
        for name, array in (("nodes", nodes), ("ordinates", ordinates)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @staticmethod
    def basis(z: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """Hat functions (N, n_nodes) of ``z`` at ``nodes``, the end segments continued linearly."""
        segment = np.clip(np.searchsorted(nodes, z) - 1, 0, nodes.size - 2)
        share = (z - nodes[segment]) / (nodes[segment + 1] - nodes[segment])
        phi = np.zeros((z.size, nodes.size))
        rows = np.arange(z.size)
        phi[rows, segment] = 1.0 - share
        phi[rows, segment + 1] = share
        return phi

    @classmethod
    def fit(cls, z: Any, y: Any, count: int, *, ridge: float = 1e-3) -> "OutputMap":
        """The map from a linear model's outputs ``z`` (N, n_y) to the measured ``y`` by least squares.

        Nodes at evenly spaced quantiles of each ``z_i`` from its 0.5th to its 99.5th percentile; the
        ordinates minimise ``|y_i - g_i(z_i)|^2 + ridge N |ordinates - nodes|^2``: the ridge pulls a
        node that few samples reach towards the identity, not towards noise.
        """
        z, y = np.asarray(z, dtype=float), np.asarray(y, dtype=float)
        if z.ndim != 2 or z.shape != y.shape or not (np.all(np.isfinite(z)) and np.all(np.isfinite(y))):
            raise InputError(f"an output map is fitted to finite z and y of one shape (N, n_y); got {z.shape}, {y.shape}")
        nodes, ordinates = [], []
        for zi, yi in zip(z.T, y.T):
            at = np.quantile(zi, np.linspace(0.005, 0.995, int(count)))
            if np.any(np.diff(at) <= 1e-12 * max(np.max(np.abs(at)), 1e-300)):
                at = np.linspace(at[0], at[-1], int(count)) if at[-1] > at[0] else at[0] + np.arange(int(count))
            phi = cls.basis(zi, at)
            weight = ridge * zi.size
            ordinates.append(np.linalg.solve(phi.T @ phi + weight * np.eye(at.size), phi.T @ yi + weight * at))
            nodes.append(at)
        return cls(np.array(nodes), np.array(ordinates))

    def apply(self, z: Any) -> np.ndarray:
        """``g(z)`` for linear outputs ``z`` (N, n_y)."""
        z = np.asarray(z, dtype=float)
        return np.column_stack([self.basis(z[:, i], self.nodes[i]) @ self.ordinates[i] for i in range(z.shape[1])])

    def apply_casadi(self, z: Any) -> Any:
        """``g(z)`` of a CasADi column ``z`` (n_y): the same map, differentiable."""
        out = []
        for i in range(self.nodes.shape[0]):
            nodes, values = self.nodes[i], self.ordinates[i]
            slopes = np.diff(values) / np.diff(nodes)
            # first segment's line, then each interior node adds its change of slope past it
            g = values[0] + slopes[0] * (z[i] - nodes[0])
            for k in range(1, nodes.size - 1):
                g += (slopes[k] - slopes[k - 1]) * ca.fmax(z[i] - nodes[k], 0)
            out.append(g)
        return ca.vertcat(*out)

    def to_dict(self) -> dict[str, Any]:
        return {"nodes": self.nodes.tolist(), "ordinates": self.ordinates.tolist()}

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "OutputMap":
        return cls(np.asarray(values["nodes"], dtype=float), np.asarray(values["ordinates"], dtype=float))


@dataclass(frozen=True, eq=False)
class ScheduledModalModel:
    """A family of modal models scheduled on one variable (e.g. speed): a frozen value.

    Parameters
    ----------
    structure : ModalStructure
        The modes and fixed C entries shared by every grid value.
    grid : ndarray (n_grid,)
        The scheduling variable's grid values, increasing.
    modal : ndarray (n_grid, n)
        The sigma/omega of every mode at each grid value (theta's modal order, omega > 0).
    B, C, D : ndarray (n_grid, n, n_u), (n_grid, n_y, n), (n_grid, n_y, n_u)
        The matched models in the input gauge (module notes): these are interpolated.
    matching : tuple of ModeMatch
        The mode assignment at each grid value (the first is the identity).
    variable : str
        Name of the scheduling variable (``speed``, or the record's channel), for exports and messages.
    input_names, output_names : tuple of str, optional
        Channel names (the schedule not among the inputs).
    meta : dict, optional
        Provenance (estimator, grid choice, ...).
    parameter_covariance : ndarray, optional
        Covariance of :attr:`parameters` (module notes), where an estimator gave one.
    offset : ndarray (n_grid, n_y), optional
        The output offset at each grid value (module notes); zero by default.
    output_map : OutputMap, optional
        A static map applied to the simulated outputs (``--schedule`` with ``--nonlinear``); the frozen
        models of :meth:`model_at`, their modes and :attr:`parameters` are the linear part's.

    Notes
    -----
    The family meets the model protocol (:class:`~identification.models.protocol.IdentifiedModel`) at a
    value of its scheduling variable: ``eigenvalues(schedule=v)``, ``modes``, ``frequency_response``,
    ``to_statespace`` and ``to_control`` are those of :meth:`linear_at` ``v`` (the input gauge, the states of
    :meth:`simulate_outputs`; the output offset and map aside), and ``simulate_outputs(u, dt, schedule=...)``
    runs it along a schedule. Its ``n_u`` counts its inputs; a record adds the schedule as a last column
    (:attr:`record_inputs`).
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
    parameter_covariance: np.ndarray | None = None
    offset: np.ndarray | None = None
    output_map: OutputMap | None = None

    def __post_init__(self) -> None:
        s = self.structure
        if self.output_map is not None and self.output_map.nodes.shape[0] != s.n_y:
            raise InputError(f"the output map has {self.output_map.nodes.shape[0]} outputs; the family {s.n_y}")
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
        offset = np.zeros((grid.size, s.n_y)) if self.offset is None else np.array(self.offset, dtype=float)
        if offset.shape != (grid.size, s.n_y) or not np.all(np.isfinite(offset)):
            raise InputError(f"offset must be finite with shape {(grid.size, s.n_y)}; got {offset.shape}")
        offset.setflags(write=False)
        object.__setattr__(self, "offset", offset)
        object.__setattr__(self, "meta", dict(self.meta))
        if self.parameter_covariance is not None:
            from .delta_method import checked_covariance

            object.__setattr__(self, "parameter_covariance",
                               checked_covariance(self.parameter_covariance, self.n_parameters))

    @classmethod
    def from_parameters(cls, structure: ModalStructure, grid: Any, theta: Any, *, variable: str = "speed",
                        input_names: tuple[str, ...] | None = None, output_names: tuple[str, ...] | None = None,
                        meta: dict[str, Any] | None = None, parameter_covariance: Any = None,
                        matching: tuple[ModeMatch, ...] | None = None,
                        output_map: OutputMap | None = None) -> "ScheduledModalModel":
        """Make the family of ``structure`` on ``grid`` with parameters ``theta`` laid out as :attr:`parameters`.

        Parameters
        ----------
        structure : ModalStructure
            The structure at every grid value.
        grid : array_like, shape (n_grid,)
            The scheduling variable's grid values, increasing.
        theta : array_like, shape (n_grid * knot_size,)
            The parameters, grid value by grid value (module notes).
        variable : str, default "speed"
            Name of the scheduling variable.
        input_names, output_names : tuple of str, optional
            Channel names.
        meta : dict, optional
            Provenance.
        parameter_covariance : array_like, optional
            Covariance of ``theta``.
        matching : tuple of ModeMatch, optional
            The mode assignment at each grid value; the identity by default.
        output_map : OutputMap, optional
            A static map applied to the simulated outputs.

        Returns
        -------
        ScheduledModalModel
            The family.
        """
        grid = np.asarray(grid, dtype=float).ravel()
        m, size = structure.n_parameters, knot_size(structure)
        theta = np.asarray(theta, dtype=float).ravel()
        if theta.size != grid.size * size:
            raise InputError(f"a family of {grid.size} grid values takes {grid.size * size} parameters; got {theta.size}")
        parts = [gauge_matrices(structure, theta[k * size:k * size + m]) for k in range(grid.size)]
        offset = np.array([theta[k * size + m:(k + 1) * size] for k in range(grid.size)])
        if matching is None:
            identity = tuple(range(len(structure.mode_states())))
            matching = tuple(ModeMatch(float(value), identity, 0.0) for value in grid)
        return cls(structure, grid, *(np.array([part[i] for part in parts]) for i in range(4)), matching, variable,
                   input_names, output_names, dict(meta or {}), parameter_covariance, offset, output_map)

    @property
    def n_parameters(self) -> int:
        """Length of :attr:`parameters`: :func:`knot_size` at every grid value."""
        return self.grid.size * knot_size(self.structure)

    @property
    def parameters(self) -> np.ndarray:
        """The family's parameters, grid value by grid value (module notes)."""
        return np.concatenate([np.concatenate([gauge_parameters(self.modal[k], self.B[k], self.C[k], self.D[k]),
                                               self.offset[k]]) for k in range(self.grid.size)])

    def with_parameters(self, theta: Any, parameter_covariance: Any = None, **meta: Any) -> "ScheduledModalModel":
        """Return the same family with other parameters.

        Parameters
        ----------
        theta : array_like
            The parameters, laid out as :attr:`parameters`.
        parameter_covariance : array_like, optional
            Their covariance; none by default.
        **meta
            Entries added to ``meta``.

        Returns
        -------
        ScheduledModalModel
            The family.
        """
        return ScheduledModalModel.from_parameters(
            self.structure, self.grid, theta, variable=self.variable, input_names=self.input_names,
            output_names=self.output_names, meta={**self.meta, **meta}, parameter_covariance=parameter_covariance,
            matching=self.matching, output_map=self.output_map)

    def _weights(self, value: float) -> np.ndarray:
        value = float(value)
        low, high = float(self.grid[0]), float(self.grid[-1])
        if not low <= value <= high:
            raise InputError(f"{self.variable} {value:g} lies outside the scheduled range {low:g}..{high:g}")
        return interpolation_weights([value], self.grid)[0]

    def model_at(self, value: float) -> ModalModel:
        """Return the modal model at one value of the scheduling variable, in canonical form.

        Where the family has a parameter covariance, the model carries the
        covariance of its own parameters (delta method through the
        interpolation and the change to the canonical form, exact CasADi
        derivatives), so that its modes and gains have standard deviations.

        Parameters
        ----------
        value : float
            The scheduling variable, within the grid's range.

        Returns
        -------
        ModalModel
            The frozen model there (the output offset and map aside).
        """
        w = self._weights(value)
        modal, B, C, D = (np.tensordot(w, array, axes=1)
                          for array in (self.modal, self.B, self.C, self.D))
        A = self.structure.matrices(np.concatenate([modal, np.zeros(self.structure.n_parameters - self.structure.n)]))[0]
        A, B, C = structure_gauge(self.structure, A, B, C)
        covariance = None
        if self.parameter_covariance is not None:
            _, jacobian = canonical_function(self.structure)(gauge_parameters(modal, np.column_stack(
                [first_input_column(self.structure), np.tensordot(w, self.B, axes=1)[:, 1:]]),
                np.tensordot(w, self.C, axes=1), D))
            m = self.structure.n_parameters
            select = np.eye(m, knot_size(self.structure))  # a grid value's parameters without its offset
            chain = np.asarray(jacobian) @ np.kron(w[None, :], select)
            covariance = chain @ self.parameter_covariance @ chain.T
        return ModalModel(self.structure, A, B, C, D, input_names=self.input_names, output_names=self.output_names,
                          meta={**self.meta, self.variable: float(value), "scheduled": True},
                          parameter_covariance=None if covariance is None else 0.5 * (covariance + covariance.T))

    def modes_at(self, values: Any, *, level: float = 0.95) -> list[dict[str, Any]]:
        """Tabulate the modes and their standard deviations at values of the scheduling variable.

        Parameters
        ----------
        values : array_like
            Values of the scheduling variable, within the grid's range.
        level : float, default 0.95
            Confidence level of the intervals.

        Returns
        -------
        list of dict
            Per value, ``{value, modes}``: each mode's ``frequency_hz``, ``frequency_hz_std``,
            ``damping``, ``damping_std`` and eigenvalue (std NaN without a covariance).
        """
        rows = []
        for value in np.atleast_1d(np.asarray(values, dtype=float)):
            modes = self.model_at(float(value)).uncertainty(level=level).modes
            rows.append({"value": float(value), "modes": [mode.as_dict() for mode in modes]})
        return rows

    def is_stable(self, *, schedule: float | None = None) -> bool:
        """Say whether every mode lies in the open left half-plane.

        Parameters
        ----------
        schedule : float, optional
            A value of the scheduling variable; without one, every grid value is
            checked (the frozen models between are interpolated, so their real
            parts lie between).

        Returns
        -------
        bool
            True when stable.
        """
        if schedule is not None:
            return self.linear_at(schedule).is_stable()
        real = np.array([[self.modal[k, s[0]] for s in self.structure.mode_states()] for k in range(self.grid.size)])
        return bool(np.all(real < 0))

    @property
    def record_inputs(self) -> int:
        """Input columns of a record the family simulates: its inputs and, last, the schedule."""
        return self.structure.n_u + 1

    #: the family is linear at each schedule value but varies along a record: the scorers of the model protocol
    #: simulate it, as a nonlinear model, its initial state fitted where the rule estimates one
    is_linear = False

    #: varies with its scheduling variable: the protocol's methods take its value (``schedule=``)
    is_scheduled = True

    @property
    def n_u(self) -> int:
        """The model's inputs, without the schedule (a record has :attr:`record_inputs` columns)."""
        return self.structure.n_u

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return self.structure.n_y

    @property
    def n_states(self) -> int:
        """Number of states (the order n)."""
        return self.structure.n

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None, schedule: Any = None,
                         method: str = "foh", return_states: bool = False) -> Any:
        """Simulate the family driven by ``u`` along a measured schedule, compiled.

        Parameters
        ----------
        u : array_like (N, n_u), or (N, n_u + 1) with the schedule last
            Input samples, time-major.
        dt : float
            Sample interval (s); required (optional only in the protocol's signature).
        x0 : array_like (n,), optional
            Initial state in the input gauge (:meth:`to_statespace`'s basis; default rest).
        schedule : array_like (N,), optional
            The scheduling variable at each sample; without it, ``u``'s last column.
        method : {"foh", "zoh", "euler"}
            Each mode advanced exactly over a sample (inputs linear or held
            between samples), or by Euler's step, with the coefficients of
            the sample's start.
        return_states : bool
            Also return the input-gauge states (N, n).

        Returns
        -------
        ndarray, shape (N, n_y), or tuple of ndarray
            The outputs; with ``return_states``, ``(y, x)``.
        """
        s = self.structure
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if schedule is not None:
            schedule = np.asarray(schedule, dtype=float).ravel()
            if u.ndim != 2 or u.shape[1] != s.n_u or schedule.shape != (u.shape[0],):
                raise InputError(f"u must have shape (N, {s.n_u}) and the schedule (N,); got {u.shape} and "
                                 f"{schedule.shape}")
            u = np.column_stack([u, schedule])
        if u.ndim != 2 or u.shape[1] != s.n_u + 1:
            raise InputError(f"u must have shape (N, {s.n_u + 1}) with the {self.variable} schedule last, or give "
                             f"schedule=; got {u.shape}")
        if not np.all(np.isfinite(u)):
            raise InputError("u or the schedule contains a non-finite value (NaN or inf)")
        if dt is None:
            raise InputError("a scheduled model (continuous time) needs the sample interval dt of its input")
        if not (dt > 0 and np.isfinite(dt)):
            raise InputError(f"dt must be positive; got {dt}")
        if method not in _HOLDS:
            raise InputError(f"unknown simulation method {method!r}; use one of {', '.join(_HOLDS)}")
        x0 = np.zeros(s.n) if x0 is None else np.asarray(x0, dtype=float).ravel()
        if x0.shape != (s.n,):
            raise InputError(f"x0 must have {s.n} entries; got {x0.shape}")
        simulator = _simulator(s, self.grid.size, _HOLDS[method])
        y, x = simulator(x0, u, np.concatenate([self.parameters, self.grid, [float(dt)]]))
        if self.output_map is not None:
            y = self.output_map.apply(y)
        return (y, x) if return_states else y

    def simulate(self, record: Any, *, x0: Any = None, method: str = "foh") -> Any:
        """The family's response to ``record`` (inputs, then the schedule) from ``x0`` (default rest).

        Parameters
        ----------
        record : IOData
            Its last input column is the schedule.
        x0 : array_like (n,), optional
            Initial state in the input gauge.
        method : {"foh", "zoh", "euler"}
            As :meth:`simulate_outputs`.

        Returns
        -------
        TimeResponse
            The record's time and inputs (the schedule among them), the family's outputs, and the record's
            outputs as ``measured``.
        """
        from .responses import simulated_response

        y = self.simulate_outputs(record.u, record.dt, x0=x0, method=method)
        return simulated_response(record, y, output_names=self.output_names)

    @property
    def schedule_range(self) -> tuple[float, float]:
        """The least and greatest value of the scheduling variable the family is defined at (its grid's ends)."""
        return float(self.grid[0]), float(self.grid[-1])

    def linear_at(self, schedule: float) -> Any:
        """Return the linear model the family is at one schedule value, in the input gauge.

        The states are those of :meth:`simulate_outputs`; the output offset and output map are left out.

        Parameters
        ----------
        schedule : float
            Within :attr:`schedule_range`.

        Returns
        -------
        ContinuousModel
            Its eigenvalues, modes and frequency response are those of :meth:`model_at` (a similarity apart).
        """
        from .discrete import ContinuousModel
        from .protocol import schedule_value

        w = self._weights(schedule_value(schedule, *self.schedule_range, self.variable))
        modal, B, C, D = (np.tensordot(w, array, axes=1) for array in (self.modal, self.B, self.C, self.D))
        rest = np.zeros(self.structure.n_parameters - self.structure.n)
        A = self.structure.matrices(np.concatenate([modal, rest]))[0]
        return ContinuousModel(A, B, C, D, self.input_names, self.output_names,
                               {**self.meta, self.variable: float(schedule), "scheduled": True})

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """Return the state-space matrices at a schedule value, in the input gauge (:meth:`linear_at`).

        Parameters
        ----------
        schedule : float
            Required: the scheduling variable, within :attr:`schedule_range`.

        Returns
        -------
        tuple
            ``(A, B, C, D, None)``: continuous time.
        """
        return self.linear_at(schedule).to_statespace()

    def eigenvalues(self, *, schedule: float | None = None) -> np.ndarray:
        """Return the eigenvalues at a schedule value.

        Parameters
        ----------
        schedule : float
            Required: the scheduling variable, within :attr:`schedule_range`.

        Returns
        -------
        ndarray of complex, shape (n,)
            The eigenvalues (1/s).
        """
        return self.linear_at(schedule).eigenvalues()

    def modes(self, *, schedule: float | None = None) -> tuple[Any, ...]:
        """Return the modes at a schedule value.

        Parameters
        ----------
        schedule : float
            Required: the scheduling variable, within :attr:`schedule_range`.

        Returns
        -------
        tuple of Mode
            One per pair and real pole.
        """
        return self.linear_at(schedule).modes()

    def frequency_response(self, f_hz: Any, *, schedule: float | None = None) -> Any:
        """Compute the linear part's frequency response at a schedule value, the output map aside.

        Parameters
        ----------
        f_hz : array_like (n_f,)
            Frequencies (Hz).
        schedule : float
            Within :attr:`schedule_range`.

        Returns
        -------
        FrequencyResponse
            The response per output and input at each frequency.
        """
        from .protocol import statespace_response

        return statespace_response(self.to_statespace(schedule=schedule), f_hz, self.input_names, self.output_names,
                                   float(schedule))

    def to_control(self, *, schedule: float | None = None) -> Any:
        """Return the linear model at a schedule value as python-control's state-space system.

        Parameters
        ----------
        schedule : float
            Required: the scheduling variable, within :attr:`schedule_range`.

        Returns
        -------
        control.StateSpace
            The continuous-time system of :meth:`linear_at`.
        """
        return self.linear_at(schedule).to_control()

    def to_casadi(self, *, name: str = "scheduled_modal_model", gauge: str = "canonical") -> ca.Function:
        """One CasADi Function ``(x, u, <variable>) -> (xdot, y)`` of the continuous-time family.

        With ``gauge="canonical"`` its states are those of :meth:`model_at`
        (the structure's canonical form); with ``gauge="input"`` those of
        :meth:`simulate_outputs`, the form to use where the schedule varies
        (module notes). The interpolated entries are piecewise-linear
        functions of the scheduling variable, held at the end values beyond
        the grid, so the Function differentiates and generates C like any
        other (for MPC).

        Parameters
        ----------
        name : str, default "scheduled_modal_model"
            The Function's name.
        gauge : {"canonical", "input"}, default "canonical"
            The states' basis.

        Returns
        -------
        casadi.Function
            ``(x, u, <variable>) -> (xdot, y)``.
        """
        if gauge not in ("canonical", "input"):
            raise InputError(f"gauge is 'canonical' or 'input'; got {gauge!r}")
        s = self.structure
        x = ca.SX.sym("x", s.n)
        u = ca.SX.sym("u", s.n_u)
        v = ca.SX.sym(self.variable)
        weights = interpolation_weights(v, [float(g) for g in self.grid])
        modal, B, C, D, offset = scheduled_matrices(s, ca.DM(self.parameters), weights)
        A = s.matrices(ca.vertcat(modal, ca.SX.zeros(s.n_parameters - s.n)), backend=ca.SX)[0]
        if gauge == "canonical":
            A, B, C = structure_gauge(s, A, B, C)
        y = ca.mtimes(C, x) + ca.mtimes(D, u) + offset
        if self.output_map is not None:
            y = self.output_map.apply_casadi(y)
        return ca.Function(name, [x, u, v], [ca.mtimes(A, x) + ca.mtimes(B, u), y],
                           ["x", "u", self.variable], ["xdot", "y"])

    def to_dict(self) -> dict[str, Any]:
        """Describe the family for JSON.

        Returns
        -------
        dict
            Every field, arrays as lists, with ``parameter_covariance`` where there is one.
        """
        return {
            "structure": self.structure.to_dict(), "grid": self.grid.tolist(), "modal": self.modal.tolist(),
            "B": self.B.tolist(), "C": self.C.tolist(), "D": self.D.tolist(), "variable": self.variable,
            "matching": [{"value": m.value, "order": list(m.order), "cost": m.cost} for m in self.matching],
            "input_names": None if self.input_names is None else list(self.input_names),
            "output_names": None if self.output_names is None else list(self.output_names), "meta": self.meta,
            "offset": self.offset.tolist(),
            **({} if self.output_map is None else {"output_map": self.output_map.to_dict()}),
            **({} if self.parameter_covariance is None
               else {"parameter_covariance": self.parameter_covariance.tolist()}),
        }

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "ScheduledModalModel":
        """Read a family that :meth:`to_dict` described.

        Parameters
        ----------
        values : mapping
            The description.

        Returns
        -------
        ScheduledModalModel
            The family.
        """
        matching = tuple(ModeMatch(float(m["value"]), tuple(int(o) for o in m["order"]), float(m["cost"]))
                         for m in values["matching"])
        names = {key: tuple(values[key]) if values.get(key) is not None else None
                 for key in ("input_names", "output_names")}
        covariance = values.get("parameter_covariance")
        return cls(ModalStructure.from_dict(values["structure"]), *(np.asarray(values[k]) for k in ("grid", "modal", "B", "C", "D")),
                   matching, str(values["variable"]), **names, meta=dict(values.get("meta") or {}),
                   parameter_covariance=None if covariance is None else np.asarray(covariance, dtype=float),
                   offset=None if values.get("offset") is None else np.asarray(values["offset"], dtype=float),
                   output_map=None if values.get("output_map") is None else OutputMap.from_dict(values["output_map"]))

    def save_json(self, path: Any) -> Any:
        """Write :meth:`to_dict` as JSON.

        Parameters
        ----------
        path : str or path-like
            The file written.

        Returns
        -------
        pathlib.Path
            The path.
        """
        import json
        from pathlib import Path

        from ..jsonable import to_jsonable

        path = Path(path)
        values = {"time_domain": "continuous", "dt": None, **self.to_dict()}
        path.write_text(json.dumps(to_jsonable(values), indent=2) + "\n")
        return path

    def save_mat(self, path: Any) -> Any:
        """Write the grid and the input-gauge arrays to a MATLAB file.

        The arrays have the grid value first; ``A``, ``B``, ``C``, ``D`` are each grid value's :meth:`to_statespace`.

        Parameters
        ----------
        path : str or path-like
            The ``.mat`` file written.

        Returns
        -------
        pathlib.Path
            The path.
        """
        from pathlib import Path

        from scipy.io import savemat

        path = Path(path)
        A = np.array([self.to_statespace(schedule=float(value))[0] for value in self.grid])
        savemat(path, {"grid": self.grid, "modal": self.modal, "A": A, "B": self.B, "C": self.C, "D": self.D,
                       "offset": self.offset,
                       "variable": self.variable,
                       **({} if self.output_map is None else {"output_map_nodes": self.output_map.nodes,
                                                               "output_map_ordinates": self.output_map.ordinates}),
                       **({} if self.parameter_covariance is None else {"parameter_covariance": self.parameter_covariance})})
        return path


def schedule_models(models: Mapping[float, ModalModel], *, variable: str = "speed") -> ScheduledModalModel:
    """The scheduled family through models identified at grid values of ``variable``.

    Parameters
    ----------
    models : mapping of float to ModalModel
        At least two models of one structure, keyed by the scheduling value.
    variable : str, default "speed"
        Name of the scheduling variable.

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
    gauged = [input_gauge(ordered[0], identity)]
    matching = [ModeMatch(values[0], tuple(identity), 0.0)]
    for value, model in zip(values[1:], ordered[1:]):
        order, cost = _match(_block_eigenvalues(structure, gauged[-1][0]), _mode_eigenvalues(model), structure.n_complex_pairs)
        gauged.append(input_gauge(model, order))
        matching.append(ModeMatch(value, tuple(order), cost))
    modal = np.array([[A[s[0], s[0]] if k == 0 else A[s[0], s[1]] for s in structure.mode_states() for k in range(len(s))]
                      for A, _, _ in gauged])
    return ScheduledModalModel(
        structure, np.array(values), modal, np.array([g[1] for g in gauged]), np.array([g[2] for g in gauged]),
        np.array([m.D for m in ordered]), tuple(matching), variable, ordered[0].input_names, ordered[0].output_names,
    )
