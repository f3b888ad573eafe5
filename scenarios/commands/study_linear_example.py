"""Reproduce the linear example of Best & Bogdanski 2017 (section 4).

Cases: single-output (Table 1), three-output (Table 2),
three-output-constrained (Table 3, the eq. 18 C pattern), noise (Table 4)
and orders (the order study, Figure 5). The data follow eq. 16 from the
given seed; the filter is the paper's Euler form unless --discretization
exact is given. Each case prints its table beside the paper's numbers and
writes an HDF5 archive under the results folder.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from vehid.identification.archive_safety import archive_lock, check_output_target
from vehid.identification.filter_models import DISCRETIZATIONS
from vehid.identification.iekf_pass import COVARIANCE_FORMS
from vehid.scenarios.linear_example import CASES, planned_passes, run_case, write_archive_for
from vehid.scenarios.paths import results_directory
from vehid.scenarios.progress import Progress

NAME = "linear-example"
GROUP = "study"
HELP = "the paper's linear example: Tables 1-4 and the order study"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--case", default="single-output", choices=CASES, help="which table (default single-output)")
    parser.add_argument("--passes", type=int, default=None, help="passes per identification (default: the case's own)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the eq. 16 data (default 0)")
    parser.add_argument("--discretization", default="euler", choices=DISCRETIZATIONS,
                        help="filter discretisation (default euler, as in the paper)")
    parser.add_argument("--covariance", default="joseph", choices=COVARIANCE_FORMS, help="covariance numerics")
    parser.add_argument("--p", type=float, default=None, help="tuning parameter p (default: the case's own)")
    parser.add_argument("--out", default=None, help="archive file name (default linear_example_<case>.h5 under results/)")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not a workbench archive")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    target = Path(args.out) if args.out else Path(f"linear_example_{args.case}.h5")
    target = (target if target.is_absolute() else results_directory() / target).absolute()
    check_output_target(target, force=args.force)  # before any work
    with archive_lock(target):
        return _run(args, target)


def _run(args: argparse.Namespace, target: Path) -> tuple[dict, str]:
    with Progress(planned_passes(args.case, args.passes), f"{args.case} passes", enabled=None if not args.quiet else False) as progress:
        result = run_case(
            args.case, seed=args.seed, passes=args.passes, discretization=args.discretization,
            covariance=args.covariance, p=args.p,
            on_pass=lambda label, record, _: progress.advance(note=f"{label} R {record.mean_fit_filter:.4f} %"),
        )
    path = write_archive_for(result, target)
    summary = {**result.summary, "archive": str(path)}
    return summary, result.text + f"\nwrote {path}"
