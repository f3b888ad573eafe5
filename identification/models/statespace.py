"""State-space conversions: hold equivalents, discrete to continuous, modal form, reduction.

With a first-order hold (inputs linear between samples, as the paper's eq. 16 input is) the exact
discrete model ``x(k+1) = Phi x(k) + G1 u(k) + G2 u(k+1)`` is brought to standard form by the state
``xi = x - G2 u``: ``Bd = G1 + Phi G2``, ``Cd = C``, ``Dd = D + C G2``, with ``G1 = T (phi1 - phi2)(AT) B``
and ``G2 = T phi2(AT) B`` (Franklin, Powell & Workman, *Digital Control of Dynamic Systems*, 3rd ed.,
sec. 6.3.2). :func:`to_modal` brings a diagonalisable model to the form of
:class:`~identification.models.modal_structure.ModalStructure`; :func:`balanced_truncation` reduces a stable discrete
model (Moore 1981; square-root form of Laub et al. 1987).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..argument_checks import finite_matrix
from ..errors import InputError
from .modal import ModalModel
from .modal_structure import ModalStructure

__all__ = [
    "HOLDS",
    "continuous_to_discrete",
    "hold_state_shift",
    "discrete_to_continuous",
    "modal_structure_for",
    "to_modal",
    "balanced_truncation",
]

HOLDS = ("zoh", "foh")
_COMPLEX_TOLERANCE = 1e-9  # |Im| / |lambda| below which an eigenvalue counts as real
_EIGENVECTOR_CONDITION_LIMIT = 1e12  # above: treated as not diagonalisable


def _system(A: Any, B: Any, C: Any, D: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    A, B, C, D = (finite_matrix(name, m) for name, m in zip("ABCD", (A, B, C, D)))
    n = A.shape[0]
    for name, m, shape in (("A", A, (n, n)), ("B", B, (n, B.shape[1])), ("C", C, (C.shape[0], n)),
                           ("D", D, (C.shape[0], B.shape[1]))):
        if m.shape != shape:
            raise InputError(f"{name} has shape {m.shape}; expected {shape} for a model with {n} states")
    return A, B, C, D


def _phi_matrices(A: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``exp(AT), phi1(AT), phi2(AT)`` from one exponential of a 3n block matrix."""
    import scipy.linalg  # half a second to import: paid where used, not at every command's start
    n = A.shape[0]
    block = np.zeros((3 * n, 3 * n))
    block[:n, :n] = A * dt
    block[:n, n:2 * n] = np.eye(n)
    block[n:2 * n, 2 * n:] = np.eye(n)
    e = scipy.linalg.expm(block)
    return e[:n, :n], e[:n, n:2 * n], e[:n, 2 * n:]


def _check_hold(hold: str, dt: float) -> None:
    if hold not in HOLDS:
        raise InputError(f"unknown hold {hold!r}; use one of {', '.join(HOLDS)}")
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"dt must be positive; got {dt}")


def continuous_to_discrete(A: Any, B: Any, C: Any, D: Any, dt: float, *, hold: str = "foh"
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact discrete equivalent for a zero- or first-order hold of the inputs.

    Parameters
    ----------
    A, B, C, D : array_like
        Continuous model, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    dt : float
        Sample interval (s).
    hold : {"foh", "zoh"}, default "foh"
        Inputs linear between samples (first-order hold) or held (zero-order hold).

    Returns
    -------
    tuple of ndarray
        ``(Ad, Bd, Cd, Dd)``; for ``foh`` the state is ``xi = x - G2 u`` (module docstring).
    """
    A, B, C, D = _system(A, B, C, D)
    _check_hold(hold, dt)
    phi, phi1, phi2 = _phi_matrices(A, dt)
    if hold == "zoh":
        return phi, dt * phi1 @ B, C.copy(), D.copy()
    g1 = dt * (phi1 - phi2) @ B
    g2 = dt * phi2 @ B
    return phi, g1 + phi @ g2, C.copy(), D + C @ g2


def hold_state_shift(A: Any, B: Any, dt: float) -> np.ndarray:
    """Return ``G2 = T phi2(AT) B``: the first-order-hold equivalent's state is ``xi = x - G2 u``.

    A continuous state ``x0`` at the first sample is ``xi0 = x0 - G2 u(0)``
    in the discrete model :func:`continuous_to_discrete` returns for ``foh``.

    Parameters
    ----------
    A, B : array_like
        Continuous model, shapes (n, n) and (n, n_u).
    dt : float
        Sample interval T (s).

    Returns
    -------
    ndarray, shape (n, n_u)
        ``G2``.
    """
    A, B = finite_matrix("A", A), finite_matrix("B", B)
    if A.shape != (A.shape[0], A.shape[0]) or B.shape[0] != A.shape[0]:
        raise InputError(f"A {A.shape} and B {B.shape} do not make a state-space model")
    _check_hold("foh", dt)
    return dt * _phi_matrices(A, dt)[2] @ B


def _diagonalise(A: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    values, vectors = np.linalg.eig(A)
    if np.linalg.cond(vectors) > _EIGENVECTOR_CONDITION_LIMIT:
        raise InputError(f"the {what} is not diagonalisable (repeated eigenvalues with one eigenvector)")
    return values, vectors


def discrete_to_continuous(Ad: Any, Bd: Any, Cd: Any, Dd: Any, dt: float, *, hold: str = "foh"
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the continuous model whose hold equivalent is ``(Ad, Bd, Cd, Dd)``.

    The inverse of :func:`continuous_to_discrete`.

    ``Ad`` (diagonalisable) is first brought to real block-diagonal form by
    its eigenvectors; each block is then mapped by the principal logarithm
    (``mu = |mu| e^{j theta}`` becomes ``sigma = ln|mu| / dt``,
    ``omega = theta / dt``), ``B`` follows from the hold's input matrix and,
    for ``foh``, ``D = Dd - C G2``. The continuous A is returned in that
    real block-diagonal basis (complex pairs first), so that its eigenvalues
    are as accurate as those of ``Ad``: a companion-form ``Ad`` (an ARX
    realisation) has badly conditioned eigenvectors, and a round trip
    through them would square that conditioning.

    Parameters
    ----------
    Ad, Bd, Cd, Dd : array_like
        Discrete model, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    dt : float
        Sample interval (s).
    hold : {"foh", "zoh"}, default "foh"
        The hold the discrete model is the equivalent of.

    Returns
    -------
    tuple of ndarray
        ``(A, B, C, D)``, continuous time, A in real block-diagonal form.

    Raises
    ------
    InputError
        A discrete eigenvalue on the closed negative real axis (no real
        continuous equivalent) or a non-diagonalisable ``Ad``.
    """
    Ad, Bd, Cd, Dd = _system(Ad, Bd, Cd, Dd)
    _check_hold(hold, dt)
    values, vectors = _diagonalise(Ad, "discrete system matrix")
    on_axis = (np.abs(values.imag) <= _COMPLEX_TOLERANCE * np.abs(values)) & (values.real <= 0)
    if np.any(on_axis):
        raise InputError(
            f"the discrete model has an eigenvalue {values[on_axis][0].real:.4g} on the negative real axis "
            "(or zero): it has no continuous-time equivalent"
        )
    logs = np.log(values.astype(complex)) / dt
    basis, A = _real_block_form(logs, vectors)
    Bd = np.linalg.solve(basis, Bd)
    Cd = Cd @ basis
    phi, phi1, phi2 = _phi_matrices(A, dt)
    if hold == "zoh":
        B = np.linalg.solve(dt * phi1, Bd)
        return A, B, Cd, Dd.copy()
    B = np.linalg.solve(dt * ((phi1 - phi2) + phi @ phi2), Bd)
    return A, B, Cd, Dd - Cd @ (dt * phi2 @ B)


def _split_modes(values: np.ndarray) -> tuple[list[int], list[int]]:
    """Indices of one eigenvalue per complex pair (positive imaginary part) and of the real ones, sorted by |lambda|."""
    scale = np.maximum(np.abs(values), 1e-300)
    complex_mask = np.abs(values.imag) > _COMPLEX_TOLERANCE * scale
    pairs = [i for i in np.argsort(np.abs(values)) if complex_mask[i] and values[i].imag > 0]
    real = [i for i in np.argsort(np.abs(values)) if not complex_mask[i]]
    if 2 * len(pairs) + len(real) != values.size:
        raise InputError("complex eigenvalues do not come in conjugate pairs")
    return pairs, real


def _real_block_form(values: np.ndarray, vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real basis ``[Re v, Im v, ..., v_real]`` (pairs first) and the block-diagonal matrix in it.

    For ``lambda = sigma + j omega`` (omega > 0) with eigenvector ``v``, the
    columns ``Re v, Im v`` carry the block ``[[sigma, omega], [-omega, sigma]]``.
    """
    n = values.size
    pairs, real = _split_modes(values)
    basis = np.zeros((n, n))
    blocks = np.zeros((n, n))
    for p, index in enumerate(pairs):
        v = vectors[:, index]
        basis[:, 2 * p], basis[:, 2 * p + 1] = v.real, v.imag
        sigma, omega = values[index].real, values[index].imag
        blocks[2 * p: 2 * p + 2, 2 * p: 2 * p + 2] = [[sigma, omega], [-omega, sigma]]
    for r, index in enumerate(real):
        state = 2 * len(pairs) + r
        basis[:, state] = vectors[:, index].real
        blocks[state, state] = values[index].real
    return basis, blocks


def modal_structure_for(A: Any, n_u: int, n_y: int) -> ModalStructure:
    """Return the default modal structure that fits ``A``'s eigenvalues.

    Equals ``ModalStructure.default(n, n_u, n_y)`` when ``A`` has as many
    complex pairs as that structure (``n // 2``); otherwise it has the pairs
    and real poles ``A`` has, tied to the outputs in the same round-robin way.

    Parameters
    ----------
    A : array_like, shape (n, n)
        A system matrix.
    n_u, n_y : int
        Numbers of inputs and outputs.

    Returns
    -------
    ModalStructure
        Pairs first, modes tied to the outputs in turn.
    """
    A = finite_matrix("A", A)
    values = np.linalg.eigvals(A)
    pairs, real = _split_modes(values)
    return ModalStructure.with_modes(len(pairs), len(real), n_u, n_y)


def to_modal(A: Any, B: Any, C: Any, D: Any, structure: ModalStructure | None = None, *,
             meta: dict[str, Any] | None = None) -> ModalModel:
    """Transform a diagonalisable continuous model into the modal form of ``structure``.

    Steps: (1) eigen-decomposition of A; complex pairs first (sorted by
    natural frequency), then real poles (sorted by magnitude), as the
    structure orders its modes; (2) the real basis ``[Re v, Im v]`` of each
    pair's eigenvector ``v`` (for ``lambda = sigma + j omega``, omega > 0),
    in which the pair's block is ``[[sigma, omega], [-omega, sigma]]``;
    (3) per mode a scaling that makes its fixed C entries 1. A real mode tied
    to output i is scaled by its entry ``c``. A pair tied to output i with
    entries ``(c1, c2)`` gets the similarity ``S = [[p, q], [-q, p]]``
    (a rotation and scale, which commutes with the pair's block),
    ``p = (c1 + c2)/2``, ``q = (c2 - c1)/2``, so that ``[c1 c2] S^-1 = [1 1]``.

    Parameters
    ----------
    A, B, C, D : array_like
        Continuous model, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    structure : ModalStructure, optional
        Default :func:`modal_structure_for` (``ModalStructure.default`` when
        the counts of pairs and real poles fit it).
    meta : dict, optional
        Stored in the model.

    Returns
    -------
    ModalModel
        With the same transfer function as ``(A, B, C, D)``.

    Raises
    ------
    InputError
        A is not diagonalisable; its numbers of complex pairs and real poles
        differ from the structure's (a pair cannot hold two distinct real
        poles); or a mode is unobservable from the output it is tied to (its
        entries in that output's row of C are zero: no scaling can make them
        1, so tie the mode to another output with another structure).
    """
    A, B, C, D = _system(A, B, C, D)
    n, n_u, n_y = A.shape[0], B.shape[1], C.shape[0]
    if structure is None:
        structure = modal_structure_for(A, n_u, n_y)
    if (structure.n, structure.n_u, structure.n_y) != (n, n_u, n_y):
        raise InputError(
            f"the structure has n={structure.n}, n_u={structure.n_u}, n_y={structure.n_y}; "
            f"the model has n={n}, n_u={n_u}, n_y={n_y}"
        )
    values, vectors = _diagonalise(A, "model's A matrix")
    pairs, real = _split_modes(values)
    if (len(pairs), len(real)) != (structure.n_complex_pairs, structure.n_real):
        raise InputError(
            f"the model has {len(pairs)} complex pairs and {len(real)} real poles but the structure "
            f"{structure.n_complex_pairs} and {structure.n_real}: use modal_structure_for(A, n_u, n_y)"
        )
    basis, a_modal = _real_block_form(values, vectors)
    b_modal = np.linalg.solve(basis, B)
    c_modal = C @ basis
    size = max(np.abs(c_modal).max(), 1e-300)
    for states in structure.mode_states():
        output = structure.output_of_state(states[0])
        entries = c_modal[output, list(states)]
        if np.all(np.abs(entries) <= 1e-12 * size):
            mode_value = complex(a_modal[states[0], states[0]], a_modal[states[0], states[-1]])
            raise InputError(
                f"the mode with eigenvalue {mode_value:.4g} is unobservable from output {output + 1}, "
                "to which the structure ties it: its C entries there are zero and cannot be scaled to 1"
            )
        if len(states) == 1:
            scale = np.array([[entries[0]]])
        else:
            p_, q_ = (entries[0] + entries[1]) / 2, (entries[1] - entries[0]) / 2
            scale = np.array([[p_, q_], [-q_, p_]])
        idx = list(states)
        b_modal[idx] = scale @ b_modal[idx]
        c_modal[:, idx] = c_modal[:, idx] @ np.linalg.inv(scale)
    for i, j in structure.fixed_c:
        c_modal[i, j] = 1.0  # equal to 1 up to rounding; made exact for the structure's check
    return ModalModel(structure, a_modal, b_modal, c_modal, D, meta=dict(meta or {}))


def _psd_root(gramian: np.ndarray) -> np.ndarray:
    """A factor L with ``L L' = gramian`` from its symmetric eigen-decomposition (negative rounding clipped)."""
    values, vectors = np.linalg.eigh((gramian + gramian.T) / 2)
    return vectors * np.sqrt(np.clip(values, 0.0, None))


def balanced_truncation(Ad: Any, Bd: Any, Cd: Any, Dd: Any, order: int
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reduce a stable discrete model to ``order`` states by balanced truncation.

    Parameters
    ----------
    Ad, Bd, Cd, Dd : array_like
        Stable discrete model, shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    order : int
        Number of states kept, 1 to n.

    Returns
    -------
    tuple of ndarray
        The reduced ``(Ad, Bd, Cd, Dd)`` and all n Hankel singular values, decreasing.

    Raises
    ------
    InputError
        The model is unstable (a Gramian does not exist), has fewer than
        ``order`` controllable and observable states, or ``order`` is out of range.
    """
    import scipy.linalg  # half a second to import: paid where used, not at every command's start
    Ad, Bd, Cd, Dd = _system(Ad, Bd, Cd, Dd)
    n = Ad.shape[0]
    if not 1 <= order <= n:
        raise InputError(f"the reduced order must lie in 1..{n}; got {order}")
    if np.max(np.abs(np.linalg.eigvals(Ad))) >= 1:
        raise InputError("balanced truncation needs a stable discrete model (all |eigenvalues| < 1)")
    wc = scipy.linalg.solve_discrete_lyapunov(Ad, Bd @ Bd.T)
    wo = scipy.linalg.solve_discrete_lyapunov(Ad.T, Cd.T @ Cd)
    lc, lo = _psd_root(wc), _psd_root(wo)  # a non-minimal model has singular Gramians: no Cholesky
    u, s, vt = np.linalg.svd(lo.T @ lc)
    if s[order - 1] <= 1e-12 * s[0]:
        raise InputError(f"the model has fewer than {order} controllable and observable states "
                         f"(Hankel singular values {np.array2string(s[: order + 1], precision=3)})")
    root = np.sqrt(s[:order])
    left = (lo @ u[:, :order]) / root  # T^-1 rows (transposed)
    right = (lc @ vt[:order].T) / root
    return left.T @ Ad @ right, left.T @ Bd, Cd @ right, Dd.copy(), s
