"""What every identified model offers, whatever estimated it.

:class:`IdentifiedModel` is the one surface that reports, metrics, scores,
archives and exports rely on, and the only one callers that take any model use:

* ``n_states``, ``n_u``, ``n_y``; ``is_linear`` (False where the model is
  not linear time-invariant: scores then simulate it whatever the horizon,
  its initial state fitted by Gauss-Newton, and its state-space form is a
  linearisation); ``is_scheduled`` (True where the model varies with a
  measured scheduling variable, e.g. a car's speed);
* ``simulate_outputs(u, dt=None, *, x0=None, schedule=None)``: outputs
  (N, n_y) driven by ``u`` (N, n_u) from the state ``x0`` (default rest) along
  the scheduling variable ``schedule`` (N,); ``simulate(record, *, x0=None)``
  does the same for an :class:`~identification.data.IOData` record (a
  scheduled model's record holds the schedule as its last input column) and
  returns a :class:`~identification.models.responses.TimeResponse`. A class may
  add keyword-only options of its own, which such callers never pass;
* ``eigenvalues()`` (s-plane if continuous, z-plane if discrete),
  ``modes()`` (frequency in Hz, damping ratio) and ``is_stable()``;
* ``frequency_response(f_hz)``: ``C (p I - A)^-1 B + D`` at ``p = j 2 pi f``
  in continuous time and ``p = exp(j 2 pi f dt)`` in discrete time, as a
  :class:`~identification.models.responses.FrequencyResponse`;
* ``to_statespace()`` giving ``(A, B, C, D, dt)`` (``dt`` None if
  continuous; the state basis that ``simulate_outputs``' ``x0`` is in),
  ``to_control()``, ``to_casadi()``, ``save_mat(path)``, ``save_json(path)``;
* a codec registered in :mod:`vehid.identification.dataio.storage`, so that an
  archive holds the model and gives it back.

Schedules. Every method that describes the model at one operating point
(``eigenvalues``, ``modes``, ``is_stable``, ``frequency_response``,
``to_statespace``, ``to_control``) takes the keyword ``schedule``: a scheduled
model is the linear model it is at that value of its scheduling variable
(which it needs: InputError without one, except ``is_stable``, which then
holds at every value), and a model without a schedule is the same at every
value, so it accepts a finite value and is unchanged by it. One call serves
both, ``model.eigenvalues(schedule=20.0)``. :func:`signature_mismatches`
checks a class's methods against these signatures.

:class:`StateSpaceModel` implements all of it from ``to_statespace()`` and
the class's ``n_u`` and ``n_y``, discrete-time simulation included, so a
model class supplies only what is its own (a continuous-time class its
``simulate_outputs``).

Modes are stated in continuous time: a discrete eigenvalue ``z`` at sample
interval ``dt`` is the continuous ``lambda = log(z) / dt`` (principal branch).
"""

from __future__ import annotations

import inspect
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..data import IOData
from ..errors import InputError
from ..jsonable import json_default
from .responses import FrequencyResponse, TimeResponse, simulated_response

__all__ = ["Mode", "IdentifiedModel", "StateSpaceModel", "sample_interval", "MARGINAL_TOLERANCE", "eigenvalues_stable",
           "PROTOCOL_METHODS", "signature_mismatches", "unscheduled", "schedule_value", "statespace_response"]

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
        """Make the mode of one continuous-time eigenvalue.

        Parameters
        ----------
        eigenvalue : complex
            The eigenvalue (1/s); its conjugate gives the same mode.

        Returns
        -------
        Mode
            Its frequency and damping.
        """
        value = complex(eigenvalue.real, abs(eigenvalue.imag))
        natural = abs(value)
        damping = -value.real / natural if natural > 0 else 1.0
        return cls(value, natural / (2 * np.pi), float(damping))


@runtime_checkable
class IdentifiedModel(Protocol):
    """The protocol every identified model meets (see the module docstring).

    A protocol is not constructed: a model class meets it by having its
    attributes and methods, which :func:`signature_mismatches` checks.

    Attributes
    ----------
    is_linear : bool
        False where the model is not linear time-invariant.
    is_scheduled : bool
        True where the model varies with a measured scheduling variable.
    """

    is_linear: bool
    is_scheduled: bool

    @property
    def n_states(self) -> int:
        """Number of states."""

    @property
    def n_u(self) -> int:
        """Number of inputs (a scheduled model's schedule not among them)."""

    @property
    def n_y(self) -> int:
        """Number of outputs."""

    def simulate(self, record: IOData, *, x0: Any = None) -> TimeResponse:
        """Simulate the model driven by a record's inputs.

        Parameters
        ----------
        record : IOData
            The inputs (a scheduled model's schedule last) and their time.
        x0 : array_like, shape (n_states,), optional
            Initial state in :meth:`to_statespace`'s basis; rest by default.

        Returns
        -------
        TimeResponse
            The outputs, with the record's own as ``measured``.
        """

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None,
                         schedule: Any = None) -> np.ndarray:
        """Simulate the outputs for bare input samples.

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Inputs, time-major.
        dt : float, optional
            Sample interval (s); a continuous-time model needs it.
        x0 : array_like, shape (n_states,), optional
            Initial state; rest by default.
        schedule : array_like, shape (N,), optional
            The scheduling variable at each sample (a scheduled model needs it).

        Returns
        -------
        ndarray, shape (N, n_y)
            The outputs.
        """

    def is_stable(self, *, schedule: float | None = None) -> bool:
        """Say whether the model is stable.

        Parameters
        ----------
        schedule : float, optional
            The operating point; a scheduled model without one is checked at every value.

        Returns
        -------
        bool
            True when every eigenvalue is in the stable region.
        """

    def eigenvalues(self, *, schedule: float | None = None) -> np.ndarray:
        """Return the eigenvalues.

        Parameters
        ----------
        schedule : float, optional
            The operating point (required of a scheduled model).

        Returns
        -------
        ndarray of complex, shape (n_states,)
            In the s-plane (1/s) if continuous, the z-plane if discrete.
        """

    def modes(self, *, schedule: float | None = None) -> tuple[Mode, ...]:
        """Return the modes in continuous time.

        Parameters
        ----------
        schedule : float, optional
            The operating point (required of a scheduled model).

        Returns
        -------
        tuple of Mode
            Frequency (Hz) and damping ratio of each pair and real pole.
        """

    def frequency_response(self, f_hz: Any, *, schedule: float | None = None) -> FrequencyResponse:
        """Compute ``C (p I - A)^-1 B + D`` on the imaginary axis (or the unit circle).

        Parameters
        ----------
        f_hz : array_like, shape (F,)
            Frequencies (Hz).
        schedule : float, optional
            The operating point (required of a scheduled model).

        Returns
        -------
        FrequencyResponse
            Complex response, shape (F, n_y, n_u).
        """

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
        """Return the state-space form.

        Parameters
        ----------
        schedule : float, optional
            The operating point (required of a scheduled model).

        Returns
        -------
        tuple
            ``(A, B, C, D, dt)``, ``dt`` None if continuous.
        """

    def to_control(self, *, schedule: float | None = None) -> Any:
        """Return the model as python-control's system.

        Parameters
        ----------
        schedule : float, optional
            The operating point (required of a scheduled model).

        Returns
        -------
        control.StateSpace
            The system (python-control must be installed).
        """

    def to_casadi(self) -> Any:
        """Return the model as a CasADi Function.

        Returns
        -------
        casadi.Function
            The model's dynamics and outputs.
        """

    def save_mat(self, path: str | Path) -> Path:
        """Write the model to a MATLAB file.

        Parameters
        ----------
        path : str or pathlib.Path
            The ``.mat`` file.

        Returns
        -------
        pathlib.Path
            The path written.
        """

    def save_json(self, path: str | Path) -> Path:
        """Write the model as JSON.

        Parameters
        ----------
        path : str or pathlib.Path
            The ``.json`` file.

        Returns
        -------
        pathlib.Path
            The path written.
        """


#: The protocol's methods, whose signatures :func:`signature_mismatches` compares.
PROTOCOL_METHODS = ("simulate", "simulate_outputs", "is_stable", "eigenvalues", "modes", "frequency_response",
                    "to_statespace", "to_control", "to_casadi", "save_mat", "save_json")
_PROTOCOL_ATTRIBUTES = ("is_linear", "is_scheduled", "n_states", "n_u", "n_y")
_POSITIONAL = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)


def _plain(signature: inspect.Signature) -> str:
    """A signature as it reads without annotations: ``(self, u, dt=None, *, x0=None)``."""
    return str(signature.replace(parameters=[p.replace(annotation=p.empty) for p in signature.parameters.values()],
                                 return_annotation=inspect.Signature.empty))


def _signature_problems(name: str, expected: inspect.Signature, got: inspect.Signature) -> list[str]:
    """How ``got`` departs from ``expected``: its positional parameters must be the same (names, kinds,
    defaults), the keyword-only ones present with the same defaults, and any other keyword-only with a default."""
    wanted, have = list(expected.parameters.values()), list(got.parameters.values())
    got = _plain(got)
    problems = []
    wanted_positional = [p for p in wanted if p.kind in _POSITIONAL]
    have_positional = [p for p in have if p.kind in _POSITIONAL]
    if [(p.name, p.default) for p in have_positional] != [(p.name, p.default) for p in wanted_positional]:
        shown = ", ".join(p.name + ("" if p.default is p.empty else f"={p.default!r}") for p in wanted_positional)
        problems.append(f"{name}{got}: the positional parameters must be ({shown})")
    by_name = {p.name: p for p in have}
    for parameter in (p for p in wanted if p.kind is inspect.Parameter.KEYWORD_ONLY):
        found = by_name.get(parameter.name)
        if found is None or found.kind is not inspect.Parameter.KEYWORD_ONLY or found.default != parameter.default:
            problems.append(f"{name}{got}: needs the keyword-only {parameter.name}={parameter.default!r}")
    expected_names = {p.name for p in wanted}
    for parameter in have:
        if parameter.name in expected_names or parameter.kind in _POSITIONAL:
            continue
        if parameter.kind is not inspect.Parameter.KEYWORD_ONLY or parameter.default is parameter.empty:
            problems.append(f"{name}{got}: its own option {parameter.name} must be keyword-only with a default")
    return problems


def signature_mismatches(model: Any) -> tuple[str, ...]:
    """Where a model (or model class) departs from the protocol's attributes and method signatures.

    A method matches when its positional parameters are the protocol's (names, kinds and defaults), it
    has the protocol's keyword-only parameters with their defaults, and its own options are keyword-only
    with defaults (so that a caller using the protocol never passes them and never misses one).

    Parameters
    ----------
    model : object or type
        An instance, or a class (whose attributes set in ``__init__`` cannot be seen).

    Returns
    -------
    tuple of str
        One line per problem; empty where the model meets the protocol's signatures.

    Examples
    --------
    >>> from vehid.identification import ModalModel
    >>> signature_mismatches(ModalModel)
    ()
    >>> class Old(ModalModel):  # the signature scheduled models had
    ...     def simulate_outputs(self, u, dt, *, x0=None):
    ...         ...
    >>> for line in signature_mismatches(Old):
    ...     print(line)
    simulate_outputs(self, u, dt, *, x0=None): the positional parameters must be (self, u, dt=None)
    simulate_outputs(self, u, dt, *, x0=None): needs the keyword-only schedule=None
    """
    cls = model if isinstance(model, type) else type(model)
    problems = [f"{name} is missing" for name in _PROTOCOL_ATTRIBUTES
                if not hasattr(model, name) and not (isinstance(model, type) and name in _annotated(cls))]
    for name in PROTOCOL_METHODS:
        member = inspect.getattr_static(cls, name, None)
        if member is None or not callable(getattr(cls, name)):
            problems.append(f"{name}() is missing")
            continue
        problems += _signature_problems(name, inspect.signature(getattr(IdentifiedModel, name)),
                                        inspect.signature(getattr(cls, name)))
    return tuple(problems)


def _annotated(cls: type) -> set[str]:
    """Names a class declares as fields or properties (present on instances though not on the class)."""
    names: set[str] = set()
    for base in cls.__mro__:
        names.update(getattr(base, "__annotations__", {}))
    return names


def schedule_value(schedule: Any, low: float, high: float, variable: str) -> float:
    """A scheduled model's one schedule value, within ``low``..``high``; InputError naming what is wrong.

    Parameters
    ----------
    schedule : float or None
        The value asked for.
    low, high : float
        The range over which the model is defined.
    variable : str
        The scheduling variable's name, for the messages.

    Returns
    -------
    float
    """
    if schedule is None:
        raise InputError(f"this model is scheduled on {variable}: give schedule= a value in {low:g}..{high:g}")
    if not isinstance(schedule, (int, float, np.number)) or isinstance(schedule, (bool, np.bool_)) \
            or not math.isfinite(schedule):
        raise InputError(f"schedule must be one finite value of {variable}; got {schedule!r}")
    if not low <= float(schedule) <= high:
        raise InputError(f"{variable} {float(schedule):g} lies outside the model's range {low:g}..{high:g}")
    return float(schedule)


def unscheduled(schedule: Any, samples: int | None = None) -> None:
    """Check the ``schedule`` given to a model without one, which is the same at every value.

    ``samples`` None: a value (or None) for a method at one operating point; otherwise a schedule of
    that many samples (or None) for a simulation. Either must be finite; it changes nothing.
    """
    if schedule is None:
        return
    values = np.asarray(schedule, dtype=float) if not isinstance(schedule, (bool, np.bool_)) else np.array([np.nan])
    wanted = () if samples is None else (samples,)
    if values.shape != wanted or not np.all(np.isfinite(values)):
        what = "one finite value" if samples is None else f"{samples} finite values (N,)"
        raise InputError(f"schedule must be {what}; got {np.shape(schedule)}")


class StateSpaceModel:
    """The protocol's methods from ``to_statespace`` (continuous models add ``simulate_outputs``)."""

    output_names: tuple[str, ...] | None = None
    #: False for a model whose state-space form is only a linearisation (scores simulate it, never predict k steps).
    is_linear = True
    #: A state-space model is the same at every value of any scheduling variable.
    is_scheduled = False

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
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

    def simulate_outputs(self, u: Any, dt: float | None = None, *, x0: Any = None,
                         schedule: Any = None) -> np.ndarray:
        """Outputs (N, n_y) driven by ``u`` (N, n_u) from ``x0`` (default zero).

        This form serves discrete-time models, ``x(k+1) = A x(k) + B u(k)``,
        ``y(k) = C x(k) + D u(k)``: ``dt``, if given, must be the model's;
        ``schedule`` (N,), if given, changes nothing (module notes).
        """
        A, B, C, D, model_dt = self.to_statespace()
        if model_dt is None:
            raise NotImplementedError("a continuous-time model simulates itself")
        if dt is not None and not np.isclose(dt, model_dt, rtol=1e-6):
            raise InputError(f"this discrete model has dt = {model_dt} s; the record has {dt} s")
        u = self.checked_input(u)
        unscheduled(schedule, u.shape[0])
        x = self.checked_state(x0)
        states = np.empty((u.shape[0], A.shape[0]))
        drive = u @ B.T
        for k in range(u.shape[0]):
            states[k] = x
            x = A @ x + drive[k]
        return states @ C.T + u @ D.T

    def simulate(self, record: IOData, *, x0: Any = None) -> TimeResponse:
        """The model's response to ``record``'s inputs from ``x0`` (default rest), with its outputs as the measurement.

        Parameters
        ----------
        record : IOData
        x0 : array_like (n_states,), optional

        Returns
        -------
        TimeResponse
            The record's time and inputs, the model's outputs, and the record's outputs as ``measured``.
        """
        y = self.simulate_outputs(record.u, record.dt, x0=x0)
        return simulated_response(record, y, output_names=self.output_names)

    def is_stable(self, *, schedule: float | None = None) -> bool:
        """Every eigenvalue in the left half-plane (continuous) or inside the unit circle (discrete), within rounding
        (:func:`eigenvalues_stable`)."""
        return eigenvalues_stable(self.eigenvalues(schedule=schedule), self.to_statespace(schedule=schedule)[4])

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready state-space form: time domain, dt, matrices, eigenvalues as [re, im]."""
        A, B, C, D, dt = self.to_statespace()
        return {"time_domain": "continuous" if dt is None else "discrete", "dt": dt, "A": A.tolist(),
                "B": B.tolist(), "C": C.tolist(), "D": D.tolist(),
                "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues()]}

    def eigenvalues(self, *, schedule: float | None = None) -> np.ndarray:
        """Eigenvalues of A (s-plane for continuous models, z-plane for discrete ones)."""
        return np.linalg.eigvals(self.to_statespace(schedule=schedule)[0])

    def modes(self, *, schedule: float | None = None) -> tuple[Mode, ...]:
        """One :class:`Mode` per complex pair (positive imaginary part) and per real pole, pairs first."""
        values = np.asarray(self.eigenvalues(schedule=schedule), dtype=complex)
        dt = self.to_statespace(schedule=schedule)[4]
        if dt is not None:
            with np.errstate(divide="ignore"):
                values = np.log(values) / dt
        scale = max(1.0, float(np.max(np.abs(values), initial=0.0)))
        pairs = sorted((v for v in values if v.imag > 1e-9 * scale), key=lambda v: (abs(v), v.real))
        real = sorted((v for v in values if abs(v.imag) <= 1e-9 * scale), key=lambda v: v.real)
        return tuple(Mode.of(v) for v in (*pairs, *real))

    def frequency_response(self, f_hz: Any, *, schedule: float | None = None) -> FrequencyResponse:
        """``C (s I - A)^-1 B + D`` at ``s = j 2 pi f`` (``z = exp(s dt)`` if discrete).

        Parameters
        ----------
        f_hz : array_like (n_f,)
            Frequencies (Hz).
        schedule : float, optional
            The scheduling variable's value (module notes).

        Returns
        -------
        FrequencyResponse
            Converts to the complex array (n_f, n_y, n_u).
        """
        return statespace_response(self.to_statespace(schedule=schedule), f_hz,
                                   getattr(self, "input_names", None), self.output_names, schedule)

    def to_control(self, *, schedule: float | None = None) -> Any:
        """A ``control.StateSpace`` (python-control, imported only here)."""
        try:
            import control
        except ImportError:  # pragma: no cover - optional dependency
            raise ImportError("python-control is not installed: pip install control") from None
        A, B, C, D, dt = self.to_statespace(schedule=schedule)
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
        path.write_text(json.dumps(values, indent=2, default=json_default) + "\n")
        return path


def statespace_response(statespace: tuple, f_hz: Any, input_names: Any = None, output_names: Any = None,
                        schedule: float | None = None) -> FrequencyResponse:
    """The :class:`FrequencyResponse` of ``(A, B, C, D, dt)`` at ``f_hz`` (Hz), by one solve per frequency.

    Parameters
    ----------
    statespace : tuple
        ``(A, B, C, D, dt)``, ``dt`` None for continuous time.
    f_hz : array_like (n_f,)
    input_names, output_names : sequence of str, optional
        Kept where they count the channels.
    schedule : float, optional
        The schedule value the matrices hold at, kept for the plot's title.

    Returns
    -------
    FrequencyResponse
    """
    A, B, C, D, dt = statespace
    f_hz = np.atleast_1d(np.asarray(f_hz, dtype=float))
    if f_hz.ndim != 1 or not np.all(np.isfinite(f_hz)):
        raise InputError("f_hz must be a finite 1-D array of frequencies (Hz)")
    s = 2j * np.pi * f_hz
    points = s if dt is None else np.exp(s * dt)
    resolvent = points[:, None, None] * np.eye(A.shape[0]) - A
    states = np.linalg.solve(resolvent, np.broadcast_to(B.astype(complex), (f_hz.size, *B.shape)))
    names = {key: tuple(value) if value is not None and len(value) == count else None
             for key, value, count in (("input_names", input_names, B.shape[1]),
                                       ("output_names", output_names, C.shape[0]))}
    return FrequencyResponse(f_hz, C @ states + D, dt, schedule=schedule, **names)


def sample_interval(dt: float | None, what: str) -> float:
    """``dt`` of a discrete-time model, or a clear error where it was never given."""
    if dt is None:
        raise InputError(f"this {what} has no sample interval: give dt when building it")
    return float(dt)
