"""`vehid identify --schedule CHANNEL`: a speed-scheduled modal model from one varying-schedule record.

The scheduling channel (a car's speed) is read beside the inputs, scaled by ``--scale`` where one names
it and never offset (the model's coefficients are functions of its measured value). The unscheduled
model of the default pipeline starts the scheduled IEKF
(:mod:`vehid.identification.filtering.scheduled_iekf`) at every knot; the family returned is a
:class:`~vehid.identification.models.scheduled.ScheduledModalModel`, scored like every model on the
estimation and held-out data, simulated from rest along their measured schedules.

The family is returned only where it validates better than the unscheduled model by
:data:`VALIDATION_MARGIN` points of mean fit (without validation data: its estimation fit by the
start-or-filter rule's whole-record margin), and never where a knot is unstable unless that was
allowed; otherwise the unscheduled model is returned with a warning. With ``--nonlinear`` the family
may gain a static output map (:func:`with_output_map`).

JSON (public): the score keys (``fit_percent``, ``estimation_fit_percent``, ``validation_fit_percent``,
``validation_R``, ``records``) describe the model returned; ``decision_margins.schedule`` the decision;
``scheduled`` holds ``model_returned`` ("scheduled" or "unscheduled"), the family's own
``estimation_fit_percent`` and ``validation_fit_percent``, the refinement (``refined_from``,
``refine_steps``, ``refine_steps_run``), ``output_map`` (with ``--nonlinear``), ``channel``, ``grid``,
``modes_at`` (per grid value ``value`` and its ``modes``, each with ``frequency_hz``,
``frequency_hz_std``, ``damping``, ``damping_std``), ``uncertainty_method`` (how the knots' covariance
behind those standard deviations was obtained), the run (``passes_run``, ``stop_reason``,
``p`` and ``p_tried``, chosen on validation data as the IEKF's p is, ``seconds``) and ``unscheduled``: the scores of the start
(also from rest, ``*_from_rest``, as the family is scored and the decision weighs them), whose matrices, eigenvalues and
modes are the summary's other keys.
"""

from __future__ import annotations

from typing import Any, Sequence

# the scheduled variant is the pipeline's (vehid.identification.automatic.scheduled); its names stay reachable here
from vehid.identification.automatic.scheduled import (NONLINEAR_NOTE, OUTPUT_MAP_NODES, VALIDATION_MARGIN,
                                                      ScheduledOutcome, identify_scheduled_model, schedule_margin,
                                                      unscheduled_fit, with_output_map)
from vehid.identification.choices import SCHEDULED_P_GRID as P_GRID

__all__ = ["NONLINEAR_NOTE", "OUTPUT_MAP_NODES", "VALIDATION_MARGIN", "P_GRID", "ScheduledOutcome",
           "identify_scheduled_model", "schedule_margin", "unscheduled_fit", "with_output_map", "text_lines"]


def text_lines(entry: dict[str, Any], output_names: Sequence[str]) -> list[str]:
    """The text face of the ``scheduled`` entry: the run, the unscheduled scores and the modes at each grid value."""
    unscheduled = entry["unscheduled"]
    validation = unscheduled.get("validation_fit_percent")
    lines = [
        f"scheduled on {entry['channel']} ({entry['knots']} knots, p {entry['p']:g}, {entry['passes_run']} passes, "
        f"{'converged' if entry['stop_reason'] == 'converged' else 'NOT converged'}): "
        + ("the scores above are its own; unscheduled start: estimation " if entry.get("model_returned") != "unscheduled"
           else "NOT returned (the scores above are the unscheduled model's); unscheduled: estimation ")
        + ", ".join(f"{n} {v:.2f}" for n, v in zip(output_names, unscheduled["estimation_fit_percent"]))
        + ("" if validation is None else "; validation " + ", ".join(
            f"{n} {v:.2f}" for n, v in zip(output_names, validation))),
        f"modes at {entry['channel']} (frequency Hz, damping; +/- 2 sigma):",
    ]
    for row in entry["modes_at"]:
        modes = "; ".join(f"{mode['frequency_hz']:.4g} +/- {2 * mode['frequency_hz_std']:.2g} Hz, "
                          f"{mode['damping']:.3f} +/- {2 * mode['damping_std']:.2g}" for mode in row["modes"])
        lines.append(f"  {entry['channel']} = {row['value']:.4g}: {modes}")
    if entry.get("uncertainty_method"):
        lines.append(f"  standard deviations: {entry['uncertainty_method']['description']}")
    return lines
