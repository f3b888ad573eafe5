"""An identified grey-box model as a value that meets the model protocol: its functions with their parameters.

:class:`~identification.filtering.greybox_structure.GreyBoxModel` is a structure (``dx/dt = f(x, u, theta, s)``,
``y = h(x, u, theta, s)`` with named constants ``theta``); :class:`IdentifiedGreyBox` is that structure with
the values (and covariance) an estimator found, simulated by the compiled recursion the estimator used
(:func:`~identification.filtering.greybox_structure.greybox_outputs`). It meets
:class:`~identification.models.protocol.IdentifiedModel` as a nonlinear model (``is_linear`` False:
scores simulate it from rest), scheduled where the structure has scheduling signals ``s``: at a schedule
value its state-space form is the exact linearisation (CasADi's Jacobians) about rest, ``x = 0`` and
``u = 0``, the state the estimator starts every record from. Its extras are the structure's own:
:attr:`IdentifiedGreyBox.model`, the named :attr:`~IdentifiedGreyBox.parameters` with their standard
deviations, and :meth:`IdentifiedGreyBox.to_casadi`, the continuous-time functions with the parameters in them.

Stored (JSON, archives) as plain data: names, the functions' algorithms as tables
(:mod:`~identification.casadi_codec`, nothing that runs code when read) and the numbers.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import casadi as ca
import numpy as np

from ..data import IOData
from ..errors import InputError
from ..models.protocol import StateSpaceModel, unscheduled
from .greybox_structure import GREYBOX_DISCRETIZATIONS, GreyBoxModel, greybox_outputs

__all__ = ["IdentifiedGreyBox", "stable_over", "schedule_columns"]

#: Points of a schedule's range at which ``is_stable()`` without a schedule value checks a model.
STABILITY_POINTS = 9


def stable_over(model: Any, low: Any, high: Any) -> bool:
    """Whether ``model`` is stable at :data:`STABILITY_POINTS` schedule values spread evenly over ``low``..``high``.

    A model whose stability changes between two of them is not caught; for a car, whose stability
    changes once with speed (an oversteering car above its critical speed), the ends decide.

    Parameters
    ----------
    model : IdentifiedModel
        A scheduled model (its ``is_stable(schedule=...)`` at one value).
    low, high : float or array_like (n_s,)
        The ends of the range (per scheduling signal).

    Returns
    -------
    bool
    """
    low, high = np.atleast_1d(np.asarray(low, dtype=float)), np.atleast_1d(np.asarray(high, dtype=float))
    for share in np.linspace(0.0, 1.0, STABILITY_POINTS):
        value = low + share * (high - low)
        if not model.is_stable(schedule=float(value[0]) if value.size == 1 else value):
            return False
    return True


def schedule_columns(u: Any, schedule: Any, n_u: int, n_s: int, variable: str) -> np.ndarray:
    """``u`` (N, n_u) with ``schedule`` (N,) or (N, n_s) as further columns, or ``u`` (N, n_u + n_s) as it is.

    Parameters
    ----------
    u : array_like
        Inputs, or inputs then the scheduling signals where ``schedule`` is None.
    schedule : array_like, optional
    n_u, n_s : int
        Inputs and scheduling signals of the model.
    variable : str
        The scheduling signals' names, for the messages.

    Returns
    -------
    ndarray (N, n_u + n_s), finite
    """
    u = np.asarray(u, dtype=float)
    if u.ndim == 1:
        u = u[:, None]
    if schedule is not None:
        values = np.asarray(schedule, dtype=float)
        values = values.reshape(-1, 1) if values.ndim == 1 else values
        if u.ndim != 2 or u.shape[1] != n_u or values.shape != (u.shape[0], n_s):
            shape = "(N,)" if n_s == 1 else f"(N, {n_s})"
            raise InputError(f"u must have shape (N, {n_u}) and the schedule ({variable}) {shape}; "
                             f"got {u.shape} and {np.shape(schedule)}")
        u = np.column_stack([u, values])
    if u.ndim != 2 or u.shape[1] != n_u + n_s:
        raise InputError(f"u must have shape (N, {n_u + n_s}), the schedule ({variable}) last, or give schedule=; "
                         f"got {u.shape}")
    if not np.all(np.isfinite(u)):
        raise InputError("u or the schedule contains a non-finite value (NaN or inf)")
    return u


@functools.lru_cache(maxsize=16)
def _linearisation(model_key: str, model: GreyBoxModel) -> ca.Function:
    """``(theta, s) -> (A, B, C, D)``: the Jacobians at ``x = 0``, ``u = 0`` (exact, CasADi)."""
    x, u = ca.SX.sym("x", model.n_states), ca.SX.sym("u", model.n_u)
    theta, s = ca.SX.sym("theta", model.n_theta), ca.SX.sym("s", model.n_s)
    rates, outputs = model.dynamics(x, u, theta, s), model.output(x, u, theta, s)
    at_rest = [ca.substitute(ca.substitute(jacobian, x, ca.DM.zeros(model.n_states)), u, ca.DM.zeros(model.n_u))
               for jacobian in (ca.jacobian(rates, x), ca.jacobian(rates, u), ca.jacobian(outputs, x),
                                ca.jacobian(outputs, u))]
    return ca.Function(f"greybox_linearisation_{model_key[:12]}", [theta, s], at_rest, ["theta", "s"],
                       ["A", "B", "C", "D"])


def _model_dict(model: GreyBoxModel) -> dict[str, Any]:
    from ..casadi_codec import function_table

    def plain(table: dict[str, Any]) -> dict[str, Any]:
        return {key: value.tolist() if isinstance(value, np.ndarray) else value for key, value in table.items()}

    return {"dynamics": plain(function_table(model.dynamics)), "output": plain(function_table(model.output)),
            **{name: list(getattr(model, name)) for name in (
                "parameter_names", "parameter_units", "positive", "state_names", "input_names", "schedule_names",
                "output_names", "parameter_scale")},
            "description": model.description}


def _model_from(values: Mapping[str, Any]) -> GreyBoxModel:
    from ..casadi_codec import table_function

    return GreyBoxModel(dynamics=table_function(values["dynamics"]), output=table_function(values["output"]),
                        parameter_names=tuple(values["parameter_names"]),
                        parameter_units=tuple(values["parameter_units"]),
                        positive=tuple(bool(v) for v in values["positive"]), state_names=tuple(values["state_names"]),
                        input_names=tuple(values["input_names"]), schedule_names=tuple(values["schedule_names"]),
                        output_names=tuple(values["output_names"]), description=str(values["description"]),
                        parameter_scale=tuple(float(v) for v in values["parameter_scale"]))


@dataclass(frozen=True, eq=False)
class IdentifiedGreyBox(StateSpaceModel):
    """A grey-box model with identified parameters: a frozen value meeting the model protocol (module notes).

    Parameters
    ----------
    model : GreyBoxModel
        The structure: its functions and names.
    parameters : array_like (n_theta,)
        In the order (and units) of ``model.parameter_names``.
    parameter_covariance : array_like (n_theta, n_theta), optional
        Covariance of ``parameters``; None where none was estimated.
    discretization : {"rk4", "euler"}
        How :meth:`simulate_outputs` steps the model over a sample (the estimator's).
    substeps : int
        Runge-Kutta steps per sample.
    schedule_range : array_like (n_s, 2), optional
        Least and greatest value of each scheduling signal the model was identified over: where given,
        ``is_stable()`` without a schedule value checks the model across it (:func:`stable_over`).
    meta : dict, optional
        Provenance (stop reason, sample interval, covariance notes).

    Examples
    --------
    A first-order lag ``dx/dt = (K u - x) / tau``, ``y = x``, with its time constant scheduled on ``s``
    (``tau = T s``):

    >>> import casadi as ca
    >>> import numpy as np
    >>> from vehid.identification import GreyBoxModel
    >>> x, u, s, theta = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("s"), ca.SX.sym("theta", 2)
    >>> lag = GreyBoxModel(ca.Function("f", [x, u, theta, s], [(theta[0] * u - x) / (theta[1] * s)]),
    ...                    ca.Function("h", [x, u, theta, s], [x]), ("gain", "time_constant"), ("-", "s"),
    ...                    (True, True), ("x",), ("u",), ("s",), ("y",))
    >>> model = IdentifiedGreyBox(lag, [2.0, 0.5])
    >>> model.eigenvalues(schedule=4.0)  # -1 / (T s)
    array([-0.5])
    >>> y = model.simulate_outputs(np.ones(2001), 0.01, schedule=np.full(2001, 4.0))
    >>> round(float(y[-1, 0]), 4)  # the steady gain K after 10 time constants
    1.9999
    """

    model: GreyBoxModel
    parameters: np.ndarray
    parameter_covariance: np.ndarray | None = None
    discretization: str = "rk4"
    substeps: int = 1
    schedule_range: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    #: Nonlinear in general: scores simulate it from rest, and its state-space form is a linearisation.
    is_linear = False

    def __post_init__(self) -> None:
        if not isinstance(self.model, GreyBoxModel):
            raise InputError(f"model must be a GreyBoxModel; got {type(self.model).__name__}")
        parameters = self.model.check_parameters(self.parameters)
        parameters.setflags(write=False)
        object.__setattr__(self, "parameters", parameters)
        n = self.model.n_theta
        if self.parameter_covariance is not None:
            covariance = np.array(self.parameter_covariance, dtype=float)
            if covariance.shape != (n, n):
                raise InputError(f"the parameter covariance must be {n} x {n}; got {covariance.shape}")
            covariance.setflags(write=False)
            object.__setattr__(self, "parameter_covariance", covariance)
        if self.discretization not in GREYBOX_DISCRETIZATIONS:
            raise InputError(f"unknown discretization {self.discretization!r}; use one of "
                             f"{', '.join(GREYBOX_DISCRETIZATIONS)}")
        if isinstance(self.substeps, bool) or int(self.substeps) != self.substeps or self.substeps < 1:
            raise InputError(f"substeps must be a whole number >= 1; got {self.substeps!r}")
        object.__setattr__(self, "substeps", int(self.substeps))
        if self.schedule_range is not None:
            bounds = np.array(self.schedule_range, dtype=float).reshape(-1, 2)
            ordered = bounds.shape == (self.model.n_s, 2) and bool(np.all(bounds[:, 0] <= bounds[:, 1]))
            if not ordered or not np.all(np.isfinite(bounds)):
                raise InputError(f"schedule_range must hold an ordered (least, greatest) pair per scheduling signal "
                                 f"({self.model.n_s}); got {np.shape(self.schedule_range)}")
            bounds.setflags(write=False)
            object.__setattr__(self, "schedule_range", bounds)
        object.__setattr__(self, "meta", dict(self.meta))

    @classmethod
    def from_result(cls, result: Any, *, schedule_range: Any = None) -> "IdentifiedGreyBox":
        """The estimate of a :class:`~identification.filtering.greybox.GreyBoxResult` as a model value.

        Parameters
        ----------
        result : GreyBoxResult
            The grey-box IEKF's result.
        schedule_range : array_like (n_s, 2), optional
            The least and greatest value of each scheduling signal over the records (where the model has any).

        Returns
        -------
        IdentifiedGreyBox
            The structure with the parameters, their covariance (None where it could not be had), the run's
            discretisation, and in ``meta`` its stop reason, sample interval and covariance notes.
        """
        covariance = result.covariance if np.all(np.isfinite(result.covariance)) else None
        return cls(result.model, result.parameters, covariance, result.options.discretization, result.options.substeps,
                   schedule_range, {"stop_reason": result.stop_reason, "dt": result.dt, **result.meta})

    @property
    def is_scheduled(self) -> bool:
        """True where the structure has scheduling signals."""
        return self.model.n_s > 0

    @property
    def n_states(self) -> int:
        """Number of states of the model definition."""
        return self.model.n_states

    @property
    def n_u(self) -> int:
        """Number of inputs, the scheduling signals apart."""
        return self.model.n_u

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return self.model.n_y

    @property
    def record_inputs(self) -> int:
        """Input columns of a record: the inputs, then the scheduling signals."""
        return self.model.n_u + self.model.n_s

    @property
    def input_names(self) -> tuple[str, ...]:
        """The structure's input names."""
        return self.model.input_names

    @property
    def output_names(self) -> tuple[str, ...] | None:  # type: ignore[override]
        """The structure's output names (None where it has none)."""
        return self.model.output_names or None

    @property
    def parameter_std(self) -> np.ndarray | None:
        """Standard deviation of each parameter (None without a covariance)."""
        if self.parameter_covariance is None:
            return None
        return np.sqrt(np.clip(np.diag(self.parameter_covariance), 0.0, None))

    def with_parameters(self, theta: Any) -> "IdentifiedGreyBox":
        """Return the same model with other parameters.

        Parameters
        ----------
        theta : array_like, shape (n_theta,)
            The parameters.

        Returns
        -------
        IdentifiedGreyBox
            The model, without a covariance.
        """
        return IdentifiedGreyBox(self.model, theta, None, self.discretization, self.substeps, self.schedule_range,
                                 self.meta)

    def _schedule_point(self, schedule: Any) -> np.ndarray:
        """The scheduling signals' values (n_s,) at one operating point; InputError naming what is missing."""
        n_s = self.model.n_s
        if n_s == 0:
            unscheduled(schedule)
            return np.zeros(0)
        names = ", ".join(self.model.schedule_names)
        if schedule is None:
            raise InputError(f"this model is scheduled on {names}: give schedule= a value"
                             f"{'' if n_s == 1 else f' for each of its {n_s} signals'}")
        values = np.atleast_1d(np.asarray(schedule, dtype=float)).ravel()
        if values.shape != (n_s,) or not np.all(np.isfinite(values)):
            raise InputError(f"schedule must be {n_s} finite value(s) of {names}; got {schedule!r}")
        return values

    def to_statespace(self, *, schedule: Any = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """Linearise the model about ``x = 0``, ``u = 0`` at a schedule value (module notes).

        Parameters
        ----------
        schedule : float or array_like, shape (n_s,), optional
            The scheduling signals' values; required where the model has any.

        Returns
        -------
        tuple
            ``(A, B, C, D, None)``: continuous time.
        """
        point = self._schedule_point(schedule)
        function = _linearisation(self.model.cache_key(), self.model)
        return (*(np.asarray(m, dtype=float).reshape(function.size_out(i))
                  for i, m in enumerate(function(self.parameters, point))), None)

    def is_stable(self, *, schedule: Any = None) -> bool:
        """Say whether every eigenvalue of the linearisation lies in the left half-plane, within rounding.

        Parameters
        ----------
        schedule : float or array_like, optional
            The operating point; a scheduled model without one is checked at
            :data:`STABILITY_POINTS` values across :attr:`schedule_range`.

        Returns
        -------
        bool
            True when stable.
        """
        if schedule is None and self.is_scheduled:
            if self.schedule_range is None:
                raise InputError("give schedule= a value: this model has no schedule_range to check across")
            return stable_over(self, self.schedule_range[:, 0], self.schedule_range[:, 1])
        return super().is_stable(schedule=schedule)

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None, schedule: Any = None,
                         return_states: bool = False) -> Any:
        """Simulate the outputs driven by ``u``, compiled (the estimator's recursion).

        Parameters
        ----------
        u : array_like (N, n_u), or (N, n_u + n_s) with the scheduling signals last
            Inputs, time-major.
        dt : float
            Sample interval (s); required (optional only in the protocol's signature).
        x0 : array_like (n_states,), optional
            Initial state; rest by default.
        schedule : array_like (N,) or (N, n_s), optional
            The scheduling signals; without them, ``u``'s last columns.
        return_states : bool
            Also return the states (N, n_states).

        Returns
        -------
        ndarray, shape (N, n_y), or tuple of ndarray
            The outputs; with ``return_states``, ``(y, x)``.
        """
        if dt is None or not (np.isfinite(dt) and dt > 0):
            raise InputError(f"a continuous-time model needs the sample interval dt (> 0) of its input; got {dt}")
        if self.model.n_s:
            names = ", ".join(self.model.schedule_names)
            driving = schedule_columns(u, schedule, self.model.n_u, self.model.n_s, names)
        else:
            driving = self.checked_input(u)
            unscheduled(schedule, driving.shape[0])
        y, x = greybox_outputs(self.model, self.parameters, driving, float(dt), x0=x0,
                               discretization=self.discretization, substeps=self.substeps)
        return (y, x) if return_states else y

    def simulate(self, record: IOData, *, x0: Any = None) -> Any:
        """The model's response to ``record`` (its inputs, then the scheduling signals) from ``x0`` (default rest).

        Parameters
        ----------
        record : IOData
            Inputs, then the scheduling signals, in ``u``.
        x0 : array_like (n_states,), optional
            Initial state; rest by default.

        Returns
        -------
        TimeResponse
            With the states and, where the record has ``n_y`` outputs, them as ``measured``.
        """
        from ..models.responses import simulated_response

        y, x = self.simulate_outputs(record.u, record.dt, x0=x0, return_states=True)
        return simulated_response(record, y, x=x, output_names=self.output_names, state_names=self.model.state_names)

    def to_casadi(self) -> ca.Function:
        """Return the continuous-time model with its parameters in it as a CasADi Function.

        Returns
        -------
        casadi.Function
            ``(x, u[, s]) -> (xdot, y)``, ``s`` where the model is scheduled.
        """
        model = self.model
        x, u, s = ca.SX.sym("x", model.n_states), ca.SX.sym("u", model.n_u), ca.SX.sym("s", model.n_s)
        theta = ca.DM(self.parameters)
        values = [model.dynamics(x, u, theta, s), model.output(x, u, theta, s)]
        inputs, names = ([x, u, s], ["x", "u", "s"]) if model.n_s else ([x, u], ["x", "u"])
        return ca.Function("vehid_greybox_model", inputs, values, names, ["xdot", "y"])

    def mat_fields(self) -> dict[str, Any]:
        """Return the fields of the model's MATLAB file.

        Returns
        -------
        dict
            The parameters (and covariance) and the linearisation's ``A``, ``B``, ``C``, ``D``: unscheduled,
            as they are; scheduled on one signal with a :attr:`schedule_range`, at ``grid``, its ends and
            middle (grid value first).
        """
        fields: dict[str, Any] = {"parameters": self.parameters, "parameter_names": list(self.model.parameter_names)}
        if self.parameter_covariance is not None:
            fields["parameter_covariance"] = self.parameter_covariance
        if not self.is_scheduled:
            return {**super().mat_fields(), **fields}
        if self.model.n_s == 1 and self.schedule_range is not None:
            grid = np.linspace(*self.schedule_range[0], 3)
            forms = [self.to_statespace(schedule=float(value)) for value in grid]
            fields.update(grid=grid, **{name: np.array([form[i] for form in forms]) for i, name in enumerate("ABCD")})
        return fields

    def to_dict(self) -> dict[str, Any]:
        """Describe the model for JSON.

        Returns
        -------
        dict
            ``kind: grey-box``, the structure (functions as tables), the numbers and settings.
        """
        return {
            "kind": "grey-box", "time_domain": "continuous", "dt": None, "model": _model_dict(self.model),
            "parameters": self.parameters.tolist(),
            "parameter_covariance": None if self.parameter_covariance is None else self.parameter_covariance.tolist(),
            "discretization": self.discretization, "substeps": self.substeps,
            "schedule_range": None if self.schedule_range is None else self.schedule_range.tolist(), "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> "IdentifiedGreyBox":
        """Read a model that :meth:`to_dict` described.

        Parameters
        ----------
        values : mapping
            The description.

        Returns
        -------
        IdentifiedGreyBox
            The model.
        """
        if values.get("kind") != "grey-box":
            raise InputError("not a grey-box model (kind grey-box)")
        covariance, bounds = values.get("parameter_covariance"), values.get("schedule_range")
        return cls(_model_from(values["model"]), np.asarray(values["parameters"], dtype=float),
                   None if covariance is None else np.asarray(covariance, dtype=float),
                   str(values.get("discretization", "rk4")), int(values.get("substeps", 1)),
                   None if bounds is None else np.asarray(bounds, dtype=float), dict(values.get("meta") or {}))

    def save_json(self, path: str | Path) -> Path:
        """Write :meth:`to_dict` as JSON.

        Parameters
        ----------
        path : str or pathlib.Path
            The file written.

        Returns
        -------
        pathlib.Path
            The path.
        """
        from ..jsonable import to_jsonable

        path = Path(path)
        path.write_text(json.dumps(to_jsonable(self.to_dict()), indent=2) + "\n")
        return path
