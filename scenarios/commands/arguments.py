"""Option groups several commands share: the output options every command has, and the data-file options.

Their defaults and choices come from plain constants
(:mod:`vehid.identification.choices`), so that registering them imports
nothing a command computes with.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.choices import JITTER_TOLERANCE, SPLINE_NODES, SPLINE_P, SPLINE_PASSES
from vehid.scenarios.commands.flags import add_option

__all__ = ["common_options", "register_data_options", "add_filter_options", "channel_names", "reading_settings",
           "min_speed_of", "run_digest", "NOT_THE_RUN"]


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

    :func:`reading_settings` reads the reading options back as the library's
    :class:`~vehid.identification.dataio.preparation.ReadSettings`; the others are
    keywords of :func:`vehid.identification.identify` of the same names.
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


def channel_names(text: str | None) -> tuple[str, ...]:
    """Channel names from a comma-separated option (empty for None); an empty list is an error."""
    from vehid.identification.errors import InputError

    if text is None:
        return ()
    names = tuple(name.strip() for name in text.split(",") if name.strip())
    if not names:
        raise InputError("an empty column list was given")
    return names


def reading_settings(args: argparse.Namespace, *, inputs: str | None = None, outputs: str | None = None) -> Any:
    """The :class:`~vehid.identification.dataio.preparation.ReadSettings` the data options describe (``inputs``
    and ``outputs``: comma-separated channels in place of ``--inputs`` and ``--outputs``)."""
    from vehid.identification.dataio.preparation import ReadSettings

    return ReadSettings(
        inputs=channel_names(args.inputs if inputs is None else inputs),
        outputs=channel_names(args.outputs if outputs is None else outputs), time_column=args.time_column,
        dt=args.dt, resample=args.resample, decimate=args.decimate, segment=args.segment,
        jitter_tolerance=args.jitter_tolerance, time_scale=args.time_scale)


def min_speed_of(text: str | None, *, moving_model: bool) -> float | None:
    """The least speed (m/s) the records are cut at: ``--min-speed`` (a speed, or ``none`` to keep every
    sample), else :data:`~vehid.scenarios.log_cleaning.MIN_SPEED` for a model that needs a moving car;
    None where no speed cuts them."""
    from vehid.identification.errors import InputError
    from vehid.scenarios.log_cleaning import MIN_SPEED

    if text is None:
        return MIN_SPEED if moving_model else None
    if text.strip().lower() == "none":
        return None
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"--min-speed takes a speed (m/s) or none; got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"--min-speed takes a finite speed (m/s) or none; got {text!r}")
    return value


#: Options that choose where or how the output is shown or written, or how the work is spread over
#: processes: they change no result, so rerunning with other values is the same run.
NOT_THE_RUN = frozenset({
    "handler", "out", "force", "resume", "save_model", "json", "quiet", "verbose", "strict", "no_report",
    "workers", "executor", "scheduler",
})


def run_digest(args: argparse.Namespace) -> str:
    """The digest that says which run a command line asks for: the command, its settings and its input files'
    content (:func:`~vehid.identification.dataio.archive_safety.settings_digest`), without :data:`NOT_THE_RUN`."""
    from vehid.identification.dataio.archive_safety import settings_digest

    handler = getattr(args, "handler", None)
    command = f"{getattr(handler, '__module__', '')}.{getattr(handler, '__name__', '')}"
    return settings_digest(command, {name: value for name, value in vars(args).items() if name not in NOT_THE_RUN})
