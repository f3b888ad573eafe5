"""Linearise the full-vehicle model at its trim and list its modes.

Each mode: undamped natural frequency (Hz), damping ratio, a label (yaw-sideslip,
roll, pitch, heave, wheel, lateral-slip-lag, speed, heading) and the states that
dominate it by participation factor.
"""

from __future__ import annotations

import argparse

NAME = "linearize"
GROUP = None
HELP = "linearise the full-vehicle model at trim and list its modes"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--speed", type=float, default=20.0,
                        help="trim speed in m/s (default 20; the model is valid from 3 to 50)")
    parser.add_argument("--vehicle", default="baseline",
                        help="baseline, understeer, or a .toml/.json vehicle file")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.vehicle.linearize import linearize  # CasADi when the command runs, not for its --help
    from vehid.vehicle.parameters import named_vehicle

    params = named_vehicle(args.vehicle)
    result = linearize(params, speed=args.speed)
    summary = {
        "vehicle": params.name,
        "speed": result.speed,
        "n_states": len(result.state_names),
        "modes": [mode.as_dict() for mode in result.modes],
    }
    lines = [f"{params.name} at {result.speed:g} m/s: {len(result.modes)} modes",
             f"{'label':<18} {'freq Hz':>8} {'damping':>8}  eigenvalue          dominant states"]
    for mode in result.modes:
        value = mode.eigenvalue
        lines.append(
            f"{mode.label:<18} {mode.frequency_hz:8.3f} {mode.damping:8.3f}  "
            f"{value.real:8.2f} {value.imag:+8.2f}j   {', '.join(mode.dominant_states)}"
        )
    return summary, "\n".join(lines)
