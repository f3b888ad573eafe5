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
filter. The summary gives the eigenvalues, the fit R (eq. 17) per output of
the continuous model simulated exactly, the matrices and the run time.

With --out ARCHIVE the record and every finished pass are written to an HDF5
archive as the run goes (atomically, so a killed run leaves the archive of
its last finished pass); --resume ARCHIVE continues such a run from there
with the same data and settings, and reaches the same parameters as a run
that was never interrupted: it runs to the run's own pass budget and stop
rule (--passes, given explicitly, sets a new budget). Once the run ends, the
archive records its final stop reason. Every method writes its model to
--out; the target is checked before any work (no directory, no input file,
no existing file that is not a workbench archive unless --force), and an
archive being written is locked against a second writer.
"""

from __future__ import annotations

import argparse
import dataclasses
from contextlib import nullcontext
from pathlib import Path

from identification.errors import DivergenceError, InputError
from identification.filter_models import DISCRETIZATIONS
from identification.iekf import START_VALUES, IEKFOptions, identify_iekf
from identification.archive import open_archive, write_archive, write_run
from identification.archive_safety import archive_lock, check_output_target
from identification.preparation import read_record
from identification.iekf_archive import Checkpointer, read_iekf_run
from identification.iekf_pass import COVARIANCE_FORMS
from identification.modal import C_PATTERNS, ModalStructure
from scenarios.data_options import (archive_records, archived_preparation, archived_records, load_from_args,
                                    records_summary, register_data_options, save_model)
from scenarios.progress import Progress

NAME = "identify"
GROUP = None
HELP = "identify a modal state-space model from a data file (IEKF by default)"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", nargs="*", help="data files: .h5, .csv, .dat, .txt, .mat, .mf4 (several: one model)")
    parser.add_argument("--inputs", help="comma-separated input column names")
    parser.add_argument("--outputs", help="comma-separated output column names")
    parser.add_argument("--order", type=int, default=4, help="model order n (default 4)")
    parser.add_argument("--pattern", default="default", choices=C_PATTERNS, help="C pattern (default: pairs tied to outputs in turn)")
    parser.add_argument("--method", default="iekf", choices=("iekf", "arx", "rls", "n4sid", "output-error"),
                        help="estimator: the IEKF (default) or a classical comparator on the same data")
    parser.add_argument("--passes", type=int, default=None,
                        help=f"largest number of passes (default {DEFAULT_PASSES}; with --resume, the run's own)")
    parser.add_argument("--p", type=float, default=1.0, help="tuning parameter p: Q = p I' (default 1)")
    parser.add_argument("--discretization", default="exact", choices=DISCRETIZATIONS, help="filter discretisation (default exact)")
    parser.add_argument("--covariance", default="joseph", choices=COVARIANCE_FORMS, help="covariance numerics (default joseph)")
    parser.add_argument("--start", default="default", choices=sorted(START_VALUES), help="start values of sigma/omega")
    parser.add_argument("--normalize", action="store_true", help="scale inputs and outputs by their RMS while filtering")
    parser.add_argument("--save-model", help="write the model to this .json or .mat file")
    parser.add_argument("--out", help="HDF5 archive of the run, checkpointed after every pass")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not a workbench archive")
    parser.add_argument("--resume", metavar="ARCHIVE",
                        help="continue the run checkpointed in ARCHIVE (its data and settings; --passes counts all passes)")
    register_data_options(parser)
    parser.set_defaults(handler=run)


def load_record(path: str, inputs: list[str] | None, outputs: list[str] | None, dt: float | None):
    """Read one raw record (any supported file type), channels selected by name."""
    return read_record(path, inputs=tuple(inputs or ()), outputs=tuple(outputs or ()), dt=dt)


RUN_NAME = "iekf"
DEFAULT_PASSES = 50


def _resume(args: argparse.Namespace):
    """Data, structure, options and the finished passes of a checkpointed run."""
    if args.data:
        raise InputError("--resume takes its data from the archive: give no DATA file")
    with open_archive(args.resume, kinds=["identification"]) as archive:
        previous = read_iekf_run(archive, RUN_NAME)
        records = archived_records(archive)
        preparation = archived_preparation(archive)
    if not records:
        raise InputError(f"{args.resume} holds no identification record to resume on")
    budget = previous.options.passes if args.passes is None else args.passes
    options = dataclasses.replace(previous.options, passes=max(budget, previous.passes_run))
    return records, previous.structure, options, previous, preparation


def run(args: argparse.Namespace) -> tuple[dict, str]:
    if args.resume and args.out:
        raise InputError("--resume continues in its own archive: give no --out")
    if args.out:  # before any work: a bad target must not cost the run
        check_output_target(args.out, inputs=list(args.data), force=args.force)
    if args.resume:  # a missing, foreign or corrupt file is named as such before anything is locked or created
        open_archive(args.resume, kinds=["identification"]).close()
    target = args.resume or args.out
    with archive_lock(target) if target else nullcontext():  # one writer per archive for the whole run
        return _identify(args)


def _identify(args: argparse.Namespace) -> tuple[dict, str]:
    previous = None
    if args.resume:
        records, structure, options, previous, preparation = _resume(args)
        data = records[0] if len(records) == 1 else records
        archive_path = Path(args.resume)
    else:
        if not args.data:
            raise InputError("give a DATA file (or --resume ARCHIVE)")
        records, preparation = load_from_args(args, args.data)
        data = records[0] if len(records) == 1 else records
        structure = ModalStructure.from_pattern(args.pattern, args.order, records[0].n_u, records[0].n_y)
        if args.method != "iekf":
            return _run_comparator(args, data, structure, records, preparation)
        options = IEKFOptions(
            p=args.p, passes=DEFAULT_PASSES if args.passes is None else args.passes,
            discretization=args.discretization, covariance=args.covariance,
            start=args.start, normalize=args.normalize,
        )
        archive_path = Path(args.out) if args.out else None
        if archive_path is not None:
            with write_archive(archive_path, kind="identification", config=options, seeds=[]) as archive:
                archive_records(archive, records, preparation)
    checkpoint = Checkpointer(archive_path, RUN_NAME) if archive_path is not None else None
    done = previous.passes_run if previous is not None else 0
    with Progress(options.passes, "IEKF passes", enabled=None if not args.quiet else False) as progress:
        progress.advance(done)

        def on_pass(record, so_far):
            if checkpoint is not None:
                checkpoint(record, so_far)
            progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

        # offsets removed: the prepared record no longer starts at rest, so its start state settles first
        settle = True if preparation is not None and preparation.detrend != "none" else None
        try:
            result = identify_iekf(data, structure, options=options, resume=previous, on_pass=on_pass,
                                   settle_start=settle)
        except DivergenceError as exc:
            if checkpoint is not None and exc.last_good is not None:
                checkpoint.finish(exc.last_good)  # the archive says how the run ended: diverged at pass k
            raise
    if checkpoint is not None:
        checkpoint.finish(result)
    model = result.model
    summary = {
        "method": "iekf",
        "order": structure.n,
        "eigenvalues": model.eigenvalues(),
        "fit_percent": result.fit_percent,
        "fit_percent_filter": result.history[-1].fit_filter,
        "passes_run": result.passes_run,
        "stop_reason": result.stop_reason,
        "discretization": options.discretization,
        "A": model.A,
        "B": model.B,
        "C": model.C,
        "D": model.D,
        "seconds": result.seconds,
    }
    summary.update(records_summary(model, records, preparation))
    if archive_path is not None:
        summary["archive"] = str(archive_path)
    if args.save_model:
        summary["model_file"] = str(save_model(model, args.save_model, preparation))
    return summary, _text(summary, records[0])


def _run_comparator(args: argparse.Namespace, data, structure, records, preparation) -> tuple[dict, str]:
    from identification.comparators import identify_with

    outcome = identify_with(data, method=args.method, order=structure.n)
    model = outcome.model
    summary = {
        "method": args.method,
        "order": structure.n,
        "eigenvalues": model.eigenvalues(),
        "fit_percent": outcome.metrics.percentage_explanation,
        "passes_run": 0,
        "discretization": "exact",
        "A": model.A,
        "B": model.B,
        "C": model.C,
        "D": model.D,
        "seconds": outcome.seconds,
    }
    summary.update(records_summary(model, records, preparation))
    if args.save_model:
        summary["model_file"] = str(save_model(model, args.save_model, preparation))
    if args.out:
        summary["archive"] = str(_archive_comparator(args, records, preparation, outcome))
    return summary, _text(summary, records[0])


def _archive_comparator(args: argparse.Namespace, records, preparation, outcome) -> Path:
    """The records and the comparator's model and fit, as ``runs/<method>`` of an identification archive."""
    path = Path(args.out)
    config = {"method": args.method, "order": outcome.model.structure.n}
    with write_archive(path, kind="identification", config=config, seeds=[]) as archive:
        archive_records(archive, records, preparation)
        run = write_run(archive, args.method, model=outcome.model, metrics=outcome.metrics)
        run.attrs["stop_reason"] = "finished"
        run.attrs["seconds"] = outcome.seconds
    return path


def _text(summary: dict, data) -> str:
    eigen = ", ".join(
        f"{v.real:.4g}{v.imag:+.4g}j" if v.imag else f"{v.real:.4g}" for v in summary["eigenvalues"]
    )
    fits = ", ".join(f"{name} {value:.3f} %" for name, value in zip(data.output_names, summary["fit_percent"]))
    lines = [
        f"{summary['method']}: order {summary['order']}, {summary['passes_run']} passes, "
        f"{summary['discretization']} discretisation, {summary['seconds']:.2f} s",
        f"eigenvalues: {eigen}",
        f"fit R (continuous model simulated exactly): {fits}",
    ]
    if len(summary.get("records", ())) > 1:
        lines += [f"  {entry['name']} ({entry['samples']} samples): "
                  + ", ".join(f"{value:.3f} %" for value in entry["fits"]) for entry in summary["records"]]
    if "model_file" in summary:
        lines.append(f"wrote {summary['model_file']}")
    return "\n".join(lines)
