"""Subspace identification: PO-MOESP (Verhaegen 1994; Verhaegen & Verdult 2007, sec. 9.6), and N4SID's state sequence.

A discrete model ``x(k+1) = A x + B u``, ``y = C x + D u`` of given order is
found in three linear-algebra steps, without iterations:

1. Block Hankel matrices of ``s`` block rows of past and future inputs and
   outputs; the RQ factorisation ``[U_f; U_p; Y_p; Y_f] = L Q'``
   (Verhaegen & Verdult 2007, eq. 9.64). Only ``L`` is formed: QR of the
   transposed data matrix in ``mode="r"``, so memory stays ``O(s N)``.
2. The SVD of ``L_32`` (future outputs against past data, the past
   inputs and outputs acting as instruments) spans the extended
   observability matrix ``O_s`` (eq. 9.66); the first ``order`` left
   singular vectors estimate it. ``C`` is its first block row, ``A`` solves
   the shift equation ``O_s[:-n_y] A = O_s[n_y:]`` (eq. 9.34) by least squares.
3. ``B``, ``D`` and the initial state ``x0`` solve a linear least-squares
   problem on the whole record (sec. 9.2.4.3), the output being linear in
   them once ``A`` and ``C`` are fixed. The regressors come from per-mode
   first-order recursions (``scipy.signal.lfilter``) in the eigenbasis of A.
   Where ``A`` has a mode growing by ``|z| > 1`` per sample (an open-loop
   unstable plant), one simulation over the whole record weights its samples
   by ``|z|^k``: the last few decide B and D, the rest hardly count, and the
   error of the growing mode's state swamps everything. The record is then
   cut into segments over which that mode grows at most e-fold
   (:func:`_segment_length`), each with an initial state of its own: B and D
   are fitted to multi-step predictions over the whole record, as the
   state-sequence methods fit them to one-step ones (Van Overschee & De Moor
   1996, ch. 4), and the problem stays linear.

:func:`estimate_subspace_states` is N4SID's state-sequence form (Van
Overschee & De Moor 1996, sec. 4.3): the oblique projection of the future
outputs along the future inputs onto the past data, its SVD, the state
sequence it implies, and ``[A B; C D]`` by least squares on the one-step
equations between consecutive states. Nothing is simulated, so a growing
mode weighs no sample more than another: it suits a model that will be
validated by prediction, as an open-loop unstable plant's is.

Both run on signals divided column by column by their RMS, and the model
is scaled back (``B / s_u``, ``s_y C``, ``s_y D / s_u``): a channel in
microvolts next to one in kilonewtons would otherwise dominate the SVD and
the regressions, so the model would depend on the units. The eigenvalues
do not change under the scaling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.lib.stride_tricks import sliding_window_view

from ..argument_checks import io_arrays, positive_int
from ..errors import ExcitationError, InputError
from ..models.protocol import StateSpaceModel, sample_interval, unscheduled

__all__ = ["SubspaceResult", "estimate_subspace", "estimate_subspace_states", "largest_subspace_order"]


@dataclass(frozen=True, eq=False)
class SubspaceResult(StateSpaceModel):
    """A discrete state-space model identified by PO-MOESP.

    Attributes
    ----------
    A, B, C, D : ndarray
        Shapes (n, n), (n, n_u), (n_y, n), (n_y, n_u).
    x0 : ndarray, shape (n,)
        Initial state estimated with B and D (of the first segment where an
        unstable A cuts the record, module docstring).
    singular_values : ndarray
        Of ``L_32`` of the RMS-scaled signals: a gap after the ``order``-th
        suggests the order.
    residuals : ndarray, shape (N, n_y)
        Measured minus simulated outputs (from x0; from each segment's
        initial state where an unstable A cuts the record).
    block_rows : int
        The block rows s of the Hankel matrices used.
    dt : float or None
        Sample interval (s), if known.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    x0: np.ndarray
    singular_values: np.ndarray
    residuals: np.ndarray
    block_rows: int
    dt: float | None

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
        """Return the discrete state-space form.

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
        return self.A, self.B, self.C, self.D, sample_interval(self.dt, "subspace model")


def _default_block_rows(order: int) -> int:
    return max(2 * order, order + 1)


def _hankel_fits(lengths: list[int], block_rows: int, n_u: int, n_y: int) -> bool:
    """Whether records of these lengths give the data matrix of ``block_rows`` at least as many columns as rows.

    Each record contributes ``N_k - 2 s + 1`` columns (none spans two
    records); the matrix ``[U_f; U_p; Y_p; Y_f]`` has ``2 s (n_u + n_y)``
    rows, and its RQ factor spans the row space only with as many columns.
    """
    counts = [length - 2 * block_rows + 1 for length in lengths]
    return min(counts) >= 1 and sum(counts) >= 2 * block_rows * (n_u + n_y)


def largest_subspace_order(lengths: int | list[int], n_u: int, n_y: int) -> int:
    """The largest order :func:`estimate_subspace` can identify from records of these lengths (default block rows).

    With ``s = 2 n`` block rows, one record of ``N`` samples must satisfy
    ``N - 4 n + 1 >= 4 n (n_u + n_y)``, i.e. ``n <= (N + 1) / (4 (1 + n_u + n_y))``;
    several records pool their Hankel columns.

    Parameters
    ----------
    lengths : int or list of int
        Samples of each record.
    n_u, n_y : int
        Numbers of inputs and outputs.

    Returns
    -------
    int
        The largest order, 0 when the records are too short for any.
    """
    lengths = [int(lengths)] if np.isscalar(lengths) else [int(length) for length in lengths]
    order = 0
    while _hankel_fits(lengths, _default_block_rows(order + 1), n_u, n_y):
        order += 1
    return order


def _hankel(signal: np.ndarray, rows: int, columns: int) -> np.ndarray:
    """Block Hankel matrix: block row i holds ``signal[i : i + columns]`` transposed."""
    windows = sliding_window_view(signal, rows, axis=0)[:columns]  # (columns, n_sig, rows)
    return windows.transpose(2, 1, 0).reshape(rows * signal.shape[1], columns)


def _responses(A: np.ndarray, C: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Output regressors of x0 and of each B entry: shapes (N, n_y, n) and (N, n_y, n, n_u)."""
    from scipy.signal import lfilter  # a second to import: paid on first use

    values, vectors = np.linalg.eig(A)
    if np.linalg.cond(vectors) > 1e12:
        raise InputError("the identified A is not diagonalisable: B and D cannot be estimated this way")
    inverse = np.linalg.inv(vectors)
    cv = C @ vectors  # (n_y, n)
    n, n_u, samples = A.shape[0], u.shape[1], u.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable A may overflow: refused below
        powers = values[None, :] ** np.arange(samples)[:, None]  # (N, n) modal free responses
        free = np.einsum("yl,kl,li->kyi", cv, powers, inverse).real
        forced = np.zeros((samples, C.shape[0], n, n_u))
        for mode in range(n):
            for j in range(n_u):
                w = np.zeros(samples, dtype=complex)
                w[1:] = lfilter([1.0], [1.0, -values[mode]], u[:-1, j].astype(complex))
                forced[:, :, :, j] += np.einsum("y,i,k->kyi", cv[:, mode], inverse[mode], w).real
    if not (np.all(np.isfinite(free)) and np.all(np.isfinite(forced))):
        # never hand LAPACK non-finite numbers: besides a wrong answer it prints to standard output
        raise InputError(f"the identified A has a mode growing by {np.max(np.abs(values)):.4g} per sample: its "
                         "responses over the record overflow, so B and D cannot be estimated (try another order)")
    return free, forced


def _scaled_experiments(data_or_arrays: Any, order: int, block_rows: int | None
                        ) -> tuple[list[tuple[np.ndarray, np.ndarray, Any]], np.ndarray, np.ndarray, int, int]:
    """The experiments of either estimator divided by their RMS (module docstring), the scales, the order
    and the block rows, with the problem's size checked: ``(experiments, input_scale, output_scale, n, s)``."""
    experiments = [io_arrays(item) for item in data_or_arrays] if isinstance(data_or_arrays, list) \
        else [io_arrays(data_or_arrays)]
    input_scale = _column_rms([e[0] for e in experiments])
    output_scale = _column_rms([e[1] for e in experiments])
    experiments = [(u_e / input_scale, y_e / output_scale, dt_e) for u_e, y_e, dt_e in experiments]
    n = positive_int(order, "order")
    s = _default_block_rows(n) if block_rows is None else positive_int(block_rows, "block_rows")
    n_u, n_y = experiments[0][0].shape[1], experiments[0][1].shape[1]
    if s * n_y < n:
        raise InputError(f"block_rows={s} with {n_y} outputs cannot reveal {n} states (need s * n_y >= order)")
    if not _hankel_fits([e[0].shape[0] for e in experiments], s, n_u, n_y):
        samples = sum(e[0].shape[0] for e in experiments)
        raise InputError(f"{samples} samples are too few for {s} block rows: fewer columns than rows in the data matrix")
    return experiments, input_scale, output_scale, n, s


def estimate_subspace(data_or_arrays: Any, *, order: int, block_rows: int | None = None,
                      estimate_x0: bool = True) -> SubspaceResult:
    """Identify a discrete state-space model of ``order`` states by PO-MOESP.

    Parameters
    ----------
    data_or_arrays : IOData, (u, y), or a list of them
        Time-major inputs (N, n_u) and outputs (N, n_y). A list holds several
        experiments: their Hankel columns are joined (no column spans two
        records), and B, D are estimated with one initial state per
        experiment (``x0`` is the first one's; ``residuals`` are stacked).
    order : int
        Number of states n.
    block_rows : int, optional
        Block rows s of the Hankel matrices, > order / n_y; default
        ``max(2 order, order + 1)``.
    estimate_x0 : bool
        Estimate the initial state with B and D (else x0 = 0).

    Returns
    -------
    SubspaceResult
        The model, its initial state, the singular values and the residuals.

    Raises
    ------
    InputError
        Bad orders, too short a record, non-finite data.
    ExcitationError
        The data do not reveal ``order`` states (rank-deficient ``L_32``)
        or do not determine B and D.
    """
    experiments, input_scale, output_scale, n, s = _scaled_experiments(data_or_arrays, order, block_rows)
    u, y, dt = experiments[0]
    n_u, n_y = u.shape[1], y.shape[1]
    counts = [e[0].shape[0] - 2 * s + 1 for e in experiments]
    su, sy = s * n_u, s * n_y
    blocks = []
    for (u_e, y_e, _), columns in zip(experiments, counts):
        u_h = _hankel(u_e, 2 * s, columns)
        y_h = _hankel(y_e, 2 * s, columns)
        blocks.append(np.vstack([u_h[su:], u_h[:su], y_h[:sy], y_h[sy:]]))  # U_f, U_p, Y_p, Y_f
    stacked = blocks[0] if len(blocks) == 1 else np.hstack(blocks)
    del blocks
    lower = scipy.linalg.qr(stacked.T, mode="r", overwrite_a=True)[0][: stacked.shape[0]].T
    start = su
    stop = 2 * su + sy
    l32 = lower[stop:, start:stop]
    left, singular, _ = np.linalg.svd(l32, full_matrices=False)
    if singular.size < n or singular[n - 1] <= 1e-12 * singular[0]:
        raise ExcitationError(
            f"the data reveal fewer than {n} states (singular values of L32: "
            f"{np.array2string(singular[: n + 1], precision=3)}): lower the order or excite more"
        )
    observability = left[:, :n] * np.sqrt(singular[:n])
    C = observability[:n_y]
    A = np.linalg.lstsq(observability[:-n_y], observability[n_y:], rcond=None)[0]
    length = _segment_length(A, s, n) if estimate_x0 else None
    segments = [(u_e[a:b], y_e[a:b]) for u_e, y_e, _ in experiments for a, b in _segments(u_e.shape[0], length)]
    # Each segment's initial state enters only its own rows: it is eliminated segment by segment (the
    # segment's free responses projected out of its regressors and outputs), and B, D solve the
    # projected problem. That is the minimiser of the whole regression, whose dense solve costs
    # O(N (n segments)^2): seconds for the hundreds of segments a fast-growing mode asks for.
    projected, targets, first_state = [], [], None
    for u_e, y_e in segments:
        samples = u_e.shape[0]
        free, forced = _responses(A, C, u_e)
        d_columns = np.zeros((samples, n_y, n_y * n_u))
        for i in range(n_y):
            d_columns[:, i, i * n_u:(i + 1) * n_u] = u_e
        shared = np.hstack([forced.reshape(samples * n_y, n * n_u), d_columns.reshape(samples * n_y, n_y * n_u)])
        target = y_e.reshape(-1)
        if estimate_x0:
            basis, triangle = np.linalg.qr(free.reshape(samples * n_y, n))
            diagonal = np.abs(np.diag(triangle))
            if diagonal.min() <= np.finfo(float).eps * max(basis.shape) * diagonal.max():
                raise ExcitationError("the input does not determine B and D (rank-deficient regression)")
            on_shared, on_target = basis.T @ shared, basis.T @ target
            if first_state is None:  # what the first segment's initial state is solved from, below
                first_state = (triangle, on_shared, on_target)
            shared = shared - basis @ on_shared
            target = target - basis @ on_target
        projected.append(shared)
        targets.append(target)
    regressors = projected[0] if len(projected) == 1 else np.vstack(projected)
    target = targets[0] if len(targets) == 1 else np.concatenate(targets)
    del projected, targets
    solution, _, rank, _ = np.linalg.lstsq(regressors, target, rcond=None)
    if rank < regressors.shape[1]:
        raise ExcitationError("the input does not determine B and D (rank-deficient regression)")
    B = solution[: n * n_u].reshape(n, n_u)
    D = solution[n * n_u:].reshape(n_y, n_u)
    x0 = np.zeros(n)
    if first_state is not None:  # the first segment's free responses fitted to what B and D leave
        triangle, on_shared, on_target = first_state
        x0 = scipy.linalg.solve_triangular(triangle, on_target - on_shared @ solution)
    # each segment's residual at its best initial state is the projected one
    residuals = (target - regressors @ solution).reshape(-1, n_y) * output_scale
    return SubspaceResult(A, B / input_scale, output_scale[:, None] * C,
                          output_scale[:, None] * D / input_scale, x0, singular, residuals, s, dt)


def estimate_subspace_states(data_or_arrays: Any, *, order: int, block_rows: int | None = None) -> SubspaceResult:
    """Identify a discrete state-space model of ``order`` states by N4SID's state sequence.

    Parameters
    ----------
    data_or_arrays : IOData, (u, y), or a list of them
        Time-major inputs (N, n_u) and outputs (N, n_y); a list holds several
        experiments, whose Hankel columns are joined and whose state
        sequences are regressed together (no pair of states spans two).
    order : int
        Number of states n.
    block_rows : int, optional
        Block rows s of the past and of the future, > order / n_y; default
        ``max(2 order, order + 1)``.

    Returns
    -------
    SubspaceResult
        ``singular_values`` are the oblique projection's; ``x0`` fits the
        first experiment's first ``max(2 s, 10 n)`` samples by least squares
        (zero where A is not diagonalisable); ``residuals`` are the output
        equation's one-step residuals, from sample s of each experiment on.

    Raises
    ------
    InputError
        Bad orders, too short a record, non-finite data.
    ExcitationError
        The data do not reveal ``order`` states, or the states and inputs do
        not determine the model.

    Notes
    -----
    With ``W_p`` the past inputs and outputs, the future outputs are
    regressed on the future inputs and ``W_p``; the part explained by
    ``W_p`` is the oblique projection ``O``. Its first ``order`` singular
    triplets give ``O ~ Gamma X``, ``Gamma = U_n S_n^(1/2)`` and the states
    ``X = Gamma^+ O``; ``[x(k+1); y(k)] = [A B; C D] [x(k); u(k)]`` is then
    solved by least squares (Van Overschee & De Moor 1996, sec. 4.3.1).
    """
    experiments, input_scale, output_scale, n, s = _scaled_experiments(data_or_arrays, order, block_rows)
    n_u, n_y = experiments[0][0].shape[1], experiments[0][1].shape[1]
    counts = [e[0].shape[0] - 2 * s + 1 for e in experiments]
    su, sy = s * n_u, s * n_y
    future_inputs, past, future_outputs = [], [], []
    for (u_e, y_e, _), columns in zip(experiments, counts):
        u_h, y_h = _hankel(u_e, 2 * s, columns), _hankel(y_e, 2 * s, columns)
        future_inputs.append(u_h[su:])
        past.append(np.vstack([u_h[:su], y_h[:sy]]))
        future_outputs.append(y_h[sy:])
    U_f, W_p, Y_f = (np.hstack(blocks) for blocks in (future_inputs, past, future_outputs))
    coefficients = np.linalg.lstsq(np.vstack([U_f, W_p]).T, Y_f.T, rcond=None)[0].T
    projection = coefficients[:, su:] @ W_p
    left, singular, _ = np.linalg.svd(projection, full_matrices=False)
    if singular.size < n or singular[n - 1] <= 1e-12 * singular[0]:
        raise ExcitationError(
            f"the data reveal fewer than {n} states (singular values of the oblique projection: "
            f"{np.array2string(singular[: n + 1], precision=3)}): lower the order or excite more")
    gamma = left[:, :n] * np.sqrt(singular[:n])
    states = np.linalg.pinv(gamma) @ projection  # x(k) for k = s .. s + columns - 1 of each experiment
    regressors, targets, offset = [], [], 0
    for (u_e, y_e, _), columns in zip(experiments, counts):
        x_e = states[:, offset: offset + columns]
        offset += columns
        u_k, y_k = u_e[s: s + columns].T, y_e[s: s + columns].T
        regressors.append(np.vstack([x_e[:, :-1], u_k[:, :-1]]))
        targets.append(np.vstack([x_e[:, 1:], y_k[:, :-1]]))
    regressor, target = np.hstack(regressors), np.hstack(targets)
    solution, _, rank, _ = np.linalg.lstsq(regressor.T, target.T, rcond=None)
    if rank < regressor.shape[0]:
        raise ExcitationError("the states and inputs do not determine the model (rank-deficient regression)")
    system = solution.T
    A, B, C, D = system[:n, :n], system[:n, n:], system[n:, :n], system[n:, n:]
    residuals = np.vstack([(y_e[s: s + columns] - states[:, first: first + columns].T @ C.T
                            - u_e[s: s + columns] @ D.T)
                           for (u_e, y_e, _), columns, first in zip(experiments, counts,
                                                                    np.cumsum([0, *counts[:-1]]))])
    u_0, y_0, _ = experiments[0]
    head = min(u_0.shape[0], max(2 * s, 10 * n))
    x0 = np.zeros(n)
    try:
        free, forced = _responses(A, C, u_0[:head])
        simulated = np.einsum("kyij,ij->ky", forced, B) + u_0[:head] @ D.T
        x0 = np.linalg.lstsq(free.reshape(head * n_y, n), (y_0[:head] - simulated).reshape(-1), rcond=None)[0]
    except InputError:  # not diagonalisable, or overflowing: the state sequence is the estimate, x0 a courtesy
        pass
    return SubspaceResult(A, B / input_scale, output_scale[:, None] * C, output_scale[:, None] * D / input_scale,
                          x0, singular, residuals * output_scale, s, experiments[0][2])


def _segment_length(A: np.ndarray, block_rows: int, order: int) -> int | None:
    """Samples over which A's fastest growing mode grows e-fold (None where no mode grows).

    At least ``max(2 block_rows, 10 order)`` samples, so that each segment's
    initial state is well determined by its own outputs.
    """
    growth = float(np.log(max(np.max(np.abs(np.linalg.eigvals(A))), 1e-300)))
    if growth <= 0:
        return None
    return max(int(np.ceil(1.0 / growth)), 2 * block_rows, 10 * order)


def _segments(samples: int, length: int | None) -> list[tuple[int, int]]:
    """``(start, stop)`` of consecutive segments of ``length`` samples; the last takes a short remainder."""
    if length is None or length >= samples:
        return [(0, samples)]
    starts = list(range(0, samples, length))
    if samples - starts[-1] < length // 2:
        starts.pop()
    return [(a, b) for a, b in zip(starts, starts[1:] + [samples])]


def _column_rms(signals: list[np.ndarray]) -> np.ndarray:
    """RMS of each column over all experiments; 1 for an all-zero column (nothing to scale)."""
    rms = np.sqrt(np.mean(np.vstack(signals) ** 2, axis=0))
    return np.where(rms > 0, rms, 1.0)
