"""The text of how sure a model is (modes with standard deviations); the checks themselves are the library's
(:mod:`vehid.identification.automatic.checks`).

The public JSON keys of the checks (a contract once released) are listed in
:mod:`vehid.identification.automatic.checks`.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from vehid.identification.automatic.checks import model_residual_tests, uncertainty_summary

__all__ = ["model_residual_tests", "uncertainty_summary", "uncertainty_lines"]


def _plus_minus(value: float, std: float, digits: str) -> str:
    if not np.isfinite(std):
        return f"{value:{digits}}"
    return f"{value:{digits}} \u00b1 {2 * std:{digits}}"


def uncertainty_lines(summary: dict[str, Any], output_names: Sequence[str]) -> list[str]:
    """Text lines: each mode as value +/- 2 sigma, and the residual tests per output."""
    covered = any(np.isfinite(mode["frequency_hz_std"]) for mode in summary["modes"])
    lines = ["modes (value \u00b1 2 sigma):" if covered else "modes (no parameter covariance: the model carries none):"]
    for index, mode in enumerate(summary["modes"], start=1):
        re, im = mode["eigenvalue"]
        re_std, im_std = mode["eigenvalue_std"]
        eigen = f"({_plus_minus(re, re_std, '.4g')}) \u00b1 j({_plus_minus(im, im_std, '.4g')})" if im else \
            _plus_minus(re, re_std, '.4g')
        lines.append(
            f"  mode {index}: {eigen}; {_plus_minus(mode['frequency_hz'], mode['frequency_hz_std'], '.4g')} Hz, "
            f"damping {_plus_minus(mode['damping'], mode['damping_std'], '.3f')}"
        )
    if covered and summary.get("uncertainty_method"):
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
    return lines
