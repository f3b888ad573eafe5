"""Start-up time of the command line: how long a user waits before a command does anything.

    python benchmarks/startup.py [--repeats 7]

Each command runs ``--repeats`` times in a fresh process, commands interleaved
so that all meet the same load; the figures are medians:

- ``vehid --help`` (target 0.3 s) and ``vehid COMMAND --help`` for every
  command (target 0.5 s: the time a command needs before it starts its work);
- ``python -c "import vehid.identification"``.

Both wall-clock seconds and the process's CPU seconds (user + system, from
``wait4``) are kept: on a shared machine the wall time grows with the load
average, which is recorded beside them, while the CPU time moves far less.
The console script is the ``vehid`` beside this Python; without it,
``python -m vehid.scenarios.cli``.

Figures go to ``results/benchmarks.json`` under ``startup``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.commands.parser import GROUPS, command_headers

HELP_TARGET_SECONDS = 0.3
COMMAND_TARGET_SECONDS = 0.5


def _vehid() -> list[str]:
    script = Path(sys.executable).with_name("vehid")
    if script.exists():
        return [str(script)]
    found = shutil.which("vehid")
    return [found] if found else [sys.executable, "-m", "vehid.scenarios.cli"]


def _commands() -> dict[str, list[str]]:
    vehid = _vehid()
    commands = {"vehid --help": [*vehid, "--help"]}
    for header in command_headers():
        words = [header["NAME"]] if header["GROUP"] is None else [header["GROUP"], header["NAME"]]
        commands[" ".join(["vehid", *words, "--help"])] = [*vehid, *words, "--help"]
    for group in GROUPS:
        commands[f"vehid {group} --help"] = [*vehid, group, "--help"]
    commands["import vehid.identification"] = [sys.executable, "-c", "import vehid.identification"]
    return commands


def _timed(command: list[str]) -> tuple[float, float]:
    """Wall and CPU seconds of one run of ``command`` (its output discarded; a failure is an error)."""
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {process.stderr.read().decode()[-300:]}")
    process.stderr.close()
    return wall, usage.ru_utime + usage.ru_stime


def main(repeats: int) -> dict:
    commands = _commands()
    for command in commands.values():  # once, unmeasured: bytecode compiled, files in the page cache
        _timed(command)
    load_before = os.getloadavg()[0]
    walls: dict[str, list[float]] = {name: [] for name in commands}
    cpus: dict[str, list[float]] = {name: [] for name in commands}
    for _ in range(repeats):
        for name, command in commands.items():
            wall, cpu = _timed(command)
            walls[name].append(wall)
            cpus[name].append(cpu)
    load_after = os.getloadavg()[0]
    rows = {name: {"wall_seconds_median": statistics.median(walls[name]),
                   "cpu_seconds_median": statistics.median(cpus[name]),
                   "wall_seconds_min": min(walls[name])} for name in commands}
    command_rows = [row for name, row in rows.items() if name.startswith("vehid ") and name != "vehid --help"]
    figures = {
        "repeats": repeats,
        "load_average_1min": [load_before, load_after],
        "targets_seconds": {"vehid --help": HELP_TARGET_SECONDS, "any command --help": COMMAND_TARGET_SECONDS},
        "commands": rows,
        "slowest_command_wall_seconds_median": max(row["wall_seconds_median"] for row in command_rows),
        "slowest_command_cpu_seconds_median": max(row["cpu_seconds_median"] for row in command_rows),
    }
    record_figures("startup", figures)
    print(f"load average (1 min) {load_before:.2f} before, {load_after:.2f} after; medians of {repeats} runs")
    print(f"{'command':42s} {'wall s':>8s} {'cpu s':>8s}")
    for name, row in rows.items():
        print(f"{name:42s} {row['wall_seconds_median']:8.3f} {row['cpu_seconds_median']:8.3f}")
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="runs of each command (default 7)")
    main(parser.parse_args().repeats)
