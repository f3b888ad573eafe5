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
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from vehid.identification.errors import InputError, StrictWarningsError

NAME = "handling"
GROUP = None
HELP = "handling metrics (ISO 4138 / ISO 7401) of an identified model or of the source model at each speed"

_ROLES = ("steer", "yaw_rate", "lateral_acceleration", "sideslip")
#: Below this fraction of the asked range the steady states are named as saturating (the baseline car's
#: steps fall 1-7 % short at 4 m/s^2 and 30 % short at 9).
_REACHED = 0.8


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
        if role not in _ROLES or not value:
            raise InputError(f"--scale takes ROLE=FACTOR with ROLE one of {', '.join(_ROLES)}; got {item!r}")
        try:
            factor = float(value)
        except ValueError:
            raise InputError(f"--scale {role} must be a number; got {value!r}") from None
        if not (math.isfinite(factor) and factor != 0):
            raise InputError(f"--scale {role} must be finite and non-zero; got {value}")
        scales[role] = factor
    return scales


def _model_from_json(path: Path) -> Any:
    from vehid.identification.models.modal import ModalModel
    from vehid.identification.models.scheduled import ScheduledModalModel

    try:
        content = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path} is not a JSON model file: {exc}") from None
    if not isinstance(content, dict):
        raise InputError(f"{path} is not a model file of the workbench")
    try:
        if content.get("kind") == "single-track":
            from vehid.vehicle.single_track import IdentifiedSingleTrack

            return IdentifiedSingleTrack.from_dict(content)  # physical units throughout: no preparation to undo
        if "grid" in content and "variable" in content:
            model = ScheduledModalModel.from_dict(content)
        elif "structure" in content and "A" in content:
            model = ModalModel.from_dict(content)
        else:
            raise InputError(f"{path} holds no linear or scheduled modal model (the model file of vehid identify)")
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path} holds a damaged model: {exc}") from None
    return _named_by_preparation(model, content.get("preparation"))


def _named_by_preparation(model: Any, preparation: Any) -> Any:
    """The model with its channels named as the record's, where the file's preparation names them
    and the model itself has only the default names (u1, y1, ...)."""
    import dataclasses

    if not isinstance(preparation, dict):
        return model
    names = {}
    for attribute, key, prefix in (("input_names", "inputs", "u"), ("output_names", "outputs", "y")):
        current, stored = tuple(getattr(model, attribute) or ()), preparation.get(key)
        generic = all(name == f"{prefix}{i + 1}" for i, name in enumerate(current))
        if generic and isinstance(stored, list) and len(stored) == len(current):
            names[attribute] = tuple(str(name) for name in stored)
    return dataclasses.replace(model, **names) if names and dataclasses.is_dataclass(model) else model


def _model_from_archive(path: Path, run_name: str | None) -> tuple[Any, dict[str, Any]]:
    from vehid.identification.dataio.archive import read_archive
    from vehid.scenarios.report import archive_verdict

    archive = read_archive(path)
    usable = {name: run.model for name, run in archive.runs.items()
              if hasattr(run.model, "to_statespace") or hasattr(run.model, "model_at")}
    if run_name is None:
        returned = ((archive_verdict(archive) or {}).get("scoring_rule") or {}).get("returned_run")
        if returned in usable:
            run_name = returned
        elif len(usable) == 1:
            run_name = next(iter(usable))
        elif not usable:
            raise InputError(f"{path} holds no linear or scheduled model")
        else:
            raise InputError(f"{path} holds several models ({', '.join(sorted(usable))}): choose one with --run")
    if run_name not in usable:
        raise InputError(f"{path} has no run {run_name!r} with a linear model; runs: {', '.join(sorted(usable))}")
    speeds = sorted({float(record.meta["speed"]) for record in archive.records.values()
                     if isinstance(record.meta.get("speed"), (int, float))})
    model = usable[run_name]
    record = next(iter(archive.records.values()), None)
    if record is not None:  # a run's model may carry default names only: the record names the channels
        model = _named_by_preparation(model, {"inputs": list(record.input_names),
                                              "outputs": list(record.output_names)})
    return model, {"run": run_name, "record_speeds": speeds}


def load_model(target: str, run_name: str | None = None) -> tuple[Any, dict[str, Any]]:
    """The model in a ``.json`` model file or an identification archive, and where it came from."""
    path = Path(target)
    if not path.is_file():
        raise InputError(f"no model file {target!r}")
    if path.suffix.lower() == ".json":
        if run_name is not None:
            raise InputError("--run names an archive's run: a .json model file holds one model")
        return _model_from_json(path), {}
    return _model_from_archive(path, run_name)


def _default_speeds(model: Any, origin: dict[str, Any]) -> list[float]:
    if hasattr(model, "model_at"):
        return [float(v) for v in model.grid]
    stored = (getattr(model, "meta", None) or {}).get("speed")
    if isinstance(stored, (int, float)):
        return [float(stored)]
    if len(origin.get("record_speeds", [])) == 1:
        return list(origin["record_speeds"])
    raise InputError("give the speed at which the model holds: --speeds V")


def _format(value: float, digits: int = 4) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


#: The text gives every steer angle in degrees (road wheel), as the understeer gradient's deg/g does; the JSON in
#: radians, each number with its unit. A gain per angle is the same per degree and per radian when the response
#: is an angle too (yaw rate, sideslip): it says so by its unit.
STEER_UNIT_TEXT = "steer angles in degrees (road wheel); the JSON gives each value with its unit, angles in rad"
_TEXT_ROWS = (
    ("yaw-rate gain r/delta (deg/s per deg)", "yaw_rate_gain", 1.0),
    ("lateral acc. gain (m/s^2 per deg)", "lateral_acceleration_gain", math.pi / 180),
    ("sideslip gain (deg per deg)", "sideslip_gain", 1.0),
    ("understeer gradient (deg/g)", "understeer_gradient_deg_per_g", 1.0),
    ("characteristic speed (m/s)", "characteristic_speed_m_s", 1.0),
    ("critical speed (m/s)", "critical_speed_m_s", 1.0),
    ("yaw-rate response time (s)", "yaw_rate_response_time_s", 1.0),
    ("yaw-rate peak time (s)", "yaw_rate_peak_response_time_s", 1.0),
    ("yaw-rate overshoot (%)", "yaw_rate_overshoot", 100.0),
    ("a_y response time (s)", "lateral_acceleration_response_time_s", 1.0),
    ("yaw-rate gain at 1 Hz (1/s)", "yaw_rate_gain_1hz", 1.0),
    ("yaw-rate phase at 1 Hz (deg)", "yaw_rate_phase_1hz_deg", 1.0),
    ("a_y phase at 1 Hz (deg)", "lateral_acceleration_phase_1hz_deg", 1.0),
    ("yaw-rate bandwidth (Hz)", "yaw_rate_bandwidth_hz", 1.0),
)


def metrics_table(title: str, metrics: tuple) -> list[str]:
    """One row per metric, one column per speed; ``value +/- std`` where a std is known."""
    lines = [title, f"{'speed (m/s)':<40}" + "".join(f"{m.speed:>20g}" for m in metrics)]
    for label, name, factor in _TEXT_ROWS:
        cells = []
        for m in metrics:
            value, std = getattr(m, name) * factor, m.std[name] * factor
            cells.append(_format(value) + (f" +/- {_format(std, 2)}" if math.isfinite(std) else ""))
        if all(cell == "-" for cell in cells):
            continue
        lines.append(f"{label:<40}" + "".join(f"{cell:>20}" for cell in cells))
    return lines


#: the units of the JSON's numbers that carry none of their own (``metrics`` entries carry theirs)
JSON_UNITS = {"speed": "m/s", "wheelbase": "m", "steer": "rad (road-wheel angle)",
              "lateral_acceleration": "m/s^2", "reached_lateral_acceleration": "m/s^2", "yaw_rate_gain": "1/s",
              "lateral_acceleration_gain": "m/s^2/rad", "understeer_gradient_deg_per_g": "deg/g",
              "characteristic_speed_m_s": "m/s", "critical_speed_m_s": "m/s"}


_FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


def _check_figure_target(args: argparse.Namespace) -> Path | None:
    """The --figure path, checked before any work: a figure suffix, an existing folder, no file unless --force."""
    if args.figure is None:
        return None
    path = Path(args.figure)
    if path.suffix.lower() not in _FIGURE_SUFFIXES:
        raise InputError(f"--figure takes a {', '.join(_FIGURE_SUFFIXES)} file; got {args.figure!r}")
    if not path.parent.is_dir():
        raise InputError(f"--figure: no folder {str(path.parent)!r}")
    if path.is_dir() or (path.exists() and not args.force):
        raise InputError(f"--figure {args.figure!r} exists: choose another name or give --force")
    return path


def _write_figure(path: Path | None, curves: dict[str, Any], title: str) -> str | None:
    if path is None:
        return None
    from vehid.scenarios.report import handling_page

    handling_page(curves, title=title).savefig(path)
    return str(path)


def _run_source(args: argparse.Namespace) -> tuple[dict, str, list[str]]:
    from vehid.vehicle import named_vehicle
    from vehid.vehicle.handling import ISO_7401_LATERAL_ACCELERATION, source_handling, source_steady_state

    if args.model is not None:
        raise InputError("--source reports the source model: give no MODEL")
    for option in ("yaw_rate", "lateral_acceleration", "sideslip", "steer", "wheelbase", "scale", "run",
                   "beside_source"):
        if getattr(args, option) is not None:
            raise InputError(f"--{option.replace('_', '-')} applies to an identified MODEL, not to --source")
    speeds = parse_speeds(args.speeds) if args.speeds is not None else [10.0, 20.0, 30.0]
    level = ISO_7401_LATERAL_ACCELERATION if args.step_lateral_acceleration is None else args.step_lateral_acceleration
    params = named_vehicle(args.vehicle)
    figure = _check_figure_target(args)
    if args.steady_range is not None and not (math.isfinite(args.steady_range) and args.steady_range > 0):
        raise InputError(f"--steady-range must be a positive lateral acceleration (m/s^2); got {args.steady_range}")
    result = source_handling(params, speeds, simulate=not args.no_simulation, step_lateral_acceleration=level)
    summary = {"source": True, **result.as_dict(), "units": JSON_UNITS, "warnings": []}
    steady = ()
    if args.steady_range is not None:
        steady = source_steady_state(params, speeds, lateral_acceleration=args.steady_range)
        summary["steady_state"] = [entry.as_dict() for entry in steady]
        short = [entry for entry in steady if entry.reached_lateral_acceleration < _REACHED * args.steady_range]
        summary["warnings"] += [f"at {entry.speed:g} m/s the steady states reach {entry.reached_lateral_acceleration:.3g} "
                                f"of the {args.steady_range:g} m/s^2 asked: the tyres saturate" for entry in short]
    curves = {"linearisation": result.linearisation,
              **({f"simulation (step to {level:g} m/s^2)": result.simulation} if result.simulation else {})}
    written = _write_figure(figure, curves, f"Handling of the source model {result.vehicle}")
    if written:
        summary["figure"] = written
    lines = [f"source model {result.vehicle} (wheelbase {result.wheelbase:g} m; {STEER_UNIT_TEXT})",
             *metrics_table("linearisation:", result.linearisation)]
    if result.simulation:
        lines += metrics_table(f"simulation (step to {level:g} m/s^2; 1 Hz sine dwell and sweep of that steer):",
                               result.simulation)
    if steady:
        lines.append(f"steady state over +/- {args.steady_range:g} m/s^2 (ISO 4138 steer steps):")
        lines += [f"  {entry.speed:g} m/s: understeer gradient {entry.understeer_gradient_deg_per_g:.4g} deg/g, "
                  f"characteristic speed {_format(entry.characteristic_speed_m_s)} m/s, "
                  f"yaw-rate gain {entry.yaw_rate_gain:.4g} deg/s per deg, lateral acc. gain "
                  f"{entry.lateral_acceleration_gain * math.pi / 180:.4g} m/s^2 per deg" for entry in steady]
    if written:
        lines.append(f"wrote {written}")
    return summary, "\n".join(lines), summary["warnings"]


def _run_model(args: argparse.Namespace) -> tuple[dict, str, list[str]]:
    from vehid.vehicle.handling import handling_metrics

    if args.model is None:
        raise InputError("give a MODEL file or archive, or --source for the source model")
    for option, given in (("--vehicle", args.vehicle != "baseline"), ("--no-simulation", args.no_simulation),
                          ("--step-lateral-acceleration", args.step_lateral_acceleration is not None),
                          ("--steady-range", args.steady_range is not None)):
        if given:
            raise InputError(f"{option} applies to --source only")
    scales = parse_scales(args.scale)
    figure = _check_figure_target(args)
    source_params = None
    if args.beside_source is not None:
        from vehid.vehicle import named_vehicle

        source_params = named_vehicle(args.beside_source)  # a bad vehicle file is bad input before any work
    model, origin = load_model(args.model, args.run)
    if args.wheelbase is None and getattr(model, "wheelbase", None) is not None:
        args.wheelbase = float(model.wheelbase)  # a physical model knows its own
    speeds = parse_speeds(args.speeds) if args.speeds is not None else _default_speeds(model, origin)
    metrics = handling_metrics(model, speeds, yaw_rate=args.yaw_rate, lateral_acceleration=args.lateral_acceleration,
                               sideslip=args.sideslip, steer=args.steer, wheelbase=args.wheelbase, scales=scales)
    source = None
    if source_params is not None:
        from vehid.vehicle.handling import source_handling

        source = source_handling(source_params, speeds, simulate=False)
    warnings = []
    if args.wheelbase is None:
        warnings.append("no --wheelbase: the understeer gradient and the characteristic speed are not computed")
    if all(not math.isfinite(m.std["yaw_rate_gain"]) for m in metrics):
        warnings.append("the model carries no parameter covariance: the metrics have no error bars")
    unstable = [m.speed for m in metrics if not math.isfinite(m.yaw_rate_response_time_s)]
    if unstable:
        warnings.append("the model is unstable or never reaches 90 % of its steady yaw rate at "
                        f"{', '.join(f'{v:g}' for v in unstable)} m/s: no step metrics there")
    from vehid.identification.automatic.reported_checks import uncertainty_method
    from vehid.scenarios import plausibility_checks as plausibility

    method = uncertainty_method(model)
    findings, sparse = plausibility.handling_findings(model, speeds, metrics, yaw_rate=args.yaw_rate,
                                                      lateral_acceleration=args.lateral_acceleration,
                                                      sideslip=args.sideslip)
    if sparse:
        warnings.append(f"the model rests on too few samples at {', '.join(f'{v:g}' for v in sparse)} m/s (a knot "
                        "with little data, or beyond the log's speeds): its metrics there are extrapolated")
    summary = {"source": False, "model": args.model, **origin, "scheduled": hasattr(model, "model_at"),
               "wheelbase": args.wheelbase, "scales": scales,
               "metrics": [{**m.as_dict(), "extrapolated": m.speed in sparse} for m in metrics], "units": JSON_UNITS,
               "uncertainty_method": method}
    plausibility.record_findings(summary, warnings, findings)
    summary["warnings"] = warnings
    lines = metrics_table(f"{Path(args.model).name} ({STEER_UNIT_TEXT}):", metrics)
    if sparse:
        lines.append(f"{'extrapolated (too few samples)':<32}"
                     + "".join(f"{'yes' if m.speed in sparse else '':>20}" for m in metrics))
    if method is not None:
        lines.append(f"standard deviations: {method['description']}")
    curves: dict[str, Any] = {"identified": metrics}
    if source is not None:
        summary["source_model"] = source.as_dict()
        lines += metrics_table(f"source model {source.vehicle} (linearisation):", source.linearisation)
        curves[f"source model {source.vehicle} (linearisation)"] = source.linearisation
    written = _write_figure(figure, curves, f"Handling of {Path(args.model).name}")
    if written:
        summary["figure"] = written
        lines.append(f"wrote {written}")
    return summary, "\n".join(lines), warnings


def run(args: argparse.Namespace) -> tuple[dict, str]:
    summary, text, warnings = (_run_source if args.source else _run_model)(args)
    if warnings and not args.json and not args.strict:  # under --strict the command line prints them
        text += "\n" + "\n".join(f"warning: {line}" for line in warnings)
    if warnings and args.strict:
        raise StrictWarningsError(warnings, summary, text)
    return summary, text
