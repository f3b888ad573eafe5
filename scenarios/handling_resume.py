"""Checkpoints and resume of the handling study.

The study's archive is rewritten atomically each time an order finishes (its
runs and its entry in ``orders_done_json``). ``vehid study handling --resume``
reads the settings, records and finished orders back bit for bit and runs
only the missing orders, so its table equals that of an uninterrupted run.
An interrupted order is run again from its start.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from vehid.identification.dataio.archive import RunName, open_archive, read_records, read_run, update_archive
from vehid.identification.errors import ArchiveError, InputError
from vehid.identification.dataio.iekf_archive import read_iekf_run
from vehid.identification.dataio.storage import read_group, read_value

from .handling_study import (
    ORDERS_DONE,
    HandlingConfig,
    OrderOutcome,
    SplineStudyRun,
    start_archive,
    write_order,
)

__all__ = ["StudyCheckpoint", "read_progress"]


class StudyCheckpoint:
    """Writes the study's archive as it goes: records at the start, then each order as it finishes.

    Parameters
    ----------
    path : Path
        The archive; the caller holds its writer's lock for the whole study.
    fresh : bool
        Start a new archive (True) or add to a resumed one (False).
    run : str, optional
        The digest of the command line that asked for the study, kept in a fresh archive.
    """

    def __init__(self, path: str | Path, config: HandlingConfig, records: dict, *, fresh: bool = True,
                 run: str | None = None):
        self.path = Path(path)
        if fresh:
            with start_archive(self.path, config, records, run=run):
                pass

    def __call__(self, outcome: OrderOutcome) -> None:
        with update_archive(self.path, kinds=["handling-study"]) as archive:
            write_order(archive, outcome.order, outcome)


def _config(stored: Any, path: Path, workers: int | None) -> HandlingConfig:
    if not isinstance(stored, dict) or "orders" not in stored:
        raise ArchiveError(f"{path} holds no handling-study settings to resume with")
    try:
        return HandlingConfig.from_dict(stored, workers)
    except KeyError as exc:
        raise ArchiveError(f"{path} holds settings this workbench does not know ({exc})") from None


def _nonlinear(run: Any) -> SplineStudyRun:
    stored = read_run(run)
    history, metrics = stored.history, stored.metrics
    curves = {}
    mode = 0
    while f"mode{mode}_frequency" in run:
        curves[mode] = (read_value(run, f"mode{mode}_frequency"), read_value(run, f"mode{mode}_damping"))
        mode += 1
    return SplineStudyRun(
        model=stored.model,
        fit_identification=np.asarray(metrics["identification_R"]),
        fit_validation=np.asarray(metrics["validation_R"]),
        fit_filter=history.get("fit_filter", np.zeros((0, 0))),
        trace_p=history.get("trace_p", np.zeros(0)),
        spline_tables=read_value(run, "spline_tables"),
        mode_curves=curves,
        stop_reason=str(run.attrs["stop_reason"]),
        seconds=float(run.attrs["seconds"]),
    )


def _outcome(archive: Any, order: int, status: dict) -> OrderOutcome:
    runs = archive["runs"]
    linear_name, nonlinear_name = str(RunName("linear", order)), str(RunName("nonlinear", order))
    linear = fit_identification = fit_validation = nonlinear = None
    if linear_name in runs:
        linear = read_iekf_run(archive, linear_name)
        metrics = read_group(runs[linear_name]["metrics"])
        fit_identification = np.asarray(metrics["identification_R"])
        fit_validation = np.asarray(metrics["validation_R"])
    if nonlinear_name in runs:
        nonlinear = _nonlinear(runs[nonlinear_name])
    return OrderOutcome(order, linear, fit_identification, fit_validation, status.get("linear_error"), nonlinear,
                        status.get("nonlinear_error"), float(status.get("seconds", 0.0)))


def read_progress(path: str | Path, workers: int | None = None) -> tuple[HandlingConfig, dict, dict[int, OrderOutcome]]:
    """The settings, records and finished orders of a (possibly unfinished) study archive.

    Parameters
    ----------
    path : str or Path
        A ``handling-study`` archive written by the study (finished or not).
    workers : int, optional
        Worker processes for the orders still to run (not part of the results).

    Returns
    -------
    config : HandlingConfig
    records : dict of str to IOData
    finished : dict of int to OrderOutcome

    Raises
    ------
    ArchiveError
        A missing, foreign or corrupt file, or one that is not a handling study
        this workbench can continue.
    """
    path = Path(path)
    with open_archive(path, kinds=["handling-study"]) as archive:
        try:
            config = _config(read_group(archive["config"]), path, workers)
            records = read_records(archive)
            done = json.loads(archive.attrs.get(ORDERS_DONE, "{}"))
            finished = {int(order): _outcome(archive, int(order), status) for order, status in done.items()
                        if int(order) in config.orders}
        except InputError as exc:
            raise ArchiveError(f"{path} cannot be resumed: {exc}") from None
        except (KeyError, ValueError) as exc:
            raise ArchiveError(f"{path} cannot be resumed: it is incomplete ({exc})") from None
    if set(records) != {"identification", "validation"}:
        raise ArchiveError(f"{path} cannot be resumed: it lacks the identification and validation records")
    return config, records, finished
