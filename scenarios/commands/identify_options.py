"""The options of `vehid identify`, registered on its parser (a module beside the command, not a command)."""

from __future__ import annotations

import argparse

from vehid.identification.automatic.options import DEFAULT_NODES, DEFAULT_NONLINEAR_PASSES, DEFAULT_PASSES
from vehid.identification.choices import (C_PATTERNS, COVARIANCE_FORMS, DISCRETIZATIONS, INITIAL_STATES,
                                          SCHEDULE_DEFAULT_KNOTS, SCHEDULE_MAX_KNOTS, SCHEDULE_MIN_KNOTS,
                                          SCHEDULED_DEFAULT_P, SCHEDULED_P_GRID, START_CHOICES, TIMESCALES)

__all__ = ["STRUCTURES", "START_HELP", "register_identify_options", "register_pipeline_options",
           "register_schedule_options", "register_single_track_options"]

#: The model structures: the modal model, or a car's single-track model (scenarios.single_track_identify).
STRUCTURES = ("modal", "single-track")
START_HELP = ("start values: data (a subspace model of the record, default), band (modes across the record's band), "
              "default (sigma = -10, omega = 10 rad/s, absolute) or paper (sigma = -1, omega = 1)")


def register_identify_options(parser: argparse.ArgumentParser) -> None:
    """Every option of `vehid identify`."""
    from vehid.scenarios.commands.arguments import register_data_options
    from vehid.scenarios.paths import OUT_RULE

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
    parser.add_argument("--start", default="data", choices=START_CHOICES, help=START_HELP)
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
    parser.add_argument("--schedule-grid", metavar="VALUES",
                        help="knots of the scheduled modal model, comma-separated and increasing (default: "
                             "--schedule-knots at evenly spaced quantiles of the channel)")
    parser.add_argument("--schedule-knots", type=int, default=SCHEDULE_DEFAULT_KNOTS,
                        help=f"the most knots at the channel's quantiles, {SCHEDULE_MIN_KNOTS}-{SCHEDULE_MAX_KNOTS} "
                             f"(default {SCHEDULE_DEFAULT_KNOTS}; knots crowded within a quarter of the even spacing "
                             "merge)")
    parser.add_argument("--schedule-p", type=float, action="append", metavar="P",
                        help=f"tuning parameter(s) of the scheduled filter, per dominant time constant; several are "
                             f"tried and one chosen on validation data (default {SCHEDULED_DEFAULT_P:g}, or "
                             f"{', '.join(f'{p:g}' for p in SCHEDULED_P_GRID)} with validation data)")


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
