"""Run the worked examples of the textbook appendix (sections A.2-A.5) with the classical estimators.

Kalman filter, RLS and batch least squares, GLS under coloured noise, the
positivity example in single precision, one UD' step, the joint EKF on a
bicycle model and the singular pencil model; see :mod:`vehid.scenarios.textbook`.
"""

from __future__ import annotations

import argparse
from typing import Any

NAME = "textbook"
GROUP = "study"
HELP = "run the textbook appendix's examples (LS, RLS, GLS, Kalman, EKF, pencil, UD') and print their numbers"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--compiled", action="store_true",
                        help="compile the EKF's lifted step to C (the default runs CasADi's virtual machine)")
    parser.set_defaults(handler=run)


def _text(summary: dict[str, Any]) -> str:
    lines = ["Kalman filter example (A.92: phi=1, P0=100, Q=25, R=15)",
             f"{'k':>3} {'P(k|k-1)':>12} {'K(k)':>10} {'P(k|k)':>12}"]
    for row in summary["kalman_example"]:
        lines.append(f"{row['k']:>3} {row['P_prior']:12.4f} {row['K']:10.4f} {row['P_post']:12.4f}")
    lines.append(f"    steady state P(k|k) = {summary['kalman_steady_state_P_post']:.4f}")
    rls = summary["rls_example"]["max_difference_to_batch"]
    lines.append("RLS started from a batch fit vs batch LS, largest difference: "
                 + ", ".join(f"{form} {value:.1e}" for form, value in rls.items()))
    gls = summary["gls_example"]
    lines.append(f"GLS vs LS under AR(1) noise, {gls['runs']} runs, true [a1, b1] = {gls['true']}:")
    lines.append(f"    LS  mean [{gls['ls_mean'][0]:.4f}, {gls['ls_mean'][1]:.4f}]"
                 f"   GLS mean [{gls['gls_mean'][0]:.4f}, {gls['gls_mean'][1]:.4f}]"
                 f" ({gls['gls_mean_passes']:.1f} passes)")
    positivity = summary["positivity_example"]
    lines.append(f"Single-parameter RLS in float32 (P0 = {positivity['P0']:.0e}, phi = 1.7 then 0.5): P(k)")
    for form in ("plain", "sqrt", "ud"):
        values = ["   nan" if v is None or v != v else f"{v:6.3f}" for v in positivity[form]["P"][:6]]
        lines.append(f"    {form:<6}" + " ".join(values))
    ud = summary["ud_example"]
    lines.append(f"UD' step: F = {ud['F']}, G = {ud['G']}, beta = {ud['beta']:.3f}, "
                 f"K = [{ud['K'][0]:.4f}, {ud['K'][1]:.4f}], D = [{ud['D'][0]:.4f}, {ud['D'][1]:.4f}]")
    ekf = summary["ekf_bicycle_example"]
    lines.append("EKF on a bicycle model, cornering stiffness [N/rad]: "
                 + ", ".join(f"{name} {est:,.0f} +/- {std:,.0f} (true {true:,.0f})" for name, est, std, true in
                             zip(("front", "rear"), ekf["estimate_N_per_rad"], ekf["std_N_per_rad"],
                                 ekf["true_N_per_rad"])))
    pencil = summary["pencil_example"]
    lines.append("Singular pencil joint estimate [a1 a2 b0 b1 b2]: "
                 + " ".join(f"{v:.4f}" for v in pencil["gamma"])
                 + "  (true " + " ".join(f"{v:g}" for v in pencil["true_gamma"]) + ")")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    from vehid.scenarios.textbook import run_all  # SciPy and CasADi when the command runs, not for its --help

    summary = run_all(compiled=args.compiled)
    return summary, _text(summary)
