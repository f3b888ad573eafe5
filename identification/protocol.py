"""What every identified model offers, whatever estimated it.

:class:`IdentifiedModel` is the one surface that reports, metrics and
exports rely on: simulate a record, eigenvalues and modes (frequency in Hz,
damping ratio), frequency response, the state-space matrices and exports to
python-control, CasADi, MATLAB and JSON. :class:`StateSpaceModel` implements
it from ``to_statespace()`` (and, in continuous time, ``simulate_outputs``),
so a model class supplies only what is its own.

Modes are stated in continuous time: a discrete eigenvalue ``z`` at sample
interval ``dt`` is the continuous ``lambda = log(z) / dt`` (principal branch).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from .data import IOData
from .errors import InputError

__all__ = ["Mode", "IdentifiedModel", "StateSpaceModel", "sample_interval"]


@dataclass(frozen=True)
class Mode:
    """One mode of a model, from its continuous-time eigenvalue.

    Attributes
    ----------
    eigenvalue : complex
        ``sigma + j omega`` (1/s), ``omega >= 0``: one per complex pair.
    frequency_hz : float
        Natural frequency ``|lambda| / 2 pi``.
    damping : float
        Damping ratio ``-sigma / |lambda|``: 1 for a stable real pole, -1 for an unstable one.
    """

    eigenvalue: complex
    frequency_hz: float
    damping: float

    @classmethod
    def of(cls, eigenvalue: complex) -> "Mode":
        """The mode of one continuous-time eigenvalue (its conjugate gives the same mode)."""
        value = complex(eigenvalue.real, abs(eigenvalue.imag))
        natural = abs(value)
        damping = -value.real / natural if natural > 0 else 1.0
        return cls(value, natural / (2 * np.pi), float(damping))


@runtime_checkable
class IdentifiedModel(Protocol):
    """The protocol every identified model meets (see the module docstring)."""

    def simulate(self, record: IOData, **options: Any) -> IOData: ...

    def simulate_outputs(self, u: Any, dt: float | None = None, **options: Any) -> np.ndarray: ...

    def eigenvalues(self) -> np.ndarray: ...

    def modes(self) -> tuple[Mode, ...]: ...

    def frequency_response(self, f_hz: Any) -> np.ndarray: ...

    def to_statespace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]: ...

    def to_control(self) -> Any: ...

    def to_casadi(self) -> Any: ...

    def save_mat(self, path: str | Path) -> Path: ...

    def save_json(self, path: str | Path) -> Path: ...


class StateSpaceModel:
    """The protocol's methods from ``to_statespace`` (continuous models add ``simulate_outputs``)."""

    output_names: tuple[str, ...] | None = None

    def to_statespace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
        """``(A, B, C, D, dt)``; ``dt`` is None for a continuous-time model."""
        raise NotImplementedError

    def simulate_outputs(self, u: Any, dt: float | None = None, *, method: str | None = None,
                         x0: Any = None) -> np.ndarray:
        """Outputs (N, n_y) driven by ``u`` (N, n_u) from ``x0`` (default zero).

        This form serves discrete-time models: ``dt``, if given, must be the
        model's, and ``method`` (a hold for continuous models) is ignored.
        """
        from scipy.signal import dlsim

        A, B, C, D, model_dt = self.to_statespace()
        if model_dt is None:
            raise NotImplementedError("a continuous-time model simulates itself")
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != B.shape[1]:
            raise InputError(f"u must have shape (N, {B.shape[1]}); got {u.shape}")
        if dt is not None and not np.isclose(dt, model_dt, rtol=1e-6):
            raise InputError(f"this discrete model has dt = {model_dt} s; the record has {dt} s")
        x0 = np.zeros(A.shape[0]) if x0 is None else np.asarray(x0, dtype=float).ravel()
        if u.shape[0] == 1:
            return (C @ x0 + D @ u[0])[None, :]
        _, y, _ = dlsim((A, B, C, D, model_dt), u, x0=x0)
        return np.asarray(y).reshape(u.shape[0], C.shape[0])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state-space form: time domain, dt, matrices, eigenvalues as [re, im]."""
        A, B, C, D, dt = self.to_statespace()
        return {"time_domain": "continuous" if dt is None else "discrete", "dt": dt, "A": A.tolist(),
                "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
                "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues()]}

    def simulate(self, record: IOData, **options: Any) -> IOData:
        """``record`` with its outputs replaced by the model's, driven by its inputs from rest.

        Options go to :meth:`simulate_outputs`.
        """
        y = self.simulate_outputs(record.u, record.dt, **options)
        names = self.output_names if self.output_names and len(self.output_names) == y.shape[1] else None
        return IOData(t=record.t, u=record.u, y=y, input_names=record.input_names, output_names=names,
                      input_units=record.input_units, meta=dict(record.meta))

    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of A (s-plane for continuous models, z-plane for discrete ones)."""
        return np.linalg.eigvals(self.to_statespace()[0])

    def modes(self) -> tuple[Mode, ...]:
        """One :class:`Mode` per complex pair (positive imaginary part) and per real pole, pairs first."""
        values, dt = np.asarray(self.eigenvalues(), dtype=complex), self.to_statespace()[4]
        if dt is not None:
            with np.errstate(divide="ignore"):
                values = np.log(values) / dt
        scale = max(1.0, float(np.max(np.abs(values), initial=0.0)))
        pairs = sorted((v for v in values if v.imag > 1e-9 * scale), key=lambda v: (abs(v), v.real))
        real = sorted((v for v in values if abs(v.imag) <= 1e-9 * scale), key=lambda v: v.real)
        return tuple(Mode.of(v) for v in (*pairs, *real))

    def frequency_response(self, f_hz: Any) -> np.ndarray:
        """``C (s I - A)^-1 B + D`` at ``s = j 2 pi f`` (``z = exp(s dt)`` if discrete): (n_f, n_y, n_u) complex."""
        A, B, C, D, dt = self.to_statespace()
        f_hz = np.atleast_1d(np.asarray(f_hz, dtype=float))
        if f_hz.ndim != 1 or not np.all(np.isfinite(f_hz)):
            raise InputError("f_hz must be a finite 1-D array of frequencies (Hz)")
        s = 2j * np.pi * f_hz
        points = s if dt is None else np.exp(s * dt)
        eye = np.eye(A.shape[0])
        return np.array([C @ np.linalg.solve(p * eye - A, B) + D for p in points]).reshape(f_hz.size, *D.shape)

    def to_control(self) -> Any:
        """A ``control.StateSpace`` (python-control, imported only here)."""
        try:
            import control
        except ImportError:  # pragma: no cover - optional dependency
            raise ImportError("python-control is not installed: pip install control") from None
        A, B, C, D, dt = self.to_statespace()
        return control.ss(A, B, C, D) if dt is None else control.ss(A, B, C, D, dt)

    def to_casadi(self) -> Any:
        """A CasADi Function ``(x, u) -> (dx, y)``: ``dx`` is dx/dt if continuous, x(k+1) if discrete."""
        import casadi as ca

        A, B, C, D, dt = self.to_statespace()
        x = ca.SX.sym("x", A.shape[0])
        u = ca.SX.sym("u", B.shape[1])
        return ca.Function("vehid_model", [x, u], [ca.DM(A) @ x + ca.DM(B) @ u, ca.DM(C) @ x + ca.DM(D) @ u],
                           ["x", "u"], ["x_next" if dt is not None else "x_dot", "y"])

    def mat_fields(self) -> dict[str, Any]:
        """What :meth:`save_mat` writes: A, B, C, D and, for a discrete model, its sample interval Ts."""
        A, B, C, D, dt = self.to_statespace()
        return {"A": A, "B": B, "C": C, "D": D, **({} if dt is None else {"Ts": dt})}

    def save_mat(self, path: str | Path) -> Path:
        """Write :meth:`mat_fields` to a MATLAB ``.mat`` file."""
        from scipy.io import savemat

        path = Path(path)
        savemat(path, self.mat_fields())
        return path

    def save_json(self, path: str | Path) -> Path:
        """Write ``to_dict()`` as JSON."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2, default=str) + "\n")
        return path


def sample_interval(dt: float | None, what: str) -> float:
    """``dt`` of a discrete-time model, or a clear error where it was never given."""
    if dt is None:
        raise InputError(f"this {what} has no sample interval: give dt when building it")
    return float(dt)
