"""The handling study of Best & Bogdanski 2017, section 6 (Table 5).

For each model order a linear modal model of the full vehicle (steer to
lateral acceleration, yaw rate and roll angle) is identified by the IEKF and a
spline-nonlinear one started from it, both scored on identification and
validation records; orders run in parallel processes. Prints the Table-5 style
table, the chosen order and the modes beside the vehicle's, and writes an HDF5
archive, checkpointed as each order finishes, and a report folder beside it.
A relative --out is taken from the working directory. An existing archive is
replaced only by a rerun of the same study (same settings), and the report
folder is written only if absent, empty or an earlier report; --force allows
both, and still deletes no file in the folder that is not the report's own.
--resume ARCHIVE runs only the orders an interrupted study's archive lacks.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vehid.identification.errors import InputError
from vehid.scenarios.commands.arguments import add_filter_options
from vehid.scenarios.commands.arguments import run_digest
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE
from vehid.scenarios.progress import Progress
from vehid.scenarios.study_settings import (HANDLING_AMPLITUDE_SCALE, HANDLING_DURATION, HANDLING_SEED, HANDLING_SPEED,
                                            HANDLING_VEHICLE, STUDY_LINEAR_P, STUDY_LINEAR_PASSES)

if TYPE_CHECKING:
    from vehid.scenarios.handling_study import HandlingResult

# The study, its filters and HDF5 are imported by the functions that run it: --help needs none of them.

NAME = "handling"
GROUP = "study"
HELP = "the paper's handling study: Table 5, linear and nonlinear models of orders 2-6"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--orders", default="2-6", help="model orders, e.g. 2-6, 4 or 2,4-6 (default 2-6)")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes running orders at once (default: as many as orders, at most the cores)")
    parser.add_argument("--seed", type=int, default=HANDLING_SEED,
                        help=f"seed of both steer inputs (default {HANDLING_SEED})")
    add_filter_options(parser, passes=STUDY_LINEAR_PASSES, p=STUDY_LINEAR_P)
    parser.add_argument("--linear-only", action="store_true", help="skip the nonlinear identifications")
    parser.add_argument("--duration", type=float, default=HANDLING_DURATION,
                        help=f"length of each record in s (default {HANDLING_DURATION:g})")
    parser.add_argument("--amplitude-scale", type=float, default=HANDLING_AMPLITUDE_SCALE,
                        help=f"steer amplitude as a fraction of the inputs' defaults (default {HANDLING_AMPLITUDE_SCALE:g}; "
                             "0.1 stays linear)")
    parser.add_argument("--vehicle", default=HANDLING_VEHICLE, help="baseline, understeer, or a vehicle file")
    parser.add_argument("--speed", type=float, default=HANDLING_SPEED,
                        help=f"trim speed in m/s (default {HANDLING_SPEED:g})")
    parser.add_argument("--out", default=None,
                        help=f"archive file ({OUT_RULE}; default handling_study.h5 under the results folder)")
    parser.add_argument("--no-report", action="store_true",
                        help="write only the archive, not the report folder beside it (figures, PDF, table, CasADi export)")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not this study's archive, and the report "
                             "go into a folder that is not an earlier report (its other files are kept)")
    parser.add_argument("--resume", metavar="ARCHIVE", default=None,
                        help="continue the study checkpointed in ARCHIVE: its settings, only the orders missing")
    parser.set_defaults(handler=run)
    for name in _SETTINGS:
        _SETTING_DEFAULTS[name] = parser.get_default(name)


# options that set the study's results: with --resume they come from the archive
_SETTINGS = ("orders", "nodes", "seed", "passes", "p", "nonlinear_passes", "nonlinear_p", "linear_only",
             "duration", "amplitude_scale", "vehicle", "speed")
_SETTING_DEFAULTS: dict = {}


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.dataio.archive import open_archive
    from vehid.identification.dataio.archive_safety import (archive_lock, check_output_target, check_report_folder,
                                                            output_identity)
    from vehid.scenarios.handling_resume import StudyCheckpoint, read_progress
    from vehid.scenarios.handling_study import (HandlingConfig, archive_path, make_records, parse_orders,
                                                spline_options, study_linear_options)

    if args.resume:
        given = [name for name in _SETTINGS if getattr(args, name) != _SETTING_DEFAULTS.get(name)]
        if args.out or given:
            named = ", ".join("--" + name.replace("_", "-") for name in (["out"] if args.out else []) + given)
            raise InputError(f"--resume continues the study with the settings and file of its archive; do not give {named}")
        path = Path(args.resume)
        open_archive(path, kinds=["handling-study"]).close()  # missing, foreign or corrupt: said before anything else
        identity = output_identity(path)
        run = identity.run if identity is not None else None  # the study goes on as the run that began it
    else:
        orders = parse_orders(args.orders)
        spline = spline_options(args.nodes, args.nonlinear_passes, args.nonlinear_p)  # checked even if unused
        config = HandlingConfig(
            orders=orders, seed=args.seed, duration=args.duration, amplitude_scale=args.amplitude_scale,
            vehicle=args.vehicle, speed=args.speed, linear_options=study_linear_options(args.p, args.passes),
            spline_options=None if args.linear_only else spline, workers=args.workers,
        )
        run = run_digest(args)
        path = check_output_target(archive_path(args.out), inputs=[args.vehicle], force=args.force,
                                   kind="handling-study", run=run, suffixes=HDF5_SUFFIXES)  # before any work
    if not args.no_report:
        check_report_folder(path.with_suffix(""), force=args.force)  # the report folder too, before hours of work
    with archive_lock(path):  # one writer for the whole study: checkpoints, archive and report
        if args.resume:
            config, records, finished = read_progress(path, workers=args.workers)
            checkpoint = StudyCheckpoint(path, config, records, fresh=False)
        else:
            records, finished = make_records(config), {}
            checkpoint = StudyCheckpoint(path, config, records, run=run)
        return _study(args, config, path, records, finished, checkpoint, run)


def _study(args, config, path, records, finished, checkpoint, run) -> tuple[dict, str]:
    from vehid.identification.dataio.archive_safety import writing_report_folder
    from vehid.scenarios.handling_study import planned_passes, run_study, summary_of, write_study_archive

    state = {order: "-" for order in config.orders}
    shown: list[Progress] = []  # drawn from the first pass on, after the set-up has logged its warnings

    def on_event(event) -> None:
        if not shown:
            shown.append(Progress(planned_passes(config), "handling study", enabled=False if args.quiet else None))
        state[event.order] = f"{'L' if event.stage == 'linear' else 'N'}{event.index}"
        shown[0].advance(note=" ".join(f"n{order}:{done}" for order, done in state.items()))

    try:
        result = run_study(config, on_event=on_event, records=records, finished=finished, on_outcome=checkpoint)
    finally:
        for progress in shown:
            progress.close()
    path = write_study_archive(result, path, run=run)
    summary = {**summary_of(result), "archive": str(path)}
    if finished:
        summary["resumed_orders"] = sorted(finished)
    text = text_of(result) + f"\nwrote {path}"
    if not args.no_report:
        from vehid.scenarios.handling_report import write_handling_report

        folder = path.with_suffix("")
        with writing_report_folder(folder, force=args.force) as partial:  # a kill leaves the old report or the new
            written = write_handling_report(path, partial)
        summary["report"] = str(folder)
        text += f"\nwrote {len(written)} report files to {folder}"
    return summary, text


def text_of(result: HandlingResult) -> str:
    """The study's text summary: Table 5, the order chosen, the modes beside the vehicle's."""
    from vehid.scenarios.handling_study import percent_text
    from vehid.scenarios.report import format_eigenvalues

    config, linear = result.config, result.config.linear_options
    lines = [
        f"Handling study (Best & Bogdanski 2017, section 6, Table 5): {config.vehicle} at {config.speed:g} m/s, "
        f"seed {config.seed}, {config.duration:g} s records, steer x{config.amplitude_scale:g}, "
        f"p = {linear.p:g}, {linear.passes} passes",
        f"{'n':>2}  {'linear eigenvalues (1/s)':<44} {'R identification %':>19} {'R validation %':>19}",
        f"{'':>2}  {'':<44} {'linear':>9} {'nonlin.':>9} {'linear':>9} {'nonlin.':>9}",
    ]
    for row in result.table:
        eigen = format_eigenvalues(list(row.linear_eigenvalues)) if row.linear_eigenvalues else "(failed)"
        lines.append(
            f"{row.order:>2}  {eigen:<44} {percent_text(row.linear_identification_R):>9} "
            f"{percent_text(row.nonlinear_identification_R):>9} {percent_text(row.linear_validation_R):>9} "
            f"{percent_text(row.nonlinear_validation_R):>9}"
        )
    converged = [run.order for run in result.linear_runs if run.converged]
    lines.append(f"chosen order: {result.assessment.chosen_order} (linear runs settled: "
                 f"{', '.join(map(str, converged)) or 'none'}; paper: 4)")
    lines.append("modes beside the vehicle's linearisation (nearest identified mode: frequency Hz / damping)")
    lines.append("    " + "   ".join(f"{label}: vehicle {m.frequency_hz:.2f} / {m.damping:.2f}"
                                     for label, m in result.vehicle_modes.items()))
    by_order: dict[int, list[str]] = {}
    for item in result.mode_comparison:
        by_order.setdefault(item.order, []).append(
            f"{item.mode}: {item.identified_frequency_hz:.2f} / {item.identified_damping:.2f}")
    for order, parts in by_order.items():
        lines.append(f"{order:>2}  " + "   ".join(parts))
    lines.append(f"nonlinear models: {result.nonlinear_status}")
    lines.append(f"{result.seconds:.1f} s on {result.workers} worker(s)")
    return "\n".join(lines)
