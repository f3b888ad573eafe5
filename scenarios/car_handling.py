"""Handling characteristics of an identified model or of the source model at each speed: :func:`handling`.

ISO 4138-style steady state (yaw-rate and lateral-acceleration gains, sideslip gain, understeer
gradient in deg/g, characteristic or critical speed) and ISO 7401-style transients (yaw-rate response
and peak response times, overshoot, gain and phase at 1 Hz, -3 dB bandwidth), each with its standard
deviation by the delta method where the model carries a parameter covariance
(:mod:`vehid.vehicle.handling`). What `vehid handling` prints is the rendering of the result:
:class:`ModelHandling` for an identified model (a model file, an identification archive's returned
model, or a model in memory), checked for physical plausibility
(:mod:`vehid.scenarios.plausibility_checks`), and :class:`SourceModelHandling` for the source model,
its linearisation and its simulated ISO 7401 step, 1 Hz sine dwell and sine sweep.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from vehid.identification.errors import InputError, OptionError, StrictWarningsError
from vehid.identification.frozen import FrozenDict, freeze_fields, thaw
from vehid.identification.optionspec import BOOLEAN, POSITIVE, Numbers, check_options, documented, option
from vehid.scenarios.paths import check_figure_target

if TYPE_CHECKING:
    from vehid.identification.automatic.result import Finding
    from vehid.vehicle.handling import HandlingMetrics, SourceHandling, SteadyStateHandling
    from vehid.vehicle.parameters import VehicleParameters

__all__ = ["handling", "HandlingOptions", "SourceHandlingOptions", "ModelHandling", "SourceModelHandling",
           "ROLES", "JSON_UNITS", "STEER_UNIT_TEXT", "metrics_table", "load_model"]

#: The channels a model's handling names, and that ``scales`` converts to SI.
ROLES = ("steer", "yaw_rate", "lateral_acceleration", "sideslip")
#: Below this fraction of the asked range the steady states are named as saturating (the baseline car's
#: steps fall 1-7 % short at 4 m/s^2 and 30 % short at 9).
_REACHED = 0.8
#: Speeds (m/s) of the source model's handling unless others are asked.
SOURCE_SPEEDS = (10.0, 20.0, 30.0)
_SPEEDS = Numbers(POSITIVE)


@documented
@dataclass(frozen=True)
class HandlingOptions:
    """How an identified model's handling is computed (`vehid handling MODEL`).

    ``scales`` are factors to SI of its channels by role (:data:`ROLES`).
    """

    yaw_rate: str | None = option(None, help="the model's yaw-rate output (default: yaw_rate)")
    lateral_acceleration: str | None = option(
        None, help="the model's lateral-acceleration output (default: lateral_acceleration, if any)")
    sideslip: str | None = option(None, help="the model's sideslip output (default: sideslip, if any)")
    steer: str | None = option(None, help="the model's steer input (default: steer, else the first)")
    wheelbase: float | None = option(
        None, POSITIVE, help="wheelbase in m, for the understeer gradient (default: a physical model's own)")
    scales: Mapping[str, float] = option(
        FrozenDict(), help="factors to SI of the model's channels by role (steer to road-wheel rad, yaw rate to "
                           "rad/s, lateral acceleration to m/s^2)")
    run: str | None = option(None, help="the archive's run whose model to use (default: the returned one)")
    beside_source: Any = option(
        None, help="also the source model's linearisation at the same speeds (a vehicle: baseline, understeer, "
                   "a .toml/.json file or its parameters)")
    strict: bool = option(False, BOOLEAN, help="fail a result with warnings (StrictWarningsError, exit status 3)")

    def __post_init__(self) -> None:
        check_options(self)
        scales = {}
        for role, factor in dict(self.scales).items():
            if role not in ROLES:
                raise OptionError(f"'scales' takes ROLE=FACTOR with ROLE one of {', '.join(ROLES)}; got {role!r}",
                                  "scales")
            if isinstance(factor, bool) or not isinstance(factor, (int, float)) or not math.isfinite(factor) \
                    or factor == 0:
                raise OptionError(f"'scales' {role} must be finite and non-zero; got {factor!r}", "scales")
            scales[role] = float(factor)
        object.__setattr__(self, "scales", FrozenDict(scales))


@documented
@dataclass(frozen=True)
class SourceHandlingOptions:
    """How the source model's handling is computed (`vehid handling --source`)."""

    simulation: bool = option(True, BOOLEAN,
                              help="also the simulated ISO 7401 step, 1 Hz sine dwell and sine sweep (else the "
                                   "linearisation only)")
    step_lateral_acceleration: float | None = option(
        None, POSITIVE, help="steady lateral acceleration of the simulated step in m/s^2 (default 4, as ISO 7401)")
    steady_range: float | None = option(
        None, POSITIVE, help="also the steady state over +/- A m/s^2 of lateral acceleration (ISO 4138 steer steps): "
                             "the reference for a model fitted on data reaching A")
    strict: bool = option(False, BOOLEAN, help="fail a result with warnings (StrictWarningsError, exit status 3)")

    def __post_init__(self) -> None:
        check_options(self)


def _model_from_json(path: Path) -> Any:
    from vehid.identification.dataio.model_files import json_model_kind
    from vehid.identification.models.modal import ModalModel
    from vehid.identification.models.scheduled import ScheduledModalModel

    try:
        content = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path} is not a JSON model file: {exc}") from None
    kind = json_model_kind(content)
    if kind is None:
        raise InputError(f"{path} holds no single-track, linear or scheduled modal model (the model file of "
                         "vehid identify)")
    try:
        if kind == "single-track":
            from vehid.vehicle.single_track import IdentifiedSingleTrack

            return IdentifiedSingleTrack.from_dict(content)  # physical units throughout: no preparation to undo
        if kind == "scheduled":
            model = ScheduledModalModel.from_dict(content)
        elif kind == "modal":
            model = ModalModel.from_dict(content)
        else:
            raise InputError(f"{path} holds a {kind!r} model, which has no handling metrics")
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
            raise OptionError(f"{path} holds several models ({', '.join(sorted(usable))}): choose one with 'run'", "run")
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


def load_model(target: str | os.PathLike, run_name: str | None = None) -> tuple[Any, dict[str, Any]]:
    """The model in a ``.json`` model file or an identification archive, and where it came from."""
    path = Path(target)
    if not path.is_file():
        raise InputError(f"no model file {str(target)!r}")
    if path.suffix.lower() == ".json":
        if run_name is not None:
            raise OptionError("'run' names an archive's run: a .json model file holds one model", "run")
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
    raise OptionError("give the speed at which the model holds: 'speeds' V", "speeds")


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


def _write_figure(path: Path | None, curves: Mapping[str, Any], title: str) -> Path | None:
    if path is None:
        return None
    from vehid.scenarios.report import handling_page

    handling_page(curves, title=title).savefig(path)
    return path


def _speeds(speeds: Sequence[float]) -> tuple[float, ...]:
    from vehid.identification.optionspec import check_value

    return check_value("speeds", speeds, _SPEEDS)


def _with_warnings(text: str, warnings: Sequence[str]) -> str:
    return text + "".join(f"\nwarning: {line}" for line in warnings)


@dataclass(frozen=True, eq=False)
class ModelHandling:
    """An identified model's handling at each speed: typed, frozen, rendering `vehid handling MODEL`'s JSON and text.

    Attributes
    ----------
    model : IdentifiedModel
        The model evaluated.
    model_file : str or None
        The model file or archive it was read from.
    origin : FrozenDict
        Where in an archive it came from (``run``, ``record_speeds``); empty for a model file.
    metrics : tuple of HandlingMetrics
        The metrics at each speed.
    extrapolated : tuple of float
        The speeds where the model rests on too few samples.
    wheelbase : float or None
        L (m), the model's own where not given.
    scales : FrozenDict
        The factors to SI applied.
    uncertainty_method : FrozenDict or None
        How the model's covariance, and so every standard deviation, was obtained.
    plausibility : tuple of Finding
        The failed checks of the car's physics (each also a warning).
    warnings : tuple of str
        One line per problem found.
    source : SourceHandling or None
        The source model's linearisation at the same speeds, where asked.
    figure : Path or None
        The handling page written.
    """

    model: Any = field(repr=False)
    model_file: str | None
    origin: FrozenDict
    metrics: tuple[HandlingMetrics, ...]
    extrapolated: tuple[float, ...]
    wheelbase: float | None
    scales: FrozenDict
    uncertainty_method: FrozenDict | None
    plausibility: tuple[Finding, ...]
    warnings: tuple[str, ...]
    source: SourceHandling | None = None
    figure: Path | None = None

    def __post_init__(self) -> None:
        for name in ("metrics", "extrapolated", "plausibility", "warnings"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        freeze_fields(self)  # the model read too: the summary says whether it is scheduled

    @property
    def name(self) -> str:
        """What the text calls the model: its file's name."""
        return Path(self.model_file).name if self.model_file is not None else type(self.model).__name__

    def render(self) -> dict[str, Any]:
        """Render the JSON summary of `vehid handling MODEL`.

        Returns
        -------
        dict
            The summary, as a fresh dict the caller may change.
        """
        return thaw({
            "source": False, "model": self.model_file, **self.origin, "scheduled": hasattr(self.model, "model_at"),
            "wheelbase": self.wheelbase, "scales": self.scales,
            "metrics": [{**m.as_dict(), "extrapolated": m.speed in self.extrapolated} for m in self.metrics],
            "units": JSON_UNITS, "uncertainty_method": self.uncertainty_method,
            "plausibility": [finding.as_dict() for finding in self.plausibility],
            "warnings": list(self.warnings),
            **({"source_model": self.source.as_dict()} if self.source is not None else {}),
            **({"figure": str(self.figure)} if self.figure is not None else {}),
        })

    def text(self, *, warnings: bool = True) -> str:
        """Render the metrics table as `vehid handling MODEL` prints it.

        Parameters
        ----------
        warnings : bool, default True
            Add the warnings, one line each.

        Returns
        -------
        str
            The table.
        """
        lines = metrics_table(f"{self.name} ({STEER_UNIT_TEXT}):", self.metrics)
        if self.extrapolated:
            lines.append(f"{'extrapolated (too few samples)':<32}"
                         + "".join(f"{'yes' if m.speed in self.extrapolated else '':>20}" for m in self.metrics))
        if self.uncertainty_method is not None:
            lines.append(f"standard deviations: {self.uncertainty_method['description']}")
        if self.source is not None:
            lines += metrics_table(f"source model {self.source.vehicle} (linearisation):", self.source.linearisation)
        if self.figure is not None:
            lines.append(f"wrote {self.figure}")
        return _with_warnings("\n".join(lines), self.warnings if warnings else ())


@dataclass(frozen=True, eq=False)
class SourceModelHandling:
    """The source model's handling: typed, frozen, rendering `vehid handling --source`'s JSON and text.

    Attributes
    ----------
    result : SourceHandling
        Its linearisation and simulation at each speed.
    steady_state : tuple of SteadyStateHandling
        The steady state over the asked range of lateral acceleration, where asked.
    steady_range : float or None
        That range (m/s^2).
    warnings : tuple of str
        Steady states that fall short of the range (saturating tyres).
    figure : Path or None
        The handling page written.
    """

    result: SourceHandling
    steady_state: tuple[SteadyStateHandling, ...]
    steady_range: float | None
    warnings: tuple[str, ...]
    figure: Path | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "steady_state", tuple(self.steady_state))
        object.__setattr__(self, "warnings", tuple(self.warnings))
        freeze_fields(self)

    def render(self) -> dict[str, Any]:
        """Render the JSON summary of `vehid handling --source`.

        Returns
        -------
        dict
            The summary, as a fresh dict the caller may change.
        """
        return thaw({
            "source": True, **self.result.as_dict(), "units": JSON_UNITS, "warnings": list(self.warnings),
            **({"steady_state": [entry.as_dict() for entry in self.steady_state]}
               if self.steady_range is not None else {}),
            **({"figure": str(self.figure)} if self.figure is not None else {}),
        })

    def text(self, *, warnings: bool = True) -> str:
        """Render the source model's handling as `vehid handling --source` prints it.

        Parameters
        ----------
        warnings : bool, default True
            Add the warnings, one line each.

        Returns
        -------
        str
            The linearisation's and the simulation's metrics tables and the steady states.
        """
        result, level = self.result, self.result.step_lateral_acceleration
        lines = [f"source model {result.vehicle} (wheelbase {result.wheelbase:g} m; {STEER_UNIT_TEXT})",
                 *metrics_table("linearisation:", result.linearisation)]
        if result.simulation:
            lines += metrics_table(f"simulation (step to {level:g} m/s^2; 1 Hz sine dwell and sweep of that steer):",
                                   result.simulation)
        if self.steady_state:
            lines.append(f"steady state over +/- {self.steady_range:g} m/s^2 (ISO 4138 steer steps):")
            lines += [f"  {entry.speed:g} m/s: understeer gradient {entry.understeer_gradient_deg_per_g:.4g} deg/g, "
                      f"characteristic speed {_format(entry.characteristic_speed_m_s)} m/s, "
                      f"yaw-rate gain {entry.yaw_rate_gain:.4g} deg/s per deg, lateral acc. gain "
                      f"{entry.lateral_acceleration_gain * math.pi / 180:.4g} m/s^2 per deg" for entry in self.steady_state]
        if self.figure is not None:
            lines.append(f"wrote {self.figure}")
        return _with_warnings("\n".join(lines), self.warnings if warnings else ())


def handling(model: Any = None, *, source: str | VehicleParameters | None = None,
             speeds: Sequence[float] | None = None, options: HandlingOptions | SourceHandlingOptions | None = None,
             figure: str | os.PathLike | None = None, force: bool = False) -> ModelHandling | SourceModelHandling:
    """Handling metrics (ISO 4138 / ISO 7401) of an identified model, or of the source model, at each speed.

    Parameters
    ----------
    model : path or IdentifiedModel, optional
        A model file written by `vehid identify --save-model` (.json), an identification archive
        (its returned model, or ``options.run``'s), or a model in memory.
    source : str or VehicleParameters, optional
        Instead of ``model``: the source model of this vehicle (baseline, understeer, a .toml/.json
        vehicle file or its parameters).
    speeds : sequence of float, optional
        Speeds in m/s (default: 10, 20 and 30 for the source model; a scheduled model's grid, or the
        speed stored with a model of one speed).
    options : HandlingOptions or SourceHandlingOptions, optional
        The settings of the one asked for (default: the defaults).
    figure : path, optional
        Write the handling page (gains and understeer gradient against speed, +/- 2 std bands) to this
        .png, .pdf or .svg file (checked before any work).
    force : bool
        Let ``figure`` replace an existing file.

    Returns
    -------
    ModelHandling or SourceModelHandling
        The metrics and warnings, rendering the command's JSON (``render()``) and text (``text()``).

    Raises
    ------
    InputError
        Bad input, before any work where it can be seen then.
    StrictWarningsError
        With ``options.strict``, where the result has warnings (carrying its summary and text).

    Examples
    --------
    The baseline car's linearisation at 20 m/s. Its understeer gradient K (deg/g) sets the
    characteristic speed ``sqrt(57.3 L g / K)`` = 46.9 m/s on the 2.7 m wheelbase:

    >>> from vehid.scenarios import SourceHandlingOptions, handling
    >>> result = handling(source="baseline", speeds=[20.0], options=SourceHandlingOptions(simulation=False))
    >>> metrics = result.result.linearisation[0]
    >>> round(metrics.understeer_gradient_deg_per_g, 2), round(metrics.characteristic_speed_m_s, 1)
    (0.69, 46.9)
    >>> round(metrics.yaw_rate_gain, 2)  # V / (L (1 + V^2 / v_ch^2)), deg/s per deg of road-wheel steer
    6.27
    """
    if (model is None) == (source is None):
        raise InputError("give a model (a model file, an archive or a model) or the source vehicle, not both")
    kind = SourceHandlingOptions if source is not None else HandlingOptions
    options = kind() if options is None else options
    if not isinstance(options, kind):
        raise InputError(f"the {'source model' if source is not None else 'model'}'s handling takes {kind.__name__}")
    speeds = None if speeds is None else _speeds(speeds)
    figure_path = check_figure_target(figure, force)
    result = (_source_handling(source, speeds, options, figure_path) if source is not None
              else _model_handling(model, speeds, options, figure_path))
    if options.strict and result.warnings:
        error = StrictWarningsError(list(result.warnings), result.render(), result.text(warnings=False))
        error.result = result
        raise error
    return result


def _source_handling(source: Any, speeds: tuple[float, ...] | None, options: SourceHandlingOptions,
                     figure: Path | None) -> SourceModelHandling:
    from vehid.vehicle import named_vehicle
    from vehid.vehicle.handling import ISO_7401_LATERAL_ACCELERATION, source_handling, source_steady_state

    speeds = SOURCE_SPEEDS if speeds is None else speeds
    level = ISO_7401_LATERAL_ACCELERATION if options.step_lateral_acceleration is None else \
        options.step_lateral_acceleration
    params = named_vehicle(source) if isinstance(source, (str, os.PathLike)) else source
    result = source_handling(params, list(speeds), simulate=options.simulation, step_lateral_acceleration=level)
    steady: tuple = ()
    warnings: list[str] = []
    if options.steady_range is not None:
        steady = tuple(source_steady_state(params, list(speeds), lateral_acceleration=options.steady_range))
        warnings += [f"at {entry.speed:g} m/s the steady states reach {entry.reached_lateral_acceleration:.3g} of the "
                     f"{options.steady_range:g} m/s^2 asked: the tyres saturate" for entry in steady
                     if entry.reached_lateral_acceleration < _REACHED * options.steady_range]
    curves = {"linearisation": result.linearisation,
              **({f"simulation (step to {level:g} m/s^2)": result.simulation} if result.simulation else {})}
    written = _write_figure(figure, curves, f"Handling of the source model {result.vehicle}")
    return SourceModelHandling(result, steady, options.steady_range, tuple(warnings), written)


def _model_handling(target: Any, speeds: tuple[float, ...] | None, options: HandlingOptions,
                    figure: Path | None) -> ModelHandling:
    from vehid.identification.automatic.reported_checks import uncertainty_method
    from vehid.scenarios import plausibility_checks as plausibility
    from vehid.vehicle.handling import handling_metrics

    beside = None
    if options.beside_source is not None:
        from vehid.vehicle import named_vehicle

        # a bad vehicle file is bad input before any work
        beside = (named_vehicle(options.beside_source) if isinstance(options.beside_source, (str, os.PathLike))
                  else options.beside_source)
    if isinstance(target, (str, os.PathLike)):
        model, origin, model_file = *load_model(target, options.run), str(target)
    else:
        if options.run is not None:
            raise OptionError("'run' names an archive's run: a model in memory is one model", "run")
        model, origin, model_file = target, {}, None
    wheelbase = options.wheelbase
    if wheelbase is None and getattr(model, "wheelbase", None) is not None:
        wheelbase = float(model.wheelbase)  # a physical model knows its own
    speeds = list(speeds) if speeds is not None else _default_speeds(model, origin)
    names = {"yaw_rate": options.yaw_rate, "lateral_acceleration": options.lateral_acceleration,
             "sideslip": options.sideslip}
    metrics = handling_metrics(model, speeds, **names, steer=options.steer, wheelbase=wheelbase,
                               scales=dict(options.scales))
    source = None
    if beside is not None:
        from vehid.vehicle.handling import source_handling

        source = source_handling(beside, speeds, simulate=False)
    warnings = []
    if wheelbase is None:
        warnings.append("no --wheelbase: the understeer gradient and the characteristic speed are not computed")
    if all(not math.isfinite(m.std["yaw_rate_gain"]) for m in metrics):
        warnings.append("the model carries no parameter covariance: the metrics have no error bars")
    unstable = [m.speed for m in metrics if not math.isfinite(m.yaw_rate_response_time_s)]
    if unstable:
        warnings.append("the model is unstable or never reaches 90 % of its steady yaw rate at "
                        f"{', '.join(f'{v:g}' for v in unstable)} m/s: no step metrics there")
    findings, sparse = plausibility.handling_findings(model, speeds, metrics, **names)
    if sparse:
        warnings.append(f"the model rests on too few samples at {', '.join(f'{v:g}' for v in sparse)} m/s (a knot "
                        "with little data, or beyond the log's speeds): its metrics there are extrapolated")
    warnings += [finding.warning() for finding in findings]
    curves: dict[str, Any] = {"identified": metrics}
    if source is not None:
        curves[f"source model {source.vehicle} (linearisation)"] = source.linearisation
    name = Path(model_file).name if model_file is not None else type(model).__name__
    written = _write_figure(figure, curves, f"Handling of {name}")
    return ModelHandling(model, model_file, origin, tuple(metrics), tuple(sparse), wheelbase, options.scales,
                         uncertainty_method(model), tuple(findings), tuple(warnings), source, written)
