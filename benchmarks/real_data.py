"""Hold-out fit of `vehid identify` on public measured records, against peer libraries, in one run.

    python benchmarks/real_data.py [--sets ballbeam,dryer] [--no-peers]

Records: the raw files under ``tests/data/`` (see each SOURCE.md), read and
split as ``benchmarks/_real_records.py`` states: the first 70 % of a record
estimates, the last 30 % validates; the cascaded tanks use their published
estimation and validation records. Score: NRMSE fit % per output on the
validation samples (MATLAB ``compare``), simulated from the validation input
from the least-squares initial state, the same for every linear model (the
spline model from rest, as ``identify --nonlinear`` scores it). Every method
scores the same centred samples (``_real_records.validation_offsets``).

Workbench rows run the command line a user runs on the raw file as
published, ``python -m vehid.scenarios.cli identify FILE --inputs .. --outputs ..
--dt .. --validation 0.3 --json`` (DaISy's headerless columns by number),
and read its ``validation_fit_percent``: default options ("iekf (default)"),
``--order auto``, ``--nonlinear`` on the nonlinear records, the paper's
absolute settings for contrast, and the comparators ``--method
arx|n4sid|output-error``. ``identify`` removes the estimation part's means
itself. The cascaded tanks' published validation record is a second pair
of variables (``uVal``, ``yVal``) in the same ``.mat`` file, named with
``--validation-inputs`` and ``--validation-outputs``.

Peers: SIPPY (N4SID, MOESP, CVA), nfoursid, python-control (Markov
parameters + ERA) and sysidentpy (FROLS ARX and degree-2 NARX) run in their
own virtual environment ``benchmarks/.peers-venv`` (created here on first
use, or by ``make bench-real``), never in the workbench's, through
``benchmarks/_peers_runner.py``.

The table goes to ``results/benchmarks.json`` under ``real_data``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import venv
from pathlib import Path

import numpy as np

import _real_records as records  # beside this script, so on sys.path when it runs

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

PEERS_VENV = HERE / ".peers-venv"
PEER_PACKAGES = ("sippy-unipi", "nfoursid", "control", "sysidentpy")
DEFAULT_ROW = "iekf (default)"
NONLINEAR_ROW = "iekf --nonlinear"
PAPER_SETTINGS = ("--start", "paper", "--timescale", "seconds", "--no-normalize", "--p", "1")
WORKBENCH_METHODS = (  # label, options after the data arguments
    (DEFAULT_ROW, ()),
    ("iekf --order auto", ("--order", "auto")),
    ("iekf, paper settings", PAPER_SETTINGS),  # the paper's absolute start, time unit and p, for contrast
    ("arx", ("--method", "arx")),
    ("n4sid", ("--method", "n4sid")),
    ("output-error", ("--method", "output-error")),
)


# ------------------------------------------------------------------ workbench
def _cli(args: list[str], timeout: float = 900) -> tuple[int, dict, float]:
    """Run ``python -m vehid.scenarios.cli`` with ``args`` (and --json); exit status, parsed JSON, wall seconds."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "vehid.scenarios.cli", *args, "--json", "--quiet"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)
    seconds = time.perf_counter() - start
    try:
        summary = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else {}
    except json.JSONDecodeError:
        summary = {"error": done.stdout.strip()[-300:]}
    if done.returncode and "error" not in summary:
        summary["error"] = done.stderr.strip()[-300:]
    return done.returncode, summary, seconds


def data_args(entry: records.RecordSet, scratch: Path) -> list[str]:
    """The raw file, its channels, its sample interval and the hold-out, as a user gives them to ``identify``."""
    args = [str(entry.file), "--inputs", ",".join(entry.inputs), "--outputs", ",".join(entry.outputs),
            "--dt", repr(entry.dt)]
    if entry.validation_path_columns is None:
        return [*args, "--validation", repr(records.HOLDOUT)]
    # the published validation variables of the same file, named as they are there
    inputs, outputs = entry.validation_path_columns
    return [*args, "--validation-file", str(entry.file), "--validation-inputs", ",".join(inputs),
            "--validation-outputs", ",".join(outputs)]


def methods(entry: records.RecordSet) -> tuple:
    """The workbench rows of a record: the spline-nonlinear IEKF too on the nonlinear records."""
    if entry.nonlinear:
        return (WORKBENCH_METHODS[0], (NONLINEAR_ROW, ("--nonlinear",)), *WORKBENCH_METHODS[1:])
    return WORKBENCH_METHODS


SUMMARY_KEYS = ("fit_percent", "estimation_fit_percent", "order", "passes_run", "stop_reason", "converged",
                "warnings", "validation_R", "horizon")


def run_workbench(entry: records.RecordSet, scratch: Path) -> dict:
    """One row per workbench method: exit status, hold-out fit per output, seconds, and the run's own account."""
    arguments = data_args(entry, scratch)
    shown = {str(entry.file): f"tests/data/{entry.path}"}
    rows: dict = {"command": "identify " + " ".join(shown.get(a, a) for a in arguments)}
    for label, extra in methods(entry):
        status, summary, seconds = _cli(["identify", *arguments, *extra])
        row: dict = {"options": " ".join(extra) or "(defaults)", "seconds": seconds, "exit_status": status}
        if status not in (0, 3):
            row["error"] = summary.get("error", "")
        else:
            row["validation_fit_percent"] = summary.get("validation_fit_percent")
        row.update({key: summary[key] for key in summary if key in SUMMARY_KEYS or "nonlinear" in key})
        if label == NONLINEAR_ROW and status in (0, 3):
            # the spline model's own hold-out fit; validation_fit_percent stays the linear start's
            row["linear_validation_fit_percent"] = row["validation_fit_percent"]
            row["validation_fit_percent"] = _nonlinear_validation_fit(summary)
        rows[label] = row
        print(f"   {label:<24} {_show(_mean_fit(row)):>9}  ({seconds:.1f} s, exit {status})", flush=True)
    return rows


def _nonlinear_validation_fit(summary: dict) -> list | None:
    """The spline model's hold-out fit from the ``identify --nonlinear`` summary."""
    return (summary.get("nonlinear") or {}).get("validation_fit_percent")


# ---------------------------------------------------------------------- peers
def peers_python() -> Path:
    """The peers' interpreter, creating their virtual environment on first use."""
    python = PEERS_VENV / "bin" / "python"
    if not python.exists():
        print(f"creating {PEERS_VENV.relative_to(ROOT)} with {', '.join(PEER_PACKAGES)}", flush=True)
        venv.create(PEERS_VENV, with_pip=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *PEER_PACKAGES],
                       check=True)
    return python


def run_peers(names: list[str]) -> dict:
    done = subprocess.run([str(peers_python()), str(HERE / "_peers_runner.py"), *names], capture_output=True,
                          text=True, timeout=3600)
    if done.returncode != 0:
        raise RuntimeError(f"peer runner failed: {done.stderr.strip()[-500:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------- table
def _mean_fit(row: dict) -> float | None:
    """Mean hold-out fit over outputs; None where the run failed, -inf where a simulation diverged."""
    fits = row.get("validation_fit_percent")
    if not fits:
        return None
    return float("-inf") if any(f is None for f in fits) else float(np.mean(fits))


def _show(value: float | None) -> str:
    if value is None:
        return "failed"
    if not np.isfinite(value):
        return "diverged"
    return "< -999" if value < -999 else f"{value:.1f}"


CLOSE = 2.0  # points: the goal is the default identify within this of the best peer on every set


def summarise(sets: dict) -> dict:
    """Per set: the best peer, the default identify against it, and the spline model against it on nonlinear sets."""
    summary = {}
    for name, rows in sets.items():
        def best(prefix):
            scored = [(m, _mean_fit(r)) for m, r in rows.items() if isinstance(r, dict) and m.startswith(prefix)]
            scored = [(m, f) for m, f in scored if f is not None and np.isfinite(f)]
            return max(scored, key=lambda item: item[1]) if scored else (None, None)

        peer, peer_fit = best("peer:")
        workbench, workbench_fit = best("workbench:")
        default = _mean_fit(rows.get(f"workbench:{DEFAULT_ROW}", {}))
        gap = None if default is None or peer_fit is None or not np.isfinite(default) else default - peer_fit
        entry = {
            "best_peer": peer, "best_peer_fit": peer_fit,
            "best_workbench": workbench, "best_workbench_fit": workbench_fit,
            "default_fit": default, "default_minus_best_peer": gap,
            "default_within_2_points": None if gap is None else gap >= -CLOSE,
            "default_ahead": None if gap is None else gap > 0,
        }
        if f"workbench:{NONLINEAR_ROW}" in rows:
            spline = _mean_fit(rows[f"workbench:{NONLINEAR_ROW}"])
            ok = spline is not None and np.isfinite(spline) and peer_fit is not None
            entry.update({"spline_fit": spline, "spline_minus_best_peer": spline - peer_fit if ok else None,
                          "spline_ahead": (spline > peer_fit) if ok else None})
        summary[name] = entry
    return summary


def print_table(sets: dict) -> None:
    methods_seen: list[str] = []
    for rows in sets.values():
        methods_seen += [m for m, r in rows.items() if isinstance(r, dict) and m not in methods_seen and "seconds" in r]
    names = list(sets)
    print("hold-out NRMSE fit % (mean over outputs); rows: method, columns: record")
    print(f"{'method':<36}" + "".join(f"{n:>15}" for n in names))
    for method in methods_seen:
        cells = "".join(f"{_show(_mean_fit(sets[n][method])) if method in sets[n] else '-':>15}" for n in names)
        print(f"{method:<36}{cells}")


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", help="comma-separated record sets (default: all)")
    parser.add_argument("--no-peers", action="store_true", help="score the workbench only")
    args = parser.parse_args(argv)
    names = args.sets.split(",") if args.sets else [entry.name for entry in records.RECORD_SETS]
    started = time.perf_counter()
    peers = {"sets": {}} if args.no_peers else run_peers(names)
    sets: dict = {}
    with tempfile.TemporaryDirectory(prefix="vehid-real-") as scratch:
        for name in names:
            entry = records.record_set(name)
            print(f"== {name}", flush=True)
            workbench = run_workbench(entry, Path(scratch))
            command = workbench.pop("command")
            rows = {f"workbench:{k}": v for k, v in workbench.items()}
            rows.update({f"peer:{k}": v for k, v in peers["sets"].get(name, {}).items()})
            (u_est, _), (u_val, _) = records.load(entry)
            sets[name] = {
                "file": entry.path, "dt": entry.dt, "dt_note": entry.dt_note, "command": command,
                "estimation_samples": len(u_est), "validation_samples": len(u_val), **rows,
            }
    figures = {
        "score": "validation NRMSE fit % per output (MATLAB compare); linear models from the least-squares initial "
                 "state, the spline model from rest (identify --nonlinear), NARX from the first measured outputs",
        "split": f"first {1 - records.HOLDOUT:.0%} estimates, last {records.HOLDOUT:.0%} validates, as identify "
                 f"--validation {records.HOLDOUT} (cascaded tanks: published estimation and validation records)",
        "offsets": "identify removes the estimation part's means (a separate validation record: its own); "
                   "the peers get the same centred samples",
        "order": "workbench: identify's default (4) unless the row says otherwise; peers: 4",
        "peer_settings": peers.get("settings"),
        "peer_versions": peers.get("versions"),
        "sets": sets,
        "summary": summarise(sets),
        "seconds": time.perf_counter() - started,
        "load_average_1min": os.getloadavg()[0],
    }
    print_table(sets)
    for name, entry in figures["summary"].items():
        print(f"{name}: default {_show(entry['default_fit'])} against best peer {entry['best_peer']} "
              f"{_show(entry['best_peer_fit'])}" + (f"; spline {_show(entry['spline_fit'])}" if "spline_fit" in entry
                                                     else ""))
    from vehid.scenarios.benchmarking import record_figures

    print(f"figures written to {record_figures('real_data', figures)}")
    return figures


if __name__ == "__main__":
    main()
