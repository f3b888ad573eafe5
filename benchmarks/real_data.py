"""Hold-out fit of `vehid identify` on public measured records, against peer libraries, in one run.

    python benchmarks/real_data.py [--sets ballbeam,dryer] [--no-peers]

Records: the raw files under ``tests/data/`` (see each SOURCE.md), read and
split as ``benchmarks/_real_records.py`` states: the first 70 % of a record
estimates, the last 30 % validates; the cascaded tanks use their published
estimation and validation records. Score: NRMSE fit % per output on the
validation samples (MATLAB ``compare``), simulated from the validation input
from the least-squares initial state, the same for every linear model.

Workbench rows run the command line a user runs, ``python -m scenarios.cli
identify FILE --json`` with default options (order 4, the IEKF), and the same
with ``--normalize``, and its comparators ``--method arx|n4sid|output-error``;
the two IEKF rows once more with time counted in hundredths of the published
unit ("dt x 0.01"), which shows what the units of time alone do to the result;
on the nonlinear records also ``--nonlinear`` where ``identify`` offers it.
When ``identify`` offers ``--validation FRACTION`` (and ``--validation-file``
for a separate validation record), its own ``validation_fit_percent`` is the
score; otherwise the benchmark hands it the estimation part only, takes the
model it saves (``--save-model``) and simulates it on the validation part
with the workbench's own simulation. Each workbench row is run on the
record as published ("raw": offsets and units as measured) and on the record
with the estimation means removed ("centred"), which is what the peers get.
The benchmark first offers the raw file itself to ``identify``; if that fails
it records the error and gives a CSV copy of the same numbers instead.

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
# label, options, factor on the time base: the IEKF's start values are absolute (rad/s), so the same samples with
# time counted in hundredths show how much of a result is owed to the units of time alone.
WORKBENCH_METHODS = (
    ("iekf", (), 1.0),
    ("iekf --normalize", ("--normalize",), 1.0),
    ("iekf, dt x 0.01", (), 0.01),
    ("iekf --normalize, dt x 0.01", ("--normalize",), 0.01),
    ("arx", ("--method", "arx"), 1.0),
    ("n4sid", ("--method", "n4sid"), 1.0),
    ("output-error", ("--method", "output-error"), 1.0),
)
FORMS = ("raw", "centred")


# ------------------------------------------------------------------ workbench
def _cli(args: list[str], timeout: float = 900) -> tuple[int, dict, float]:
    """Run ``python -m scenarios.cli`` with ``args`` (and --json); exit status, parsed JSON, wall seconds."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "scenarios.cli", *args, "--json", "--quiet"], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=timeout)
    seconds = time.perf_counter() - start
    try:
        summary = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else {}
    except json.JSONDecodeError:
        summary = {"error": done.stdout.strip()[-300:]}
    if done.returncode and "error" not in summary:
        summary["error"] = done.stderr.strip()[-300:]
    return done.returncode, summary, seconds


def identify_options() -> set[str]:
    """The options ``vehid identify`` offers, from its --help."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    text = subprocess.run([sys.executable, "-m", "scenarios.cli", "identify", "--help"], cwd=ROOT, env=env,
                          capture_output=True, text=True).stdout
    return {word.strip(",[]") for word in text.split() if word.startswith("--")}


def _write_csv(path: Path, u: np.ndarray, y: np.ndarray, dt: float) -> Path:
    names = [f"u{i + 1}" for i in range(u.shape[1])] + [f"y{i + 1}" for i in range(y.shape[1])]
    t = np.arange(len(u)) * dt
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header=",".join(["t", *names]), comments="",
               fmt="%.17g")  # 17 digits: the copy holds exactly the same doubles
    return path


def _column_args(entry: records.RecordSet, n_u: int, n_y: int, *, raw: bool, dt: float) -> list[str]:
    """--inputs, --outputs, --dt: the published column names of the raw file, or those of the CSV copy."""
    inputs = entry.inputs if raw else [f"u{i + 1}" for i in range(n_u)]
    outputs = entry.outputs if raw else [f"y{i + 1}" for i in range(n_y)]
    return ["--inputs", ",".join(inputs), "--outputs", ",".join(outputs), "--dt", repr(dt)]


def _workbench_fit(model_file: Path, u_val: np.ndarray, y_val: np.ndarray, dt: float) -> list[float]:
    """Hold-out fit of a saved workbench model, simulated by the workbench from the least-squares initial state."""
    from identification.modal import ModalModel

    model = ModalModel.from_dict(json.loads(model_file.read_text()))
    return records.fit_of_linear_simulator(lambda u, x0: model.simulate(u, dt, x0=x0), model.structure.n, u_val, y_val)


def _data_args(entry: records.RecordSet, form: str, time_factor: float, holdout_in_cli: bool, raw_file: bool,
               estimation, validation, scratch: Path) -> list[str]:
    """DATA and its options for ``identify``: the raw file where it is read, else a CSV copy of the same numbers."""
    (ue, ye), (uv, yv) = estimation, validation
    dt = entry.dt * time_factor
    separate = entry.validation_path_columns is not None
    if raw_file and form == "raw" and holdout_in_cli and not separate and time_factor == 1:
        columns = _column_args(entry, ue.shape[1], ye.shape[1], raw=True, dt=dt)
        return [str(entry.file), *columns, "--validation", repr(records.HOLDOUT)]
    stem = scratch / f"{entry.name}_{form}_{time_factor:g}"
    columns = _column_args(entry, ue.shape[1], ye.shape[1], raw=False, dt=dt)
    if not holdout_in_cli:
        return [str(_write_csv(Path(f"{stem}_est.csv"), ue, ye, dt)), *columns]
    if separate:
        return [str(_write_csv(Path(f"{stem}_est.csv"), ue, ye, dt)), *columns,
                "--validation-file", str(_write_csv(Path(f"{stem}_val.csv"), uv, yv, dt))]
    full = _write_csv(Path(f"{stem}_full.csv"), np.vstack([ue, uv]), np.vstack([ye, yv]), dt)
    return [str(full), *columns, "--validation", repr(records.HOLDOUT)]


def _methods(entry: records.RecordSet, options: set[str], holdout_in_cli: bool) -> tuple:
    """The workbench rows for a record: the spline-nonlinear IEKF too on nonlinear records, where identify has it."""
    if entry.nonlinear and holdout_in_cli and "--nonlinear" in options:
        return (*WORKBENCH_METHODS, ("iekf --nonlinear", ("--nonlinear",), 1.0))
    return WORKBENCH_METHODS


def run_workbench(entry: records.RecordSet, options: set[str], scratch: Path) -> dict:
    (u_est, y_est), (u_val, y_val) = records.load(entry)
    separate = entry.validation_path_columns is not None
    holdout_in_cli = "--validation-file" in options if separate else "--validation" in options
    result: dict = {"validation_by": "identify --validation" if holdout_in_cli
                    else "benchmark simulation of --save-model"}
    # Offer the raw file as published; where identify cannot read it, a CSV copy of the same numbers is used.
    columns = _column_args(entry, u_est.shape[1], y_est.shape[1], raw=True, dt=entry.dt)
    status, summary, _ = _cli(["identify", str(entry.file), *columns, "--method", "arx"])
    result["raw_file_read"] = status == 0
    if status != 0:
        result["raw_file_error"] = summary.get("error", f"exit status {status}")
    u_offset, y_offset = u_est.mean(axis=0), y_est.mean(axis=0)
    for form in FORMS:
        shift_u, shift_y = (u_offset, y_offset) if form == "centred" else (0.0, 0.0)
        estimation, validation = (u_est - shift_u, y_est - shift_y), (u_val - shift_u, y_val - shift_y)
        for label, extra, time_factor in _methods(entry, options, holdout_in_cli):
            data_args = _data_args(entry, form, time_factor, holdout_in_cli, result["raw_file_read"], estimation,
                                   validation, scratch)
            model_file = scratch / f"{entry.name}_{form}_{len(result)}.json"
            status, summary, seconds = _cli(["identify", *data_args, *extra, "--save-model", str(model_file)])
            row: dict = {"seconds": seconds, "exit_status": status}
            if status not in (0, 3):
                row["error"] = summary.get("error", "")
            elif holdout_in_cli:
                row["validation_fit_percent"] = summary.get("validation_fit_percent")
            else:
                row["validation_fit_percent"] = _workbench_fit(model_file, *validation, entry.dt * time_factor)
            for key in summary:
                if key in ("fit_percent", "passes_run", "stop_reason", "warnings") or "nonlinear" in key:
                    row[key] = summary[key]
            result[f"{label} [{form}]"] = row
    return result


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


def summarise(sets: dict) -> dict:
    """Best peer and best workbench row per set, by mean hold-out fit over outputs."""
    summary = {}
    for name, rows in sets.items():
        def best(prefix_filter):
            scored = [(m, _mean_fit(r)) for m, r in rows.items() if isinstance(r, dict) and prefix_filter(m)]
            scored = [(m, f) for m, f in scored if f is not None and np.isfinite(f)]
            return max(scored, key=lambda item: item[1]) if scored else (None, None)
        peer = best(lambda m: m.startswith("peer:"))
        default = _mean_fit(rows.get("workbench:iekf [raw]", {}))
        summary[name] = {
            "best_peer": peer[0], "best_peer_fit": peer[1],
            "best_workbench": best(lambda m: m.startswith("workbench:"))[0],
            "best_workbench_fit": best(lambda m: m.startswith("workbench:"))[1],
            "default_iekf_fit": default,
            "default_minus_best_peer": None if default is None or peer[1] is None else default - peer[1],
        }
    return summary


def print_table(sets: dict) -> None:
    methods: list[str] = []
    for rows in sets.values():
        methods += [m for m, r in rows.items() if isinstance(r, dict) and m not in methods and "seconds" in r]
    names = list(sets)
    print("hold-out NRMSE fit % (mean over outputs); rows: method, columns: record")
    print(f"{'method':<48}" + "".join(f"{n:>15}" for n in names))
    for method in methods:
        cells = "".join(f"{_show(_mean_fit(sets[n][method])) if method in sets[n] else '-':>15}" for n in names)
        print(f"{method:<48}{cells}")


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", help="comma-separated record sets (default: all)")
    parser.add_argument("--no-peers", action="store_true", help="score the workbench only")
    args = parser.parse_args(argv)
    names = args.sets.split(",") if args.sets else [entry.name for entry in records.RECORD_SETS]
    options = identify_options()
    started = time.perf_counter()
    peers = {"sets": {}} if args.no_peers else run_peers(names)
    sets: dict = {}
    with tempfile.TemporaryDirectory(prefix="vehid-real-") as scratch:
        for name in names:
            entry = records.record_set(name)
            print(f"== {name}", flush=True)
            workbench = run_workbench(entry, options, Path(scratch))
            rows = {f"workbench:{k}": v for k, v in workbench.items() if isinstance(v, dict)}
            rows.update({f"peer:{k}": v for k, v in peers["sets"].get(name, {}).items()})
            (u_est, _), (u_val, _) = records.load(entry)
            sets[name] = {
                "file": entry.path, "dt": entry.dt, "dt_note": entry.dt_note,
                "estimation_samples": len(u_est), "validation_samples": len(u_val),
                "raw_file_read": workbench["raw_file_read"],
                **({"raw_file_error": workbench["raw_file_error"]} if "raw_file_error" in workbench else {}),
                "validation_by": workbench["validation_by"], **rows,
            }
    figures = {
        "score": "validation NRMSE fit % per output (MATLAB compare), least-squares initial state",
        "split": f"first {1 - records.HOLDOUT:.0%} estimates, last {records.HOLDOUT:.0%} validates "
                 "(cascaded tanks: published estimation and validation records)",
        "order": 4,
        "peer_settings": peers.get("settings"),
        "peer_versions": peers.get("versions"),
        "sets": sets,
        "summary": summarise(sets),
        "seconds": time.perf_counter() - started,
        "load_average_1min": os.getloadavg()[0],
    }
    print_table(sets)
    from scenarios.benchmarking import record_figures

    print(f"figures written to {record_figures('real_data', figures)}")
    return figures


if __name__ == "__main__":
    main()
