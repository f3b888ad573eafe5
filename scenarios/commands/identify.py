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
summary gives the eigenvalues, the
fit R (eq. 17) per output of the continuous model simulated exactly, NRMSE
fits on estimation and validation data (--validation, --validation-file),
whether the run converged, any warnings (--strict: the summary, then exit status 3), the
matrices and the run time. --order takes a number, a range (2-8) or auto,
chosen on validation data; --nonlinear adds the spline-nonlinear model. It
also says how sure the model is (scenarios.model_checks): each mode with
standard deviations (text: value +/- 2 sigma; JSON: the list `modes`), the
residual tests per output (`residual_whiteness_p`, `input_correlation_max`)
and, for the IEKF, the innovation NIS per pass with its band.

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

import numpy as np

from vehid.identification.dataio.archive import (open_archive, read_records, run_group, update_archive, write_archive,
                                          write_run)
from vehid.identification.dataio.archive_safety import RUN_ATTRIBUTE, archive_lock, check_output_target
from vehid.identification.errors import InputError, StrictWarningsError
from vehid.identification.filtering.filter_models import DISCRETIZATIONS
from vehid.identification.filtering.iekf import TIMESCALES, identify_iekf
from vehid.identification.filtering.iekf_archive import Checkpointer, read_iekf_run, write_pass_history
from vehid.identification.filtering.iekf_pass import COVARIANCE_FORMS
from vehid.identification.jsonable import to_jsonable
from vehid.identification.models.modal import C_PATTERNS, ModalModel
from vehid.identification.assessment.multirecord import pooled_simulation_fit
from vehid.identification.pipeline import DEFAULT_NODES, DEFAULT_NONLINEAR_PASSES, DEFAULT_PASSES
from vehid.identification.dataio.preparation import prepare_validation, read_record
from vehid.identification.dataio.storage import write_value
from vehid.identification.assessment.validation import INITIAL_STATES
from vehid.scenarios import identify_workflow as workflow
from vehid.scenarios import schedule_channel, scheduled_identify
from vehid.scenarios import single_track_identify as single_track
from vehid.scenarios.data_options import (RECORD_PREFIX, archive_records, archived_preparation, record_series,
                                          check_model_target, records_summary, register_data_options, save_model,
                                          settings_from_args, write_record_series, data_warnings)
from vehid.scenarios.model_checks import uncertainty_lines, uncertainty_summary
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE, run_digest
from vehid.scenarios.progress import Progress

NAME = "identify"
GROUP = None
HELP = "identify a modal state-space model from a data file (IEKF by default)"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", nargs="*", help="data files: .h5, .csv, .dat, .txt, .mat, .mf4 (several: one model)")
    parser.add_argument("--inputs", help="comma-separated input column names")
    parser.add_argument("--outputs", help="comma-separated output column names")
    parser.add_argument("--order", default="4", help="model order n, a range such as 2-8, or auto (default 4)")
    parser.add_argument("--pattern", choices=C_PATTERNS,
                        help="C pattern, complex pairs first (without it: with --start data the start model's complex "
                             "pairs and real poles, else the default pattern; either way modes tied to outputs in turn)")
    parser.add_argument("--method", default="iekf", choices=("iekf", "arx", "rls", "n4sid", "output-error"),
                        help="estimator: the IEKF (default) or a classical comparator on the same data")
    parser.add_argument("--passes", type=int, default=None,
                        help=f"largest number of passes (default {DEFAULT_PASSES}; with --resume, the run's own)")
    parser.add_argument("--p", type=float, default=None,
                        help="tuning parameter p: Q = p I' (default: 1e-4, 1e-5 or 1e-6 per dominant time constant, chosen by "
                             "two-fold cross-validation on the estimation data; 1 with --timescale seconds)")
    parser.add_argument("--discretization", default="exact", choices=DISCRETIZATIONS, help="filter discretisation (default exact)")
    parser.add_argument("--covariance", default="joseph", choices=COVARIANCE_FORMS, help="covariance numerics (default joseph)")
    parser.add_argument("--start", default="data", choices=workflow.START_CHOICES, help=workflow.START_HELP)
    parser.add_argument("--normalize", action=argparse.BooleanOptionalAction, default=True,
                        help="scale inputs and outputs by their RMS while filtering (default on)")
    parser.add_argument("--save-model", help=f"write the model to this .json or .mat file ({OUT_RULE})")
    parser.add_argument("--out", help=f"HDF5 archive of the run, checkpointed after every pass ({OUT_RULE})")
    parser.add_argument("--force", action="store_true",
                        help="let --out and --save-model replace an existing file that is not this run's own output")
    parser.add_argument("--resume", metavar="ARCHIVE",
                        help="continue the run checkpointed in ARCHIVE (its data and settings; --passes counts all passes)")
    parser.add_argument("--bootstrap", type=int, metavar="N",
                        help="with --method n4sid: residual-bootstrap replicates for its parameter covariance, each "
                             "one subspace fit (default: none, the asymptotic covariance of its simulation errors; "
                             "0 for no covariance)")
    parser.add_argument("--structure", default="modal", choices=single_track.STRUCTURES,
                        help="model structure: modal (default) or single-track (a car's physical parameters)")
    register_data_options(parser)
    register_pipeline_options(parser)
    scheduled_identify.register_options(parser)
    single_track.register_options(parser)
    parser.set_defaults(handler=run)


def register_pipeline_options(parser: argparse.ArgumentParser) -> None:
    """The validation, order, model-class and warning options of `vehid identify`."""
    parser.add_argument("--validation", type=float, metavar="FRACTION",
                        help="hold out the last FRACTION of the record for validation (e.g. 0.3)")
    parser.add_argument("--validation-file", action="append", default=[], metavar="FILE",
                        help="validate on this record too (repeatable; same columns)")
    parser.add_argument("--validation-inputs", metavar="NAMES",
                        help="the input channels' names in the validation files, where they differ")
    parser.add_argument("--validation-outputs", metavar="NAMES",
                        help="the output channels' names in the validation files, where they differ")
    parser.add_argument("--initial-state", default="estimate", choices=INITIAL_STATES,
                        help="simulate linear models from a least-squares initial state (default) or from rest")
    parser.add_argument("--horizon", type=int, metavar="K",
                        help="score by K-step-ahead prediction instead of simulation (automatic for unstable models)")
    parser.add_argument("--allow-unstable", action="store_true",
                        help="keep unstable modes (open-loop unstable plants) instead of stopping")
    parser.add_argument("--timescale", default="auto", choices=TIMESCALES,
                        help="filter time unit: auto (samples; p per dominant time constant, default) or seconds (absolute, the paper's)")
    parser.add_argument("--nonlinear", action="store_true",
                        help="after the linear model, identify the spline-nonlinear model started from it")
    parser.add_argument("--nodes", type=int, default=DEFAULT_NODES,
                        help=f"nodes per spline with --nonlinear (default {DEFAULT_NODES})")
    parser.add_argument("--nonlinear-p", type=float, action="append", metavar="P",
                        help="tuning parameter(s) of the spline model; several are tried and one chosen on "
                             "validation data (default 1e-7, or 1e-7, 1e-8, 1e-9 with validation data)")
    parser.add_argument("--nonlinear-passes", type=int, default=DEFAULT_NONLINEAR_PASSES,
                        help=f"largest number of nonlinear passes (default {DEFAULT_NONLINEAR_PASSES})")
    parser.add_argument("--strict", action="store_true", help="exit with status 3 when the run ends with warnings")


RUN_NAME = "iekf"
ARCHIVE_KIND = "identification"
VALIDATION_PREFIX = "validation"


def _resume(args: argparse.Namespace):
    """Plan, structure, options and the finished passes of a checkpointed run."""
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
    plan = workflow.make_plan(args, records, load, held_out=held_out, preparation=preparation)
    if judged:  # the run goes on: a verdict on fewer passes must not outlive it (a kill would leave it stale)
        with update_archive(args.resume) as archive:
            del archive.attrs[VERDICT]
    return plan, previous.structure, options, previous, decisions


def run(args: argparse.Namespace) -> tuple[dict, str]:
    if args.structure == "single-track":
        return single_track.run(args)
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


DECISIONS = "decisions_json"  # root attribute: the p tuning and the stability decision taken before the passes


def _archive_decisions(archive, tuning, unstable) -> None:
    """What the run decided before its passes, so that a resumed run returns and warns as the original did."""
    archive.attrs[DECISIONS] = json.dumps(to_jsonable({"tuning": tuning, "open_loop_unstable": unstable}),
                                          allow_nan=False)


def _read_decisions(archive) -> tuple:
    """The archived ``(tuning, unstable)`` of a run; ``(None, None)`` for an archive written before they were kept."""
    if DECISIONS not in archive.attrs:
        return None, None
    try:
        stored = json.loads(archive.attrs[DECISIONS])
        tuning = stored["tuning"]
        return (workflow.PTuning(p=float(tuning["p"]), tried=tuple(tuning["tried"]), seconds=float(tuning["seconds"]),
                                 start_fit=tuning["start_fit"], q_schedule=tuning.get("q_schedule", "constant")),
                stored["open_loop_unstable"])
    except (ValueError, KeyError, TypeError):
        raise InputError(f"{archive.filename} holds an unreadable record of the run's decisions") from None


def _archive_plan(archive, plan) -> None:
    """The prepared estimation records, the preparation and the held-out parts (what a resume needs)."""
    archive_records(archive, plan.records, plan.preparation)
    write_record_series(archive, plan.validation[:plan.held_out_count], VALIDATION_PREFIX)


def identify_run(args, plan=None) -> tuple[dict, str, object]:
    """The whole run: summary, text and the model returned; ``plan`` given, its records are identified instead of
    the DATA files' (the library's :func:`~vehid.scenarios.identify_workflow.identify`)."""
    previous, unstable = None, None
    if args.resume:
        plan, structure, options, previous, (tuning, unstable) = _resume(args)
        if tuning is None:  # an archive written before the tuning was kept: the run's own p, as archived
            tuning = workflow.given_p(options)
        # the archived options run the passes; an archive written before the schedule was kept names it by them
        tuning = dataclasses.replace(tuning, q_schedule=workflow.q_schedule_of(options))
        archive_path = Path(args.resume)
    else:
        if plan is None:
            if not args.data:
                raise InputError("give a DATA file (or --resume ARCHIVE)")
            plan = workflow.load_plan(args, args.data)
        if args.method != "iekf":
            return _run_comparator(args, plan)
        options = workflow.iekf_options(args, DEFAULT_PASSES)
        if len(plan.orders) > 1:
            return _run_order_search(args, plan, options)
        options, unstable = workflow.assume_unstable(args, plan, options, plan.orders[0])
        structure = workflow.structure_for(args, plan.orders[0], plan, options)
        tuning = workflow.tune_p(args, plan, options, structure) if workflow.tunes_p(args) else workflow.given_p(options)
        options = tuning.applied(options)
        archive_path = Path(args.out) if args.out else None
        if archive_path is not None:
            with write_archive(archive_path, kind=ARCHIVE_KIND, config=options, seeds=[]) as archive:
                archive.attrs[RUN_ATTRIBUTE] = args.output_run
                _archive_plan(archive, plan)
                _archive_decisions(archive, tuning, unstable)
    checkpoint = Checkpointer(archive_path, RUN_NAME) if archive_path is not None else None
    done = previous.passes_run if previous is not None else 0
    with Progress(options.passes, "IEKF passes", enabled=None if not args.quiet else False) as progress:
        progress.advance(done)

        def on_pass(record, so_far):
            if checkpoint is not None:
                checkpoint(record, so_far)
            progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

        result, divergence = workflow.last_good_on_divergence(
            lambda: identify_iekf(plan.estimation, structure, options=options, resume=previous, on_pass=on_pass,
                                  settle_start=plan.settle_start))
    if checkpoint is not None:
        checkpoint.finish(result)  # the archive says how the run ended: converged, passes or diverged at pass k
    model, keys = workflow.returned_model(result, plan, args, tuning, unstable)
    summary = {**_iekf_summary(result), **tuning.summary(), **keys}
    if divergence:
        summary["divergence"] = divergence
    return _finish(args, plan, summary, model, result=result, archive_path=archive_path)


def _iekf_summary(result) -> dict:
    """The IEKF run's summary keys (the public contract of `vehid identify --json`)."""
    model = result.model
    return {
        "method": "iekf",
        "order": result.structure.n,
        "eigenvalues": model.eigenvalues(),
        "fit_percent": result.fit_percent,
        "fit_percent_filter": result.history[-1].fit_filter,
        "passes_run": result.passes_run,
        "stop_reason": result.stop_reason,
        "discretization": result.options.discretization,
        **_matrices(model),
        "seconds": result.seconds,
    }


def _matrices(model) -> dict:
    """The summary's ``A``, ``B``, ``C`` and ``D`` of the model returned."""
    return {"A": model.A, "B": model.B, "C": model.C, "D": model.D}


def _finish(args, plan, summary: dict, model, *, result=None, archive_path=None) -> tuple[dict, str, object]:
    """Scores, warnings, the nonlinear model, archive and model file: the common end of every identify run."""
    data = plan.records[0]
    start_returned = result is not None and model is not result.model
    if start_returned:  # the summary describes the model returned
        summary.update(eigenvalues=model.eigenvalues(), **_matrices(model),
                       fit_percent=pooled_simulation_fit(model, plan.records), model_returned="start")
    evaluation = workflow.evaluate(model, plan, args)
    summary.update(workflow.scores_summary(evaluation, summary["fit_percent"]))
    summary.update(records_summary(model, plan.records, plan.preparation))
    tests = None
    if isinstance(model, ModalModel):  # how sure the model is; on the (first) estimation record
        checks, tests = uncertainty_summary(model, data, [record.nis for record in result.history] if result else None)
        summary.update(checks)
    summary.setdefault("orders_tried", [{"order": summary["order"], "fit_percent": summary["fit_percent"],
                                         "estimation_fit_percent": evaluation.estimation.fit,
                                         "validation_fit_percent": evaluation.validation_fit,
                                         "seconds": summary["seconds"]}])
    allow_unstable = bool(getattr(args, "allow_unstable", False)) or (
        result is not None and result.options.allow_unstable)
    # modes that never left their start are a problem of the run, whichever of the two models is returned
    start_fit, start_moved = workflow.start_of(result, plan.records) if result is not None else (None, None)
    summary["notes"] = workflow.decision_notes(summary)  # choices made for the user: said once, not warnings
    warnings = workflow.run_warnings(
        model=model, evaluation=evaluation, start_fit=start_fit,
        stop_reason=None if start_returned else (f"{summary['stop_reason']}: {summary['divergence']}"
                                                 if "divergence" in summary else summary.get("stop_reason")),
        final_fit=float(np.mean(summary["fit_percent"])) if result is not None else None,
        allow_unstable=allow_unstable, start_moved=start_moved, p_tuned=bool(summary.get("p_tried")),
        fit_history=[record.mean_fit_continuous for record in result.history] if result is not None else None,
    )
    if result is not None and not start_returned:  # a pass that diverged and ran again with a smaller p
        warnings += list(result.meta.get("notes", ()))
    if evaluation.horizon is not None and args.horizon is None:
        summary["scoring_note"] = (f"the model is unstable: scored by {evaluation.horizon}-step-ahead prediction, "
                                   "since its simulation diverges (--horizon K to choose K)")
    if result is not None:
        summary["start"] = {k: v for k, v in result.meta.items() if k != "start_parameters"}
    nonlinear = None
    if args.nonlinear:
        outcome = workflow.identify_nonlinear(model, plan, args)
        nonlinear = outcome.result.model
        summary["nonlinear"] = outcome.summary
        scores = outcome.scores
        warnings += workflow.run_warnings(
            model=nonlinear, evaluation=workflow.Evaluation(
                scores.estimation, scores.estimation.R, scores.validation, None),
            stop_reason=outcome.result.stop_reason, start_fit=float(np.mean(outcome.result.start_fit)),
            final_fit=float(np.mean(outcome.result.fit_percent)), allow_unstable=True, label="nonlinear")
        warnings += workflow.nonlinear_warnings(outcome, evaluation)
    warnings += data_warnings(plan.records)
    scheduled, unscheduled = None, model
    if args.schedule:  # the scheduled family, started from the model above, returned where it validates better
        scheduled = scheduled_identify.identify_scheduled_model(model, plan, args, evaluation)
        summary.update(scheduled=scheduled.summary)
        summary.setdefault("decision_margins", {})["schedule"] = scheduled.margin
        warnings += scheduled.warnings
        if nonlinear is not None:
            summary["notes"].append(scheduled_identify.NONLINEAR_NOTE)
        if scheduled.returned:
            summary.update(scheduled.scores)
            model = scheduled.model
    summary["warnings"] = list(warnings)
    if archive_path is not None:
        summary["archive"] = str(archive_path)
        with update_archive(archive_path) as archive:  # one atomic update (each copies the archive)
            if nonlinear is not None:
                write_run(archive, "nonlinear", model=nonlinear)
                write_pass_history(archive, "nonlinear", outcome.result.history)
            if scheduled is not None:
                write_run(archive, "scheduled", model=scheduled.model)
            if start_returned:
                write_run(archive, "start", model=unscheduled)
            if tests is not None:
                write_value(run_group(archive, RUN_NAME if result is not None else args.method),
                            "residual_tests", tests)
            returned_scheduled = scheduled is not None and scheduled.returned
            _archive_verdict(archive, summary, args, returned="scheduled" if returned_scheduled else (
                "start" if start_returned else (RUN_NAME if result is not None else args.method)))
    if args.save_model:
        summary["model_file"] = str(save_model(model, args.save_model, plan.preparation))
    text = workflow.text_summary(summary, data, plan)
    if "modes" in summary:
        text += "\n" + "\n".join(uncertainty_lines(summary, data.output_names))
    if scheduled is not None:
        text += "\n" + "\n".join(scheduled_identify.text_lines(summary["scheduled"], data.output_names))
    try:
        workflow.emit(summary, warnings, args)
    except StrictWarningsError as exc:  # the summary is printed all the same, then the exit status says "warnings"
        exc.text = text
        raise
    return summary, text, model


SCORING_RULE = "scoring_rule"  # key of the archived summary only: how every model of the run is scored
VERDICT = "summary_json"  # root attribute, as a study keeps its summary


def _archive_verdict(archive, summary: dict, args, *, returned: str) -> None:
    """The command's summary (scores, warnings) as the archive's ``summary_json``: what a report and a resume show.

    Beside the public keys it names the run whose model the command returned and
    the rule by which every model was scored (initial state, prediction horizon
    where one was given), so that a report scores the other runs the same way.
    """
    verdict = {**summary, SCORING_RULE: {"initial_state": args.initial_state, "horizon": args.horizon,
                                         "returned_run": returned}}
    archive.attrs[VERDICT] = json.dumps(to_jsonable(verdict), allow_nan=False)


def _run_order_search(args, plan, options) -> tuple[dict, str, object]:
    """Each order of a range identified on the estimation data; one chosen on validation data."""
    rows, kept = workflow.search_orders(
        plan, lambda order: workflow.run_iekf_order(args, plan, options, order), args)
    chosen = workflow.choose_order(rows)
    model, extra, _ = kept[chosen]
    result = extra["result"]
    summary = {**_iekf_summary(result), **extra["tuning"].summary(), "orders_tried": rows,
               "seconds": sum(row["seconds"] for row in rows),
               **{key: extra[key] for key in ("open_loop_unstable", "start_kept", "decision_margins") if key in extra}}
    summary["decision_margins"] = {**summary.get("decision_margins", {}), "order": workflow.order_margin(rows, chosen)}
    archive_path = Path(args.out) if args.out else None
    if archive_path is not None:
        from vehid.identification.filtering.iekf_archive import write_iekf_run

        with write_archive(archive_path, kind=ARCHIVE_KIND, config=options, seeds=[]) as archive:
            archive.attrs[RUN_ATTRIBUTE] = args.output_run
            _archive_plan(archive, plan)
            _archive_decisions(archive, extra["tuning"], extra.get("open_loop_unstable"))
            write_iekf_run(archive, RUN_NAME, result)
    return _finish(args, plan, summary, model, result=result, archive_path=archive_path)


def _run_comparator(args: argparse.Namespace, plan) -> tuple[dict, str, object]:
    from vehid.identification.classical.comparators import identify_with

    outcomes = {}

    if args.bootstrap is not None and args.method != "n4sid":
        raise InputError("--bootstrap applies to --method n4sid (the other methods' covariances cost no refits)")
    options = {"bootstrap": args.bootstrap} if args.bootstrap is not None else {}

    def fit_one(order):
        outcome = identify_with(plan.estimation, method=args.method, order=order, **options)
        outcomes[order] = outcome
        return outcome.model, {"fit_percent": outcome.metrics.percentage_explanation}

    rows = None
    if len(plan.orders) == 1:
        chosen = plan.orders[0]
        fit_one(chosen)  # errors carry their own exit status
    else:
        rows, _ = workflow.search_orders(plan, fit_one, args)
        chosen = workflow.choose_order(rows)
    outcome = outcomes[chosen]
    model = outcome.model
    summary = {
        "method": args.method,
        "order": chosen,
        "eigenvalues": model.eigenvalues(),
        "fit_percent": outcome.metrics.percentage_explanation,
        "passes_run": 0,
        "discretization": "exact",
        "time_domain": model.meta.get("time_domain", "continuous"),
        **_matrices(model),
        "seconds": outcome.seconds,
    }
    if rows is not None:
        summary["orders_tried"] = rows
        summary["decision_margins"] = {"order": workflow.order_margin(rows, chosen)}
    archive_path = _archive_comparator(args, plan, outcome) if args.out else None
    return _finish(args, plan, summary, model, archive_path=archive_path)


def _archive_comparator(args: argparse.Namespace, plan, outcome) -> Path:
    """The records and the comparator's model and fit, as ``runs/<method>`` of an identification archive."""
    path = Path(args.out)
    config = {"method": args.method, "order": outcome.model.n_states}
    with write_archive(path, kind=ARCHIVE_KIND, config=config, seeds=[]) as archive:
        archive.attrs[RUN_ATTRIBUTE] = args.output_run
        _archive_plan(archive, plan)
        run = write_run(archive, args.method, model=outcome.model, metrics=outcome.metrics)
        run.attrs["stop_reason"] = "finished"
        run.attrs["seconds"] = outcome.seconds
    return path
