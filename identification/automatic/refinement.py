"""The refinement of a linear model by its simulation error, and its cross-validation.

Where the verdict is a simulation (a stable plant, no ``--horizon``: :func:`refines`), the
filter's model and its start are refined by their simulation errors on the estimation records
(:mod:`vehid.identification.classical.simulation_error`, :func:`refine`). The p tuning's
two folds score each of them as it is and refined (:func:`refined_cross_validation`, the
models named in :data:`CANDIDATES`), which the returned-model decision
(:mod:`vehid.identification.automatic.returned`) weighs; :func:`refinement_note` says what it chose.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.filtering.iekf import IEKFOptions
from vehid.identification.models.modal import ModalModel
from vehid.identification.automatic.options import IdentifyOptions

__all__ = ["CANDIDATES", "CROSS_VALIDATION_ITERATIONS", "refined_cross_validation", "refines", "refine",
    "REFINED_CV_MEASURE", "SPLINE_START", "REFINED_MEASURE", "refinement_note"]


#: The models the returned-model decision weighs, by name: the filter's and its start's, as they are and refined.
CANDIDATES = ("filter", "start", "filter refined", "start refined")
#: Refinement steps at most on a cross-validation's half: it asks whether refining predicts the other half
#: clearly better or worse (by the schedule margin), which the first steps decide; on the public records the
#: hold-out fits of a refinement stopped after 10, 20 or 40 steps differ by 0.7 point at most.
CROSS_VALIDATION_ITERATIONS = 20


def refined_cross_validation(folds: Sequence[tuple], settings: IdentifyOptions, options: IEKFOptions,
                             held_out_fit: Callable[[ModalModel, tuple[IOData, ...]], float]
                             ) -> dict[str, float | None] | None:
    """Two-fold cross-validated fits of the chosen candidate's model and of its start, as they are and refined.

    ``folds`` holds each fold's ``(model, start, fitted on, scored on)``; each
    stable model is refined by its simulation error on the half it was
    fitted to (:func:`refine`) and scored, as it is and refined, on the other
    half. None where no refinement applies (:func:`refines`) or a fold is
    missing; a model that cannot be scored on both folds gets None.
    """
    if len(folds) != 2 or not refines(settings, options):
        return None
    scores: dict[str, list[float]] = {name: [] for name in CANDIDATES}
    for model, start, fit_on, score_on in folds:
        for name, candidate in (("filter", model), ("start", start)):
            if not isinstance(candidate, ModalModel) or not candidate.is_stable():
                continue
            scores[name].append(held_out_fit(candidate, score_on))
            try:
                refined = refine(candidate, fit_on, settings, max_iterations=CROSS_VALIDATION_ITERATIONS)
                scores[f"{name} refined"].append(held_out_fit(refined.model, score_on))
            except InputError:  # not simulable on its half: no refined score
                pass
    return {name: float(np.mean(values)) if len(values) == 2 and np.all(np.isfinite(values)) else None
            for name, values in scores.items()}


def refines(settings: IdentifyOptions, options: IEKFOptions) -> bool:
    """Whether a run's models are refined by their simulation errors: on the unit-free settings only (the paper's
    absolute ones are its method as published, kept for contrast), and not where the score is a k-step
    prediction (``--horizon``, or a run that allows unstable modes, an open-loop unstable plant's), which a
    simulation error does not measure."""
    return options.timescale == "auto" and settings.horizon is None and not options.allow_unstable


def refine(model: ModalModel, records: Sequence[IOData], settings: IdentifyOptions, **limits: Any) -> Any:
    """``model`` refined by its simulation error on ``records``, each from its own initial state where the scores
    estimate it (:func:`~vehid.identification.classical.simulation_error.refine_simulation_error`, which takes
    ``limits``)."""
    from vehid.identification.classical.simulation_error import refine_simulation_error

    return refine_simulation_error(model, records, initial_state="estimate" if settings.initial_state == "estimate"
                                   else "zero", **limits)


REFINED_CV_MEASURE = "two-fold cross-validated NRMSE fit % of each model refined by its simulation error"
# the key of a refined run's linear model before refinement, from which the spline filter (--nonlinear) starts: it
# continues the filter's own estimate, as the paper's spline filter continues its linear one. From the refined
# model of the cascaded tanks it validated at 70.8 % against 75.7 % from the filter's, below its linear start.
SPLINE_START = "spline_start"
REFINED_MEASURE = "estimation NRMSE fit % of each model refined by its simulation error"


def refinement_note(entry: dict[str, Any]) -> str:
    """The note of a model refined by its simulation error, or of a refinement left out
    (:func:`~vehid.identification.automatic.returned.returned_model`'s
    ``refinement``)."""
    fits = entry.get("fits") or {}

    def best(*names: str) -> float:
        return max(fits[name] for name in names if fits.get(name) is not None)

    if entry.get("left_out"):
        return (f"the models refined by their simulation errors predict the other half of the record worse than as "
                f"they are (two-fold cross-validated fit {best('filter refined', 'start refined'):.2f} % against "
                f"{best('filter', 'start'):.2f} %): no refinement")
    whose = "the filter's model" if entry["model"] == "filter" else "the data start"
    text = (f"{whose} refined by its simulation error on the estimation data: estimation fit "
            f"{entry['fit_before']:.2f} -> {entry['fit_after']:.2f} % ({entry['steps']} steps, {entry['stop_reason']})")
    if fits.get(f"{entry['model']} refined") is not None and fits.get(entry["model"]) is not None:
        text += (f"; two-fold cross-validated fit {fits[entry['model'] + ' refined']:.2f} % against "
                 f"{fits[entry['model']]:.2f} % as it was")
    if entry["model"] == "start" and fits.get("start refined") is not None and fits.get("filter refined") is not None:
        text += (f"; returned in the filter's place: the filter's model refined alike cross-validates "
                 f"{fits['filter refined']:.2f} %")
    return text
