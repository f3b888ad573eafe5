"""A car's cornering stiffnesses and yaw inertia from its log: :func:`identify_single_track`
(`vehid identify --structure single-track`).

The physical single-track model (:mod:`vehid.vehicle.single_track`) with the log's speed as a measured
time-varying parameter (``schedule``), identified by the grey-box IEKF
(:mod:`vehid.identification.filtering.greybox`) from the samples at or above ``min_speed`` (default
5 m/s), each run of them a record of its own (:func:`~vehid.identification.automatic.intake.clean_runs`).
Signals are taken as recorded, times ``scale``: a physical model has no operating point to remove, and a
track log's mean yaw rate (a circuit driven one way round) is response, not offset. Mass and axle
distances are the :class:`~vehid.vehicle.single_track.SingleTrackConfig`'s (the command takes them from
``--mass``, ``--lf``, ``--lr`` or a vehicle file). :class:`SingleTrackOptions` holds the grey-box filter's
``p`` (the random-walk variance of a scaled parameter over the first pass,
:class:`~identification.filtering.greybox.GreyBoxOptions`) and its largest number of ``passes``. The
result, :class:`SingleTrackIdentification`, renders the command's JSON and text.

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
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vehid.identification.assessment.metrics import nrmse_fit
from vehid.identification.data import IOData, as_records
from vehid.identification.errors import InputError, OptionError, StrictWarningsError
from vehid.identification.frozen import FrozenDict, freeze_fields, thaw
from vehid.identification.optionspec import BOOLEAN, POSITIVE, Number, check_options, documented, option
from vehid.scenarios import single_track_segments
from vehid.scenarios.log_cleaning import MIN_RUN_SECONDS, MIN_SPEED
# most Runge-Kutta steps per sample, and how much of a time constant one covers: the identified model's own
from vehid.vehicle.single_track import MAX_SUBSTEPS, STEP_PER_TIME_CONSTANT

if TYPE_CHECKING:
    from vehid.identification.assessment.segments import SegmentConsistency, UncertaintyMethod
    from vehid.identification.automatic.result import Finding
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.identification.filtering.greybox import GreyBoxResult
    from vehid.vehicle.single_track import IdentifiedSingleTrack, SingleTrackConfig, SingleTrackHandling

__all__ = ["identify_single_track", "SingleTrackOptions", "SingleTrackIdentification", "Estimate", "fit_log",
           "MIN_LOG_SPEED", "CORRELATION_WARNING", "LINEAR_LIMIT_G", "MAX_SUBSTEPS"]

#: Below this speed (m/s) slip angles of a rolling car are not small and the model is not meant to hold: the
#: least speed of the samples used, unless ``min_speed`` says otherwise (:data:`~vehid.scenarios.log_cleaning.MIN_SPEED`).
MIN_LOG_SPEED = MIN_SPEED
#: |correlation| above which two parameters are named as not separated by the log.
CORRELATION_WARNING = 0.98
#: Lateral acceleration (g) beyond which a linear axle characteristic averages over saturation.
LINEAR_LIMIT_G = 0.5


@documented
@dataclass(frozen=True)
class SingleTrackOptions:
    """Settings of the single-track identification (:func:`identify_single_track`).

    The defaults are those of `vehid identify --structure single-track`.
    """

    p: float | None = option(
        None, POSITIVE, help="tuning parameter p of the grey-box filter: the random-walk variance of a scaled "
                             "parameter over the first pass (default: the grey-box filter's)")
    passes: int | None = option(None, Number(low=1, whole=True),
                                help="largest number of passes of the grey-box filter (default: its own)")
    strict: bool = option(False, BOOLEAN, help="fail a run that ends with warnings (StrictWarningsError, exit status 3)")

    def __post_init__(self) -> None:
        check_options(self)


@dataclass(frozen=True)
class Estimate:
    """One identified parameter: its value, standard deviation and unit (JSON ``{value, std, unit}``).

    Parameters
    ----------
    name : str
        The parameter's name (``cornering_stiffness_front``, ...).
    value : float
        The estimate.
    std : float
        Its standard deviation.
    unit : str
        The unit of both.
    """

    name: str
    value: float
    std: float
    unit: str

    def as_dict(self) -> dict[str, Any]:
        """Describe the estimate for JSON.

        Returns
        -------
        dict
            ``{value, std, unit}``.
        """
        return {"value": self.value, "std": self.std, "unit": self.unit}


@dataclass(frozen=True, eq=False)
class SingleTrackIdentification:
    """The single-track model identified from a log: typed, frozen all the way down.

    It renders the JSON and text of `vehid identify --structure single-track`
    (the module docstring lists the keys).

    Attributes
    ----------
    model : IdentifiedSingleTrack
        The car's model: its configuration, parameters, their covariance (the jackknife's) and the speeds of
        the log; what ``save_model`` writes and `vehid handling` reads.
    estimator : GreyBoxResult
        The grey-box filter's run (passes, fits, the filter's covariance and correlation).
    schedule : str
        The speed channel.
    parameters : tuple of Estimate
        The physical parameters, then the sensor offsets, each with its standard deviation.
    handling : SingleTrackHandling
        Understeer gradient, characteristic or critical speed and yaw-rate gains, with standard deviations.
    estimation_fit_percent, validation_fit_percent : tuple of float or None
        NRMSE fit per output of the model simulated along the estimation runs and the held-out ones.
    uncertainty : UncertaintyMethod
        How the standard deviations were obtained.
    segments : SegmentConsistency or None
        The log's parts identified one by one and compared.
    notes, warnings : tuple of str
        Choices said once, and one line per problem (the plausibility findings among them).
    cleaning : FrozenDict
        The data's cleaning (JSON ``outliers``, ``left_out``, ...).
    seconds : float
        Run time of the identification.
    divergence : str or None
        How the filter diverged, where its last good pass is returned.
    plausibility : tuple of Finding
        The failed checks of the car's physics (each also a warning).
    output_names : tuple of str
        The outputs' channels.
    validated : bool
        Whether a part of the log was held out.
    model_file : Path or None
        The model file written.
    """

    model: IdentifiedSingleTrack
    estimator: GreyBoxResult = dataclasses.field(repr=False)
    schedule: str
    parameters: tuple[Estimate, ...]
    handling: SingleTrackHandling
    estimation_fit_percent: tuple[float, ...]
    validation_fit_percent: tuple[float, ...] | None
    uncertainty: UncertaintyMethod
    segments: SegmentConsistency | None
    notes: tuple[str, ...]
    warnings: tuple[str, ...]
    cleaning: FrozenDict
    seconds: float
    divergence: str | None
    plausibility: tuple[Finding, ...]
    output_names: tuple[str, ...]
    validated: bool
    model_file: Path | None = None

    def __post_init__(self) -> None:
        for name in ("parameters", "notes", "warnings", "plausibility", "output_names"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
        freeze_fields(self)  # the model and the filter's run too: the summary is rendered from them

    @property
    def config(self) -> SingleTrackConfig:
        """The car's configuration: mass, axle distances, the quantities measured, the model's options."""
        return self.model.config

    def render(self) -> dict[str, Any]:
        """Render the JSON summary of `vehid identify --structure single-track`.

        Returns
        -------
        dict
            The summary, as a fresh dict the caller may change.
        """
        config, result = self.config, self.estimator
        physical = {estimate.name: estimate.as_dict() for estimate in self.parameters[:config.n_physical]}
        offsets = {estimate.name: estimate.as_dict() for estimate in self.parameters[config.n_physical:]}
        names = config.parameter_names
        return thaw({
            "method": "iekf",
            "structure": "single-track",
            "physical_parameters": physical,
            **({"sensor_offsets": offsets} if offsets else {}),
            "parameter_correlation": result.correlation,
            "parameter_names": list(names),
            "handling": self.handling.as_dict(),
            "quantities": list(config.quantities),
            "schedule": self.schedule,
            "speed_range_m_s": list(self.model.speed_range),
            "fit_percent": result.nrmse_fit_percent,
            "R": result.fit_percent,
            "estimation_fit_percent": self.estimation_fit_percent,
            "validation_fit_percent": self.validation_fit_percent,
            "passes_run": result.passes_run,
            "stop_reason": result.stop_reason,
            "trace_p": result.trace_p,
            "measurement_noise": result.measurement_noise,
            "start": dict(zip(names, result.start.tolist())),
            "covariance_source": self.uncertainty.describe(),
            "uncertainty_method": self.uncertainty.as_dict(),
            "segments": None if self.segments is None else self.segments.as_dict(),
            "notes": list(self.notes),
            **self.cleaning,
            "seconds": self.seconds,
            **({"divergence": self.divergence} if self.divergence else {}),
            **({"model_file": str(self.model_file)} if self.model_file is not None else {}),
            "plausibility": [finding.as_dict() for finding in self.plausibility],
            "warnings": list(self.warnings),
        })

    def text(self) -> str:
        """Render what the command prints without ``--json``.

        Returns
        -------
        str
            The run, each parameter +/- 2 sigma, the handling, the parts of the log and the fits.
        """
        summary = self.render()
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
        lines += [f"  {line}" for line in ([] if self.segments is None else self.segments.text_lines())]
        for name, est, val in zip(self.output_names, summary["estimation_fit_percent"],
                                  summary["validation_fit_percent"] if self.validated else [None] * len(self.output_names)):
            lines.append(f"  NRMSE fit % {name:<15} estimation {est:7.2f}   validation "
                         f"{'-' if val is None else f'{val:.2f}'}")
        lines += [f"note: {note}" for note in summary["notes"]]
        return "\n".join(lines)


def _log(data: IOData | str | os.PathLike, reading: ReadSettings | None, speed: str, sideslip: str | None) -> IOData:
    """The raw log as the model reads it: inputs (steer, speed), outputs the measured quantities (and the measured
    sideslip last, where named). A file is read with ``reading`` (one input: the steer); a workbench record may
    keep the speed among its inputs or its outputs, and so may a record in memory."""
    from vehid.identification.dataio.preparation import ReadSettings, read_record

    if isinstance(data, IOData):
        raw = data
    else:
        settings = reading if reading is not None else ReadSettings()
        if len(settings.inputs) != 1:
            raise OptionError("the single-track structure takes one input, the steer angle (rad): give 'inputs' "
                              "CHANNEL", "inputs")
        outputs = settings.outputs + ((sideslip,) if sideslip else ())
        try:  # a text table's columns are all alike; a workbench record keeps its speed among its inputs or outputs
            return read_record(data, dataclasses.replace(settings, inputs=(settings.inputs[0], speed), outputs=outputs))
        except InputError:
            from vehid.identification.choices import HDF5_SUFFIXES

            if Path(data).suffix.lower() not in HDF5_SUFFIXES:
                raise  # the file's own problem (a column, a segment), not where the speed is kept
            try:
                raw = read_record(data, dataclasses.replace(settings, outputs=outputs + (speed,)))
            except InputError:
                raise OptionError(f"no channel {speed!r} (the speed, 'schedule') among the file's inputs or outputs",
                                  "schedule") from None
    if speed in raw.input_names:
        steer = [name for name in raw.input_names if name != speed]
        if len(steer) != 1:
            raise OptionError("the single-track structure takes one input, the steer angle (rad): give 'inputs' "
                              "CHANNEL", "inputs")
        record = raw.select_inputs((steer[0], speed))
    elif speed in raw.output_names:
        index = raw.output_names.index(speed)
        keep = [i for i in range(raw.n_y) if i != index]
        record = raw.replace(u=np.column_stack([raw.u, raw.y[:, index]]), y=raw.y[:, keep],
                             input_names=(*raw.input_names, speed),
                             output_names=tuple(raw.output_names[i] for i in keep),
                             input_units=(*raw.input_units, raw.output_units[index]),
                             output_units=tuple(raw.output_units[i] for i in keep))
        if record.n_u != 2:
            raise OptionError("the single-track structure takes one input, the steer angle (rad): give 'inputs' "
                              "CHANNEL", "inputs")
    else:
        raise OptionError(f"no channel {speed!r} (the speed, 'schedule') among the record's inputs or outputs",
                          "schedule")
    if sideslip and record.output_names[-1] != sideslip:  # a record in memory: the sideslip moved last
        if sideslip not in record.output_names:
            raise OptionError(f"no channel {sideslip!r} ('measured_sideslip') among the record's outputs",
                              "measured_sideslip")
        order = [name for name in record.output_names if name != sideslip] + [sideslip]
        record = record.select_outputs(order)
    return record


def _runs(record: IOData, speed: str, sideslip: str | None, *, validation: float | None, scale: Any,
          despike: bool, exclude: Any, min_speed: float | None, min_run_seconds: float
          ) -> tuple[tuple[IOData, ...], tuple[IOData, ...], tuple[np.ndarray, ...] | None]:
    """The runs of the raw log (steer, speed -> outputs) a moving car's model is identified from, times ``scale``,
    the runs of its held-out tail where asked (:func:`~vehid.identification.automatic.intake.clean_runs`), and
    the measured sideslip on each estimation run (None without it).

    The measured sideslip is read as one more output, so that the spikes, windows and slow parts the
    fitted channels lose are lost by it too; it is taken off the runs before they are returned."""
    from vehid.identification.automatic.intake import clean_runs
    from vehid.identification.data import check_channels
    from vehid.identification.dataio.preparation import parse_scale

    factors = parse_scale(scale)
    unknown = [name for name in factors if name not in record.input_names + record.output_names]
    if unknown:
        raise OptionError(f"'scale' names {unknown[0]!r}, which is not a chosen channel", "scale")
    # spikes found (and repaired where asked), the windows and the slow parts left out: each run of a moving car
    # its own record, the hold-out the last part of the samples kept
    cleaned = clean_runs([record], speeds=[record.u[:, 1]], speed_name=speed, speed_factor=factors.get(speed, 1.0),
                         min_speed=min_speed, min_run_seconds=min_run_seconds, despike=despike, exclude=exclude,
                         holdout=validation, speed_in_record=True)
    input_scale = [factors.get(n, 1.0) for n in record.input_names]
    output_scale = [factors.get(n, 1.0) for n in record.output_names]
    estimation, held = (tuple(part.replace(u=part.u * input_scale, y=part.y * output_scale) for part in parts)
                        for parts in (cleaned.estimation, cleaned.validation))
    measured_sideslip = None
    if sideslip:
        measured_sideslip = tuple(part.y[:, -1].copy() for part in estimation)
        estimation, held = (tuple(part.replace(y=part.y[:, :-1], output_names=part.output_names[:-1],
                                               output_units=part.output_units[:-1]) for part in parts)
                            for parts in (estimation, held))
    check_channels(tuple(IOData(t=part.t, u=part.u[:, :1], y=part.y, input_names=part.input_names[:1],
                                output_names=part.output_names) for part in estimation), detrend="none")
    slowest = min(float(np.min(part.u[:, 1])) for part in estimation + held)
    if slowest < 0:
        raise OptionError(f"the speed channel {speed!r} falls to {slowest:.3g}: the single-track model needs a car "
                          "moving forwards (m/s; 'min_speed' leaves the slow parts out)", "min_speed")
    return estimation, held, measured_sideslip


def identify_single_track(data: IOData | str | os.PathLike, *, schedule: str, config: SingleTrackConfig,
                          options: SingleTrackOptions = SingleTrackOptions(), reading: ReadSettings | None = None,
                          validation: float | None = None, despike: bool = False, exclude: Any = (),
                          min_speed: float | None = MIN_SPEED, min_run_seconds: float = MIN_RUN_SECONDS,
                          scale: Any = None, measured_sideslip: str | None = None,
                          save_model: str | os.PathLike | None = None,
                          force: bool = False) -> SingleTrackIdentification:
    """Identify a car's single-track model from its log (module docstring).

    Parameters
    ----------
    data : IOData or path
        The log: a file (read with ``reading``: one input, the steer angle, and the outputs ``config``
        names as its quantities), or a raw record whose inputs are the steer and the speed (a workbench
        record may keep the speed among its outputs).
    schedule : str
        The speed channel (m/s after ``scale``), read beside the inputs.
    config : SingleTrackConfig
        The car's mass and axle distances, what each output measures, the model's options.
    options : SingleTrackOptions
        The grey-box filter's settings, and ``strict``.
    reading : ReadSettings, optional
        How the file is read.
    validation : float, optional
        The fraction of the log's moving samples held out at its end.
    despike : bool
        Replace spikes and drop-outs by interpolation, as :func:`vehid.identification.identify` does.
    exclude : str, TimeWindow or a sequence of them
        Windows of time left out, as :func:`vehid.identification.identify` takes them.
    min_speed : float or None
        Only the samples at or above this speed (m/s), each run of them a record; None keeps every sample.
    min_run_seconds : float
        The shortest run kept.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Channel factors (a unit, a sign).
    measured_sideslip : str, optional
        A channel that measured the sideslip (rad, ISO 8855): the model's predicted sideslip is checked
        against it (JSON ``plausibility``), never fitted.
    save_model : path, optional
        Write the model to this ``.json`` file (checked before any work).
    force : bool
        Let ``save_model`` replace a file that is not a model file of the workbench.

    Returns
    -------
    SingleTrackIdentification
        The model, its parameters with standard deviations, the handling and the fits.

    Raises
    ------
    InputError
        Bad data or settings (before any work where they can be seen then).
    StrictWarningsError
        With ``options.strict``, where the run ends with warnings (carrying the summary and text).

    Examples
    --------
    Ten seconds of a car at 20 m/s simulated by the model itself (cornering stiffnesses 80 and
    100 kN/rad, yaw inertia 2500 kg m^2), and its parameters identified from the log:

    >>> import numpy as np
    >>> from vehid.identification import IOData, simulate_greybox
    >>> from vehid.scenarios import identify_single_track
    >>> from vehid.vehicle.single_track import SingleTrackConfig, single_track_model
    >>> car = SingleTrackConfig(mass=1500.0, cg_to_front_axle=1.2, cg_to_rear_axle=1.5)
    >>> steer = 0.02 * np.convolve(np.random.default_rng(1).standard_normal(1000), np.ones(10) / 10, "same")
    >>> drive = IOData(t=np.arange(1000) * 0.01, u=np.column_stack([steer, np.full(1000, 20.0)]),
    ...                y=np.zeros((1000, 2)), input_names=("steer", "speed"),
    ...                output_names=("yaw_rate", "lateral_acceleration"))
    >>> y, _ = simulate_greybox(single_track_model(car), [80_000.0, 100_000.0, 2500.0], drive)
    >>> result = identify_single_track(drive.replace(y=y), schedule="speed", config=car)
    >>> [(estimate.name, round(estimate.value)) for estimate in result.parameters]
    [('cornering_stiffness_front', 80000), ('cornering_stiffness_rear', 100000), ('yaw_inertia', 2500)]
    >>> round(result.handling.understeer_gradient.value, 2)  # m/L (l_r/C_f - l_f/C_r) g, in deg/g
    2.11
    """
    from vehid.identification.automatic.scoring import Evaluation, last_good_on_divergence, run_warnings
    from vehid.identification.dataio.cleaning import cleaning_notes, cleaning_summary, cleaning_warnings
    from vehid.identification.dataio.model_files import check_model_target
    from vehid.identification.dataio.model_files import save_model as write_model
    from vehid.identification.filtering.greybox import GreyBoxOptions
    from vehid.identification.filtering.greybox_structure import simulate_greybox
    from vehid.scenarios import plausibility_checks as plausibility
    from vehid.vehicle.single_track import GRAVITY, IdentifiedSingleTrack, single_track_handling, single_track_model

    started = time.perf_counter()
    if not isinstance(data, (IOData, str, os.PathLike)):
        raise InputError("the single-track structure identifies from one record or data file")
    if validation is not None and (isinstance(validation, bool) or not 0 < validation < 1):
        raise OptionError(f"'validation' takes a fraction between 0 and 1; got {validation}", "validation")
    speed = schedule.strip()
    sideslip = (measured_sideslip or "").strip() or None
    if save_model is not None:  # before the file is read: a bad target costs nothing
        if Path(save_model).suffix.lower() != ".json":
            raise OptionError(f"a single-track model is saved as .json; got {str(save_model)!r}", "save_model")
        check_model_target(save_model, inputs=[] if isinstance(data, IOData) else [data], force=force)
    record = _log(data, reading, speed, sideslip)
    if len(config.quantities) != record.n_y - (1 if sideslip else 0):
        raise OptionError(f"'quantities' names {len(config.quantities)} quantities for "
                          f"{record.n_y - (1 if sideslip else 0)} 'outputs' channels: name what each output "
                          "measures, in order", "quantities", "outputs")
    estimation, held, sideslip_runs = _runs(record, speed, sideslip, validation=validation, scale=scale,
                                            despike=despike, exclude=exclude, min_speed=min_speed,
                                            min_run_seconds=min_run_seconds)
    model = single_track_model(config)
    substeps = _substeps(config, *estimation, *held)
    filter_options = GreyBoxOptions(substeps=substeps, **({"p": options.p} if options.p is not None else {}),
                                    **({"passes": options.passes} if options.passes is not None else {}))

    fit = functools.partial(fit_log, config, options=filter_options)
    result, divergence = last_good_on_divergence(lambda: fit(estimation))
    # the filter's covariance pass takes the innovations as white; the fit's block jackknife measures the spread
    covariance, uncertainty = single_track_segments.honest_covariance(model, result, estimation)
    consistency = single_track_segments.part_consistency(config, model, estimation, fit)

    names, units = config.parameter_names, model.parameter_units
    std = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    estimates = tuple(Estimate(name, float(value), float(s), unit)
                      for name, value, s, unit in zip(names, result.parameters, std, units))
    speeds = np.concatenate([record.u[:, 1] for record in estimation])
    speed_range = (float(np.min(speeds)), float(np.max(speeds)))
    grid = sorted({float(v) for v in np.round(np.linspace(speeds.min(), speeds.max(), 3))})
    handling = single_track_handling(config, result.parameters, covariance, speeds=grid)

    def fit_on(records: tuple[IOData, ...]) -> np.ndarray:
        """NRMSE fit over the runs, each simulated from its start (pooled: the runs as one series)."""
        simulated = [simulate_greybox(model, result.parameters, record, substeps=filter_options.substeps)[0]
                     for record in records]
        return nrmse_fit(np.vstack([record.y for record in records]), np.vstack(simulated))

    estimation_fit = fit_on(estimation)
    validation_fit = fit_on(held) if held else None
    notes = ["signals taken as recorded (no offsets removed): a physical model has no operating point",
             *cleaning_notes(estimation)]
    warnings = run_warnings(
        model=None, evaluation=Evaluation(
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
    for estimate in estimates[: config.n_physical]:  # an offset may be ~0
        if not estimate.std < abs(estimate.value):
            warnings.append(f"{estimate.name} is not determined by the log (std {estimate.std:.3g} against "
                            f"{estimate.value:.3g})")
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
        warnings.extend(_friction_warnings(config, result.parameters, estimation, held))
    if consistency is not None and not consistency.consistent:
        warnings.append(consistency.warning("the single-track model"))
    identified = IdentifiedSingleTrack(
        config, result.parameters, covariance, speed_range,
        {"data": [str(data.meta.get("source", "record")) if isinstance(data, IOData) else str(data)],
         "schedule": speed,
         "validation_fit_percent": None if validation_fit is None else [float(f) for f in validation_fit],
         "uncertainty_method": uncertainty.as_dict()})
    seconds = time.perf_counter() - started
    model_file = None if save_model is None else write_model(identified, save_model, None)
    findings = plausibility.single_track_findings(
        IdentifiedSingleTrack(config, result.parameters, None, speed_range), estimation,
        plausibility.single_track_sideslip(config, result.parameters, estimation, sideslip_runs,
                                           filter_options.substeps))
    outcome = SingleTrackIdentification(
        model=identified, estimator=result, schedule=speed, parameters=estimates, handling=handling,
        estimation_fit_percent=tuple(float(f) for f in estimation_fit),
        validation_fit_percent=None if validation_fit is None else tuple(float(f) for f in validation_fit),
        uncertainty=uncertainty, segments=consistency, notes=tuple(notes),
        warnings=tuple(warnings) + tuple(finding.warning() for finding in findings), cleaning=cleaning_summary(estimation),
        seconds=seconds, divergence=divergence, plausibility=findings, output_names=estimation[0].output_names,
        validated=bool(held), model_file=model_file)
    if options.strict and outcome.warnings:
        error = StrictWarningsError(list(outcome.warnings), outcome.render(), outcome.text())
        error.result = outcome
        raise error
    return outcome


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
