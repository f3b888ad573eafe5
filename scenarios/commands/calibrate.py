"""Calibrate the 23-state vehicle model to a measured log with the grey-box IEKF.

LOG holds the road-wheel steer (--inputs), the forward speed (--speed) and measured channels
(--outputs), which the model's quantities (--quantities, in the same order: yaw_rate,
lateral_acceleration, roll_angle, sideslip, ...) stand for; --acceleration names a measured
longitudinal acceleration, fed forward to the model's speed hold in place of the speed's rate.
The speed drives the model's speed hold as in ``vehid simulate --replay``. Parts of the log outside
the vehicle's speed range (standstill, below 3 m/s, above its top speed: 50 m/s, or 75 m/s with
aerodynamics) are left out with a note, each stretch inside it its own record.

The car starts from the prior vehicle (--vehicle) made able to drive the log: the friction the log's
largest accelerations need, a centre of gravity low enough not to tip, a slip limiter (--slip-limit)
and the front/rear cornering balance of the log's quasi-steady corners, whose steer at zero
lateral acceleration, where it stands out of its std, is a steer sensor's zero error removed from the
steer; each change is a note. The first part of the log calibrates the chosen parameters
(--parameters section.field,..., default the front cornering scale, the tyres' load sensitivity
PKY2, the friction scale, the yaw inertia and the curvature PEY1 of the tyres' lateral force,
with the rear cornering scale when the sideslip is fitted and the roll inertia and front anti-roll
bar when the roll angle is measured), in stages (balance, then everything, then roll); the last
--validation fraction is held out and predicted, the prior, start and calibrated cars each driven
over the whole log from its start and scored alike by the NRMSE fit (``*_fit_percent``; R of eq.
17 under ``*_R``). --check CHANNEL=QUANTITY scores a measured
channel that is never fitted (``check_fit_percent``). The two halves of the calibrating part are
calibrated again and compared. Parameters the log does not determine (std above their size or half
their prior std, or |correlation| > 0.95 with another) are held with a warning (exit 3 under
--strict); --prior NAME=VALUE[:STD] sets a parameter's prior and, with STD (in its unit), how well
it is known. --out writes the calibrated vehicle file (TOML), never over an existing file without
--force; --figure draws the measured channels over the whole log against the prior, start and
calibrated cars (.png, .pdf or .svg; the same file rule). A stage that fails keeps the last one
that finished: its vehicle file, figure and JSON are written, the failure named, exit status 1.

The command is a client of the library: it maps its arguments to
:func:`vehid.scenarios.car_calibration.calibrate` and its :class:`~vehid.scenarios.CalibrateOptions`
and prints the result's rendering.
"""

from __future__ import annotations

import argparse
import math

from vehid.identification.errors import InputError
from vehid.scenarios.car_calibration import CalibrateOptions
from vehid.scenarios.commands.flags import add_option
from vehid.scenarios.paths import OUT_RULE

NAME = "calibrate"
GROUP = None
HELP = "calibrate the full-vehicle model's parameters to a measured log (grey-box IEKF)"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", help="measured log (.csv, .dat, .txt, .mat, .mf4 or a workbench .h5 record)")
    parser.add_argument("--vehicle", default="baseline",
                        help="the prior vehicle: baseline, understeer, saloon or a .toml/.json vehicle file")
    parser.add_argument("--inputs", required=True, metavar="STEER", help="the log's road-wheel steer channel (rad)")
    parser.add_argument("--speed", required=True, metavar="CHANNEL", help="the log's forward speed channel (m/s)")
    parser.add_argument("--outputs", required=True, metavar="CH,...", help="the log's measured channels")
    parser.add_argument("--quantities", required=True, metavar="Q,...",
                        help="the model quantity each output measures, in order (yaw_rate, lateral_acceleration, "
                             "roll_angle, sideslip, ...; SI units)")
    parser.add_argument("--acceleration", default=None, metavar="CHANNEL",
                        help="the log's longitudinal acceleration (m/s^2), fed forward to the speed hold "
                             "(default: the speed's smoothed rate)")
    parser.add_argument("--check", action="append", default=None, metavar="CHANNEL=QUANTITY",
                        help="score a measured channel the calibration does not fit, e.g. beta_true=sideslip "
                             "(repeatable)")
    add_option(parser, CalibrateOptions, "validation")
    parser.add_argument("--segment", default=None, metavar="T0:T1",
                        help="use only this part of the log (s; as the workbench's readers take it)")
    add_option(parser, CalibrateOptions, "despike")
    parser.add_argument("--time-column", default=None, help="the log's time column (default t when present)")
    parser.add_argument("--scale", action="append", metavar="NAME=FACTOR", default=None,
                        help="multiply a log channel by FACTOR (a unit or a sign); repeatable or a comma list")
    add_option(parser, CalibrateOptions, "parameters", metavar="NAME,...")
    add_option(parser, CalibrateOptions, "prior", action="append", default=None, metavar="NAME=VALUE[:STD]",
               note="repeatable")
    add_option(parser, CalibrateOptions, "prior_std")
    add_option(parser, CalibrateOptions, "p")
    add_option(parser, CalibrateOptions, "passes")
    add_option(parser, CalibrateOptions, "substeps")
    add_option(parser, CalibrateOptions, "slip_limit")
    add_option(parser, CalibrateOptions, "halves")
    parser.add_argument("--out", default=None, help=f"write the calibrated vehicle to this .toml file ({OUT_RULE})")
    parser.add_argument("--figure", default=None, metavar="FILE",
                        help="draw measured against simulated channels, prior, start and calibrated car "
                             "(.png, .pdf, .svg)")
    parser.add_argument("--force", action="store_true", help="let --out or --figure replace an existing file")
    parser.add_argument("--strict", action="store_true", help="exit with status 3 when the result has warnings")
    parser.set_defaults(handler=run)


def _names(text: str, option: str) -> tuple[str, ...]:
    names = tuple(item.strip() for item in str(text).split(",") if item.strip())
    if not names:
        raise InputError(f"{option} needs at least one name")
    return names


def _priors(items: list[str] | None) -> dict[str, float | tuple[float, float]]:
    """``--prior`` items as ``name -> value``, or ``name -> (value, std)`` where a std is given."""
    priors: dict[str, float | tuple[float, float]] = {}
    for item in items or ():
        name, equals, text = item.partition("=")
        value, colon, std_text = text.partition(":")
        try:
            number = float(value)
            std = float(std_text) if colon else 1.0
        except ValueError:
            number = std = math.nan
        if not equals or not name.strip() or not math.isfinite(number) or not (math.isfinite(std) and std > 0):
            raise InputError(f"--prior takes NAME=VALUE[:STD] with a finite value and a positive std; got {item!r}")
        priors[name.strip()] = (number, std) if colon else number
    return priors


def _checks(items: list[str] | None) -> dict[str, str]:
    """``--check`` items as ``channel -> quantity``."""
    checks: dict[str, str] = {}
    for item in items or ():
        channel, equals, quantity = item.partition("=")
        if not equals or not channel.strip() or not quantity.strip():
            raise InputError(f"--check takes CHANNEL=QUANTITY, e.g. beta_true=sideslip; got {item!r}")
        if channel.strip() in checks:
            raise InputError(f"--check names {channel.strip()!r} twice")
        checks[channel.strip()] = quantity.strip()
    return checks


def options_from_args(args: argparse.Namespace) -> CalibrateOptions:
    """The calibration's settings named by the command's arguments (each checked where it is declared)."""
    return CalibrateOptions(
        validation=args.validation, parameters=_names(args.parameters, "--parameters") if args.parameters else None,
        prior=_priors(args.prior), prior_std=args.prior_std, p=args.p, passes=args.passes, substeps=args.substeps,
        slip_limit=args.slip_limit, halves=args.halves, despike=args.despike, strict=args.strict)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.scenarios.car_calibration import calibrate

    options = options_from_args(args)  # before the log is read: a bad option costs nothing
    reading = ReadSettings(inputs=(args.inputs,), outputs=_names(args.outputs, "--outputs"),
                           time_column=args.time_column, segment=args.segment)
    result = calibrate(args.log, speed=args.speed, quantities=_names(args.quantities, "--quantities"),
                       reading=reading, vehicle=args.vehicle, acceleration=args.acceleration, checks=_checks(args.check),
                       options=options, scale=args.scale, out=args.out, figure=args.figure, force=args.force)
    # the warnings close the text (under --json they are in the summary, under --strict the command line says them)
    return result.render(), result.text(warnings=not args.json)
