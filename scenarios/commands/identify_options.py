"""The options of `vehid identify`, registered on its parser (a module beside the command, not a command)."""

from __future__ import annotations

import argparse

from vehid.identification.automatic.options import IdentifyOptions
from vehid.scenarios.commands.flags import add_option

__all__ = ["STRUCTURES", "register_identify_options", "register_pipeline_options", "register_schedule_options",
           "register_single_track_options"]

#: The model structures: the modal model, or a car's single-track model (scenarios.single_track_identify).
STRUCTURES = ("modal", "single-track")


def register_identify_options(parser: argparse.ArgumentParser) -> None:
    """Every option of `vehid identify`."""
    from vehid.scenarios.commands.arguments import register_data_options
    from vehid.scenarios.paths import OUT_RULE

    parser.add_argument("data", nargs="*", help="data files: .h5, .csv, .dat, .txt, .mat, .mf4 (several: one model)")
    parser.add_argument("--inputs", help="comma-separated input column names")
    parser.add_argument("--outputs", help="comma-separated output column names")
    parser.add_argument("--order", default="4", help="model order n, a range such as 2-8, or auto (default 4)")
    add_option(parser, IdentifyOptions, "pattern")
    add_option(parser, IdentifyOptions, "method")
    # None: not given, so that --resume runs to the archived run's own budget
    add_option(parser, IdentifyOptions, "passes", default=None, note="with --resume, the run's own")
    add_option(parser, IdentifyOptions, "p")
    add_option(parser, IdentifyOptions, "discretization")
    add_option(parser, IdentifyOptions, "covariance")
    add_option(parser, IdentifyOptions, "start")
    add_option(parser, IdentifyOptions, "normalize")
    parser.add_argument("--save-model", help=f"write the model to this .json or .mat file ({OUT_RULE})")
    parser.add_argument("--out", help=f"HDF5 archive of the run, checkpointed after every pass ({OUT_RULE})")
    parser.add_argument("--force", action="store_true",
                        help="let --out and --save-model replace an existing file that is not this run's own output")
    parser.add_argument("--resume", metavar="ARCHIVE",
                        help="continue the run checkpointed in ARCHIVE (its data and settings; --passes counts all passes)")
    add_option(parser, IdentifyOptions, "bootstrap", metavar="N")
    parser.add_argument("--structure", default="modal", choices=STRUCTURES,
                        help="model structure: modal (default) or single-track (a car's physical parameters)")
    register_data_options(parser)
    register_pipeline_options(parser)
    register_schedule_options(parser)
    register_single_track_options(parser)


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
    add_option(parser, IdentifyOptions, "initial_state")
    add_option(parser, IdentifyOptions, "horizon", metavar="K")
    add_option(parser, IdentifyOptions, "allow_unstable")
    add_option(parser, IdentifyOptions, "timescale")
    add_option(parser, IdentifyOptions, "nonlinear")
    add_option(parser, IdentifyOptions, "nodes", note="with --nonlinear")
    add_option(parser, IdentifyOptions, "nonlinear_p", type=float, action="append", metavar="P")
    add_option(parser, IdentifyOptions, "nonlinear_passes")
    add_option(parser, IdentifyOptions, "strict")


def register_schedule_options(parser: argparse.ArgumentParser) -> None:
    """``--schedule`` and the scheduled model's settings."""
    parser.add_argument("--schedule", metavar="CHANNEL",
                        help="scheduling channel (a speed such as vx), read beside the inputs and never offset: "
                             "identify a model whose coefficients vary with it (modal: piecewise linear over "
                             "--schedule-grid; --structure single-track: the speed in m/s)")
    parser.add_argument("--min-speed", metavar="M_S", default=None,
                        help="with --schedule (a speed) or --structure single-track: use only the samples at or above "
                             "this speed (m/s, after --scale), each run of them its own record (default 5; none keeps "
                             "every sample)")
    # comma-separated on the command line (commands.identify.parse_schedule_grid)
    add_option(parser, IdentifyOptions, "schedule_grid", metavar="V1,V2,...")
    add_option(parser, IdentifyOptions, "schedule_knots")
    add_option(parser, IdentifyOptions, "schedule_p", type=float, action="append", metavar="P")


def register_single_track_options(parser: argparse.ArgumentParser) -> None:
    """The single-track options of `vehid identify` (``--structure`` and ``--schedule`` are registered beside them)."""
    group = parser.add_argument_group("single-track structure (--structure single-track)")
    group.add_argument("--quantities", metavar="NAMES",
                       help="what each --outputs channel measures, in order: yaw_rate (rad/s), lateral_acceleration "
                            "(m/s^2), sideslip (rad), lateral_velocity (m/s) (default yaw_rate,lateral_acceleration); "
                            "a modal model's outputs so named (or other) are checked as a car's (JSON plausibility)")
    group.add_argument("--mass", type=float, metavar="KG", help="vehicle mass (kg)")
    group.add_argument("--lf", type=float, metavar="M", help="CG to front axle (m)")
    group.add_argument("--lr", type=float, metavar="M", help="CG to rear axle (m)")
    group.add_argument("--vehicle", metavar="FILE",
                       help="vehicle parameter file (.toml/.json) or name for mass and axle distances")
    group.add_argument("--relaxation-length", type=float, metavar="M",
                       help="tyre relaxation length: slip angles lag the kinematic ones (default: no lag)")
    group.add_argument("--saturation", action="store_true",
                       help="saturating axle characteristic mu F_z tanh(C alpha / (mu F_z)), mu estimated")
    group.add_argument("--offsets", action="store_true",
                       help="estimate constant sensor offsets of the steer and of each output as well")
    group.add_argument("--measured-sideslip", metavar="CHANNEL",
                       help="a channel that measured the sideslip (rad, ISO 8855), not fitted: the model's predicted "
                            "sideslip is checked against it (JSON plausibility)")
