"""The order search: each order of the plan identified and scored, and the order chosen.

* Order: one, a range ``2-8`` or ``auto`` (stopping after two orders in a row
  without gain); the smallest order within :data:`ORDER_TOLERANCE` points of
  the best mean validation fit wins (:func:`choose_order`, its margin :func:`order_margin`).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from vehid.identification.errors import DivergenceError, WorkbenchError
from vehid.identification.automatic.plan import Plan
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.scoring import Evaluation, evaluate, margin_entry

__all__ = ["ORDER_TOLERANCE", "order_margin", "choose_order", "search_orders"]


ORDER_TOLERANCE = 0.5  # points of mean validation fit


def order_margin(rows: list[dict[str, Any]], chosen: int) -> dict[str, Any]:
    """The order decision of an order search: the chosen order's ranking fit and the best other eligible order's."""
    eligible = {row["order"]: row["ranking_fit"] for row in rows if row.get("eligible")}
    others = [(order, fit) for order, fit in eligible.items() if order != chosen]
    runner_up = max(others, key=lambda item: item[1]) if others else (None, None)
    return margin_entry(chosen, eligible.get(chosen), runner_up[0], runner_up[1], measure="mean validation NRMSE fit %",
                   rule=f"the smallest order within {ORDER_TOLERANCE} points of the best")


def choose_order(rows: list[dict[str, Any]]) -> int:
    """The smallest order within :data:`ORDER_TOLERANCE` points of the best mean validation fit (eligible rows only)."""
    eligible = [row for row in rows if row.get("eligible")]
    if not eligible:
        raise DivergenceError("no order gave a usable model: " + "; ".join(
            f"n = {row['order']}: {row.get('error') or 'unstable or diverged'}" for row in rows))
    best = max(row["ranking_fit"] for row in eligible)
    return min(row["order"] for row in eligible if row["ranking_fit"] >= best - ORDER_TOLERANCE)


def search_orders(plan: Plan, fit_one: Callable[[int], tuple[Any, dict[str, Any]]], settings: IdentifyOptions
                  ) -> tuple[list[dict[str, Any]], dict[int, tuple[Any, dict[str, Any], Evaluation]]]:
    """Identify each order of the plan (``fit_one(order) -> (model, extra)``), score it, stop early for auto."""
    rows: list[dict[str, Any]] = []
    kept: dict[int, tuple[Any, dict[str, Any], Evaluation]] = {}
    best, without_gain = -np.inf, 0
    for order in plan.orders:
        started = time.perf_counter()
        row: dict[str, Any] = {"order": order}
        try:
            model, extra = fit_one(order)
        except WorkbenchError as exc:
            row.update(error=str(exc), eligible=False, seconds=time.perf_counter() - started)
            rows.append(row)
            continue
        evaluation = evaluate(model, plan, settings)
        assumed = (extra.get("open_loop_unstable") or {}).get("assumed", False)  # as --allow-unstable
        stable_enough = settings.allow_unstable or assumed or not model.is_linear or model.is_stable()
        row.update(
            fit_percent=extra.get("fit_percent"),
            estimation_fit_percent=evaluation.estimation.fit,
            validation_fit_percent=evaluation.validation_fit,
            ranking_fit=evaluation.ranking_fit(),
            stop_reason=extra.get("stop_reason"),
            **({"p": extra["p"]} if "p" in extra else {}),
            **({"q_schedule": extra["tuning"].q_schedule} if "tuning" in extra else {}),
            seconds=time.perf_counter() - started,
            eligible=bool(stable_enough and np.isfinite(evaluation.ranking_fit())),
        )
        rows.append(row)
        kept[order] = (model, extra, evaluation)
        if plan.auto:
            if row["eligible"] and row["ranking_fit"] > best + ORDER_TOLERANCE:
                best, without_gain = row["ranking_fit"], 0
            else:
                without_gain += 1
                if without_gain >= 2:
                    break
    return rows, kept
