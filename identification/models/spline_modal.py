"""Spline-nonlinear modal models (Best & Bogdanski 2017, section 5, eq. 20-22).

Every coefficient of a linear modal model becomes a cubic spline (:mod:`vehid.identification.models.spline`) of the
variable it multiplies, through ``p`` evenly spaced nodes whose ordinates are the parameters:

* a complex pair's sigma and omega follow the pair's amplitude ``rho = sqrt(x_a^2 + x_b^2 + eps^2)``
  (``eps`` keeps its slope finite at rest), so the block stays a scaled rotation and the mode's
  frequency and damping are functions of its amplitude (the paper's Figure 8);
* a real pole's sigma follows its state; ``B_ij`` and ``D_ij`` follow input ``u_j``;
* a free ``C_ij`` follows state ``x_j``; the entries fixed to 1 set the states' scale.

Inputs and outputs are divided by their largest magnitude on the identification record, so that B and D
nodes sit evenly over -1..1. Node ranges are constants of the compiled filter, so A and C nodes can move
between passes to the range their variable reaches. ``exact`` advances each mode exactly over a sample
with its coefficients frozen at the sample's start; ``euler`` is the paper's.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..choices import SPLINE_NODE_COUNT
from ..compiled import CompiledRecursion
from ..errors import InputError
from ..optionspec import check_value
from .modal import ModalModel
from .modal_structure import ModalStructure
from .protocol import Mode, StateSpaceModel, unscheduled
from .spline import SplineBasis, resample
from .transition import check_discretization, modal_transition

__all__ = [
    "AMPLITUDE_FLOOR",
    "SplineModalStructure",
    "SplineModalModel",
    "SplineModalFilterModel",
]

AMPLITUDE_FLOOR = 1e-3  # eps of the pair amplitude, normalised units

# The unit basis on nodes 0, 1, ..., p-1: a spline over [lower, lower + (p-1) step]
# is this basis at s = (v - lower)/step, so that node ranges can be numeric inputs.
_unit_basis = functools.lru_cache(maxsize=None)(lambda p: SplineBasis.uniform(0.0, p - 1.0, p))


@dataclass(frozen=True)
class SplineModalStructure:
    """The linear structure, the number of nodes per spline, and what each coefficient follows.

    Variables (the things splines are functions of) are numbered: one
    amplitude per complex pair, then each state, then each input.

    Parameters
    ----------
    linear : ModalStructure
        The structure of the linear model whose every parameter becomes a spline.
    nodes : int, default 5
        Number of nodes (ordinates) per spline, p.
    """

    linear: ModalStructure
    nodes: int = 5

    def __post_init__(self) -> None:
        check_value("nodes", self.nodes, SPLINE_NODE_COUNT)

    @property
    def n_variables(self) -> int:
        """Number of variables: one amplitude per complex pair, then the states, then the inputs."""
        s = self.linear
        return s.n_complex_pairs + s.n + s.n_u

    def variable_names(self) -> tuple[str, ...]:
        """Name the variables.

        Returns
        -------
        tuple of str
            ``amplitude1, ..., x1, ..., u1, ...`` (1-based), in the variables' order.
        """
        s = self.linear
        return (
            tuple(f"amplitude{k + 1}" for k in range(s.n_complex_pairs))
            + tuple(f"x{j + 1}" for j in range(s.n))
            + tuple(f"u{j + 1}" for j in range(s.n_u))
        )

    def amplitude_variable(self, pair: int) -> int:
        """Return the variable of a complex pair's amplitude.

        Parameters
        ----------
        pair : int
            Pair index, 0-based.

        Returns
        -------
        int
            Its variable's index.
        """
        return pair

    def state_variable(self, state: int) -> int:
        """Return the variable of a state.

        Parameters
        ----------
        state : int
            State index, 0-based.

        Returns
        -------
        int
            Its variable's index.
        """
        return self.linear.n_complex_pairs + state

    def input_variable(self, index: int) -> int:
        """Return the variable of an input.

        Parameters
        ----------
        index : int
            Input index, 0-based.

        Returns
        -------
        int
            Its variable's index.
        """
        return self.linear.n_complex_pairs + self.linear.n + index

    def coefficient_variables(self) -> tuple[int, ...]:
        """Return the variable each linear parameter's spline follows.

        Returns
        -------
        tuple of int
            One variable index per linear parameter, in the linear theta order: a pair's
            sigma and omega follow its amplitude, a real pole and a free C entry their
            state, B and D entries their input.
        """
        s = self.linear
        follows: list[int] = []
        for pair in range(s.n_complex_pairs):
            follows += [self.amplitude_variable(pair)] * 2
        for pole in range(s.n_real):
            follows.append(self.state_variable(2 * s.n_complex_pairs + pole))
        follows += [self.input_variable(j) for _ in range(s.n) for j in range(s.n_u)]
        follows += [self.state_variable(j) for _, j in s.free_c]
        follows += [self.input_variable(j) for _ in range(s.n_y) for j in range(s.n_u)]
        return tuple(follows)

    @property
    def n_parameters(self) -> int:
        """Length of theta: p ordinates per linear parameter."""
        return self.nodes * self.linear.n_parameters

    def coefficient_names(self) -> tuple[str, ...]:
        """Name the coefficients, as the linear structure names its parameters.

        Returns
        -------
        tuple of str
            ``sigma1, omega1, ..., b11, ..., c21, ..., d11, ...``.
        """
        return self.linear.parameter_names()

    def from_linear(self, theta_linear: np.ndarray) -> np.ndarray:
        """Return theta with every node of each spline at the linear value: the nonlinear model equals the linear one.

        Parameters
        ----------
        theta_linear : array_like, shape (n_linear_parameters,)
            Parameters of the linear model (normalised units).

        Returns
        -------
        ndarray, shape (n_parameters,)
            Each linear parameter repeated p times.
        """
        theta_linear = np.asarray(theta_linear, dtype=float).ravel()
        if theta_linear.size != self.linear.n_parameters:
            raise InputError(f"expected {self.linear.n_parameters} linear parameters; got {theta_linear.size}")
        return np.repeat(theta_linear, self.nodes)

    def gammas(self, theta: np.ndarray) -> np.ndarray:
        """Arrange theta as the node ordinates of each coefficient's spline.

        Parameters
        ----------
        theta : array_like, shape (n_parameters,)
            The spline model's parameters.

        Returns
        -------
        ndarray, shape (n_coefficients, p)
            One row of ordinates per coefficient.
        """
        return np.asarray(theta, dtype=float).reshape(self.linear.n_parameters, self.nodes)

    def default_ranges(self) -> np.ndarray:
        """Return the default node ranges.

        Returns
        -------
        ndarray, shape (n_variables, 2)
            (lower, upper) per variable: amplitudes 0..1, states and inputs -1..1 (normalised units).
        """
        ranges = np.tile([-1.0, 1.0], (self.n_variables, 1))
        ranges[: self.linear.n_complex_pairs] = [0.0, 1.0]
        return ranges

    def constants(self, ranges: np.ndarray) -> np.ndarray:
        """Return the filter's constants for given node ranges.

        Parameters
        ----------
        ranges : array_like, shape (n_variables, 2)
            (lower, upper) of each variable's nodes, upper > lower.

        Returns
        -------
        ndarray, shape (2 n_variables,)
            (lower, step) per variable, interleaved.
        """
        ranges = np.asarray(ranges, dtype=float)
        if ranges.shape != (self.n_variables, 2) or not np.all(ranges[:, 1] > ranges[:, 0]):
            raise InputError(f"node ranges must be (lower, upper) with upper > lower for {self.n_variables} variables")
        step = (ranges[:, 1] - ranges[:, 0]) / (self.nodes - 1)
        return np.column_stack([ranges[:, 0], step]).ravel()

    def to_dict(self) -> dict[str, Any]:
        """Describe the structure for JSON.

        Returns
        -------
        dict
            ``linear`` (:meth:`ModalStructure.to_dict`) and ``nodes``.
        """
        return {"linear": self.linear.to_dict(), "nodes": self.nodes}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "SplineModalStructure":
        """Read the structure :meth:`to_dict` described.

        Parameters
        ----------
        values : dict
            The description.

        Returns
        -------
        SplineModalStructure
            The structure.
        """
        return cls(ModalStructure.from_dict(values["linear"]), int(values["nodes"]))


@dataclass(frozen=True)
class SplineModalFilterModel:
    """The spline-modal model as a filter model (normalised units); constants are the node ranges.

    Its simulation and the IEKF both run it: it meets the filter's
    :class:`~vehid.identification.filtering.filter_models.FilterModel` protocol by its members.
    """

    structure: SplineModalStructure

    @property
    def n_states(self) -> int:
        return self.structure.linear.n

    @property
    def n_theta(self) -> int:
        return self.structure.n_parameters

    @property
    def n_u(self) -> int:
        return self.structure.linear.n_u

    @property
    def n_y(self) -> int:
        return self.structure.linear.n_y

    @property
    def n_constants(self) -> int:
        return 2 * self.structure.n_variables

    def cache_key(self) -> str:
        return f"spline-modal:{self.structure.to_dict()}"

    def _variables(self, x: Any, u: Any) -> list[Any]:
        s = self.structure.linear
        amplitudes = [
            ca.sqrt(x[2 * k] ** 2 + x[2 * k + 1] ** 2 + AMPLITUDE_FLOOR**2) for k in range(s.n_complex_pairs)
        ]
        return amplitudes + [x[j] for j in range(s.n)] + [u[j] for j in range(s.n_u)]

    def _bases(self, variables: list[Any], constants: Any, needed: set[int]) -> dict[int, Any]:
        basis = _unit_basis(self.structure.nodes)
        return {
            v: basis.symbolic((variables[v] - constants[2 * v]) / constants[2 * v + 1]) for v in sorted(needed)
        }

    def coefficients(self, x: Any, theta: Any, u: Any, constants: Any, which: slice | None = None) -> list[Any]:
        """Every linear coefficient's value at (x, u), as SX, in the linear theta order."""
        st = self.structure
        p = st.nodes
        follows = st.coefficient_variables()
        indices = range(st.linear.n_parameters)[which or slice(None)]
        bases = self._bases(self._variables(x, u), constants, {follows[i] for i in indices})
        return [ca.dot(bases[follows[i]], theta[i * p:(i + 1) * p]) for i in indices]

    def _input_drive(self, x: Any, theta: Any, u: Any, constants: Any) -> Any:
        s = self.structure.linear
        b = self.coefficients(x, theta, u, constants, self.structure.linear.slices()["B"])
        return [sum(b[i * s.n_u + j] * u[j] for j in range(s.n_u)) for i in range(s.n)]

    def transition(self, x: ca.SX, theta: ca.SX, u0: ca.SX, u1: ca.SX, dt: float, discretization: str,
                   constants: ca.SX) -> ca.SX:
        check_discretization(discretization)
        s = self.structure.linear
        modal = self.coefficients(x, theta, u0, constants, s.slices()["modal"])
        drive0 = self._input_drive(x, theta, u0, constants)
        drive1 = self._input_drive(x, theta, u1, constants)
        return modal_transition(s, modal, x, drive0, drive1, dt, discretization)

    def output(self, x: ca.SX, theta: ca.SX, u: ca.SX, constants: ca.SX) -> ca.SX:
        s = self.structure.linear
        sl = s.slices()
        c_free = self.coefficients(x, theta, u, constants, sl["C"])
        d = self.coefficients(x, theta, u, constants, sl["D"])
        y = [0] * s.n_y
        for i, j in s.fixed_c:
            y[i] = y[i] + x[j]
        for k, (i, j) in enumerate(s.free_c):
            y[i] = y[i] + c_free[k] * x[j]
        for i in range(s.n_y):
            for j in range(s.n_u):
                y[i] = y[i] + d[i * s.n_u + j] * u[j]
        return ca.vertcat(*y)


@functools.lru_cache(maxsize=16)
def _simulator(structure: SplineModalStructure, discretization: str) -> CompiledRecursion:
    """Compiled simulation of the normalised model: params = [theta; constants; dt].

    The sample time is a parameter rather than a constant of the code, so that one library serves
    every record of the structure."""
    model = SplineModalFilterModel(structure)
    x = ca.SX.sym("x", model.n_states)
    u0 = ca.SX.sym("u0", model.n_u)
    u1 = ca.SX.sym("u1", model.n_u)
    params = ca.SX.sym("params", model.n_theta + model.n_constants + 1)
    theta, constants, dt = params[: model.n_theta], params[model.n_theta:-1], params[-1]
    step = ca.Function(
        "spline_modal_step",
        [x, u0, u1, params],
        [model.transition(x, theta, u0, u1, dt, discretization, constants), model.output(x, theta, u0, constants)],
        ["x", "u0", "u1", "params"],
        ["x_next", "y"],
        {"cse": True},
    )
    return CompiledRecursion(step, optimisation="-O1")


@functools.lru_cache(maxsize=256)
def _uniform_basis(lower: float, upper: float, count: int) -> SplineBasis:
    """A uniform basis, shared between models: a basis is never changed once built, and a model and
    its sampled neighbours (one node range each) linearise thousands of times."""
    return SplineBasis.uniform(lower, upper, count)


@dataclass(frozen=True, eq=False)
class SplineModalModel(StateSpaceModel):
    """An identified spline-nonlinear modal model: a frozen value.

    Parameters
    ----------
    structure : SplineModalStructure
        The linear structure and the number of nodes per spline.
    theta : ndarray (n_coefficients * p,)
        Node ordinates, coefficient by coefficient (normalised units).
    ranges : ndarray (n_variables, 2)
        Node range (lower, upper) of every variable (normalised units).
    input_scale, output_scale : ndarray
        The normalisation: ``u_normalised = u / input_scale``, ``y = output_scale * y_normalised``.
    dt : float
        The sample interval it was identified at (s).
    discretization : {"exact", "exact-zoh", "euler"}, default "exact"
        The filter's discretisation of the continuous model, which its simulation repeats.
    input_names, output_names : tuple of str, optional
        Channel names.
    meta : dict, optional
        Provenance (estimator, passes, ...).
    parameter_covariance : ndarray, optional
        Covariance of ``theta`` (normalised units), as the spline IEKF left it
        in its P; ``None`` where none was estimated.
    """

    structure: SplineModalStructure
    theta: np.ndarray
    ranges: np.ndarray
    input_scale: np.ndarray
    output_scale: np.ndarray
    dt: float
    discretization: str = "exact"
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    parameter_covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        st = self.structure
        for name, expected in (
            ("theta", (st.n_parameters,)), ("ranges", (st.n_variables, 2)),
            ("input_scale", (st.linear.n_u,)), ("output_scale", (st.linear.n_y,)),
        ):
            array = np.array(getattr(self, name), dtype=float)
            if array.shape != expected:
                raise InputError(f"{name} has shape {array.shape}; expected {expected}")
            if not np.all(np.isfinite(array)):
                raise InputError(f"{name} holds a non-finite value")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        st.constants(self.ranges)  # checks the ranges
        check_discretization(self.discretization)
        object.__setattr__(self, "meta", dict(self.meta))
        if self.parameter_covariance is not None:
            from .delta_method import checked_covariance

            object.__setattr__(self, "parameter_covariance",
                               checked_covariance(self.parameter_covariance, st.n_parameters))

    @classmethod
    def from_linear(
        cls, linear: ModalModel, nodes: int, input_scale: np.ndarray, output_scale: np.ndarray, dt: float,
        discretization: str = "exact", ranges: np.ndarray | None = None,
    ) -> "SplineModalModel":
        """Make the nonlinear model equal to ``linear``: every node at its (normalised) value.

        Parameters
        ----------
        linear : ModalModel
            The linear model, in original units.
        nodes : int
            Number of nodes per spline.
        input_scale, output_scale : ndarray, shapes (n_u,) and (n_y,)
            The normalisation: ``u_normalised = u / input_scale``, ``y = output_scale * y_normalised``.
        dt : float
            Sample interval (s).
        discretization : {"exact", "exact-zoh", "euler"}, default "exact"
            The discretisation of the continuous model.
        ranges : ndarray, shape (n_variables, 2), optional
            Node ranges; :meth:`SplineModalStructure.default_ranges` by default.

        Returns
        -------
        SplineModalModel
            The model.
        """
        structure = SplineModalStructure(linear.structure, nodes)
        theta_linear = linear.structure.normalize_parameters(linear.parameters, np.asarray(input_scale, float), np.asarray(output_scale, float))
        return cls(
            structure, structure.from_linear(theta_linear),
            structure.default_ranges() if ranges is None else ranges,
            input_scale, output_scale, dt, discretization,
            input_names=linear.input_names, output_names=linear.output_names,
        )

    @property
    def constants(self) -> np.ndarray:
        """The filter's constants of the node ranges, (lower, step) per variable."""
        return self.structure.constants(self.ranges)

    def state_scale(self) -> np.ndarray:
        """Return the scale of each state.

        Returns
        -------
        ndarray, shape (n,)
            Original units of each state (those of its tied output) per normalised unit.
        """
        s = self.structure.linear
        return np.array([self.output_scale[s.output_of_state(j)] for j in range(s.n)])

    def simulate_normalised(self, u_normalised: np.ndarray, x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Simulate in normalised units, compiled.

        Parameters
        ----------
        u_normalised : ndarray, shape (N, n_u)
            Inputs divided by ``input_scale``.
        x0 : ndarray, shape (n,), optional
            Initial state in normalised units; zero by default.

        Returns
        -------
        tuple of ndarray
            ``(y, x)``, shapes (N, n_y) and (N, n), normalised units.
        """
        sim = _simulator(self.structure, self.discretization)
        x0 = np.zeros(self.structure.linear.n) if x0 is None else x0
        return sim(x0, u_normalised, np.concatenate([self.theta, self.constants, [float(self.dt)]]))

    #: Nonlinear: its state-space form is the linearisation at rest, and scores simulate it (its initial state fitted
    #: by Gauss-Newton where the rule estimates one).
    is_linear = False

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return self.structure.linear.n_u

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return self.structure.linear.n_y

    @property
    def n_states(self) -> int:
        """Number of states (the order n)."""
        return self.structure.linear.n

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None, schedule: Any = None,
                         return_states: bool = False) -> Any:
        """Simulate the outputs in original units.

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Inputs in original units, time-major.
        dt : float, optional
            Must equal the sample interval the model was identified at (its
            discrete-time behaviour is tied to it), if given.
        x0 : array_like, shape (n,), optional
            Initial state in original units; rest by default.
        schedule : array_like, optional
            Changes nothing (the model is not scheduled).
        return_states : bool, default False
            Also return the states.

        Returns
        -------
        ndarray, shape (N, n_y), or tuple of ndarray
            The outputs; with ``return_states``, ``(y, x)`` with ``x`` of shape (N, n) in original units.
        """
        u = self.checked_input(u)
        unscheduled(schedule, u.shape[0])
        if dt is not None and not np.isclose(dt, self.dt, rtol=1e-9):
            raise InputError(f"this model was identified at dt = {self.dt} s; got {dt} s")
        start = self.checked_state(x0) / self.state_scale()
        y, x = self.simulate_normalised(u / self.input_scale, start)
        y = y * self.output_scale
        return (y, x * self.state_scale()) if return_states else y

    def spline(self, coefficient: int | str) -> tuple[SplineBasis, np.ndarray]:
        """Return one coefficient's spline.

        Parameters
        ----------
        coefficient : int or str
            Its index or name (e.g. ``"sigma1"``, ``"b21"``).

        Returns
        -------
        tuple
            ``(basis, ordinates)``: the :class:`SplineBasis` on the variable's node range
            and the p ordinates (normalised units).
        """
        names = self.structure.coefficient_names()
        index = names.index(coefficient) if isinstance(coefficient, str) else int(coefficient)
        variable = self.structure.coefficient_variables()[index]
        lower, upper = self.ranges[variable]
        basis = SplineBasis.uniform(lower, upper, self.structure.nodes)
        return basis, self.structure.gammas(self.theta)[index]

    def coefficient(self, name: str, values: Any) -> np.ndarray:
        """Evaluate a coefficient at values of the variable it follows.

        Parameters
        ----------
        name : str
            The coefficient's name (e.g. ``"sigma1"``).
        values : array_like
            Values of its variable (normalised units).

        Returns
        -------
        ndarray
            The coefficient at each value (normalised units), flattened.
        """
        basis, gamma = self.spline(name)
        return basis.evaluate(np.asarray(values, dtype=float).ravel()) @ gamma

    def spline_tables(self) -> dict[str, dict[str, Any]]:
        """Tabulate every coefficient's spline.

        Returns
        -------
        dict of str to dict
            Per coefficient: ``variable`` (the name of the variable it follows), ``nodes``
            (positions) and ``values`` (ordinates), normalised units.
        """
        variables = self.structure.variable_names()
        follows = self.structure.coefficient_variables()
        tables = {}
        for index, name in enumerate(self.structure.coefficient_names()):
            basis, gamma = self.spline(index)
            tables[name] = {"variable": variables[follows[index]], "nodes": basis.nodes.copy(), "values": gamma.copy()}
        return tables

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """Return the continuous state-space form of :meth:`linear_model` at zero amplitude.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the model is not scheduled).

        Returns
        -------
        tuple
            ``(A, B, C, D, None)`` in original units.
        """
        return self.linear_model().to_statespace(schedule=schedule)

    def eigenvalues(self, *, schedule: float | None = None) -> np.ndarray:
        """Return the eigenvalues of :meth:`linear_model` at zero amplitude.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the model is not scheduled).

        Returns
        -------
        ndarray of complex, shape (n,)
            The eigenvalues (1/s).
        """
        return self.linear_model().eigenvalues(schedule=schedule)

    def modes(self, *, schedule: float | None = None, amplitude: float = 0.0) -> tuple[Mode, ...]:
        """Return the modes of :meth:`linear_model` at an amplitude.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the model is not scheduled).
        amplitude : float, default 0.0
            Amplitude (normalised) at which each pair is taken.

        Returns
        -------
        tuple of Mode
            One per mode, pairs first.
        """
        return self.linear_model(amplitude).modes(schedule=schedule)

    def mat_fields(self) -> dict[str, Any]:
        """Return the fields of the model's MATLAB file.

        Returns
        -------
        dict
            The linearisation's A, B, C, D with ``theta`` (the ordinates), ``ranges``,
            ``input_scale``, ``output_scale`` and ``Ts``.
        """
        return {**super().mat_fields(), "theta": self.theta, "ranges": self.ranges, "input_scale": self.input_scale,
                "output_scale": self.output_scale, "Ts": self.dt}

    def _block(self, index: int) -> np.ndarray | None:
        """The covariance of one coefficient's node ordinates (p, p), or None."""
        if self.parameter_covariance is None:
            return None
        p = self.structure.nodes
        return self.parameter_covariance[index * p:(index + 1) * p, index * p:(index + 1) * p]

    def coefficient_std(self, name: str, values: Any) -> np.ndarray:
        """Return the standard deviation of a coefficient at values of its variable.

        The spline is linear in its ordinates, ``c(v) = phi(v)' gamma``, so
        ``var c(v) = phi(v)' cov(gamma) phi(v)`` exactly.

        Parameters
        ----------
        name : str
            The coefficient's name.
        values : array_like
            Values of its variable (normalised units).

        Returns
        -------
        ndarray
            Standard deviation at each value (normalised units); NaN without a covariance.
        """
        index = self.structure.coefficient_names().index(name)
        basis, _ = self.spline(index)
        rows = basis.evaluate(np.asarray(values, dtype=float).ravel())
        block = self._block(index)
        if block is None:
            return np.full(rows.shape[0], np.nan)
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", rows, block, rows), 0.0))

    def mode_frequency_damping_std(self, mode: int, amplitudes: Any) -> tuple[np.ndarray, np.ndarray]:
        """Return the standard deviations of a pair's frequency and damping by the delta method.

        The values are those of :meth:`modes`. With ``sigma = phi' g_s``, ``omega = phi' g_w`` and ``r = |sigma + j omega|``:
        ``df = (sigma ds + omega dw) / (2 pi r)``, ``dzeta = (-omega^2 ds + sigma omega dw) / r^3``;
        the ordinates of sigma and omega and their cross-covariance enter.

        Parameters
        ----------
        mode : int
            The complex pair, 0-based.
        amplitudes : array_like, shape (K,)
            Amplitudes (normalised) of the pair.

        Returns
        -------
        tuple of ndarray
            Standard deviations of the frequency (Hz) and of the damping ratio, each
            shape (K,); NaN without a covariance.
        """
        if not 0 <= mode < self.structure.linear.n_complex_pairs:
            raise InputError(f"mode {mode} is not a complex pair of this model")
        amplitudes = np.asarray(amplitudes, dtype=float).ravel()
        if self.parameter_covariance is None:
            return np.full(amplitudes.size, np.nan), np.full(amplitudes.size, np.nan)
        names = self.structure.coefficient_names()
        indices = [names.index(f"sigma{mode + 1}"), names.index(f"omega{mode + 1}")]
        p = self.structure.nodes
        rows = self.spline(indices[0])[0].evaluate(amplitudes)  # sigma and omega share the amplitude's nodes
        sigma = rows @ self.structure.gammas(self.theta)[indices[0]]
        omega = rows @ self.structure.gammas(self.theta)[indices[1]]
        radius = np.hypot(sigma, omega)
        positions = np.concatenate([np.arange(i * p, (i + 1) * p) for i in indices])
        covariance = self.parameter_covariance[np.ix_(positions, positions)]
        results = []
        for d_sigma, d_omega in ((sigma / (2 * np.pi * radius), omega / (2 * np.pi * radius)),
                                 (-omega**2 / radius**3, sigma * omega / radius**3)):
            jacobian = np.hstack([d_sigma[:, None] * rows, d_omega[:, None] * rows])
            results.append(np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jacobian, covariance, jacobian), 0.0)))
        return results[0], results[1]

    def linear_model(self, at: float = 0.0) -> ModalModel:
        """Return the linear model of the splines' values at zero input and states.

        Parameters
        ----------
        at : float, default 0.0
            The pairs' amplitude (normalised).

        Returns
        -------
        ModalModel
            The linear model in original units.
        """
        st = self.structure
        values = []
        follows = st.coefficient_variables()
        gammas = st.gammas(self.theta)
        # The coefficients following one variable share its basis and its row at the point: built once per
        # variable, not per coefficient (a sampled band evaluates thousands of linearisations)
        rows: dict[int, np.ndarray] = {}
        for index, variable in enumerate(follows):
            if variable not in rows:
                lower, upper = self.ranges[variable]
                point = at if variable < st.linear.n_complex_pairs else 0.0
                rows[variable] = _uniform_basis(float(lower), float(upper), st.nodes).evaluate(np.array([point], dtype=float))
            values.append(float((rows[variable] @ gammas[index])[0]))
        theta = st.linear.denormalize(np.array(values), self.input_scale, self.output_scale)
        return ModalModel.from_parameters(st.linear, theta, input_names=self.input_names, output_names=self.output_names)

    def resampled(self, ranges: np.ndarray) -> tuple["SplineModalModel", np.ndarray]:
        """Return the same functions on new node ranges.

        Parameters
        ----------
        ranges : array_like, shape (n_variables, 2)
            The new node ranges.

        Returns
        -------
        tuple
            The resampled model, and the linear map of theta, shape (n_parameters,
            n_parameters), that carries a covariance over.
        """
        st = self.structure
        ranges = np.asarray(ranges, dtype=float)
        follows = st.coefficient_variables()
        p = st.nodes
        transform = np.eye(st.n_parameters)
        maps = {}
        for variable in set(follows):
            old = SplineBasis.uniform(*self.ranges[variable], p)
            new = SplineBasis.uniform(*ranges[variable], p)
            maps[variable] = resample(old, np.eye(p), new)
        for index, variable in enumerate(follows):
            transform[index * p:(index + 1) * p, index * p:(index + 1) * p] = maps[variable]
        theta = transform @ self.theta
        model = SplineModalModel(
            st, theta, ranges, self.input_scale, self.output_scale, self.dt, self.discretization,
            self.input_names, self.output_names, self.meta,
        )
        return model, transform

    def with_parameters(self, theta: np.ndarray, **meta: Any) -> "SplineModalModel":
        """Return the model with other ordinates.

        Parameters
        ----------
        theta : ndarray, shape (n_parameters,)
            The new ordinates (normalised units).
        **meta
            Entries added to ``meta``.

        Returns
        -------
        SplineModalModel
            The model (without a parameter covariance).
        """
        return SplineModalModel(
            self.structure, theta, self.ranges, self.input_scale, self.output_scale, self.dt, self.discretization,
            self.input_names, self.output_names, {**self.meta, **meta},
        )

    def to_casadi(self, *, n_samples: int | None = None) -> ca.Function:
        """A self-contained CasADi Function in original units, splines, ranges and scales embedded.

        Without ``n_samples``: one step ``vehid_spline_step(x, u0, u1) -> (x_next, y)``, the state in
        original units (those of the output each state is tied to, as :meth:`simulate_outputs`' ``x0``);
        with it: ``vehid_spline_model(u (n_u, N)) -> y (n_y, N)``, the
        simulation from rest. Save it with ``Function.save(path)`` and load it
        with ``casadi.Function.load`` where the workbench is not installed.

        Parameters
        ----------
        n_samples : int, optional
            Length N of the simulation the Function computes; one step without it.

        Returns
        -------
        casadi.Function
            The step or the simulation.
        """
        model = SplineModalFilterModel(self.structure)
        x = ca.SX.sym("x", model.n_states)
        u0 = ca.SX.sym("u0", model.n_u)
        u1 = ca.SX.sym("u1", model.n_u)
        theta = ca.DM(self.theta)
        constants = ca.DM(self.constants)
        scale_in = ca.DM(1.0 / self.input_scale)
        u0n, u1n = u0 * scale_in, u1 * scale_in
        state_scale = ca.DM(self.state_scale())  # the state in original units, as simulate_outputs' x0
        xn = x / state_scale
        step = ca.Function(
            "vehid_spline_step", [x, u0, u1],
            [model.transition(xn, theta, u0n, u1n, self.dt, self.discretization, constants) * state_scale,
             model.output(xn, theta, u0n, constants) * ca.DM(self.output_scale)],
            ["x", "u0", "u1"], ["x_next", "y"],
        )
        if n_samples is None:
            return step
        lifted = step.mapaccum("vehid_spline_steps", n_samples)
        u = ca.MX.sym("u", model.n_u, n_samples)
        u_next = ca.horzcat(u[:, 1:], u[:, n_samples - 1])
        _, y = lifted(ca.MX.zeros(model.n_states), u, u_next)
        return ca.Function("vehid_spline_model", [u], [y], ["u"], ["y"])

    def to_dict(self) -> dict[str, Any]:
        """Describe the model for JSON.

        Returns
        -------
        dict
            Every field, arrays as lists; ``parameter_covariance`` only where estimated.
        """
        return {
            "structure": self.structure.to_dict(),
            "theta": self.theta.tolist(),
            "ranges": self.ranges.tolist(),
            "input_scale": self.input_scale.tolist(),
            "output_scale": self.output_scale.tolist(),
            "dt": self.dt,
            "discretization": self.discretization,
            "input_names": list(self.input_names or ()),
            "output_names": list(self.output_names or ()),
            "meta": self.meta,
            **({} if self.parameter_covariance is None else {"parameter_covariance": self.parameter_covariance.tolist()}),
        }

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "SplineModalModel":
        """Read a model that :meth:`to_dict` described.

        Parameters
        ----------
        values : dict
            The description.

        Returns
        -------
        SplineModalModel
            The model.
        """
        covariance = values.get("parameter_covariance")
        return cls(
            SplineModalStructure.from_dict(values["structure"]), np.array(values["theta"]),
            np.array(values["ranges"]), np.array(values["input_scale"]), np.array(values["output_scale"]),
            float(values["dt"]), values.get("discretization", "exact"),
            tuple(values.get("input_names") or ()) or None, tuple(values.get("output_names") or ()) or None,
            dict(values.get("meta") or {}),
            None if covariance is None else np.array(covariance, dtype=float),
        )
