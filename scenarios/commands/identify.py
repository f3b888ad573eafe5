"""Identify a modal state-space model from an input/output record.

DATA is a workbench HDF5 file (as written by `vehid simulate --out`) or a CSV
file with a header row. Name the columns with --inputs and --outputs (for an
HDF5 record they select among its inputs and outputs; for a CSV they are
required); time comes from a column `t` or from --dt.

The default method is the Identifying EKF (Best & Bogdanski 2017) with the
exact first-order-hold discretisation, so the identified parameters are those
of the continuous-time model; --discretization euler reproduces the paper's
filter. The defaults do not depend on the units of time or of the signals:
signals normalised (--no-normalize to switch off), start values from a
subspace model of the record (--start paper for the paper's), time counted
in samples inside the filter and p per dominant time constant (--timescale
seconds for the absolute behaviour). The summary gives the eigenvalues, the
fit R (eq. 17) per output of the continuous model simulated exactly, NRMSE
fits on estimation and validation data (--validation, --validation-file),
whether the run converged, any warnings (--strict: exit status 3), the
matrices and the run time. --order takes a number, a range (2-8) or auto,
chosen on validation data; --nonlinear adds the spline-nonlinear model.

With --out ARCHIVE the record and every finished pass are written to an HDF5
archive as the run goes (atomically, so a killed run leaves the archive of
its last finished pass); --resume ARCHIVE continues such a run from there
with the same data and settings, and reaches the same parameters as a run
that was never interrupted.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from identification import read_csv, read_hdf5
from identification.errors import InputError
from identification.filter_models import DISCRETIZATIONS
from identification.iekf import identify_iekf
from identification.archive import open_archive, read_records, write_archive, write_record
from identification.iekf_archive import Checkpointer, read_iekf_run
from identification.iekf_pass import COVARIANCE_FORMS
from identification.modal import C_PATTERNS, ModalStructure
from scenarios import identify_workflow as workflow
from scenarios.progress import Progress

NAME = "identify"
GROUP = None
HELP = "identify a modal state-space model from a data file (IEKF by default)"


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise InputError("an empty column list was given")
    return names


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", nargs="?", help="workbench HDF5 file or CSV file with a header row")
    parser.add_argument("--inputs", help="comma-separated input column names")
    parser.add_argument("--outputs", help="comma-separated output column names")
    parser.add_argument("--dt", type=float, help="sample interval in s (CSV without a time column)")
    parser.add_argument("--order", default="4", help="model order n, a range such as 2-8, or auto (default 4)")
    parser.add_argument("--pattern", default="default", choices=C_PATTERNS, help="C pattern (default: pairs tied to outputs in turn)")
    parser.add_argument("--method", default="iekf", choices=("iekf", "arx", "rls", "n4sid", "output-error"),
                        help="estimator: the IEKF (default) or a classical comparator on the same data")
    parser.add_argument("--passes", type=int, default=50, help="largest number of passes (default 50)")
    parser.add_argument("--p", type=float, default=None,
                        help="tuning parameter p: Q = p I' (default 1e-4 per dominant time constant; 1 with --timescale seconds)")
    parser.add_argument("--discretization", default="exact", choices=DISCRETIZATIONS, help="filter discretisation (default exact)")
    parser.add_argument("--covariance", default="joseph", choices=COVARIANCE_FORMS, help="covariance numerics (default joseph)")
    parser.add_argument("--start", default="data", choices=workflow.START_CHOICES, help=workflow.START_HELP)
    parser.add_argument("--normalize", action=argparse.BooleanOptionalAction, default=True,
                        help="scale inputs and outputs by their RMS while filtering (default on)")
    parser.add_argument("--save-model", help="write the model to this .json or .mat file")
    parser.add_argument("--out", help="HDF5 archive of the run, checkpointed after every pass")
    parser.add_argument("--resume", metavar="ARCHIVE",
                        help="continue the run checkpointed in ARCHIVE (its data and settings; --passes counts all passes)")
    workflow.register_options(parser)
    parser.set_defaults(handler=run)


def load_record(path: str, inputs: list[str] | None, outputs: list[str] | None, dt: float | None):
    """Read DATA as the identify command does: HDF5 or CSV, columns selected by name."""
    suffix = Path(path).suffix.lower()
    if suffix in (".h5", ".hdf5", ".hdf"):
        if dt is not None:
            raise InputError("--dt applies to CSV files; an HDF5 record carries its own time base")
        data = read_hdf5(path)
        if inputs:
            data = data.select_inputs(inputs)
        if outputs:
            data = data.select_outputs(outputs)
        return data
    if suffix == ".csv":
        if not inputs or not outputs:
            raise InputError("a CSV file needs --inputs and --outputs naming its columns")
        return read_csv(path, inputs=inputs, outputs=outputs, dt=dt)
    raise InputError(f"unknown data file type {suffix or '(none)'!r}: give a .h5 or .csv file")


RUN_NAME = "iekf"


def _resume(args: argparse.Namespace):
    """Data, structure, options and the finished passes of a checkpointed run."""
    if args.data is not None:
        raise InputError("--resume takes its data from the archive: give no DATA file")
    with open_archive(args.resume, kinds=["identification"]) as archive:
        previous = read_iekf_run(archive, RUN_NAME)
        records = read_records(archive)
    if "identification" not in records:
        raise InputError(f"{args.resume} holds no identification record to resume on")
    options = dataclasses.replace(previous.options, passes=max(args.passes, previous.passes_run))
    return records["identification"], previous.structure, options, previous, records.get("validation")


def run(args: argparse.Namespace) -> tuple[dict, str]:
    previous = None

    def load(path: str):
        return load_record(path, _names(args.inputs), _names(args.outputs), args.dt)

    if args.resume:
        data, structure, options, previous, held_out = _resume(args)
        plan = workflow.make_plan(args, data, load, held_out=held_out)
        archive_path = Path(args.resume)
    else:
        if args.data is None:
            raise InputError("give a DATA file (or --resume ARCHIVE)")
        plan = workflow.make_plan(args, load(args.data), load)
        data = plan.estimation
        if args.method != "iekf":
            return _run_comparator(args, plan)
        options = workflow.iekf_options(args)
        if len(plan.orders) > 1:
            return _run_order_search(args, plan, options)
        structure = ModalStructure.from_pattern(args.pattern, plan.orders[0], data.n_u, data.n_y)
        archive_path = Path(args.out) if args.out else None
        if archive_path is not None:
            with write_archive(archive_path, kind="identification", config=options, seeds=[]) as archive:
                write_record(archive, "identification", data)
                if args.validation is not None:
                    write_record(archive, "validation", plan.validation[0])
    checkpoint = Checkpointer(archive_path, RUN_NAME) if archive_path is not None else None
    done = previous.passes_run if previous is not None else 0
    with Progress(options.passes, "IEKF passes", enabled=None if not args.quiet else False) as progress:
        progress.advance(done)

        def on_pass(record, so_far):
            if checkpoint is not None:
                checkpoint(record, so_far)
            progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

        result, divergence = workflow.last_good_on_divergence(
            lambda: identify_iekf(data, structure, options=options, resume=previous, on_pass=on_pass))
    summary = _iekf_summary(result)
    if divergence:
        summary["divergence"] = divergence
    return _finish(args, plan, summary, result.model, result=result, archive_path=archive_path)


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
        "A": model.A,
        "B": model.B,
        "C": model.C,
        "D": model.D,
        "seconds": result.seconds,
    }


def _finish(args, plan, summary: dict, model, *, result=None, archive_path=None) -> tuple[dict, str]:
    """Scores, warnings, the nonlinear model, archive and model file: the common end of every identify run."""
    data = plan.estimation
    evaluation = workflow.evaluate(model, plan, args)
    summary.update(workflow.scores_summary(evaluation, summary["fit_percent"]))
    summary.setdefault("orders_tried", [{"order": summary["order"], "fit_percent": summary["fit_percent"],
                                         "estimation_fit_percent": evaluation.estimation.fit,
                                         "validation_fit_percent": evaluation.validation_fit,
                                         "seconds": summary["seconds"]}])
    allow_unstable = bool(getattr(args, "allow_unstable", False)) or (
        result is not None and result.options.allow_unstable)
    start_fit, start_moved = workflow.start_of(result, data) if result is not None else (None, None)
    warnings = workflow.run_warnings(
        model=model, evaluation=evaluation, start_fit=start_fit,
        stop_reason=(f"{summary['stop_reason']}: {summary['divergence']}" if "divergence" in summary
                     else summary.get("stop_reason")),
        final_fit=float(summary["fit_percent"].mean()) if result is not None else None,
        allow_unstable=allow_unstable, start_moved=start_moved,
    )
    if evaluation.horizon is not None and args.horizon is None:
        summary["scoring_note"] = (f"the model is unstable: scored by {evaluation.horizon}-step-ahead prediction, "
                                   "since its simulation diverges (--horizon K to choose K)")
    if result is not None:
        summary["start"] = {k: v for k, v in result.meta.items() if k != "start_parameters"}
    if args.nonlinear:
        from identification.archive import update_archive, write_run

        outcome = workflow.identify_nonlinear(model, plan, args)
        summary["nonlinear"] = outcome.summary
        warnings += workflow.run_warnings(
            model=outcome.result.model, evaluation=workflow.Evaluation(
                workflow.score(outcome.result.model, data, initial_state="zero"), outcome.summary["fit_percent"],
                tuple(workflow.score(outcome.result.model, r, initial_state="zero") for r in plan.validation), None),
            stop_reason=outcome.result.stop_reason, start_fit=float(np.mean(outcome.result.start_fit)),
            final_fit=float(np.mean(outcome.result.fit_percent)), allow_unstable=True, label="nonlinear")
        if archive_path is not None:
            with update_archive(archive_path) as archive:
                write_run(archive, "nonlinear", model=outcome.result.model)
    if archive_path is not None:
        summary["archive"] = str(archive_path)
    if args.save_model:
        summary["model_file"] = str(_save_model(model, args.save_model))
    workflow.emit(summary, warnings, args)
    return summary, workflow.text_summary(summary, data, plan)


def _run_order_search(args, plan, options) -> tuple[dict, str]:
    """Each order of a range identified on the estimation data; one chosen on validation data."""
    rows, kept = workflow.search_orders(
        plan, lambda order: workflow.run_iekf_order(args, plan.estimation, options, order), args)
    chosen = workflow.choose_order(rows)
    model, extra, _ = kept[chosen]
    result = extra["result"]
    summary = {**_iekf_summary(result), "orders_tried": rows, "seconds": sum(row["seconds"] for row in rows)}
    archive_path = Path(args.out) if args.out else None
    if archive_path is not None:
        from identification.iekf_archive import write_iekf_run

        with write_archive(archive_path, kind="identification", config=options, seeds=[]) as archive:
            write_record(archive, "identification", plan.estimation)
            write_iekf_run(archive, RUN_NAME, result)
    return _finish(args, plan, summary, model, result=result, archive_path=archive_path)


def _save_model(model, target: str) -> Path:
    path = Path(target)
    if path.suffix.lower() == ".mat":
        return model.save_mat(path)
    if path.suffix.lower() == ".json":
        return model.save_json(path)
    raise InputError(f"--save-model takes a .json or .mat file; got {target!r}")


def _run_comparator(args: argparse.Namespace, plan) -> tuple[dict, str]:
    from identification.comparators import identify_with

    outcomes = {}

    def fit_one(order):
        outcome = identify_with(plan.estimation, method=args.method, order=order)
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
        "A": model.A,
        "B": model.B,
        "C": model.C,
        "D": model.D,
        "seconds": outcome.seconds,
    }
    if rows is not None:
        summary["orders_tried"] = rows
    return _finish(args, plan, summary, model)
