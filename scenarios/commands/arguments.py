"""Option groups several commands share: the output options every command has, and the data-file options.

Their defaults and choices come from plain constants
(:mod:`vehid.identification.choices`), so that registering them imports
nothing a command computes with.
"""

from __future__ import annotations

import argparse

from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.choices import JITTER_TOLERANCE, SPLINE_NODES, SPLINE_P, SPLINE_PASSES
from vehid.scenarios.commands.flags import add_option

__all__ = ["common_options", "register_data_options", "add_filter_options"]


def common_options() -> argparse.ArgumentParser:
    """The output options of every command (``--json``, ``--quiet``, ``--verbose``), as a parent parser."""
    common = argparse.ArgumentParser(add_help=False)
    output = common.add_argument_group("output")
    output.add_argument("--json", action="store_true", help="print one JSON summary object on stdout")
    output.add_argument("--quiet", action="store_true", help="no progress display; warnings and errors only")
    output.add_argument("--verbose", action="store_true", help="log progress details (and tracebacks of internal errors)")
    return common


def register_data_options(parser: argparse.ArgumentParser) -> None:
    """Add the reading, time-base and preparation options (their names are the Python API's).

    :mod:`vehid.scenarios.data_options` reads them back (``settings_from_args``,
    ``preparation_options``).
    """
    group = parser.add_argument_group("data files")
    group.add_argument("--time-column", metavar="NAME",
                       help="time column or variable (default: t, or time, when present, with or without "
                            "a unit as in time(s); 'none' disables it)")
    group.add_argument("--dt", type=float, help="sample interval in s, for files without a time column")
    group.add_argument("--time-scale", type=float, metavar="FACTOR",
                       help="seconds per unit of the time column, 0.001 for ms (default: from the column's unit, "
                            "t(ms) or a units row, else 1)")
    group.add_argument("--resample", type=float, metavar="HZ",
                       help="interpolate every channel linearly onto a uniform grid at HZ (low-passed first when the rate falls)")
    group.add_argument("--decimate", type=int, metavar="K", help="keep every K-th sample after an anti-aliasing FIR filter")
    group.add_argument("--segment", metavar="T0:T1",
                       help="use only T0 <= t <= T1: the file's time in s, or +T0:+T1 in s from the log's first sample")
    group.add_argument("--exclude", action="append", metavar="T0:T1", default=None,
                       help="leave out T0 <= t <= T1 (as --segment: file time, or +T0:+T1 from the log's first "
                            "sample); the parts before and after are records of their own; repeatable or a comma list")
    group.add_argument("--despike", action="store_true",
                       help="replace spikes and drop-outs (found in every channel, listed in any case) by straight "
                            "lines between their neighbours")
    group.add_argument("--jitter-tolerance", type=float, default=JITTER_TOLERANCE, metavar="FRACTION",
                       help=f"largest stray of a sample time from a uniform grid, in steps (default {JITTER_TOLERANCE:g})")
    add_option(group, IdentifyOptions, "detrend")
    group.add_argument("--scale", action="append", metavar="NAME=FACTOR", default=None,
                       help="multiply a channel by FACTOR before identification: a unit (yawRate=0.0174533 for "
                            "deg/s), a sign (ay=-1 for an axis pointing right); repeatable or a comma list")
    group.add_argument("--steering-ratio", action="append", metavar="[NAME=]RATIO", default=None,
                       help="divide a steering-wheel angle by the steering ratio, giving the road-wheel angle "
                            "(a bare RATIO: the only input); repeatable or a comma list")


def add_filter_options(parser: argparse.ArgumentParser, *, passes: int, p: float) -> None:
    """The filters' options the vehicle studies share: ``--passes`` and ``--p`` of the linear IEKF (defaults
    ``passes`` and ``p``), ``--nodes``, ``--nonlinear-passes`` and ``--nonlinear-p`` of the spline IEKF."""
    parser.add_argument("--passes", type=int, default=passes,
                        help=f"passes of each linear identification (default {passes})")
    parser.add_argument("--p", type=float, default=p,
                        help=f"tuning parameter p of the linear identifications (default {p:g})")
    parser.add_argument("--nodes", type=int, default=SPLINE_NODES,
                        help=f"spline nodes per coefficient of the nonlinear models (default {SPLINE_NODES})")
    parser.add_argument("--nonlinear-passes", type=int, default=None,
                        help=f"passes of each nonlinear identification (default {SPLINE_PASSES})")
    parser.add_argument("--nonlinear-p", type=float, default=None,
                        help=f"tuning parameter p of the nonlinear identifications (default {SPLINE_P:g})")
