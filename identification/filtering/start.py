"""Start values of the IEKF taken from the data, in units that do not depend on the user's.

Fixed starts in seconds and signal units (the paper's sigma = -1, omega = 1)
fail on records whose time base or signal scale differ from the paper's. The
starts here are computed on the normalised problem (signals divided by their
RMS, time in samples), so relabelling time or rescaling signals gives the
same start up to rounding.

``data``
    The best-simulating (R, eq. 17; where unstable modes are allowed, the
    best-predicting, 10 samples ahead) of the ``band`` start and subspace
    models with 2n, 10 and 25 block rows (PO-MOESP; N4SID's state sequence
    where unstable modes are allowed), converted to continuous time for a
    first-order hold and to the structure's modal form. Where a subspace
    model does not fit the structure, its eigenvalues are placed on the
    structure's modes (:func:`place_eigenvalues`) and B and D fitted by least
    squares (:func:`fit_input_gains`). A subspace model with a lightly
    damped mode beyond the band the input drives (:func:`input_band_edge`,
    with a margin; :func:`lightly_damped_beyond`) fits the record's noise at
    that order and is no candidate; nor is one that fits the structure only
    through a pair made of a real pole beyond that band
    (:func:`reals_made_into_pairs`).
``band``
    Modes spread log-evenly over the record's band, damping 0.5; B and D by
    least squares.

A start needs the dynamics, not all of a long record: both are found on its
first samples only (``_START_BYTES``).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, WorkbenchError
from ..models.modal import ModalModel
from ..models.modal_structure import ModalStructure

__all__ = ["DataStart", "data_start", "band_eigenvalues", "place_eigenvalues", "fit_input_gains", "input_band_edge",
           "lightly_damped_beyond", "reals_made_into_pairs", "DATA_STARTS"]

from vehid.identification.choices import DATA_STARTS  # noqa: E402  (the one definition, light to import)

_BAND_DAMPING = 0.5
# the share of an input's variance above its band's edge (input_band_edge): the handling study's steer holds
# all but 1e-4 of it below 0.31 rad/sample; the public records' edges lie at 0.37 (cascaded tanks) to 3.14
_OUT_OF_BAND_POWER = 1e-4
# a subspace candidate is left out only for a mode beyond this many times the edge: the edge is an estimate,
# and a lightly damped mode just above it may still be told from the little input there (the CD player arm's
# at 1.15 times its edge); the handling records' spurious modes lie at 3.2-3.8 times theirs
_BAND_MARGIN = 2.0
_MAX_RATE = 3.0  # rad/sample: the fastest a discrete model can say (pi) with a margin of rounding
# The start is found on as many first samples as keep the largest subspace start's block-Hankel matrix
# (25 block rows) within this many bytes, at least _START_MIN_SAMPLES: a long record's whole Hankel
# matrix would take gigabytes.
_START_BYTES = 32e6
_START_MIN_SAMPLES = 1000
# data starts remembered (see data_start): a command asks for at most five distinct ones
_REMEMBER = 8
_REMEMBERED: OrderedDict[tuple, DataStart] = OrderedDict()
_REMEMBERED_LOCK = threading.Lock()


@dataclass(frozen=True, eq=False)
class DataStart:
    """A start model on the normalised problem (time in samples) and how it was found.

    Attributes
    ----------
    model : ModalModel
        Continuous-time in units of samples: eigenvalues in rad/sample,
        inputs and outputs divided by their RMS.
    source : str
        ``"subspace"``, ``"subspace eigenvalues"`` or ``"band"``.
    note : str
        Why a fallback was taken (empty when none was).
    """

    model: ModalModel
    source: str
    note: str = ""


def band_eigenvalues(structure: ModalStructure, n_samples: int) -> np.ndarray:
    """One eigenvalue per mode of ``structure`` (rad/sample), spread log-evenly over the record's band.

    From ten periods in the record to a quarter of the Nyquist frequency;
    pairs get damping 0.5, real poles the same magnitudes, negative.
    """
    modes = structure.n_complex_pairs + structure.n_real
    low = min(2 * np.pi * 10 / max(n_samples, 1), 0.05)
    high = np.pi / 4
    rates = np.geomspace(low, high, modes + 2)[1:-1] if modes > 1 else np.array([np.sqrt(low * high)])
    values = []
    for k in range(structure.n_complex_pairs):
        w = rates[k]
        values.append(complex(-_BAND_DAMPING * w, w * np.sqrt(1 - _BAND_DAMPING**2)))
    for k in range(structure.n_real):
        values.append(complex(-rates[structure.n_complex_pairs + k], 0.0))
    return np.array(values)


def _complex_and_real(values: np.ndarray) -> tuple[list[complex], list[float]]:
    """One eigenvalue of each conjugate pair (the upper one) and the real ones, each slowest first: what
    :func:`place_eigenvalues` fills a structure from, and :func:`reals_made_into_pairs` reads."""
    values = np.asarray(values, dtype=complex)
    upper = sorted((v for v in values if v.imag > 1e-9 * abs(v)), key=abs)
    real = sorted((v.real for v in values if abs(v.imag) <= 1e-9 * abs(v)), key=abs)
    return upper, real


def place_eigenvalues(values: np.ndarray, structure: ModalStructure, *, stable: bool = True) -> np.ndarray:
    """Map a model's eigenvalues onto the structure's modes: one per mode, pairs first.

    Complex eigenvalues (one of each conjugate pair) fill the structure's
    pairs, slowest first; left-over pairs are made from two real poles
    (their mean as sigma, half their distance, at least a tenth of the mean,
    as omega); real eigenvalues, then left-over complex ones (by their
    magnitude), fill the real poles. With ``stable`` every real part is made
    negative (reflected).
    """
    upper, real = _complex_and_real(values)
    pairs: list[complex] = []
    while len(pairs) < structure.n_complex_pairs and upper:
        pairs.append(upper.pop(0))
    while len(pairs) < structure.n_complex_pairs and len(real) >= 2:
        a, b = real.pop(0), real.pop(0)
        sigma = 0.5 * (a + b)
        pairs.append(complex(sigma, max(0.5 * abs(a - b), 0.1 * abs(sigma))))
    while len(pairs) < structure.n_complex_pairs:  # not enough eigenvalues at all: repeat the slowest, spread
        base = pairs[-1] if pairs else complex(-0.01, 0.01)
        pairs.append(complex(base.real, abs(base.imag) * 1.5 + 1e-3))
    poles = list(real)
    for v in upper:
        poles.append(-abs(v) if v.real <= 0 else abs(v))
    poles = poles[: structure.n_real]
    while len(poles) < structure.n_real:
        poles.append(-(abs(poles[-1]) * 1.5 if poles else 0.01))
    placed = np.array(pairs + [complex(p, 0.0) for p in poles])
    if stable:
        bad = placed.real >= 0
        placed[bad] = -np.maximum(np.abs(placed[bad].real), 1e-4 * np.abs(placed[bad])) + 1j * placed[bad].imag
    return placed


def input_band_edge(u: np.ndarray) -> float:
    """The highest frequency (rad/sample) at which the inputs drive the plant: below it each input holds
    all but :data:`_OUT_OF_BAND_POWER` of its variance (the largest over the inputs that vary; an input
    held constant drives nothing and bounds nothing). Pi where no input varies, or where the record is
    too short or not finite to tell."""
    u = np.asarray(u, dtype=float)
    if u.shape[0] < 3:
        return float(np.pi)
    # a record's ends are not those of a period: tapered, the leak of its power to high frequencies falls
    # below the share counted (a sine of 0.2 rad/sample over 4000 samples: edge 1.44 untapered, 0.21 tapered)
    taper = np.hanning(u.shape[0])
    edge = None
    for column in (u - u.mean(axis=0)).T:
        power = np.abs(np.fft.rfft(taper * column)) ** 2
        total = power.sum()
        if not np.isfinite(total):
            return float(np.pi)
        if total <= 0:
            continue
        below = np.cumsum(power) / total
        found = float(np.pi * np.searchsorted(below, 1.0 - _OUT_OF_BAND_POWER) / (power.size - 1))
        edge = found if edge is None else max(edge, found)
    return float(np.pi) if edge is None else min(edge, float(np.pi))


def lightly_damped_beyond(values: np.ndarray, limit: float) -> int:
    """How many lightly damped modes (a conjugate pair counts once) of ``values`` (rad/sample) lie beyond
    ``limit``: damped less than the band start (:data:`_BAND_DAMPING`) and faster than ``limit``.

    The data start's limit is :data:`_BAND_MARGIN` times the input's band edge
    (:func:`input_band_edge`). The input hardly drives a mode beyond it, so the record cannot tell its
    frequency or gain, and a subspace model with such a mode has fitted a resonance of the noise: on the
    handling study's noisy records damping 0.006 at three times the steer's band edge, where the true
    modes within the band were merged into fewer. A filter started there could not leave it: it diverged
    (n = 6), rang on the validation record (n = 7, up to 88 points of hold-out fit lost) or, with the
    mode moved into the band, kept the merged modes (n = 5, ``benchmarks/noisy_handling.py``).
    """
    values = np.asarray(values, dtype=complex)
    magnitude = np.abs(values)
    damping = -values.real / np.maximum(magnitude, np.finfo(float).tiny)  # 0 at the origin, which no limit counts
    beyond = (magnitude > limit) & (damping < _BAND_DAMPING)
    return int(np.sum(beyond & (values.imag >= 0)))


class _NoiseModes(WorkbenchError):
    """A subspace candidate fitted to noise beyond the input's band: lightly damped modes there
    (:func:`lightly_damped_beyond`), or a real pole there that the structure would make into a pair
    (:func:`reals_made_into_pairs`)."""


def reals_made_into_pairs(values: np.ndarray, structure: ModalStructure) -> np.ndarray:
    """The real eigenvalues of ``values`` that :func:`place_eigenvalues` makes into ``structure``'s
    left-over complex pairs (two per pair, slowest first; empty where the complex ones fill its pairs)."""
    upper, real = _complex_and_real(values)
    made = min(max(structure.n_complex_pairs - len(upper), 0), len(real) // 2)
    return np.array(real[: 2 * made])


def _modal_matrix(structure: ModalStructure, modes: np.ndarray) -> np.ndarray:
    theta = np.zeros(structure.n_parameters)
    for k in range(structure.n_complex_pairs):
        theta[2 * k], theta[2 * k + 1] = modes[k].real, abs(modes[k].imag)
    for k in range(structure.n_real):
        theta[2 * structure.n_complex_pairs + k] = modes[structure.n_complex_pairs + k].real
    return theta


def fit_input_gains(structure: ModalStructure, modes: np.ndarray, u: np.ndarray, y: np.ndarray) -> ModalModel:
    """The model with these modes (rad/sample) whose B and D fit ``y`` best, the free C entries zero.

    ``y`` is linear in B and D once the modes and C are fixed: one
    simulation per B entry gives its regressor (time in samples, inputs
    linear between samples).
    """
    theta = _modal_matrix(structure, modes)
    slices = structure.slices()
    n, n_u, n_y = structure.n, structure.n_u, structure.n_y
    columns = []
    for k in range(n * n_u):
        trial = theta.copy()
        trial[slices["B"].start + k] = 1.0
        with np.errstate(over="ignore", invalid="ignore"):
            columns.append(ModalModel.from_parameters(structure, trial).simulate_outputs(u, 1.0).ravel())
    for i in range(n_y):
        for j in range(n_u):
            column = np.zeros_like(y)
            column[:, i] = u[:, j]
            columns.append(column.ravel())
    regressors = np.column_stack(columns)
    if not np.all(np.isfinite(regressors)):
        return ModalModel.from_parameters(structure, theta)
    solution = np.linalg.lstsq(regressors, y.ravel(), rcond=None)[0]
    theta[slices["B"]] = solution[: n * n_u]
    theta[slices["D"]] = solution[n * n_u:]
    return ModalModel.from_parameters(structure, theta)


def _simulation_fit(model: ModalModel, u: np.ndarray, y: np.ndarray) -> float:
    """Mean R (eq. 17) of the model simulated from rest (time in samples); -inf where it overflows."""
    from ..assessment.metrics import percentage_explanation

    with np.errstate(all="ignore"):
        simulated = model.simulate_outputs(u, 1.0)
        if not np.all(np.isfinite(simulated)):
            return -np.inf
        return float(np.mean(percentage_explanation(y, simulated)))


def _prediction_fit(model: ModalModel, u: np.ndarray, y: np.ndarray) -> float:
    """Mean R (eq. 17) of the model's k-step prediction (time in samples); -inf where it overflows.

    The candidates of a start that may be unstable are ranked by the score an unstable model's
    validation uses. Simulated, even from the least-squares initial state, a growing mode's drift
    decides the fit: on the ball and beam (order 4) the start so chosen scored 82.2-84.4 % over held-out
    fractions 0.3-0.4, and 83.1-85.1 % ranked by prediction.
    """
    from ..data import IOData
    from ..assessment.validation import UNSTABLE_HORIZON, score

    with np.errstate(all="ignore"):
        try:
            fit = score(model, IOData(t=np.arange(u.shape[0], dtype=float), u=u, y=y), horizon=UNSTABLE_HORIZON).fit
        except (WorkbenchError, np.linalg.LinAlgError):
            return -np.inf
    return float(np.mean(fit)) if np.all(np.isfinite(fit)) else -np.inf


def _subspace_start(u: np.ndarray, y: np.ndarray, structure: ModalStructure, stable: bool,
                    block_rows: int | None = None, free_modes: bool = False,
                    band_edge: float | None = None) -> DataStart:
    """One subspace candidate of the data start; ``band_edge`` is :func:`input_band_edge` of ``u``
    (computed where not given: the candidates of one record share it).

    Raises :class:`_NoiseModes` for a model with lightly damped modes beyond :data:`_BAND_MARGIN` times
    the edge, and for one whose eigenvalues fit the structure only through a pair made of a real pole
    beyond the edge (:func:`reals_made_into_pairs`): the pair's frequency would be set by a pole the input
    does not drive. On the handling study's noisy records at n = 4 that pole is the noise's (a sign flip
    every sample, or a real pole at twice the edge); the pair placed between it and a true slow pole
    started the filter 20-40 times too fast, and it lost up to 6.7 points of hold-out fit where the band
    start lost under one (``benchmarks/noisy_handling.py``).
    """
    from ..models.statespace import discrete_to_continuous, to_modal
    from ..classical.subspace import estimate_subspace, estimate_subspace_states

    # PO-MOESP fits B and D to simulated outputs, which a growing mode swamps even in short segments;
    # where unstable modes are allowed the model is validated by prediction, and N4SID's state sequence
    # fits it to one-step equations (on the ball and beam, order 4: hold-out 10-step fit 82-84 % at
    # every held-out fraction 0.3-0.4 against 72-79 %, and 83-85 % ranked by _prediction_fit,
    # docs/measurements.md)
    estimate = estimate_subspace if stable else estimate_subspace_states
    fit = estimate((u, y), order=structure.n, block_rows=block_rows)
    discrete = np.linalg.eigvals(fit.A)
    magnitude = np.maximum(np.abs(discrete), 1e-12)
    negative = (np.abs(discrete.imag) <= 1e-9 * magnitude) & (discrete.real < 0)
    # A negative real discrete pole (a sign flip every sample, mostly noise) has no continuous
    # counterpart; its decay rate alone is kept, as a real pole.
    continuous = np.where(negative, np.log(magnitude).astype(complex), np.log(discrete.astype(complex)))
    if free_modes:
        pairs = int(np.sum(continuous.imag > 1e-9 * np.abs(continuous)))
        structure = ModalStructure.with_modes(pairs, structure.n - 2 * pairs, structure.n_u, structure.n_y)
    edge = input_band_edge(u) if band_edge is None else band_edge
    limit = _BAND_MARGIN * edge
    noise = lightly_damped_beyond(continuous, limit)
    if noise:
        raise _NoiseModes(f"{noise} lightly damped mode{'s' if noise > 1 else ''} beyond the input's band "
                          f"({limit:.3g} rad/sample): a fit of the noise")
    note = ""
    try:
        A, B, C, D = discrete_to_continuous(fit.A, fit.B, fit.C, fit.D, 1.0, hold="foh")
        model = to_modal(A, B, C, D, structure, meta={"start": "subspace"})
        if stable and not model.is_stable():
            note = "the subspace model is unstable"
        elif not np.all(np.abs(model.mode_eigenvalues()) < _MAX_RATE * 10):
            note = "the subspace model has modes beyond the sample rate"
        else:
            return DataStart(model, "subspace")
    except InputError:
        # the conversion's own message advises a library call; the start's note speaks of the model
        pairs = int(np.sum(np.abs(continuous.imag) > 1e-9 * np.abs(continuous))) // 2
        counts = (f" ({pairs} complex pairs and {structure.n - 2 * pairs} real poles where the structure has "
                  f"{structure.n_complex_pairs} and {structure.n_real})"
                  if (pairs, structure.n - 2 * pairs) != (structure.n_complex_pairs, structure.n_real) else "")
        note = f"the subspace model does not fit the structure's modes{counts}"
    merged = reals_made_into_pairs(continuous, structure)
    undriven = merged[np.abs(merged) > edge]
    if undriven.size:
        raise _NoiseModes(f"a pair of the structure would be made of a real pole at {abs(undriven[0]):.3g} "
                          f"rad/sample, beyond the input's band ({edge:.3g} rad/sample)")
    modes = place_eigenvalues(continuous, structure, stable=stable)
    model = fit_input_gains(structure, modes, u, y)
    return DataStart(model, "subspace eigenvalues", note)


def data_start(u: np.ndarray, y: np.ndarray, structure: ModalStructure, *, method: str = "data",
               stable: bool = True, free_modes: bool = False) -> DataStart:
    """A start model for ``structure`` from normalised inputs ``u`` (N, n_u) and outputs ``y`` (N, n_y).

    Parameters
    ----------
    u, y : ndarray
        Inputs and outputs, each divided by its RMS; time is counted in samples.
    structure : ModalStructure
    method : {"data", "band"}
        See the module docstring.
    stable : bool
        Reflect unstable start modes into the left half-plane.
    free_modes : bool
        Let each subspace candidate keep its own numbers of complex pairs and
        real poles (same order, modes tied to outputs as
        :meth:`ModalStructure.with_modes`); the returned model's structure is
        the best candidate's.

    Returns
    -------
    DataStart

    Notes
    -----
    The answers to the last eight distinct problems (the windowed record's
    digest, the structure and the options) are kept and returned again,
    the same immutable object: one `vehid identify` asks for each
    cross-validation fold's start once per candidate p.
    """
    if method not in DATA_STARTS:
        raise InputError(f"unknown data start {method!r}; use one of {', '.join(DATA_STARTS)}")
    largest_rows = max(2 * structure.n, structure.n + 1, 25)
    window = max(int(_START_BYTES / (8 * 2 * largest_rows * (u.shape[1] + y.shape[1]))), _START_MIN_SAMPLES)
    u, y = np.asarray(u[:window], dtype=float), np.asarray(y[:window], dtype=float)
    # a pure function of its arguments, asked for the same record several times by one command (each p
    # of a cross-validation starts from its fold's start): the last few answers are kept, keyed by a
    # digest of the data, and the immutable result is shared
    digest = hashlib.blake2b(digest_size=16)
    for array in (u, y):
        digest.update(repr(array.shape).encode())
        digest.update(np.ascontiguousarray(array).tobytes())
    key = (digest.hexdigest(), structure, method, bool(stable), bool(free_modes))
    with _REMEMBERED_LOCK:
        if key in _REMEMBERED:
            _REMEMBERED.move_to_end(key)
            return _REMEMBERED[key]
    found = _found_start(u, y, structure, method, stable, free_modes)
    with _REMEMBERED_LOCK:
        _REMEMBERED[key] = found
        while len(_REMEMBERED) > _REMEMBER:
            _REMEMBERED.popitem(last=False)
    return found


def _found_start(u: np.ndarray, y: np.ndarray, structure: ModalStructure, method: str, stable: bool,
                 free_modes: bool) -> DataStart:
    """:func:`data_start` on the window of the record it uses."""
    modes = band_eigenvalues(structure, u.shape[0])
    model = fit_input_gains(structure, modes, u, y)
    band = DataStart(model, "band")
    if method == "band":
        return band
    # Subspace models with a few block-row counts (more rows average noise better, fewer suit short
    # records) and the band start: the one that simulates the record best.
    candidates, notes = [band], []
    default_rows = max(2 * structure.n, structure.n + 1)
    edge = input_band_edge(u)
    for rows in sorted({default_rows, max(default_rows, 10), max(default_rows, 25)}):
        try:
            candidates.append(_subspace_start(u, y, structure, stable, block_rows=rows, free_modes=free_modes,
                                              band_edge=edge))
        except _NoiseModes as exc:
            notes.append(f"subspace with {rows} block rows left out ({exc})")
        except (WorkbenchError, np.linalg.LinAlgError) as exc:
            notes.append(f"subspace with {rows} block rows failed ({exc})")
    fits = [_simulation_fit(candidate.model, u, y) if stable else _prediction_fit(candidate.model, u, y)
            for candidate in candidates]
    best = candidates[int(np.argmax(fits))]
    note = "; ".join(filter(None, [best.note, *notes]))
    return DataStart(best.model, best.source, note)
