"""Plain state-space models: discrete-time ones, for what has no continuous-time equivalent, and continuous ones.

A discrete pole on the closed negative real axis (an output that alternates
sign from sample to sample, common in ARX and subspace fits of real records)
has no real continuous-time model with the same samples. The comparators
then return a :class:`DiscreteModel`, labelled ``time_domain = "discrete"``,
instead of failing: ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)``
with the record's sample interval. :class:`ContinuousModel` is the
continuous-time counterpart without the modal form's structure, e.g. a
linearisation given as matrices.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .protocol import StateSpaceModel, unscheduled
from .statespace import continuous_to_discrete, hold_state_shift

__all__ = ["ContinuousModel", "DiscreteModel", "has_no_continuous_equivalent"]


def has_no_continuous_equivalent(Ad: np.ndarray) -> bool:
    """True when ``Ad`` has an eigenvalue on the closed negative real axis (or zero)."""
    values = np.linalg.eigvals(np.asarray(Ad, dtype=float))
    return bool(np.any((np.abs(values.imag) <= 1e-9 * np.abs(values)) & (values.real <= 0)))


def _freeze_matrices(model: Any, what: str) -> None:
    """A, B, C, D of ``model`` as read-only float arrays of consistent shapes, names as tuples; else InputError."""
    for name in "ABCD":
        array = np.array(getattr(model, name), dtype=float)
        if array.ndim != 2 or not np.all(np.isfinite(array)):
            raise InputError(f"{name} must be a finite 2-D array")
        array.setflags(write=False)
        object.__setattr__(model, name, array)
    n = model.A.shape[0]
    expected = {"A": (n, n), "B": (n, model.B.shape[1]), "C": (model.C.shape[0], n),
                "D": (model.C.shape[0], model.B.shape[1])}
    for name, shape in expected.items():
        if getattr(model, name).shape != shape:
            raise InputError(f"{name} of a {what} model has shape {getattr(model, name).shape}; expected {shape}")
    for name in ("input_names", "output_names"):
        if getattr(model, name) is not None:
            object.__setattr__(model, name, tuple(str(item) for item in getattr(model, name)))


@dataclass(frozen=True, eq=False)
class DiscreteModel(StateSpaceModel):
    """A discrete-time state-space model with its sample interval: a frozen value.

    ``x[k+1] = A x[k] + B u[k]``, ``y[k] = C x[k] + D u[k]``.

    Parameters
    ----------
    A, B, C, D : array_like
        Shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    dt : float
        Sample interval (s), positive.
    input_names, output_names : tuple of str, optional
        Channel names.
    meta : dict, optional
        Provenance; ``time_domain`` is set to ``"discrete"``.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _freeze_matrices(self, "discrete")
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise InputError(f"the sample interval dt must be positive; got {self.dt}")
        object.__setattr__(self, "dt", float(self.dt))
        object.__setattr__(self, "meta", {**dict(self.meta), "time_domain": "discrete"})

    @property
    def n_states(self) -> int:
        """Number of states."""
        return int(self.A.shape[0])

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return int(self.B.shape[1])

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.C.shape[0])

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """Return the state-space form with the sample interval.

        Parameters
        ----------
        schedule : float, optional
            Changes nothing (the model is not scheduled).

        Returns
        -------
        tuple
            ``(A, B, C, D, dt)``.
        """
        unscheduled(schedule)
        return self.A, self.B, self.C, self.D, self.dt

    def to_dict(self) -> dict[str, Any]:
        """Describe the model for JSON.

        Returns
        -------
        dict
            The state-space form (matrices as lists, ``dt``) with names and meta.
        """
        return {**super().to_dict(), "input_names": list(self.input_names or ()),
                "output_names": list(self.output_names or ()), "meta": self.meta}


@dataclass(frozen=True, eq=False)
class ContinuousModel(StateSpaceModel):
    """A continuous-time state-space model ``xdot = A x + B u``, ``y = C x + D u``: a frozen value.

    Parameters
    ----------
    A, B, C, D : array_like
        Shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u); time in seconds.
    input_names, output_names : tuple of str, optional
        Channel names.
    meta : dict, optional
        Provenance.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        _freeze_matrices(self, "continuous")
        object.__setattr__(self, "meta", dict(self.meta))

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return int(self.B.shape[1])

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.C.shape[0])

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """Return the state-space form.

        Parameters
        ----------
        schedule : float, optional
            Changes nothing (the model is not scheduled).

        Returns
        -------
        tuple
            ``(A, B, C, D, None)``: continuous time.
        """
        unscheduled(schedule)
        return self.A, self.B, self.C, self.D, None

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None,
                         schedule: Any = None) -> np.ndarray:
        """Simulate the outputs for inputs linear between samples, exactly.

        The first-order-hold equivalent (:func:`~identification.models.statespace.continuous_to_discrete`),
        whose state is ``x - G2 u``, started from ``x0 - G2 u(0)``.

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Inputs, time-major.
        dt : float
            Sample interval (s); required.
        x0 : array_like, shape (n,), optional
            Initial state; rest by default.
        schedule : array_like, optional
            Changes nothing (the model is not scheduled).

        Returns
        -------
        ndarray, shape (N, n_y)
            The outputs.
        """
        if dt is None:
            raise InputError("a continuous-time model needs the sample interval dt of its input")
        u = self.checked_input(u)
        unscheduled(schedule, u.shape[0])
        x = self.checked_state(x0)
        Ad, Bd, Cd, Dd = continuous_to_discrete(self.A, self.B, self.C, self.D, dt, hold="foh")
        equivalent = DiscreteModel(Ad, Bd, Cd, Dd, dt)
        return equivalent.simulate_outputs(u, x0=x - hold_state_shift(self.A, self.B, dt) @ u[0])

    def to_dict(self) -> dict[str, Any]:
        """Describe the model for JSON.

        Returns
        -------
        dict
            The state-space form (matrices as lists) with names and meta.
        """
        return {**super().to_dict(), "input_names": list(self.input_names or ()),
                "output_names": list(self.output_names or ()), "meta": self.meta}
