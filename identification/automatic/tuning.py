"""The IEKF's settings for a run: its p and Q schedule by cross-validation.

* The IEKF's settings follow the options (:func:`iekf_options`): the unit-invariant ones unless
  asked otherwise.
* The IEKF's p and Q schedule, unless p is given: two-fold cross-validation
  over :data:`P_GRID`, each p with Q held constant and with Q shrinking from
  pass to pass (:data:`Q_SCHEDULES`, :func:`tune_p`).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.decisions import SCHEDULE_MARGIN, ScheduleCandidate, choose_p_and_schedule
from vehid.identification.errors import InputError, WorkbenchError
from vehid.identification.frozen import FrozenDict, freeze
from vehid.identification.filtering.iekf import (INVARIANT_P, INVARIANT_P_DECAY, IEKFOptions, identify_iekf,
                                                 invariant_noise_settings)
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.validation import default_horizon, split_holdout
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.scoring import last_good_on_divergence, mean_scores
from vehid.identification.automatic.refinement import refined_cross_validation

__all__ = ["P_GRID", "P_TOLERANCE", "Q_SCHEDULES", "q_schedule_of", "PCandidate", "PTuning", "given_p", "tunes_p",
    "planned_filter_steps", "halves", "tune_p", "iekf_options"]


P_GRID = (1e-4, 1e-5, 1e-6)  # p per dominant time constant tried by cross-validation, largest first
P_TOLERANCE = 0.1  # points of cross-validated fit within which the largest p is taken
# Q schedules tried at each p, as IEKFOptions.p_decay. A shrinking Q averages the parameters over the whole
# record and stops them chasing sensor noise (it saves 10-36 points on noisy handling records); a constant Q
# keeps following the record's last part, so its hold-out fit moves with the record's length (the heat
# exchanger: 49.5-65.4 % over held-out fractions 0.3-0.4) and it is chosen only where it scores clearly
# better (identification.decisions.SCHEDULE_MARGIN)
Q_SCHEDULES = {"constant": 1.0, "shrinking": INVARIANT_P_DECAY}


def q_schedule_of(options: IEKFOptions) -> str:
    """The name in :data:`Q_SCHEDULES` of the options' Q schedule: "constant" or "shrinking"."""
    return "constant" if options.p_decay >= 1 else "shrinking"


@dataclass(frozen=True)
class PCandidate:
    """One p and Q schedule tried by the cross-validation: its two-fold fit (None where it failed) and cost.

    ``q_schedule`` is None in a row archived before schedules were kept (every run's Q was constant then).
    """

    p: float
    q_schedule: str | None
    cv_fit_percent: float | None
    seconds: float
    error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        """The row's keys in ``p_tried``."""
        return {"p": self.p, **({} if self.q_schedule is None else {"q_schedule": self.q_schedule}),
                "seconds": self.seconds, "cv_fit_percent": self.cv_fit_percent,
                **({} if self.error is None else {"error": self.error})}

    @classmethod
    def from_dict(cls, row: Mapping[str, Any]) -> "PCandidate":
        """A row as :meth:`as_dict` wrote it (an archived run's)."""
        fit = row.get("cv_fit_percent")
        return cls(p=float(row["p"]), q_schedule=row.get("q_schedule"), cv_fit_percent=None if fit is None else float(fit),
                   seconds=float(row.get("seconds", 0.0)), error=row.get("error"))


@dataclass(frozen=True)
class PTuning:
    """The filter's p and Q schedule chosen by two-fold cross-validation, with each candidate's score and cost."""

    p: float
    tried: tuple[PCandidate, ...]
    seconds: float
    start_fit: float | None = None  # the data start's cross-validated fit, on the same halves
    q_schedule: str = "constant"  # a key of Q_SCHEDULES
    # the chosen candidate's and the start's cross-validated fits, as they are and refined by their simulation
    # errors (keys of CANDIDATES; refined_cross_validation), where the run is one to refine
    candidate_fits: FrozenDict | None = None

    def __post_init__(self) -> None:
        if self.candidate_fits is not None:
            object.__setattr__(self, "candidate_fits", freeze(self.candidate_fits))

    def summary(self) -> dict[str, Any]:
        """The public JSON keys ``p``, ``q_schedule``, ``p_tried``, ``tuning_seconds`` and ``start_cv_fit_percent``."""
        return {"p": self.p, "q_schedule": self.q_schedule, "p_tried": [row.as_dict() for row in self.tried],
                "tuning_seconds": self.seconds, "start_cv_fit_percent": self.start_fit}

    def as_dict(self) -> dict[str, Any]:
        """Every field, as an archive keeps the run's decisions (:meth:`from_dict` reads it back)."""
        return {"p": self.p, "tried": [row.as_dict() for row in self.tried], "seconds": self.seconds,
                "start_fit": self.start_fit, "q_schedule": self.q_schedule,
                "candidate_fits": None if self.candidate_fits is None else dict(self.candidate_fits)}

    @classmethod
    def from_dict(cls, stored: Mapping[str, Any]) -> "PTuning":
        """The tuning :meth:`as_dict` wrote; an archive written before the Q schedule was kept reads as constant Q."""
        return cls(p=float(stored["p"]), tried=tuple(PCandidate.from_dict(row) for row in stored["tried"]),
                   seconds=float(stored["seconds"]), start_fit=stored["start_fit"],
                   q_schedule=stored.get("q_schedule", "constant"), candidate_fits=stored.get("candidate_fits"))

    def applied(self, options: IEKFOptions) -> IEKFOptions:
        """``options`` with the chosen p and Q schedule."""
        shrinks = self.q_schedule != "constant"
        # a shrinking schedule keeps the options' own rate where they have one
        decay = (options.p_decay if options.p_decay < 1 else Q_SCHEDULES[self.q_schedule]) if shrinks else 1.0
        return dataclasses.replace(options, p=self.p, p_decay=decay)

    @property
    def chosen_fit(self) -> float | None:
        """The chosen p and schedule's cross-validated fit (None where it was not scored)."""
        return next((row.cv_fit_percent for row in self.tried if row.p == self.p
                     and (row.q_schedule or self.q_schedule) == self.q_schedule), None)

    @property
    def start_wins(self) -> bool:
        """Whether the filter's chosen candidate fails to beat the data start by more than
        :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points in cross-validation.

        The filter starts from the data start and moves it; a move whose cross-validated lead is
        within the margin is not shown to be a gain (such leads do not rank hold-out fits: on the
        ball and beam the filter led its start by 0.2-0.8 point at orders 2 and 3 and validated
        2.3-3.8 points below it), so the start, the model the data fix most directly, stays.
        """
        fit = self.chosen_fit
        return self.start_fit is not None and (fit is None or fit <= self.start_fit + SCHEDULE_MARGIN)

    def margin(self) -> dict[str, Any] | None:
        """The p decision: the chosen p, its Q schedule and fit, the best other candidate (another p or
        schedule, or the data start)."""
        if not self.tried:
            return None
        scored = {(row.p, row.q_schedule or self.q_schedule): row.cv_fit_percent for row in self.tried
                  if row.cv_fit_percent is not None}
        chosen = (self.p, self.q_schedule)
        others = [(f"p {p:g}, {schedule} Q", fit) for (p, schedule), fit in scored.items() if (p, schedule) != chosen]
        if self.start_fit is not None:
            others.append(("data start", self.start_fit))
        runner_up = max(others, key=lambda item: item[1]) if others else (None, None)
        return {"choice": f"p {self.p:g}", "q_schedule": self.q_schedule, "score": scored.get(chosen),
                "runner_up": runner_up[0], "runner_up_score": runner_up[1],
                "measure": "two-fold cross-validated NRMSE fit %",
                "rule": f"a shrinking Q unless a constant one scores more than {SCHEDULE_MARGIN:g} points better; "
                        f"at that schedule the largest p within {P_TOLERANCE} points of its best"}


def given_p(options: IEKFOptions) -> PTuning:
    """No tuning: the p the user gave (or the settings fixed), with the options' Q schedule."""
    return PTuning(options.p, (), 0.0, q_schedule=q_schedule_of(options))


def tunes_p(settings: IdentifyOptions) -> bool:
    """Whether the IEKF's p is chosen by cross-validation: no --p given, on the unit-free time scale."""
    return settings.p is None and settings.timescale == "auto"


def planned_filter_steps(plan: Plan, options: IEKFOptions, tuned: bool) -> int:
    """The most filter steps one order's runs take in all: where p is ``tuned``, the cross-validation's
    candidates (two folds of half the estimation records each, every schedule), and the final run, each
    at most ``options.passes`` passes. A resumed run is tuned where the run it resumes tried candidates.

    Every run of the order is given this figure (``identify_iekf``'s ``planned_steps``): runs of a few
    thousand samples each would otherwise build the compiled pass for a short run (no optimisation),
    while together they make millions of steps; and all of them use the one build, so the run returned
    has the rounding of the cross-validated ones.
    """
    samples = sum(record.n_samples for record in plan.records)
    candidates = len(P_GRID) * len(Q_SCHEDULES) if tuned else 0
    return (candidates + 1) * options.passes * samples


def halves(records: tuple[IOData, ...]) -> tuple[tuple[IOData, ...], tuple[IOData, ...]]:
    """Each record cut at its middle: the first halves and the second halves, in the records' order."""
    parts = [split_holdout(record, 0.5) for record in records]
    return tuple(part[0] for part in parts), tuple(part[1] for part in parts)


def tune_p(settings: IdentifyOptions, plan: Plan, options: IEKFOptions, structure: ModalStructure) -> PTuning:
    """The IEKF's p and Q schedule by two-fold cross-validation on the estimation records (module docstring).

    Each record is cut in halves; a model identified on the first halves is scored on the second and
    the reverse, and the two NRMSE fits averaged. Each p of the grid :data:`P_GRID` is tried with
    each schedule of :data:`Q_SCHEDULES` (only the constant one where ``options`` keep Q constant).
    The shrinking Q is run unless a constant Q's best candidate beats its best by more than
    :data:`~vehid.identification.decisions.SCHEDULE_MARGIN` points: cross-validated fits that
    close do not rank the hold-out fits, and the constant Q's outcome moves with the record
    (:func:`~vehid.identification.decisions.choose_p_and_schedule`). Of that schedule's
    candidates within :data:`P_TOLERANCE` points of its best, the largest p wins: a larger p
    moves the parameters faster, so the run converges in fewer passes, and the difference below
    the tolerance is noise.
    """
    started = time.perf_counter()
    try:
        first, second = halves(plan.records)
    except InputError:  # too short to halve: the run itself names what the record lacks
        return given_p(options)
    schedules = list(Q_SCHEDULES) if options.p_decay < 1 else ["constant"]

    def held_out_fit(model: ModalModel, records: tuple[IOData, ...]) -> float:
        horizon = settings.horizon if settings.horizon is not None else default_horizon(model)
        return float(np.mean(mean_scores(model, records, initial_state=settings.initial_state, horizon=horizon).fit))

    planned = planned_filter_steps(plan, options, tuned=True)
    rows = []
    start_fits: dict[int, float] = {}  # per fold: the data start does not depend on p
    folds: dict[tuple[float, str], list] = {}  # per candidate: (model, start, fitted on, scored on) of each fold
    for p, schedule in ((p, schedule) for p in P_GRID for schedule in schedules):
        trial = PTuning(p, (), 0.0, q_schedule=schedule).applied(options)
        began = time.perf_counter()
        fits, errors = [], []
        # the second halves start mid-motion: their start state is unknown, whatever the record's is
        for fold, (fit_on, score_on, settle) in enumerate(((first, second, plan.settle_start), (second, first, True))):
            data = fit_on[0] if len(fit_on) == 1 else fit_on
            try:
                result, _ = last_good_on_divergence(
                    lambda: identify_iekf(data, structure, options=trial, settle_start=settle, parameter_covariance=False,
                                          planned_steps=planned))
            except WorkbenchError as exc:
                errors.append(str(exc))
                continue
            fits.append(held_out_fit(result.model, score_on))
            start = (ModalModel.from_parameters(structure, result.meta["start_parameters"])
                     if result.meta.get("start_parameters") is not None else None)
            if fold not in start_fits and start is not None:
                start_fits[fold] = held_out_fit(start, score_on)
            folds.setdefault((p, schedule), []).append((result.model, start, fit_on, score_on))
        fit = None if errors or not np.all(np.isfinite(fits)) else float(np.mean(fits))
        rows.append(PCandidate(p, schedule, fit, time.perf_counter() - began, "; ".join(errors) if errors else None))
    choice = choose_p_and_schedule([ScheduleCandidate(row.p, row.q_schedule, row.cv_fit_percent)
                                    for row in rows if row.cv_fit_percent is not None], P_TOLERANCE)
    # no candidate scored on the other half: the default, whose own run then says what went wrong
    chosen, schedule = choice if choice is not None else (options.p, q_schedule_of(options))
    start_fit = float(np.mean(list(start_fits.values()))) if len(start_fits) == 2 else None
    candidates = refined_cross_validation(folds.get((chosen, schedule), []), settings, options, held_out_fit)
    return PTuning(chosen, tuple(rows), time.perf_counter() - started,
                   start_fit if start_fit is not None and np.isfinite(start_fit) else None, schedule, candidates)


def iekf_options(settings: IdentifyOptions) -> IEKFOptions:
    """The IEKF's settings for these options: the unit-invariant ones unless asked otherwise."""
    p = settings.p if settings.p is not None else (INVARIANT_P if settings.timescale == "auto" else 1.0)
    # the unit-free time scale meets noise as IEKFOptions.invariant does; the paper's settings keep Q and R = I
    noise = invariant_noise_settings() if settings.timescale == "auto" else {}
    return IEKFOptions(
        p=p, passes=settings.passes, discretization=settings.discretization, covariance=settings.covariance,
        start=settings.start, normalize=settings.normalize, timescale=settings.timescale, allow_unstable=settings.allow_unstable,
        **noise,
    )
