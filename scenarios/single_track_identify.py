"""`vehid identify --structure single-track`: a car's cornering stiffnesses and yaw inertia from its log.

The physical single-track model (:mod:`vehid.vehicle.single_track`) with the log's speed as a measured
time-varying parameter (``--schedule``), identified by the grey-box IEKF
(:mod:`vehid.identification.filtering.greybox`) from the samples at or above ``--min-speed`` (default
5 m/s), each run of them a record of its own (:mod:`vehid.scenarios.log_cleaning`). Signals are taken as
recorded, times ``--scale``: a physical model has no operating point to remove, and a track log's mean yaw
rate (a circuit driven one way round) is response, not offset; ``--detrend`` other than the default is
refused. Mass and axle distances come from ``--mass``, ``--lf``, ``--lr`` or a vehicle file (``--vehicle``;
the options override it).
``--p`` is the grey-box filter's (the random-walk variance of a scaled parameter over the first
pass, :class:`~identification.filtering.greybox.GreyBoxOptions`), ``--passes`` its largest number of passes.

JSON (public contract): ``structure``, ``physical_parameters`` (``cornering_stiffness_front``,
``cornering_stiffness_rear``, ``yaw_inertia`` and, with ``--saturation``, ``axle_friction``, each
``{value, std, unit}``), with ``--offsets`` ``sensor_offsets`` (``steer_offset`` and
``<quantity>_offset``, alike), ``parameter_correlation`` (in the order of ``parameter_names``),
``handling`` (``understeer_gradient_deg_per_g``, ``characteristic_speed_m_s`` or
``critical_speed_m_s``, each ``{value, std, unit}``, and ``yaw_rate_gain`` at speeds spanning the
log), ``fit_percent`` and ``R`` (NRMSE fit and fit R of eq. 17 of the model simulated from rest over
the estimation data), ``estimation_fit_percent`` and ``validation_fit_percent`` (NRMSE; every key ending
in ``fit_percent`` is an NRMSE fit), ``speed_range_m_s``, ``passes_run``, ``stop_reason``,
``trace_p``, ``notes``, ``warnings``, ``seconds``, the data's cleaning (``outliers``, ``left_out``, and
``despiked`` and ``excluded`` where asked: :func:`~vehid.identification.dataio.cleaning.cleaning_summary`),
``plausibility`` (each failed check of the car's physics, ``{quantity, value, range, speed, cause}``, also a
warning: :mod:`vehid.scenarios.plausibility_checks`; ``--measured-sideslip CHANNEL`` adds the predicted
sideslip against a measured one); with ``--save-model`` (.json) ``model_file``, the identified model
(:class:`~vehid.vehicle.single_track.IdentifiedSingleTrack`) that ``vehid handling`` reads.
Every std is the fit's delete-one-block jackknife over the log (``uncertainty_method``), and the log's
parts identified one by one are compared in ``segments`` (:mod:`vehid.scenarios.single_track_segments`).
"""

from __future__ import annotations

import dataclasses
import functools
import time
from types import SimpleNamespace
from typing import Any

import numpy as np

from vehid.identification.assessment.metrics import nrmse_fit
from vehid.identification.data import IOData, as_records
from vehid.identification.dataio.cleaning import cleaning_notes, cleaning_summary, cleaning_warnings
from vehid.identification.errors import InputError
from vehid.scenarios import single_track_segments
from vehid.scenarios.log_cleaning import MIN_SPEED
# most Runge-Kutta steps per sample, and how much of a time constant one covers: the identified model's own
from vehid.vehicle.single_track import MAX_SUBSTEPS, STEP_PER_TIME_CONSTANT

__all__ = ["run", "MIN_LOG_SPEED", "CORRELATION_WARNING", "LINEAR_LIMIT_G", "MAX_SUBSTEPS"]

#: Below this speed (m/s) slip angles of a rolling car are not small and the model is not meant to hold: the
#: least speed of the samples used, unless --min-speed says otherwise (:data:`~vehid.scenarios.log_cleaning.MIN_SPEED`).
MIN_LOG_SPEED = MIN_SPEED
#: |correlation| above which two parameters are named as not separated by the log.
CORRELATION_WARNING = 0.98
#: Lateral acceleration (g) beyond which a linear axle characteristic averages over saturation.
LINEAR_LIMIT_G = 0.5

def _config(args: Any, n_outputs: int):
    from vehid.vehicle.single_track import SingleTrackConfig

    quantities = tuple(q.strip() for q in (args.quantities or "yaw_rate,lateral_acceleration").split(",") if q.strip())
    if len(quantities) != n_outputs:
        raise InputError(f"--quantities names {len(quantities)} quantities for {n_outputs} --outputs channels: "
                         "name what each output measures, in order")
    geometry: dict[str, Any] = {}
    if args.vehicle:
        from vehid.vehicle.parameters import named_vehicle

        chassis = named_vehicle(args.vehicle).chassis
        geometry = {"mass": chassis.mass, "cg_to_front_axle": chassis.cg_to_front_axle,
                    "cg_to_rear_axle": chassis.cg_to_rear_axle}
    for option, key in (("mass", "mass"), ("lf", "cg_to_front_axle"), ("lr", "cg_to_rear_axle")):
        if getattr(args, option) is not None:
            geometry[key] = getattr(args, option)
    missing = [f"--{o}" for o, k in (("mass", "mass"), ("lf", "cg_to_front_axle"), ("lr", "cg_to_rear_axle"))
               if k not in geometry]
    if missing:
        raise InputError(f"the single-track structure needs the car's mass and axle distances: give "
                         f"{', '.join(missing)} (or --vehicle FILE)")
    from vehid.identification.dataio.preparation import parse_steering_ratio

    # --steering-ratio is the data options' (a steering-wheel angle on the one input); the model divides by it
    steer = (args.inputs or "").split(",")[0].strip()
    steering_ratio = parse_steering_ratio(getattr(args, "steering_ratio", None), [steer]).get(steer, 1.0)
    return SingleTrackConfig(**geometry, quantities=quantities, steering_ratio=steering_ratio,
                             relaxation_length=args.relaxation_length, saturation=args.saturation,
                             offsets=args.offsets)


def _refuse_other_options(args: Any) -> None:
    """Options of the modal structure that mean nothing here: named, not silently ignored."""
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


def _is_workbench_record(path: str) -> bool:
    from pathlib import Path

    from vehid.scenarios.paths import HDF5_SUFFIXES

    return Path(path).suffix.lower() in HDF5_SUFFIXES


def _read(args: Any) -> tuple[tuple[IOData, ...], tuple[IOData, ...], tuple[np.ndarray, ...] | None]:
    """The runs of the raw record (steer, speed -> outputs) a moving car's model is identified from, times
    --scale, the runs of its held-out tail where asked (:mod:`vehid.scenarios.log_cleaning`), and the
    ``--measured-sideslip`` channel on each estimation run (None without it).

    The measured sideslip is read as one more output, so that the spikes, windows and slow parts the
    fitted channels lose are lost by it too; it is taken off the runs before they are returned."""
    from vehid.identification.data import check_channels
    from vehid.identification.dataio.preparation import parse_scale
    from vehid.scenarios.data_options import read_from_args
    from vehid.scenarios.log_cleaning import clean_records, min_speed_of

    if len(args.data) != 1:
        raise InputError("--structure single-track identifies from one data file")
    if args.validation is not None and not 0 < args.validation < 1:
        raise InputError(f"--validation takes a fraction between 0 and 1; got {args.validation}")
    speed = args.schedule.strip()
    sideslip = (getattr(args, "measured_sideslip", None) or "").strip() or None
    outputs = f"{args.outputs},{sideslip}" if sideslip else args.outputs
    # a text table's columns are all alike; a workbench record keeps its speed among its inputs or its outputs
    try:
        reading = SimpleNamespace(**{**vars(args), "inputs": f"{args.inputs},{speed}", "outputs": outputs})
        (record,), _ = read_from_args(reading, args.data)
    except InputError:
        if not _is_workbench_record(args.data[0]):
            raise  # the file's own problem (a column, a segment), not where the speed is kept
        reading = SimpleNamespace(**{**vars(args), "outputs": f"{outputs},{speed}"})
        try:
            (raw,), _ = read_from_args(reading, args.data)
        except InputError:
            raise InputError(f"no channel {speed!r} (the speed, --schedule) among the file's inputs or outputs") \
                from None
        record = raw.replace(u=np.column_stack([raw.u, raw.y[:, -1]]), y=raw.y[:, :-1],
                             input_names=(*raw.input_names, speed), output_names=raw.output_names[:-1],
                             input_units=(*raw.input_units, raw.output_units[-1]),
                             output_units=raw.output_units[:-1])
    scale = parse_scale(args.scale)
    unknown = [name for name in scale if name not in record.input_names + record.output_names]
    if unknown:
        raise InputError(f"--scale names {unknown[0]!r}, which is not a chosen channel")
    # spikes found (and repaired with --despike), --exclude windows and the slow parts left out: each run
    # of a moving car its own record, the hold-out the last part of the samples kept
    min_speed = min_speed_of(args, moving_model=True)
    cleaned = clean_records(args, [record], speeds=[record.u[:, 1]], speed_name=speed,
                            speed_factor=scale.get(speed, 1.0), min_speed=min_speed, holdout=args.validation,
                            speed_in_record=True)
    input_scale = [scale.get(n, 1.0) for n in record.input_names]
    output_scale = [scale.get(n, 1.0) for n in record.output_names]
    estimation, validation = (tuple(part.replace(u=part.u * input_scale, y=part.y * output_scale) for part in parts)
                              for parts in (cleaned.estimation, cleaned.validation))
    measured_sideslip = None
    if sideslip:
        measured_sideslip = tuple(part.y[:, -1].copy() for part in estimation)
        estimation, validation = (tuple(part.replace(y=part.y[:, :-1], output_names=part.output_names[:-1],
                                                     output_units=part.output_units[:-1]) for part in parts)
                                  for parts in (estimation, validation))
    check_channels(tuple(IOData(t=part.t, u=part.u[:, :1], y=part.y, input_names=part.input_names[:1],
                                output_names=part.output_names) for part in estimation), detrend="none")
    slowest = min(float(np.min(part.u[:, 1])) for part in estimation + validation)
    if slowest < 0:
        raise InputError(f"the speed channel {speed!r} falls to {slowest:.3g}: the single-track model needs a car "
                         "moving forwards (m/s; --min-speed leaves the slow parts out)")
    return estimation, validation, measured_sideslip


def run(args: Any) -> tuple[dict, str]:
    """Identify the single-track model and summarise it (module docstring)."""
    from vehid.identification.filtering.greybox import GreyBoxOptions, simulate_greybox
    from vehid.identification.automatic import steps as workflow
    from vehid.vehicle.single_track import GRAVITY, single_track_handling, single_track_model

    started = time.perf_counter()
    _refuse_other_options(args)
    if not args.data:
        raise InputError("give a DATA file")
    from vehid.scenarios.data_options import channel_names

    config = _config(args, len(channel_names(args.outputs)))  # before the file is read: a bad option costs nothing
    if args.save_model:
        from pathlib import Path

        from vehid.scenarios.data_options import check_model_target

        if Path(args.save_model).suffix.lower() != ".json":
            raise InputError(f"a single-track model is saved as .json; got {args.save_model!r}")
        check_model_target(args.save_model, inputs=[*args.data, *args.validation_file], force=args.force)
    estimation, validation, measured_sideslip = _read(args)
    model = single_track_model(config)
    substeps = _substeps(config, *estimation, *validation)
    options = GreyBoxOptions(substeps=substeps, **({"p": args.p} if args.p is not None else {}),
                             **({"passes": args.passes} if args.passes is not None else {}))

    fit = functools.partial(fit_log, config, options=options)
    result, divergence = workflow.last_good_on_divergence(lambda: fit(estimation))
    # the filter's covariance pass takes the innovations as white; the fit's block jackknife measures the spread
    covariance, uncertainty = single_track_segments.honest_covariance(model, result, estimation)
    consistency = single_track_segments.part_consistency(config, model, estimation, fit)

    names, units = config.parameter_names, model.parameter_units
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    entries = [(name, {"value": float(value), "std": float(s), "unit": unit})
               for name, value, s, unit in zip(names, result.parameters, std, units)]
    parameters = dict(entries[: config.n_physical])
    offsets = dict(entries[config.n_physical:])
    speeds = np.concatenate([record.u[:, 1] for record in estimation])
    grid = sorted({float(v) for v in np.round(np.linspace(speeds.min(), speeds.max(), 3))})
    handling = single_track_handling(config, result.parameters, covariance, speeds=grid)

    def fit_on(records: tuple[IOData, ...]) -> np.ndarray:
        """NRMSE fit over the runs, each simulated from its start (pooled: the runs as one series)."""
        simulated = [simulate_greybox(model, result.parameters, record, substeps=options.substeps)[0]
                     for record in records]
        return nrmse_fit(np.vstack([record.y for record in records]), np.vstack(simulated))

    estimation_fit = fit_on(estimation)
    validation_fit = fit_on(validation) if validation else None
    notes = ["signals taken as recorded (no offsets removed): a physical model has no operating point",
             *cleaning_notes(estimation)]
    warnings = workflow.run_warnings(
        model=None, evaluation=workflow.Evaluation(
            _Scores(estimation_fit), estimation_fit, tuple(_Scores(f) for f in [validation_fit] if f is not None),
            None),
        stop_reason=result.stop_reason if divergence is None else f"{result.stop_reason}: {divergence}",
        start_fit=None, final_fit=None, allow_unstable=True,
        fit_history=[record.mean_fit_filter for record in result.history],
        # a physical structure has no order to change: its options are what an engineer can change
        below_zero_remedy="the structure does not fit this log (try "
                          f"{'' if config.saturation else '--saturation, '}--relaxation-length or a --segment "
                          "within the linear range)")
    # how well the log separates the parameters is the curvature's to say: the jackknife's correlations rest
    # on a handful of blocks
    correlation = result.correlation
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if abs(correlation[i, j]) > CORRELATION_WARNING:
                warnings.append(f"the log hardly separates {names[i]} from {names[j]} (correlation "
                                f"{correlation[i, j]:.3f}): excite more, or add a measured quantity (sideslip)")
    for name, value, s in list(zip(names, result.parameters, std))[: config.n_physical]:  # an offset may be ~0
        if not s < abs(value):
            warnings.append(f"{name} is not determined by the log (std {s:.3g} against {value:.3g})")
    if float(np.min(speeds)) < MIN_LOG_SPEED:
        warnings.append(f"the log's speed falls to {np.min(speeds):.2f} m/s, below {MIN_LOG_SPEED:g} m/s where the "
                        f"single-track model holds: --min-speed {MIN_LOG_SPEED:g} leaves the slow parts out")
    warnings += cleaning_warnings(estimation)
    if "lateral_acceleration" in config.quantities and not config.saturation:
        column = config.quantities.index("lateral_acceleration")
        peak = max(float(np.max(np.abs(record.y[:, column]))) for record in estimation) / GRAVITY
        if peak > LINEAR_LIMIT_G:
            warnings.append(f"the log reaches {peak:.2f} g, beyond the linear axle's range (about {LINEAR_LIMIT_G} g): "
                            "the cornering stiffnesses average over saturation; try --saturation")
    if "lateral_acceleration" in config.quantities and config.saturation:
        warnings.extend(_friction_warnings(config, result.parameters, estimation, validation))
    if consistency is not None and not consistency.consistent:
        warnings.append(consistency.warning("the single-track model"))
    summary: dict[str, Any] = {
        "method": "iekf",
        "structure": "single-track",
        "physical_parameters": parameters,
        **({"sensor_offsets": offsets} if offsets else {}),
        "parameter_correlation": correlation,
        "parameter_names": list(names),
        "handling": handling.as_dict(),
        "quantities": list(config.quantities),
        "schedule": args.schedule.strip(),
        "speed_range_m_s": [float(np.min(speeds)), float(np.max(speeds))],
        "fit_percent": result.nrmse_fit_percent,
        "R": result.fit_percent,
        "estimation_fit_percent": estimation_fit,
        "validation_fit_percent": validation_fit,
        "passes_run": result.passes_run,
        "stop_reason": result.stop_reason,
        "trace_p": result.trace_p,
        "measurement_noise": result.measurement_noise,
        "start": dict(zip(names, result.start.tolist())),
        "covariance_source": uncertainty.describe(),
        "uncertainty_method": uncertainty.as_dict(),
        "segments": None if consistency is None else consistency.as_dict(),
        "notes": notes,
        **cleaning_summary(estimation),
        "seconds": time.perf_counter() - started,
    }
    if divergence:
        summary["divergence"] = divergence
    if args.save_model:
        from vehid.scenarios.data_options import save_model
        from vehid.vehicle.single_track import IdentifiedSingleTrack

        identified = IdentifiedSingleTrack(
            config, result.parameters, covariance, (float(np.min(speeds)), float(np.max(speeds))),
            {"data": [str(d) for d in args.data], "schedule": args.schedule.strip(),
             "validation_fit_percent": None if validation_fit is None else [float(f) for f in validation_fit],
             "uncertainty_method": uncertainty.as_dict()})
        summary["model_file"] = str(save_model(identified, args.save_model, None))
    from vehid.scenarios import plausibility_checks as plausibility
    from vehid.vehicle.single_track import IdentifiedSingleTrack

    plausibility.record_findings(summary, warnings, plausibility.single_track_findings(
        IdentifiedSingleTrack(config, result.parameters, None, (float(np.min(speeds)), float(np.max(speeds)))),
        estimation, plausibility.single_track_sideslip(config, result.parameters, estimation, measured_sideslip,
                                                       options.substeps)))
    summary["warnings"] = list(warnings)  # said on standard error (or made an error by --strict) by the command
    text = _text(summary, estimation[0].output_names, bool(validation),
                 [] if consistency is None else consistency.text_lines())
    return summary, text


def fit_log(config: Any, records: IOData | tuple[IOData, ...], *, options: Any) -> Any:
    """The grey-box identification of the single-track model of ``config`` on a log (or its runs), from the
    start values of its mass and geometry, as the command runs it (``options`` without the states' prior,
    which is the log's)."""
    from vehid.identification.filtering.greybox import identify_greybox
    from vehid.vehicle.single_track import single_track_model, single_track_start

    records = as_records(records)
    model = single_track_model(config)
    # a log (and each run of it) starts mid-drive, not at rest: the states' prior at its start (a sideslip of
    # up to 0.1 rad, yaw rates of 0.5 rad/s, slip angles of 0.1 rad), so the filter estimates them rather than
    # taking the first second's transient for a property of the car
    first_speed = max(float(record.u[0, 1]) for record in records)
    start_std = {"lateral_velocity": 0.1 * max(first_speed, MIN_LOG_SPEED), "yaw_rate": 0.5,
                 "slip_angle_front": 0.1, "slip_angle_rear": 0.1}
    return identify_greybox(records, model, single_track_start(config), options=dataclasses.replace(
        options, initial_state_std=tuple(start_std[name] for name in model.state_names)))


def _friction_warnings(config: Any, parameters: np.ndarray, estimation: IOData | tuple[IOData, ...],
                       validation: IOData | tuple[IOData, ...] | None) -> list[str]:
    """Warnings when the log corners harder than the estimated saturating axles can.

    With static axle loads, ``mu F_z tanh(.)`` on both axles bounds the model's lateral acceleration
    by ``mu g``. A friction below the estimation part's own peak contradicts the data it came from:
    the filter's state corrections have carried the cornering the axles cannot, and the model's
    simulated response is capped (on the committed race car's full lap the estimate falls to
    ``mu`` 0.5 against a peak of 1.38 g, from starts of 1, 1.5 and 2 alike). A held-out part that
    corners beyond ``mu g`` is predicted capped there, its fit can fall far below the linear model's,
    which has no cap, and the friction is extrapolated. Each warning says so with the figures.
    """
    from vehid.vehicle.single_track import GRAVITY

    column = config.quantities.index("lateral_acceleration")
    friction = float(parameters[config.parameter_names.index("axle_friction")])
    measured = np.vstack([record.y for record in as_records(estimation)])[:, column]
    peak_estimation = float(np.max(np.abs(measured))) / GRAVITY
    warnings = []
    if peak_estimation > friction:
        warnings.append(f"the estimated axle_friction {friction:.2f} is below the {peak_estimation:.2f} g the "
                        "estimation data itself reaches: the saturating axles cannot produce the log's cornering "
                        "and their simulated response is capped at that friction (the friction is not identified "
                        "by this log); prefer the linear axles")
    if validation:  # a record, or a non-empty tuple of them
        held = np.vstack([record.y for record in as_records(validation)])[:, column]
        peak_validation = float(np.max(np.abs(held))) / GRAVITY
        if peak_validation > friction:
            beyond = float(np.mean(np.abs(held) > friction * GRAVITY)) * 100.0
            warnings.append(f"the validation part reaches {peak_validation:.2f} g ({beyond:.0f} % of it beyond "
                            f"{friction:.2f} g), but the saturating axles cap the model at the estimated axle_friction "
                            f"{friction:.2f} g, identified from an estimation part that reaches only "
                            f"{peak_estimation:.2f} g: the friction is extrapolated (hold out a part within the "
                            "estimation part's range, or use the linear axles)")
    return warnings


def _substeps(config: Any, *records: IOData) -> int:
    """Runge-Kutta steps per sample that keep every mode well inside RK4's stability region.

    The fastest rate is bounded by the trace of the bicycle's system matrix at the lowest speed with
    twice the start stiffnesses and half its yaw inertia (``(C_f + C_r) / (m v) + (l_f^2 C_f + l_r^2 C_r)
    / (I_z v)``) and, with a
    relaxation length, by ``v / sigma`` at the highest speed; a step covers at most half a time
    constant (RK4 is stable to 2.8). A log that would need more than :data:`MAX_SUBSTEPS` reaches
    standstill, where the model does not hold: InputError.
    """
    from vehid.vehicle.single_track import MIN_SPEED, single_track_start

    speeds = np.concatenate([record.u[:, 1] for record in records])
    low, high = max(float(np.min(speeds)), MIN_SPEED), float(np.max(speeds))
    c_f, c_r, inertia = single_track_start(config)[:3] * [2.0, 2.0, 0.5]
    lf, lr = config.cg_to_front_axle, config.cg_to_rear_axle
    rate = (c_f + c_r) / (config.mass * low) + (lf**2 * c_f + lr**2 * c_r) / (inertia * low)
    if config.relaxation_length is not None:
        rate = max(rate, high / config.relaxation_length)
    needed = int(np.ceil(rate * records[0].dt / STEP_PER_TIME_CONSTANT))
    if needed > MAX_SUBSTEPS:
        raise InputError(f"the log's speed falls to {np.min(speeds):.3g} m/s, where the single-track model's modes are "
                         f"too fast for its {records[0].dt:g} s samples: --min-speed {MIN_LOG_SPEED:g} leaves the "
                         "slow parts out")
    return max(needed, 1)


class _Scores:
    """The two fields of a score that the shared warnings read."""

    def __init__(self, fit: np.ndarray):
        self.fit = np.asarray(fit, dtype=float)
        self.R = self.fit


def _text(summary: dict[str, Any], outputs: tuple[str, ...], validated: bool, parts: list[str]) -> str:
    lines = [f"single-track model (grey-box IEKF): {summary['passes_run']} passes, "
             f"{'pass budget reached' if summary['stop_reason'] == 'passes' else summary['stop_reason']}, "
             f"speed {summary['speed_range_m_s'][0]:.1f}-{summary['speed_range_m_s'][1]:.1f} m/s, "
             f"{summary['seconds']:.2f} s"]
    for name, entry in {**summary["physical_parameters"], **summary.get("sensor_offsets", {})}.items():
        lines.append(f"  {name:<27} {entry['value']:>12.5g} +/- {2 * entry['std']:.3g} {entry['unit']} (2 sigma)")
    handling = summary["handling"]
    lines.append(f"  {'understeer gradient':<27} {handling['understeer_gradient_deg_per_g']['value']:>12.4g} +/- "
                 f"{2 * handling['understeer_gradient_deg_per_g']['std']:.3g} deg/g")
    for kind in ("characteristic", "critical"):
        key = f"{kind}_speed_m_s"
        if key in handling:
            label = f"{kind} speed"
            lines.append(f"  {label:<27} {handling[key]['value']:>12.4g} +/- {2 * handling[key]['std']:.3g} m/s")
    lines.append(f"  standard deviations: {summary['uncertainty_method']['description']}")
    lines += [f"  {line}" for line in parts]
    for name, est, val in zip(outputs, summary["estimation_fit_percent"],
                              summary["validation_fit_percent"] if validated else [None] * len(outputs)):
        lines.append(f"  NRMSE fit % {name:<15} estimation {est:7.2f}   validation {'-' if val is None else f'{val:.2f}'}")
    lines += [f"note: {note}" for note in summary["notes"]]
    return "\n".join(lines)
