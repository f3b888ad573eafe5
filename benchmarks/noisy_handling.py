"""Does sensor noise cost the IEKF hold-out fit, or make it diverge?

The handling study's records in the linear regime (a tenth of the steer
amplitude, 10 s, excitation seeds 0-4) with and without the white sensor
noise of ``handling_study.SENSOR_NOISE`` (0.05 m/s^2 lateral acceleration,
0.003 rad/s yaw rate, 0.1 deg roll angle; noise seeds 11 and 12). Every
order 2-8 and every p of the command line's tuning grid
(``identify_workflow.P_GRID``) is identified by the IEKF at its invariant
settings on the identification record, noise-free and noisy, and scored by
the NRMSE fit (initial state estimated) on the noise-free validation record:
the model's error alone, not the noise's.

Per run it prints and records whether it diverged (a DivergenceError; the
model scored is then the last good pass's, as the command line returns it), how many restarts with a smaller p it took, its fit and the noisy
run's loss against the noise-free run of the same record, order and p. The
target: no divergence, and every loss below 3 points. Figures go to
``results/benchmarks.json`` under ``noisy_handling``.

Usage: ``python benchmarks/noisy_handling.py [--excitation-seeds 0,1,...]
[--noise-seeds 11,12] [--orders 2,...,8] [--p 1e-4,...]``; the defaults are
the full study (ten seed pairs, 210 noisy runs), which takes hours on two
cores.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from vehid.identification.errors import DivergenceError
from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
from vehid.identification.models.modal import ModalStructure
from vehid.identification.assessment.validation import score
from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.handling_study import HandlingConfig, make_records, with_sensor_noise
from vehid.scenarios.identify_workflow import P_GRID

EXCITATION_SEEDS = (0, 1, 2, 3, 4)
NOISE_SEEDS = (11, 12)
ORDERS = (2, 3, 4, 5, 6, 7, 8)
PASSES = 50  # the command line's default
LOSS_TARGET = 3.0  # points of hold-out fit a noisy run may lose against the noise-free one


def _numbers(text: str, kind: type) -> tuple:
    return tuple(kind(item) for item in text.split(",") if item.strip())


def identify(data, order: int, p: float):
    """The IEKF result at the invariant settings (where it diverged the last good pass's, or None before
    the first), its restarts and its stop reason."""
    structure = ModalStructure.default(order, data.n_u, data.n_y)
    try:
        result = identify_iekf(data, structure, options=IEKFOptions.invariant(p=p, passes=PASSES),
                               parameter_covariance=False)
    except DivergenceError as exc:  # as the command line does: the last good pass's model, if any
        last = exc.last_good
        return last, int(last.meta.get("backed_off", 0)) if last else -1, f"diverged: {exc}"
    return result, int(result.meta.get("backed_off", 0)), result.stop_reason


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--excitation-seeds", type=lambda text: _numbers(text, int), default=EXCITATION_SEEDS)
    parser.add_argument("--noise-seeds", type=lambda text: _numbers(text, int), default=NOISE_SEEDS)
    parser.add_argument("--orders", type=lambda text: _numbers(text, int), default=ORDERS)
    parser.add_argument("--p", type=lambda text: _numbers(text, float), default=P_GRID)
    args = parser.parse_args(argv)

    rows = []
    for excitation_seed in args.excitation_seeds:
        clean = make_records(HandlingConfig(duration=10.0, amplitude_scale=0.1, seed=excitation_seed))
        truth = clean["validation"]
        noisy = {seed: with_sensor_noise(clean, seed)["identification"] for seed in args.noise_seeds}
        for order in args.orders:
            for p in args.p:
                began = time.perf_counter()
                reference, _, reference_stop = identify(clean["identification"], order, p)
                reference_fit = float(np.mean(score(reference.model, truth).fit)) if reference else None
                for noise_seed, data in noisy.items():
                    result, restarts, stop = identify(data, order, p)
                    fit = float(np.mean(score(result.model, truth).fit)) if result else None
                    loss = reference_fit - fit if reference_fit is not None and fit is not None else None
                    row = {"excitation_seed": excitation_seed, "noise_seed": noise_seed, "order": order, "p": p,
                           "noise_free_fit_percent": reference_fit, "noise_free_stop_reason": reference_stop,
                           "fit_percent": fit, "loss_points": loss, "restarts": restarts, "stop_reason": stop,
                           "diverged": stop.startswith("diverged"),
                           "notes": list(result.meta.get("notes", ())) if result else []}
                    rows.append(row)
                    shown = "no model" if fit is None else f"{fit:6.2f} % (loss {loss:+.2f}, restarts {restarts})"
                    shown += " DIVERGED" if row["diverged"] else ""
                    print(f"seeds {excitation_seed}/{noise_seed} n = {order} p = {p:g}: noise-free "
                          f"{reference_fit if reference_fit is None else round(reference_fit, 2)} %, noisy {shown}",
                          flush=True)
                print(f"  ({time.perf_counter() - began:.0f} s)", flush=True)

    losses = [row["loss_points"] for row in rows if row["loss_points"] is not None]
    figures = {
        "settings": {"excitation_seeds": list(args.excitation_seeds), "noise_seeds": list(args.noise_seeds),
                     "orders": list(args.orders), "p": list(args.p), "passes": PASSES},
        "runs": len(rows),
        "diverged": sum(row["diverged"] for row in rows),
        "restarted": sum(row["restarts"] > 0 for row in rows),
        "largest_loss_points": max(losses) if losses else None,
        "median_loss_points": float(np.median(losses)) if losses else None,
        "losses_above_target": sum(loss > LOSS_TARGET for loss in losses),
        "rows": rows,
    }
    print(f"{figures['runs']} noisy runs: {figures['diverged']} diverged, {figures['restarted']} restarted with a "
          f"smaller p; loss of hold-out fit median {figures['median_loss_points']}, largest "
          f"{figures['largest_loss_points']} points, {figures['losses_above_target']} above {LOSS_TARGET}")
    record_figures("noisy_handling", figures)
    return figures


if __name__ == "__main__":
    main()
