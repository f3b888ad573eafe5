"""Discrete-time state-space models, for what has no continuous-time equivalent.

A discrete pole on the closed negative real axis (an output that alternates
sign from sample to sample, common in ARX and subspace fits of real records)
has no real continuous-time model with the same samples. The comparators
then return a :class:`DiscreteModel`, labelled ``time_domain = "discrete"``,
instead of failing: ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)``
with the record's sample interval.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.signal import dlsim

from .errors import InputError

__all__ = ["DiscreteModel", "has_no_continuous_equivalent"]


def has_no_continuous_equivalent(Ad: np.ndarray) -> bool:
    """True when ``Ad`` has an eigenvalue on the closed negative real axis (or zero)."""
    values = np.linalg.eigvals(np.asarray(Ad, dtype=float))
    return bool(np.any((np.abs(values.imag) <= 1e-9 * np.abs(values)) & (values.real <= 0)))


@dataclass(frozen=True, eq=False)
class DiscreteModel:
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

    def eigenvalues(self) -> np.ndarray:
        """The discrete eigenvalues (z-plane)."""
        return np.linalg.eigvals(self.A)

    def is_stable(self) -> bool:
        """Every eigenvalue strictly inside the unit circle."""
        return bool(np.all(np.abs(self.eigenvalues()) < 1))

    def simulate(self, u: Any, dt: float | None = None, *, method: str | None = None, x0: Any = None) -> np.ndarray:
        """Outputs (N, n_y) driven by ``u`` (N, n_u) from ``x0`` (default zero); ``dt`` must be the model's."""
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != self.n_u:
            raise InputError(f"u must have shape (N, {self.n_u}); got {u.shape}")
        if dt is not None and not np.isclose(dt, self.dt, rtol=1e-6):
            raise InputError(f"this discrete model has dt = {self.dt} s; the record has {dt} s")
        x0 = np.zeros(self.n_states) if x0 is None else np.asarray(x0, dtype=float).ravel()
        if u.shape[0] == 1:
            return (self.C @ x0 + self.D @ u[0])[None, :]
        _, y, _ = dlsim((self.A, self.B, self.C, self.D, self.dt), u, x0=x0)
        return np.asarray(y).reshape(u.shape[0], self.n_y)

    def to_dict(self) -> dict[str, Any]:
        return {"time_domain": "discrete", "dt": self.dt, "A": self.A.tolist(), "B": self.B.tolist(),
                "C": self.C.tolist(), "D": self.D.tolist(),
                "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues()],
                "input_names": list(self.input_names or ()), "output_names": list(self.output_names or ()),
                "meta": self.meta}

    def save_json(self, path: str | Path) -> Path:
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2, default=str) + "\n")
        return path

    def save_mat(self, path: str | Path) -> Path:
        from scipy.io import savemat

        path = Path(path)
        savemat(path, {"A": self.A, "B": self.B, "C": self.C, "D": self.D, "Ts": self.dt})
        return path
