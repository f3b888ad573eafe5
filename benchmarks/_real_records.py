"""The public measured records under ``tests/data/`` and how the real-data benchmark scores models on them.

This module needs only NumPy and SciPy, so the benchmark, the peer libraries'
runner (in its own virtual environment) and the tests read the records and
score the models with the same code.

Every record is read from its file exactly as published. The split is the
same for every method and the same as ``vehid identify --validation
HOLDOUT``'s: the first ``round((1 - HOLDOUT) N)`` samples of a record
estimate, the rest validates (the cascaded tanks come with their own
estimation and validation records, which are used as published).

Offsets, as ``vehid identify`` removes them by default: the estimation
part's means, from both parts of a split record; a separate validation
record (``--validation-file``) is another experiment and has its own means
removed (``validation_offsets``).

The score is MATLAB ``compare``'s NRMSE fit per output on the validation
samples, ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``, with ``yhat`` simulated
from the validation input alone (no measured output fed back), starting from
the least-squares initial state: the state that best explains the validation
output given the input (``compare``'s default). Nonlinear ARX models start
from the first measured outputs of the validation record instead, which is
the same information for a model whose state is its past outputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

DATA_DIRECTORY = Path(__file__).resolve().parent.parent / "tests" / "data"
HOLDOUT = 0.3  # last 30 % of a single record validates


@dataclass(frozen=True)
class RecordSet:
    """One public record: its file, which columns are inputs and outputs, its sample interval."""

    name: str
    path: str  # relative to tests/data
    inputs: tuple[str, ...]  # column names, as `vehid identify --inputs` takes them (a headerless .dat: 1-based numbers)
    outputs: tuple[str, ...]
    dt: float
    dt_note: str
    # inputs and outputs of a separate validation record in the same file, where the publisher split the data
    validation_path_columns: tuple[tuple[str, ...], tuple[str, ...]] | None = None
    nonlinear: bool = False

    @property
    def file(self) -> Path:
        return DATA_DIRECTORY / self.path


RECORD_SETS: tuple[RecordSet, ...] = (
    RecordSet("ballbeam", "ballbeam/ballbeam.dat", ("1",), ("2",), 0.1, "published"),
    RecordSet("dryer", "dryer/dryer.dat", ("1",), ("2",), 0.08, "Ljung's hair-dryer record (not stated in DaISy)"),
    RecordSet("robot_arm", "robot_arm/robot_arm.dat", ("1",), ("2",), 1.0, "not published: time in samples"),
    RecordSet("exchanger", "exchanger/exchanger.dat", ("2",), ("3",), 1.0, "published", nonlinear=True),
    RecordSet("cd_player_arm", "cd_player_arm/CD_player_arm.dat", ("1", "2"), ("3", "4"), 1.0,
              "not published: time in samples"),
    RecordSet("cascaded_tanks", "cascaded_tanks/dataBenchmark.mat", ("uEst",), ("yEst",), 4.0, "published",
              validation_path_columns=(("uVal",), ("yVal",)), nonlinear=True),
)


def record_set(name: str) -> RecordSet:
    for entry in RECORD_SETS:
        if entry.name == name:
            return entry
    raise KeyError(f"no record set {name!r}; known: {', '.join(s.name for s in RECORD_SETS)}")


def _columns(path: Path) -> dict[str, np.ndarray]:
    """Every column of a raw file by name: DaISy .dat columns are numbered from 1."""
    if path.suffix == ".mat":
        from scipy.io import loadmat

        return {k: np.asarray(v, dtype=float).ravel() for k, v in loadmat(path).items() if not k.startswith("__")}
    table = np.loadtxt(path, ndmin=2)
    return {str(i + 1): table[:, i] for i in range(table.shape[1])}


def load(entry: RecordSet, holdout: float = HOLDOUT, file: Path | None = None
         ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """``(u_est, y_est), (u_val, y_val)``, each time-major (N, n), raw values.

    ``holdout`` is the fraction of a single record held out (a separately
    published validation record ignores it); ``file`` reads a copy of the
    record (``perturbed_copy``) in place of the published one.
    """
    columns = _columns(entry.file if file is None else file)
    u = np.column_stack([columns[c] for c in entry.inputs])
    y = np.column_stack([columns[c] for c in entry.outputs])
    if entry.validation_path_columns is not None:
        val_in, val_out = entry.validation_path_columns
        return (u, y), (np.column_stack([columns[c] for c in val_in]), np.column_stack([columns[c] for c in val_out]))
    n_est = split_index(len(u), holdout)
    return (u[:n_est], y[:n_est]), (u[n_est:], y[n_est:])


def split_index(n_samples: int, holdout: float = HOLDOUT) -> int:
    """First validation sample of a single record: the last ``holdout`` of it is held out (as ``IOData.split``)."""
    return int(round((1.0 - holdout) * n_samples))


def perturbed_copy(entry: RecordSet, directory: Path, relative: float, seed: int) -> Path:
    """A copy of the record's file with every number multiplied by ``1 + relative * N(0, 1)``, in ``directory``.

    The copy keeps the file's format and variable names, so ``vehid identify``
    reads it with the same options as the published file. Numbers are
    written with 17 significant digits: the copy differs from the original by
    the perturbation alone, not by rounding in the text.
    """
    rng = np.random.default_rng(seed)
    target = Path(directory) / f"{entry.name}-perturbed-{relative:g}-seed{seed}{entry.file.suffix}"
    if entry.file.suffix == ".mat":
        from scipy.io import loadmat, savemat

        variables = {k: np.asarray(v, dtype=float) for k, v in loadmat(entry.file).items() if not k.startswith("__")}
        savemat(target, {k: v * (1.0 + relative * rng.standard_normal(v.shape)) for k, v in variables.items()})
    else:
        table = np.loadtxt(entry.file, ndmin=2)
        np.savetxt(target, table * (1.0 + relative * rng.standard_normal(table.shape)), fmt="%.17g")
    return target


ORDER_TOLERANCE = 0.5  # points; identify's own (vehid.identification.automatic.orders), passed in by real_data.py


def choose_order(mean_fits: dict[int, float | None], tolerance: float = ORDER_TOLERANCE) -> int | None:
    """The smallest order within ``tolerance`` points of the best finite mean fit, as ``identify --order`` chooses.

    Orders whose model has no fit (failed, or its simulation diverged) are
    not eligible; None when no order is.
    """
    eligible = {order: fit for order, fit in mean_fits.items() if fit is not None and np.isfinite(fit)}
    if not eligible:
        return None
    best = max(eligible.values())
    return min(order for order, fit in eligible.items() if fit >= best - tolerance)


def validation_offsets(entry: RecordSet, estimation: tuple[np.ndarray, np.ndarray],
                       validation: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Input and output offsets removed from the validation part before scoring, as ``vehid identify`` removes them.

    A held-out tail of a record shares the estimation part's operating point;
    a separate validation record is centred on its own means.
    """
    u, y = validation if entry.validation_path_columns is not None else estimation
    return u.mean(axis=0), y.mean(axis=0)


def nrmse_fit(y: np.ndarray, y_hat: np.ndarray) -> list[float | None]:
    """MATLAB ``compare``'s fit in percent per output; None for every output where the simulation diverged."""
    y = np.asarray(y, dtype=float).reshape(len(y), -1)
    y_hat = np.asarray(y_hat, dtype=float).reshape(len(y), -1)
    if not np.all(np.isfinite(y_hat)):
        return [None] * y.shape[1]  # JSON has no infinity; a diverged simulation has no fit
    spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
    return [float(v) for v in (1.0 - np.linalg.norm(y - y_hat, axis=0) / spread) * 100.0]


def fit_from_estimated_state(forced: np.ndarray, free: np.ndarray,
                             y: np.ndarray) -> tuple[list[float | None], np.ndarray]:
    """Fit of ``forced + free @ x0`` with ``x0`` the least-squares initial state.

    ``forced`` (N, n_y) is the response from zero state; ``free`` (N, n_y, n)
    holds the response to each unit initial state with zero input (a linear
    model's output is ``forced + free @ x0``).
    """
    n_y = y.shape[1]
    basis = free.transpose(1, 0, 2).reshape(-1, free.shape[2])  # outputs stacked
    target = (y - forced).T.reshape(-1)
    ok = np.all(np.isfinite(basis)) and np.all(np.isfinite(forced))
    x0 = np.linalg.lstsq(basis, target, rcond=None)[0] if ok else np.zeros(free.shape[2])
    y_hat = forced + np.einsum("kin,n->ki", free, x0)
    return nrmse_fit(y, y_hat.reshape(len(y), n_y)), x0


def fit_of_linear_simulator(simulate, n_states: int, u: np.ndarray, y: np.ndarray) -> list[float | None]:
    """Hold-out fit of a linear model given as ``simulate(u, x0) -> y``, from the least-squares initial state."""
    with np.errstate(all="ignore"):
        forced = simulate(u, np.zeros(n_states))
        free = np.stack([simulate(np.zeros_like(u), np.eye(n_states)[i]) for i in range(n_states)], axis=2)
    return fit_from_estimated_state(forced, free, y)[0]


def discrete_responses(A, B, C, D, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Zero-state output and unit-initial-state responses of ``x+ = A x + B u, y = C x + D u``."""
    A, B, C, D = (np.atleast_2d(np.asarray(m, dtype=float)) for m in (A, B, C, D))
    n = A.shape[0]
    x = np.zeros(n)
    forced = np.empty((len(u), C.shape[0]))
    power = np.eye(n)
    free = np.empty((len(u), C.shape[0], n))
    with np.errstate(over="ignore", invalid="ignore"):
        for k in range(len(u)):
            forced[k] = C @ x + D @ u[k]
            free[k] = C @ power
            x = A @ x + B @ u[k]
            power = A @ power
    return forced, free


def score_discrete(A, B, C, D, u_val: np.ndarray, y_val: np.ndarray, u_offset, y_offset) -> list[float | None]:
    """Hold-out fit of a discrete-time model identified on data with ``u_offset``, ``y_offset`` removed."""
    forced, free = discrete_responses(A, B, C, D, u_val - u_offset)
    return fit_from_estimated_state(forced, free, y_val - y_offset)[0]
