"""`vehid identify` from Python: the automatic pipeline, which the command itself runs.

:func:`identify` runs the steps of the command (p by cross-validation, the
open-loop-unstable treatment, start or filter, order search, hold-out
scoring, warnings, the spline-nonlinear model, the speed-scheduled family)
on records in memory or on files, and returns a typed, frozen
:class:`Identification` that renders the command's JSON summary and text.
It prints nothing: its warnings come back in the result. With ``out`` it
keeps the run in an HDF5 archive as it goes, and ``resume`` goes on with such
a run; ``save_model`` writes the model returned.

The pipeline's parts live in :mod:`vehid.identification.automatic`:
``options`` (the settings, checked once), ``intake`` (records and files to a
plan), ``plan`` (records and orders), ``scoring`` (scores and warnings),
``refinement``, ``tuning`` (p and Q schedule), ``returned`` (the filter's
model or its start), ``orders`` (the order search), ``nonlinear`` (the
spline model), ``iekf_order`` (one order's run), ``reported_checks`` (model
and data checks), ``scheduled`` (the speed-scheduled variant), ``run`` (the
run on a plan, with checkpoints),
``archiving`` (the run kept on disk), ``result`` (the typed result and its
JSON summary) and ``text`` (its text).
"""

from __future__ import annotations

import dataclasses
import os
from contextlib import nullcontext
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from vehid.identification.automatic.options import (DEFAULT_NODES, DEFAULT_NONLINEAR_PASSES, DEFAULT_PASSES,
                                                    MIN_PASSES, IdentifyOptions, Resume)
from vehid.identification.automatic.result import Decision, Finding, Identification, OrderRow
from vehid.identification.data import IOData
from vehid.identification.errors import InputError, OptionError, StrictWarningsError

if TYPE_CHECKING:
    from vehid.identification.automatic.archiving import ProgressDisplay
    from vehid.identification.automatic.plan import Plan
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.identification.models.protocol import IdentifiedModel

__all__ = ["DEFAULT_PASSES", "MIN_PASSES", "DEFAULT_NONLINEAR_PASSES", "DEFAULT_NODES", "IdentifyOptions", "Resume",
           "OrderRow", "Decision", "Identification", "identify"]

#: What a caller's ``checks`` is: the returned model and the run's plan in, the failed checks out (None: the
#: checks do not apply to this model).
ModelChecks = Callable[["IdentifiedModel", "Plan"], "Sequence[Finding] | None"]


def identify(data: IOData | str | os.PathLike | Sequence[IOData | str | os.PathLike] | None = None, *,
             order: int | str = 4, validation: Any = None, options: IdentifyOptions = IdentifyOptions(),
             schedule: str | Sequence[float] | None = None, schedule_channel: str = "schedule",
             despike: bool = False, exclude: Any = (), min_speed: float | None = None, min_run_seconds: float = 0.0,
             reading: ReadSettings | None = None, scale: Mapping[str, float] | Sequence[str] | None = None,
             steering_ratio: Any = None, validation_inputs: Sequence[str] | None = None,
             validation_outputs: Sequence[str] | None = None, out: str | os.PathLike | None = None,
             resume: str | os.PathLike | Resume | None = None, save_model: str | os.PathLike | None = None,
             force: bool = False, checks: ModelChecks | None = None,
             progress: Callable[[int, str], ProgressDisplay] | None = None) -> Identification:
    """Identify a modal model from raw records or files as `vehid identify` does.

    Parameters
    ----------
    data : IOData, path or a sequence of either
        The estimation record(s), raw (offsets are removed here, as by the command), or the files
        they are read from with ``reading``. None with ``resume``.
    order : int or str
        A model order, a range such as ``"2-8"`` or ``"auto"``.
    validation : float, IOData, path, or a sequence of records and paths with at most one float
        A fraction of each record held out at its end, and validation records or files (prepared
        with the estimation records' scale factors and their own offsets).
    options : IdentifyOptions
        The pipeline's settings.
    schedule : str or array_like, optional
        The schedule channel (a speed, say): a speed-scheduled family is started from the model
        identified and returned where it validates better (``result.scheduled``). A name is a
        channel read beside the inputs of the files (or taken from the inputs of the records, and of
        validation records alike); samples, one per sample of the one estimation record, are
        validated on a fraction of it. Never offset; times its ``scale`` factor.
    schedule_channel : str
        The name of schedule samples (in the family's grid and the summary).
    despike : bool
        Replace the spikes and drop-outs found in every channel by interpolation (they are listed in
        the summary's ``outliers`` either way; :mod:`~vehid.identification.dataio.cleaning`).
    exclude : str, TimeWindow or a sequence of them
        Windows of time left out (``"T0:T1"`` file time, ``"+T0:+T1"`` from the record's first
        sample); the parts around them are records of their own.
    min_speed : float, optional
        With a schedule (a speed in m/s after ``scale``): only the samples where it is at least
        this, each run of them a record of its own (JSON ``left_out`` counts the others as
        ``below_min_speed``).
    min_run_seconds : float
        Where ``min_speed`` cuts the records: the shortest run kept, in seconds.
    reading : ReadSettings, optional
        How files are read: channels, time column, time base, segment.
    scale : mapping or sequence of "NAME=FACTOR", optional
        Channel factors applied before identification (a unit, a sign), kept with the model.
    steering_ratio : float, mapping or sequence of "[NAME=]RATIO", optional
        Steering-wheel angles divided by the ratio, giving road-wheel angles.
    validation_inputs, validation_outputs : sequence of str, optional
        The channels' names in validation files, where they differ from the estimation files'.
    out : path, optional
        An HDF5 archive of the run, written before the IEKF's passes and after each (atomically: a
        killed run leaves the archive of its last finished pass), then with every model of the run
        (:mod:`~vehid.identification.automatic.archiving`). An existing file is replaced only if it is
        this run's own archive (same data and settings), unless ``force``; the archive is locked
        against a second writer while the run goes.
    resume : path or Resume, optional
        Go on with the run kept in this archive (its data and settings; ``Resume(archive, passes=N)``
        sets a new pass budget), to the same parameters as a run never interrupted.
    save_model : path, optional
        Write the model returned, with its preparation, to a ``.json`` or ``.mat`` file.
    force : bool
        Let ``out`` and ``save_model`` replace an existing file that is not this run's output.
    checks : callable, optional
        ``checks(model, plan)`` returns failed checks of the model returned (each with ``as_dict()``
        and ``warning()``: JSON ``plausibility`` and warnings), or None where they do not apply
        (`vehid identify` checks a car's physics so).
    progress : callable, optional
        ``progress(passes, label)`` returns a display told of each IEKF pass (``advance``) and then
        closed.

    Returns
    -------
    Identification
        The model returned, its scores, decisions with margins, warnings and order rows; its
        ``render()`` is the command's JSON summary and its ``text()`` the command's text.

    Raises
    ------
    InputError
        Bad data or settings, before any work where they can be seen then (the command's exit status 2).
    StrictWarningsError
        With ``options.strict``, where the run ends with warnings (carrying the summary and text);
        the archive and model file are written first.

    Examples
    --------
    Ten seconds of a lightly damped mode (eigenvalues ``-1 +/- 4j``: 0.656 Hz, damping
    0.243) driven by white noise, identified at order 2:

    >>> import numpy as np
    >>> from vehid.identification import ContinuousModel, IdentifyOptions, IOData, identify
    >>> plant = ContinuousModel(A=[[-1.0, 4.0], [-4.0, -1.0]], B=[[1.0], [0.5]], C=[[1.0, 0.0]], D=[[0.0]])
    >>> u = np.random.default_rng(0).standard_normal((200, 1))
    >>> record = IOData(t=np.arange(200) * 0.05, u=u, y=plant.simulate_outputs(u, 0.05))
    >>> result = identify(record, order=2, options=IdentifyOptions(passes=6))
    >>> result.method, result.order, result.warnings
    ('iekf', 2, ())
    >>> mode = result.model.modes()[0]
    >>> round(mode.frequency_hz, 2), round(mode.damping, 2)
    (0.66, 0.24)
    >>> sorted(result.render())[:4]
    ['A', 'B', 'C', 'D']
    """
    from vehid.identification.automatic import archiving
    from vehid.identification.automatic.intake import is_source_path, plan_run, split_validation
    from vehid.identification.automatic.run import identify_plan
    from vehid.identification.blas import one_blas_thread
    from vehid.identification.dataio.archive import open_archive
    from vehid.identification.dataio.archive_safety import (HDF5_SUFFIXES, archive_lock, check_output_target,
                                                            settings_digest)
    from vehid.identification.dataio.model_files import check_model_target
    from vehid.identification.dataio.model_files import save_model as write_model

    if resume is not None and not isinstance(resume, Resume):
        resume = Resume(resume)
    if resume is not None:
        if data is not None:
            raise OptionError("'resume' takes its data from the archive: give no data", "resume")
        if out is not None:
            raise OptionError("'resume' continues in its own archive: give no 'out'", "resume", "out")
        if schedule is not None:
            raise OptionError("'schedule' runs are not checkpointed: give no 'resume'", "schedule", "resume")
    elif data is None:
        raise InputError("give the data to identify (or an archive to resume)")
    fraction, sources = split_validation(validation)
    files = [source for source in ([] if data is None else [data] if isinstance(data, IOData) or is_source_path(data)
                                   else list(data)) if is_source_path(source)]
    inputs = [*files, *(source for source in sources if is_source_path(source)),
              None if resume is None else resume.archive]
    # the run's identity, kept with the archive: a rerun of the same run may replace it, another may not
    run = "" if out is None else settings_digest("identify", {
        "data": data, "order": order, "validation": validation, "options": dataclasses.replace(options, strict=False),
        "schedule": schedule, "schedule_channel": schedule_channel, "despike": despike, "exclude": exclude,
        "min_speed": min_speed, "min_run_seconds": min_run_seconds, "reading": reading, "scale": scale,
        "steering_ratio": steering_ratio, "validation_inputs": validation_inputs,
        "validation_outputs": validation_outputs, "checks": _named(checks)})
    if out is not None:  # before any work: a bad target must not cost the run
        check_output_target(out, inputs=inputs, force=force, kind=archiving.ARCHIVE_KIND, run=run,
                            suffixes=HDF5_SUFFIXES)
    if save_model is not None:
        check_model_target(save_model, inputs=[*inputs, out], force=force)
    if resume is not None:  # a missing, foreign or corrupt file is named as such before anything is locked or created
        open_archive(resume.archive, kinds=[archiving.ARCHIVE_KIND]).close()
    target = Path(resume.archive) if resume is not None else (Path(out) if out is not None else None)
    with archive_lock(target) if target is not None else nullcontext():  # one writer per archive for the whole run
        resumed = None
        if resume is not None:
            plan, resumed = archiving.resumed_plan(resume.archive, order=order, validation=sources,
                                                   passes=resume.passes, reading=reading)
        else:
            plan = plan_run(data, order=order, validation=validation, detrend=options.detrend, schedule=schedule,
                            schedule_channel=schedule_channel, despike=despike, exclude=exclude, min_speed=min_speed,
                            min_run_seconds=min_run_seconds, reading=reading, scale=scale,
                            steering_ratio=steering_ratio, validation_inputs=validation_inputs,
                            validation_outputs=validation_outputs)
        keeper = archiving.ArchiveKeeper(target, plan, run, progress) if target or progress else None
        try:
            with one_blas_thread():
                result = identify_plan(plan, options, resumed=resumed, checkpoints=keeper)
        finally:
            if keeper is not None:
                keeper.close()
        if out is not None and (options.method != "iekf" or len(plan.orders) > 1):
            archiving.archive_search(Path(out), run, plan, options, result)
        if checks is not None:
            findings = checks(result.model, plan)
            if findings is not None:  # the failed checks are warnings about the model returned
                result = dataclasses.replace(result, plausibility=tuple(findings),
                                             warnings=result.warnings + tuple(f.warning() for f in findings))
        if target is not None:
            result = dataclasses.replace(result, archive=target)
            archiving.archive_outcome(target, result, options)
        if save_model is not None:
            result = dataclasses.replace(result, model_file=write_model(result.model, save_model, plan.preparation))
    if options.strict and result.warnings:
        error = StrictWarningsError(list(result.warnings), result.render(), result.text())
        error.result = result
        raise error
    return result


def _named(checks: Any) -> Any:
    """The checks as they enter the run's identity: a dataclass by its values, a function by its name."""
    if checks is None or dataclasses.is_dataclass(checks):
        return checks
    return f"{getattr(checks, '__module__', '')}.{getattr(checks, '__qualname__', type(checks).__name__)}"
