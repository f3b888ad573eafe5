"""Scoring one model on several records: fits per record and over all of them.

Each record is simulated from its own zero initial state (experiments are
separate: no state carries across a record boundary). The overall R of
eq. 17 pools the records: one minus the summed squared error of all records
over their summed output energy, so a long record weighs more than a short one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

from ..data import IOData, as_records
from ..errors import InputError
from .metrics import FitMetrics, nrmse_fit, percentage_explanation, r_squared

__all__ = ["RecordFit", "MultiRecordFit", "score_records", "pooled_percentage_explanation", "pooled_simulation_fit",
           "pooled_nrmse_fit_of_R"]


def pooled_percentage_explanation(pairs: Iterable[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """R (eq. 17) per output over several ``(y, y_hat)`` pairs, pooled: ``1 - sum of errors / sum of energies``."""
    error = energy = 0.0
    for y, y_hat in pairs:  # one pair at a time: pairs may be a generator simulating each record in turn
        y = np.asarray(y)
        error = error + np.sum((y - np.asarray(y_hat)) ** 2, axis=0)
        energy = energy + np.sum(y**2, axis=0)
    if np.any(energy == 0):
        raise InputError("an output is identically zero over all records: R (eq. 17) is undefined")
    return (1.0 - error / energy) * 100.0


def pooled_nrmse_fit_of_R(R: Any, records: Sequence[IOData]) -> np.ndarray:
    """The NRMSE fit per output pooled over records, of a prediction whose pooled R (eq. 17) over them is ``R``.

    Pooled as R is: the summed squared error of all records against the summed
    spread of each record's outputs about that record's own mean (each record
    is its own experiment). With one record this is
    :func:`~vehid.identification.assessment.metrics.nrmse_fit_of_R`.
    """
    energy = sum(np.sum(record.y**2, axis=0) for record in records)
    spread = np.sqrt(sum(np.sum((record.y - record.y.mean(axis=0)) ** 2, axis=0) for record in records))
    if np.any(spread == 0):
        raise InputError("an output is constant over all records: the NRMSE fit is undefined")
    with np.errstate(all="ignore"):
        error = np.maximum(1.0 - np.asarray(R, dtype=float) / 100.0, 0.0) * energy
        return (1.0 - np.sqrt(error) / spread) * 100.0


def _simulation_options(method: str | None) -> dict[str, Any]:
    """No options for the protocol's own simulation; ``method`` only where a caller asks a modal model for another."""
    return {} if method is None else {"method": method}


def pooled_simulation_fit(model: Any, records: Sequence[IOData], method: str | None = None) -> np.ndarray:
    """R per output of ``model`` simulated from rest over each record in turn, pooled.

    ``method`` (a :class:`~identification.models.modal.ModalModel`'s simulation method)
    is passed only where given; by default each model simulates as the
    protocol says (exactly, inputs linear between samples, for a continuous one).
    ``-inf`` where a simulation overflowed (an unstable model, where one is allowed).
    """
    options = _simulation_options(method)
    with np.errstate(all="ignore"):
        fit = pooled_percentage_explanation((record.y, model.simulate_outputs(record.u, record.dt, **options))
                                            for record in records)
    return np.where(np.isfinite(fit), fit, -np.inf)


def _defined(metric: Any, y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """The metric per output, NaN where it is undefined (a constant or zero output in this record)."""
    try:
        return metric(y, y_hat)
    except InputError:
        return np.full(y.shape[1], np.nan)


@dataclass(frozen=True, eq=False)
class RecordFit:
    """The fit of a model on one record."""

    name: str
    samples: int
    metrics: FitMetrics

    def as_dict(self) -> dict[str, Any]:
        """The JSON ``records`` entry: name, samples, fits (R per output, %), and all metrics."""
        return {"name": self.name, "samples": self.samples,
                "fits": self.metrics.percentage_explanation.tolist(), "metrics": self.metrics.as_dict()}


@dataclass(frozen=True, eq=False)
class MultiRecordFit:
    """Fits per record and the pooled R per output over all records."""

    records: tuple[RecordFit, ...]
    fit_percent: np.ndarray


def score_records(model: Any, data: IOData | Sequence[IOData], *, method: str | None = None,
                  names: Sequence[str] | None = None) -> MultiRecordFit:
    """Simulate ``model`` on each record from rest and score it per record and pooled.

    Parameters
    ----------
    model : IdentifiedModel
    data : IOData or sequence of IOData
    method : str, optional
        A modal model's simulation method; by default the model's own
        (exact, inputs linear between samples, for a continuous model).
    names : sequence of str, optional
        Record names; default each record's ``meta["source"]`` or ``record k``.

    A record on which a metric is undefined (a constant output) gets NaN
    fits rather than failing the whole scoring.
    """
    records = as_records(data)
    fits, pairs = [], []
    for index, record in enumerate(records):
        simulated = model.simulate_outputs(record.u, record.dt, **_simulation_options(method))
        name = names[index] if names is not None else str(record.meta.get("source", f"record {index + 1}"))
        fits.append(RecordFit(name, record.n_samples, FitMetrics(
            *(_defined(metric, record.y, simulated) for metric in (percentage_explanation, nrmse_fit, r_squared)))))
        pairs.append((record.y, simulated))
    return MultiRecordFit(tuple(fits), pooled_percentage_explanation(pairs))
