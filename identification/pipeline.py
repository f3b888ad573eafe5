"""`vehid identify` from Python: the automatic pipeline on records in memory.

:func:`identify` runs the steps of the command (p by cross-validation, the
open-loop-unstable treatment, start or filter, order search, hold-out
scoring, warnings, the spline-nonlinear model, the speed-scheduled family)
on :class:`IOData` records and returns a typed :class:`Identification`. It
writes no file and prints nothing: its warnings come back in the result.

The pipeline's parts live in :mod:`vehid.identification.automatic`:
``options`` (the settings, checked once), ``plan`` (records and orders),
``steps`` (tuning, decisions, scores, warnings), ``checks`` (model and data
checks), ``scheduled`` (the speed-scheduled variant), ``run`` (the run on a
plan, with checkpoints for a caller that keeps it on disk) and ``result``
(the typed result and its JSON summary).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Sequence

from vehid.identification.automatic.options import (DEFAULT_NODES, DEFAULT_NONLINEAR_PASSES, DEFAULT_PASSES,
                                                    MIN_PASSES, IdentifyOptions)
from vehid.identification.automatic.result import Decision, Identification, OrderRow
from vehid.identification.data import IOData
from vehid.identification.errors import InputError, StrictWarningsError

__all__ = ["DEFAULT_PASSES", "MIN_PASSES", "DEFAULT_NONLINEAR_PASSES", "DEFAULT_NODES", "IdentifyOptions",
           "OrderRow", "Decision", "Identification", "identify"]


def identify(data: IOData | Sequence[IOData], *, order: int | str = 4,
             validation: float | IOData | Sequence[IOData] | None = None,
             options: IdentifyOptions = IdentifyOptions(), schedule: Any = None,
             schedule_channel: str = "schedule", despike: bool = False, exclude: Any = (),
             min_speed: float | None = None) -> Identification:
    """Identify a modal model from raw records as `vehid identify` does.

    Parameters
    ----------
    data : IOData or sequence of IOData
        The estimation record(s), raw (offsets are removed here, as by the command).
    order : int or str
        A model order, a range such as ``"2-8"`` or ``"auto"``.
    validation : float, IOData, sequence of IOData or None
        A fraction of each record held out at its end, or validation records
        (prepared with the estimation records' scale factors and their own offsets).
    options : IdentifyOptions
        The pipeline's settings.
    schedule : array_like or None
        The schedule channel's samples (a speed, say), one per sample of the one estimation record:
        a speed-scheduled family is started from the model identified and returned where it
        validates better (``result.scheduled``). Validation then takes a fraction, whose
        schedule is the tail of this one.
    schedule_channel : str
        The schedule channel's name (in the family's grid and the summary).
    despike : bool
        Replace the spikes and drop-outs found in every channel by interpolation (they are listed in
        the summary's ``outliers`` either way; :mod:`~vehid.identification.dataio.cleaning`).
    exclude : str, TimeWindow or a sequence of them
        Windows of time left out (``"T0:T1"`` file time, ``"+T0:+T1"`` from the record's first
        sample); the parts around them are records of their own.
    min_speed : float, optional
        With a schedule (a speed): only the samples where it is at least this, each run of them a
        record of its own.

    Returns
    -------
    Identification
        The model returned, its scores, decisions with margins, warnings and order rows.

    Raises
    ------
    InputError
        Bad data or settings (the command's exit status 2).
    StrictWarningsError
        With ``options.strict``, where the run ends with warnings.
    """
    import numpy as np

    from vehid.identification.automatic.plan import ScheduleData, holdout_fraction, make_plan
    from vehid.identification.automatic.run import identify_plan
    from vehid.identification.blas import one_blas_thread
    from vehid.identification.dataio.cleaning import MIN_RUN_SAMPLES, clean_records
    from vehid.identification.dataio.preparation import prepare, prepare_validation
    from vehid.identification.dataio.timewindow import parse_time_windows

    raw = (data,) if isinstance(data, IOData) else tuple(data)
    if not raw or not all(isinstance(record, IOData) for record in raw):
        raise InputError("identify takes an IOData record or a sequence of them")
    extra: tuple[IOData, ...] = ()
    fraction = None
    if isinstance(validation, IOData):
        extra = (validation,)
    elif validation is not None and not isinstance(validation, (int, float)):
        extra = tuple(validation)
        if not all(isinstance(record, IOData) for record in extra):
            raise InputError("validation takes a fraction, an IOData record or a sequence of them")
    elif validation is not None:
        fraction = float(validation)
    fraction, note = holdout_fraction(order, fraction, bool(extra))
    schedule_samples = None
    if schedule is not None:
        schedule_samples = np.asarray(schedule, dtype=float)
        if len(raw) != 1 or extra:
            raise InputError("a schedule identifies from one record, validated on a fraction of it")
        if schedule_samples.shape != (raw[0].n_samples,) or not np.all(np.isfinite(schedule_samples)):
            raise InputError(f"schedule must hold one finite value per sample ({raw[0].n_samples}); "
                             f"got shape {schedule_samples.shape}")
    if min_speed is not None and schedule_samples is None:
        raise InputError("min_speed needs the speed: give schedule")
    # spikes found (repaired where asked), windows and slow samples left out, the hold-out cut: runs as records
    cleaned = clean_records(raw, extras=None if schedule_samples is None else [{schedule_channel: schedule_samples}],
                            keeps=None if min_speed is None else [schedule_samples >= min_speed],
                            min_run_samples=MIN_RUN_SAMPLES, despike_outliers=despike,
                            exclude=parse_time_windows(exclude), holdout=fraction)
    records, preparation = prepare(cleaned.estimation, detrend=options.detrend)
    held = tuple(prepare_validation(part, preparation, record=i)
                 for i, part in zip(cleaned.validation_follows, cleaned.validation))
    # each named by its source, as the command names validation files by their paths
    named = tuple((str(record.meta.get("source", f"validation record {i + 1}")), record)
                  for i, record in enumerate(extra))
    plan = make_plan(records, order=order, validation=named,
                     load=lambda record: prepare_validation(record, preparation, own_offsets=True),
                     held_out=held, fraction=fraction, note=note, preparation=preparation)
    if schedule_samples is not None:
        plan = dataclasses.replace(plan, schedule=ScheduleData(
            schedule_channel, cleaned.extra_estimation[schedule_channel], cleaned.extra_validation[schedule_channel]))
    with one_blas_thread():
        result = identify_plan(plan, options)
    if options.strict and result.warnings:
        raise StrictWarningsError(list(result.warnings), result.render())
    return result
