"""The plan of one identification from what its caller gives: records in memory or files, cleaned, cut, prepared.

:func:`identify <vehid.identification.pipeline.identify>` (and through it `vehid identify`) builds
every plan here, whether the records come from files or from memory:

1. The records are read (files with :class:`~vehid.identification.dataio.preparation.ReadSettings`),
   with a schedule channel beside the inputs where one is named (a car's speed: kept apart, times
   its ``scale`` factor, never offset).
2. Each is cleaned and cut (:func:`clean_runs`): spikes and drop-outs found in every channel and
   replaced where asked (``despike``), the ``exclude`` windows left out, the samples whose speed is
   below ``min_speed`` left out (runs shorter than ``min_run_seconds`` dropped); each contiguous run
   of what is left is its own record, and the held-out fraction is the last part of each.
3. The estimation runs are prepared (offsets, scale factors, steering ratio), the held-out parts
   alike with their record's offsets, and the validation records or files with their own offsets
   (:func:`~vehid.identification.automatic.plan.make_plan`).
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any, Mapping, Sequence

import numpy as np

from vehid.identification.automatic.plan import Plan, ScheduleData, holdout_fraction, make_plan
from vehid.identification.data import IOData
from vehid.identification.dataio.cleaning import MIN_RUN_SAMPLES, CleanedRecords
from vehid.identification.errors import InputError, OptionError

__all__ = ["LEFT_OUT_SLOW", "Source", "is_source_path", "split_validation", "clean_runs", "plan_run"]

#: The key of ``left_out`` counting samples below the least speed.
LEFT_OUT_SLOW = "below_min_speed"

#: A record in memory or a file it is read from.
Source = IOData | str | os.PathLike


def is_source_path(value: Any) -> bool:
    """Whether ``value`` names a file (text or a path), not a record or a number."""
    return isinstance(value, (str, os.PathLike))


def _sources(value: Any) -> tuple[Source, ...]:
    """The data: one source or a sequence of them, as a tuple, refused where any is neither a record nor a path."""
    items = (value,) if isinstance(value, IOData) or is_source_path(value) else tuple(value)
    if not items or not all(isinstance(item, IOData) or is_source_path(item) for item in items):
        raise InputError("identify takes an IOData record, a data file, or a sequence of either")
    return items


def split_validation(validation: Any) -> tuple[float | None, tuple[Source, ...]]:
    """The fraction held out of each record and the validation records or files of ``validation``.

    A number is the fraction; a record or a file one validation source; a sequence may hold
    both, a fraction at most once.
    """
    if validation is None:
        return None, ()
    if isinstance(validation, (int, float)) and not isinstance(validation, bool):
        return float(validation), ()
    items = (validation,) if isinstance(validation, IOData) or is_source_path(validation) else tuple(validation)
    fractions = [item for item in items if isinstance(item, (int, float)) and not isinstance(item, bool)]
    sources = tuple(item for item in items if not isinstance(item, (int, float)) or isinstance(item, bool))
    if len(fractions) > 1 or not all(isinstance(item, IOData) or is_source_path(item) for item in sources):
        raise OptionError("'validation' takes a fraction held out, validation records or files, or a sequence of "
                          "records and files with at most one fraction", "validation")
    return (float(fractions[0]) if fractions else None), sources


def clean_runs(records: Sequence[IOData], *, speeds: Sequence[np.ndarray] | None = None,
               speed_name: str | None = None, speed_factor: float = 1.0, min_speed: float | None = None,
               min_run_seconds: float = 0.0, despike: bool = False, exclude: Any = (),
               holdout: float | None = None, speed_in_record: bool = False) -> CleanedRecords:
    """Each record cleaned and cut into runs (module docstring), the runs of all records in order.

    Parameters
    ----------
    records : sequence of IOData
        As read, in the file's units.
    speeds : sequence of ndarray, optional
        The speed (or scheduling) channel of each record, as read.
    speed_name : str, optional
        Its name, for the outliers list.
    speed_factor : float
        Its ``scale`` factor to m/s; the runs' speeds (``extra_estimation`` and ``extra_validation``
        under ``speed_name``) are returned scaled.
    min_speed : float, optional
        Samples below it are left out (counted as :data:`LEFT_OUT_SLOW`); runs shorter than
        ``min_run_seconds`` (and :data:`~vehid.identification.dataio.cleaning.MIN_RUN_SAMPLES`) are dropped.
    min_run_seconds : float
        The shortest run kept where ``min_speed`` cuts the records.
    despike : bool
        Replace the spikes and drop-outs found by interpolation.
    exclude : str, TimeWindow or a sequence of them
        Windows left out (``"T0:T1"`` file time, ``"+T0:+T1"`` from the record's first sample).
    holdout : float, optional
        The fraction of each record's kept samples held out, at its end.
    speed_in_record : bool
        The speed is one of the records' own channels (searched and cut with them), not a channel beside
        them: no runs' speeds are returned.
    """
    from vehid.identification.dataio import cleaning
    from vehid.identification.dataio.timewindow import parse_time_windows

    keeps = None
    if min_speed is not None:
        if speeds is None:
            raise OptionError("'min_speed' needs the speed channel: give 'schedule' CHANNEL", "min_speed", "schedule")
        keeps = []
        for record, speed in zip(records, speeds):
            scaled = np.asarray(speed, dtype=float) * speed_factor
            if not np.any(scaled >= min_speed):
                raise OptionError(f"{record.meta.get('source', 'the record')}: the speed channel {speed_name!r} never "
                                  f"reaches 'min_speed' {min_speed:g} (it runs from {scaled.min():.4g} to "
                                  f"{scaled.max():.4g}): is it in m/s, forwards positive? (convert with 'scale')",
                                  "min_speed", "scale")
            keeps.append(scaled >= min_speed)
    beside = speeds is not None and not speed_in_record
    name = speed_name or "speed"
    cleaned = cleaning.clean_records(
        records, extras=[{name: speed} for speed in speeds] if beside else None, keeps=keeps,
        min_run_samples=[max(MIN_RUN_SAMPLES, math.ceil(min_run_seconds / record.dt)) if keeps else MIN_RUN_SAMPLES
                         for record in records],
        despike_outliers=bool(despike), exclude=parse_time_windows(exclude), left_out_as=LEFT_OUT_SLOW,
        holdout=holdout)
    if not beside:
        return cleaned
    return dataclasses.replace(cleaned, **{f"extra_{side}": {name: tuple(part * speed_factor for part in parts[name])}
                                           for side, parts in (("estimation", cleaned.extra_estimation),
                                                               ("validation", cleaned.extra_validation))})


def _read_files(paths: Sequence[Source], reading: Any, schedule: str | None
                ) -> tuple[tuple[IOData, ...], Any, list[np.ndarray] | None, str]:
    """The raw records of files, the settings that read them, each record's schedule (read beside the inputs)
    and its unit as read."""
    from vehid.identification.dataio.preparation import ReadSettings, read_raw_records

    if len(set(map(str, paths))) != len(paths):
        raise InputError("a data file is named twice")
    settings = reading if reading is not None else ReadSettings()
    if schedule is None:
        raw, settings = read_raw_records(list(paths), settings)
        return raw, settings, None, "-"
    if not settings.inputs:
        raise OptionError("'schedule' needs 'inputs' naming the inputs (the schedule is read beside them)",
                          "schedule", "inputs")
    if schedule in settings.inputs or schedule in settings.outputs:
        raise OptionError(f"'schedule' {schedule} is also named among 'inputs' or 'outputs': the schedule is a "
                          "channel of its own", "schedule", "inputs", "outputs")
    raw, full = read_raw_records(list(paths), dataclasses.replace(settings, inputs=settings.inputs + (schedule,)))
    inputs = full.inputs[:-1]
    return (tuple(record.select_inputs(inputs) for record in raw), dataclasses.replace(full, inputs=inputs),
            [record.u[:, -1] for record in raw], raw[0].input_units[-1])


def _schedule_input(records: Sequence[IOData], schedule: str) -> tuple[tuple[IOData, ...], list[np.ndarray], str]:
    """Records in memory with their input ``schedule`` taken out as the schedule, and its unit."""
    if any(schedule not in record.input_names for record in records):
        raise OptionError(f"'schedule' {schedule!r} is not an input of the record (inputs: "
                          f"{', '.join(records[0].input_names)})", "schedule")
    index = records[0].input_names.index(schedule)
    others = tuple(name for name in records[0].input_names if name != schedule)
    return (tuple(record.select_inputs(others) for record in records),
            [record.u[:, index] for record in records], records[0].input_units[index])


def _validation_loader(preparation: Any, channels: Any, schedule: str | None, factor: float,
                       found: list[np.ndarray]) -> Any:
    """What turns a validation source into a prepared record: a record in memory or a file (with its own
    offsets, as a separate experiment's), its schedule appended to ``found`` where a channel is named."""
    from vehid.identification.dataio.preparation import prepare_validation, read_record

    def load(source: Source) -> IOData:
        if schedule is None:
            return prepare_validation(source, preparation, own_offsets=True, channels=channels)
        if isinstance(source, IOData):
            (record,), (values,), _ = _schedule_input([source], schedule)
            found.append(values * factor)
            return prepare_validation(record, preparation, own_offsets=True)
        inputs, outputs = channels if channels is not None else (preparation.settings.inputs,
                                                                 preparation.settings.outputs)
        settings = dataclasses.replace(preparation.settings, inputs=tuple(inputs) + (schedule,),
                                       outputs=tuple(outputs), segment=None)
        raw = read_record(source, settings)
        found.append(raw.u[:, -1] * factor)
        raw = raw.select_inputs(tuple(inputs)).replace(input_names=preparation.input_names,
                                                       output_names=preparation.output_names)
        return prepare_validation(raw, preparation, own_offsets=True)

    return load


def _source_name(source: Source, index: int) -> str:
    """How a validation source is named: a file by its path, a record by its source."""
    if isinstance(source, IOData):
        return str(source.meta.get("source", f"validation record {index + 1}"))
    return str(source)


def plan_run(data: Any, *, order: int | str, validation: Any = None, detrend: str = "mean",
             schedule: Any = None, schedule_channel: str = "schedule", despike: bool = False, exclude: Any = (),
             min_speed: float | None = None, min_run_seconds: float = 0.0, reading: Any = None,
             scale: Mapping[str, float] | Sequence[str] | None = None, steering_ratio: Any = None,
             validation_inputs: Sequence[str] | None = None, validation_outputs: Sequence[str] | None = None) -> Plan:
    """The plan of one run (module docstring); the keywords are those of
    :func:`~vehid.identification.pipeline.identify`.

    The split comes before the preparation, so the offsets kept with the model are the
    estimation part's own (the held-out part plays no role in them).
    """
    from vehid.identification.dataio.preparation import parse_scale, prepare, prepare_validation

    sources = _sources(data)
    fraction, extra = split_validation(validation)
    fraction, note = holdout_fraction(order, fraction, bool(extra))
    files = [is_source_path(source) for source in sources]
    if any(files) and not all(files):
        raise InputError("identify takes records or data files, not both")
    factors = parse_scale(scale)
    channel = schedule.strip() if isinstance(schedule, str) else (schedule_channel if schedule is not None else None)
    schedules, unit, settings = None, "-", None
    if isinstance(schedule, str) and len(sources) > 1:
        raise OptionError("'schedule' identifies the scheduled model from one record; give one data file", "schedule")
    if all(files):
        raw, settings, schedules, unit = _read_files(sources, reading, channel if isinstance(schedule, str) else None)
    else:
        if reading is not None:
            raise InputError("the reading settings read files; these data are records in memory")
        raw = tuple(sources)
        if isinstance(schedule, str):
            raw, schedules, unit = _schedule_input(raw, channel)
    if schedule is not None and not isinstance(schedule, str):  # the samples themselves
        samples = np.asarray(schedule, dtype=float)
        if len(raw) != 1 or extra:
            raise OptionError("'schedule' samples belong to one record, validated on a fraction of it (name the "
                              "channel instead to read it from validation records too)", "schedule")
        if samples.shape != (raw[0].n_samples,) or not np.all(np.isfinite(samples)):
            raise OptionError(f"'schedule' must hold one finite value per sample ({raw[0].n_samples}); "
                              f"got shape {samples.shape}", "schedule")
        schedules = [samples]
    factor = factors.pop(channel, 1.0) if channel is not None and schedules is not None else 1.0
    if factor != 1.0:
        unit = "-"  # a scaled channel's unit is the caller's to name
    # spikes found (and repaired where asked), the windows and a standing car left out, the hold-out cut: each
    # run of what is left is its own record
    cleaned = clean_runs(raw, speeds=schedules, speed_name=channel, speed_factor=factor, min_speed=min_speed,
                         min_run_seconds=min_run_seconds, despike=despike, exclude=exclude, holdout=fraction)
    records, preparation = prepare(cleaned.estimation, detrend=detrend, scale=factors, settings=settings,
                                   steering_ratio=steering_ratio)
    held = tuple(prepare_validation(part, preparation, record=i)
                 for i, part in zip(cleaned.validation_follows, cleaned.validation))
    channels = None
    if validation_inputs is not None or validation_outputs is not None:  # the validation files' own names
        settings = preparation.settings
        if settings is None:
            raise OptionError("'validation_inputs' and 'validation_outputs' name the channels of validation files; "
                              "these data are records in memory", "validation_inputs", "validation_outputs")
        channels = (tuple(validation_inputs) if validation_inputs is not None else settings.inputs,
                    tuple(validation_outputs) if validation_outputs is not None else settings.outputs)
    found: list[np.ndarray] = []  # the schedule of each validation source, as the loader reads it
    load = _validation_loader(preparation, channels, channel if schedules is not None and extra else None,
                              factor, found)
    plan = make_plan(records, order=order, validation=[(_source_name(s, i), s) for i, s in enumerate(extra)],
                     load=load, held_out=held, fraction=fraction, note=note, preparation=preparation)
    if schedules is None:
        return plan
    return dataclasses.replace(plan, schedule=ScheduleData(
        channel, cleaned.extra_estimation[channel], cleaned.extra_validation[channel] + tuple(found), unit))
