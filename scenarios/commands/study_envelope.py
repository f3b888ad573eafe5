"""The operating envelope: models across vehicles, speeds and orders, and a speed-scheduled family.

Each job (vehicle, speed, order, seed) identifies a linear modal model (and a
spline-nonlinear one unless --linear-only) from steer inputs at
--amplitude-fraction of the grip limit at its speed. Jobs run on a process pool
or Dask and are archived as they finish (--resume skips those done). The grid
models become one speed-scheduled model, validated at the speeds between.
A relative --out is taken from the working directory; an existing archive is
only continued (--resume), never replaced. The report folder beside it is
written only if absent, empty or an earlier report, or with --force (which
still deletes no file in it that is not the report's own).
"""

from __future__ import annotations

import argparse
import errno
import os

from vehid.scenarios.commands.arguments import add_filter_options
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE, results_path
from vehid.scenarios.progress import Progress
from vehid.scenarios.study_settings import (ENVELOPE_AMPLITUDE_FRACTION, ENVELOPE_ARCHIVE_KIND, ENVELOPE_DURATION,
                                            ENVELOPE_EXECUTORS, ENVELOPE_P, ENVELOPE_PASSES)
from vehid.identification.errors import InputError

# The campaign, its filters and HDF5 are imported by the functions that run it: --help needs none of them.

NAME = "envelope"
GROUP = "study"
HELP = "models across vehicles and speeds, and a speed-scheduled model, on a process pool or Dask"


def _seeds(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise InputError(f"seeds must be whole numbers separated by commas; got {text!r}") from None


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--vehicles", default="baseline", help="baseline, understeer or vehicle files, comma-separated")
    parser.add_argument("--speeds", default="10,15,20,25,30", help="grid speeds in m/s (default 10,15,20,25,30)")
    parser.add_argument("--off-grid", default=None,
                        help="speeds where the scheduled model is validated (default: midpoints of the grid; 'none')")
    parser.add_argument("--amplitude-fraction", type=float, default=ENVELOPE_AMPLITUDE_FRACTION,
                        help="steer amplitude as a fraction of each speed's grip limit "
                             f"(default {ENVELOPE_AMPLITUDE_FRACTION:g}: the linear range)")
    parser.add_argument("--orders", default="2-4", help="model orders, e.g. 2-4 (default 2-4)")
    parser.add_argument("--seeds", default="0", help="seeds of the steer inputs, comma-separated (default 0)")
    parser.add_argument("--linear-only", action="store_true", help="skip the spline-nonlinear models")
    parser.add_argument("--duration", type=float, default=ENVELOPE_DURATION,
                        help=f"length of each record in s (default {ENVELOPE_DURATION:g})")
    add_filter_options(parser, passes=ENVELOPE_PASSES, p=ENVELOPE_P)
    parser.add_argument("--executor", choices=ENVELOPE_EXECUTORS, default="process",
                        help="local process pool (default) or Dask distributed")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes of the pool or of the local Dask cluster (default: the cores)")
    parser.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (with --executor dask)")
    parser.add_argument("--out", default=None,
                        help=f"archive file ({OUT_RULE}; default envelope.h5 under the results folder)")
    parser.add_argument("--resume", action="store_true", help="continue the campaign in --out, skipping finished jobs")
    parser.add_argument("--no-report", action="store_true", help="write only the archive, not the figures beside it")
    parser.add_argument("--force", action="store_true",
                        help="let the report go into a folder that is not an earlier report (its other files are kept)")
    parser.set_defaults(handler=run)


def _check_archive_target(path, resume: bool) -> None:
    """A campaign archive is only ever continued, never replaced: say so before any job is planned."""
    from vehid.identification.dataio.archive_safety import OutputTargetError, output_identity

    if path.is_dir():
        raise OutputTargetError(f"cannot write the archive {path}: {os.strerror(errno.EISDIR)}")
    if path.suffix.lower() not in HDF5_SUFFIXES:
        raise OutputTargetError(f"cannot write the archive {path}: its name must end in {' or '.join(HDF5_SUFFIXES)}, "
                                "the format written")
    if not path.exists():
        return
    if not resume:
        raise OutputTargetError(f"{path} exists; refusing to overwrite it (give --resume to continue the campaign "
                                "it holds, or choose another file)")
    identity = output_identity(path)
    if identity is None or identity.kind != ENVELOPE_ARCHIVE_KIND:
        raise OutputTargetError(f"{path} is not a campaign archive of the workbench; nothing to resume there "
                                "(choose another file)")


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.dataio.archive_safety import check_report_folder, writing_report_folder
    from vehid.scenarios.envelope import EnvelopeConfig, parse_speeds, run_campaign
    from vehid.scenarios.handling_study import parse_orders

    _check_archive_target(results_path(args.out, "envelope.h5"), args.resume)
    if not args.no_report:  # before the campaign: a folder of the user's is refused now, not after hours
        check_report_folder(results_path(args.out, "envelope.h5").with_suffix(""), force=args.force)
    off_grid = None
    if args.off_grid is not None:
        off_grid = () if args.off_grid.strip().lower() == "none" else parse_speeds(args.off_grid, "off-grid speeds")
    config = EnvelopeConfig(
        vehicles=tuple(v.strip() for v in args.vehicles.split(",") if v.strip()),
        speeds=parse_speeds(args.speeds), amplitude_fraction=args.amplitude_fraction, orders=parse_orders(args.orders),
        seeds=_seeds(args.seeds), nonlinear=not args.linear_only, off_grid=off_grid, duration=args.duration,
        p=args.p, passes=args.passes, nodes=args.nodes, nonlinear_passes=args.nonlinear_passes,
        nonlinear_p=args.nonlinear_p,
    )
    shown: list[Progress] = []

    def on_job(outcome, done, total) -> None:
        if not shown:
            shown.append(Progress(total, "envelope", enabled=False if args.quiet else None))
            shown[0].count = done - 1
        shown[0].advance(note=f"{outcome.key} {outcome.seconds:.0f} s")

    try:
        result = run_campaign(config, out=args.out, resume=args.resume, executor=args.executor,
                              workers=args.workers, scheduler=args.scheduler, on_job=on_job)
    finally:
        for progress in shown:
            progress.close()
    text = result.text
    if not args.no_report:
        from vehid.scenarios.envelope_report import write_envelope_report

        folder = result.archive.with_suffix("")
        with writing_report_folder(folder, force=args.force) as partial:
            files = write_envelope_report(result, partial)
        text += f"\nwrote {len(files)} report files to {folder}"
    return result.summary, text
