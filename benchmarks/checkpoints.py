"""What keeping a run resumable costs: ``vehid identify`` with ``--out`` against the same run without it.

    python benchmarks/checkpoints.py [--repeats 5]

A run with ``--out`` checkpoints its passes in the archive so that ``--resume``
can go on after a kill. A checkpoint copies, rewrites and re-verifies the
archive, which on a short record takes far longer than a pass; the
checkpointer therefore gathers passes until the time computed since its last
checkpoint reaches ``COMPUTE_PER_CHECKPOINT`` times what that checkpoint took
(``identification/dataio/iekf_archive.py``). Three commands on the hair
dryer record (700 estimation samples, order 4, a given p, 50 passes at most),
interleaved so that they meet the same load, each ``--repeats`` times in a
fresh process:

- ``no archive``: no ``--out``;
- ``gathered``: ``--out``, as the command runs;
- ``every pass``: ``--out`` with a checkpoint after every pass
  (``COMPUTE_PER_CHECKPOINT = 0``), how the command ran before.

Figures: median wall and CPU seconds of each, the ratios of the two archived
runs to the run without an archive, and the CPU seconds each archived run
adds to it. Part of what an archive adds is fixed (the record and the plan
written first, the model and scores last: about half a second here);
checkpoints are the rest. Target: ``gathered`` adds at most a third of what
``every pass`` adds. On this record a pass takes milliseconds, so the rule
writes a few checkpoints where the old one wrote fifty; checkpointing every
pass again would bring the share near one. Results go to
``results/benchmarks.json`` under ``checkpoints``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

from vehid.scenarios.benchmarking import record_figures, timed_command

ROOT = Path(__file__).resolve().parent.parent
RECORD = ROOT / "tests" / "data" / "dryer" / "dryer.dat"
ARGUMENTS = ["identify", str(RECORD), "--inputs", "1", "--outputs", "2", "--dt", "0.08", "--validation", "0.3",
             "--order", "4", "--p", "1e-4", "--passes", "50", "--json", "--quiet"]
TARGET_SHARE = 1 / 3  # of every pass's added CPU time that gathered checkpoints may add

# The command line in a fresh interpreter, its checkpointing rule set first (None: as shipped).
_RUN = """
import sys
from vehid.identification.dataio import iekf_archive
if sys.argv[1] != "None":
    iekf_archive.COMPUTE_PER_CHECKPOINT = float(sys.argv[1])
from vehid.scenarios import cli
sys.exit(cli.main(sys.argv[2:]))
"""

CASES = {  # name: (checkpoint rule, whether to keep an archive)
    "no archive": ("None", False),
    "gathered": ("None", True),
    "every pass": ("0", True),
}


def _timed(arguments: list[str]) -> tuple[float, float, dict]:
    """Wall and CPU seconds (user + system, the child's own) of one command, and its JSON summary."""
    run = timed_command(arguments)
    return run.wall, run.cpu, json.loads(run.stdout)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="runs of each command (default 5)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be at least 1")
    times: dict[str, dict[str, list[float]]] = {name: {"wall": [], "cpu": []} for name in CASES}
    passes: dict[str, int] = {}
    with tempfile.TemporaryDirectory(prefix="vehid-checkpoints-") as scratch:
        for repeat in range(args.repeats + 1):  # the first round warms the compile cache and is not counted
            for name, (rule, archived) in CASES.items():
                out = ["--out", str(Path(scratch) / f"{name.replace(' ', '-')}-{repeat}.h5")] if archived else []
                wall, cpu, summary = _timed([sys.executable, "-c", _RUN, rule, *ARGUMENTS, *out])
                passes[name] = summary["passes_run"]
                if repeat:
                    times[name]["wall"].append(wall)
                    times[name]["cpu"].append(cpu)
    medians = {name: {kind: statistics.median(values) for kind, values in entry.items()} for name, entry in times.items()}
    base = medians["no archive"]
    figures = {
        "command": "vehid " + " ".join(a if a != str(RECORD) else "tests/data/dryer/dryer.dat" for a in ARGUMENTS),
        "repeats": args.repeats,
        "passes_run": passes,
        "median_seconds": medians,
        "ratio_to_no_archive": {name: {kind: medians[name][kind] / base[kind] for kind in base}
                                for name in ("gathered", "every pass")},
        "added_cpu_seconds": {name: medians[name]["cpu"] - base["cpu"] for name in ("gathered", "every pass")},
        "target_share": TARGET_SHARE,
        "load_average_1min": os.getloadavg()[0],
    }
    added = figures["added_cpu_seconds"]
    figures["gathered_share"] = added["gathered"] / added["every pass"] if added["every pass"] > 0 else None
    figures["target_met"] = figures["gathered_share"] is not None and figures["gathered_share"] <= TARGET_SHARE
    for name, entry in medians.items():
        ratio = "" if name == "no archive" else (
            f"   x{figures['ratio_to_no_archive'][name]['wall']:.2f} wall, "
            f"x{figures['ratio_to_no_archive'][name]['cpu']:.2f} cpu")
        print(f"{name:<12} {entry['wall']:6.2f} s wall {entry['cpu']:6.2f} s cpu  ({passes[name]} passes){ratio}")
    share = figures["gathered_share"]
    print(f"added CPU: gathered {added['gathered']:.2f} s, every pass {added['every pass']:.2f} s; share "
          f"{'n/a' if share is None else f'{share:.2f}'} (target at most {TARGET_SHARE:.2f}): "
          f"{'met' if figures['target_met'] else 'NOT met'}")
    print(f"figures written to {record_figures('checkpoints', figures)}")
    return figures


if __name__ == "__main__":
    sys.exit(0 if main()["target_met"] else 1)
