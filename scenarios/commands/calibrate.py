"""Calibrate the 23-state vehicle model to a measured log with the grey-box IEKF.

LOG holds the road-wheel steer (--inputs), the forward speed (--speed) and measured channels
(--outputs), which the model's quantities (--quantities, in the same order: yaw_rate,
lateral_acceleration, roll_angle, sideslip, ...) stand for. The speed drives the model's speed hold
as in ``vehid simulate --replay``; the first part of the log calibrates the vehicle's chosen
parameters (--parameters section.field,..., default the tyres' cornering stiffness PKY1, the front
axle's share of it and the yaw inertia, with the roll inertia and front anti-roll bar when the roll
angle is measured), the last --validation fraction is held out and predicted (the car simulated over the whole log from
its start, its outputs scored on the held-out part). Parameters the log
does not determine (std above their size or half their prior std, or |correlation| > 0.95 with
another) are held at their prior with a warning (exit 3 under --strict); --prior NAME=VALUE[:STD]
sets a parameter's prior and, with STD (in its unit), how well it is known. --out writes the
calibrated vehicle file (TOML), never over an existing file without --force; --figure draws the
measured channels over the whole log against the prior and the calibrated car, each simulated from
straight running at the log's first speed (.png, .pdf or .svg; the same file rule).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from vehid.identification.errors import InputError, StrictWarningsError
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
    parser.add_argument("--validation", type=float, default=0.4,
                        help="fraction of the log at its end held out for validation (default 0.4)")
    parser.add_argument("--parameters", default=None, metavar="NAME,...",
                        help="vehicle fields to calibrate, section.field as in a vehicle file")
    parser.add_argument("--prior", action="append", default=None, metavar="NAME=VALUE[:STD]",
                        help="prior value of a calibrated parameter and optionally its std in the "
                             "parameter's unit (repeatable); default the vehicle's value and --prior-std")
    parser.add_argument("--prior-std", type=float, default=1.0,
                        help="relative prior standard deviation of every parameter (default 1: a factor e)")
    parser.add_argument("--time-column", default=None, help="the log's time column (default t when present)")
    parser.add_argument("--out", default=None, help=f"write the calibrated vehicle to this .toml file ({OUT_RULE})")
    parser.add_argument("--figure", default=None, metavar="FILE",
                        help="draw measured against simulated channels, prior and calibrated car (.png, .pdf, .svg)")
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


def run(args: argparse.Namespace) -> tuple[dict, str]:
    import numpy as np

    from vehid.identification.dataio.archive_safety import check_output_target
    from vehid.identification.filtering.greybox import GreyBoxOptions
    from vehid.identification.assessment.metrics import percentage_explanation
    from vehid.identification.dataio.preparation import ReadSettings, read_record
    from vehid.vehicle import named_vehicle
    from vehid.vehicle.calibration import calibrate_vehicle, calibration_record, vehicle_toml
    from vehid.vehicle.handling import source_handling

    log = Path(args.log)
    if not log.is_file():
        raise InputError(f"no such log: {log}")
    outputs = _names(args.outputs, "--outputs")
    quantities = _names(args.quantities, "--quantities")
    if len(outputs) != len(quantities):
        raise InputError(f"--outputs names {len(outputs)} channel(s), --quantities {len(quantities)}: give one "
                         "quantity per output")
    channels = (args.speed, *outputs)
    if args.inputs in channels or len(set(channels)) != len(channels):
        raise InputError("a log channel is named twice among --inputs, --speed and --outputs")
    if not (math.isfinite(args.validation) and 0 <= args.validation < 1):
        raise InputError(f"--validation is the held-out fraction, in [0, 1); got {args.validation}")
    if not (math.isfinite(args.prior_std) and args.prior_std > 0):
        raise InputError(f"--prior-std must be a positive number; got {args.prior_std}")
    parameters = _names(args.parameters, "--parameters") if args.parameters else None
    priors, prior_std = _priors(args.prior)
    params = named_vehicle(args.vehicle)
    figure = _figure_target(args.figure, args.force)
    if args.out:
        check_output_target(args.out, inputs=[args.vehicle, args.log], force=args.force, what="vehicle file",
                            identify=lambda path: None, suffixes=(".toml",))
    data = read_record(log, ReadSettings(inputs=(args.inputs,), outputs=channels, time_column=args.time_column))
    n_estimation = int(round(data.n_samples * (1 - args.validation)))
    if n_estimation < 50 or (args.validation > 0 and data.n_samples - n_estimation < 50):
        raise InputError(f"the log's {data.n_samples} samples leave fewer than 50 for calibration or validation")
    speed = data.y[:, 0]
    record = calibration_record(data.u[:, 0], speed, data.y[:, 1:], data.dt, quantities, t0=float(data.t[0]))
    estimation = _part(record, 0, n_estimation)
    calibration = calibrate_vehicle(params, estimation, quantities, parameters=parameters, priors=priors,
                                    prior_std=prior_std,
                                    options=GreyBoxOptions(prior_std=args.prior_std, coloured_residuals=True))
    if calibration.result is None:
        raise InputError("the log determines none of the chosen parameters: " + "; ".join(calibration.warnings))
    validation_fit: dict[str, float] = {}
    if args.validation > 0:
        # the calibrated car drives the whole log from its start, so the held-out part begins in the
        # state the car reached (from its inputs alone) rather than from straight running mid-drive
        predicted = calibration.result.simulate(record)[n_estimation:]
        fits = percentage_explanation(record.y[n_estimation:], predicted)
        validation_fit = {channel: float(value) for channel, value in zip(outputs, fits)}
    lo, hi = float(np.min(speed)), float(np.max(speed))
    speeds = sorted({round(v, 1) for v in np.linspace(max(lo, 5.0), max(hi, 5.0), 3)})
    handling = source_handling(calibration.vehicle, speeds, simulate=False).as_dict()
    summary: dict[str, Any] = {
        "log": str(log),
        "vehicle_prior": params.name,
        "samples": int(data.n_samples),
        "estimation_samples": int(n_estimation),
        "parameters": calibration.parameters_dict(),
        "correlation": {name: {other: (None if not math.isfinite(calibration.correlation[i, j])
                                       else float(calibration.correlation[i, j]))
                               for j, other in enumerate(calibration.parameter_names)}
                        for i, name in enumerate(calibration.parameter_names)},
        "not_identifiable": dict(calibration.held),
        "estimation_fit_percent": {channel: float(value)
                                   for channel, value in zip(outputs, calibration.result.fit_percent)},
        "validation_fit_percent": validation_fit,
        "handling": handling,
        "vehicle_file": None,
        "figure": None,
        "warnings": list(calibration.warnings),
    }
    lines = [f"calibration of {params.name} to {log.name}: {n_estimation} of {data.n_samples} samples at "
             f"{1 / data.dt:g} Hz, {len(calibration.result.history)} passes"]
    for name, row in summary["parameters"].items():
        std = "held at prior" if row["std"] is None else f"+/- {row['std']:.3g}"
        lines.append(f"  {name} = {row['value']:.6g} {std} [{row['unit']}]")
    for channel, value in validation_fit.items():
        lines.append(f"hold-out fit {channel}: {value:.1f} %")
    for row in handling["linearisation"]:
        gradient = row["understeer_gradient_deg_per_g"]["value"]
        if gradient is not None:
            lines.append(f"calibrated car at {row['speed']:g} m/s: understeer gradient {gradient:.3g} deg/g")
    if args.out:
        comment = (f"{params.name} calibrated to {log.name} by vehid calibrate "
                   f"({', '.join(calibration.parameter_names)})")
        _write_text(Path(args.out), vehicle_toml(calibration.vehicle, comment))
        summary["vehicle_file"] = str(args.out)
        lines.append(f"wrote {args.out}")
    if figure is not None:
        from vehid.identification.filtering.greybox import simulate_greybox
        from vehid.scenarios.plots import plot_time_fits

        result = calibration.result
        prior, _ = simulate_greybox(result.model, result.start, record, discretization=result.options.discretization,
                                    substeps=result.options.substeps)
        page = plot_time_fits(record.t, record.y, {"prior car": prior, "calibrated car": result.simulate(record)},
                              outputs, record.output_units,
                              title=f"{params.name} calibrated to {log.name}: the first "
                                    f"{n_estimation / data.n_samples:.0%} calibrates, the rest is held out")
        for axis in page.axes:  # where the held-out part begins
            axis.axvline(record.t[n_estimation - 1], color="0.5", linestyle="--", linewidth=1.0)
        page.savefig(figure)
        summary["figure"] = str(figure)
        lines.append(f"wrote {figure}")
    text = "\n".join(lines)
    warnings = list(calibration.warnings)
    if warnings and not args.json and not args.strict:
        text += "\n" + "\n".join(f"warning: {line}" for line in warnings)
    if warnings and args.strict:
        raise StrictWarningsError(warnings, summary, text)
    return summary, text


def _part(record: Any, first: int, stop: int) -> Any:
    """Samples ``first:stop`` of a record, its time base kept."""
    from vehid.identification.data import IOData

    return IOData(t=record.t[first:stop], u=record.u[first:stop], y=record.y[first:stop],
                  input_names=record.input_names, output_names=record.output_names,
                  input_units=record.input_units, output_units=record.output_units)
