"""Reproduce the linear example of Best & Bogdanski 2017 (section 4): Tables 1-4 and the order study.

Runs the paper's Euler filter unless --discretization exact is given; prints
each case's table beside the paper's numbers and writes an HDF5 archive (a
relative --out is taken from the working directory; an existing file is
replaced only by a rerun of the same case and settings, or with --force).
"""

from __future__ import annotations

import argparse

from vehid.identification.choices import COVARIANCE_FORMS, DISCRETIZATIONS
from vehid.scenarios.commands.arguments import run_digest
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE, results_path
from vehid.scenarios.progress import Progress
from vehid.scenarios.study_settings import LINEAR_EXAMPLE_CASES

# The study, its filter and HDF5 are imported by run: --help needs none of them.

NAME = "linear-example"
GROUP = "study"
HELP = "the paper's linear example: Tables 1-4 and the order study"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--case", default="single-output", choices=LINEAR_EXAMPLE_CASES, help="which table (default single-output)")
    parser.add_argument("--passes", type=int, default=None, help="passes per identification (default: the case's own)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the eq. 16 data (default 0)")
    parser.add_argument("--discretization", default="euler", choices=DISCRETIZATIONS,
                        help="filter discretisation (default euler, as in the paper)")
    parser.add_argument("--covariance", default="joseph", choices=COVARIANCE_FORMS, help="covariance numerics")
    parser.add_argument("--p", type=float, default=None, help="tuning parameter p (default: the case's own)")
    parser.add_argument("--out", default=None,
                        help=f"archive file ({OUT_RULE}; default linear_example_<case>.h5 under the results folder)")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not this case's own archive")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.dataio.archive_safety import archive_lock, check_output_target
    from vehid.scenarios.linear_example import planned_passes, run_case, write_archive_for

    target = results_path(args.out, f"linear_example_{args.case}.h5").absolute()
    run = run_digest(args)
    check_output_target(target, force=args.force, kind="linear-example", run=run, suffixes=HDF5_SUFFIXES)  # before any work
    with archive_lock(target):
        with Progress(planned_passes(args.case, args.passes), f"{args.case} passes",
                      enabled=None if not args.quiet else False) as progress:
            result = run_case(
                args.case, seed=args.seed, passes=args.passes, discretization=args.discretization,
                covariance=args.covariance, p=args.p,
                on_pass=lambda label, record, _: progress.advance(note=f"{label} R {record.mean_fit_filter:.4f} %"),
            )
        path = write_archive_for(result, target, run=run)
    summary = {**result.summary, "archive": str(path)}
    return summary, result.text + f"\nwrote {path}"
