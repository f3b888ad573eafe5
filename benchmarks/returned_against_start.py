"""Does the held-out part rank the model `identify` returns against its data start?

    python benchmarks/returned_against_start.py [--sets robot_arm,dryer] [--fractions 0.3,0.4]

For each public record of ``benchmarks/real_data.py`` (at each held-out
fraction; the cascaded tanks on their published validation record) and the
committed race-car log (steer in, yaw rate and lateral acceleration out, 40 %
held out), the default ``identify`` runs as the command runs it, and two
models are scored on the held-out part output by output: the model returned
and the data start the filter began from. Each is scored as ``identify``
scores (a stable model simulated from its least-squares initial state, an
unstable one predicted 10 samples ahead), on the whole held-out part and on
each of its :data:`PARTS` consecutive parts alone (each from its own initial
state).

The held-out part ranks the two on an output only where every part agrees
in sign with the whole part's difference (:func:`ranks`): a difference that
changes sign from one part to the next is one the held-out data do not
show. The run names each output on which the returned model trails its start
where the held-out part ranks them, and then exits with status 1.

Figures go to ``results/benchmarks.json`` under ``returned_against_start``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

import _real_records as records  # beside this script, so on sys.path when it runs

ROOT = Path(__file__).resolve().parents[1]
RACE_LOG = ROOT / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
#: Consecutive parts the held-out part is cut into: each keeps at least a quarter of it, enough samples for
#: an initial state and several of the slowest records' time constants.
PARTS = 4
FRACTIONS = (0.3, 0.3333, 0.35, 0.4)
RACE_CAR_FRACTION = 0.4


def ranks(whole: float, parts: Sequence[float]) -> bool:
    """Whether a difference of fits is one the held-out data show: every part's difference has the whole's sign.

    A zero difference, on the whole or on a part, ranks nothing.
    """
    sign = np.sign(whole)
    return bool(sign != 0 and all(np.sign(part) == sign for part in parts))


def compare(result: Any) -> dict[str, Any]:
    """The returned model and its data start scored on the run's held-out part, whole and in parts, per output."""
    from vehid.identification.assessment.validation import default_horizon, score
    from vehid.identification.automatic.returned import start_model

    validation = result.plan.validation
    validation = validation[0] if isinstance(validation, (list, tuple)) else validation
    models = {"returned": result.model, "start": start_model(result.estimator)}

    def fits(model: Any, data: Any) -> np.ndarray:
        return np.asarray(score(model, data, horizon=default_horizon(model)).fit, dtype=float)

    whole = {name: fits(model, validation) for name, model in models.items()}
    edges = np.linspace(0, validation.n_samples, PARTS + 1).astype(int)
    parts = [fits(models["returned"], validation[a:b]) - fits(models["start"], validation[a:b])
             for a, b in zip(edges[:-1], edges[1:])]
    difference = whole["returned"] - whole["start"]
    return {
        "model_returned": result.returned,
        "returned_fit_percent": whole["returned"].tolist(),
        "start_fit_percent": whole["start"].tolist(),
        "returned_minus_start": difference.tolist(),
        "returned_minus_start_by_part": [part.tolist() for part in parts],
        "held_out_ranks": [ranks(difference[k], [part[k] for part in parts]) for k in range(difference.size)],
    }


def cases(selected: Sequence[str] | None, fractions: Sequence[float]) -> list[tuple[str, str, dict[str, Any]]]:
    """Each case: its record's name, its split and the ``identify`` arguments that run it as the command does."""
    from vehid.identification import ReadSettings

    chosen = []
    for entry in records.RECORD_SETS:
        if selected and entry.name not in selected:
            continue
        reading = ReadSettings(inputs=entry.inputs, outputs=entry.outputs, dt=entry.dt)
        if entry.validation_path_columns is not None:
            inputs, outputs = entry.validation_path_columns
            chosen.append((entry.name, "published", dict(data=str(entry.file), reading=reading,
                                                         validation=str(entry.file), validation_inputs=inputs,
                                                         validation_outputs=outputs)))
            continue
        for fraction in fractions:
            chosen.append((entry.name, f"{fraction:g}", dict(data=str(entry.file), reading=reading,
                                                              validation=fraction)))
    if (not selected or "race_car" in selected) and RACE_LOG.exists():
        reading = ReadSettings(inputs=("delta",), outputs=("yawRate", "ayCG"), time_column="t")
        chosen.append(("race_car", f"{RACE_CAR_FRACTION:g}", dict(data=str(RACE_LOG), reading=reading,
                                                                  validation=RACE_CAR_FRACTION)))
    return chosen


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", default="", help="comma-separated records (default: all, and race_car)")
    parser.add_argument("--fractions", default=",".join(f"{f:g}" for f in FRACTIONS),
                        help="held-out fractions of the single records")
    args = parser.parse_args(argv)
    from vehid.identification import identify
    from vehid.scenarios.benchmarking import record_figures

    selected = [name for name in args.sets.split(",") if name]
    fractions = [float(f) for f in args.fractions.split(",") if f]
    started = time.perf_counter()
    figures: dict[str, Any] = {}
    trailing = []
    print(f"{'record':<16}{'split':>10}  returned / start, hold-out NRMSE fit % per output; returned minus start "
          f"on each of {PARTS} parts")
    for name, split, arguments in cases(selected, fractions):
        result = identify(arguments.pop("data"), **arguments)
        row = compare(result)
        figures[f"{name} | {split}"] = row
        for k, (ahead, ranked) in enumerate(zip(row["returned_minus_start"], row["held_out_ranks"])):
            by_part = " ".join(f"{part[k]:+.2f}" for part in row["returned_minus_start_by_part"])
            verdict = "ranked" if ranked else "not ranked"
            print(f"{name:<16}{split:>10}  {row['returned_fit_percent'][k]:.2f} / {row['start_fit_percent'][k]:.2f}"
                  f" ({ahead:+.2f}; parts {by_part}: {verdict})", flush=True)
            if ranked and ahead < 0:
                trailing.append(f"{name} at {split}, output {k + 1}: {ahead:+.2f} points")
    record_figures("returned_against_start", {
        "what": "hold-out NRMSE fit % per output of the model identify returns and of its data start, on the "
                f"whole held-out part and on each of {PARTS} consecutive parts (each from its own initial state)",
        "rule": "the held-out part ranks the two on an output where every part's difference has the whole's sign",
        "cases": figures, "trailing_where_ranked": trailing, "seconds": time.perf_counter() - started})
    if trailing:
        print("the returned model trails its start where the held-out part ranks them: " + "; ".join(trailing))
        return 1
    print("the returned model trails its start on no output where the held-out part ranks them")
    return 0


if __name__ == "__main__":
    sys.exit(main())
