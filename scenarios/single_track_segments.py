"""How sure a single-track identification is, measured on its own log.

Two things `vehid identify --structure single-track` adds to the grey-box fit
(:mod:`vehid.scenarios.single_track_identify`):

* **The covariance** of the physical parameters is that of the estimate as a
  fit of its simulation errors, by the delete-one-block jackknife over
  contiguous blocks of the log (:func:`honest_covariance`;
  :func:`vehid.identification.filtering.greybox_structure.simulation_fit_covariance`),
  not the filter's covariance pass, which takes the innovations as white: on
  real logs that pass made the standard deviations 6-40 times narrower than
  the parameters move between parts of one drive. The handling numbers
  follow from it by the delta method.
* **Segment consistency**: the log is cut into up to :data:`MOST_PARTS`
  disjoint parts of at least :data:`MIN_PART_SECONDS` each, each identified
  on its own as the whole log is (start, filter settings, covariance), and
  the parts' estimates of every physical parameter and of the understeer
  gradient are compared pair by pair within their 95 % intervals
  (:func:`vehid.identification.assessment.segments.segment_consistency`).
  Where a quantity's parts agree in fewer than 80 % of their pairs and the
  joint test (Cochran's Q at 1 %) rejects one common value, the model does
  not hold over the whole log (one warning names them); the parts'
  estimates are the JSON ``segments``.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from vehid.identification.assessment.segments import SegmentConsistency, UncertaintyMethod, block_edges, \
    formal_method, segment_consistency
from vehid.identification.data import IOData, as_records
from vehid.identification.errors import DivergenceError

__all__ = ["MIN_PART_SECONDS", "MOST_PARTS", "JACKKNIFE_FORM", "honest_covariance", "part_edges",
           "part_consistency"]

#: Shortest part of a log the consistency check identifies on its own: on the race car's log, parts of
#: 20 s each held corners of both directions and supported the jackknife's eight blocks.
MIN_PART_SECONDS = 20.0
#: Most parts a log is cut into for the consistency check (each one more identification of its length).
MOST_PARTS = 5

#: How the quantities are named and shown in the warning: label, display unit, factor from the SI unit.
_DISPLAY = {
    "cornering_stiffness_front": ("front cornering stiffness", "kN/rad", 1e-3),
    "cornering_stiffness_rear": ("rear cornering stiffness", "kN/rad", 1e-3),
    "yaw_inertia": ("yaw inertia", "kg m^2", 1.0),
    "axle_friction": ("axle friction", "-", 1.0),
    "understeer_gradient": ("understeer gradient", "deg/g", 1.0),
}


#: The jackknife's replicates for the single-track: one Gauss-Newton step with the curvature without the
#: block. Its three parameters are informed by every block, so the step stays bounded, and it counts a
#: block whose corners carry much of a part's information, which the linearised form (the whole record's
#: curvature) does not: on the race car's four 20 s parts the understeer gradients agreed in 6 of 6 pairs
#: against 5 of 6, two of them at the edge of their intervals (benchmarks/segment_consistency.py).
JACKKNIFE_FORM = "one-step"


def honest_covariance(model: Any, result: Any, records: Any) -> tuple[np.ndarray, UncertaintyMethod]:
    """The covariance of a grey-box result's parameters as a fit of its simulation errors on ``records``.

    The delete-one-block jackknife in the form :data:`JACKKNIFE_FORM`. Where the model cannot be
    simulated to finite values, the filter's own covariance stands and the method says so.
    """
    from vehid.identification.filtering.greybox_structure import simulation_fit_covariance

    found = simulation_fit_covariance(model, result.parameters, records, discretization=result.options.discretization,
                                      substeps=result.options.substeps, form=JACKKNIFE_FORM)
    if found is None:
        return result.covariance, formal_method("the filter's covariance pass (white innovations): the model's "
                                                "simulation over the log is not finite")
    return found


def part_edges(records: IOData | Sequence[IOData]) -> np.ndarray | None:
    """Edges, in samples of the runs taken one after the other, of the parts the consistency check cuts
    ``records`` into, or None where fewer than two fit."""
    runs = as_records(records)
    samples = sum(run.n_samples for run in runs)
    count = min(MOST_PARTS, int(samples * runs[0].dt // MIN_PART_SECONDS))
    return block_edges(samples, count) if count >= 2 else None


def _file_time(record: IOData) -> np.ndarray:
    """The record's sample times as its file counts them."""
    return record.t + float(record.meta.get("time_base", {}).get("time_offset", 0.0))


def _pieces(runs: Sequence[IOData], start: int, stop: int) -> tuple[IOData, ...]:
    """The runs' samples ``start:stop`` of their joined count, a piece per run they fall in; a piece too short
    to identify from (:data:`~vehid.identification.dataio.cleaning.MIN_RUN_SAMPLES`) is left out."""
    from vehid.identification.dataio.cleaning import MIN_RUN_SAMPLES

    pieces, offset = [], 0
    for run in runs:
        low, high = max(start, offset) - offset, min(stop, offset + run.n_samples) - offset
        if high - low >= MIN_RUN_SAMPLES:
            pieces.append(run[low:high])
        offset += run.n_samples
    return tuple(pieces)


def part_consistency(config: Any, model: Any, records: IOData | Sequence[IOData],
                     fit: Callable[[tuple[IOData, ...]], Any]) -> SegmentConsistency | None:
    """Identify each part of ``records`` with ``fit`` and compare the parts' estimates (module docstring).

    ``records`` are the log's runs (a log cut where the car stood is several); the parts are cut from
    them taken one after the other, a part holding a piece of each run it spans. ``fit(part)``
    identifies one part's pieces as the whole log was identified and returns its grey-box result (a
    run that diverged gives its last good pass). None where the log is shorter than two parts. A part
    whose identification fails outright counts as no estimate (NaN), and its pairs as not judged.
    """
    from vehid.vehicle.single_track import single_track_handling

    runs = as_records(records)
    edges = part_edges(runs)
    if edges is None:
        return None
    physical = config.parameter_names[: config.n_physical]
    units = model.parameter_units[: config.n_physical]
    values = {name: [] for name in (*physical, "understeer_gradient")}
    stds = {name: [] for name in values}
    spans, methods = [], []
    for start, stop in zip(edges[:-1], edges[1:]):
        part = _pieces(runs, int(start), int(stop))
        if not part:
            continue
        spans.append((float(_file_time(part[0])[0]), float(_file_time(part[-1])[-1] + part[-1].dt)))
        try:
            result = fit(part)
        except DivergenceError as exc:
            result = exc.last_good
        if result is None:
            for name in values:
                values[name].append(np.nan)
                stds[name].append(np.nan)
            continue
        covariance, method = honest_covariance(model, result, part)
        methods.append(method)
        spread = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
        for index, name in enumerate(physical):
            values[name].append(float(result.parameters[index]))
            stds[name].append(float(spread[index]))
        gradient = single_track_handling(config, result.parameters, covariance, speeds=()).understeer_gradient
        values["understeer_gradient"].append(gradient.value)
        stds["understeer_gradient"].append(gradient.std)
    estimates = {}
    for name in values:
        label, display_unit, factor = _DISPLAY.get(name, (name, None, 1.0))
        unit = "deg/g" if name == "understeer_gradient" else units[physical.index(name)]
        estimates[name] = {"values": values[name], "stds": stds[name], "unit": unit, "label": label,
                           "display_unit": display_unit, "display_factor": factor}
    return segment_consistency(spans, estimates, method=methods[0] if methods else None)
