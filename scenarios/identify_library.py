"""`vehid identify` from Python: the command's automatic pipeline on records in memory.

:func:`identify` runs exactly the steps of the command (p by cross-validation,
the open-loop-unstable treatment, start or filter, order search, hold-out
scoring, warnings, the spline-nonlinear model) on :class:`IOData` records and
returns a typed :class:`~vehid.identification.pipeline.Identification`. It
writes no file; its warnings come back in the result (and go to standard
error, as the command's do).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace
from typing import Sequence

from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.pipeline import Identification, IdentifyOptions
from vehid.identification.dataio.preparation import prepare, prepare_validation
from vehid.identification.assessment.validation import split_holdout

__all__ = ["identify"]


def _settings(order: int | str, validation: float | None, options: IdentifyOptions) -> SimpleNamespace:
    """The command's settings for these options: no files, no archive, no model file, no progress bar."""
    return SimpleNamespace(
        data=[], order=str(order), method="iekf", structure="modal", schedule=None, resume=None, out=None,
        save_model=None, force=False, quiet=True, bootstrap=None, scale=None, steering_ratio=None,
        validation=validation, validation_file=[], validation_inputs=None, validation_outputs=None,
        p=options.p, passes=options.passes, start=options.start, normalize=options.normalize,
        discretization=options.discretization, covariance=options.covariance, pattern=options.pattern,
        timescale=options.timescale, allow_unstable=options.allow_unstable, initial_state=options.initial_state,
        horizon=options.horizon, nonlinear=options.nonlinear, nodes=options.nodes,
        nonlinear_p=list(options.nonlinear_p) if options.nonlinear_p is not None else None,
        nonlinear_passes=options.nonlinear_passes, detrend=options.detrend, strict=options.strict,
        output_run=None,
    )


def identify(data: IOData | Sequence[IOData], *, order: int | str = 4,
             validation: float | IOData | Sequence[IOData] | None = None,
             options: IdentifyOptions = IdentifyOptions()) -> Identification:
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
    from vehid.scenarios import identify_workflow as workflow
    from vehid.scenarios.commands.identify import identify_run

    raw = (data,) if isinstance(data, IOData) else tuple(data)
    if not raw or not all(isinstance(record, IOData) for record in raw):
        raise InputError("identify takes an IOData record or a sequence of them")
    extra: tuple[IOData, ...] = ()
    fraction = None
    if isinstance(validation, IOData):
        extra = (validation,)
    elif validation is not None and not isinstance(validation, (int, float)):
        extra = tuple(validation)
    elif validation is not None:
        fraction = float(validation)
    settings = _settings(order, fraction, options)
    fraction, note = workflow.holdout_fraction(settings if not extra else SimpleNamespace(
        **{**vars(settings), "validation_file": list(extra)}))
    held_raw: tuple[IOData, ...] = ()
    if fraction is not None:
        parts = [split_holdout(record, fraction) for record in raw]
        raw, held_raw = tuple(part[0] for part in parts), tuple(part[1] for part in parts)
    records, preparation = prepare(raw, detrend=options.detrend)
    held = tuple(prepare_validation(part, preparation, record=i) for i, part in enumerate(held_raw))
    settings.validation_file = list(extra)
    plan = workflow.make_plan(settings, records, lambda record: prepare_validation(record, preparation,
                                                                                   own_offsets=True),
                              held_out=held, fraction=fraction, note=note, preparation=preparation)
    if extra:  # named by their sources, as the command names validation files by their paths
        names = plan.validation_names[:plan.held_out_count] + tuple(
            str(record.meta.get("source", f"validation record {i + 1}")) for i, record in enumerate(extra))
        plan = dataclasses.replace(plan, validation_names=names)
    summary, _, model = identify_run(settings, plan)
    return Identification.from_summary(summary, model)
