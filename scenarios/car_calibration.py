"""The full-vehicle model calibrated to a car's measured log: :func:`calibrate` (`vehid calibrate`).

The log is read through the workbench's readers (``reading``: the steer as its one input, the
measured channels as its outputs, the time base and segment), each channel times its ``scale``
factor; spikes and drop-outs are found and named, and replaced by straight lines where
``despike`` asks. The drive (:class:`~vehid.vehicle.drive_calibration.DriveLog`: steer, speed,
measured channels and what each measures, a measured longitudinal acceleration, channels scored but
never fitted) is calibrated by :func:`~vehid.vehicle.drive_calibration.calibrate_drive` from the
prior vehicle: a start made able to drive the log, stages of the grey-box IEKF, the prior, start
and calibrated cars driven over the whole log and scored alike on its held-out end, the halves of
the calibrating part compared. The calibrated car's handling is computed where the log drove it.

The result, :class:`CalibrationResult`, renders the command's JSON and text. JSON (public
contract): ``log``, ``vehicle_prior``, ``samples``, ``estimation_samples``, ``valid_speed_range``,
``records``, ``samples_driven``, ``substeps``, ``parameters`` (each ``{value, std, unit}``, and
``in_vehicle`` where the vehicle file carries another value), ``correlation``,
``not_identifiable``, the NRMSE fits ``estimation_fit_percent``, ``validation_fit_percent`` and
``check_fit_percent`` of the calibrated car and ``prior_*`` / ``start_*`` of the others (R of eq. 17
under the keys ending in ``_R``), ``stages``, ``balance``, ``halves``, ``notes``, ``failure``,
``handling``, ``vehicle_file``, ``figure``, ``outliers`` and ``warnings``.

A stage that fails after one finished keeps what was computed: :func:`calibrate` writes the last
finished stage's vehicle file and figure, and raises
:class:`~vehid.identification.PartialResultError` whose ``result`` is the
:class:`CalibrationResult` (its ``failure`` says what stopped), with its rendering.
"""

from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from vehid.identification.errors import InputError, OptionError, PartialResultError, StrictWarningsError
from vehid.identification.frozen import FrozenDict, freeze_fields, thaw
from vehid.identification.optionspec import (BOOLEAN, POSITIVE, Constraint, Number, check_options, documented,
                                             option)
from vehid.scenarios.paths import check_figure_target

if TYPE_CHECKING:
    from vehid.identification.dataio.cleaning import Outlier
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.vehicle.drive_calibration import DriveCalibration, DriveLog
    from vehid.vehicle.handling import SourceHandling
    from vehid.vehicle.parameters import VehicleParameters

__all__ = ["calibrate", "CalibrateOptions", "CalibrationResult"]


class _ParameterNames(Constraint):
    """Vehicle fields as ``section.field``: a sequence of names, or one text of comma-separated names."""

    def conform(self, value: Any) -> Any:
        items = value.split(",") if isinstance(value, str) else list(value)
        if not items or not all(isinstance(item, str) for item in items):
            raise ValueError
        names = tuple(item.strip() for item in items)
        if any(name.count(".") != 1 for name in names) or len(set(names)) != len(names):
            raise ValueError
        return names

    def describe(self) -> str:
        return "one or more distinct vehicle fields, each section.field"

    def type_name(self) -> str:
        return "tuple of str"


class _Priors(Constraint):
    """Each named parameter's prior: a finite value, or a (value, positive std) pair; stored as (value, std or None)."""

    def conform(self, value: Any) -> Any:
        if not isinstance(value, Mapping):
            raise ValueError
        priors = {}
        for name, given in value.items():
            number, std = (given if isinstance(given, (tuple, list)) and len(given) == 2 else (given, None))
            if not isinstance(name, str) or not name.strip():
                raise ValueError
            number = Number().conform(number)
            std = None if std is None else Number(low=0, low_open=True).conform(std)
            priors[name.strip()] = (float(number), None if std is None else float(std))
        return FrozenDict(priors)

    def describe(self) -> str:
        return "a mapping of section.field to a finite value, or to a (value, positive std) pair"

    def type_name(self) -> str:
        return "mapping"


@documented
@dataclass(frozen=True)
class CalibrateOptions:
    """How a drive is calibrated (:func:`calibrate`); the defaults are those of `vehid calibrate`.

    Examples
    --------
    >>> CalibrateOptions(prior={"chassis.yaw_inertia": (1300.0, 200.0)}, halves=False).prior
    FrozenDict({'chassis.yaw_inertia': (1300.0, 200.0)})
    >>> CalibrateOptions(slip_limit=0.7)
    Traceback (most recent call last):
    ...
    vehid.identification.errors.OptionError: 'slip_limit' must be a number in [0, 0.5); got 0.7
    """

    validation: float = option(0.4, Number(low=0, high=1, high_open=True),
                               help="fraction of the log at its end held out for validation")
    parameters: tuple[str, ...] | None = option(
        None, _ParameterNames(),
        help="vehicle fields to calibrate, section.field as in a vehicle file (default "
             "tyre.front_cornering_scale, tyre.PKY2, tyre.friction_scale, chassis.yaw_inertia, tyre.PEY1; with the "
             "sideslip fitted also tyre.rear_cornering_scale, with the roll angle chassis.roll_inertia and "
             "suspension.front_anti_roll_bar)")
    prior: Mapping[str, tuple[float, float | None]] = option(
        FrozenDict(), _Priors(),
        help="prior value of a calibrated parameter and optionally its std in the parameter's unit; default the "
             "vehicle's value and ``prior_std``")
    prior_std: float | None = option(
        None, POSITIVE, help="relative prior standard deviation of every parameter (1: a factor e); default the "
                             "plausible spread of each default parameter (0.2-0.5), 1 for the others")
    p: float | None = option(
        None, POSITIVE, help="the filter's random-walk variance of a scaled parameter per pass (default: the "
                             "grey-box filter's); smaller holds the parameters steadier")
    passes: int | None = option(None, Number(low=1, whole=True),
                                help="most passes of the filter per stage (default: the grey-box filter's)")
    substeps: int | None = option(
        None, Number(low=1, whole=True),
        help="RK4 steps per sample (default and least: the fewest that keep the car's modes stable at the log's "
             "top speed)")
    slip_limit: float | None = option(
        None, Number(low=0, high=0.5, high_open=True),
        help="slip ratio at which the car's drive and brake torques fade (default: the vehicle's, else 0.1; 0: none)")
    halves: bool = option(True, BOOLEAN,
                          help="calibrate the two halves of the calibrating part again and compare them; off is faster")
    despike: bool = option(False, BOOLEAN,
                           help="replace the spikes and drop-outs found in the channels by straight lines between "
                                "their neighbours (they are named either way)")
    strict: bool = option(False, BOOLEAN, help="fail a result with warnings (StrictWarningsError, exit status 3)")

    def __post_init__(self) -> None:
        check_options(self)


def _fit_list(values: Any) -> list[float | None] | None:
    """Per-output scores as a JSON list (None for a non-finite score)."""
    if values is None:
        return None
    return [float(v) if math.isfinite(v) else None for v in values]


def _fit_keys(fits: Mapping[str, Any], label: str) -> dict[str, Any]:
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


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """A car calibrated to its log: typed, frozen all the way down, rendering `vehid calibrate`'s JSON and text.

    Attributes
    ----------
    log : Path
        The log read.
    prior : VehicleParameters
        The vehicle given.
    drive : DriveLog
        The drive as calibrated: steer, speed, measured and checked channels, in SI units.
    calibration : DriveCalibration
        The calibration: the start, each stage, the scores and predictions of the prior, start and
        calibrated cars, the halves compared, and the failure where a stage failed.
    options : CalibrateOptions
        The settings it ran with.
    speed_range : tuple of float
        The speeds (m/s) the vehicle model holds: the least, and the vehicle's own top speed.
    outliers : tuple of Outlier
        The spikes and drop-outs found in the log, with their values as read.
    handling : SourceHandling or None
        The calibrated car's linearised handling at speeds the log drove (None where not computed,
        a note saying why).
    notes : tuple of str
        Choices and changes said once: what was left out of the log, what the start changed.
    warnings : tuple of str
        One line per problem.
    vehicle_file : Path or None
        The calibrated vehicle file written (TOML).
    figure : Path or None
        The figure written.
    """

    log: Path
    prior: VehicleParameters
    drive: DriveLog = field(repr=False)
    calibration: DriveCalibration = field(repr=False)
    options: CalibrateOptions
    speed_range: tuple[float, float]
    outliers: tuple[Outlier, ...]
    handling: SourceHandling | None
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    vehicle_file: Path | None = None
    figure: Path | None = None

    def __post_init__(self) -> None:
        for name in ("speed_range", "outliers", "notes", "warnings"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        freeze_fields(self)  # the drive, the calibration's cars, scores and predictions too: the summary reads them

    @property
    def vehicle(self) -> VehicleParameters:
        """The calibrated car (the last stage that finished), or the start where none did."""
        return self.calibration.vehicle

    @property
    def failure(self) -> str | None:
        """What stopped the calibration part of the way (None where every stage finished)."""
        return self.calibration.failure

    def render(self) -> dict[str, Any]:
        """Render the JSON summary of `vehid calibrate`.

        Returns
        -------
        dict
            The summary (module docstring), as a fresh dict the caller may change.
        """
        result, drive = self.calibration, self.drive
        calibration = result.calibration
        names = calibration.parameter_names if calibration is not None else ()
        return thaw({
            "log": str(self.log),
            "vehicle_prior": self.prior.name,
            "samples": int(drive.n_samples),
            "estimation_samples": int(result.n_estimation),
            "valid_speed_range": list(self.speed_range),
            "records": [[float(drive.t[a]), float(drive.t[b - 1])] for a, b in result.runs],
            "samples_driven": int(sum(b - a for a, b in result.runs)),
            "substeps": int(result.substeps),
            "parameters": calibration.parameters_dict() if calibration is not None else {},
            "correlation": {name: {other: (None if not math.isfinite(calibration.correlation[i, j])
                                           else float(calibration.correlation[i, j]))
                                   for j, other in enumerate(names)}
                            for i, name in enumerate(names)},
            "not_identifiable": dict(calibration.held) if calibration is not None else {},
            **_fit_keys(result.fits, "calibrated"),
            **_fit_keys(result.fits, "prior"),
            **_fit_keys(result.fits, "start"),
            "stages": [{"stage": label, "passes": len(stage.result.history),
                        "parameters": {name: row for name, row in stage.parameters_dict().items()
                                       if row["std"] is not None}}
                       for label, stage in result.stages],
            "balance": result.balance.as_dict() if result.balance is not None else None,
            "halves": {name: {**{half: None if row[half] is None else {"value": row[half][0], "std": row[half][1]}
                                 for half in ("first", "second")}, "difference_sigma": row["difference_sigma"],
                              "not_determined": dict(row.get("not_determined", {}))}
                       for name, row in result.halves.items()},
            "notes": list(self.notes),
            "failure": result.failure,
            "handling": self.handling.as_dict() if self.handling is not None else None,
            "vehicle_file": None if self.vehicle_file is None else str(self.vehicle_file),
            "figure": None if self.figure is None else str(self.figure),
            "outliers": [{**outlier.as_dict(), "treatment": "interpolated" if self.options.despike else "in the fit"}
                         for outlier in self.outliers],
            "warnings": list(self.warnings),
        })

    def text(self, *, warnings: bool = True) -> str:
        """Render what `vehid calibrate` prints without ``--json``.

        Parameters
        ----------
        warnings : bool, default True
            Add the warnings, one line each.

        Returns
        -------
        str
            The calibration's parts and stages, each parameter, the hold-out fits of each car, the halves,
            the calibrated car's understeer gradient and the files written.
        """
        summary, result, drive = self.render(), self.calibration, self.drive
        low, top = self.speed_range
        lines = [f"calibration of {self.prior.name} to {self.log.name}: {result.n_estimation} of {drive.n_samples} "
                 f"samples at {1 / drive.dt:g} Hz calibrate, the rest is held out; speed range of this vehicle "
                 f"{low:g}-{top:g} m/s"]
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
                             if self.options.validation > 0 else "")
                continue
            shown = ", ".join(f"{channel} {value:.1f} %" if value is not None else f"{channel} -"
                              for channel, value in zip(drive.channels, values))
            unfitted = ", ".join(f"{channel} {value:.1f} % (not fitted)" for channel, value in checks.items()
                                 if value is not None)
            lines.append(f"hold-out NRMSE fit, {label} car: {shown}" + (f"; {unfitted}" if unfitted else ""))
        for name, row in summary["halves"].items():
            shown = [f"{row[half]['value']:.5g} +/- {row[half]['std']:.2g}" if row[half] else
                     f"not determined ({row['not_determined'].get(half, 'held')})" for half in ("first", "second")]
            apart = "" if row["difference_sigma"] is None else f" ({row['difference_sigma']:.1f} std apart)"
            lines.append(f"halves of the calibrating part: {name} {shown[0]} and {shown[1]}{apart}")
        for row in (summary["handling"] or {}).get("linearisation", ()):
            gradient = row["understeer_gradient_deg_per_g"]["value"]
            if gradient is not None:
                lines.append(f"calibrated car at {row['speed']:g} m/s: understeer gradient {gradient:.3g} deg/g")
        lines += [f"wrote {path}" for path in (self.vehicle_file, self.figure) if path is not None]
        if self.outliers and self.options.despike:
            lines.append(f"{len(self.outliers)} spike(s) or drop-out(s) replaced by straight lines between their "
                         "neighbours (--despike); the JSON key outliers lists their values as read")
        lines += [f"warning: {line}" for line in (self.warnings if warnings else ())]
        return "\n".join(line for line in lines if line)

    def plot(self) -> Any:
        """Draw the measured channels, fitted then checked, against each scored car over the whole log.

        Returns
        -------
        matplotlib.figure.Figure
            One panel per channel; the legends give each car's hold-out NRMSE fit and R, a dashed
            line marks where the held-out part begins.
        """
        checks = {channel: quantity for channel, (quantity, _) in self.drive.checks.items()}
        return _figure_page(self.log, self.prior, self.drive, self.calibration, self.drive.channels, checks)


def _figure_page(log: Path, prior: Any, drive: Any, result: Any, outputs: tuple[str, ...],
                 checks: Mapping[str, str]) -> Any:
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
        predictions[label] = result.predictions[label]
        if score:
            scores[label] = (np.concatenate([score["nrmse"], [score["checks"][channel] for channel in checks]]),
                             np.concatenate([score["R"], [score["checks_R"][channel] for channel in checks]]))
    title = textwrap.fill(f"{prior.name} calibrated to {Path(log).name}: the first "
                          f"{result.n_estimation / drive.n_samples:.0%} calibrates, the rest (after the dashed line) "
                          "is held out and scored in the legends" + (f"; {', '.join(checks)} not fitted" if checks
                                                                     else ""), 60)
    page = plot_time_fits(drive.t, measured, predictions, (*outputs, *checks), [units[q] for q in quantities],
                          title=title, scores=scores or None)
    for axis in page.axes:  # where the held-out part begins
        axis.axvline(drive.t[result.n_estimation - 1], color="0.5", linestyle="--", linewidth=1.0)
    return page


def _write_text(path: Path, text: str) -> Path:
    """Write under a hidden name and rename: a killed run never leaves half a file at ``path``."""
    import uuid

    temporary = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")
    try:
        temporary.write_text(text)
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
    return path


def _vehicle_file(path: Path, log: Path, prior: VehicleParameters, result: DriveCalibration) -> Path:
    """Write the calibrated car (the last stage that finished, or the start), its comment saying which."""
    from vehid.vehicle.calibration import vehicle_toml

    if result.calibration is not None:
        what = f"calibrated to {log.name} by vehid calibrate ({', '.join(result.calibration.parameter_names)})"
        if result.failure is not None:
            what += f"; the last stage that finished ({result.stages[-1][0]}): {result.failure}"
    else:
        what = f"NOT calibrated: the start derived from {log.name} by vehid calibrate; {result.failure}"
    return _write_text(path, vehicle_toml(result.vehicle, f"{prior.name} {what}"))


def _calibrated_handling(result: DriveCalibration, drive: DriveLog, top: float) -> tuple[Any, str | None]:
    """The calibrated car's linearised handling at three speeds the log drove inside its own range, or why not."""
    import numpy as np

    from vehid.vehicle.handling import source_handling

    driven = drive.speed[np.concatenate([np.arange(a, b) for a, b in result.runs])]
    lo, hi = float(np.min(driven)), float(np.max(driven))
    speeds = sorted({round(v, 1) for v in np.linspace(max(lo, 5.0), min(max(hi, 5.0), top), 3)})
    try:
        return source_handling(result.vehicle, speeds, simulate=False), None
    except (InputError, ValueError, np.linalg.LinAlgError) as exc:
        return None, f"handling of the calibrated car not computed: {exc}"


def _check_channels(reading: ReadSettings, speed: str, quantities: tuple[str, ...], acceleration: str | None,
                    checks: Mapping[str, str]) -> tuple[str, ...]:
    """Every log channel the calibration reads beside the steer, after checking that each is named once and each
    quantity is the model's."""
    from vehid.vehicle.model import OUTPUT_NAMES

    if len(reading.inputs) != 1:
        raise OptionError("'inputs' names the log's one steer channel (road-wheel angle, rad)", "inputs")
    outputs = tuple(reading.outputs)
    if not outputs:
        raise OptionError("'outputs' needs at least one name", "outputs")
    if len(outputs) != len(quantities):
        raise OptionError(f"'outputs' names {len(outputs)} channel(s), 'quantities' {len(quantities)}: give one "
                          "quantity per output", "outputs", "quantities")
    for quantity in (*quantities, *checks.values()):
        if quantity not in OUTPUT_NAMES:
            raise OptionError(f"unknown quantity {quantity!r} ('quantities' or a check's); the model offers "
                              f"{', '.join(OUTPUT_NAMES)}", "quantities")
    channels = (speed, *outputs, *checks, *((acceleration,) if acceleration else ()))
    if reading.inputs[0] in channels or len(set(channels)) != len(channels):
        raise OptionError("a log channel is named twice among 'inputs', 'speed', 'outputs', the checked channels and "
                          "'acceleration'", "inputs", "speed", "outputs", "acceleration")
    return channels


def calibrate(log: str | os.PathLike, *, speed: str, quantities: Sequence[str], reading: ReadSettings,
              vehicle: str | os.PathLike | VehicleParameters = "baseline", acceleration: str | None = None,
              checks: Mapping[str, str] | None = None, options: CalibrateOptions = CalibrateOptions(),
              scale: Any = None, out: str | os.PathLike | None = None, figure: str | os.PathLike | None = None,
              force: bool = False) -> CalibrationResult:
    """Calibrate the full-vehicle model's parameters to a car's measured log (module docstring).

    Parameters
    ----------
    log : path
        The measured log (.csv, .dat, .txt, .mat, .mf4 or a workbench .h5 record).
    speed : str
        The log's forward speed channel (m/s after ``scale``), which drives the model's speed hold.
    quantities : sequence of str
        The model quantity each of ``reading.outputs`` measures, in order (``yaw_rate``,
        ``lateral_acceleration``, ``roll_angle``, ``sideslip``, ...; SI units).
    reading : ReadSettings
        How the log is read: its one input the road-wheel steer (rad), its outputs the measured channels
        the calibration fits, and the time column and segment.
    vehicle : str, path or VehicleParameters
        The prior vehicle: baseline, understeer, saloon, a .toml/.json vehicle file or its parameters.
    acceleration : str, optional
        The log's longitudinal acceleration (m/s^2), fed forward to the speed hold (default: the speed's
        smoothed rate).
    checks : mapping of str to str, optional
        Measured channels scored but never fitted, each to the model quantity it measures
        (``{"beta_true": "sideslip"}``).
    options : CalibrateOptions
        The calibration's settings.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Factors of log channels (a unit, a sign).
    out : path, optional
        Write the calibrated vehicle to this .toml file (checked before any work; never over an input).
    figure : path, optional
        Draw the measured channels against the prior, start and calibrated cars (.png, .pdf or .svg; checked
        before any work).
    force : bool
        Let ``out`` or ``figure`` replace an existing file.

    Returns
    -------
    CalibrationResult
        The calibrated car, its parameters with standard deviations, the scores of each car and the halves,
        rendering the command's JSON (``render()``) and text (``text()``).

    Raises
    ------
    InputError
        Bad input, before any work where it can be seen then (an
        :class:`~vehid.identification.OptionError` names the option).
    PartialResultError
        A stage failed after the work began: its ``result`` is the :class:`CalibrationResult` of the last
        stage that finished (written to ``out`` and ``figure``), with its summary and text.
    StrictWarningsError
        With ``options.strict``, where the result has warnings (carrying its summary and text).

    Examples
    --------
    The committed race-car log's yaw rate and lateral acceleration from a plain prior (the baseline car
    with the race car's mass and axle positions), the sideslip scored but never fitted; not run here,
    it takes minutes of CPU (the model is compiled and filtered in stages)::

        from vehid.identification import ReadSettings
        from vehid.scenarios import CalibrateOptions, calibrate
        from vehid.vehicle.parameters import vehicle_from_mapping

        prior = vehicle_from_mapping({"base": "baseline", "name": "race car prior",
                                      "chassis": {"mass": 982.0, "cg_to_front_axle": 1.33, "cg_to_rear_axle": 1.07}})
        reading = ReadSettings(inputs=("delta",), outputs=("yawRate", "ayCG"))
        result = calibrate("tests/data/race_car_250lm/20140222_01_01_03_250lm.csv", speed="vx",
                           quantities=("yaw_rate", "lateral_acceleration"), reading=reading, vehicle=prior,
                           checks={"beta_true": "sideslip"}, options=CalibrateOptions(halves=False))
        print(result.text())          # result.render(): the --json summary
        print(result.vehicle.tyre.front_cornering_scale, result.failure)
    """
    import numpy as np

    from vehid.identification.dataio.archive_safety import check_output_target
    from vehid.identification.dataio.cleaning import despike, find_outliers
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.identification.filtering.greybox import GreyBoxOptions
    from vehid.scenarios.drive_log import read_drive, scaled_channels
    from vehid.vehicle import named_vehicle
    from vehid.vehicle import drive_calibration
    from vehid.vehicle.model import speed_limit
    from vehid.vehicle.validity import MIN_SPEED

    if not isinstance(options, CalibrateOptions):
        raise InputError("calibrate takes CalibrateOptions")
    if not isinstance(reading, ReadSettings):
        raise OptionError("'reading' is a ReadSettings naming the steer as its input and the measured channels "
                          "as its outputs", "reading")
    path = Path(log)
    if not path.is_file():
        raise InputError(f"no such log: {path}")
    quantities = tuple(quantities)
    checks = dict(checks or {})
    channels = _check_channels(reading, speed, quantities, acceleration, checks)
    steer = reading.inputs[0]
    filter_settings = {name: getattr(options, name) for name in ("p", "passes", "substeps")
                       if getattr(options, name) is not None}
    filter_options = GreyBoxOptions(prior_std=options.prior_std or 1.0, coloured_residuals=True,
                                    parameter_tolerance=drive_calibration.DRIVE_PARAMETER_TOLERANCE, **filter_settings)
    prior = named_vehicle(vehicle)
    figure_path = check_figure_target(figure, force)
    if out is not None:
        check_output_target(out, inputs=[path, *([vehicle] if isinstance(vehicle, (str, os.PathLike)) else [])],
                            force=force, what="vehicle file", identify=lambda target: None, suffixes=(".toml",))
    settings = {item.name: getattr(reading, item.name) for item in dataclasses.fields(reading)
                if item.name not in ("inputs", "outputs")}
    data, factors = read_drive(path, steer, channels, scale, what="a channel of this calibration", **settings)
    outliers = find_outliers(data)
    if options.despike and outliers:
        data = despike(data, outliers)
    channel = scaled_channels(data, steer, factors)
    outputs = tuple(reading.outputs)
    drive = drive_calibration.DriveLog(
        t=data.t, steer=channel(steer), speed=channel(speed),
        outputs=np.column_stack([channel(name) for name in outputs]), channels=outputs, quantities=quantities,
        acceleration=channel(acceleration) if acceleration else None,
        checks={name: (quantity, channel(name)) for name, quantity in checks.items()},
    )
    priors = {name: value for name, (value, _) in options.prior.items()}
    prior_std = {name: std for name, (_, std) in options.prior.items() if std is not None}
    run = drive_calibration.calibrate_drive(
        prior, drive, validation=options.validation, parameters=options.parameters, priors=priors,
        prior_std=prior_std, options=filter_options, slip_limit=options.slip_limit, halves=options.halves,
        relative_prior_std=options.prior_std)
    top = speed_limit(prior)
    handling, why_not = _calibrated_handling(run, drive, top)
    offset = float(data.meta.get("time_base", {}).get("time_offset", 0.0) or 0.0)
    warnings = list(run.warnings)
    if outliers and not options.despike:
        from vehid.identification.dataio.timewindow import time_text

        shown = ", ".join(f"{o.channel} {o.value:.4g} at {time_text(o.time - offset, offset)}" for o in outliers[:5])
        warnings.insert(0, f"{len(outliers)} spike(s) or drop-out(s) entered the calibration: {shown}"
                           f"{' and more' if len(outliers) > 5 else ''}; --despike replaces them by interpolation")
    result = CalibrationResult(
        log=path, prior=prior, drive=drive, calibration=run, options=options, speed_range=(MIN_SPEED, top),
        outliers=tuple(outliers), handling=handling,
        notes=(*run.notes, *([why_not] if why_not else [])), warnings=tuple(warnings))
    written = {}
    if out is not None:
        written["vehicle_file"] = _vehicle_file(Path(out), path, prior, run)
    if figure_path is not None:
        import matplotlib.pyplot as plt

        page = result.plot()
        try:
            page.savefig(figure_path)
        finally:
            plt.close(page)
        written["figure"] = figure_path
    if written:
        result = dataclasses.replace(result, **written)
    if result.failure is not None:
        # the filter's advice (other start values, a smaller p) in the options of this function
        advice = ("; here 'prior' NAME=VALUE gives a parameter another start and 'p' a smaller random walk"
                  if "diverged" in result.failure else "")
        raise PartialResultError(f"the calibration failed part of the way: {result.failure}{advice}",
                                 result.render(), result.text(), result=result,
                                 options=("prior", "p") if advice else ())
    if options.strict and result.warnings:
        error = StrictWarningsError(list(result.warnings), result.render(), result.text(warnings=False))
        error.result = result
        raise error
    return result
