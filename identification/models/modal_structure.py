"""The structure of a modal canonical state-space model, and its parameter vector's layout.

The model (Best & Bogdanski 2017, eq. 5-6) is ``xdot = A x + B u``,
``y = C x + D u`` with ``A`` real block-diagonal: a complex pair
``sigma +/- j omega`` is the block ``[[sigma, omega], [-omega, sigma]]``, a
real pole the block ``[sigma]``. Pairs come first, then real poles. ``B`` and
``D`` are free. In ``C`` exactly one entry per state column is fixed to 1,
which ties each mode to an output and removes the scaling freedom of the
state basis; the other entries of ``C`` are free.

The structure (:class:`ModalStructure`) says how many modes of which kind, which
output each is tied to, and how a parameter vector is laid out; the model built
from a structure and parameters is :class:`~vehid.identification.models.modal.ModalModel`.

Parameter vector layout (``theta``), in this order:

1. per complex pair ``sigma_i, omega_i``; per real pole ``sigma_i``;
2. ``B`` row-major;
3. the free entries of ``C``, row-major, skipping the fixed ones;
4. ``D`` row-major.

A complex pair written with ``state a + j state b`` evolves as
``(sigma - j omega)``, so the pair's eigenvalues are ``sigma +/- j omega``
whichever sign omega takes; the workbench keeps omega positive when it
reports a model.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..choices import C_PATTERNS
from ..errors import InputError

__all__ = ["ModalStructure", "C_PATTERNS", "check_shape"]


# Which output each mode (pairs first, then real poles) is tied to in eq. 19,
# for three outputs; n = 5 is eq. 18. The paper ties n = 7's real pole to the
# third output, beside the third pair, where plain round-robin would wrap.
_EQ19_MODE_OUTPUTS = {
    3: (0, 1),
    4: (0, 1),
    5: (0, 1, 2),
    6: (0, 1, 2),
    7: (0, 1, 2, 2),
}


def _positive_int(value: Any, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or int(value) != value or int(value) < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}; got {value!r}")
    return int(value)


@dataclass(frozen=True)
class ModalStructure:
    """The shape of a modal model: its modes and which C entries are fixed to 1.

    Use :meth:`default` or :meth:`from_pattern` rather than listing ``fixed_c``.

    Parameters
    ----------
    n_complex_pairs, n_real : int
        Number of complex-pair blocks (2 states each) and real poles.
    n_u, n_y : int
        Numbers of inputs and outputs.
    fixed_c : tuple of (output, state) pairs
        The C entries fixed to 1, exactly one per state column.
    """

    n_complex_pairs: int
    n_real: int
    n_u: int
    n_y: int
    fixed_c: tuple[tuple[int, int], ...]

    def __post_init__(self) -> None:
        _positive_int(self.n_complex_pairs, "n_complex_pairs", 0)
        _positive_int(self.n_real, "n_real", 0)
        _positive_int(self.n_u, "n_u")
        _positive_int(self.n_y, "n_y")
        if self.n < 1:
            raise InputError("a modal structure needs at least one state")
        fixed = tuple(sorted((int(i), int(j)) for i, j in self.fixed_c))
        object.__setattr__(self, "fixed_c", fixed)
        columns = [j for _, j in fixed]
        if sorted(columns) != list(range(self.n)):
            raise InputError(
                f"fixed_c must fix exactly one C entry per state column 0..{self.n - 1}; got {fixed}"
            )
        for i, j in fixed:
            if not 0 <= i < self.n_y:
                raise InputError(f"fixed C entry ({i}, {j}) names output {i} of {self.n_y}")
        for pair in range(self.n_complex_pairs):
            a, b = self.output_of_state(2 * pair), self.output_of_state(2 * pair + 1)
            if a != b:
                raise InputError(
                    f"complex pair {pair + 1} must be tied to one output by both its fixed C entries"
                )

    @classmethod
    def default(cls, n: int, n_u: int, n_y: int) -> "ModalStructure":
        """Make the structure of order ``n`` with pairs first, each mode tied to the next output in turn.

        This generalises eq. 18/19: a complex pair is tied to one output by two
        fixed 1s, a real pole by one, outputs assigned round-robin.
        With one output every C entry is fixed (``C = [1 1 ... 1]``).

        Parameters
        ----------
        n : int
            Model order: ``n // 2`` complex pairs and, for odd ``n``, one real pole.
        n_u, n_y : int
            Numbers of inputs and outputs.

        Returns
        -------
        ModalStructure
            The structure.
        """
        pairs, real = divmod(_positive_int(n, "order n"), 2)
        return cls.with_modes(pairs, real, n_u, n_y)

    @classmethod
    def with_modes(cls, n_complex_pairs: int, n_real: int, n_u: int, n_y: int) -> "ModalStructure":
        """Make a structure of given modes, each tied to the next output in turn (as :meth:`default`).

        Parameters
        ----------
        n_complex_pairs, n_real : int
            Number of complex pairs (2 states each) and of real poles.
        n_u, n_y : int
            Numbers of inputs and outputs.

        Returns
        -------
        ModalStructure
            The structure, pairs first.
        """
        modes = range(n_complex_pairs + n_real)
        return cls._tied(n_complex_pairs, n_real, n_u, n_y, [mode % n_y for mode in modes])

    @classmethod
    def from_pattern(cls, pattern: str, n: int, n_u: int, n_y: int) -> "ModalStructure":
        """Make a structure with one of the named C patterns of :data:`C_PATTERNS`.

        Parameters
        ----------
        pattern : str
            ``"default"`` (as :meth:`default`), ``"all-ones"`` (every mode tied to
            the first output), ``"eq18"`` (n = 5) or ``"eq19"`` (n = 3..7), the
            paper's patterns for three outputs.
        n : int
            Model order.
        n_u, n_y : int
            Numbers of inputs and outputs.

        Returns
        -------
        ModalStructure
            The structure.

        Raises
        ------
        InputError
            For an unknown pattern, or one not defined for this order or number of outputs.
        """
        n = _positive_int(n, "order n")
        pairs, real = divmod(n, 2)
        if pattern == "default":
            return cls.default(n, n_u, n_y)
        if pattern == "all-ones":
            return cls._tied(pairs, real, n_u, n_y, [0] * (pairs + real))
        if pattern in ("eq18", "eq19"):
            if n_y != 3:
                raise InputError(f"the {pattern} pattern is defined for three outputs; got {n_y}")
            if pattern == "eq18" and n != 5:
                raise InputError(f"the eq18 pattern is defined for n = 5; got n = {n}")
            if n not in _EQ19_MODE_OUTPUTS:
                raise InputError(f"the eq19 patterns are defined for n = 3..7; got n = {n}")
            return cls._tied(pairs, real, n_u, n_y, list(_EQ19_MODE_OUTPUTS[n]))
        raise InputError(f"unknown C pattern {pattern!r}; use one of {', '.join(C_PATTERNS)}")

    @classmethod
    def _tied(cls, pairs: int, real: int, n_u: int, n_y: int, mode_outputs: Sequence[int]) -> "ModalStructure":
        fixed = []
        for mode, output in enumerate(mode_outputs):
            states = (2 * mode, 2 * mode + 1) if mode < pairs else (2 * pairs + mode - pairs,)
            fixed.extend((output, state) for state in states)
        return cls(pairs, real, n_u, n_y, tuple(fixed))

    @property
    def n(self) -> int:
        """Model order (number of states)."""
        return 2 * self.n_complex_pairs + self.n_real

    @property
    def n_modal(self) -> int:
        """Number of sigma/omega parameters (equals n)."""
        return self.n

    @property
    def n_free_c(self) -> int:
        """Number of free C entries."""
        return self.n_y * self.n - self.n

    @property
    def n_parameters(self) -> int:
        """Length of the parameter vector theta."""
        return self.n_modal + self.n * self.n_u + self.n_free_c + self.n_y * self.n_u

    def output_of_state(self, state: int) -> int:
        """Return the output a state is tied to by its fixed C entry.

        Parameters
        ----------
        state : int
            State index, 0-based.

        Returns
        -------
        int
            Output index, 0-based.
        """
        for i, j in self.fixed_c:
            if j == state:
                return i
        raise InputError(f"state {state} out of range 0..{self.n - 1}")

    @functools.cached_property
    def free_c(self) -> tuple[tuple[int, int], ...]:
        """The free C entries (output, state), row-major (asked for at every conversion of theta: kept)."""
        fixed = set(self.fixed_c)
        return tuple((i, j) for i in range(self.n_y) for j in range(self.n) if (i, j) not in fixed)

    def parameter_names(self) -> tuple[str, ...]:
        """Name theta's entries: ``sigma1, omega1, ..., b11, ..., c21, ..., d11, ...`` (1-based).

        Returns
        -------
        tuple of str
            One name per entry of theta, ``n_parameters`` of them.
        """
        names = []
        for pair in range(self.n_complex_pairs):
            names += [f"sigma{pair + 1}", f"omega{pair + 1}"]
        for pole in range(self.n_real):
            names.append(f"sigma{self.n_complex_pairs + pole + 1}")
        names += [f"b{i + 1}{j + 1}" for i in range(self.n) for j in range(self.n_u)]
        names += [f"c{i + 1}{j + 1}" for i, j in self.free_c]
        names += [f"d{i + 1}{j + 1}" for i in range(self.n_y) for j in range(self.n_u)]
        return tuple(names)

    def slices(self) -> dict[str, slice]:
        """Locate each group of parameters in theta.

        Returns
        -------
        dict of str to slice
            The slices of ``modal`` (sigma, omega), ``B``, ``C`` (free entries) and ``D``.
        """
        a = self.n_modal
        b = a + self.n * self.n_u
        c = b + self.n_free_c
        return {"modal": slice(0, a), "B": slice(a, b), "C": slice(b, c), "D": slice(c, c + self.n_y * self.n_u)}

    def mode_states(self) -> list[tuple[int, ...]]:
        """List the states of each mode.

        Returns
        -------
        list of tuple of int
            ``(2i, 2i+1)`` for each pair, then ``(j,)`` for each real pole.
        """
        modes: list[tuple[int, ...]] = [(2 * p, 2 * p + 1) for p in range(self.n_complex_pairs)]
        modes += [(2 * self.n_complex_pairs + r,) for r in range(self.n_real)]
        return modes

    def matrices(self, theta: Any, backend: Any = np) -> tuple[Any, Any, Any, Any]:
        """Build A, B, C, D from theta, as NumPy arrays or (``backend=casadi.SX``) symbolic matrices.

        With CasADi, ``theta`` is an SX column and the result is built from its
        elements, so that Jacobians with respect to theta are exact.

        Parameters
        ----------
        theta : array_like or casadi.SX
            Parameter vector, ``n_parameters`` entries laid out as :meth:`slices` says.
        backend : module or class, default numpy
            ``numpy`` for arrays, or a CasADi matrix class (``casadi.SX``, ``casadi.MX``).

        Returns
        -------
        tuple of ndarray or of casadi matrices
            ``(A, B, C, D)``, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
        """
        n, n_u, n_y = self.n, self.n_u, self.n_y
        s = self.slices()
        if backend is np:
            theta = np.asarray(theta, dtype=float).ravel()
            if theta.size != self.n_parameters:
                raise InputError(f"theta must have {self.n_parameters} entries for this structure; got {theta.size}")
            A = np.zeros((n, n))
            C = np.zeros((n_y, n))
        else:
            A = backend.zeros(n, n)
            C = backend.zeros(n_y, n)
        modal = theta[s["modal"]]
        for pair in range(self.n_complex_pairs):
            sigma, omega = modal[2 * pair], modal[2 * pair + 1]
            a, b = 2 * pair, 2 * pair + 1
            A[a, a] = sigma
            A[a, b] = omega
            A[b, a] = -omega
            A[b, b] = sigma
        for pole in range(self.n_real):
            state = 2 * self.n_complex_pairs + pole
            A[state, state] = modal[state]
        if backend is np:
            B = theta[s["B"]].reshape(n, n_u)
            D = theta[s["D"]].reshape(n_y, n_u)
        else:
            B = backend.zeros(n, n_u)
            D = backend.zeros(n_y, n_u)
            for k in range(n * n_u):
                B[k // n_u, k % n_u] = theta[s["B"].start + k]
            for k in range(n_y * n_u):
                D[k // n_u, k % n_u] = theta[s["D"].start + k]
        for (i, j) in self.fixed_c:
            C[i, j] = 1.0
        for k, (i, j) in enumerate(self.free_c):
            C[i, j] = theta[s["C"].start + k]
        return A, B, C, D

    def pack(self, A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> np.ndarray:
        """Pack matrices of this structure into theta, checking that A is modal and C's fixed entries are 1.

        Parameters
        ----------
        A, B, C, D : array_like
            Shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).

        Returns
        -------
        ndarray, shape (n_parameters,)
            The parameter vector.
        """
        A, B, C, D = (np.asarray(m, dtype=float) for m in (A, B, C, D))
        check_shape("A", A, (self.n, self.n))
        check_shape("B", B, (self.n, self.n_u))
        check_shape("C", C, (self.n_y, self.n))
        check_shape("D", D, (self.n_y, self.n_u))
        modal = []
        for pair in range(self.n_complex_pairs):
            a = 2 * pair
            modal += [A[a, a], A[a, a + 1]]
        for pole in range(self.n_real):
            state = 2 * self.n_complex_pairs + pole
            modal.append(A[state, state])
        theta = self._theta_of(modal, B, C, D)
        rebuilt = self.matrices(theta)
        if not _equal_within(rebuilt[0], A, 1e-12 * max(1.0, np.abs(A).max())):
            raise InputError("A is not in the modal block form of this structure")
        if not _equal_within(rebuilt[2], C, 1e-12 * max(1.0, np.abs(C).max())):
            raise InputError("C's fixed entries are not 1 for this structure")
        return theta

    def _theta_of(self, modal: Any, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> np.ndarray:
        """theta from the modal entries and B, C, D of this structure, unchecked."""
        return np.concatenate([modal, B.ravel(), [C[i, j] for i, j in self.free_c], D.ravel()])

    def initial_parameters(self, *, sigma: float = -1.0, omega: float = 1.0, omega_spread: float = 0.0) -> np.ndarray:
        """Return the filter's start: every sigma given, omegas ``omega * (1 + omega_spread * i)``, B, free C, D zero.

        A spread of the omegas keeps the pairs apart, so that the filter does
        not start symmetric in them (identical pairs get identical updates).

        Parameters
        ----------
        sigma : float, default -1.0
            Real part of every eigenvalue (1/s in the model's time unit).
        omega : float, default 1.0
            Imaginary part of the first pair (rad/s in the model's time unit).
        omega_spread : float, default 0.0
            Relative step between the omegas of successive pairs.

        Returns
        -------
        ndarray, shape (n_parameters,)
            The parameter vector.
        """
        theta = np.zeros(self.n_parameters)
        for pair in range(self.n_complex_pairs):
            theta[2 * pair] = sigma
            theta[2 * pair + 1] = omega * (1.0 + omega_spread * pair)
        for pole in range(self.n_real):
            theta[2 * self.n_complex_pairs + pole] = sigma
        return theta

    def denormalize(self, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
        """Convert parameters identified on scaled data to the original units.

        With ``u = Su u_n`` and ``y = Sy y_n`` and the state basis rescaled by the
        scale of the output each state is tied to, ``A`` is unchanged, the fixed
        C entries stay 1, ``B -> S B Su^-1``, ``C -> Sy C S^-1``, ``D -> Sy D Su^-1``.

        Parameters
        ----------
        theta : array_like, shape (n_parameters,)
            Parameters of the model of the scaled data.
        input_scale : ndarray, shape (n_u,)
            ``Su``, the input scales (the original input is ``Su u_n``).
        output_scale : ndarray, shape (n_y,)
            ``Sy``, the output scales.

        Returns
        -------
        ndarray, shape (n_parameters,)
            Parameters of the model in the original units.
        """
        _, B, C, D = self.matrices(theta)
        state_scale = np.array([output_scale[self.output_of_state(j)] for j in range(self.n)])
        B = state_scale[:, None] * B / input_scale[None, :]
        C = output_scale[:, None] * C / state_scale[None, :]
        D = output_scale[:, None] * D / input_scale[None, :]
        # A is unchanged and C's fixed entries stay 1 (each state is scaled by its own output's scale): the
        # matrices are this structure's by construction, and pack's check would only repeat that
        return self._theta_of(np.asarray(theta, dtype=float).ravel()[self.slices()["modal"]], B, C, D)

    def normalize_parameters(self, theta: np.ndarray, input_scale: np.ndarray, output_scale: np.ndarray) -> np.ndarray:
        """Convert parameters in the original units to those of scaled data: the inverse of :meth:`denormalize`.

        Parameters
        ----------
        theta : array_like, shape (n_parameters,)
            Parameters in the original units.
        input_scale, output_scale : ndarray, shapes (n_u,) and (n_y,)
            The scales, as for :meth:`denormalize`.

        Returns
        -------
        ndarray, shape (n_parameters,)
            Parameters of the model of the scaled data.
        """
        return self.denormalize(theta, 1.0 / input_scale, 1.0 / output_scale)

    def rescale_time(self, theta: np.ndarray, factor: float) -> np.ndarray:
        """Express the parameters in a time unit ``factor`` times the present one.

        ``xdot = A x + B u`` in time ``t' = t / factor`` reads ``dx/dt' = factor A x + factor B u``:
        sigma, omega and B are multiplied by ``factor``, C and D are unchanged.

        Parameters
        ----------
        theta : array_like, shape (n_parameters,)
            Parameters in the present time unit.
        factor : float
            The new time unit in present ones.

        Returns
        -------
        ndarray, shape (n_parameters,)
            Parameters in the new time unit.
        """
        return np.array(theta, dtype=float) * self.time_weights(factor)

    def time_weights(self, ratio: float) -> np.ndarray:
        """Weigh each parameter by its change under a change of time unit.

        Parameters
        ----------
        ratio : float
            The new time unit in present ones.

        Returns
        -------
        ndarray, shape (n_parameters,)
            ``ratio`` for sigma, omega and B; 1 for C and D.
        """
        weights = np.ones(self.n_parameters)
        slices = self.slices()
        weights[slices["modal"]] = ratio
        weights[slices["B"]] = ratio
        return weights

    def to_dict(self) -> dict[str, Any]:
        """Describe the structure for JSON.

        Returns
        -------
        dict
            ``n``, ``n_complex_pairs``, ``n_real``, ``n_u``, ``n_y`` and ``fixed_c`` (a list of [output, state]).
        """
        return {
            "n": self.n,
            "n_complex_pairs": self.n_complex_pairs,
            "n_real": self.n_real,
            "n_u": self.n_u,
            "n_y": self.n_y,
            "fixed_c": [list(entry) for entry in self.fixed_c],
        }

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "ModalStructure":
        """Read the structure :meth:`to_dict` described.

        Parameters
        ----------
        values : dict
            The description.

        Returns
        -------
        ModalStructure
            The structure.
        """
        return cls(
            int(values["n_complex_pairs"]),
            int(values["n_real"]),
            int(values["n_u"]),
            int(values["n_y"]),
            tuple((int(i), int(j)) for i, j in values["fixed_c"]),
        )


def _equal_within(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    """``np.allclose(a, b, rtol=0, atol=atol)`` for arrays of one shape, at a tenth of its cost.

    :meth:`ModalStructure.pack` checks every model made and every parameter
    vector converted, several times per filter pass, where ``allclose``'s
    generality took a sixth of a short identification run.
    """
    with np.errstate(invalid="ignore"):  # inf - inf: equal infinities pass through a == b, as in allclose
        return bool(np.all((a == b) | (np.abs(a - b) <= atol)))


def check_shape(name: str, array: np.ndarray, expected: tuple[int, int]) -> None:
    """Refuse a matrix ``name`` whose shape is not the structure's ``expected`` one."""
    if array.shape != expected:
        raise InputError(f"{name} has shape {array.shape}; this structure needs {expected}")
