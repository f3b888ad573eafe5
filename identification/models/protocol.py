"""What every identified model offers, whatever estimated it.

:class:`IdentifiedModel` is the one surface that reports, metrics, scores,
archives and exports rely on, and the only one callers that take any model use:

* ``n_states``, ``n_u``, ``n_y``; ``is_linear`` (False where the model is
  not linear time-invariant: scores then simulate it whatever the horizon,
  its initial state fitted by Gauss-Newton, and its state-space form is a
  linearisation);
* ``simulate_outputs(u, dt=None, *, x0=None)``: outputs (N, n_y) driven by
  ``u`` (N, n_u) from the state ``x0`` (default rest); ``simulate(record)``
  does the same for an :class:`~identification.data.IOData` record. A class
  may add keyword-only options of its own, which such callers never pass;
* ``eigenvalues()`` (s-plane if continuous, z-plane if discrete),
  ``modes()`` (frequency in Hz, damping ratio) and ``is_stable()``;
* ``frequency_response(f_hz)``: ``C (p I - A)^-1 B + D`` at ``p = j 2 pi f``
  in continuous time and ``p = exp(j 2 pi f dt)`` in discrete time;
* ``to_statespace()`` giving ``(A, B, C, D, dt)`` (``dt`` None if
  continuous), ``to_control()``, ``to_casadi()``, ``save_mat(path)``,
  ``save_json(path)``;
* a codec registered in :mod:`vehid.identification.dataio.storage`, so that an
  archive holds the model and gives it back.

:class:`StateSpaceModel` implements all of it from ``to_statespace()`` and
the class's ``n_u`` and ``n_y``, discrete-time simulation included, so a
model class supplies only what is its own (a continuous-time class its
``simulate_outputs``).

Modes are stated in continuous time: a discrete eigenvalue ``z`` at sample
interval ``dt`` is the continuous ``lambda = log(z) / dt`` (principal branch).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..data import IOData
from ..errors import InputError

__all__ = ["Mode", "IdentifiedModel", "StateSpaceModel", "sample_interval", "MARGINAL_TOLERANCE", "eigenvalues_stable"]

#: An eigenvalue whose growth rate lies within this fraction of the fastest eigenvalue's magnitude is on the
#: stability boundary to rounding, not beyond it: an integrator identified at z = 1 (ARX of too high an order
#: on a lag) lands 1e-12 1/s either side of the imaginary axis as the BLAS kernel rounds, and calling one side
#: unstable would flip the model's treatment (warning, scoring by prediction) with the machine. A mode growing
#: at 1e-9 of the fastest rate grows by less than e over a billion of that mode's time constants.
MARGINAL_TOLERANCE = 1e-9


def eigenvalues_stable(eigenvalues: Any, dt: float | None = None) -> bool:
    """Every eigenvalue in the left half-plane (``dt`` None) or inside the unit circle, within rounding.

    A continuous eigenvalue counts as stable where its real part is below
    :data:`MARGINAL_TOLERANCE` times the largest eigenvalue magnitude; a
    discrete one where its magnitude is below ``1 + MARGINAL_TOLERANCE``.
    """
    values = np.asarray(eigenvalues, dtype=complex).ravel()
    if values.size == 0:
        return True
    if dt is None:
        return bool(np.all(values.real < MARGINAL_TOLERANCE * np.max(np.abs(values))))
    return bool(np.all(np.abs(values) < 1.0 + MARGINAL_TOLERANCE))


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

    is_linear: bool

    @property
    def n_states(self) -> int: ...

    @property
    def n_u(self) -> int: ...

    @property
    def n_y(self) -> int: ...

    def simulate(self, record: IOData) -> IOData: ...

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None) -> np.ndarray: ...

    def is_stable(self) -> bool: ...

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
    #: False for a model whose state-space form is only a linearisation (scores simulate it, never predict k steps).
    is_linear = True

    def to_statespace(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
        """``(A, B, C, D, dt)``; ``dt`` is None for a continuous-time model."""
        raise NotImplementedError

    @property
    def n_states(self) -> int:
        """Number of states (the order n)."""
        return int(self.to_statespace()[0].shape[0])

    def checked_input(self, u: Any) -> np.ndarray:
        """``u`` as a finite float (N, n_u) array (1-D: one input); InputError naming what is wrong."""
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != self.n_u:
            raise InputError(f"u must have shape (N, {self.n_u}); got {u.shape}")
        if not np.all(np.isfinite(u)):
            raise InputError("u contains a non-finite value (NaN or inf)")
        return u

    def checked_state(self, x0: Any) -> np.ndarray:
        """``x0`` as an (n,) array, zero where None; InputError for another length or a non-finite entry."""
        n = self.n_states
        if x0 is None:
            return np.zeros(n)
        x0 = np.asarray(x0, dtype=float).ravel()
        if x0.shape != (n,) or not np.all(np.isfinite(x0)):
            raise InputError(f"x0 must hold {n} finite entries; got shape {x0.shape}")
        return x0

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None) -> np.ndarray:
        """Outputs (N, n_y) driven by ``u`` (N, n_u) from ``x0`` (default zero).

        This form serves discrete-time models, ``x(k+1) = A x(k) + B u(k)``,
        ``y(k) = C x(k) + D u(k)``: ``dt``, if given, must be the model's.
        """
        A, B, C, D, model_dt = self.to_statespace()
        if model_dt is None:
            raise NotImplementedError("a continuous-time model simulates itself")
        if dt is not None and not np.isclose(dt, model_dt, rtol=1e-6):
            raise InputError(f"this discrete model has dt = {model_dt} s; the record has {dt} s")
        u = self.checked_input(u)
        x = self.checked_state(x0)
        states = np.empty((u.shape[0], A.shape[0]))
        drive = u @ B.T
        for k in range(u.shape[0]):
            states[k] = x
            x = A @ x + drive[k]
        return states @ C.T + u @ D.T

    def simulate(self, record: IOData, *, x0: Any = None) -> IOData:
        """``record`` with its outputs replaced by the model's, driven by its inputs from ``x0`` (default rest)."""
        y = self.simulate_outputs(record.u, record.dt, x0=x0)
        names = self.output_names if self.output_names and len(self.output_names) == y.shape[1] else None
        return IOData(t=record.t, u=record.u, y=y, input_names=record.input_names, output_names=names,
                      input_units=record.input_units, meta=dict(record.meta))

    def is_stable(self) -> bool:
        """Every eigenvalue in the left half-plane (continuous) or inside the unit circle (discrete), within rounding
        (:func:`eigenvalues_stable`)."""
        return eigenvalues_stable(self.eigenvalues(), self.to_statespace()[4])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state-space form: time domain, dt, matrices, eigenvalues as [re, im]."""
        A, B, C, D, dt = self.to_statespace()
        return {"time_domain": "continuous" if dt is None else "discrete", "dt": dt, "A": A.tolist(),
                "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
                "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues()]}

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
        resolvent = points[:, None, None] * np.eye(A.shape[0]) - A
        states = np.linalg.solve(resolvent, np.broadcast_to(B.astype(complex), (f_hz.size, *B.shape)))
        return C @ states + D

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
        """Write ``to_dict()`` as JSON, with the time domain and ``dt`` of :meth:`to_statespace` first."""
        path = Path(path)
        dt = self.to_statespace()[4]
        values = {"time_domain": "continuous" if dt is None else "discrete", "dt": dt, **self.to_dict()}
        path.write_text(json.dumps(values, indent=2, default=str) + "\n")
        return path


def sample_interval(dt: float | None, what: str) -> float:
    """``dt`` of a discrete-time model, or a clear error where it was never given."""
    if dt is None:
        raise InputError(f"this {what} has no sample interval: give dt when building it")
    return float(dt)
