"""The scheduling channel of `vehid identify --schedule CHANNEL`: read beside the inputs, kept apart.

The channel (a car's speed) is read with the record's inputs, scaled by ``--scale`` where one names it
and never offset: a scheduled model's coefficients are functions of its measured value. The command's
plan (:mod:`vehid.scenarios.commands.identify`) reads it here; the scheduled identification
(:mod:`vehid.identification.automatic.scheduled`) uses what the plan holds.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.automatic.plan import ScheduleData
from vehid.identification.automatic.scheduled import scheduled_records
from vehid.identification.errors import InputError

__all__ = ["ScheduleData", "parse_schedule_grid", "check_options", "read_with_schedule", "schedule_factor",
           "schedule_loader",
           "scheduled_records"]


def parse_schedule_grid(text: str | None) -> tuple[float, ...] | None:
    if text is None:
        return None
    try:
        values = tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise InputError(f"--schedule-grid takes comma-separated numbers; got {text!r}") from None
    return values


def check_options(args: Any) -> None:
    """Refuse combinations the scheduled model does not support, before any work.

    The family's own settings (knots, grid, p) are checked where they are declared, in
    :class:`~vehid.identification.automatic.options.IdentifyOptions`.
    """
    if args.resume:
        raise InputError("--schedule runs are not checkpointed: give no --resume")
    if len(args.data) > 1:
        raise InputError("--schedule identifies the scheduled model from one record; give one data file")
    if not args.inputs:
        raise InputError("--schedule needs --inputs naming the inputs (the schedule is read beside them)")


def _without_schedule(args: Any) -> dict[str, float]:
    from vehid.identification.dataio.preparation import parse_scale

    return {name: factor for name, factor in parse_scale(args.scale).items() if name != args.schedule}


def read_with_schedule(args: Any, paths: Sequence[str]) -> tuple[tuple[IOData, ...], Any, list[np.ndarray], dict, str]:
    """Raw records without the schedule, their reading settings, each record's schedule as read (its
    ``--scale`` factor is :func:`schedule_factor`'s), the ``--scale`` factors of the other channels and the
    schedule's unit ("-" where unknown or scaled)."""
    from vehid.identification.dataio.preparation import read_raw_records
    from vehid.scenarios.data_options import settings_from_args

    check_options(args)
    settings = settings_from_args(args)
    channel = args.schedule.strip()
    if channel in settings.inputs or channel in settings.outputs:
        raise InputError(f"--schedule {channel} is also named among --inputs or --outputs: the schedule is a "
                         "channel of its own")
    raw, full_settings = read_raw_records(list(paths), dataclasses.replace(settings, inputs=settings.inputs + (channel,)))
    schedules = [record.u[:, -1] for record in raw]
    inputs = full_settings.inputs[:-1]
    unit = raw[0].input_units[-1] if schedule_factor(args) == 1.0 else "-"  # a scaled channel's unit is the user's to name
    return (tuple(record.select_inputs(inputs) for record in raw), dataclasses.replace(full_settings, inputs=inputs),
            schedules, _without_schedule(args), unit)


def schedule_factor(args: Any) -> float:
    """The ``--scale`` factor of the schedule channel (1 where none names it)."""
    from vehid.identification.dataio.preparation import parse_scale

    return parse_scale(args.scale).get(args.schedule.strip(), 1.0)


def schedule_loader(args: Any, preparation: Any, channels: Any, found: list[np.ndarray]):
    """A validation-file loader that also reads the file's schedule (appended to ``found``, in order)."""
    from vehid.identification.dataio.preparation import prepare_validation, read_record

    channel = args.schedule.strip()
    factor = schedule_factor(args)

    def load(path: str) -> IOData:
        inputs, outputs = channels if channels is not None else (preparation.settings.inputs, preparation.settings.outputs)
        settings = dataclasses.replace(preparation.settings, inputs=tuple(inputs) + (channel,),
                                       outputs=tuple(outputs), segment=None)
        raw = read_record(path, settings)
        found.append(raw.u[:, -1] * factor)
        raw = raw.select_inputs(tuple(inputs)).replace(input_names=preparation.input_names,
                                                       output_names=preparation.output_names)
        return prepare_validation(raw, preparation, own_offsets=True)

    return load
