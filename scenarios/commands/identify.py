"""Identify a modal state-space model from an input/output record.

DATA is one or several files: workbench HDF5 (as written by `vehid simulate
--out`), CSV, whitespace-separated .dat/.txt, MATLAB .mat or ASAM MDF4 .mf4.
Name the channels with --inputs and --outputs (for an HDF5 record they select
among its inputs and outputs; for other files they are required; text tables
also take 1-based column numbers). Time comes from a column `t`, the column
--time-column names, or --dt; --resample, --decimate and --segment shape the
time base. Each record's offsets (means, or lines with --detrend linear) are
removed and kept with the model, --scale multiplies a channel; several files
identify one model, scored per record ("records" in the JSON summary).

The default method is the Identifying EKF (Best & Bogdanski 2017) with the
exact first-order-hold discretisation, so the identified parameters are those
of the continuous-time model; --discretization euler reproduces the paper's
filter. The defaults do not depend on the units of time or of the signals:
signals normalised (--no-normalize to switch off), start values from a
subspace model of the record (--start paper for the paper's), time counted
in samples inside the filter and p per dominant time constant (--timescale
seconds for the absolute behaviour), p chosen by cross-validation on the
estimation data unless --p is given. Where the data start, left unstable,
predicts the record clearly better than a stable one, the plant is treated
as open-loop unstable (as --allow-unstable; JSON `open_loop_unstable`), and
the data start is returned where it beats every p in cross-validation or
the filter's model on the estimation data (`start_kept`), at every order.
These choices are said once as notes (JSON `notes`), each with its margin
(JSON `decision_margins`: choice, score, runner-up and its score). The
summary first names the model returned (`model_returned`), then gives its
NRMSE fits on estimation and validation data (--validation,
--validation-file) with the fit R (eq. 17) beside each (every JSON key
ending in `fit_percent` is an NRMSE fit, every key ending in `R` the fit R;
lists in --outputs order), the eigenvalues and matrices of the linear model,
whether the run converged, any warnings about the model returned (--strict:
the summary, then exit status 3) and the run time. --order takes a number, a
range (2-8) or auto, chosen on validation data; --nonlinear adds the
spline-nonlinear model and --schedule the scheduled family: each is scored
by the same rule as the linear model (initial state, horizon, records), the
better by that rule is returned, and what became of the others is said in
notes. It also says how sure the returned model is (scenarios.model_checks): each mode with
standard deviations (text: value +/- 2 sigma; JSON: the list `modes`), the
residual tests per output (`residual_whiteness_p`, `input_correlation_max`)
and, for the IEKF, the innovation NIS per pass with its band. A model of a
car (an output named, or by --quantities, yaw_rate) is checked for physical
plausibility: each failure joins `plausibility` and the warnings.

With --out ARCHIVE the record and every finished pass are written to an HDF5
archive as the run goes (atomically, so a killed run leaves the archive of
its last finished pass); --resume ARCHIVE continues such a run from there
with the same data and settings, and reaches the same parameters as a run
that was never interrupted: it runs to the run's own pass budget and stop
rule (--passes, given explicitly, sets a new budget). Once the run ends, the
archive records its final stop reason. Every method writes its model to
--out. A relative --out or --save-model is taken from the working directory.
Both are checked before any work: an HDF5 name for --out, .json or .mat for
--save-model, no directory, no input file, and an existing file is replaced
only if it is the identification archive of the same run (same data and
settings) or a model file of the workbench, unless --force; an archive being
written is locked against a second writer.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from contextlib import nullcontext
from pathlib import Path
from typing import Any

from vehid.identification.automatic.options import DEFAULT_PASSES, IdentifyOptions
from vehid.identification.errors import InputError

NAME = "identify"
GROUP = None
HELP = "identify a modal state-space model from a data file (IEKF by default)"


def register(parser: argparse.ArgumentParser) -> None:
    from vehid.scenarios.commands.identify_options import register_identify_options

    register_identify_options(parser)
    parser.set_defaults(handler=run)


RUN_NAME = "iekf"
ARCHIVE_KIND = "identification"
VALIDATION_PREFIX = "validation"


def _resume(args: argparse.Namespace):
    """The plan of a checkpointed run, and what the pipeline needs to go on with it."""
    from vehid.identification.automatic import steps
    from vehid.identification.automatic.plan import make_plan
    from vehid.identification.automatic.run import Resumed
    from vehid.identification.dataio.archive import open_archive, read_records, update_archive
    from vehid.identification.dataio.preparation import prepare_validation, read_record
    from vehid.identification.dataio.iekf_archive import read_iekf_run
    from vehid.scenarios.data_options import RECORD_PREFIX, archived_preparation, record_series, settings_from_args

    if args.data:
        raise InputError("--resume takes its data from the archive: give no DATA file")
    with open_archive(args.resume, kinds=["identification"]) as archive:
        previous = read_iekf_run(archive, RUN_NAME)
        preparation = archived_preparation(archive)
        stored = read_records(archive)
        decisions = _read_decisions(archive)
        judged = VERDICT in archive.attrs
    records = record_series(stored, RECORD_PREFIX)
    if not records:
        raise InputError(f"{args.resume} holds no identification record to resume on")
    held_out = record_series(stored, VALIDATION_PREFIX)
    budget = previous.options.passes if args.passes is None else args.passes
    options = dataclasses.replace(previous.options, passes=max(budget, previous.passes_run))
    if preparation is not None:
        load = lambda path: prepare_validation(path, preparation, own_offsets=True)  # noqa: E731
    else:  # an archive written before preparations were kept
        load = lambda path: read_record(path, settings_from_args(args))  # noqa: E731
    plan = make_plan(records, order=args.order, validation=[(path, path) for path in args.validation_file], load=load,
                     held_out=held_out, preparation=preparation)
    if judged:  # the run goes on: a verdict on fewer passes must not outlive it (a kill would leave it stale)
        with update_archive(args.resume) as archive:
            del archive.attrs[VERDICT]
    tuning, unstable = decisions
    if tuning is None:  # an archive written before the tuning was kept: the run's own p, as archived
        tuning = steps.given_p(options)
    # the archived options run the passes; an archive written before the schedule was kept names it by them
    tuning = dataclasses.replace(tuning, q_schedule=steps.q_schedule_of(options))
    return plan, Resumed(previous.structure, options, previous, tuning, unstable)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.dataio.archive import open_archive
    from vehid.identification.dataio.archive_safety import archive_lock, check_output_target
    from vehid.scenarios import schedule_channel
    from vehid.scenarios.data_options import check_model_target
    from vehid.scenarios.paths import HDF5_SUFFIXES, run_digest
    from vehid.scenarios.plausibility_checks import check_quantities

    check_quantities(args)
    if args.structure == "single-track":
        from vehid.scenarios import single_track_identify

        summary, text = single_track_identify.run(args)
        emit(summary, summary["warnings"], args)
        return summary, text
    if args.resume and args.out:
        raise InputError("--resume continues in its own archive: give no --out")
    if args.schedule:
        schedule_channel.check_options(args)
    inputs = [*args.data, *args.validation_file, args.resume]
    # the run's identity, kept with the archive: a rerun of the same run may replace it, another may not
    args = argparse.Namespace(**vars(args), output_run=run_digest(args))
    if args.out:  # before any work: a bad target must not cost the run
        check_output_target(args.out, inputs=inputs, force=args.force, kind=ARCHIVE_KIND, run=args.output_run,
                            suffixes=HDF5_SUFFIXES)
    if args.save_model:
        check_model_target(args.save_model, inputs=[*inputs, args.out], force=args.force)
    if args.resume:  # a missing, foreign or corrupt file is named as such before anything is locked or created
        open_archive(args.resume, kinds=["identification"]).close()
    target = args.resume or args.out
    with archive_lock(target) if target else nullcontext():  # one writer per archive for the whole run
        summary, text, _ = identify_run(args)
    return summary, text


REFINED_RUN = "refined"  # the archive's run holding the filter's model refined by its simulation error
DECISIONS = "decisions_json"  # root attribute: the p tuning and the stability decision taken before the passes


def _archive_decisions(archive, tuning, unstable) -> None:
    """What the run decided before its passes, so that a resumed run returns and warns as the original did."""
    from vehid.identification.jsonable import to_jsonable

    archive.attrs[DECISIONS] = json.dumps(to_jsonable({"tuning": tuning, "open_loop_unstable": unstable}),
                                          allow_nan=False)


def _read_decisions(archive) -> tuple:
    """The archived ``(tuning, unstable)`` of a run; ``(None, None)`` for an archive written before they were kept."""
    from vehid.identification.automatic.steps import PTuning

    if DECISIONS not in archive.attrs:
        return None, None
    try:
        stored = json.loads(archive.attrs[DECISIONS])
        tuning = stored["tuning"]
        return (PTuning(p=float(tuning["p"]), tried=tuple(tuning["tried"]), seconds=float(tuning["seconds"]),
                                 start_fit=tuning["start_fit"], q_schedule=tuning.get("q_schedule", "constant"),
                                 candidate_fits=tuning.get("candidate_fits")),
                stored["open_loop_unstable"])
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{archive.filename} holds an unreadable record of the run's decisions") from None


def _archive_plan(archive, plan) -> None:
    """The prepared estimation records, the preparation and the held-out parts (what a resume needs)."""
    from vehid.scenarios.data_options import archive_records, write_record_series

    archive_records(archive, plan.records, plan.preparation)
    write_record_series(archive, plan.validation[:plan.held_out_count], VALIDATION_PREFIX)


def options_from_args(args: argparse.Namespace) -> IdentifyOptions:
    """The pipeline's settings named by the command's arguments (each checked where it is defined)."""
    from vehid.scenarios.schedule_channel import parse_schedule_grid

    return IdentifyOptions(
        p=args.p, passes=DEFAULT_PASSES if args.passes is None else args.passes, start=args.start,
        normalize=args.normalize, discretization=args.discretization, covariance=args.covariance,
        pattern=args.pattern, timescale=args.timescale, allow_unstable=args.allow_unstable,
        initial_state=args.initial_state, horizon=args.horizon, nonlinear=args.nonlinear, nodes=args.nodes,
        nonlinear_p=tuple(args.nonlinear_p) if args.nonlinear_p else None, nonlinear_passes=args.nonlinear_passes,
        detrend=args.detrend, strict=args.strict, method=args.method, bootstrap=args.bootstrap,
        **({} if not args.schedule else {  # the schedule's settings count only where a schedule is read
            "schedule_knots": args.schedule_knots, "schedule_grid": parse_schedule_grid(args.schedule_grid),
            "schedule_p": tuple(args.schedule_p) if args.schedule_p else None}))


def holdout_of(args: argparse.Namespace) -> tuple[float | None, str | None]:
    """The fraction of each record held out (:func:`~vehid.identification.automatic.plan.holdout_fraction`)."""
    from vehid.identification.automatic.plan import holdout_fraction

    return holdout_fraction(args.order, args.validation, bool(args.validation_file))


def load_plan(args: argparse.Namespace, paths: list[str]):
    """Read the data files, hold out the tail of each record where asked, and prepare both alike.

    The split comes before the preparation, so the offsets kept with the model
    are the estimation part's own (the held-out part plays no role in them).
    """
    from vehid.identification.automatic.plan import make_plan
    from vehid.identification.dataio.preparation import prepare, prepare_validation
    from vehid.scenarios import schedule_channel
    from vehid.scenarios.data_options import preparation_options, read_from_args
    from vehid.scenarios.log_cleaning import clean_records, min_speed_of

    fraction, note = holdout_of(args)
    scale, schedules = args.scale, None
    if args.schedule:  # the schedule channel is read beside the inputs, kept apart and never offset
        raw, settings, schedules, scale, schedule_unit = schedule_channel.read_with_schedule(args, paths)
    else:
        raw, settings = read_from_args(args, paths)
    # spikes found (and repaired with --despike), --exclude windows and a standing car left out, the hold-out
    # cut: each run of what is left is its own record
    cleaned = clean_records(args, raw, speeds=schedules, speed_name=args.schedule and args.schedule.strip(),
                            speed_factor=schedule_channel.schedule_factor(args) if args.schedule else 1.0,
                            min_speed=min_speed_of(args, moving_model=bool(args.schedule)), holdout=fraction)
    records, preparation = prepare(cleaned.estimation, settings=settings,
                                   **{**preparation_options(args), "scale": scale})
    held = tuple(prepare_validation(part, preparation, record=i)
                 for i, part in zip(cleaned.validation_follows, cleaned.validation))
    channels = validation_channels(args, preparation)
    # a validation file is another experiment: its offsets are its own, as each estimation record's are
    load = lambda path: prepare_validation(path, preparation, own_offsets=True, channels=channels)  # noqa: E731
    found: list = []  # the schedule channel of each validation file, as the loader reads it
    if schedules is not None:
        load = schedule_channel.schedule_loader(args, preparation, channels, found)
    plan = make_plan(records, order=args.order, validation=[(path, path) for path in args.validation_file],
                     load=load, held_out=held, fraction=fraction, note=note, preparation=preparation)
    if schedules is not None:
        channel = args.schedule.strip()
        plan = dataclasses.replace(plan, schedule=schedule_channel.ScheduleData(
            channel, cleaned.extra_estimation[channel], cleaned.extra_validation[channel] + tuple(found),
            schedule_unit))
    return plan


def validation_channels(args: argparse.Namespace, preparation) -> tuple[tuple[str, ...], tuple[str, ...]] | None:
    """The validation files' channel names (model order), where the options name them."""
    if args.validation_inputs is None and args.validation_outputs is None:
        return None
    from vehid.scenarios.data_options import channel_names

    inputs = channel_names(args.validation_inputs) if args.validation_inputs is not None else preparation.settings.inputs
    outputs = (channel_names(args.validation_outputs) if args.validation_outputs is not None
               else preparation.settings.outputs)
    return tuple(inputs), tuple(outputs)


class _Keeper:
    """The command's checkpoints of a single IEKF run: the archive written before the passes and after each,
    and the progress bar."""

    def __init__(self, args: argparse.Namespace, plan, archive_path: Path | None):
        self.args, self.plan, self.archive_path = args, plan, archive_path
        self.checkpoint = None
        self.progress = None

    def decided(self, options, tuning, unstable, previous) -> None:
        from vehid.identification.dataio.archive import write_archive
        from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
        from vehid.identification.dataio.iekf_archive import Checkpointer
        from vehid.scenarios.progress import Progress

        if self.archive_path is not None and previous is None:
            with write_archive(self.archive_path, kind=ARCHIVE_KIND, config=options, seeds=[]) as archive:
                archive.attrs[RUN_ATTRIBUTE] = self.args.output_run
                _archive_plan(archive, self.plan)
                _archive_decisions(archive, tuning, unstable)
        if self.archive_path is not None:
            self.checkpoint = Checkpointer(self.archive_path, RUN_NAME)
        self.progress = Progress(options.passes, "IEKF passes", enabled=None if not self.args.quiet else False)
        self.progress.__enter__()
        self.progress.advance(previous.passes_run if previous is not None else 0)

    def passed(self, record, so_far) -> None:
        if self.checkpoint is not None:
            self.checkpoint(record, so_far)
        self.progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

    def _stop_progress(self) -> None:
        if self.progress is not None:
            progress, self.progress = self.progress, None
            progress.__exit__(None, None, None)

    def close(self) -> None:
        """On the way out, however the run ends: an interrupted run's archive keeps every finished pass."""
        self._stop_progress()
        if self.checkpoint is not None:
            checkpoint, self.checkpoint = self.checkpoint, None
            checkpoint.flush()

    def finished(self, result) -> None:
        self._stop_progress()
        if self.checkpoint is not None:
            checkpoint, self.checkpoint = self.checkpoint, None
            checkpoint.finish(result)  # the archive says how the run ended: converged, passes or diverged at pass k


def identify_run(args) -> tuple[dict, str, object]:
    """The whole run: summary, text and the model returned."""
    from vehid.identification.automatic.run import identify_plan

    options = options_from_args(args)
    resumed = None
    if args.resume:
        plan, resumed = _resume(args)
        archive_path = Path(args.resume)
    else:
        if not args.data:
            raise InputError("give a DATA file (or --resume ARCHIVE)")
        plan = load_plan(args, args.data)
        archive_path = Path(args.out) if args.out else None
    keeper = _Keeper(args, plan, archive_path)
    try:
        result = identify_plan(plan, options, resumed=resumed, checkpoints=keeper)
    finally:
        keeper.close()
    if archive_path is not None and resumed is None and (options.method != "iekf" or len(plan.orders) > 1):
        _archive_search(args, plan, options, result)
    return _finish(args, plan, result, archive_path)


def _archive_search(args, plan, options, result) -> None:
    """The archive of a run whose estimator was not checkpointed: an order search's chosen run, or a classical method's."""
    if options.method != "iekf":
        _archive_comparator(args, plan, result.estimator)
        return
    from vehid.identification.automatic.steps import iekf_options
    from vehid.identification.dataio.archive import write_archive
    from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE
    from vehid.identification.dataio.iekf_archive import write_iekf_run

    with write_archive(Path(args.out), kind=ARCHIVE_KIND, config=iekf_options(options), seeds=[]) as archive:
        archive.attrs[RUN_ATTRIBUTE] = args.output_run
        _archive_plan(archive, plan)
        _archive_decisions(archive, result.tuning, result.open_loop_unstable)
        write_iekf_run(archive, RUN_NAME, result.estimator)


def _finish(args, plan, result, archive_path=None) -> tuple[dict, str, object]:
    """Archive, model file and the text: the command's end of every identify run."""
    from vehid.identification.dataio.archive import run_group, update_archive, write_run
    from vehid.identification.dataio.storage import write_value
    from vehid.identification.dataio.iekf_archive import write_pass_history
    from vehid.identification.errors import StrictWarningsError
    from vehid.scenarios import scheduled_identify
    from vehid.scenarios.data_options import save_model
    from vehid.scenarios.model_checks import uncertainty_lines
    from vehid.scenarios.plausibility_checks import identify_findings, record_findings

    data = plan.records[0]
    summary = result.render()
    model = result.model
    warnings = list(result.warnings)
    findings = identify_findings(args, plan, model)
    if findings is not None:  # a car's model: named checks of its physics (JSON plausibility), as warnings
        record_findings(summary, warnings, findings)
        summary["warnings"] = list(warnings)
    nonlinear = result.nonlinear.result.model if result.nonlinear is not None else None
    scheduled = result.scheduled
    linear = result.unscheduled if result.unscheduled is not None else model
    if archive_path is not None:
        summary["archive"] = str(archive_path)
        own_run = RUN_NAME if result.is_iekf else args.method
        with update_archive(archive_path) as archive:  # one atomic update (each copies the archive)
            if nonlinear is not None:
                write_run(archive, "nonlinear", model=nonlinear)
                write_pass_history(archive, "nonlinear", result.nonlinear.result.history)
            if scheduled is not None:
                write_run(archive, "scheduled", model=scheduled.model)
                scheduled_identify.archive_schedule(archive, plan, VALIDATION_PREFIX)
            # the filter's model refined by its simulation error is a model of its own, beside the filter's
            refined = result.is_iekf and not result.start_returned and linear is not result.estimator.model
            if result.start_returned:
                write_run(archive, "start", model=linear)
            elif refined:
                write_run(archive, REFINED_RUN, model=linear)
            returned_run = REFINED_RUN if refined and result.returned == "filter" else \
                RETURNED_RUNS.get(result.returned, own_run)
            if result.residual_tests is not None:
                write_value(run_group(archive, returned_run), "residual_tests", result.residual_tests)
            _archive_verdict(archive, summary, args, returned=returned_run)
    if args.save_model:
        summary["model_file"] = str(save_model(model, args.save_model, plan.preparation))
    text = text_summary(summary, data, plan)
    if "modes" in summary:
        text += "\n" + "\n".join(uncertainty_lines(summary, data.output_names))
    if scheduled is not None:
        text += "\n" + "\n".join(scheduled_identify.text_lines(summary["scheduled"], data.output_names))
    try:
        emit(summary, warnings, args)
    except StrictWarningsError as exc:  # the summary is printed all the same, then the exit status says "warnings"
        exc.text = text
        raise
    return summary, text, model


SCORING_RULE = "scoring_rule"  # key of the archived summary only: how every model of the run is scored
#: the archive's run of each returned model (``Identification.returned``); the filter's is the IEKF's run
RETURNED_RUNS = {"filter": RUN_NAME, "start": "start", "scheduled": "scheduled", "nonlinear": "nonlinear"}
VERDICT = "summary_json"  # root attribute, as a study keeps its summary


def _archive_verdict(archive, summary: dict, args, *, returned: str) -> None:
    """The command's summary (scores, warnings) as the archive's ``summary_json``: what a report and a resume show.

    Beside the public keys it names the run whose model the command returned and
    the rule by which every model was scored (initial state, prediction horizon
    where one was given), so that a report scores the other runs the same way.
    """
    from vehid.identification.jsonable import to_jsonable

    verdict = {**summary, SCORING_RULE: {"initial_state": args.initial_state, "horizon": args.horizon,
                                         "returned_run": returned}}
    archive.attrs[VERDICT] = json.dumps(to_jsonable(verdict), allow_nan=False)


def _archive_comparator(args: argparse.Namespace, plan, outcome) -> Path:
    """The records and the comparator's model and fit, as ``runs/<method>`` of an identification archive."""
    from vehid.identification.dataio.archive import write_archive, write_run
    from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE

    path = Path(args.out)
    config = {"method": args.method, "order": outcome.model.n_states}
    with write_archive(path, kind=ARCHIVE_KIND, config=config, seeds=[]) as archive:
        archive.attrs[RUN_ATTRIBUTE] = args.output_run
        _archive_plan(archive, plan)
        run = write_run(archive, args.method, model=outcome.model, metrics=outcome.metrics)
        run.attrs["stop_reason"] = "finished"
        run.attrs["seconds"] = outcome.seconds
    return path


def emit(summary: dict[str, Any], warnings: list[str], args: argparse.Namespace) -> None:
    """Print the warnings (one line each) and raise under --strict."""
    import sys

    from vehid.identification.errors import StrictWarningsError

    summary["warnings"] = list(warnings)
    if args.strict and warnings:
        raise StrictWarningsError(warnings, summary)
    for line in warnings:
        print(f"vehid: warning: {line}", file=sys.stderr)


def _fits(names: tuple[str, ...], values: Any) -> str:
    """Each output's name and fit, or "-" where there is none."""
    if values is None:
        return "-"
    return ", ".join(f"{name} {value:.2f}" for name, value in zip(names, values))


def _fit_and_R(fit: Any, R: Any) -> str:
    """One output's NRMSE fit with its R labelled beside it (``-`` where there is none)."""
    if fit is None:
        return "-"
    return f"{fit:.2f}" + ("" if R is None else f" (R {R:.2f})")


def _at(values: Any, index: int) -> Any:
    return None if values is None else values[index]


#: what the text calls each model the command may return (``model_returned``)
RETURNED_TEXT = {"filter": "the IEKF's linear model", "start": "the IEKF's start model (linear)",
                 "scheduled": "the scheduled family", "nonlinear": "the spline-nonlinear model"}


def text_summary(summary: dict[str, Any], data, plan) -> str:
    """The text face: the model returned, its NRMSE fits (R beside) on estimation and validation data, the run."""
    import numpy as np

    from vehid.identification.automatic.steps import ORDER_TOLERANCE, P_TOLERANCE, decision_notes
    from vehid.identification.decisions import SCHEDULE_MARGIN

    eigen = ", ".join(
        f"{v.real:.4g}{v.imag:+.4g}j" if v.imag else f"{v.real:.4g}" for v in np.asarray(summary["eigenvalues"], dtype=complex)
    )
    stop = summary.get("stop_reason")
    converged = "converged" if stop == "converged" else (f"NOT converged ({stop})" if stop else "direct method (no iterations)")
    kind = summary.get("time_domain", "continuous")
    returned = summary.get("model_returned", summary["method"])
    linear_returned = returned not in ("scheduled", "nonlinear")
    lines = [
        f"model returned: {RETURNED_TEXT.get(returned, returned)}, order {summary['order']}"
        + ("" if linear_returned else f" (the linear {summary['method']} model it started from is not returned)"),
        f"{summary['method']}: order {summary['order']}, {summary['passes_run']} passes, "
        f"{summary['discretization']} discretisation, {summary['seconds']:.2f} s, {converged}",
        f"eigenvalues ({kind}-time{'' if linear_returned else ', of the linear model'}): {eigen}",
    ]
    how = (f"{summary['horizon']}-step-ahead prediction" if summary.get("horizon")
           else f"simulation, initial state {summary.get('initial_state', 'zero')}")
    lines.append(f"{'NRMSE fit %':<14} {'estimation':>28} {'validation':>28}   ({how}; R of eq. 17 beside)")
    for i, name in enumerate(data.output_names):
        est = _fit_and_R(summary["estimation_fit_percent"][i], _at(summary.get("estimation_R"), i))
        val = _fit_and_R(_at(summary.get("validation_fit_percent"), i), _at(summary.get("validation_R"), i))
        lines.append(f"{name:<14} {est:>28} {val:>28}")
    unstable = np.any(np.asarray(summary["eigenvalues"], dtype=complex).real > 0) and linear_returned
    lines.append(
        "simulated from rest over the estimation data (continuous model, exact): NRMSE fit "
        + ", ".join(f"{name} {_fit_and_R(fit, R)}" for name, fit, R in zip(data.output_names, summary["fit_percent"],
                                                                            summary["R"])) + " %"
        + (" (an unstable model's simulation diverges: the k-step scores above measure it)" if unstable else ""))
    if plan.validation:
        lines.append("validation on: " + "; ".join(plan.validation_names))
    for note in summary.get("notes", decision_notes(summary)):
        lines.append(f"note: {note}")
    if summary.get("p_tried"):
        tried = ", ".join(f"{row['p']:g}" + (f" {row['q_schedule']}" if "q_schedule" in row else "") + ": "
                          + ("failed" if row["cv_fit_percent"] is None else f"{row['cv_fit_percent']:.2f}")
                          for row in summary["p_tried"])
        lines.append(f"p {summary['p']:g}, {summary.get('q_schedule', 'constant')} Q, by two-fold cross-validation "
                     f"(NRMSE fit %: {tried}; a shrinking Q unless a constant one is {SCHEDULE_MARGIN:g} points better, "
                     f"the largest p within {P_TOLERANCE} points of its best), {summary['tuning_seconds']:.1f} s")
    if summary.get("scoring_note"):
        lines.append(f"note: {summary['scoring_note']}")
    for note in plan.notes:
        lines.append(f"note: {note}")
    if summary.get("orders_tried") and len(summary["orders_tried"]) > 1:
        tried = ", ".join(
            f"n={row['order']}: " + (f"{row['ranking_fit']:.2f}" if "ranking_fit" in row else "failed")
            for row in summary["orders_tried"])
        lines.append(f"orders tried (mean validation NRMSE fit %): {tried}; chosen {summary['order']} "
                     f"(smallest within {ORDER_TOLERANCE} points of the best)")
    if "nonlinear" in summary:
        nl = summary["nonlinear"]
        lines.append(f"nonlinear (spline, {nl['nodes']} nodes, p {nl['p']:g}, {nl['passes_run']} passes, "
                     f"{'converged' if nl['stop_reason'] == 'converged' else 'NOT converged'}"
                     f"{', returned' if returned == 'nonlinear' else ', NOT returned'}): NRMSE fit "
                     f"estimation {_fits(data.output_names, nl['estimation_fit_percent'])}; "
                     f"validation {_fits(data.output_names, nl['validation_fit_percent'])} %")
    if "model_file" in summary:
        lines.append(f"wrote {summary['model_file']}")
    return "\n".join(lines)
