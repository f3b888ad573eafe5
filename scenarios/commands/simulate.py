"""Simulate the 23-state full-vehicle model under a steer manoeuvre, or replay a measured drive.

Prints peak lateral acceleration, speed range, wall time and, for a step, the
steady-state gains; --out writes the record to HDF5 (a relative path is taken
from the working directory, so `vehid identify` finds it under the same name).
An existing file is replaced only if it is the record of the same simulation,
or with --force. A run that leaves the model's physical envelope fails (exit
status 1), writing with --out the record up to that sample.

--replay LOG reads a measured log (text table or record, through the
workbench's readers), and simulates the model sample for sample at the log's
rate under its steer channel (--steer-channel, a road-wheel or a steering-wheel
angle as --steer-is says) while it follows its speed channel
(--speed-channel); --compare OUTPUT=CHANNEL,... sets model outputs beside the
channels that measured them and reports each fit.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from vehid.identification.errors import InputError, SimulationError
from vehid.scenarios.commands.arguments import run_digest
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE
from vehid.vehicle.choices import MANOEUVRE_NAMES, STEER_KINDS

# NumPy, CasADi, h5py and the vehicle model are imported by the functions that use them: --help needs none.

NAME = "simulate"
GROUP = None
HELP = "simulate the full-vehicle model under a steer manoeuvre"

_STEADY_WINDOW = 0.5  # [s] the end of a step record averaged as its steady state


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--manoeuvre", default=None, choices=sorted(MANOEUVRE_NAMES),
                        help="steer input (default: identification)")
    parser.add_argument("--amplitude-deg", type=float, default=None,
                        help="road-wheel steer amplitude in degrees (default: the manoeuvre's own)")
    parser.add_argument("--duration", type=float, default=None, help="record length in seconds")
    parser.add_argument("--speed", type=float, default=None,
                        help="trim and reference speed in m/s (default 20; the model is valid from 3 to 50); "
                             "the speed-* manoeuvres carry their own speed profile")
    parser.add_argument("--vehicle", default=None,
                        help="baseline, understeer, saloon, or a .toml/.json vehicle file "
                             "(default: baseline; saloon for --replay)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random parts of the input")
    parser.add_argument("--method", default="rk4", choices=("rk4", "cvodes"),
                        help="compiled fixed-step RK4 (default) or the CVODES cross-check")
    parser.add_argument("--out", default=None, help=f"write the record to this HDF5 file ({OUT_RULE})")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not this simulation's record")
    replay_group = parser.add_argument_group("replaying a measured drive")
    replay_group.add_argument("--replay", metavar="LOG", default=None,
                              help="simulate the log's steer and speed sample for sample")
    replay_group.add_argument("--steer-channel", metavar="NAME", help="the log's steer channel (rad, positive left)")
    replay_group.add_argument("--speed-channel", metavar="NAME", help="the log's forward speed channel (m/s)")
    replay_group.add_argument("--steer-is", default="road", choices=STEER_KINDS,
                              help="road: a road-wheel angle (the steering's compliance is already in it); "
                                   "wheel: a steering-wheel angle, divided by the vehicle's steering ratio "
                                   "(default: road)")
    replay_group.add_argument("--acceleration-channel", metavar="NAME",
                              help="the log's longitudinal acceleration (m/s^2), fed forward to the speed hold "
                                   "(default: the speed's rate)")
    replay_group.add_argument("--slip-limit", type=float, default=None,
                              help="slip ratio at which the replayed car's drive and brake torques fade (traction "
                                   "control, anti-lock brakes, brakes shared by the axles' loads; default: the "
                                   "vehicle's, else 0.1; 0: none)")
    replay_group.add_argument("--compare", metavar="OUTPUT=CHANNEL,...", default=None,
                              help="model outputs and the log channels that measured them, e.g. "
                                   "yaw_rate=yawRate,lateral_acceleration=ayCG,sideslip=beta_true")
    replay_group.add_argument("--time-column", metavar="NAME",
                              help="the log's time column (default: t or time when present)")
    replay_group.add_argument("--time-scale", type=float, metavar="FACTOR",
                              help="seconds per unit of the time column (default: from its unit)")
    replay_group.add_argument("--segment", metavar="T0:T1",
                              help="replay only T0 <= t <= T1 (s, log time; +T0:+T1 from the log's first sample)")
    replay_group.add_argument("--resample", type=float, metavar="HZ",
                              help="interpolate the log onto a uniform grid at HZ first")
    replay_group.add_argument("--scale", action="append", metavar="NAME=FACTOR", default=None,
                              help="multiply a log channel by FACTOR (a unit or a sign); repeatable or a comma list")
    parser.set_defaults(handler=run)


def step_gains(data, amplitude: float, window: float = _STEADY_WINDOW) -> dict[str, float]:
    """Steady-state gains of a step record: mean of the last ``window`` seconds over the step size."""
    import numpy as np

    if amplitude == 0:
        raise InputError("a step of zero amplitude has no gain")
    tail = slice(-max(int(round(window / data.dt)), 1), None)
    yaw = float(np.mean(data.output("yaw_rate")[tail]))
    lateral = float(np.mean(data.output("lateral_acceleration")[tail]))
    roll = float(np.mean(data.output("roll_angle")[tail]))
    return {
        "yaw_rate_gain": yaw / amplitude,
        "lateral_acceleration_gain": lateral / math.degrees(amplitude),
        "roll_gain": roll / amplitude,
    }


RECORD_KIND = "simulated-record"


def _write_record(data, args: argparse.Namespace, run: str) -> Path:
    """Write the record under a hidden name and rename it: a killed run never leaves half a file at --out."""
    import os
    import uuid

    import casadi
    import h5py

    from vehid.identification.dataio.archive_safety import KIND_ATTRIBUTE, RUN_ATTRIBUTE

    path = Path(args.out)
    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
    try:
        with h5py.File(temporary, "w") as handle:
            handle.attrs["casadi_version"] = casadi.__version__
            handle.attrs["seed"] = args.seed
            handle.attrs[KIND_ATTRIBUTE] = RECORD_KIND
            handle.attrs[RUN_ATTRIBUTE] = run
            data.to_hdf5(handle.create_group("data"))
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
    return path


_STEER_WORDS = {"road": "road-wheel angle", "wheel": "steering-wheel angle"}
_MANOEUVRE_OPTIONS = ("manoeuvre", "amplitude_deg", "duration", "speed")
_REPLAY_OPTIONS = ("steer_channel", "speed_channel", "compare", "time_column", "time_scale", "segment", "resample",
                   "scale", "acceleration_channel", "slip_limit")
# a replay's car gets traction control and anti-lock brakes where its vehicle has none (DriveParameters.slip_limit)
_REPLAY_SLIP_LIMIT = 0.1


def run(args: argparse.Namespace) -> tuple[dict, str]:
    import numpy as np

    from vehid.identification.dataio.archive_safety import check_output_target
    from vehid.vehicle import make_manoeuvre, named_vehicle, simulate

    if args.replay is not None:
        return run_replay(args)
    given = [name for name in _REPLAY_OPTIONS if getattr(args, name) is not None] + (
        ["steer_is"] if args.steer_is != "road" else [])
    if given:
        raise InputError(f"--{given[0].replace('_', '-')} belongs to --replay LOG")
    if args.manoeuvre is None:
        args.manoeuvre = "identification"
    if args.vehicle is None:
        args.vehicle = "baseline"
    params = named_vehicle(args.vehicle)
    options = {"seed": args.seed}
    if args.amplitude_deg is not None:
        if not math.isfinite(args.amplitude_deg):
            raise InputError(f"--amplitude-deg must be finite; got {args.amplitude_deg}")
        options["amplitude"] = math.radians(args.amplitude_deg)
    if args.duration is not None:
        options["duration"] = args.duration
    manoeuvre = make_manoeuvre(args.manoeuvre, **options)
    if manoeuvre.speed is not None and args.speed is not None:
        raise InputError(f"the {args.manoeuvre} manoeuvre carries its own speed profile: give no --speed")
    if manoeuvre.speed is None and args.speed is None:
        args.speed = 20.0
    run = run_digest(args)
    if args.out:  # before the simulation: an HDF5 name, no directory, no input file, nothing of the user's
        check_output_target(args.out, inputs=[args.vehicle], force=args.force, what="record", kind=RECORD_KIND,
                            run=run, suffixes=HDF5_SUFFIXES)
    try:
        data = simulate(params, manoeuvre, speed=args.speed, method=args.method)  # speed None under a profile
    except SimulationError as exc:
        if not args.out or exc.partial is None:
            raise
        path = _write_record(exc.partial, args, run)  # nothing computed is lost
        raise SimulationError(
            f"{exc}; the record up to it ({exc.partial.n_samples} samples) is in {path}",
            exc.partial, quantity=exc.quantity, value=exc.value, time=exc.time,
        ) from None
    a_y = data.output("lateral_acceleration")
    speed = data.output("speed")
    summary = {
        "manoeuvre": args.manoeuvre,
        "vehicle": params.name,
        "speed": float(data.meta["speed"]),  # the initial reference under a speed profile
        "samples": data.n_samples,
        "dt": data.dt,
        "method": args.method,
        "peak_lateral_acceleration": float(np.max(np.abs(a_y))),
        "min_speed": float(np.min(speed)),
        "max_speed": float(np.max(speed)),
        "seconds": float(data.meta["seconds"]),
    }
    if manoeuvre.speed is not None:
        summary["reference_speed_range"] = [float(np.min(manoeuvre.speed)), float(np.max(manoeuvre.speed))]
        summary["max_speed_tracking_error"] = float(np.max(np.abs(speed - manoeuvre.speed)))
    if args.manoeuvre == "step":
        summary.update(step_gains(data, float(manoeuvre.meta["amplitude"])))
    if args.out:
        summary["out"] = str(_write_record(data, args, run))
    at_speed = (f"at {args.speed:g} m/s" if manoeuvre.speed is None else
                "reference {0:g}-{1:g} m/s".format(*summary["reference_speed_range"]))
    lines = [
        f"{args.manoeuvre} on {params.name} {at_speed}: {data.n_samples} samples, "
        f"{data.duration:g} s simulated in {summary['seconds'] * 1000:.1f} ms ({args.method})",
        f"peak lateral acceleration {summary['peak_lateral_acceleration']:.3f} m/s^2, "
        f"speed {summary['min_speed']:.3f}-{summary['max_speed']:.3f} m/s",
    ]
    if manoeuvre.speed is not None:
        lines.append(f"speed follows its reference within {summary['max_speed_tracking_error']:.3g} m/s")
    if args.manoeuvre == "step":
        lines.append(
            f"steady state: yaw rate {summary['yaw_rate_gain']:.4f} 1/s, lateral acceleration "
            f"{summary['lateral_acceleration_gain']:.4f} m/s^2/deg, roll {summary['roll_gain']:.4f} deg/deg"
        )
    if args.out:
        lines.append(f"wrote {summary['out']}")
    return summary, "\n".join(lines)


def _compare_pairs(text: str | None) -> dict[str, str]:
    """``OUTPUT=CHANNEL,...`` as a mapping, each output a model output named once."""
    from vehid.vehicle.model import OUTPUT_NAMES

    pairs: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        output, equals, channel = (part.strip() for part in item.partition("="))
        if not equals or not output or not channel:
            raise InputError(f"--compare takes OUTPUT=CHANNEL pairs; got {item.strip()!r}")
        if output not in OUTPUT_NAMES:
            raise InputError(f"--compare: the model has no output {output!r}; it has {', '.join(OUTPUT_NAMES)}")
        if output in pairs:
            raise InputError(f"--compare: output {output!r} is named twice")
        pairs[output] = channel
    return pairs


def run_replay(args: argparse.Namespace) -> tuple[dict, str]:
    """``--replay LOG``: the measured steer and speed through the model, on the log's samples."""
    import numpy as np

    from vehid.identification.dataio.archive_safety import check_output_target
    from vehid.scenarios.drive_log import read_drive, scaled_channels
    from vehid.vehicle import named_vehicle
    from vehid.vehicle.replay import channel_fits, replay

    for name in _MANOEUVRE_OPTIONS:
        if getattr(args, name) is not None:
            raise InputError(f"--{name.replace('_', '-')} does not go with --replay: the log gives steer and speed")
    if not args.steer_channel or not args.speed_channel:
        raise InputError("--replay needs --steer-channel NAME and --speed-channel NAME")
    log = Path(args.replay)
    if not log.is_file():
        raise InputError(f"no such log: {log}")
    compare = _compare_pairs(args.compare)
    channels = [args.speed_channel, *compare.values(),
                *([args.acceleration_channel] if args.acceleration_channel else [])]
    if args.steer_channel in channels or len(set(channels)) != len(channels):
        raise InputError("a log channel is named twice among --steer-channel, --speed-channel, --compare and "
                         "--acceleration-channel")
    if args.slip_limit is not None and not (math.isfinite(args.slip_limit) and 0 <= args.slip_limit < 0.5):
        raise InputError(f"--slip-limit is a slip ratio in [0, 0.5); got {args.slip_limit}")
    if args.vehicle is None:
        args.vehicle = "saloon"
    params = named_vehicle(args.vehicle)
    data, scale = read_drive(log, args.steer_channel, channels, args.scale, what="a replayed channel",
                             time_column=args.time_column, resample=args.resample, segment=args.segment,
                             time_scale=args.time_scale)
    channel = scaled_channels(data, args.steer_channel, scale)

    run = run_digest(args)
    if args.out:
        check_output_target(args.out, inputs=[args.vehicle, args.replay], force=args.force, what="record",
                            kind=RECORD_KIND, run=run, suffixes=HDF5_SUFFIXES)
    meta = {"replay_log": log.name, "steer_channel": args.steer_channel, "speed_channel": args.speed_channel}
    measured = {output: (name, channel(name)) for output, name in compare.items()}
    slip_limit = args.slip_limit if args.slip_limit is not None else (params.drive.slip_limit or _REPLAY_SLIP_LIMIT)
    acceleration = channel(args.acceleration_channel) if args.acceleration_channel else None
    try:
        record = replay(params, channel(args.steer_channel), channel(args.speed_channel), data.dt,
                        steer_is=args.steer_is, t0=float(data.t[0]), method=args.method, meta=meta,
                        acceleration=acceleration, slip_limit=slip_limit)
    except SimulationError as exc:
        if exc.partial is None:
            raise
        partial = exc.partial
        fits = channel_fits(partial, {k: (n, v[:partial.n_samples]) for k, (n, v) in measured.items()})
        shown = ", ".join(f"{name} {value:.1f} %" for name, value in fits.fit_percent.items())
        where = f"; the record up to it ({partial.n_samples} samples) is in {_write_record(partial, args, run)}" \
            if args.out else ""
        raise SimulationError(f"{exc}{where}" + (f"; fit up to there: {shown}" if shown else ""),
                              partial, quantity=exc.quantity, value=exc.value, time=exc.time) from None
    fits = channel_fits(record, measured)
    speed = record.output("speed")
    summary = {
        "replay": {"log": str(log), "steer_channel": args.steer_channel, "speed_channel": args.speed_channel,
                   "steer_is": args.steer_is, "substeps": int(record.meta["replay_substeps"]),
                   "slip_limit": slip_limit, "acceleration_channel": args.acceleration_channel,
                   "t_start": float(record.t[0]), "t_end": float(record.t[-1])},
        "vehicle": params.name,
        "samples": record.n_samples,
        "dt": record.dt,
        "method": args.method,
        "peak_lateral_acceleration": float(np.max(np.abs(record.output("lateral_acceleration")))),
        "min_speed": float(np.min(speed)),
        "max_speed": float(np.max(speed)),
        "max_speed_tracking_error": float(np.max(np.abs(speed - channel(args.speed_channel)))),
        "seconds": float(record.meta["seconds"]),
        "fits": fits.as_dict(),
    }
    if args.out:
        summary["out"] = str(_write_record(record, args, run))
    lines = [
        f"replay of {log.name} ({args.steer_channel} as {_STEER_WORDS[args.steer_is]}, speed {args.speed_channel}) "
        f"on {params.name}: {record.n_samples} samples at {1 / record.dt:g} Hz, "
        f"{summary['replay']['substeps']} step(s) per sample ({args.method}), {summary['seconds']:.2f} s",
        f"peak lateral acceleration {summary['peak_lateral_acceleration']:.3f} m/s^2, speed "
        f"{summary['min_speed']:.2f}-{summary['max_speed']:.2f} m/s, following the log within "
        f"{summary['max_speed_tracking_error']:.3g} m/s",
    ]
    for output, row in summary["fits"].items():
        lines.append(f"{output} against {row['channel']}: fit {row['fit_percent']:.1f} %, "
                     f"rms error {row['rms_error']:.4g}")
    if args.out:
        lines.append(f"wrote {summary['out']}")
    return summary, "\n".join(lines)
