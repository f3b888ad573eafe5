"""Discrete-time state-space models, for what has no continuous-time equivalent.

A discrete pole on the closed negative real axis (an output that alternates
sign from sample to sample, common in ARX and subspace fits of real records)
has no real continuous-time model with the same samples. The comparators
then return a :class:`DiscreteModel`, labelled ``time_domain = "discrete"``,
instead of failing: ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)``
with the record's sample interval.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import InputError
from .protocol import StateSpaceModel

__all__ = ["DiscreteModel", "has_no_continuous_equivalent"]


def has_no_continuous_equivalent(Ad: np.ndarray) -> bool:
    """True when ``Ad`` has an eigenvalue on the closed negative real axis (or zero)."""
    values = np.linalg.eigvals(np.asarray(Ad, dtype=float))
    return bool(np.any((np.abs(values.imag) <= 1e-9 * np.abs(values)) & (values.real <= 0)))


@dataclass(frozen=True, eq=False)
class DiscreteModel(StateSpaceModel):
    """A discrete-time state-space model with its sample interval: a frozen value."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    dt: float
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in "ABCD":
            array = np.array(getattr(self, name), dtype=float)
            if array.ndim != 2 or not np.all(np.isfinite(array)):
                raise InputError(f"{name} must be a finite 2-D array")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        n = self.A.shape[0]
        if self.A.shape != (n, n) or self.B.shape[0] != n or self.C.shape[1] != n or \
                self.D.shape != (self.C.shape[0], self.B.shape[1]):
            raise InputError("A, B, C, D of a discrete model have inconsistent shapes")
        object.__setattr__(self, "meta", {**dict(self.meta), "time_domain": "discrete"})

    @property
    def n_states(self) -> int:
        return int(self.A.shape[0])

    @property
    def n_u(self) -> int:
        return int(self.B.shape[1])

    @property
    def n_y(self) -> int:
        return int(self.C.shape[0])

    def to_statespace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
        """``(A, B, C, D, dt)``."""
        return self.A, self.B, self.C, self.D, self.dt

    def is_stable(self) -> bool:
        """Every eigenvalue strictly inside the unit circle."""
        return bool(np.all(np.abs(self.eigenvalues()) < 1))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: the state-space form with names and meta."""
        return {**super().to_dict(), "input_names": list(self.input_names or ()),
                "output_names": list(self.output_names or ()), "meta": self.meta}
