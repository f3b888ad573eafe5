"""The real-car table: every identification path on the committed race car's lap, 40 % held out.

The log is ``tests/data/race_car_250lm`` (a race car on a track, 80 s at 100 Hz, speed 16-60 m/s,
lateral acceleration to 1.38 g; its SOURCE.md names source and licence). Mass and geometry are not
published: the single-track runs assume 1100 kg and 1.2 m to each axle, which leave the understeer
gradient and the characteristic speed unchanged (they depend on stiffness per unit mass only).

Rows: the default (``--order auto``), ``--schedule vx``, ``--nonlinear --order 2``,
``--schedule vx --nonlinear``, and ``--structure single-track --schedule vx`` with linear and
saturating axles, each with and without the measured sideslip as a fitted quantity. Each row gives
the hold-out fit per output; a single-track row also its parameters with std and its handling
numbers, and where sideslip is measured but not fitted, the fit of the model's predicted sideslip
on the held-out part. ``vehid handling`` of each saved modal model at 20/30/40 m/s where it applies.
Figures go to ``results/benchmarks.json`` under ``real_car``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from vehid.identification.data import IOData
from vehid.identification.filtering.greybox_structure import simulate_greybox
from vehid.identification.assessment.metrics import nrmse_fit
from vehid.scenarios.benchmarking import record_figures
from vehid.vehicle.single_track import SingleTrackConfig, single_track_model

LOG = Path(__file__).resolve().parents[1] / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
VALIDATION = 0.4
MASS, LF, LR = 1100.0, 1.2, 1.2
HANDLING_SPEEDS = (20.0, 30.0, 40.0)
VEHID = [sys.executable, "-m", "vehid.scenarios.cli"]
MODAL = {
    "default": ("--order", "auto"),
    "schedule": ("--schedule", "vx"),
    "nonlinear": ("--nonlinear", "--order", "2"),
    "schedule_nonlinear": ("--schedule", "vx", "--nonlinear"),
}
SINGLE_TRACK = {
    "single_track": (),
    "single_track_sideslip": (),
    "single_track_saturation": ("--saturation",),
    "single_track_saturation_sideslip": ("--saturation",),
}


def _run(arguments: list[str]) -> tuple[dict[str, Any], float]:
    began = time.perf_counter()
    completed = subprocess.run([*VEHID, *arguments, "--json"], capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - began
    if completed.returncode not in (0, 3):
        raise RuntimeError(f"vehid {' '.join(arguments)} exited {completed.returncode}: {completed.stderr.strip()}")
    return json.loads(completed.stdout), seconds


def _held_out_sideslip_fit(row: dict[str, Any], saturation: bool) -> float:
    """Fit (%) of the single-track model's predicted sideslip on the held-out part, sideslip not fitted."""
    data = np.genfromtxt(LOG, delimiter=",", skip_header=2)
    held_out = data[int(round((1.0 - VALIDATION) * len(data))):]
    config = SingleTrackConfig(MASS, LF, LR, saturation=saturation,
                               quantities=("yaw_rate", "lateral_acceleration", "sideslip"))
    record = IOData(t=held_out[:, 0] - held_out[0, 0], u=held_out[:, [1, 2]], y=held_out[:, [3, 4, 5]])
    theta = [row["physical_parameters"][name]["value"] for name in config.parameter_names]
    from vehid.scenarios.single_track_identify import _substeps

    y_hat, _ = simulate_greybox(single_track_model(config), theta, record, substeps=_substeps(config, record))
    return float(nrmse_fit(record.y[:, 2:], y_hat[:, 2:])[0])


def main() -> dict[str, Any]:
    figures: dict[str, Any] = {"log": LOG.name, "validation": VALIDATION, "rows": {}}
    common = [str(LOG), "--inputs", "delta", "--validation", str(VALIDATION)]
    with tempfile.TemporaryDirectory(prefix="vehid-real-car-") as folder:
        for name, options in MODAL.items():
            saved = Path(folder) / f"{name}.json"
            summary, seconds = _run(["identify", *common, "--outputs", "yawRate,ayCG", *options,
                                     "--save-model", str(saved)])
            row: dict[str, Any] = {"validation_fit_percent": summary["validation_fit_percent"], "seconds": seconds,
                                   "warnings": summary.get("warnings", [])}
            try:
                handling, _ = _run(["handling", str(saved), "--speeds", ",".join(f"{v:g}" for v in HANDLING_SPEEDS),
                                    "--yaw-rate", "yawRate", "--lateral-acceleration", "ayCG", "--steer", "delta",
                                    "--wheelbase", str(LF + LR)])
                row["handling"] = [{key: metric[key] for key in ("speed", "yaw_rate_gain", "understeer_gradient_deg_per_g",
                                                                "characteristic_speed_m_s", "yaw_rate_response_time_s")}
                                   for metric in handling["metrics"]]
            except RuntimeError as error:  # a one-speed model answers at its own speed only
                row["handling"] = str(error).splitlines()[-1]
            figures["rows"][name] = row
        for name, options in SINGLE_TRACK.items():
            sideslip = name.endswith("sideslip")
            outputs, quantities = (("yawRate,ayCG,beta_true", "yaw_rate,lateral_acceleration,sideslip") if sideslip
                                   else ("yawRate,ayCG", "yaw_rate,lateral_acceleration"))
            summary, seconds = _run(["identify", *common, "--structure", "single-track", "--schedule", "vx",
                                     "--outputs", outputs, "--quantities", quantities, "--mass", str(MASS),
                                     "--lf", str(LF), "--lr", str(LR), *options])
            row = {key: summary[key] for key in ("validation_fit_percent", "physical_parameters", "handling",
                                                  "warnings")}
            row["seconds"] = seconds
            if not sideslip:
                row["sideslip_prediction_fit_percent"] = _held_out_sideslip_fit(summary, bool(options))
            figures["rows"][name] = row
    _print(figures)
    path = record_figures("real_car", figures)
    print(f"figures in {path}")
    return figures


def _print(figures: dict[str, Any]) -> None:
    print(f"real car ({figures['log']}, last {figures['validation']:g} held out): hold-out NRMSE fit %")
    for name, row in figures["rows"].items():
        fits = " / ".join(f"{fit:6.1f}" for fit in row["validation_fit_percent"])
        extra = ""
        if "sideslip_prediction_fit_percent" in row:
            extra = f"   predicted sideslip {row['sideslip_prediction_fit_percent']:6.1f}"
        print(f"  {name:<34} {fits}{extra}   ({row['seconds']:.0f} s, {len(row['warnings'])} warnings)")
        for parameter, entry in row.get("physical_parameters", {}).items():
            print(f"      {parameter:<27} {entry['value']:12.5g} +/- {entry['std']:.3g} {entry['unit']}")
        handling = row.get("handling")
        if isinstance(handling, dict):
            for key in ("understeer_gradient_deg_per_g", "characteristic_speed_m_s", "critical_speed_m_s"):
                if key in handling:
                    print(f"      {key:<27} {handling[key]['value']:12.4g} +/- {handling[key]['std']:.3g}")
        elif isinstance(handling, list):
            for metric in handling:
                gain, gradient = metric["yaw_rate_gain"], metric["understeer_gradient_deg_per_g"]
                print(f"      at {metric['speed']:4.0f} m/s: yaw-rate gain {gain['value']:.3g} +/- {gain['std']:.2g} 1/s, "
                      f"understeer gradient {gradient['value']:.3g} +/- {gradient['std']:.2g} deg/g")
        elif handling:
            print(f"      handling: {handling}")


if __name__ == "__main__":
    main()
