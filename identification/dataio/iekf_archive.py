"""IEKF runs in results archives: per-pass history, final model, resume state, checkpoints.

A run ``runs/<name>`` holds its history, model, resume state and options (``results/RESULTS_LAYOUT.md``).
A pass depends only on the parameters and P it starts from and on the data, so a run resumed from its
checkpoint reaches the same parameters as one that was never interrupted.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from .archive import append_history, read_run, run_group, update_archive, write_run
from ..errors import ArchiveError
from ..filtering.iekf import FilterState, IEKFOptions, IEKFResult, PassRecord
from ..jsonable import to_jsonable
from ..models.modal import ModalModel
from .storage import read_value, write_value

__all__ = ["HISTORY_UNITS", "write_iekf_run", "write_pass_history", "append_iekf_pass", "read_iekf_run",
           "Checkpointer"]

# seconds of passes computed per second of checkpoint writing, at least (see Checkpointer)
COMPUTE_PER_CHECKPOINT = 4.0

HISTORY_UNITS = {
    "index": "-",
    "parameters": "model units",
    "fit_filter": "%",
    "fit_continuous": "%",
    "trace_p": "normalised units",
    "min_eig_p": "normalised units",
    "seconds": "s",
    "nis": "-",
}


def _history_row(record: PassRecord) -> dict[str, Any]:
    return {
        "index": np.int64(record.index),
        "parameters": record.parameters,
        "fit_filter": record.fit_filter,
        "fit_continuous": record.fit_continuous,
        "trace_p": record.trace_p,
        "min_eig_p": record.min_eig_p,
        "seconds": record.seconds,
        "nis": record.nis,
    }


def _write_summary(run: h5py.Group, result: IEKFResult) -> None:
    write_run(run.file, run.name.rsplit("/", 1)[-1], model=result.model, state=result.state)
    write_value(run, "options", result.options)
    run.attrs["dt"] = result.dt
    run.attrs["stop_reason"] = result.stop_reason
    run.attrs["seconds"] = result.seconds
    # how the run started, its start parameters included: a resumed run judges its model against the same start
    run.attrs["meta_json"] = json.dumps(to_jsonable(result.meta), allow_nan=False)


def write_iekf_run(archive: h5py.File, name: str, result: IEKFResult) -> h5py.Group:
    """Store a finished (or diverged) IEKF result as ``runs/<name>`` (replacing one of that name)."""
    runs = archive.require_group("runs")
    if name in runs:
        del runs[name]
    run = run_group(archive, name)
    for record in result.history:
        append_history(run, _history_row(record), units=HISTORY_UNITS)
    _write_summary(run, result)
    return run


def write_pass_history(archive: h5py.File, name: str, history: tuple[PassRecord, ...]) -> h5py.Group:
    """Store the passes of a filter run that keeps no resume state (the spline IEKF's) as ``runs/<name>/history``.

    Its rows are those of an IEKF run, so that a report draws and counts its passes alike.
    """
    run = run_group(archive, name)
    if "history" in run:
        del run["history"]
    for record in history:
        row = _history_row(record)
        if not np.isfinite(record.nis):  # a filter that does not measure its innovations: no column of NaN
            del row["nis"]
        append_history(run, row, units=HISTORY_UNITS)
    return run


def append_iekf_pass(archive: h5py.File, name: str, record: PassRecord, result: IEKFResult) -> None:
    """Add one pass to ``runs/<name>`` and replace its model and resume state (a checkpoint)."""
    run = _append_history_row(archive, name, record)
    _write_summary(run, result)


def _append_history_row(archive: h5py.File, name: str, record: PassRecord) -> h5py.Group:
    """Add one pass's row to the history of ``runs/<name>``, which must hold the passes before it."""
    run = run_group(archive, name)
    recorded = int(run["history"].attrs.get("n_pass", 0)) if "history" in run else 0
    if record.index != recorded + 1:
        raise ArchiveError(f"run {name!r} holds {recorded} passes; pass {record.index} cannot follow")
    row = _history_row(record)
    if recorded and "nis" not in run["history"]:
        del row["nis"]  # a run begun before the history recorded it keeps its columns
    append_history(run, row, units=HISTORY_UNITS)
    return run


def read_iekf_run(archive: h5py.File, name: str) -> IEKFResult:
    """Rebuild the :class:`IEKFResult` of ``runs/<name>`` (for reports and ``--resume``)."""
    runs = archive.get("runs")
    if runs is None or name not in runs:
        raise ArchiveError(f"the archive has no run {name!r}")
    run = runs[name]
    stored = read_run(run)
    history, model, state = stored.history, stored.model, stored.state
    try:
        options = read_value(run, "options")
        dt, stop_reason, seconds = float(run.attrs["dt"]), str(run.attrs["stop_reason"]), float(run.attrs["seconds"])
    except (KeyError, ArchiveError) as missing:
        raise ArchiveError(f"run {name!r} is incomplete: missing {missing}") from None
    if not isinstance(model, ModalModel) or not isinstance(state, FilterState) or not isinstance(options, IEKFOptions):
        raise ArchiveError(f"run {name!r} does not hold an IEKF model, state and options")
    records = tuple(
        PassRecord(index=int(history["index"][k]), parameters=history["parameters"][k],
                   fit_filter=history["fit_filter"][k], fit_continuous=history["fit_continuous"][k],
                   trace_p=float(history["trace_p"][k]), min_eig_p=float(history["min_eig_p"][k]),
                   seconds=float(history["seconds"][k]),
                   nis=float(history["nis"][k]) if "nis" in history else float("nan"))
        for k in range(len(history.get("index", ())))
    )
    return IEKFResult(
        model=model, structure=model.structure, options=options, history=records, state=state,
        dt=dt, stop_reason=stop_reason, seconds=seconds, meta=_read_meta(run),
    )


def _read_meta(run: h5py.Group) -> dict[str, Any]:
    """The run's start description; empty for a run archived before it was kept."""
    if "meta_json" not in run.attrs:
        return {}
    try:
        meta = json.loads(run.attrs["meta_json"])
    except ValueError:
        raise ArchiveError(f"run {run.name!r} holds an unreadable start description") from None
    if meta.get("start_parameters") is not None:
        meta["start_parameters"] = np.asarray(meta["start_parameters"], dtype=float)
    return meta


class Checkpointer:
    """An ``on_pass`` callback that records finished passes in an archive, atomically.

    A checkpoint copies, rewrites and re-verifies the archive, which takes far
    longer than a pass on a short record (0.14 s against 4 ms measured on a
    2000-sample record), so passes are gathered and written together once the
    time computed since the last checkpoint reaches
    :data:`COMPUTE_PER_CHECKPOINT` times what that checkpoint took to write.
    Checkpoints then cost at most about a fifth of a run, and a run killed
    outright loses at most that much computing, which a resume redoes exactly
    (a pass depends only on where it starts). The first pass is written at
    once. :meth:`flush` writes what is gathered (the command calls it on the
    way out of an interrupted run); :meth:`finish` writes the end.

    Parameters
    ----------
    path : str or Path
        An archive that exists (written by :func:`vehid.identification.dataio.archive.write_archive`).
    name : str
        The run's name.
    """

    def __init__(self, path: str | Path, name: str):
        self.path = Path(path)
        self.name = name
        self._gathered: list[PassRecord] = []
        self._latest: IEKFResult | None = None
        self._write_seconds = 0.0
        self._since = time.perf_counter()

    def __call__(self, record: PassRecord, result: IEKFResult) -> None:
        self._gathered.append(record)
        self._latest = result
        if time.perf_counter() - self._since >= COMPUTE_PER_CHECKPOINT * self._write_seconds:
            self.flush()

    def flush(self) -> None:
        """Write the passes gathered since the last checkpoint, with the latest model and resume state."""
        if not self._gathered:
            return
        started = time.perf_counter()
        self._write(self._latest)
        self._since = time.perf_counter()
        self._write_seconds = self._since - started

    def finish(self, result: IEKFResult) -> None:
        """Record how the run ended: its final stop reason (no longer ``running``), model, state and time."""
        self._write(result)

    def _write(self, result: IEKFResult) -> None:
        """One checkpoint: the gathered passes' rows, then ``result``'s model, resume state and account."""
        with update_archive(self.path) as archive:
            for record in self._gathered:
                _append_history_row(archive, self.name, record)
            _write_summary(run_group(archive, self.name), result)
        self._gathered.clear()
