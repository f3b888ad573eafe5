"""Hold-out fit of `vehid identify` on public measured records, against peer libraries, in one run.

    python benchmarks/real_data.py [--sets ballbeam,dryer] [--fractions 0.3,0.4] [--seeds 0,1]
        [--kernels Sandybridge] [--default-only] [--no-perturbations]
        [--no-peers | --peers-from FILE ...] [--workbench-from FILE] [--order-rule holdout|estimation-split]

Records: the raw files under ``tests/data/`` (see each SOURCE.md), read and
split as ``benchmarks/_real_records.py`` states: the first 70 % of a record
estimates, the last 30 % validates; the cascaded tanks use their published
estimation and validation records. Score: NRMSE fit % per output on the
validation samples, as ``identify`` scores: a stable linear model simulated
from the validation input from the least-squares initial state (MATLAB
``compare``), an unstable one predicted 10 samples ahead, the workbench's
and the linear peers' models alike (``score_as_identify``; each peer row
keeps ``compare``'s own figure, simulated whatever the stability, as
``compare_fit_percent``); the spline model by the same rule, its initial state
estimated, as ``identify --nonlinear`` scores it. Every method scores the same centred samples
(``_real_records.validation_offsets``).

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
``benchmarks/_peers_runner.py``. Every peer gets the order search ``identify
--order 2-8`` gets: each order 2-8 is identified and the smallest within
identify's ``ORDER_TOLERANCE`` of the best is chosen; the fits that choose
are the held-out fits, as ``identify --validation 0.3 --order 2-8`` ranks its
orders, each scored as above (``--order-rule estimation-split`` chooses on
a split of the estimation part instead). Each peer's chosen order is
reported beside its fit.

Perturbations: per record, the default ``identify`` run again with the
held-out fraction at each of ``--fractions`` (a published validation record
has no fraction to move), on copies of the record with every number
multiplied by ``1 + 1e-6 N(0, 1)`` (``--seeds``), and under each OpenBLAS
kernel this CPU runs other than the one it picks (``OPENBLAS_CORETYPE``, set
for those subprocesses alone). The record's range is the spread of the
default's mean hold-out fit over all these runs; beside each fraction, the
best peer's fit at that fraction, and the fit of one fixed model (the
default's at the usual fraction) on that fraction's held-out part, whose
range is what the scored samples alone move (``fixed_model_range``). Each
run keeps the choices it made by itself (its ``decision_margins``), and
``switched_decisions`` names every decision whose choice differs between
the runs: a range without one comes from the data each run estimates on.
Each peer is held to the same two goals over the fractions
(``peers_against_the_goal``: its range and its worst gap to the best peer),
and beside the best peer at each fraction stands the best at the default's
own order (``best_peer_at_default_order``), the default not searching its
order.

The table goes to ``results/benchmarks.json`` under ``real_data``.

Regressions: every workbench row's hold-out fit per output at the usual
split, and the default's at every held-out fraction, are compared with the
figures committed in ``benchmarks/baselines/real_data.json``
(``_baselines.py``); an output that lost more than a point is named and the
script exits with status 1 (``--update-baseline`` writes this run's figures
there instead, after a change meant to move them).
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

import _baselines as baselines  # beside this script, so on sys.path when it runs
import _real_records as records

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
def _cli(args: list[str], timeout: float = 900, environment: dict[str, str] | None = None
         ) -> tuple[int, dict, float]:
    """Run ``python -m vehid.scenarios.cli`` with ``args`` (and --json); exit status, parsed JSON, wall seconds.

    ``environment`` adds variables to this subprocess's environment alone.
    """
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "vehid.scenarios.cli", *args, "--json", "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **environment} if environment else None)
    seconds = time.perf_counter() - start
    try:
        summary = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else {}
    except json.JSONDecodeError:
        summary = {"error": done.stdout.strip()[-300:]}
    if done.returncode and "error" not in summary:
        summary["error"] = done.stderr.strip()[-300:]
    return done.returncode, summary, seconds


def data_args(entry: records.RecordSet, scratch: Path, holdout: float = records.HOLDOUT,
              file: Path | None = None) -> list[str]:
    """The raw file, its channels, its sample interval and the hold-out, as a user gives them to ``identify``.

    ``file`` replaces the published file by a copy of it (``records.perturbed_copy``).
    """
    file = entry.file if file is None else file
    args = [str(file), "--inputs", ",".join(entry.inputs), "--outputs", ",".join(entry.outputs),
            "--dt", repr(entry.dt)]
    if entry.validation_path_columns is None:
        return [*args, "--validation", repr(holdout)]
    # the published validation variables of the same file, named as they are there
    inputs, outputs = entry.validation_path_columns
    return [*args, "--validation-file", str(file), "--validation-inputs", ",".join(inputs),
            "--validation-outputs", ",".join(outputs)]


def methods(entry: records.RecordSet) -> tuple:
    """The workbench rows of a record: the spline-nonlinear IEKF too on the nonlinear records."""
    if entry.nonlinear:
        return (WORKBENCH_METHODS[0], (NONLINEAR_ROW, ("--nonlinear",)), *WORKBENCH_METHODS[1:])
    return WORKBENCH_METHODS


SUMMARY_KEYS = ("fit_percent", "estimation_fit_percent", "order", "passes_run", "stop_reason", "converged",
                "warnings", "validation_R", "horizon")


def run_workbench(entry: records.RecordSet, scratch: Path, default_only: bool = False) -> dict:
    """One row per workbench method (the default alone if asked): exit status, hold-out fit per output, seconds,
    and the run's own account."""
    arguments = data_args(entry, scratch)
    shown = {str(entry.file): f"tests/data/{entry.path}"}
    rows: dict = {"command": "identify " + " ".join(shown.get(a, a) for a in arguments)}
    for label, extra in methods(entry)[:1] if default_only else methods(entry):
        status, summary, seconds = _cli(["identify", *arguments, *extra])
        row: dict = {"options": " ".join(extra) or "(defaults)", "seconds": seconds, "exit_status": status}
        if status not in (0, 3):
            row["error"] = summary.get("error", "")
        else:
            row["validation_fit_percent"] = summary.get("validation_fit_percent")
        row.update({key: summary[key] for key in summary if key in SUMMARY_KEYS or "nonlinear" in key})
        if label == NONLINEAR_ROW and status in (0, 3):
            # the spline model's own hold-out fit, and its linear start's (the model returned is the better)
            row["linear_validation_fit_percent"] = summary["orders_tried"][0]["validation_fit_percent"]
            row["validation_fit_percent"] = _nonlinear_validation_fit(summary)
        if label == DEFAULT_ROW and status in (0, 3):
            row["decisions"] = decisions_of(summary)
            # the default's model, to score on every other fraction's held-out part (not written out)
            row[FIXED_MODEL] = {key: summary.get(key) for key in ("method", "A", "B", "C", "D", "preparation")}
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
    if not python.exists() and (PEERS_VENV.exists() or PEERS_VENV.is_symlink()):
        # raised as the runner's own failure, so that the workbench's figures measured before are still written
        raise RuntimeError(f"{PEERS_VENV.relative_to(ROOT)} exists but holds no interpreter "
                           f"(a broken link or an interrupted creation): remove it to have it created again")
    if not python.exists():
        print(f"creating {PEERS_VENV.relative_to(ROOT)} with {', '.join(PEER_PACKAGES)}", flush=True)
        venv.create(PEERS_VENV, with_pip=True)
        subprocess.run([str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", *PEER_PACKAGES],
                       check=True)
    return python


def run_peers(names: list[str], fractions: list[float], rule: str) -> dict:
    """The peers' order searches on the named records at each held-out fraction, by identify's own order rule."""
    from vehid.identification.automatic.plan import AUTO_HOLDOUT
    from vehid.identification.automatic.orders import ORDER_TOLERANCE

    done = subprocess.run([str(peers_python()), str(HERE / "_peers_runner.py"), *names,
                           "--fractions", ",".join(repr(f) for f in fractions), "--rule", rule,
                           "--tolerance", repr(ORDER_TOLERANCE), "--inner-holdout", repr(AUTO_HOLDOUT)],
                          capture_output=True, text=True, timeout=3 * 3600)
    if done.returncode != 0:
        raise RuntimeError(f"peer runner failed: {done.stderr.strip()[-500:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def saved_peers(paths: list[Path], names: list[str], fractions: list[float], rule: str) -> dict:
    """Earlier outputs of the peers' runner, merged and checked to cover these records and fractions by this rule."""
    from vehid.identification.automatic.orders import ORDER_TOLERANCE

    merged: dict = {"sets": {}}
    for path in paths:
        try:
            peers = json.loads(Path(path).read_text().strip().splitlines()[-1])
        except (OSError, ValueError, IndexError) as exc:
            raise ValueError(f"cannot read the peers' results {path}: {exc}") from None
        settings = peers.get("settings") or {}
        if settings.get("order_rule") != rule or settings.get("order_tolerance") != ORDER_TOLERANCE:
            raise ValueError(f"{path} chose orders by {settings.get('order_rule')!r} within "
                             f"{settings.get('order_tolerance')} points, not {rule!r} within {ORDER_TOLERANCE}")
        merged.update(settings=settings, versions=peers.get("versions"))
        merged["sets"].update(peers.get("sets") or {})
    for name in names:
        entry = records.record_set(name)
        missing = {_fraction(entry, f) for f in fractions} - set(merged["sets"].get(name, {}))
        if missing:
            raise ValueError(f"no peer results for {name} at {', '.join(sorted(missing))} in "
                             f"{', '.join(map(str, paths))}")
    return merged


def score_as_identify(peers: dict, rule: str) -> None:
    """Score every linear peer's models as ``identify`` scores its own, and choose its order again (in place).

    The peers' runner scores by MATLAB ``compare``'s rule: simulation from the
    least-squares initial state, whatever the model. ``identify`` simulates a
    stable model the same way but predicts an unstable one 10 samples ahead
    (``default_horizon``), which on the open-loop unstable ball and beam
    scores the same model several points lower (docs/measurements.md).
    Scoring both alike is the like for like comparison. Each such row keeps the runner's own order and fit as
    ``compare_order`` and ``compare_fit_percent``; ``scored_as`` says which
    rule ``validation_fit_percent`` follows. Rows without models (a NARX
    peer, an earlier runner's output) keep ``compare``'s rule. With the
    ``estimation-split`` rule the order stays the runner's (its inner models
    are not kept).
    """
    from vehid.identification.assessment.validation import default_horizon, score
    from vehid.identification.data import IOData
    from vehid.identification.errors import WorkbenchError
    from vehid.identification.models.discrete import DiscreteModel
    from vehid.identification.automatic.orders import ORDER_TOLERANCE

    for name, splits in (peers.get("sets") or {}).items():
        entry = records.record_set(name)
        for label, rows in splits.items():
            fraction = records.HOLDOUT if label == "published" else float(label)
            estimation, validation = records.load(entry, fraction)
            u_offset, y_offset = records.validation_offsets(entry, estimation, validation)
            held_out = IOData(t=np.arange(len(validation[0])) * entry.dt, u=validation[0] - u_offset,
                              y=validation[1] - y_offset)
            for row in rows.values():
                models = row.pop("models_by_order", None)
                if not models:
                    row["scored_as"] = "compare"
                    continue
                fits = {}
                for order, matrices in models.items():
                    try:
                        model = DiscreteModel(*(np.asarray(matrices[key], dtype=float) for key in "ABCD"), entry.dt)
                        per_output = score(model, held_out, horizon=default_horizon(model)).fit
                    except (WorkbenchError, np.linalg.LinAlgError):  # a peer's non-finite model: no fit
                        per_output = np.full(held_out.n_y, np.nan)
                    fits[int(order)] = [float(f) if np.isfinite(f) else None for f in per_output]
                means = {order: (float(np.mean(f)) if None not in f else None) for order, f in fits.items()}
                chosen = records.choose_order(means, ORDER_TOLERANCE) if rule == "holdout" else row.get("order")
                row.update(compare_order=row.get("order"), compare_fit_percent=row.get("validation_fit_percent"),
                           fit_by_order=means, scored_as="identify")
                if chosen is None or chosen not in fits:
                    row.pop("order", None)
                    row.pop("validation_fit_percent", None)
                    row["error"] = "no order gave a finite fit as identify scores"
                else:
                    row.update(order=chosen, validation_fit_percent=fits[chosen])


def saved_workbench(path: Path, names: list[str]) -> dict:
    """The workbench's rows and perturbed runs of these records from an earlier ``benchmarks.json``."""
    try:
        saved = json.loads(Path(path).read_text())["real_data"]["sets"]
    except (OSError, ValueError, KeyError) as exc:
        raise SystemExit(f"real_data.py: no real_data records in {path}: {exc}") from None
    sets = {}
    for name in names:
        if name not in saved:
            raise SystemExit(f"real_data.py: {path} holds no workbench results for {name}")
        rows = {k: v for k, v in saved[name].items() if not k.startswith("peer") and k != "perturbations"}
        spread = saved[name].get("perturbations")
        if spread:
            rows["perturbations"] = spread["runs"] if isinstance(spread, dict) else spread
        sets[name] = rows
    return sets


# -------------------------------------------------------------- perturbations
PERTURBATION = 1e-6  # relative size of the noise on every number of a perturbed copy
FRACTIONS = (0.3, 0.3333, 0.35, 0.4)
SEEDS = (0, 1)
# OpenBLAS's x86-64 kernel names, newest first; which of them this CPU runs is asked of OpenBLAS itself
KERNEL_CANDIDATES = ("SkylakeX", "Cooperlake", "Zen", "Haswell", "Sandybridge", "Nehalem", "Core2", "Prescott")
_CORENAME = """
import ctypes, glob, os, numpy
for library in glob.glob(os.path.join(os.path.dirname(numpy.__file__), os.pardir, "numpy.libs", "*openblas*")):
    for symbol in ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_",
                   "openblas_get_corename"):
        function = getattr(ctypes.CDLL(library), symbol, None)
        if function is not None:
            function.restype = ctypes.c_char_p
            numpy.ones((64, 64)) @ numpy.ones((64, 64))  # a kernel this CPU cannot run stops the process here
            print(function().decode())
            raise SystemExit
"""


def _kernel_in_use(coretype: str | None) -> str | None:
    """The OpenBLAS kernel NumPy uses in a subprocess with ``OPENBLAS_CORETYPE=coretype`` (None: not OpenBLAS)."""
    environment = {**os.environ, "OPENBLAS_CORETYPE": coretype} if coretype else \
        {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    done = subprocess.run([sys.executable, "-c", _CORENAME], capture_output=True, text=True, env=environment)
    return done.stdout.strip() or None


def other_kernels() -> list[str]:
    """The ``OPENBLAS_CORETYPE`` values that make OpenBLAS run a kernel other than the one it picks on this CPU.

    A name is kept only where the kernel OpenBLAS then reports is new and a
    matrix product runs under it (some builds load a kernel the CPU cannot
    execute, and the process dies on its first instruction).
    """
    chosen = _kernel_in_use(None)
    if chosen is None:
        return []
    seen, kernels = {chosen.lower()}, []
    for candidate in KERNEL_CANDIDATES:
        reported = _kernel_in_use(candidate)
        if reported and reported.lower() not in seen:
            seen.add(reported.lower())
            kernels.append(candidate)
    return kernels


FIXED_MODEL = "_model"  # a default row's key holding its model in memory; dropped before the results are written


def fixed_model_fits(entry: records.RecordSet, model: dict | None, fractions: list[float]) -> dict[str, float] | None:
    """Mean hold-out fit % of one fixed model, the default's at the usual fraction, on each fraction's held-out part.

    Moving the fraction changes which samples are scored as well as the data
    the default identifies from; a fixed model's spread over the same held-out
    parts is the part of the default's range that the samples alone make. The
    model is scored as ``identify`` scores it (first-order hold, least-squares
    initial state; k-step prediction where it is unstable), on the samples
    centred by the estimation part's means of its own run. None where the
    record has a published validation record, or the run gave no continuous
    IEKF model.
    """
    if entry.validation_path_columns is not None or not model or model.get("method") != "iekf" or not model.get("A"):
        return None
    from vehid.identification.data import IOData
    from vehid.identification.models.discrete import ContinuousModel
    from vehid.identification.assessment.validation import default_horizon, score

    fixed = ContinuousModel(*(np.asarray(model[key], dtype=float) for key in "ABCD"))
    input_offset = np.asarray(model["preparation"]["input_offset"], dtype=float)
    output_offset = np.asarray(model["preparation"]["output_offset"], dtype=float)
    fits = {}
    for fraction in sorted({records.HOLDOUT, *fractions}):
        _, (u, y) = records.load(entry, fraction)
        held_out = IOData(t=np.arange(len(u)) * entry.dt, u=u - input_offset, y=y - output_offset)
        fits[f"{fraction:g}"] = float(np.mean(score(fixed, held_out, horizon=default_horizon(fixed)).fit))
    return fits


def run_perturbations(entry: records.RecordSet, scratch: Path, default_row: dict, options) -> list[dict]:
    """The default ``identify`` run under each perturbation: held-out fraction, 1e-6 noise, BLAS kernel."""
    runs = [{"perturbation": "none", "fraction": _fraction(entry, records.HOLDOUT),
             "validation_fit_percent": default_row.get("validation_fit_percent"), "order": default_row.get("order"),
             "decisions": default_row.get("decisions"), "exit_status": default_row["exit_status"],
             "seconds": default_row["seconds"]}]
    plans: list[tuple[str, float, list[str], dict | None]] = []
    if entry.validation_path_columns is None:
        plans += [(f"fraction {f:g}", f, data_args(entry, scratch, f), None)
                  for f in options.fractions if f != records.HOLDOUT]
    for seed in options.seeds:
        copy = records.perturbed_copy(entry, scratch, PERTURBATION, seed)
        plans.append((f"samples x (1 + {PERTURBATION:g} N(0,1)), seed {seed}", records.HOLDOUT,
                      data_args(entry, scratch, file=copy), None))
    plans += [(f"OPENBLAS_CORETYPE={kernel}", records.HOLDOUT, data_args(entry, scratch),
               {"OPENBLAS_CORETYPE": kernel}) for kernel in options.kernels]
    for label, fraction, arguments, environment in plans:
        status, summary, seconds = _cli(["identify", *arguments], environment=environment)
        run = {"perturbation": label, "fraction": _fraction(entry, fraction), "exit_status": status,
               "seconds": seconds, "order": summary.get("order")}
        if status in (0, 3):
            run["validation_fit_percent"] = summary.get("validation_fit_percent")
            run["decisions"] = decisions_of(summary)
        else:
            run["error"] = summary.get("error", "")
        runs.append(run)
        print(f"   default, {label:<40} {_show(_mean_fit(run)):>9}  ({seconds:.1f} s, exit {status})", flush=True)
    return runs


def decisions_of(summary: dict) -> dict:
    """The choices one ``identify`` run made by itself (its ``decision_margins``), each with the Q schedule where
    the p decision names one: what to compare between perturbed runs to see whether a decision switched."""
    choices = {}
    for name, entry in (summary.get("decision_margins") or {}).items():
        choice = entry.get("choice")
        choices[name] = f"{choice}, {entry['q_schedule']} Q" if entry.get("q_schedule") else choice
    return choices


def switched_decisions(runs: list[dict]) -> dict[str, list]:
    """Each decision whose choice differs between the runs that report it, with the distinct choices in run order.

    A range with no switched decision comes from the data each run estimates on and scores on (the held-out
    part moves with the fraction); a switched one names the rule to look at.
    """
    seen: dict[str, list] = {}
    for run in runs:
        for name, choice in (run.get("decisions") or {}).items():
            if choice not in seen.setdefault(name, []):
                seen[name].append(choice)
    return {name: choices for name, choices in seen.items() if len(choices) > 1}


def _fraction(entry: records.RecordSet, fraction: float) -> str:
    """A split's name, as the peers' runner names it: the fraction, or ``published``."""
    return "published" if entry.validation_path_columns is not None else f"{fraction:g}"


def _best_peer(peer_rows: dict) -> tuple[str | None, float | None, int | None]:
    scored = [(m, _mean_fit(r), r.get("order")) for m, r in peer_rows.items()]
    scored = [item for item in scored if item[1] is not None and np.isfinite(item[1])]
    return max(scored, key=lambda item: item[1]) if scored else (None, None, None)


def best_peer_at_order(peer_rows: dict, order: int | None) -> tuple[str | None, float | None]:
    """The peer whose model of ``order`` states scores best (``fit_by_order``, as ``identify`` scores), and
    its fit: the like-for-like figure for a default that does not search its order."""
    if order is None:
        return None, None
    scored = []
    for name, row in peer_rows.items():
        fits = row.get("fit_by_order") or {}
        fit = fits.get(order, fits.get(str(order)))  # int keys as scored here, text keys once read from JSON
        if fit is not None and np.isfinite(fit):
            scored.append((name, fit))
    return max(scored, key=lambda item: item[1]) if scored else (None, None)


def peers_against_the_goal(peers_by_fraction: dict) -> dict[str, dict]:
    """Each peer held to the default's goals over the fractions it was run at: its fit's range, and its
    worst gap to the best peer (itself included) at the same fraction.

    A goal no peer meets on a record measures what that record's held-out parts can tell apart, not the
    workbench. A peer without a finite fit at some fraction gets None for both.
    """
    fractions = list(peers_by_fraction)
    if len(fractions) < 2:
        return {}
    best = {fraction: _best_peer(rows)[1] for fraction, rows in peers_by_fraction.items()}
    names = sorted({name for rows in peers_by_fraction.values() for name in rows})
    verdicts = {}
    for name in names:
        fits = [_mean_fit(peers_by_fraction[fraction].get(name, {})) for fraction in fractions]
        if any(fit is None or not np.isfinite(fit) for fit in fits):
            verdicts[name] = {"range": None, "worst_minus_best_peer": None, "meets_both": False}
            continue
        spread = max(fits) - min(fits)
        worst = min(fit - best[fraction] for fit, fraction in zip(fits, fractions))
        verdicts[name] = {"range": spread, "worst_minus_best_peer": worst,
                          "meets_both": bool(spread <= CLOSE and worst >= -CLOSE)}
    return verdicts


def perturbation_summary(runs: list[dict], peers_by_fraction: dict, fixed_fits: dict[str, float] | None = None
                         ) -> dict:
    """The default's range over the perturbed runs, and the best peer against the default at each fraction.

    ``fixed_fits`` (:func:`fixed_model_fits`) adds the fixed model's fit at
    each fraction and its range: the spread the scored samples make alone.
    """
    fits = [_mean_fit(run) for run in runs]
    finite = [f for f in fits if f is not None and np.isfinite(f)]
    summary: dict = {
        "runs": runs,
        "default_min": min(finite) if finite else None,
        "default_max": max(finite) if finite else None,
        "default_range": max(finite) - min(finite) if finite else None,
        "runs_without_fit": len(fits) - len(finite),
        "within_2_points_range": bool(finite) and len(finite) == len(fits) and max(finite) - min(finite) <= CLOSE,
        "switched_decisions": switched_decisions(runs),
    }
    by_fraction = {}
    for run, fit in zip(runs, fits):
        if run["perturbation"] != "none" and not run["perturbation"].startswith("fraction"):
            continue
        peer, peer_fit, peer_order = _best_peer(peers_by_fraction.get(run["fraction"], {}))
        gap = None if fit is None or peer_fit is None or not np.isfinite(fit) else fit - peer_fit
        same, same_fit = best_peer_at_order(peers_by_fraction.get(run["fraction"], {}), run.get("order"))
        by_fraction[run["fraction"]] = {"default_fit": fit, "default_order": run.get("order"), "best_peer": peer,
                                        "best_peer_fit": peer_fit, "best_peer_order": peer_order,
                                        "default_minus_best_peer": gap,
                                        "best_peer_at_default_order": same,
                                        "best_peer_at_default_order_fit": same_fit}
    if fixed_fits:
        for fraction, fit in fixed_fits.items():
            by_fraction.setdefault(fraction, {})["fixed_model_fit"] = fit
        summary["fixed_model_range"] = max(fixed_fits.values()) - min(fixed_fits.values())
    summary["by_fraction"] = by_fraction
    gaps = [entry["default_minus_best_peer"] for entry in by_fraction.values()]
    # the held-out part itself changes with the fraction; the gap to the best peer on the same part does not
    known = [g for g in gaps if g is not None]
    summary["default_minus_best_peer_range"] = [min(known), max(known)] if known else None
    # a fraction without a default fit or without any peer's counts as not within
    summary["default_within_2_points_of_best_peer_at_every_fraction"] = (
        None if not peers_by_fraction else all(g is not None and g >= -CLOSE for g in gaps))
    summary["peers_against_the_goal"] = peers_against_the_goal(peers_by_fraction)
    return summary


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
        peer_order = rows[peer].get("order") if peer else None
        workbench, workbench_fit = best("workbench:")
        default = _mean_fit(rows.get(f"workbench:{DEFAULT_ROW}", {}))
        gap = None if default is None or peer_fit is None or not np.isfinite(default) else default - peer_fit
        entry = {
            "best_peer": peer, "best_peer_fit": peer_fit, "best_peer_order": peer_order,
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
        cells = "".join(f"{_cell(sets[n][method]) if method in sets[n] else '-':>15}" for n in names)
        print(f"{method:<36}{cells}")


def _cell(row: dict) -> str:
    """A table cell: the mean hold-out fit and, where known, the order that gave it."""
    order = row.get("order")
    return _show(_mean_fit(row)) + (f" n={order}" if isinstance(order, int) else "")


def print_perturbations(sets: dict) -> None:
    print(f"default identify's mean hold-out fit % under perturbation (fractions, {PERTURBATION:g} noise, BLAS "
          "kernels): range, and the best peer at each fraction")
    for name, rows in sets.items():
        spread = rows.get("perturbations")
        if not spread:
            continue
        print(f"{name:<16} {_show(spread['default_min'])} to {_show(spread['default_max'])}, range "
              f"{_show(spread['default_range'])} over {len(spread['runs'])} runs"
              + (f" ({spread['runs_without_fit']} without a fit)" if spread["runs_without_fit"] else "")
              + ("" if not spread["default_minus_best_peer_range"] else
                 ", default minus best peer {:+.1f} to {:+.1f}".format(*spread["default_minus_best_peer_range"])))
        if spread.get("fixed_model_range") is not None:
            print(f"{'':<16} the default's model at {records.HOLDOUT:g}, held fixed, on each fraction's held-out part: "
                  f"range {_show(spread['fixed_model_range'])}")
        switched = spread.get("switched_decisions") or {}
        print(f"{'':<16} decisions switched between runs: "
              + ("; ".join(f"{name} ({' / '.join(map(str, choices))})" for name, choices in switched.items())
                 or "none"))
        verdicts = spread.get("peers_against_the_goal") or {}
        held = [f"{peer} {_show(v['range'])} / {v['worst_minus_best_peer']:+.1f}"
                for peer, v in verdicts.items() if v["range"] is not None]
        if held:
            print(f"{'':<16} each peer held to the same goals (range / worst minus best peer): " + ", ".join(held)
                  + f"; {sum(v['meets_both'] for v in verdicts.values())} of {len(verdicts)} meet both")
        for fraction, entry in spread["by_fraction"].items():
            if "default_fit" not in entry:
                continue
            gap = entry["default_minus_best_peer"]
            peer = (f", best peer {entry['best_peer']} {_show(entry['best_peer_fit'])} n={entry['best_peer_order']}"
                    if entry["best_peer"] else "")
            fixed = (f", fixed model {_show(entry['fixed_model_fit'])}" if entry.get("fixed_model_fit") is not None
                     else "")
            same = (f"; at n={entry['default_order']} best peer {entry['best_peer_at_default_order']} "
                    f"{_show(entry['best_peer_at_default_order_fit'])}"
                    if entry.get("best_peer_at_default_order") else "")
            print(f"   {fraction:>9}: default {_show(entry['default_fit'])} n={entry['default_order']}{peer}"
                  + ("" if gap is None else f", {gap:+.1f}") + fixed + same)


def baseline_figures(sets: dict) -> dict[str, list]:
    """The figures the committed baseline guards: ``"record | row | split" -> fit per output`` (an empty list
    where the run failed), for every workbench row at the usual split and the default at every fraction."""
    figures: dict[str, list] = {}
    for name, rows in sets.items():
        entry = records.record_set(name)
        for key, row in rows.items():
            if key.startswith("workbench:") and isinstance(row, dict):
                label = key[len("workbench:"):]
                figures[f"{name} | {label} | {_fraction(entry, records.HOLDOUT)}"] = list(
                    row.get("validation_fit_percent") or [])
        spread = rows.get("perturbations") or {}
        for run in spread.get("runs", []) if isinstance(spread, dict) else spread:
            if run["perturbation"].startswith("fraction"):
                figures[f"{name} | {DEFAULT_ROW} | {run['fraction']}"] = list(run.get("validation_fit_percent") or [])
    return figures


def _numbers(kind):
    return lambda text: [kind(item) for item in text.split(",") if item.strip()]


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", help="comma-separated record sets (default: all)")
    parser.add_argument("--no-peers", action="store_true", help="score the workbench only")
    parser.add_argument("--fractions", type=_numbers(float), default=list(FRACTIONS),
                        help=f"held-out fractions of the perturbation runs (default {','.join(map(str, FRACTIONS))})")
    parser.add_argument("--seeds", type=_numbers(int), default=list(SEEDS),
                        help=f"seeds of the {PERTURBATION:g} perturbed copies (default {','.join(map(str, SEEDS))}; "
                             "empty for none)")
    parser.add_argument("--kernels", type=_numbers(str), default=None,
                        help="OPENBLAS_CORETYPE values to run the default under (default: every other kernel this "
                             "CPU runs; empty for none)")
    parser.add_argument("--default-only", action="store_true",
                        help="of the workbench's rows, run the default identify alone")
    parser.add_argument("--no-perturbations", action="store_true", help="skip the perturbed runs of the default")
    parser.add_argument("--peers-from", type=Path, nargs="+", metavar="FILE",
                        help="JSON files holding earlier outputs of _peers_runner.py (records split between them), "
                             "read instead of running it")
    parser.add_argument("--workbench-from", type=Path, metavar="FILE",
                        help="a benchmarks.json whose real_data section holds the workbench's rows and perturbed runs "
                             "for these records, reused instead of running identify")
    parser.add_argument("--update-baseline", action="store_true",
                        help="write this run's workbench figures to benchmarks/baselines/real_data.json instead of "
                             "comparing them with it")
    parser.add_argument("--order-rule", choices=("holdout", "estimation-split"), default="holdout",
                        help="what chooses a peer's order: the held-out fits (as identify --validation F --order "
                             "2-8) or a split of the estimation part")
    args = parser.parse_args(argv)
    names = args.sets.split(",") if args.sets else [entry.name for entry in records.RECORD_SETS]
    for name in names:
        records.record_set(name)  # an unknown name stops here, before anything runs
    if any(not 0 < f < 1 for f in args.fractions):
        parser.error(f"--fractions must lie strictly between 0 and 1; got {args.fractions}")
    if args.no_perturbations:
        args.fractions, args.seeds, args.kernels = [], [], []
    elif args.kernels is None:
        args.kernels = other_kernels()
    started = time.perf_counter()
    sets: dict = {} if args.workbench_from is None else saved_workbench(args.workbench_from, names)
    with tempfile.TemporaryDirectory(prefix="vehid-real-") as scratch:
        for name in names if args.workbench_from is None else ():
            entry = records.record_set(name)
            print(f"== {name}", flush=True)
            workbench = run_workbench(entry, Path(scratch), args.default_only)
            command = workbench.pop("command")
            (u_est, _), (u_val, _) = records.load(entry)
            sets[name] = {
                "file": entry.path, "dt": entry.dt, "dt_note": entry.dt_note, "command": command,
                "estimation_samples": len(u_est), "validation_samples": len(u_val),
                **{f"workbench:{k}": v for k, v in workbench.items()},
            }
            model = sets[name][f"workbench:{DEFAULT_ROW}"].pop(FIXED_MODEL, None)
            if not args.no_perturbations:
                sets[name]["perturbations"] = run_perturbations(entry, Path(scratch), workbench[DEFAULT_ROW], args)
                sets[name]["fixed_model_fits"] = fixed_model_fits(entry, model, args.fractions)
    # the peers after the workbench: their run does not depend on it, and may be one saved earlier
    peer_fractions = sorted({records.HOLDOUT, *args.fractions})
    try:
        if args.no_peers:
            peers = {"sets": {}}
        elif args.peers_from:
            peers = saved_peers(args.peers_from, names, peer_fractions, args.order_rule)
        else:
            peers = run_peers(names, peer_fractions, args.order_rule)
    except (RuntimeError, ValueError, subprocess.SubprocessError) as exc:
        # the workbench's figures took long to measure: they are written all the same, and the run fails after
        print(f"real_data.py: no peer results: {exc}", file=sys.stderr)
        peers = {"sets": {}, "error": str(exc)}
    score_as_identify(peers, args.order_rule)
    for name in names:
        entry = records.record_set(name)
        peers_by_fraction = peers["sets"].get(name, {})
        sets[name].update({f"peer:{k}": v for k, v in peers_by_fraction.get(_fraction(entry, records.HOLDOUT),
                                                                           {}).items()})
        if "perturbations" in sets[name]:
            sets[name]["perturbations"] = perturbation_summary(sets[name]["perturbations"], peers_by_fraction,
                                                               sets[name].pop("fixed_model_fits", None))
        if peers_by_fraction:
            sets[name]["peers_by_fraction"] = peers_by_fraction
    figures = {
        "score": "validation NRMSE fit % per output, as identify scores: a stable linear model simulated from the "
                 "least-squares initial state (MATLAB compare), an unstable one predicted 10 samples ahead, the "
                 "workbench's and the linear peers' alike (a peer's compare_fit_percent: simulated whatever its "
                 "stability); the spline model from rest (identify --nonlinear), NARX from the first measured outputs",
        "split": f"first {1 - records.HOLDOUT:.0%} estimates, last {records.HOLDOUT:.0%} validates, as identify "
                 f"--validation {records.HOLDOUT} (cascaded tanks: published estimation and validation records)",
        "offsets": "identify removes the estimation part's means (a separate validation record: its own); "
                   "the peers get the same centred samples",
        "order": "workbench: identify's default (4) unless the row says otherwise; peers: each searches orders "
                 f"{(peers.get('settings') or {}).get('orders')} and is scored at the order it chooses (its "
                 f"'order'), by the rule {args.order_rule!r}",
        "perturbations": {"fractions": args.fractions, "seeds": args.seeds, "relative_noise": PERTURBATION,
                          "openblas_kernels": args.kernels, "openblas_kernel_chosen": _kernel_in_use(None),
                          "goal": f"range at most {CLOSE} points; default within {CLOSE} points of the best peer at "
                                  "every fraction"},
        "peer_settings": peers.get("settings"),
        **({"peers_error": peers["error"]} if "error" in peers else {}),
        "peer_versions": peers.get("versions"),
        "sets": sets,
        "summary": summarise(sets),
        "seconds": time.perf_counter() - started,
        "load_average_1min": os.getloadavg()[0],
    }
    print_table(sets)
    for name, entry in figures["summary"].items():
        print(f"{name}: default {_show(entry['default_fit'])} against best peer {entry['best_peer']} "
              f"{_show(entry['best_peer_fit'])} n={entry['best_peer_order']}"
              + (f"; spline {_show(entry['spline_fit'])}" if "spline_fit" in entry else ""))
    print_perturbations(sets)
    from vehid.scenarios.benchmarking import record_figures

    print(f"figures written to {record_figures('real_data', figures)}")
    figures["regressions"] = baselines.check(
        "real_data", baseline_figures(sets), update=args.update_baseline,
        about={"benchmark": "benchmarks/real_data.py", "score": figures["score"], "split": figures["split"],
               "cases": "record | workbench row | held-out fraction (published: the record's own validation "
                        "record): hold-out NRMSE fit % per output"})
    return figures


if __name__ == "__main__":
    outcome = main()
    sys.exit(1 if "peers_error" in outcome or outcome["regressions"] else 0)
