"""Identify a modal state-space model from an input/output record.

DATA is a workbench HDF5 file (as written by `vehid simulate --out`) or a CSV
file with a header row. Name the columns with --inputs and --outputs (for an
HDF5 record they select among its inputs and outputs; for a CSV they are
required); time comes from a column `t` or from --dt.

The default method is the Identifying EKF (Best & Bogdanski 2017) with the
exact first-order-hold discretisation, so the identified parameters are those
of the continuous-time model; --discretization euler reproduces the paper's
filter. The summary gives the eigenvalues, the fit R (eq. 17) per output of
the continuous model simulated exactly, the matrices and the run time, and
how sure the model is (scenarios.model_checks): each mode with standard
deviations (text: value +/- 2 sigma; JSON: the list `modes`), the residual
tests per output (`residual_whiteness_p`, `input_correlation_max`) and, for
the IEKF, the innovation NIS per pass with its band.

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

from identification import read_csv, read_hdf5
from identification.errors import DivergenceError, InputError
from identification.filter_models import DISCRETIZATIONS
from identification.iekf import START_VALUES, IEKFOptions, identify_iekf
from identification.archive import (open_archive, read_records, run_group, update_archive, write_archive,
                                    write_record, write_run)
from identification.archive_safety import archive_lock, check_output_target
from identification.iekf_archive import Checkpointer, read_iekf_run
from identification.iekf_pass import COVARIANCE_FORMS
from identification.modal import C_PATTERNS, ModalStructure
from identification.storage import write_value
from scenarios.model_checks import uncertainty_lines, uncertainty_summary
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
DEFAULT_PASSES = 50


def _resume(args: argparse.Namespace):
    """Data, structure, options and the finished passes of a checkpointed run."""
    if args.data is not None:
        raise InputError("--resume takes its data from the archive: give no DATA file")
    with open_archive(args.resume, kinds=["identification"]) as archive:
        previous = read_iekf_run(archive, RUN_NAME)
        records = read_records(archive)
    if "identification" not in records:
        raise InputError(f"{args.resume} holds no identification record to resume on")
    budget = previous.options.passes if args.passes is None else args.passes
    options = dataclasses.replace(previous.options, passes=max(budget, previous.passes_run))
    return records["identification"], previous.structure, options, previous


def run(args: argparse.Namespace) -> tuple[dict, str]:
    if args.resume and args.out:
        raise InputError("--resume continues in its own archive: give no --out")
    if args.out:  # before any work: a bad target must not cost the run
        check_output_target(args.out, inputs=[args.data], force=args.force)
    if args.resume:  # a missing, foreign or corrupt file is named as such before anything is locked or created
        open_archive(args.resume, kinds=["identification"]).close()
    target = args.resume or args.out
    with archive_lock(target) if target else nullcontext():  # one writer per archive for the whole run
        return _identify(args)


def _identify(args: argparse.Namespace) -> tuple[dict, str]:
    previous = None
    if args.resume:
        data, structure, options, previous = _resume(args)
        archive_path = Path(args.resume)
    else:
        if args.data is None:
            raise InputError("give a DATA file (or --resume ARCHIVE)")
        data = load_record(args.data, _names(args.inputs), _names(args.outputs), args.dt)
        structure = ModalStructure.from_pattern(args.pattern, args.order, data.n_u, data.n_y)
        if args.method != "iekf":
            return _run_comparator(args, data, structure)
        options = IEKFOptions(
            p=args.p, passes=DEFAULT_PASSES if args.passes is None else args.passes,
            discretization=args.discretization, covariance=args.covariance,
            start=args.start, normalize=args.normalize,
        )
        archive_path = Path(args.out) if args.out else None
        if archive_path is not None:
            with write_archive(archive_path, kind="identification", config=options, seeds=[]) as archive:
                write_record(archive, "identification", data)
    checkpoint = Checkpointer(archive_path, RUN_NAME) if archive_path is not None else None
    done = previous.passes_run if previous is not None else 0
    with Progress(options.passes, "IEKF passes", enabled=None if not args.quiet else False) as progress:
        progress.advance(done)

        def on_pass(record, so_far):
            if checkpoint is not None:
                checkpoint(record, so_far)
            progress.advance(note=f"R {record.mean_fit_filter:.4f} %")

        try:
            result = identify_iekf(data, structure, options=options, resume=previous, on_pass=on_pass)
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
    checks, tests = uncertainty_summary(model, data, [record.nis for record in result.history])
    summary.update(checks)
    if archive_path is not None:
        with update_archive(archive_path) as archive:
            write_value(run_group(archive, RUN_NAME), "residual_tests", tests)
        summary["archive"] = str(archive_path)
    if args.save_model:
        summary["model_file"] = str(_save_model(model, args.save_model))
    return summary, _text(summary, data)


def _save_model(model, target: str) -> Path:
    path = Path(target)
    if path.suffix.lower() == ".mat":
        return model.save_mat(path)
    if path.suffix.lower() == ".json":
        return model.save_json(path)
    raise InputError(f"--save-model takes a .json or .mat file; got {target!r}")


def _run_comparator(args: argparse.Namespace, data, structure) -> tuple[dict, str]:
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
    checks, tests = uncertainty_summary(model, data)
    summary.update(checks)
    if args.save_model:
        summary["model_file"] = str(_save_model(model, args.save_model))
    if args.out:
        summary["archive"] = str(_archive_comparator(args, data, outcome, tests))
    return summary, _text(summary, data)


def _archive_comparator(args: argparse.Namespace, data, outcome, tests) -> Path:
    """The record and the comparator's model and fit, as ``runs/<method>`` of an identification archive."""
    path = Path(args.out)
    config = {"method": args.method, "order": outcome.model.structure.n}
    with write_archive(path, kind="identification", config=config, seeds=[]) as archive:
        write_record(archive, "identification", data)
        run = write_run(archive, args.method, model=outcome.model, metrics=outcome.metrics)
        write_value(run, "residual_tests", tests)
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
    if "modes" in summary:
        lines += uncertainty_lines(summary, data.output_names)
    if "model_file" in summary:
        lines.append(f"wrote {summary['model_file']}")
    return "\n".join(lines)
