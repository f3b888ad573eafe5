"""An identification kept on disk: its archive written as it goes, and a run resumed from one.

:func:`identify <vehid.identification.pipeline.identify>` with ``out`` writes an HDF5
identification archive (``results/RESULTS_LAYOUT.md``): before the IEKF's passes the
prepared records, their preparation, the held-out parts and the decisions taken
(:class:`ArchiveKeeper`), then every finished pass (checkpoints, atomically, so that a
killed run leaves the archive of its last finished pass); once the run ends, every
other model of the run, the residual tests of the one returned and the summary
(:func:`archive_outcome`). With ``resume`` a run goes on from such an archive
(:func:`resumed_plan`), to the same parameters as a run never interrupted. Classical
methods and order searches are not checkpointed: their archive is written once they
end (:func:`archive_search`).
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Protocol, Sequence

from vehid.identification.errors import InputError

if TYPE_CHECKING:
    import h5py

    from vehid.identification.automatic.options import IdentifyOptions
    from vehid.identification.automatic.plan import Plan
    from vehid.identification.automatic.result import Identification
    from vehid.identification.automatic.run import Resumed
    from vehid.identification.data import IOData
    from vehid.identification.dataio.preparation import Preparation, ReadSettings

__all__ = ["ARCHIVE_KIND", "RUN_NAME", "REFINED_RUN", "RECORD_PREFIX", "VALIDATION_PREFIX", "DECISIONS", "VERDICT",
           "SCORING_RULE", "RETURNED_RUNS", "ProgressDisplay", "record_series_name", "write_record_series",
           "record_series", "archive_records", "archived_preparation", "archive_decisions", "read_decisions",
           "archive_schedule", "ArchiveKeeper", "resumed_plan", "archive_search", "archive_outcome"]

ARCHIVE_KIND = "identification"
RUN_NAME = "iekf"  # the archive's run of the IEKF
REFINED_RUN = "refined"  # the archive's run holding the filter's model refined by its simulation error
RECORD_PREFIX = "identification"  # the prepared estimation records: data/identification, data/identification_2, ...
VALIDATION_PREFIX = "validation"  # their held-out parts, alike
PREPARATION_MEMBER = "preparation"
DECISIONS = "decisions_json"  # root attribute: the p tuning and the stability decision taken before the passes
VERDICT = "summary_json"  # root attribute, as a study keeps its summary
SCORING_RULE = "scoring_rule"  # key of the archived summary only: how every model of the run is scored
#: the archive's run of each returned model (``Identification.returned``); the filter's is the IEKF's run
RETURNED_RUNS = {"filter": RUN_NAME, "start": "start", "scheduled": "scheduled", "nonlinear": "nonlinear"}


class ProgressDisplay(Protocol):
    """A display of the IEKF's passes (the command line's progress bar): told of passes done, then closed."""

    def advance(self, steps: int = 1, note: str = "") -> None: ...

    def close(self) -> None: ...


def record_series_name(prefix: str, index: int) -> str:
    """The archive name of record ``index`` (0-based) of a series: ``prefix``, ``prefix_2``, ``prefix_3``, ..."""
    return prefix if index == 0 else f"{prefix}_{index + 1}"


def write_record_series(archive: h5py.File, records: Sequence[IOData], prefix: str) -> None:
    """Store records as a series under ``prefix`` (:func:`record_series_name`), in order."""
    from vehid.identification.dataio.archive import write_record

    for index, record in enumerate(records):
        write_record(archive, record_series_name(prefix, index), record)


def record_series(stored: Mapping[str, IOData], prefix: str) -> tuple[IOData, ...]:
    """The series under ``prefix`` among an archive's records (:func:`read_records`), in order."""
    found = []
    while record_series_name(prefix, len(found)) in stored:
        found.append(stored[record_series_name(prefix, len(found))])
    return tuple(found)


def archive_records(archive: h5py.File, records: Sequence[IOData], preparation: Preparation | None) -> None:
    """Store the prepared records (``data/identification``, ``data/identification_2``, ...) and the preparation."""
    from vehid.identification.dataio.storage import write_value

    write_record_series(archive, records, RECORD_PREFIX)
    if preparation is not None:
        write_value(archive, PREPARATION_MEMBER, preparation)


def archived_preparation(archive: h5py.File) -> Preparation | None:
    """The preparation stored with an identification run (None in archives written before it was kept)."""
    from vehid.identification.dataio.preparation import Preparation
    from vehid.identification.dataio.storage import read_value

    if PREPARATION_MEMBER not in archive:
        return None
    value = read_value(archive, PREPARATION_MEMBER)
    if not isinstance(value, Preparation):
        raise InputError(f"the archive's {PREPARATION_MEMBER!r} member is not a Preparation")
    return value


def archive_decisions(archive: h5py.File, tuning: Any, unstable: Any) -> None:
    """What the run decided before its passes, so that a resumed run returns and warns as the original did."""
    from vehid.identification.jsonable import to_jsonable

    archive.attrs[DECISIONS] = json.dumps(to_jsonable({"tuning": tuning.as_dict(), "open_loop_unstable": unstable}),
                                          allow_nan=False)


def read_decisions(archive: h5py.File) -> tuple[Any, dict[str, Any] | None]:
    """The archived ``(tuning, unstable)`` of a run; ``(None, None)`` for an archive written before they were kept."""
    from vehid.identification.automatic.tuning import PTuning

    if DECISIONS not in archive.attrs:
        return None, None
    try:
        stored = json.loads(archive.attrs[DECISIONS])
        return PTuning.from_dict(stored["tuning"]), stored["open_loop_unstable"]
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{archive.filename} holds an unreadable record of the run's decisions") from None


def archive_plan(archive: h5py.File, plan: Plan) -> None:
    """The prepared estimation records, the preparation and the held-out parts (what a resume needs)."""
    archive_records(archive, plan.records, plan.preparation)
    write_record_series(archive, plan.validation[:plan.held_out_count], VALIDATION_PREFIX)


def archive_schedule(archive: h5py.File, plan: Plan) -> None:
    """The schedule channel of every archived record (root member ``schedule``), so that a report can simulate
    the family on them: ``channel``, ``unit`` and ``records`` (record name to samples)."""
    import numpy as np

    from vehid.identification.dataio.archive import SCHEDULE_MEMBER
    from vehid.identification.dataio.storage import write_value

    schedule = plan.schedule
    records = {record_series_name(RECORD_PREFIX, i): np.asarray(values, dtype=float)
               for i, values in enumerate(schedule.estimation)}
    records.update({record_series_name(VALIDATION_PREFIX, i): np.asarray(values, dtype=float)
                    for i, values in enumerate(schedule.validation[:plan.held_out_count])})
    write_value(archive, SCHEDULE_MEMBER, {"channel": schedule.channel, "unit": schedule.unit,
                                           "records": records})


class ArchiveKeeper:
    """The checkpoints of a single IEKF run (:class:`~vehid.identification.automatic.run.Checkpoints`): the archive
    written before the passes and after each, and the display of the passes.

    Parameters
    ----------
    path : Path or None
        The archive (None: nothing is written, the passes are only displayed).
    plan : Plan
        The run's records.
    run : str
        The run's identity (:data:`~vehid.identification.dataio.archive_safety.RUN_ATTRIBUTE`).
    progress : callable, optional
        ``progress(total, label)`` makes the display of ``total`` passes.
    """

    def __init__(self, path: Path | None, plan: Plan, run: str, progress: Callable[[int, str], ProgressDisplay] | None):
        self.path, self.plan, self.run, self.make_progress = path, plan, run, progress
        self.checkpoint: Any = None
        self.progress: ProgressDisplay | None = None

    def decided(self, options: Any, tuning: Any, unstable: Any, previous: Any) -> None:
        from vehid.identification.dataio.archive import write_archive
        from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
        from vehid.identification.dataio.iekf_archive import Checkpointer

        if self.path is not None and previous is None:
            with write_archive(self.path, kind=ARCHIVE_KIND, config=options, seeds=[]) as archive:
                archive.attrs[RUN_ATTRIBUTE] = self.run
                archive_plan(archive, self.plan)
                archive_decisions(archive, tuning, unstable)
        if self.path is not None:
            self.checkpoint = Checkpointer(self.path, RUN_NAME)
        if self.make_progress is not None:
            self.progress = self.make_progress(options.passes, "IEKF passes")
            self.progress.advance(previous.passes_run if previous is not None else 0)

    def passed(self, record: Any, so_far: Any) -> None:
        if self.checkpoint is not None:
            self.checkpoint(record, so_far)
        if self.progress is not None:
            self.progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

    def _stop_progress(self) -> None:
        if self.progress is not None:
            progress, self.progress = self.progress, None
            progress.close()

    def close(self) -> None:
        """On the way out, however the run ends: an interrupted run's archive keeps every finished pass."""
        self._stop_progress()
        if self.checkpoint is not None:
            checkpoint, self.checkpoint = self.checkpoint, None
            checkpoint.flush()

    def finished(self, result: Any) -> None:
        self._stop_progress()
        if self.checkpoint is not None:
            checkpoint, self.checkpoint = self.checkpoint, None
            checkpoint.finish(result)  # the archive says how the run ended: converged, passes or diverged at pass k


def resumed_plan(path: str | Path, *, order: int | str, validation: Sequence[Any] = (), passes: int | None = None,
                 reading: ReadSettings | None = None) -> tuple[Plan, Resumed]:
    """The plan of a checkpointed run, and what the pipeline needs to go on with it.

    ``validation`` are further validation files or records (the held-out parts are the archive's);
    ``passes`` a new pass budget (None: the run's own); ``reading`` reads the validation files of an
    archive written before preparations were kept.
    """
    from vehid.identification.automatic.tuning import given_p, q_schedule_of
    from vehid.identification.automatic.plan import make_plan
    from vehid.identification.automatic.run import Resumed
    from vehid.identification.dataio.archive import open_archive, read_records, update_archive
    from vehid.identification.dataio.preparation import ReadSettings, prepare_validation, read_record
    from vehid.identification.dataio.iekf_archive import read_iekf_run

    with open_archive(path, kinds=[ARCHIVE_KIND]) as archive:
        previous = read_iekf_run(archive, RUN_NAME)
        preparation = archived_preparation(archive)
        stored = read_records(archive)
        tuning, unstable = read_decisions(archive)
        judged = VERDICT in archive.attrs
    records = record_series(stored, RECORD_PREFIX)
    if not records:
        raise InputError(f"{path} holds no identification record to resume on")
    held_out = record_series(stored, VALIDATION_PREFIX)
    budget = previous.options.passes if passes is None else passes
    options = dataclasses.replace(previous.options, passes=max(budget, previous.passes_run))
    if preparation is not None:
        load = lambda source: prepare_validation(source, preparation, own_offsets=True)  # noqa: E731
    else:  # an archive written before preparations were kept
        load = lambda source: read_record(source, reading or ReadSettings())  # noqa: E731
    plan = make_plan(records, order=order, validation=[(str(source), source) for source in validation], load=load,
                     held_out=held_out, preparation=preparation)
    if judged:  # the run goes on: a verdict on fewer passes must not outlive it (a kill would leave it stale)
        with update_archive(path) as archive:
            del archive.attrs[VERDICT]
    if tuning is None:  # an archive written before the tuning was kept: the run's own p, as archived
        tuning = given_p(options)
    # the archived options run the passes; an archive written before the schedule was kept names it by them
    tuning = dataclasses.replace(tuning, q_schedule=q_schedule_of(options))
    return plan, Resumed(previous.structure, options, previous, tuning, unstable)


def archive_search(path: Path, run: str, plan: Plan, options: IdentifyOptions, result: Identification) -> None:
    """The archive of a run whose estimator was not checkpointed: an order search's chosen IEKF run, or a
    classical method's model and fit as ``runs/<method>``."""
    from vehid.identification.automatic.tuning import iekf_options
    from vehid.identification.dataio.archive import write_archive, write_run
    from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
    from vehid.identification.dataio.iekf_archive import write_iekf_run

    if options.method != "iekf":
        outcome = result.estimator
        config = {"method": options.method, "order": outcome.model.n_states}
        with write_archive(path, kind=ARCHIVE_KIND, config=config, seeds=[]) as archive:
            archive.attrs[RUN_ATTRIBUTE] = run
            archive_plan(archive, plan)
            written = write_run(archive, options.method, model=outcome.model, metrics=outcome.metrics)
            written.attrs["stop_reason"] = "finished"
            written.attrs["seconds"] = outcome.seconds
        return
    with write_archive(path, kind=ARCHIVE_KIND, config=iekf_options(options), seeds=[]) as archive:
        archive.attrs[RUN_ATTRIBUTE] = run
        archive_plan(archive, plan)
        archive_decisions(archive, result.tuning, result.open_loop_unstable)
        write_iekf_run(archive, RUN_NAME, result.estimator)


def archive_outcome(path: Path, result: Identification, options: IdentifyOptions) -> None:
    """Every model of the run beside the estimator's, the residual tests of the one returned and the summary
    (``summary_json``: what a report and a resume show), in one atomic update of the archive.

    Beside the public keys the summary names the run whose model was returned and the rule by which
    every model was scored (initial state, prediction horizon where one was given), so that a report
    scores the other runs the same way.
    """
    from vehid.identification.dataio.archive import run_group, update_archive, write_run
    from vehid.identification.dataio.storage import write_value
    from vehid.identification.dataio.iekf_archive import write_pass_history
    from vehid.identification.jsonable import to_jsonable

    plan = result.plan
    nonlinear = result.nonlinear.result.model if result.nonlinear is not None else None
    linear = result.linear_model
    with update_archive(path) as archive:  # one atomic update (each copies the archive)
        if nonlinear is not None:
            write_run(archive, "nonlinear", model=nonlinear)
            write_pass_history(archive, "nonlinear", result.nonlinear.result.history)
        if result.scheduled is not None:
            write_run(archive, "scheduled", model=result.scheduled.model)
            archive_schedule(archive, plan)
        # the filter's model refined by its simulation error is a model of its own, beside the filter's
        refined = result.is_iekf and not result.start_returned and linear is not result.estimator.model
        if result.start_returned:
            write_run(archive, "start", model=linear)
        elif refined:
            write_run(archive, REFINED_RUN, model=linear)
        returned = REFINED_RUN if refined and result.returned == "filter" else \
            RETURNED_RUNS.get(result.returned, RUN_NAME if result.is_iekf else options.method)
        if result.residual_tests is not None:
            write_value(run_group(archive, returned), "residual_tests", result.residual_tests)
        verdict = {**result.render(), SCORING_RULE: {"initial_state": options.initial_state,
                                                     "horizon": options.horizon, "returned_run": returned}}
        archive.attrs[VERDICT] = json.dumps(to_jsonable(verdict), allow_nan=False)
