"""The text of how sure a model is (modes with standard deviations); the checks themselves are the library's
(:mod:`vehid.identification.automatic.reported_checks`).

The public JSON keys of the checks (a contract once released) are listed in
:mod:`vehid.identification.automatic.reported_checks`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from vehid.identification.automatic.reported_checks import model_residual_tests, uncertainty_summary

__all__ = ["model_residual_tests", "uncertainty_summary", "uncertainty_lines", "mode_lines"]


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
