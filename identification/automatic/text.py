"""The text face of an identification: what `vehid identify` prints without ``--json``.

Every line is made from the result's summary (:meth:`~vehid.identification.automatic.result.Identification.render`),
so that the text and the JSON say the same: the model returned and its fits (:func:`identification_text`),
how sure it is (:func:`uncertainty_lines`: modes with two standard deviations, residual tests, the
filter's NIS) and a scheduled family's run (:func:`scheduled_lines`).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ["RETURNED_TEXT", "identification_text", "mode_lines", "uncertainty_lines", "scheduled_lines"]


def _fits(names: tuple[str, ...], values: Any) -> str:
    """Each output's name and fit, or "-" where there is none."""
    if values is None:
        return "-"
    return ", ".join(f"{name} {value:.2f}" for name, value in zip(names, values))


def _fit_and_R(fit: Any, R: Any) -> str:
    """One output's NRMSE fit with its R labelled beside it (``-`` where there is none)."""
    if fit is None:
        return "-"
    return f"{fit:.2f}" + ("" if R is None else f" (R {R:.2f})")


def _at(values: Any, index: int) -> Any:
    return None if values is None else values[index]


#: what the text calls each model the command may return (``model_returned``)
RETURNED_TEXT = {"filter": "the IEKF's linear model", "start": "the IEKF's start model (linear)",
                 "scheduled": "the scheduled family", "nonlinear": "the spline-nonlinear model"}


def identification_text(summary: dict[str, Any], plan: Any) -> str:
    """The text face: the model returned, its NRMSE fits (R beside) on estimation and validation data, the run,
    then how sure the model is and a scheduled family's run."""
    from vehid.identification.automatic.tuning import P_TOLERANCE
    from vehid.identification.automatic.returned import decision_notes
    from vehid.identification.automatic.orders import ORDER_TOLERANCE
    from vehid.identification.decisions import SCHEDULE_MARGIN

    data = plan.records[0]
    eigen = ", ".join(
        f"{v.real:.4g}{v.imag:+.4g}j" if v.imag else f"{v.real:.4g}" for v in np.asarray(summary["eigenvalues"], dtype=complex)
    )
    stop = summary.get("stop_reason")
    converged = "converged" if stop == "converged" else (f"NOT converged ({stop})" if stop else "direct method (no iterations)")
    kind = summary.get("time_domain", "continuous")
    returned = summary.get("model_returned", summary["method"])
    linear_returned = returned not in ("scheduled", "nonlinear")
    lines = [
        f"model returned: {RETURNED_TEXT.get(returned, returned)}, order {summary['order']}"
        + ("" if linear_returned else f" (the linear {summary['method']} model it started from is not returned)"),
        f"{summary['method']}: order {summary['order']}, {summary['passes_run']} passes, "
        f"{summary['discretization']} discretisation, {summary['seconds']:.2f} s, {converged}",
        f"eigenvalues ({kind}-time{'' if linear_returned else ', of the linear model'}): {eigen}",
    ]
    how = (f"{summary['horizon']}-step-ahead prediction" if summary.get("horizon")
           else f"simulation, initial state {summary.get('initial_state', 'zero')}")
    lines.append(f"{'NRMSE fit %':<14} {'estimation':>28} {'validation':>28}   ({how}; R of eq. 17 beside)")
    for i, name in enumerate(data.output_names):
        est = _fit_and_R(summary["estimation_fit_percent"][i], _at(summary.get("estimation_R"), i))
        val = _fit_and_R(_at(summary.get("validation_fit_percent"), i), _at(summary.get("validation_R"), i))
        lines.append(f"{name:<14} {est:>28} {val:>28}")
    unstable = np.any(np.asarray(summary["eigenvalues"], dtype=complex).real > 0) and linear_returned
    lines.append(
        "simulated from rest over the estimation data (continuous model, exact): NRMSE fit "
        + ", ".join(f"{name} {_fit_and_R(fit, R)}" for name, fit, R in zip(data.output_names, summary["fit_percent"],
                                                                            summary["R"])) + " %"
        + (" (an unstable model's simulation diverges: the k-step scores above measure it)" if unstable else ""))
    if plan.validation:
        lines.append("validation on: " + "; ".join(plan.validation_names))
    for note in summary.get("notes", decision_notes(summary)):
        lines.append(f"note: {note}")
    if summary.get("p_tried"):
        tried = ", ".join(f"{row['p']:g}" + (f" {row['q_schedule']}" if "q_schedule" in row else "") + ": "
                          + ("failed" if row["cv_fit_percent"] is None else f"{row['cv_fit_percent']:.2f}")
                          for row in summary["p_tried"])
        lines.append(f"p {summary['p']:g}, {summary.get('q_schedule', 'constant')} Q, by two-fold cross-validation "
                     f"(NRMSE fit %: {tried}; a shrinking Q unless a constant one is {SCHEDULE_MARGIN:g} points better, "
                     f"the largest p within {P_TOLERANCE} points of its best), {summary['tuning_seconds']:.1f} s")
    if summary.get("scoring_note"):
        lines.append(f"note: {summary['scoring_note']}")
    for note in plan.notes:
        lines.append(f"note: {note}")
    if summary.get("orders_tried") and len(summary["orders_tried"]) > 1:
        tried = ", ".join(
            f"n={row['order']}: " + (f"{row['ranking_fit']:.2f}" if "ranking_fit" in row else "failed")
            for row in summary["orders_tried"])
        lines.append(f"orders tried (mean validation NRMSE fit %): {tried}; chosen {summary['order']} "
                     f"(smallest within {ORDER_TOLERANCE} points of the best)")
    if "nonlinear" in summary:
        nl = summary["nonlinear"]
        lines.append(f"nonlinear (spline, {nl['nodes']} nodes, p {nl['p']:g}, {nl['passes_run']} passes, "
                     f"{'converged' if nl['stop_reason'] == 'converged' else 'NOT converged'}"
                     f"{', returned' if returned == 'nonlinear' else ', NOT returned'}): NRMSE fit "
                     f"estimation {_fits(data.output_names, nl['estimation_fit_percent'])}; "
                     f"validation {_fits(data.output_names, nl['validation_fit_percent'])} %")
    if "model_file" in summary:
        lines.append(f"wrote {summary['model_file']}")
    if "modes" in summary:
        lines += uncertainty_lines(summary, data.output_names)
    if "scheduled" in summary:
        lines += scheduled_lines(summary["scheduled"], data.output_names)
    return "\n".join(lines)


def _plus_minus(value: float, std: float, digits: str) -> str:
    if not np.isfinite(std):
        return f"{value:{digits}}"
    return f"{value:{digits}} \u00b1 {2 * std:{digits}}"


def mode_lines(modes: Sequence[dict[str, Any]], *, title: str = "modes", channel: str | None = None) -> list[str]:
    """Each mode as value +/- 2 sigma under ``title``; a scheduled family's (``schedule_value``) by grid value."""
    covered = any(np.isfinite(mode["frequency_hz_std"]) for mode in modes)
    lines = [f"{title} (value \u00b1 2 sigma):" if covered else
             f"{title} (no parameter covariance: the model carries none):"]
    index, at = 0, None
    for mode in modes:
        if mode.get("schedule_value") is not None and mode["schedule_value"] != at:
            at, index = mode["schedule_value"], 0
            lines.append(f"  at {channel or 'schedule'} = {at:.4g}:")
        index += 1
        re, im = mode["eigenvalue"]
        re_std, im_std = mode["eigenvalue_std"]
        eigen = f"({_plus_minus(re, re_std, '.4g')}) \u00b1 j({_plus_minus(im, im_std, '.4g')})" if im else \
            _plus_minus(re, re_std, '.4g')
        lines.append(
            f"{'    ' if at is not None else '  '}mode {index}: {eigen}; "
            f"{_plus_minus(mode['frequency_hz'], mode['frequency_hz_std'], '.4g')} Hz, "
            f"damping {_plus_minus(mode['damping'], mode['damping_std'], '.3f')}"
        )
    return lines


def uncertainty_lines(summary: dict[str, Any], output_names: Sequence[str]) -> list[str]:
    """Text lines: the returned model's modes as value +/- 2 sigma (first), the residual tests per output,
    then the modes of the linear model where another model is returned in its place."""
    channel = (summary.get("scheduled") or {}).get("channel")
    returned = summary.get("model_returned")
    title = f"modes of the returned {returned} model" if returned in ("scheduled", "nonlinear") else "modes"
    lines = mode_lines(summary["modes"], title=title + (" at rest" if returned == "nonlinear" else ""),
                       channel=channel)
    if any(np.isfinite(mode["frequency_hz_std"]) for mode in summary["modes"]) and summary.get("uncertainty_method"):
        lines.append(f"  standard deviations: {summary['uncertainty_method']['description']}")
    bound = summary["residual_tests"]["bound"]
    growing = any(mode["eigenvalue"][0] > 0 for mode in summary["modes"])
    lines.append(f"residual tests (99 %, {summary['residual_tests']['lags']} lags, bound {bound:.3g})"
                 + (", of a simulation from rest that an unstable mode makes diverge:" if growing else ":"))
    for name, output in zip(output_names, summary["residual_tests"]["outputs"]):
        if output["exact"]:
            lines.append(f"  {name}: fitted to rounding, no residual left to test")
            continue
        verdict = "white" if output["white"] else "NOT white"
        independent = "independent of the input" if output["independent"] else "correlated with the input"
        lines.append(f"  {name}: whiteness p = {output['residual_whiteness_p']:.3g} ({verdict}); input correlation "
                     f"max {output['input_correlation_max']:.3g}, p = {output['input_correlation_p']:.3g} ({independent})")
    if "innovation_nis" in summary:
        low, high = summary["innovation_nis_band"]
        last = float(summary["innovation_nis"][-1])
        state = "inside" if low <= last <= high else ("above: the filter's R is too small for these data" if last > high
                                                       else "below: the filter's R is too large for these data")
        lines.append(f"innovation NIS of the last pass {last:.3g}, band [{low:.3g}, {high:.3g}]: {state}")
    if summary.get("linear_modes"):
        lines += mode_lines(summary["linear_modes"], title="modes of the linear model (not returned; its matrices "
                                                           "and eigenvalues are the summary's)")
    return lines


def scheduled_lines(entry: dict[str, Any], output_names: Sequence[str]) -> list[str]:
    """The text face of the ``scheduled`` entry: the run, the unscheduled scores, and the family's modes where
    it is not returned (the returned model's modes head the summary's modes)."""
    unscheduled = entry["unscheduled"]
    validation = unscheduled.get("validation_fit_percent")
    returned = entry.get("model_returned")
    state = {"scheduled": "returned: the scores above are its own",
             "unscheduled": "NOT returned (the scores above are the unscheduled model's)",
             "nonlinear": "NOT returned (the scores above are the spline model's)"}.get(returned, "")
    lines = [
        f"scheduled on {entry['channel']} ({entry['knots']} knots, p {entry['p']:g}, {entry['passes_run']} passes, "
        f"{'converged' if entry['stop_reason'] == 'converged' else 'NOT converged'}): {state}; unscheduled "
        + ("start" if returned != "unscheduled" else "model") + ": NRMSE fit estimation "
        + ", ".join(f"{n} {v:.2f}" for n, v in zip(output_names, unscheduled["estimation_fit_percent"]))
        + ("" if validation is None else "; validation " + ", ".join(
            f"{n} {v:.2f}" for n, v in zip(output_names, validation))) + " %",
    ]
    if returned != "scheduled":
        lines.append(f"modes of the scheduled family (not returned) at {entry['channel']} (frequency Hz, damping; "
                     "+/- 2 sigma):")
        for row in entry["modes_at"]:
            modes = "; ".join(f"{mode['frequency_hz']:.4g} +/- {2 * mode['frequency_hz_std']:.2g} Hz, "
                              f"{mode['damping']:.3f} +/- {2 * mode['damping_std']:.2g}" for mode in row["modes"])
            sparse = " (extrapolated: too few samples at this knot)" if row.get("extrapolated") else ""
            lines.append(f"  {entry['channel']} = {row['value']:.4g}: {modes}{sparse}")
    if entry.get("uncertainty_method"):
        lines.append(f"  standard deviations: {entry['uncertainty_method']['description']}")
    return lines
