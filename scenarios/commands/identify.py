"""Identify a modal state-space model from an input/output record.

DATA is one or several files: workbench HDF5 (as written by `vehid simulate
--out`), CSV, whitespace-separated .dat/.txt, MATLAB .mat or ASAM MDF4 .mf4.
Name the channels with --inputs and --outputs (for an HDF5 record they select
among its inputs and outputs; for other files they are required; text tables
also take 1-based column numbers). Time comes from a column `t`, the column
--time-column names, or --dt; --resample, --decimate and --segment shape the
time base. Each record's offsets (means, or lines with --detrend linear) are
removed and kept with the model, --scale multiplies a channel; several files
identify one model, scored per record ("records" in the JSON summary).

The default method is the Identifying EKF (Best & Bogdanski 2017) with the
exact first-order-hold discretisation, so the identified parameters are those
of the continuous-time model; --discretization euler reproduces the paper's
filter. The defaults do not depend on the units of time or of the signals:
signals normalised (--no-normalize to switch off), start values from a
subspace model of the record (--start paper for the paper's), time counted
in samples inside the filter and p per dominant time constant (--timescale
seconds for the absolute behaviour), p chosen by cross-validation on the
estimation data unless --p is given. Where the data start, left unstable,
predicts the record clearly better than a stable one, the plant is treated
as open-loop unstable (as --allow-unstable; JSON `open_loop_unstable`), and
the data start is returned where the filter's model does not beat it
clearly in cross-validation (by 1.25 points), or where it beats the
filter's model on the estimation data (`start_kept`), at every order.
These choices are said once as notes (JSON `notes`), each with its margin
(JSON `decision_margins`: choice, score, runner-up and its score). The
summary first names the model returned (`model_returned`), then gives its
NRMSE fits on estimation and validation data (--validation,
--validation-file) with the fit R (eq. 17) beside each (every JSON key
ending in `fit_percent` is an NRMSE fit, every key ending in `R` the fit R;
lists in --outputs order), the eigenvalues and matrices of the linear model,
whether the run converged, any warnings about the model returned (--strict:
the summary, then exit status 3) and the run time. --order takes a number, a
range (2-8) or auto, chosen on validation data; --nonlinear adds the
spline-nonlinear model and --schedule the scheduled family: each is scored
by the same rule as the linear model (initial state, horizon, records), the
better by that rule is returned, and what became of the others is said in
notes. It also says how sure the returned model is (identification.automatic.reported_checks): each mode with
standard deviations (text: value +/- 2 sigma; JSON: the list `modes`), the
residual tests per output (`residual_whiteness_p`, `input_correlation_max`)
and, for the IEKF, the innovation NIS per pass with its band. A model of a
car (an output named, or by --quantities, yaw_rate) is checked for physical
plausibility: each failure joins `plausibility` and the warnings.

With --out ARCHIVE the record and every finished pass are written to an HDF5
archive as the run goes (atomically, so a killed run leaves the archive of
its last finished pass); --resume ARCHIVE continues such a run from there
with the same data and settings, and reaches the same parameters as a run
that was never interrupted: it runs to the run's own pass budget and stop
rule (--passes, given explicitly, sets a new budget). Once the run ends, the
archive records its final stop reason. Every method writes its model to
--out. A relative --out or --save-model is taken from the working directory.
Both are checked before any work: an HDF5 name for --out, .json or .mat for
--save-model, no directory, no input file, and an existing file is replaced
only if it is the identification archive of the same run (same data and
settings) or a model file of the workbench, unless --force; an archive being
written is locked against a second writer.

The command is a client of the library: it maps its arguments to the keywords
of :func:`vehid.identification.identify` (the same names) and prints the
result's rendering (``render()`` for ``--json``, ``text()`` otherwise);
``--structure single-track`` calls :func:`vehid.scenarios.identify_single_track`.
"""

from __future__ import annotations

import argparse
import functools
from typing import Any

from vehid.identification.automatic.options import DEFAULT_PASSES, IdentifyOptions

NAME = "identify"
GROUP = None
HELP = "identify a modal state-space model from a data file (IEKF by default)"


def register(parser: argparse.ArgumentParser) -> None:
    from vehid.scenarios.commands.identify_options import register_identify_options

    register_identify_options(parser)
    parser.set_defaults(handler=run)


def options_from_args(args: argparse.Namespace) -> IdentifyOptions:
    """The pipeline's settings named by the command's arguments (each checked where it is defined)."""
    return IdentifyOptions(
        p=args.p, passes=DEFAULT_PASSES if args.passes is None else args.passes, start=args.start,
        normalize=args.normalize, discretization=args.discretization, covariance=args.covariance,
        pattern=args.pattern, timescale=args.timescale, allow_unstable=args.allow_unstable,
        initial_state=args.initial_state, horizon=args.horizon, nonlinear=args.nonlinear, nodes=args.nodes,
        nonlinear_p=tuple(args.nonlinear_p) if args.nonlinear_p else None, nonlinear_passes=args.nonlinear_passes,
        detrend=args.detrend, strict=args.strict, method=args.method, bootstrap=args.bootstrap,
        **({} if not args.schedule else {  # the schedule's settings count only where a schedule is read
            "schedule_knots": args.schedule_knots, "schedule_grid": parse_schedule_grid(args.schedule_grid),
            "schedule_p": tuple(args.schedule_p) if args.schedule_p else None}))


def parse_schedule_grid(text: str | None) -> tuple[float, ...] | None:
    """``--schedule-grid V1,V2,...`` as numbers (their range is the options' to check)."""
    from vehid.identification.errors import InputError

    if text is None:
        return None
    try:
        return tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise InputError(f"--schedule-grid takes comma-separated numbers; got {text!r}") from None


def car_checks(args: argparse.Namespace) -> Any:
    """The checks of a car's physics on the model returned (``--quantities``, and the wheelbase from ``--lf`` and
    ``--lr`` or ``--vehicle``), as :func:`vehid.identification.identify` takes them."""
    from vehid.scenarios.commands.arguments import channel_names
    from vehid.scenarios.plausibility_checks import CarChecks, check_quantities

    quantities = None
    if args.quantities is not None:
        quantities = check_quantities([q.strip() for q in args.quantities.split(",") if q.strip()],
                                      channel_names(args.outputs) if args.outputs else ())
    wheelbase = None
    if args.lf is not None and args.lr is not None:
        wheelbase = float(args.lf) + float(args.lr)
    elif args.vehicle:
        from vehid.vehicle.parameters import named_vehicle

        chassis = named_vehicle(args.vehicle).chassis
        wheelbase = chassis.cg_to_front_axle + chassis.cg_to_rear_axle
    return CarChecks(quantities, wheelbase)


def _progress(total: int, label: str, *, quiet: bool) -> Any:
    """The progress bar of the IEKF's passes, drawn on a terminal unless ``--quiet``."""
    from vehid.scenarios.progress import Progress

    return Progress(total, label, enabled=False if quiet else None).__enter__()


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.identification.errors import InputError

    if args.structure == "single-track":
        result = identify_single_track_from_args(args)
        emit(result.warnings)
        return result.render(), result.text()
    if args.measured_sideslip:
        raise InputError("--measured-sideslip checks a single-track model's predicted sideslip: give "
                         "--structure single-track, or the channel among --outputs with --quantities")
    checks = car_checks(args)  # before any work: a bad option costs nothing
    result = identify_from_args(args, options_from_args(args), checks)
    emit(result.warnings)
    return result.render(), result.text()


def identify_from_args(args: argparse.Namespace, options: IdentifyOptions, checks: Any = None) -> Any:
    """:func:`vehid.identification.identify` called with the command's arguments."""
    from vehid.identification import identify
    from vehid.identification.automatic.options import Resume
    from vehid.scenarios.commands.arguments import channel_names, min_speed_of, reading_settings
    from vehid.scenarios.log_cleaning import MIN_RUN_SECONDS

    validation = [*([] if args.validation is None else [args.validation]), *args.validation_file]
    schedule = args.schedule.strip() if args.schedule else None
    return identify(
        args.data or None, order=args.order, validation=validation or None, options=options, schedule=schedule,
        despike=args.despike, exclude=args.exclude or (),
        min_speed=min_speed_of(args.min_speed, moving_model=schedule is not None), min_run_seconds=MIN_RUN_SECONDS,
        reading=reading_settings(args), scale=args.scale, steering_ratio=args.steering_ratio,
        validation_inputs=channel_names(args.validation_inputs) if args.validation_inputs is not None else None,
        validation_outputs=channel_names(args.validation_outputs) if args.validation_outputs is not None else None,
        out=args.out, resume=Resume(args.resume, passes=args.passes) if args.resume else None,
        save_model=args.save_model, force=args.force, checks=checks,
        progress=functools.partial(_progress, quiet=args.quiet))


def _refuse_modal_options(args: argparse.Namespace) -> None:
    """Options of the modal structure that mean nothing to the single-track one: named, not silently ignored."""
    from vehid.identification.errors import InputError

    given = [name for name, value, default in (
        ("--out", args.out, None), ("--resume", args.resume, None),
        ("--nonlinear", args.nonlinear, False), ("--method", args.method, "iekf"),
        ("--detrend", args.detrend, "mean"), ("--horizon", args.horizon, None), ("--pattern", args.pattern, None),
        ("--validation-file", args.validation_file, []), ("--bootstrap", args.bootstrap, None),
    ) if value != default]
    if given:
        raise InputError(f"{given[0]} does not apply to --structure single-track")
    if not args.schedule:
        raise InputError("--structure single-track needs the speed channel: give --schedule CHANNEL (m/s)")
    if not args.inputs or len([n for n in args.inputs.split(",") if n.strip()]) != 1:
        raise InputError("--structure single-track takes one input, the steer angle (rad): give --inputs CHANNEL")
    if len(args.data) != 1:
        raise InputError("give a DATA file" if not args.data else "--structure single-track identifies from one "
                                                                   "data file")


def single_track_config(args: argparse.Namespace) -> Any:
    """The car and the model the single-track options describe: ``--quantities`` (one per ``--outputs``
    channel), mass and axle distances (``--vehicle``, overridden by ``--mass``, ``--lf``, ``--lr``), the
    steering ratio of the one input, ``--relaxation-length``, ``--saturation``, ``--offsets``."""
    from vehid.identification.dataio.preparation import parse_steering_ratio
    from vehid.identification.errors import InputError
    from vehid.scenarios.commands.arguments import channel_names
    from vehid.vehicle.single_track import SingleTrackConfig

    outputs = channel_names(args.outputs)
    quantities = tuple(q.strip() for q in (args.quantities or "yaw_rate,lateral_acceleration").split(",") if q.strip())
    if len(quantities) != len(outputs):
        raise InputError(f"--quantities names {len(quantities)} quantities for {len(outputs)} --outputs channels: "
                         "name what each output measures, in order")
    geometry: dict[str, Any] = {}
    if args.vehicle:
        from vehid.vehicle.parameters import named_vehicle

        chassis = named_vehicle(args.vehicle).chassis
        geometry = {"mass": chassis.mass, "cg_to_front_axle": chassis.cg_to_front_axle,
                    "cg_to_rear_axle": chassis.cg_to_rear_axle}
    flags = (("mass", "mass"), ("lf", "cg_to_front_axle"), ("lr", "cg_to_rear_axle"))
    geometry.update({key: getattr(args, flag) for flag, key in flags if getattr(args, flag) is not None})
    missing = [f"--{flag}" for flag, key in flags if key not in geometry]
    if missing:
        raise InputError(f"the single-track structure needs the car's mass and axle distances: give "
                         f"{', '.join(missing)} (or --vehicle FILE)")
    # --steering-ratio is the data options' (a steering-wheel angle on the one input); the model divides by it
    steer = channel_names(args.inputs)[0]
    steering_ratio = parse_steering_ratio(args.steering_ratio, [steer]).get(steer, 1.0)
    return SingleTrackConfig(**geometry, quantities=quantities, steering_ratio=steering_ratio,
                             relaxation_length=args.relaxation_length, saturation=args.saturation,
                             offsets=args.offsets)


def identify_single_track_from_args(args: argparse.Namespace) -> Any:
    """:func:`vehid.scenarios.single_track_identify.identify_single_track` called with the command's arguments."""
    from vehid.scenarios.commands.arguments import min_speed_of, reading_settings
    from vehid.scenarios.single_track_identify import SingleTrackOptions, identify_single_track

    _refuse_modal_options(args)
    config = single_track_config(args)  # before the file is read: a bad option costs nothing
    return identify_single_track(
        args.data[0], schedule=args.schedule, config=config,
        options=SingleTrackOptions(p=args.p, passes=args.passes, strict=args.strict), reading=reading_settings(args),
        validation=args.validation, despike=args.despike, exclude=args.exclude or (),
        min_speed=min_speed_of(args.min_speed, moving_model=True), scale=args.scale,
        measured_sideslip=args.measured_sideslip, save_model=args.save_model, force=args.force)


def emit(warnings: Any) -> None:
    """Print the warnings, one line each (under ``--strict`` the library raised instead)."""
    import sys

    for line in warnings:
        print(f"vehid: warning: {line}", file=sys.stderr)
