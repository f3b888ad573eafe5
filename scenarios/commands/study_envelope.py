"""The operating envelope: models across vehicles, speeds and orders, and a speed-scheduled family.

Each job (vehicle, speed, order, seed) measures the vehicle's grip limit at
its speed, simulates the identification and validation steer inputs at
--amplitude-fraction of it, identifies a linear modal model by the IEKF (and
a spline-nonlinear one unless --linear-only) and scores both. Jobs run on a
local process pool, or on Dask (--executor dask with --scheduler ADDRESS, or
--workers N for a local cluster); results go to one archive, one group per
job, written as jobs finish (--resume skips those already there). The grid
models of each vehicle and order become one speed-scheduled model, validated
at the speeds between the grid speeds against a model identified there.
Prints a table per vehicle: fits, identified modes beside the vehicle's
linearised yaw-sideslip and roll modes, and the scheduled model's validation.
"""

from __future__ import annotations

import argparse

from vehid.scenarios.envelope import EXECUTORS, EnvelopeConfig, parse_speeds, run_campaign
from vehid.scenarios.commands.study_handling import add_filter_options
from vehid.scenarios.handling_study import parse_orders
from vehid.scenarios.progress import Progress
from vehid.identification.errors import InputError

NAME = "envelope"
GROUP = "study"
HELP = "models across vehicles and speeds, and a speed-scheduled model, on a process pool or Dask"

_DEFAULTS = EnvelopeConfig()


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
    parser.add_argument("--amplitude-fraction", type=float, default=_DEFAULTS.amplitude_fraction,
                        help="steer amplitude as a fraction of each speed's grip limit "
                             f"(default {_DEFAULTS.amplitude_fraction:g}: the linear range)")
    parser.add_argument("--orders", default="2-4", help="model orders, e.g. 2-4 (default 2-4)")
    parser.add_argument("--seeds", default="0", help="seeds of the steer inputs, comma-separated (default 0)")
    parser.add_argument("--linear-only", action="store_true", help="skip the spline-nonlinear models")
    parser.add_argument("--duration", type=float, default=_DEFAULTS.duration,
                        help=f"length of each record in s (default {_DEFAULTS.duration:g})")
    add_filter_options(parser, _DEFAULTS.linear_options)
    parser.add_argument("--executor", choices=EXECUTORS, default="process",
                        help="local process pool (default) or Dask distributed")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes of the pool or of the local Dask cluster (default: the cores)")
    parser.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (with --executor dask)")
    parser.add_argument("--out", default=None, help="archive file (default envelope.h5 under results/)")
    parser.add_argument("--resume", action="store_true", help="continue the campaign in --out, skipping finished jobs")
    parser.add_argument("--no-report", action="store_true", help="write only the archive, not the figures beside it")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
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

        files = write_envelope_report(result, result.archive.with_suffix(""))
        text += f"\nwrote {len(files)} report files to {result.archive.with_suffix('')}"
    return result.summary, text
