"""Model-order selection from a series of IEKF identifications (Best & Bogdanski 2017, section 4.3).

The paper prefers the lowest order that explains the outputs very well and whose identification is well
conditioned: trace(P) settles and the parameters stop moving, where an order with more parameters than
the data need fits marginally better while trace(P) grows and parameters drift. Over the last ``window``
passes, ``trace_growth`` is the relative change of trace(P) and ``drift`` the largest relative change of
a parameter (relative to max(|value|, 0.01 x the largest parameter), so that a zero crossing is not
infinite drift). An order converges when its run stopped on the IEKF's settling test or both measures
are within tolerance; the choice is the lowest converged order whose mean R is within ``fit_margin``
points of the best (with none converged, the lowest order within the margin).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..errors import InputError

__all__ = ["AssessedOrder", "OrderAssessment", "assess_orders", "convergence_measures"]


@dataclass(frozen=True)
class AssessedOrder:
    """One order's figures."""

    order: int
    mean_fit: float
    mean_fit_filter: float
    trace_p: float
    trace_growth: float
    drift: float
    converged: bool
    eigenvalues: tuple[complex, ...]

    def as_dict(self) -> dict[str, Any]:
        return {
            "order": self.order,
            "mean_R": self.mean_fit,
            "mean_R_filter": self.mean_fit_filter,
            "trace_p": self.trace_p,
            "trace_growth": self.trace_growth,
            "drift": self.drift,
            "converged": self.converged,
            "eigenvalues": [[float(v.real), float(v.imag)] for v in self.eigenvalues],
        }


@dataclass(frozen=True)
class OrderAssessment:
    """The per-order table and the chosen order.

    Attributes
    ----------
    rows : tuple of AssessedOrder
        One row per order: fits, trace of P, its growth and the parameters' drift.
    chosen_order : int
        The order chosen.
    fit_margin : float
        Points of mean R an order could fall below the best and still be chosen.
    window : int
        Passes over which growth and drift were measured.
    """

    rows: tuple[AssessedOrder, ...]
    chosen_order: int
    fit_margin: float
    window: int

    def text(self) -> str:
        """Render the table as plain text.

        Returns
        -------
        str
            One line per order, under a header.
        """
        lines = [f"{'n':>2} {'R filter %':>10} {'R exact %':>10} {'trace(P)':>10} {'trace growth':>13} {'drift':>9} {'converged':>9}"]
        for row in self.rows:
            lines.append(
                f"{row.order:>2} {row.mean_fit_filter:10.4f} {row.mean_fit:10.4f} {row.trace_p:10.4g} {row.trace_growth:13.3%} "
                f"{row.drift:9.2e} {'yes' if row.converged else 'no':>9}"
            )
        return "\n".join(lines)


def convergence_measures(parameters: np.ndarray, trace_p: np.ndarray, window: int) -> tuple[float, float]:
    """(trace growth, drift) over the last ``window`` passes; see the module notes."""
    parameters = np.asarray(parameters, dtype=float)
    trace_p = np.asarray(trace_p, dtype=float)
    if parameters.shape[0] < 2:
        raise InputError("at least two passes are needed to judge convergence")
    span = min(window, parameters.shape[0] - 1)
    first, last = parameters[-1 - span], parameters[-1]
    floor = 0.01 * max(float(np.max(np.abs(last))), 1e-12)
    drift = float(np.max(np.abs(last - first) / np.maximum(np.abs(last), floor))) * window / span
    growth = float((trace_p[-1] - trace_p[-1 - span]) / abs(trace_p[-1 - span])) * window / span
    return growth, drift


def assess_orders(
    results: Mapping[int, Any],
    *,
    window: int = 20,
    trace_tolerance: float = 0.02,
    drift_tolerance: float = 1e-3,
    fit_margin: float = 0.05,
) -> OrderAssessment:
    """Judge a series of identifications of increasing order and choose one.

    Parameters
    ----------
    results : mapping order -> IEKFResult
        Each with its per-pass history.
    window : int
        Passes over which growth and drift are measured (the paper's figures span tens of passes).
    trace_tolerance, drift_tolerance : float
        Largest relative change per window of trace(P) and of any parameter for a converged run.
    fit_margin : float
        Points of mean R (percent) an order may fall below the best and still be chosen.

    Returns
    -------
    OrderAssessment
        The table and the order chosen.
    """
    if not results:
        raise InputError("no identifications to assess")
    rows = []
    for order in sorted(results):
        result = results[order]
        history = result.history
        parameters = np.array([record.parameters for record in history])
        trace = np.array([record.trace_p for record in history])
        growth, drift = convergence_measures(parameters, trace, window)
        rows.append(
            AssessedOrder(
                order=int(order),
                mean_fit=history[-1].mean_fit_continuous,
                mean_fit_filter=history[-1].mean_fit_filter,
                trace_p=float(trace[-1]),
                trace_growth=growth,
                drift=drift,
                converged=result.stop_reason == "converged"
                or (abs(growth) < trace_tolerance and drift < drift_tolerance),
                eigenvalues=tuple(complex(v) for v in result.model.eigenvalues()),
            )
        )
    best = max(row.mean_fit_filter for row in rows)
    good = [row for row in rows if row.mean_fit_filter >= best - fit_margin]
    converged = [row for row in good if row.converged]
    chosen = (converged or good)[0].order
    return OrderAssessment(tuple(rows), chosen, fit_margin, window)
