"""What an identification reports beside its scores: checks of the model and of the data.

Public JSON keys of the model checks (a contract once released):
``modes``
    One object per mode (pairs first, then real poles): ``eigenvalue`` and
    ``eigenvalue_std`` as [re, im], ``frequency_hz``, ``frequency_hz_std``,
    ``damping``, ``damping_std`` (NaN standard deviations where the
    estimator gave no covariance).
``uncertainty_method``
    How the parameter covariance behind every standard deviation was
    obtained (:class:`~vehid.identification.assessment.segments.UncertaintyMethod`:
    ``name`` ``block-jackknife`` or ``formal``, the blocks, the degrees of
    freedom, the factor applied, a ``description``); None without a covariance.
``residual_whiteness_p``, ``input_correlation_max``
    Per output, of the continuous model's simulation residuals on the
    record (:mod:`vehid.identification.assessment.residuals`); ``residual_tests`` holds the
    full test results per output (also ``ljung_box``,
    ``input_correlation_p``, ``white``, ``independent``) with the 99 % bound.
``innovation_nis``, ``innovation_nis_band``
    IEKF only: the mean normalised innovation squared ``e' R^-1 e`` of every
    pass and the 99 % band of a consistent filter. The filter's innovation
    covariance is ``H P H' + R``; the compiled pass returns innovations
    only, so R stands for it, which overstates the NIS a little while P is
    large and not at all once it has settled.

The data's keys: ``records`` (the model scored per estimation record),
``sample_jitter``, ``preparation`` and ``conversions`` (offsets and scale
factors removed), ``time_offset`` and ``resample`` where the time base was
shifted or resampled; one warning per record whose gaps were bridged. Where the
records were cleaned (:func:`~vehid.identification.dataio.cleaning.clean_record`):
``outliers``, ``left_out``, and ``despiked`` and ``excluded`` where asked, with
one warning naming the spikes that entered the fit.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.dataio.cleaning import cleaning_summary, cleaning_warnings
from vehid.identification.dataio.timewindow import time_text
from vehid.identification.models.modal import ModalModel
from vehid.identification.assessment.multirecord import score_records
from vehid.identification.assessment.residuals import ResidualTests, nis_band, residual_tests

__all__ = ["model_residual_tests", "uncertainty_summary", "uncertainty_method", "returned_checks", "record_names",
           "records_summary", "data_warnings"]


def model_residual_tests(model: Any, data: IOData, inputs: int | None = None) -> ResidualTests:
    """The residual tests of ``model`` simulated exactly (first-order hold) from rest over ``data``.

    ``inputs``: how many of the record's input columns the residuals are tested against (default
    all; a scheduled family's record carries its schedule last, which is not one of its inputs).
    """
    residuals = data.y - model.simulate_outputs(data.u, data.dt)
    count = data.n_u if inputs is None else inputs
    return residual_tests(data.u[:, :count], residuals, input_names=data.input_names[:count],
                          output_names=data.output_names, output_scale=np.sqrt(np.mean(data.y**2, axis=0)))


def uncertainty_summary(model: ModalModel, data: IOData, nis: Sequence[float] | None = None) -> tuple[dict[str, Any], ResidualTests]:
    """The summary entries of the module docstring, and the residual tests (for an archive)."""
    tests = model_residual_tests(model, data)
    summary: dict[str, Any] = {
        "modes": [mode.as_dict() for mode in model.uncertainty().modes],
        "uncertainty_method": uncertainty_method(model),
        "residual_whiteness_p": tests.residual_whiteness_p,
        "input_correlation_max": tests.input_correlation_max,
        "residual_tests": tests.as_dict(),
    }
    if nis is not None:
        summary["innovation_nis"] = np.asarray(nis, dtype=float)
        summary["innovation_nis_band"] = list(nis_band(data.n_samples, data.n_y))
    return summary, tests


def uncertainty_method(model: Any) -> dict[str, Any] | None:
    """The JSON ``uncertainty_method`` of a model: how its covariance was obtained, None without one.

    A model that carries a covariance but not how it was obtained (a file written before models
    recorded it) is said to carry the formal one, as those did.
    """
    if getattr(model, "parameter_covariance", None) is None:
        return None
    stored = (getattr(model, "meta", None) or {}).get("uncertainty_method")
    if stored is None:
        from vehid.identification.assessment.segments import formal_method

        return formal_method("the model does not record how its covariance was obtained: one written before "
                             "models did carries the formal covariance of white residuals").as_dict()
    return stored


def returned_checks(model: Any, data: IOData, nis: Sequence[float] | None = None
                    ) -> tuple[dict[str, Any] | None, ResidualTests | None]:
    """The checks of the module docstring for whichever model is returned, on its (first) estimation record.

    A modal model as :func:`uncertainty_summary`; a scheduled family (``model_at``) its modes at
    each grid value, each mode with ``schedule_value`` (the grid value), and the residual tests of
    its simulation along ``data``'s schedule (the record's last input); a spline model (``linear_model``)
    its modes at rest. ``nis`` (the IEKF's) belongs to a linear model's run only. None where the
    model offers no modes.
    """
    if isinstance(model, ModalModel):
        return uncertainty_summary(model, data, nis)
    if hasattr(model, "model_at") and hasattr(model, "grid"):
        modes = [{**mode, "schedule_value": row["value"]} for row in model.modes_at(model.grid) for mode in row["modes"]]
        tests = model_residual_tests(model, data, inputs=data.n_u - 1)
    elif hasattr(model, "linear_model"):
        modes = [mode.as_dict() for mode in model.linear_model().uncertainty().modes]
        tests = model_residual_tests(model, data)
    else:
        return None, None
    return {"modes": modes, "residual_whiteness_p": tests.residual_whiteness_p,
            "input_correlation_max": tests.input_correlation_max, "residual_tests": tests.as_dict(),
            "uncertainty_method": uncertainty_method(model)}, tests


def record_names(records: Sequence[IOData]) -> list[str]:
    """Unique display names of records: their sources, numbered where one repeats."""
    names = [str(r.meta.get("source", f"record {i + 1}")) for i, r in enumerate(records)]
    return [f"{n} ({i + 1})" if names.count(n) > 1 else n for i, n in enumerate(names)]


def records_summary(model: Any, records: Sequence[IOData], preparation: Any) -> dict[str, Any]:
    """The JSON keys about the data: ``records``, ``sample_jitter``, ``preparation``."""
    scored = score_records(model, records, names=record_names(records))
    jitters = [r.meta.get("time_base", {}).get("sample_jitter") for r in records]
    summary: dict[str, Any] = {
        "records": [fit.as_dict() for fit in scored.records],
        "sample_jitter": max((j for j in jitters if j is not None), default=None),
    }
    if preparation is not None:
        summary["preparation"] = preparation.as_dict()
        summary["conversions"] = preparation.conversion_list()
    offsets = [float(r.meta.get("time_base", {}).get("time_offset", 0.0)) for r in records]
    if any(offsets):  # time counted from each record's first sample: where that was in the file's time
        summary["time_offset"] = offsets
    resampled = [r.meta.get("time_base", {}).get("resample") for r in records]
    if any(resampled):
        summary["resample"] = next(r for r in resampled if r)
    summary.update(cleaning_summary(records))  # outliers, and what was left out, where the records were cleaned
    return summary


def data_warnings(records: Sequence[IOData]) -> list[str]:
    """One line per record whose gaps in time were bridged by resampling, naming where they were, and one
    naming the spikes and drop-outs that entered the fit."""
    lines = []
    for name, record in zip(record_names(records), records):
        base = record.meta.get("time_base", {})
        gaps, count = base.get("gaps") or [], int(base.get("gap_count", 0))
        if not count:
            continue
        offset = float(base.get("time_offset", 0.0))  # at_s is file time; the message speaks the axes' time
        shown = ", ".join(f"{gap['length_s']:.3g} s at {time_text(gap['at_s'] - offset, offset)} ({gap['location']})"
                          for gap in gaps[:3])
        more = f" and {count - 3} more" if count > 3 else ""
        lines.append(f"{name}: {count} gap{'s' if count > 1 else ''} in time bridged by straight lines when "
                     f"resampling ({shown}{more}): the model sees no data there; --segment T0:T1 leaves a gap out")
    return lines + cleaning_warnings(records)
