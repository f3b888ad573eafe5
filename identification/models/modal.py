"""Modal canonical state-space models: the model built from a structure and parameters, and its simulation.

The model (Best & Bogdanski 2017, eq. 5-6) is ``xdot = A x + B u``,
``y = C x + D u`` with ``A`` real block-diagonal, one block per complex pair
or real pole, and one entry of ``C`` per state fixed to 1.

Three things are kept apart, as in the rest of the workbench: the structure
(:class:`~vehid.identification.models.modal_structure.ModalStructure`, which
also lays out the parameter vector), a parameter vector laid out by it, and
the model (:class:`ModalModel`, matrices built from the structure and
parameters), which simulates itself mode by mode (:data:`SIMULATION_METHODS`)
and gives its outputs' sensitivities to its parameters.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError
from .protocol import Mode, StateSpaceModel, eigenvalues_stable, unscheduled
from .modal_structure import ModalStructure, check_shape

__all__ = ["ModalModel", "phi_functions"]


def phi_functions(z: np.ndarray | complex) -> tuple[np.ndarray, np.ndarray]:
    """``phi1(z) = (e^z - 1)/z`` and ``phi2(z) = (e^z - 1 - z)/z^2``, accurate near z = 0.

    They give the exact hold-equivalent input gains of a mode with eigenvalue
    lambda over one sample T (``z = lambda T``): zero-order hold
    ``T phi1(z)``; first-order hold ``T (phi1 - phi2)`` on ``u_k`` and
    ``T phi2`` on ``u_{k+1}``.
    """
    z = np.asarray(z, dtype=complex)
    small = np.abs(z) < 1e-3
    safe = np.where(small, 1.0, z)
    exp = np.exp(safe)
    phi1 = np.where(small, 1 + z / 2 + z**2 / 6 + z**3 / 24, (exp - 1) / safe)
    phi2 = np.where(small, 0.5 + z / 6 + z**2 / 24 + z**3 / 120, (exp - 1 - safe) / safe**2)
    return phi1, phi2


SIMULATION_METHODS = ("foh", "zoh", "euler")


@dataclass(frozen=True, eq=False)
class ModalModel(StateSpaceModel):
    """An identified modal state-space model: a frozen value.

    Parameters
    ----------
    structure : ModalStructure
        The modes and the fixed C entries.
    A, B, C, D : ndarray
        Continuous-time matrices, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    input_names, output_names : tuple of str, optional
        Channel names; ``u1, u2, ...`` and ``y1, y2, ...`` by default.
    meta : dict, optional
        Provenance (estimator, discretisation, passes, ...).
    parameter_covariance : ndarray, optional
        Covariance of :attr:`parameters` (n_theta, n_theta), in the model's
        units, as the estimator found it (see :mod:`vehid.identification.assessment.uncertainty`);
        ``None`` where none was estimated.
    """

    structure: ModalStructure
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    parameter_covariance: np.ndarray | None = None

    def __post_init__(self) -> None:
        s = self.structure
        for name, expected in (("A", (s.n, s.n)), ("B", (s.n, s.n_u)), ("C", (s.n_y, s.n)), ("D", (s.n_y, s.n_u))):
            array = np.array(getattr(self, name), dtype=float)
            check_shape(name, array, expected)
            if not np.all(np.isfinite(array)):
                raise InputError(f"{name} holds a non-finite value")
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        s.pack(self.A, self.B, self.C, self.D)  # checks the modal form
        object.__setattr__(self, "input_names", tuple(self.input_names) if self.input_names else tuple(f"u{i + 1}" for i in range(s.n_u)))
        object.__setattr__(self, "output_names", tuple(self.output_names) if self.output_names else tuple(f"y{i + 1}" for i in range(s.n_y)))
        object.__setattr__(self, "meta", dict(self.meta))
        if self.parameter_covariance is not None:
            from .delta_method import checked_covariance

            object.__setattr__(self, "parameter_covariance", checked_covariance(self.parameter_covariance, s.n_parameters))

    @classmethod
    def from_parameters(cls, structure: ModalStructure, theta: Any, **kwargs: Any) -> "ModalModel":
        """Make the model of ``structure`` with parameter vector ``theta``.

        Parameters
        ----------
        structure : ModalStructure
            The model's structure.
        theta : array_like, shape (n_parameters,)
            Its parameters, laid out as :meth:`ModalStructure.slices` says.
        **kwargs
            The other fields of the model (names, ``meta``, ``parameter_covariance``).

        Returns
        -------
        ModalModel
            The model.
        """
        return cls(structure, *structure.matrices(theta), **kwargs)

    @property
    def parameters(self) -> np.ndarray:
        """The parameter vector theta, laid out as :class:`ModalStructure` describes."""
        return self.structure.pack(self.A, self.B, self.C, self.D)

    def parameter_std(self) -> np.ndarray | None:
        """Return the standard deviations of :attr:`parameters`.

        Returns
        -------
        ndarray, shape (n_parameters,), or None
            Square roots of the covariance's diagonal; ``None`` without a covariance.
        """
        if self.parameter_covariance is None:
            return None
        return np.sqrt(np.diag(self.parameter_covariance))

    def with_parameter_covariance(self, covariance: Any) -> "ModalModel":
        """Return the same model carrying a covariance of its parameters.

        Parameters
        ----------
        covariance : array_like, shape (n_theta, n_theta)
            Covariance of :attr:`parameters`, in the model's units.

        Returns
        -------
        ModalModel
            A copy with ``parameter_covariance`` set.
        """
        return dataclasses.replace(self, parameter_covariance=covariance)

    def uncertainty(self, *, level: float = 0.95) -> Any:
        """Estimate the modes, steady-state gains and their confidence intervals by the delta method.

        Parameters
        ----------
        level : float, default 0.95
            Confidence level of the intervals.

        Returns
        -------
        ModelUncertainty
            Each mode's and gain's value, standard deviation and interval; without a
            parameter covariance every standard deviation is NaN.
        """
        from .delta_method import model_uncertainty

        return model_uncertainty(self, level=level)

    def frequency_response_band(self, frequencies_hz: Any, *, level: float = 0.95) -> Any:
        """Compute magnitude and phase at ``frequencies_hz`` with delta-method bands.

        Parameters
        ----------
        frequencies_hz : array_like, shape (F,)
            Frequencies (Hz).
        level : float, default 0.95
            Confidence level of the bands.

        Returns
        -------
        FrequencyResponseBand
            The response and its bands per output and input
            (:func:`vehid.identification.models.delta_method.frequency_response_band`).
        """
        from .delta_method import frequency_response_band

        return frequency_response_band(self, frequencies_hz, level=level)

    def mode_eigenvalues(self) -> np.ndarray:
        """Return one eigenvalue per mode.

        Returns
        -------
        ndarray of complex, shape (n_modes,)
            ``sigma + j|omega|`` for each pair, then the real poles (1/s).
        """
        theta = self.parameters
        values = []
        for pair in range(self.structure.n_complex_pairs):
            values.append(complex(theta[2 * pair], abs(theta[2 * pair + 1])))
        for pole in range(self.structure.n_real):
            values.append(complex(theta[2 * self.structure.n_complex_pairs + pole], 0.0))
        return np.array(values)

    def eigenvalues(self, *, schedule: float | None = None) -> np.ndarray:
        """Return all n eigenvalues.

        Parameters
        ----------
        schedule : None
            Must be ``None``: the model is not scheduled (the argument is the protocol's).

        Returns
        -------
        ndarray of complex, shape (n,)
            Each pair as ``sigma + j|omega|, sigma - j|omega|``, then the real poles (1/s).
        """
        unscheduled(schedule)
        values: list[complex] = []
        for value in self.mode_eigenvalues()[: self.structure.n_complex_pairs]:
            values += [value, value.conjugate()]
        values += list(self.mode_eigenvalues()[self.structure.n_complex_pairs:])
        return np.array(values)

    def modes(self, *, schedule: float | None = None) -> tuple[Mode, ...]:
        """Return the modes: frequency, damping, time constant.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the protocol's argument; the model is not scheduled).

        Returns
        -------
        tuple of Mode
            One per mode, in the structure's order (pairs first).
        """
        unscheduled(schedule)
        return tuple(Mode.of(value) for value in self.mode_eigenvalues())

    def is_stable(self, *, schedule: float | None = None) -> bool:
        """Say whether every eigenvalue lies in the left half-plane, within rounding.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the model is not scheduled).

        Returns
        -------
        bool
            True when stable (:func:`~vehid.identification.models.protocol.eigenvalues_stable`).
        """
        unscheduled(schedule)
        return eigenvalues_stable(self.mode_eigenvalues())

    @property
    def n_u(self) -> int:
        """Number of inputs."""
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
        """Output of the model driven by ``u`` from state ``x0`` (default zero).

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Input samples, time-major.
        dt : float
            Sample interval (s); required (the argument is optional only in the protocol's signature).
        x0 : array_like, shape (n,), optional
            Initial state; zero by default.
        schedule : array_like, shape (N,), optional
            Changes nothing: the model is the same at every value of a scheduling variable.
        method : {"foh", "zoh", "euler"}
            ``foh``: exact, inputs linear between samples (the continuous model
            simulated exactly for such inputs); ``zoh``: exact, inputs held;
            ``euler``: ``x_{k+1} = x_k + dt (A x_k + B u_k)``, the paper's
            filter discretisation.
        return_states : bool
            Also return the states, shape (N, n).

        Returns
        -------
        ndarray, shape (N, n_y), or tuple of ndarray
            The output ``y``; with ``return_states``, ``(y, x)`` with the states ``x`` of shape (N, n).

        Notes
        -----
        Each mode is advanced as one complex (or real) first-order recursion
        by a compiled section filter (``scipy.signal.sosfilt``): exact and
        vectorised.
        """
        s = self.structure
        u = self._checked_input(u, dt, method)
        unscheduled(schedule, u.shape[0])
        x0 = self.checked_state(x0)
        # without states asked for, y gathers each mode in turn: no (N, n) state array held for a long record
        x = np.empty((u.shape[0], s.n)) if return_states else None
        y = None if return_states else u @ self.D.T
        theta = self.parameters
        for states in s.mode_states():
            if len(states) == 2:
                a, b = states
                lam = complex(theta[a], -theta[a + 1])  # state a + j state b evolves by sigma - j omega
                drive = _mode_drive(u, self.B[a], self.B[b])
                start = complex(x0[a], x0[b])
            else:
                (a,) = states
                lam = complex(theta[a], 0.0)
                drive = u @ self.B[a]
                start = complex(x0[a], 0.0)
            xi = _first_order_recursion(lam, drive, dt, method, start)
            del drive
            if x is not None:
                x[:, a] = xi.real
                if len(states) == 2:
                    x[:, states[1]] = xi.imag
            else:
                y += np.multiply.outer(xi.real, self.C[:, a])
                if len(states) == 2:
                    y += np.multiply.outer(xi.imag, self.C[:, states[1]])
        if x is None:
            return y
        return x @ self.C.T + u @ self.D.T, x

    def _checked_input(self, u: Any, dt: float | None, method: str) -> np.ndarray:
        """u as a float (N, n_u) array; InputError naming what is wrong with u, dt or method."""
        u = self.checked_input(u)
        if dt is None:
            raise InputError("a continuous-time model needs the sample interval dt of its input")
        if not (dt > 0 and np.isfinite(dt)):
            raise InputError(f"dt must be positive; got {dt}")
        if method not in SIMULATION_METHODS:
            raise InputError(f"unknown simulation method {method!r}; use one of {', '.join(SIMULATION_METHODS)}")
        return u

    def output_sensitivity(self, u: Any, dt: float, *, method: str = "foh") -> tuple[np.ndarray, np.ndarray]:
        """Output from rest and its exact derivatives with respect to :attr:`parameters`.

        Parameters
        ----------
        u : array_like, shape (N, n_u)
            Input samples, time-major.
        dt : float
            Sample interval (s).
        method : {"foh", "zoh", "euler"}
            The discretisation, as in :meth:`simulate_outputs`.

        Returns
        -------
        y : ndarray, shape (N, n_y)
            The output from rest.
        sensitivity : ndarray, shape (N, n_y, n_theta)
            ``d y[k, i] / d theta[p]``.

        Notes
        -----
        Every derivative is the output of a small linear recursion, so the
        whole Jacobian costs about as many first-order recursions as
        ``n_u + 1`` simulations, whatever the number of parameters: a
        mode's state is linear in its input row, so ``d xi / d B`` is the
        mode's response to each input alone (``xi`` is their sum); ``d y /
        d C`` is the state and ``d y / d D`` the input; and with ``xi`` of
        eigenvalue ``lambda`` obeying ``xi_{k+1} = g xi_k + w_k``, its
        derivative ``eta = d xi / d lambda`` obeys ``eta_{k+1} = g eta_k +
        g' xi_k + w'_k`` (``'`` the derivative in ``lambda`` of the hold
        equivalent, :func:`_hold_weight_derivatives`), from ``eta_0 = 0``. A pair's
        ``lambda`` is ``sigma - j omega``: ``d xi / d sigma = eta``,
        ``d xi / d omega = -j eta``.
        """
        s = self.structure
        u = self._checked_input(u, dt, method)
        samples = u.shape[0]
        theta = self.parameters
        b_start, c_start, d_start = (s.slices()[group].start for group in ("B", "C", "D"))
        # parameter-major storage: each derivative is written whole, and the returned view is the
        # column-major (N n_y, n_theta) Jacobian that a QR factorisation reads without a copy
        columns = np.empty((s.n_parameters, samples, s.n_y))
        columns[c_start:] = 0.0  # C and D columns are filled one output at a time below
        x = np.empty((samples, s.n))
        inputs = np.ascontiguousarray(u.T)  # (n_u, N), shared by every mode
        C = self.C

        def write(index: int, real: np.ndarray, imag: np.ndarray | None, a: int, b: int) -> None:
            # the output of a state (real part through column a of C, imaginary part through column b)
            target = columns[index]
            np.multiply.outer(real, C[:, a], out=target)
            if imag is not None:
                target += np.multiply.outer(imag, C[:, b])

        for states in s.mode_states():
            a, b = states[0], states[-1]
            pair = len(states) == 2
            lam = complex(theta[a], -theta[a + 1]) if pair else complex(theta[a], 0.0)
            row = self.B[a] + 1j * self.B[b] if pair else self.B[a]
            # the mode's response to each input alone (unit gain); its state is their sum weighted by its B row
            responses = _first_order_recursion(lam, inputs, dt, method, 0j)
            xi = row @ responses
            eta = _lambda_derivative(_mode_drive(u, self.B[a], self.B[b]) if pair else u @ row, dt, method, lam)
            write(a, eta.real, eta.imag if pair else None, a, b)
            for j in range(s.n_u):
                response = responses[j]
                write(b_start + a * s.n_u + j, response.real, response.imag if pair else None, a, b)
            if pair:  # by sigma - j omega: d/d omega = -j d/d lambda, and B_b enters as j B_b
                write(a + 1, eta.imag, -eta.real, a, b)
                for j in range(s.n_u):
                    write(b_start + b * s.n_u + j, -responses[j].imag, responses[j].real, a, b)
            x[:, a] = xi.real
            if pair:
                x[:, b] = xi.imag
        for k, (i, j) in enumerate(s.free_c):
            columns[c_start + k, :, i] = x[:, j]
        for i in range(s.n_y):
            for j in range(s.n_u):
                columns[d_start + i * s.n_u + j, :, i] = u[:, j]
        return x @ self.C.T + u @ self.D.T, columns.transpose(1, 2, 0)

    def free_response_sensitivity(self, x0: Any, n_samples: int, dt: float, *, method: str = "foh"
                                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The output of the initial state ``x0`` with zero input, and its exact derivatives.

        A simulation from ``x0`` is the simulation from rest
        (:meth:`output_sensitivity`) plus this free response, and so are
        their derivatives with respect to :attr:`parameters`.

        Parameters
        ----------
        x0 : array_like, shape (n,)
            The initial state.
        n_samples : int
            The response's length N.
        dt : float
            Sample interval (s).
        method : {"foh", "zoh", "euler"}
            The discretisation, as for :meth:`output_sensitivity`.

        Returns
        -------
        y : ndarray, shape (N, n_y)
            The free response.
        by_parameters : ndarray, shape (N, n_y, n_theta)
            ``d y[k, i] / d theta[p]``: a mode's eigenvalue through its
            free decay, the free C entries through the free states.
        by_state : ndarray, shape (N, n_y, n)
            ``d y[k, i] / d x0[j]``.

        Notes
        -----
        A mode's free state is ``xi_k = g^k xi_0`` with ``g`` the hold
        equivalent's pole (:func:`_hold_weights`), so ``d xi_k / d lambda =
        k g^(k-1) g' xi_0`` (``g' = dt g`` for an exact hold). A pair's
        ``xi_0`` is ``x0[a] + j x0[b]`` and its ``lambda`` is ``sigma - j omega``,
        as in :meth:`output_sensitivity`.
        """
        s = self.structure
        x0 = self.checked_state(x0)
        if method not in SIMULATION_METHODS:
            raise InputError(f"unknown simulation method {method!r}; use one of {', '.join(SIMULATION_METHODS)}")
        steps = np.arange(int(n_samples))
        theta = self.parameters
        C = self.C
        y = np.zeros((steps.size, s.n_y))
        by_parameters = np.zeros((steps.size, s.n_y, s.n_parameters))
        by_state = np.zeros((steps.size, s.n_y, s.n))
        states = np.zeros((steps.size, s.n))
        for mode in s.mode_states():
            a, b = mode[0], mode[-1]
            pair = len(mode) == 2
            lam = complex(theta[a], -theta[a + 1]) if pair else complex(theta[a], 0.0)
            g = _hold_weights(lam * dt, method)[0]
            slope = dt if method == "euler" else dt * g  # d g / d lambda
            # past e^-50 of its start (k |g|^k too, for any record shorter than e^14 samples) a decaying mode's
            # response is zero to rounding: only its head is computed
            live = steps.size if abs(g) >= 1.0 else min(steps.size, int(np.ceil(50.0 / -np.log(abs(g)))) + 1)
            head = steps[:live]
            with np.errstate(all="ignore"):  # a growing mode may overflow: its sensitivities say so
                powers = g ** head
                by_lambda = head * slope * g ** np.maximum(head - 1, 0)
            start = complex(x0[a], x0[b]) if pair else complex(x0[a], 0.0)
            free, by_eigenvalue = powers * start, by_lambda * start
            states[:live, a] = free.real
            y[:live] += np.multiply.outer(free.real, C[:, a])
            by_parameters[:live, :, a] += np.multiply.outer(by_eigenvalue.real, C[:, a])
            by_state[:live, :, a] += np.multiply.outer(powers.real, C[:, a])
            if pair:  # the imaginary part through column b; d/d omega = -j d/d lambda, d/d x0[b] = j d/d xi_0
                states[:live, b] = free.imag
                y[:live] += np.multiply.outer(free.imag, C[:, b])
                by_parameters[:live, :, a] += np.multiply.outer(by_eigenvalue.imag, C[:, b])
                by_parameters[:live, :, a + 1] += (np.multiply.outer(by_eigenvalue.imag, C[:, a])
                                                   - np.multiply.outer(by_eigenvalue.real, C[:, b]))
                by_state[:live, :, a] += np.multiply.outer(powers.imag, C[:, b])
                by_state[:live, :, b] += (np.multiply.outer(powers.real, C[:, b])
                                          - np.multiply.outer(powers.imag, C[:, a]))
        c_start = s.slices()["C"].start
        for k, (i, j) in enumerate(s.free_c):
            by_parameters[:, i, c_start + k] += states[:, j]
        return y, by_parameters, by_state

    def to_statespace(self, *, schedule: float | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, None]:
        """Return the state-space matrices.

        Parameters
        ----------
        schedule : None
            Must be ``None`` (the model is not scheduled).

        Returns
        -------
        tuple
            ``(A, B, C, D, None)``: continuous time (no sample interval).
        """
        unscheduled(schedule)
        return self.A, self.B, self.C, self.D, None

    def to_dict(self) -> dict[str, Any]:
        """Describe the model for JSON.

        Returns
        -------
        dict
            Structure, matrices, names, eigenvalues as [re, im], ``meta`` and, if
            estimated, ``parameter_covariance``.
        """
        return {
            "structure": self.structure.to_dict(),
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues()],
            "input_names": list(self.input_names),
            "output_names": list(self.output_names),
            "meta": self.meta,
            **({} if self.parameter_covariance is None else {"parameter_covariance": self.parameter_covariance.tolist()}),
        }

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "ModalModel":
        """Read a model that :meth:`to_dict` described.

        Parameters
        ----------
        values : dict
            The description; without ``parameter_covariance`` the model has none.

        Returns
        -------
        ModalModel
            The model.
        """
        covariance = values.get("parameter_covariance")
        return cls(
            ModalStructure.from_dict(values["structure"]),
            np.array(values["A"]),
            np.array(values["B"]),
            np.array(values["C"]),
            np.array(values["D"]),
            input_names=tuple(values.get("input_names") or ()),
            output_names=tuple(values.get("output_names") or ()),
            meta=dict(values.get("meta") or {}),
            parameter_covariance=None if covariance is None else np.array(covariance, dtype=float),
        )

    def mat_fields(self) -> dict[str, Any]:
        """Return the fields of the model's MATLAB file.

        Returns
        -------
        dict
            A, B, C, D and ``C_fixed``, the mask of output-matrix entries the structure fixes.
        """
        mask = np.zeros((self.structure.n_y, self.structure.n))
        for i, j in self.structure.fixed_c:
            mask[i, j] = 1
        return {**super().mat_fields(), "C_fixed": mask}


def _mode_drive(u: np.ndarray, real_row: np.ndarray, imag_row: np.ndarray) -> np.ndarray:
    """``u (B_a + j B_b)``, a pair's complex input, by two real matrix-vector products.

    At inner size ``n_u`` these cost a fifth of an einsum over the inputs
    (0.03 against 0.25 ms at 50,000 samples, with or without the other core
    loaded).
    """
    drive = np.empty(u.shape[0], dtype=complex)
    drive.real = u @ real_row
    drive.imag = u @ imag_row
    return drive


def _first_order_recursion(lam: complex, drive: np.ndarray, dt: float, method: str, start: complex) -> np.ndarray:
    """xi_{k+1} = g xi_k + dt (alpha d_k + beta d_{k+1}) from ``xi_0 = start``; returns xi_0..xi_{N-1}.

    ``drive`` may hold several signals along its leading axes (time last),
    each filtered from the same ``start``: one call for them all.
    """
    gain, alpha, beta = _hold_weights(lam * dt, method)
    return _section_from(np.array([dt * beta, dt * alpha, 0.0]), np.array([1.0, -gain, 0.0]), drive, start)


def _section_from(numerator: np.ndarray, denominator: np.ndarray, drive: np.ndarray, first: complex,
                  second: complex | None = None) -> np.ndarray:
    """The recursion ``a(q^-1) y = b(q^-1) d`` (degree two at most) along the last axis from given first outputs.

    A recursion's output is that of the filter from the state that yields
    its first outputs (``y_0``, and ``y_1`` where given for a second-order
    one; the state of the transposed direct form is solved for below), so
    the hold's boundary at the first sample needs no arrays of its own.
    scipy's section filter has a loop compiled per data type; ``lfilter``'s
    generic one takes about twice as long per complex sample.
    """
    from scipy.signal import sosfilt  # a second to import: paid on first use

    coefficients = np.concatenate([numerator, denominator])
    # a real mode of a real drive runs in real arithmetic (about two thirds of the complex loop's time)
    kind = complex if np.iscomplexobj(drive) or np.any(np.imag(coefficients) != 0) else float
    coefficients = np.array(np.real(coefficients) if kind is float else coefficients, dtype=kind)
    if kind is float:
        first, second = np.real(first), None if second is None else np.real(second)
    b0, b1, _, _, a1, _ = coefficients
    d0 = drive[..., 0]
    state = np.zeros((1,) + drive.shape[:-1] + (2,), dtype=kind)
    state[..., 0] = first - b0 * d0  # y_0 = b0 d_0 + z_0
    if second is not None and drive.shape[-1] > 1:  # y_1 = b0 d_1 + b1 d_0 - a1 y_0 + z_1
        state[..., 1] = second - b0 * drive[..., 1] - b1 * d0 + a1 * first
    return sosfilt(coefficients[None, :], drive, axis=-1, zi=state)[0]


def _hold_weights(z: complex, method: str) -> tuple[complex, complex, complex]:
    """``(g, alpha, beta)`` of ``xi_{k+1} = g xi_k + dt (alpha d_k + beta d_{k+1})`` at ``z = lambda dt``."""
    if method == "euler":
        return 1.0 + z, 1.0, 0.0
    phi1, phi2 = (complex(value) for value in phi_functions(z))
    if method == "zoh":
        return np.exp(z), phi1, 0.0
    return np.exp(z), phi1 - phi2, phi2


def _hold_weight_derivatives(z: complex, method: str) -> tuple[complex, complex, complex]:
    """Derivatives in ``z`` of :func:`_hold_weights` (by ``phi_k' = phi_k - k phi_{k+1}``)."""
    if method == "euler":
        return 1.0, 0.0, 0.0
    phi1, phi2 = (complex(value) for value in phi_functions(z))
    if method == "zoh":
        return np.exp(z), phi1 - phi2, 0.0
    phi3 = _phi3(complex(z), phi2)
    return np.exp(z), phi1 - 2 * phi2 + 2 * phi3, phi2 - 2 * phi3


def _phi3(z: complex, phi2: complex) -> complex:
    """``phi_3(z) = (phi_2(z) - 1/2) / z`` to rounding at any ``z``.

    Below ``|z| = 1/2`` its Taylor series ``sum z^m / (m + 3)!`` to ``m = 16``
    (remainder below 1e-20), where the recurrence would cancel; above, the
    recurrence loses at most a factor of 4 over ``phi_2``'s rounding.
    """
    if abs(z) >= 0.5:
        return (phi2 - 0.5) / z
    term, total = 1.0 / 6.0, 0j
    for m in range(17):
        total += term
        term *= z / (m + 4)
    return total


def _lambda_derivative(drive: np.ndarray, dt: float, method: str, lam: complex) -> np.ndarray:
    """``d xi / d lambda`` of a mode's recursion from rest (:meth:`ModalModel.output_sensitivity`).

    ``eta`` obeys ``eta_{k+1} = g eta_k + dt g' xi_k + dt^2 (alpha' d_k +
    beta' d_{k+1})`` (``'`` the derivative in ``z = lambda dt``) with
    ``(1 - g q^-1) xi = dt (alpha q^-1 + beta) d``; eliminating ``xi``
    leaves one recursion with a double pole at ``g``, which holds from the
    third sample on: ``(1 - g q^-1)^2 eta = dt^2 (b0 + b1 q^-1 + b2 q^-2) d``
    with ``b0 = beta'``, ``b1 = g' beta + alpha' - g beta'``, ``b2 = g' alpha
    - g alpha'``. From rest, ``eta_0 = 0`` and ``eta_1 = dt^2 (alpha' d_0 +
    beta' d_1)``.
    """
    g, alpha, beta = _hold_weights(lam * dt, method)
    g_z, alpha_z, beta_z = _hold_weight_derivatives(lam * dt, method)
    scale = dt * dt
    numerator = scale * np.array([beta_z, g_z * beta + alpha_z - g * beta_z, g_z * alpha - g * alpha_z])
    second = scale * (alpha_z * drive[0] + beta_z * drive[1]) if drive.shape[-1] > 1 else None
    return _section_from(numerator, np.array([1.0, -2 * g, g * g]), drive, 0j, second)
