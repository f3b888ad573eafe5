"""`vehid identify --schedule CHANNEL`: a speed-scheduled modal model from one varying-schedule record.

The scheduling channel (a car's speed) is read beside the inputs, scaled by ``--scale`` where one names
it and never offset (the model's coefficients are functions of its measured value); the samples below
``--min-speed`` are left out and each run of the rest is a record of its own, simulated from rest
(:mod:`vehid.identification.automatic.intake`). The unscheduled
model of the default pipeline starts the scheduled IEKF
(:mod:`vehid.identification.filtering.scheduled_iekf`) at every knot; the family returned is a
:class:`~vehid.identification.models.scheduled.ScheduledModalModel`, scored like every model on the
estimation and held-out data, simulated from rest along their measured schedules.

The family is returned only where it validates better than the unscheduled model by
:data:`VALIDATION_MARGIN` points of mean fit (without validation data: its estimation fit by the
start-or-filter rule's whole-record margin), both scored by the run's one rule (initial state,
horizon, records), and never where a knot is unstable unless that was allowed; otherwise the
unscheduled model is returned and a note says why. With ``--nonlinear`` the family may gain a
static output map (:func:`with_output_map`), and the spline model is a third candidate.

JSON (public): the score keys (``fit_percent``, ``R``, ``estimation_fit_percent``,
``validation_fit_percent``, ``validation_R``, ``records``), the checks (``modes``, each with its
``schedule_value``, and the residual tests) and ``warnings`` describe the model returned
(``model_returned``); ``linear_modes`` the unscheduled model's modes, whose matrices and eigenvalues
are the summary's ``A`` ... ``eigenvalues``; ``decision_margins.schedule`` the decision;
``scheduled`` holds ``model_returned`` ("scheduled", "unscheduled" or "nonlinear"), the family's
own ``estimation_fit_percent`` and ``validation_fit_percent``, the refinement (``refined_from``,
``refine_steps``, ``refine_steps_run``), ``output_map`` (with ``--nonlinear``), ``channel``,
``grid``, ``modes_at`` (per grid value ``value``, its ``modes``, each with ``frequency_hz``,
``frequency_hz_std``, ``damping``, ``damping_std``, and ``extrapolated``: the knot rests on too few
samples), ``uncertainty_method`` (how the knots' covariance behind those standard deviations was
obtained), ``knot_coverage`` (per knot ``value``, ``samples``, ``seconds``, ``excitation``: the first
input's RMS there over the record's, and ``extrapolated``;
:func:`~vehid.identification.filtering.scheduled_iekf.knot_coverage`), the run (``passes_run``,
``stop_reason``, ``p`` and ``p_tried``, chosen on validation data as the IEKF's p is, ``start_fit_percent``
and ``start_R`` of its start, ``seconds``) and ``unscheduled``: the scores of the start by the same
rule (and from rest, ``*_from_rest``). Every ``*fit_percent`` is an NRMSE fit, every ``*R`` the
fit R of eq. 17.
"""

from __future__ import annotations

# the scheduled variant is the pipeline's (vehid.identification.automatic.scheduled); its names stay reachable here
from vehid.identification.automatic.scheduled import (NONLINEAR_NOTE, OUTPUT_MAP_NODES, VALIDATION_MARGIN,
                                                      ScheduledOutcome, identify_scheduled_model, schedule_margin,
                                                      unscheduled_fit, with_output_map)
from vehid.identification.automatic.text import scheduled_lines as text_lines
from vehid.identification.choices import SCHEDULED_P_GRID as P_GRID

__all__ = ["NONLINEAR_NOTE", "OUTPUT_MAP_NODES", "VALIDATION_MARGIN", "P_GRID", "ScheduledOutcome",
           "identify_scheduled_model", "schedule_margin", "unscheduled_fit", "with_output_map", "text_lines"]
