"""Does sensor noise cost the identified model hold-out fit on any output, or make the IEKF diverge?

The handling study's records in the linear regime (a tenth of the steer
amplitude, 10 s, excitation seeds 0 and 1) with and without the white sensor
noise of ``handling_study.SENSOR_NOISE`` (0.05 m/s^2 lateral acceleration,
0.003 rad/s yaw rate, 0.1 deg roll angle; noise seeds 100 and 101, not the 11
and 12 the invariant settings were tuned on: docs/iekf_tuning.md). Every
order 2-8 and every p of the command line's tuning grid
(``vehid.identification.automatic.tuning.P_GRID``) is identified as ``vehid identify --order N
--p P`` identifies it (:func:`vehid.identification.pipeline.identify`, the
model it returns), on the noise-free identification record and on the noisy
one.

Score, output by output: the NRMSE fit on the noisy validation record (its
own offsets removed, as ``identify --validation-file`` scores), of the noisy
run's model and of the noise-free run's model on the same noisy samples:
the reference holds the noise-free model's error and the noise together, so
that a noisy run loses only what the noise cost its model. The target:
every output of every noisy run within :data:`LOSS_TARGET` points of the
reference, no divergence. A mean over outputs is never the score: a yaw
rate that gains would hide a roll angle that collapses.

Per run it prints and records whether it diverged (the last good pass
returned, or no model), the model returned (filter or start), the fits per
output and the losses. Figures go to ``results/benchmarks.json`` under
``noisy_handling``; each run's fits per output (the noisy runs' on the noisy
record, the noise-free runs' on the noise-free validation record) are
compared with ``benchmarks/baselines/noisy_handling.json``, and an output
that lost more than a point there makes the script exit with status 1
(``--update-baseline`` writes this run's figures instead).

Usage: ``python benchmarks/noisy_handling.py [--excitation-seeds 0,1]
[--noise-seeds 100,101] [--orders 2,...,8] [--p 1e-4,...] [--update-baseline]``;
the defaults (84 noisy runs, 42 noise-free) take about an hour on two shared cores.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import _baselines as baselines  # beside this script, so on sys.path when it runs
from vehid.identification.assessment.validation import score
from vehid.identification.automatic.options import IdentifyOptions
from vehid.identification.automatic.tuning import P_GRID
from vehid.identification.errors import DivergenceError
from vehid.identification.pipeline import identify
from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.handling_study import HandlingConfig, make_records, with_sensor_noise

EXCITATION_SEEDS = (0, 1)
NOISE_SEEDS = (100, 101)
ORDERS = (2, 3, 4, 5, 6, 7, 8)
LOSS_TARGET = 3.0  # points of hold-out fit any output of a noisy run may lose against the noise-free model


def _numbers(text: str, kind: type) -> tuple:
    return tuple(kind(item) for item in text.split(",") if item.strip())


def identified(data, validation, order: int, p: float):
    """``identify``'s result at this order and p, validated on ``validation``; the message where it gave no model."""
    try:
        return identify(data, order=order, validation=validation, options=IdentifyOptions(p=p)), None
    except DivergenceError as exc:  # diverged before any good pass: no model
        return None, f"diverged: {exc}"


def per_output(values) -> list[float]:
    return [float(value) for value in values]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--excitation-seeds", type=lambda text: _numbers(text, int), default=EXCITATION_SEEDS)
    parser.add_argument("--noise-seeds", type=lambda text: _numbers(text, int), default=NOISE_SEEDS)
    parser.add_argument("--orders", type=lambda text: _numbers(text, int), default=ORDERS)
    parser.add_argument("--p", type=lambda text: _numbers(text, float), default=P_GRID)
    parser.add_argument("--update-baseline", action="store_true",
                        help="write this run's figures to benchmarks/baselines/noisy_handling.json instead of "
                             "comparing them with it")
    args = parser.parse_args(argv)

    rows, guarded = [], {}
    started = time.perf_counter()
    for excitation_seed in args.excitation_seeds:
        clean = make_records(HandlingConfig(duration=10.0, amplitude_scale=0.1, seed=excitation_seed))
        noisy = {seed: with_sensor_noise(clean, seed) for seed in args.noise_seeds}
        for order in args.orders:
            for p in args.p:
                began = time.perf_counter()
                reference, reference_error = identified(clean["identification"], clean["validation"], order, p)
                case = f"seeds {excitation_seed}/none | n={order} | p={p:g}"
                guarded[case] = per_output(reference.validation_fit_percent) if reference else []
                for noise_seed, records in noisy.items():
                    result, error = identified(records["identification"], records["validation"], order, p)
                    row = {"excitation_seed": excitation_seed, "noise_seed": noise_seed, "order": order, "p": p,
                           "noise_free_fit_on_clean_record": guarded[case] or None,
                           "noise_free_error": reference_error, "error": error}
                    if result is not None:
                        # the noisy validation record as identify prepared it (its own offsets removed)
                        held_out = result.plan.validation[0]
                        fit = per_output(result.validation_fit_percent)
                        row.update(fit_percent=fit, model_returned="start" if result.start_returned else "filter",
                                   diverged=result.divergence is not None,
                                   fit_on_clean_record=per_output(score(result.model, _centred(clean["validation"]))
                                                                  .fit))
                        if reference is not None:
                            noise_free = per_output(score(reference.model, held_out).fit)
                            row.update(noise_free_fit_percent=noise_free,
                                       loss_points=[a - b for a, b in zip(noise_free, fit)])
                    else:
                        row["diverged"] = True
                    guarded[f"seeds {excitation_seed}/{noise_seed} | n={order} | p={p:g}"] = row.get("fit_percent", [])
                    rows.append(row)
                    print(f"seeds {excitation_seed}/{noise_seed} n = {order} p = {p:g}: {_shown(row)}", flush=True)
                print(f"  ({time.perf_counter() - began:.0f} s)", flush=True)

    losses = [loss for row in rows for loss in row.get("loss_points", [])]
    worst = [max(row["loss_points"]) for row in rows if "loss_points" in row]
    figures = {
        "settings": {"excitation_seeds": list(args.excitation_seeds), "noise_seeds": list(args.noise_seeds),
                     "orders": list(args.orders), "p": list(args.p)},
        "score": "hold-out NRMSE fit % per output on the noisy validation record; reference: the noise-free run's "
                 "model on the same noisy samples",
        "runs": len(rows),
        "diverged": sum(bool(row.get("diverged")) for row in rows),
        "start_returned": sum(row.get("model_returned") == "start" for row in rows),
        "largest_loss_points": max(losses) if losses else None,
        "median_worst_output_loss_points": float(np.median(worst)) if worst else None,
        "runs_with_an_output_above_target": sum(value > LOSS_TARGET for value in worst),
        "loss_target_points": LOSS_TARGET,
        "rows": rows,
        "seconds": time.perf_counter() - started,
    }
    print(f"{figures['runs']} noisy runs: {figures['diverged']} diverged, the start returned by "
          f"{figures['start_returned']}; worst output's loss median {figures['median_worst_output_loss_points']}, "
          f"largest {figures['largest_loss_points']} points; {figures['runs_with_an_output_above_target']} runs "
          f"with an output above {LOSS_TARGET}")
    record_figures("noisy_handling", figures)
    figures["regressions"] = baselines.check(
        "noisy_handling", guarded, update=args.update_baseline,
        about={"benchmark": "benchmarks/noisy_handling.py", "settings": figures["settings"],
               "cases": "seeds excitation/noise (none: the noise-free run, scored on the noise-free validation "
                        "record) | order | p: hold-out NRMSE fit % per output on the validation record of the "
                        "same noise"})
    return figures


def _centred(record):
    """A record with its own means removed, as ``identify`` prepares a validation record."""
    return record.replace(u=record.u - record.u.mean(axis=0), y=record.y - record.y.mean(axis=0))


def _shown(row: dict) -> str:
    if "fit_percent" not in row:
        return f"no model ({row['error']})"
    text = "noisy " + " / ".join(f"{fit:.1f}" for fit in row["fit_percent"])
    if "noise_free_fit_percent" in row:
        text += (", noise-free model " + " / ".join(f"{fit:.1f}" for fit in row["noise_free_fit_percent"])
                 + ", loss " + " / ".join(f"{loss:+.1f}" for loss in row["loss_points"]))
    text += f" ({row['model_returned']} returned)" + (" DIVERGED" if row["diverged"] else "")
    return text


if __name__ == "__main__":
    outcome = main()
    sys.exit(1 if outcome["regressions"] else 0)
