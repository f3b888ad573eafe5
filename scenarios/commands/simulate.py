"""Simulate the 23-state full-vehicle model under a steer manoeuvre.

Prints peak lateral acceleration, speed range, wall time and, for a step, the
steady-state gains; --out writes the record to HDF5 (a relative path is taken
from the working directory, so `vehid identify` finds it under the same name).
An existing file is replaced only if it is the record of the same simulation,
or with --force. A run that leaves the model's physical envelope fails (exit
status 1), writing with --out the record up to that sample.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from vehid.identification.archive_safety import KIND_ATTRIBUTE, RUN_ATTRIBUTE, check_output_target
from vehid.identification.errors import InputError, SimulationError
from vehid.scenarios.paths import HDF5_SUFFIXES, OUT_RULE, run_digest
from vehid.vehicle import MANOEUVRES, make_manoeuvre, named_vehicle, simulate

NAME = "simulate"
GROUP = None
HELP = "simulate the full-vehicle model under a steer manoeuvre"

_STEADY_WINDOW = 0.5  # [s] the end of a step record averaged as its steady state


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--manoeuvre", default="identification", choices=sorted(MANOEUVRES),
                        help="steer input (default: identification)")
    parser.add_argument("--amplitude-deg", type=float, default=None,
                        help="road-wheel steer amplitude in degrees (default: the manoeuvre's own)")
    parser.add_argument("--duration", type=float, default=None, help="record length in seconds")
    parser.add_argument("--speed", type=float, default=None,
                        help="trim and reference speed in m/s (default 20; the model is valid from 3 to 50); "
                             "the speed-* manoeuvres carry their own speed profile")
    parser.add_argument("--vehicle", default="baseline",
                        help="baseline, understeer, or a .toml/.json vehicle file")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random parts of the input")
    parser.add_argument("--method", default="rk4", choices=("rk4", "cvodes"),
                        help="compiled fixed-step RK4 (default) or the CVODES cross-check")
    parser.add_argument("--out", default=None, help=f"write the record to this HDF5 file ({OUT_RULE})")
    parser.add_argument("--force", action="store_true",
                        help="let --out replace an existing file that is not this simulation's record")
    parser.set_defaults(handler=run)


def step_gains(data, amplitude: float, window: float = _STEADY_WINDOW) -> dict[str, float]:
    """Steady-state gains of a step record: mean of the last ``window`` seconds over the step size."""
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


def run(args: argparse.Namespace) -> tuple[dict, str]:
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
