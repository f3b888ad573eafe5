"""Handling characteristics of an identified model or of the source model, at each speed.

ISO 4138-style steady state (yaw-rate and lateral-acceleration gains, sideslip
gain, understeer gradient in deg/g, characteristic or critical speed) and ISO
7401-style transients (yaw-rate response and peak response times, overshoot,
gain and phase at 1 Hz, -3 dB bandwidth), each with its standard deviation by
the delta method where the model carries a parameter covariance
(:mod:`vehid.vehicle.handling`).

MODEL is a model file written by ``vehid identify --save-model`` (.json) or an
identification archive (``--out``, .h5: its returned model); a scheduled
model is evaluated at each of --speeds, a model of one speed at the one speed
given. ``--source`` reports the source model instead: its linearisation and
its simulated ISO 7401 step, 1 Hz sine dwell and sine sweep. Warnings (no wheelbase for the
understeer gradient, no covariance for error bars) exit 3 under --strict.
JSON ``uncertainty_method`` says how the model's covariance, and so every
standard deviation, was obtained (as ``vehid identify`` says it; None
without a covariance).

A model of a car is checked for physical plausibility (:mod:`vehid.scenarios.plausibility_checks`): each
failure joins the JSON list ``plausibility`` (``quantity``, ``value``, ``range``, ``speed``, ``cause``) and
the warnings. Each row of ``metrics`` says whether the model is ``extrapolated`` at its speed (a scheduled
family's knot with too few samples, a speed beyond the log's).

The command is a client of the library: it maps its arguments to
:func:`vehid.scenarios.car_handling.handling` and prints the result's rendering.
"""

from __future__ import annotations

import argparse
import math

from vehid.identification.errors import InputError

NAME = "handling"
GROUP = None
HELP = "handling metrics (ISO 4138 / ISO 7401) of an identified model or of the source model at each speed"

#: The model's channels ``--scale`` names (the library's ROLES, said here so that registering imports nothing).
ROLES = ("steer", "yaw_rate", "lateral_acceleration", "sideslip")


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("model", nargs="?", default=None,
                        help="model file (.json from --save-model) or identification archive (.h5)")
    parser.add_argument("--source", action="store_true", help="report the source vehicle model instead of MODEL")
    parser.add_argument("--vehicle", default="baseline",
                        help="with --source: baseline, understeer, or a .toml/.json vehicle file")
    parser.add_argument("--speeds", default=None,
                        help="comma-separated speeds in m/s (default: 10,20,30 for --source, a scheduled "
                             "model's grid, or the speed stored with a one-speed model)")
    parser.add_argument("--yaw-rate", default=None, help="the model's yaw-rate output (default: yaw_rate)")
    parser.add_argument("--lateral-acceleration", default=None,
                        help="the model's lateral-acceleration output (default: lateral_acceleration, if any)")
    parser.add_argument("--sideslip", default=None, help="the model's sideslip output (default: sideslip, if any)")
    parser.add_argument("--steer", default=None, help="the model's steer input (default: steer, else the first)")
    parser.add_argument("--wheelbase", type=float, default=None, help="wheelbase in m, for the understeer gradient")
    parser.add_argument("--scale", default=None,
                        help="factors to SI of the model's channels, e.g. steer=0.001091,yaw_rate=0.01745 "
                             "(steer to road-wheel rad; yaw rate to rad/s; lateral acceleration to m/s^2)")
    parser.add_argument("--run", default=None, help="the archive's run whose model to use (default: the returned one)")
    parser.add_argument("--no-simulation", action="store_true",
                        help="with --source: the linearisation only, no simulated step, sine dwell and sweep")
    parser.add_argument("--step-lateral-acceleration", type=float, default=None,
                        help="with --source: steady lateral acceleration of the simulated step in m/s^2 "
                             "(default 4, as ISO 7401)")
    parser.add_argument("--steady-range", type=float, default=None, metavar="A",
                        help="with --source: also the steady state over +/- A m/s^2 of lateral acceleration "
                             "(ISO 4138 steer steps): the reference for a model fitted on data reaching A")
    parser.add_argument("--beside-source", default=None, metavar="VEHICLE",
                        help="with MODEL: also the source model's linearisation at the same speeds "
                             "(baseline, understeer, or a .toml/.json vehicle file)")
    parser.add_argument("--figure", default=None,
                        help="write the handling page (gains and understeer gradient against speed, "
                             "+/- 2 std bands) to this .png, .pdf or .svg file")
    parser.add_argument("--force", action="store_true", help="let --figure replace an existing file")
    parser.add_argument("--strict", action="store_true", help="exit with status 3 when the result has warnings")
    parser.set_defaults(handler=run)


def parse_speeds(text: str) -> list[float]:
    """``"10,20,30"`` as speeds in m/s, or InputError naming the bad entry."""
    speeds = []
    for item in str(text).split(","):
        try:
            value = float(item)
        except ValueError:
            raise InputError(f"--speeds takes comma-separated numbers in m/s; got {item.strip()!r}") from None
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--speeds must be positive and finite (m/s); got {item.strip()}")
        speeds.append(value)
    return speeds


def parse_scales(text: str | None) -> dict[str, float]:
    """``"steer=0.0175,yaw_rate=0.0175"`` as factors to SI per channel role."""
    scales: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in (text or "").split(","))):
        role, _, value = item.partition("=")
        role = role.strip().replace("-", "_")
        if role not in ROLES or not value:
            raise InputError(f"--scale takes ROLE=FACTOR with ROLE one of {', '.join(ROLES)}; got {item!r}")
        try:
            factor = float(value)
        except ValueError:
            raise InputError(f"--scale {role} must be a number; got {value!r}") from None
        if not (math.isfinite(factor) and factor != 0):
            raise InputError(f"--scale {role} must be finite and non-zero; got {value}")
        scales[role] = factor
    return scales


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.scenarios.car_handling import HandlingOptions, SourceHandlingOptions, handling

    speeds = parse_speeds(args.speeds) if args.speeds is not None else None
    if args.source:
        if args.model is not None:
            raise InputError("--source reports the source model: give no MODEL")
        for option in ("yaw_rate", "lateral_acceleration", "sideslip", "steer", "wheelbase", "scale", "run",
                       "beside_source"):
            if getattr(args, option) is not None:
                raise InputError(f"--{option.replace('_', '-')} applies to an identified MODEL, not to --source")
        if args.steady_range is not None and not (math.isfinite(args.steady_range) and args.steady_range > 0):
            raise InputError(f"--steady-range must be a positive lateral acceleration (m/s^2); got {args.steady_range}")
        options = SourceHandlingOptions(simulation=not args.no_simulation,
                                        step_lateral_acceleration=args.step_lateral_acceleration,
                                        steady_range=args.steady_range, strict=args.strict)
        result = handling(source=args.vehicle, speeds=speeds, options=options, figure=args.figure, force=args.force)
    else:
        if args.model is None:
            raise InputError("give a MODEL file or archive, or --source for the source model")
        for option, given in (("--vehicle", args.vehicle != "baseline"), ("--no-simulation", args.no_simulation),
                              ("--step-lateral-acceleration", args.step_lateral_acceleration is not None),
                              ("--steady-range", args.steady_range is not None)):
            if given:
                raise InputError(f"{option} applies to --source only")
        options = HandlingOptions(yaw_rate=args.yaw_rate, lateral_acceleration=args.lateral_acceleration,
                                  sideslip=args.sideslip, steer=args.steer, wheelbase=args.wheelbase,
                                  scales=parse_scales(args.scale), run=args.run, beside_source=args.beside_source,
                                  strict=args.strict)
        result = handling(args.model, speeds=speeds, options=options, figure=args.figure, force=args.force)
    # the warnings close the text (under --json they are in the summary, under --strict the command line says them)
    return result.render(), result.text(warnings=not args.json)
