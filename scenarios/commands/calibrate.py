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
and the front/rear cornering balance of the log's quasi-steady corners; each change is a note. The
first part of the log calibrates the chosen parameters (--parameters section.field,..., default the
front cornering scale, the tyres' load sensitivity PKY2, the friction scale and the yaw inertia,
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
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from vehid.identification.errors import InputError, PartialResultError, StrictWarningsError
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
    parser.add_argument("--validation", type=float, default=0.4,
                        help="fraction of the log at its end held out for validation (default 0.4)")
    parser.add_argument("--segment", default=None, metavar="T0:T1",
                        help="use only this part of the log (s; as the workbench's readers take it)")
    parser.add_argument("--despike", action="store_true",
                        help="replace the spikes and drop-outs found in the channels by straight lines between "
                             "their neighbours (they are named either way)")
    parser.add_argument("--time-column", default=None, help="the log's time column (default t when present)")
    parser.add_argument("--scale", action="append", metavar="NAME=FACTOR", default=None,
                        help="multiply a log channel by FACTOR (a unit or a sign); repeatable or a comma list")
    parser.add_argument("--parameters", default=None, metavar="NAME,...",
                        help="vehicle fields to calibrate, section.field as in a vehicle file (default "
                             "tyre.front_cornering_scale, tyre.PKY2, tyre.friction_scale, chassis.yaw_inertia; "
                             "with the sideslip fitted also tyre.rear_cornering_scale, with the roll angle "
                             "chassis.roll_inertia and suspension.front_anti_roll_bar)")
    parser.add_argument("--prior", action="append", default=None, metavar="NAME=VALUE[:STD]",
                        help="prior value of a calibrated parameter and optionally its std in the "
                             "parameter's unit (repeatable); default the vehicle's value and --prior-std")
    parser.add_argument("--prior-std", type=float, default=None,
                        help="relative prior standard deviation of every parameter (1: a factor e); default the "
                             "plausible spread of each default parameter (0.2-0.5), 1 for the others")
    parser.add_argument("--p", type=float, default=None,
                        help="the filter's random-walk variance of a scaled parameter per pass (default 1e-4); "
                             "smaller holds the parameters steadier")
    parser.add_argument("--passes", type=int, default=None, help="most passes of the filter per stage (default 30)")
    parser.add_argument("--substeps", type=int, default=None,
                        help="RK4 steps per sample (default and least: the fewest that keep the car's modes "
                             "stable at the log's top speed)")
    parser.add_argument("--slip-limit", type=float, default=None,
                        help="slip ratio at which the car's drive and brake torques fade (default: the "
                             "vehicle's, else 0.1; 0: none)")
    parser.add_argument("--no-halves", action="store_true",
                        help="skip calibrating the two halves of the calibrating part again (faster)")
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


def _priors(items: list[str] | None) -> tuple[dict[str, float], dict[str, float]]:
    """``--prior`` items as ``(name -> value, name -> std)``."""
    priors: dict[str, float] = {}
    stds: dict[str, float] = {}
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
        priors[name.strip()] = number
        if colon:
            stds[name.strip()] = std
    return priors, stds


_FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def _figure_target(figure: str | None, force: bool) -> Path | None:
    """The --figure path, checked before any work: a figure suffix, an existing folder, no file unless --force."""
    if figure is None:
        return None
    path = Path(figure)
    if path.suffix.lower() not in _FIGURE_SUFFIXES:
        raise InputError(f"--figure takes a {', '.join(_FIGURE_SUFFIXES)} file; got {figure!r}")
    if not path.parent.is_dir():
        raise InputError(f"--figure: no folder {str(path.parent)!r}")
    if path.is_dir() or (path.exists() and not force):
        raise InputError(f"--figure {figure!r} exists: choose another name or give --force")
    return path


def _write_text(path: Path, text: str) -> None:
    """Write under a hidden name and rename: a killed run never leaves half a file at --out."""
    import os
    import uuid

    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
    try:
        temporary.write_text(text)
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()


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


def _fit_list(values: Any) -> list[float | None] | None:
    """Per-output scores as a JSON list (None for a non-finite score)."""
    if values is None:
        return None
    return [float(v) if math.isfinite(v) else None for v in values]


def _fit_keys(fits: dict, label: str, channels: tuple[str, ...]) -> dict[str, Any]:
    """The ``*_fit_percent`` (NRMSE) keys of one car's scores and the ``*_R`` keys (R of eq. 17) beside them."""
    prefix = "" if label == "calibrated" else f"{label}_"
    scores = fits.get(label)
    keys: dict[str, Any] = {}
    for part in ("estimation", "validation"):
        if label != "calibrated" and part == "estimation":
            continue
        score = scores.get(part) if scores else None
        keys[f"{prefix}{part}_fit_percent"] = _fit_list(score["nrmse"]) if score else None
        keys[f"{prefix}{part}_R"] = _fit_list(score["R"]) if score else None
    validation = scores.get("validation") if scores else None
    for key, scored in (("check_fit_percent", "checks"), ("check_R", "checks_R")):
        keys[f"{prefix}{key}"] = ({channel: (value if math.isfinite(value) else None)
                                   for channel, value in validation[scored].items()} if validation else None)
    return keys


def run(args: argparse.Namespace) -> tuple[dict, str]:
    import numpy as np

    from vehid.identification.dataio.archive_safety import check_output_target
    from vehid.identification.dataio.cleaning import despike, find_outliers
    from vehid.identification.filtering.greybox import GreyBoxOptions
    from vehid.identification.dataio.timewindow import time_text
    from vehid.scenarios.drive_log import read_drive, scaled_channels
    from vehid.vehicle import named_vehicle
    from vehid.vehicle.drive_calibration import DRIVE_PARAMETER_TOLERANCE, DriveLog, calibrate_drive
    from vehid.vehicle.model import OUTPUT_NAMES, speed_limit
    from vehid.vehicle.validity import MIN_SPEED

    log = Path(args.log)
    if not log.is_file():
        raise InputError(f"no such log: {log}")
    outputs = _names(args.outputs, "--outputs")
    quantities = _names(args.quantities, "--quantities")
    if len(outputs) != len(quantities):
        raise InputError(f"--outputs names {len(outputs)} channel(s), --quantities {len(quantities)}: give one "
                         "quantity per output")
    checks = _checks(args.check)
    for channel, quantity in checks.items():
        if quantity not in OUTPUT_NAMES:
            raise InputError(f"--check {channel}={quantity}: unknown quantity; the model offers "
                             f"{', '.join(OUTPUT_NAMES)}")
    channels = (args.speed, *outputs, *checks, *((args.acceleration,) if args.acceleration else ()))
    if args.inputs in channels or len(set(channels)) != len(channels):
        raise InputError("a log channel is named twice among --inputs, --speed, --outputs, --check and --acceleration")
    if not (math.isfinite(args.validation) and 0 <= args.validation < 1):
        raise InputError(f"--validation is the held-out fraction, in [0, 1); got {args.validation}")
    if args.prior_std is not None and not (math.isfinite(args.prior_std) and args.prior_std > 0):
        raise InputError(f"--prior-std must be a positive number; got {args.prior_std}")
    if args.slip_limit is not None and not (math.isfinite(args.slip_limit) and 0 <= args.slip_limit < 0.5):
        raise InputError(f"--slip-limit is a slip ratio in [0, 0.5); got {args.slip_limit}")
    filter_settings = {name: value for name, value in (("p", args.p), ("passes", args.passes),
                                                       ("substeps", args.substeps)) if value is not None}
    options = GreyBoxOptions(prior_std=args.prior_std or 1.0, coloured_residuals=True,
                             parameter_tolerance=DRIVE_PARAMETER_TOLERANCE, **filter_settings)
    parameters = _names(args.parameters, "--parameters") if args.parameters else None
    priors, prior_std = _priors(args.prior)
    params = named_vehicle(args.vehicle)
    figure = _figure_target(args.figure, args.force)
    if args.out:
        check_output_target(args.out, inputs=[args.vehicle, args.log], force=args.force, what="vehicle file",
                            identify=lambda path: None, suffixes=(".toml",))
    data, scale = read_drive(log, args.inputs, channels, args.scale, what="a channel of this calibration",
                             time_column=args.time_column, segment=args.segment)
    outliers = find_outliers(data)
    if args.despike and outliers:
        data = despike(data, outliers)
    channel = scaled_channels(data, args.inputs, scale)

    offset = float(data.meta.get("time_base", {}).get("time_offset", 0.0) or 0.0)
    drive = DriveLog(
        t=data.t, steer=channel(args.inputs), speed=channel(args.speed),
        outputs=np.column_stack([channel(name) for name in outputs]), channels=outputs, quantities=quantities,
        acceleration=channel(args.acceleration) if args.acceleration else None,
        checks={name: (quantity, channel(name)) for name, quantity in checks.items()},
    )
    result = calibrate_drive(params, drive, validation=args.validation, parameters=parameters, priors=priors,
                             prior_std=prior_std, options=options, slip_limit=args.slip_limit,
                             halves=not args.no_halves, relative_prior_std=args.prior_std)
    summary, lines = _summary(args, log, params, drive, result, outputs, speed_limit(params), MIN_SPEED)
    summary["outliers"] = [{**outlier.as_dict(), "treatment": "interpolated" if args.despike else "in the fit"}
                           for outlier in outliers]
    if args.out:
        _write_vehicle(args, log, params, result, summary, lines)
    if figure is not None:
        _draw(figure, log, params, drive, result, outputs, checks)
        summary["figure"] = str(figure)
        lines.append(f"wrote {figure}")
    text = "\n".join(lines)
    warnings = list(result.warnings)
    if outliers and not args.despike:
        shown = ", ".join(f"{o.channel} {o.value:.4g} at {time_text(o.time - offset, offset)}" for o in outliers[:5])
        warnings.insert(0, f"{len(outliers)} spike(s) or drop-out(s) entered the calibration: {shown}"
                           f"{' and more' if len(outliers) > 5 else ''}; --despike replaces them by interpolation")
    elif outliers:
        lines.append(f"{len(outliers)} spike(s) or drop-out(s) replaced by straight lines between their neighbours "
                     "(--despike); the JSON key outliers lists their values as read")
        text = "\n".join(lines)
    summary["warnings"] = warnings
    if result.failure is not None:
        # the filter's advice (other start values, a smaller p) in this command's options
        advice = ("; here --prior NAME=VALUE gives a parameter another start and --p a smaller random walk"
                  if "diverged" in result.failure else "")
        raise PartialResultError(f"the calibration failed part of the way: {result.failure}{advice}", summary,
                                 text + "".join(f"\nwarning: {line}" for line in warnings))
    if warnings and not args.json and not args.strict:
        text += "\n" + "\n".join(f"warning: {line}" for line in warnings)
    if warnings and args.strict:
        raise StrictWarningsError(warnings, summary, text)
    return summary, text


def _summary(args: argparse.Namespace, log: Path, params: Any, drive: Any, result: Any, outputs: tuple[str, ...],
             top: float, low: float) -> tuple[dict[str, Any], list[str]]:
    """The JSON summary and the text lines of a drive calibration."""
    import numpy as np

    from vehid.vehicle.handling import source_handling

    calibration = result.calibration
    names = calibration.parameter_names if calibration is not None else ()
    summary: dict[str, Any] = {
        "log": str(log),
        "vehicle_prior": params.name,
        "samples": int(drive.n_samples),
        "estimation_samples": int(result.n_estimation),
        "valid_speed_range": [low, top],
        "records": [[float(drive.t[a]), float(drive.t[b - 1])] for a, b in result.runs],
        "samples_driven": int(sum(b - a for a, b in result.runs)),
        "substeps": int(result.substeps),
        "parameters": calibration.parameters_dict() if calibration is not None else {},
        "correlation": {name: {other: (None if not math.isfinite(calibration.correlation[i, j])
                                       else float(calibration.correlation[i, j]))
                               for j, other in enumerate(names)}
                        for i, name in enumerate(names)},
        "not_identifiable": dict(calibration.held) if calibration is not None else {},
        **_fit_keys(result.fits, "calibrated", outputs),
        **_fit_keys(result.fits, "prior", outputs),
        **_fit_keys(result.fits, "start", outputs),
        "stages": [{"stage": label, "passes": len(stage.result.history),
                    "parameters": {name: row for name, row in stage.parameters_dict().items()
                                   if row["std"] is not None}}
                   for label, stage in result.stages],
        "balance": result.balance.as_dict() if result.balance is not None else None,
        "halves": {name: {**{half: None if row[half] is None else {"value": row[half][0], "std": row[half][1]}
                             for half in ("first", "second")}, "difference_sigma": row["difference_sigma"],
                          "not_determined": dict(row.get("not_determined", {}))}
                   for name, row in result.halves.items()},
        "notes": list(result.notes),
        "failure": result.failure,
        "handling": None,
        "vehicle_file": None,
        "figure": None,
    }
    driven = drive.speed[np.concatenate([np.arange(a, b) for a, b in result.runs])]
    lines = [f"calibration of {params.name} to {log.name}: {result.n_estimation} of {drive.n_samples} samples at "
             f"{1 / drive.dt:g} Hz calibrate, the rest is held out; speed range of this vehicle {low:g}-{top:g} m/s"]
    lines.extend(f"note: {note}" for note in result.notes)
    for label, stage in result.stages:
        lines.append(f"stage {label}: {len(stage.result.history)} passes")
    earlier = {name: (label, row["std"]) for label, stage in result.stages
               for name, row in stage.parameters_dict().items() if row["std"] is not None}
    for name, row in summary["parameters"].items():
        if row["std"] is not None:
            std = f"+/- {row['std']:.3g}"
        elif name in earlier:
            std = f"held at stage '{earlier[name][0]}' (+/- {earlier[name][1]:.3g} there)"
        else:
            std = "held"
        in_vehicle = f"; in the vehicle file {row['in_vehicle']:.6g}" if "in_vehicle" in row else ""
        lines.append(f"  {name} = {row['value']:.6g} {std} [{row['unit']}]{in_vehicle}")
    for label, key in (("prior", "prior_validation_fit_percent"), ("start", "start_validation_fit_percent"),
                       ("calibrated", "validation_fit_percent")):
        values = summary.get(key)
        checks = summary.get(f"{'' if label == 'calibrated' else label + '_'}check_fit_percent") or {}
        if values is None:
            lines.append(f"hold-out NRMSE fit, {label} car: not scored (its simulation is not finite)"
                         if args.validation > 0 else "")
            continue
        shown = ", ".join(f"{channel} {value:.1f} %" if value is not None else f"{channel} -"
                          for channel, value in zip(outputs, values))
        unfitted = ", ".join(f"{channel} {value:.1f} % (not fitted)" for channel, value in checks.items()
                             if value is not None)
        lines.append(f"hold-out NRMSE fit, {label} car: {shown}" + (f"; {unfitted}" if unfitted else ""))
    for name, row in summary["halves"].items():
        shown = [f"{row[half]['value']:.5g} +/- {row[half]['std']:.2g}" if row[half] else
                 f"not determined ({row['not_determined'].get(half, 'held')})" for half in ("first", "second")]
        apart = "" if row["difference_sigma"] is None else f" ({row['difference_sigma']:.1f} std apart)"
        lines.append(f"halves of the calibrating part: {name} {shown[0]} and {shown[1]}{apart}")
    # the calibrated car's handling where the log drove it, inside its own speed range
    lo, hi = float(np.min(driven)), float(np.max(driven))
    speeds = sorted({round(v, 1) for v in np.linspace(max(lo, 5.0), min(max(hi, 5.0), top), 3)})
    try:
        summary["handling"] = source_handling(result.vehicle, speeds, simulate=False).as_dict()
    except (InputError, ValueError, np.linalg.LinAlgError) as exc:
        summary["notes"].append(f"handling of the calibrated car not computed: {exc}")
    if summary["handling"] is not None:
        for row in summary["handling"]["linearisation"]:
            gradient = row["understeer_gradient_deg_per_g"]["value"]
            if gradient is not None:
                lines.append(f"calibrated car at {row['speed']:g} m/s: understeer gradient {gradient:.3g} deg/g")
    return summary, [line for line in lines if line]


def _write_vehicle(args: argparse.Namespace, log: Path, params: Any, result: Any, summary: dict,
                   lines: list[str]) -> None:
    from vehid.vehicle.calibration import vehicle_toml

    if result.calibration is not None:
        what = f"calibrated to {log.name} by vehid calibrate ({', '.join(result.calibration.parameter_names)})"
        if result.failure is not None:
            what += f"; the last stage that finished ({result.stages[-1][0]}): {result.failure}"
    else:
        what = f"NOT calibrated: the start derived from {log.name} by vehid calibrate; {result.failure}"
    _write_text(Path(args.out), vehicle_toml(result.vehicle, f"{params.name} {what}"))
    summary["vehicle_file"] = str(args.out)
    lines.append(f"wrote {args.out}")


def _draw(figure: Path, log: Path, params: Any, drive: Any, result: Any, outputs: tuple[str, ...],
          checks: dict[str, str]) -> None:
    """Write :func:`_figure_page` to ``figure``."""
    import matplotlib.pyplot as plt

    page = _figure_page(log, params, drive, result, outputs, checks)
    try:
        page.savefig(figure)
    finally:
        plt.close(page)


def _figure_page(log: Path, params: Any, drive: Any, result: Any, outputs: tuple[str, ...],
                 checks: dict[str, str]) -> Any:
    """Measured channels (fitted, then checked) against each scored car over the whole log: what the JSON
    scores, the legends giving each car's hold-out NRMSE fit and R."""
    import textwrap

    import numpy as np

    from vehid.scenarios.plots import plot_time_fits
    from vehid.vehicle.model import OUTPUT_NAMES, OUTPUT_UNITS

    units = dict(zip(OUTPUT_NAMES, OUTPUT_UNITS))
    quantities = drive.quantities + tuple(checks.values())
    measured = np.column_stack([drive.outputs] + [values for _, values in drive.checks.values()])
    predictions, scores = {}, {}
    for label in ("prior", "start", "calibrated"):
        if label not in result.predictions or result.fits.get(label) is None:
            continue
        score = result.fits[label].get("validation")
        name = label
        predictions[name] = result.predictions[label]
        if score:
            scores[name] = (np.concatenate([score["nrmse"], [score["checks"][channel] for channel in checks]]),
                            np.concatenate([score["R"], [score["checks_R"][channel] for channel in checks]]))
    title = textwrap.fill(f"{params.name} calibrated to {log.name}: the first "
                          f"{result.n_estimation / drive.n_samples:.0%} calibrates, the rest (after the dashed line) "
                          "is held out and scored in the legends" + (f"; {', '.join(checks)} not fitted" if checks
                                                                     else ""), 60)
    page = plot_time_fits(drive.t, measured, predictions, (*outputs, *checks), [units[q] for q in quantities],
                          title=title, scores=scores or None)
    for axis in page.axes:  # where the held-out part begins
        axis.axvline(drive.t[result.n_estimation - 1], color="0.5", linestyle="--", linewidth=1.0)
    return page
