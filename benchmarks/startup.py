"""Start-up time of the command line: how long a user waits before a command does anything.

    python benchmarks/startup.py [--repeats 7] [--as-configured]

Each command runs ``--repeats`` times in a fresh process, commands interleaved
so that all meet the same load; the figures are medians:

- ``vehid --help`` (target 0.3 s) and ``vehid COMMAND --help`` for every
  command (target 0.5 s);
- ``vehid COMMAND ... (to its work)``: the command line of every command, its
  required arguments filled in, run up to the moment its handler would begin
  the work (target 0.5 s): the interpreter, the imports, the parser, the
  logging set-up; the handler is replaced by an exit, so nothing is computed;
- ``python -c "import vehid.identification"`` and ``python -c pass``, the
  floor every process pays.

Both wall-clock seconds and the process's CPU seconds (user + system, from
``wait4``) are kept: on a shared machine the wall time grows with the load
average, which is recorded beside them, while the CPU time moves far less.
The console script is the ``vehid`` beside this Python; without it,
``python -m vehid.scenarios.cli``.

An installed package has its bytecode compiled (pip does it on install). Where
the environment forbids writing bytecode (``PYTHONDONTWRITEBYTECODE``), every
run would compile the workbench's sources anew, so the processes measured
keep their bytecode in a temporary folder instead (``PYTHONPYCACHEPREFIX``);
``--as-configured`` measures with the environment as it is.

Figures go to ``results/benchmarks.json`` under ``startup``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

from vehid.scenarios.benchmarking import record_figures, timed_command
from vehid.scenarios.commands.parser import GROUPS, build_parser, command_headers

HELP_TARGET_SECONDS = 0.3
COMMAND_TARGET_SECONDS = 0.5

# Runs the command line as ``vehid`` would, with the chosen command's handler replaced by an exit: what is
# timed is everything before the command's own work.
_UP_TO_THE_WORK = """
import sys
from vehid.scenarios import cli
from vehid.scenarios.commands import parser as command_parser

def stop(args):
    raise SystemExit(0)

def stopping_parser(argv):
    built = command_parser.build_parser(argv)
    chosen = built
    for word in command_parser.chosen_command(argv):
        chosen = next(a for a in chosen._actions if a.dest in ("command", "subcommand")).choices[word]
    chosen.set_defaults(handler=stop)
    return built

cli.build_parser = stopping_parser
sys.exit(cli.main(sys.argv[1:]))
"""


def _vehid() -> list[str]:
    script = Path(sys.executable).with_name("vehid")
    if script.exists():
        return [str(script)]
    found = shutil.which("vehid")
    return [found] if found else [sys.executable, "-m", "vehid.scenarios.cli"]


def _required_arguments(words: list[str]) -> list[str]:
    """Arguments the command cannot run without: its positional arguments and required options, each given
    a value its parser accepts (the first choice, else 1), so that parsing succeeds and nothing is read."""
    chosen = build_parser(words)
    for word in words:
        chosen = next(a for a in chosen._actions if a.dest in ("command", "subcommand")).choices[word]
    filled: list[str] = []
    for action in chosen._actions:
        if action.option_strings and not action.required:
            continue
        if action.nargs in ("?", "*", 0) or isinstance(action, argparse._HelpAction):
            continue
        count = action.nargs if isinstance(action.nargs, int) else 1
        value = str(next(iter(action.choices))) if action.choices else "1"
        filled += [*action.option_strings[:1], *[value] * count]
    return filled


def _commands() -> dict[str, list[str]]:
    vehid = _vehid()
    commands = {"vehid --help": [*vehid, "--help"]}
    headers = command_headers()
    for header in headers:
        words = [header["NAME"]] if header["GROUP"] is None else [header["GROUP"], header["NAME"]]
        commands[" ".join(["vehid", *words, "--help"])] = [*vehid, *words, "--help"]
    for group in GROUPS:
        commands[f"vehid {group} --help"] = [*vehid, group, "--help"]
    for header in headers:
        words = [header["NAME"]] if header["GROUP"] is None else [header["GROUP"], header["NAME"]]
        commands[" ".join(["vehid", *words, "(to its work)"])] = [
            sys.executable, "-c", _UP_TO_THE_WORK, *words, *_required_arguments(words)]
    commands["import vehid.identification"] = [sys.executable, "-c", "import vehid.identification"]
    commands["python -c pass"] = [sys.executable, "-c", "pass"]
    return commands


def _timed(command: list[str], environment: dict[str, str]) -> tuple[float, float]:
    """Wall and CPU seconds of one run of ``command`` (its output discarded; a failure is an error)."""
    run = timed_command(command, environment=environment)
    return run.wall, run.cpu


def main(repeats: int, as_configured: bool = False) -> dict:
    commands = _commands()
    environment = dict(os.environ)
    with tempfile.TemporaryDirectory(prefix="vehid-bytecode-") as bytecode:
        bytecode_kept = not as_configured and bool(environment.get("PYTHONDONTWRITEBYTECODE"))
        if bytecode_kept:
            environment.pop("PYTHONDONTWRITEBYTECODE")
            environment["PYTHONPYCACHEPREFIX"] = bytecode
        for command in commands.values():  # once, unmeasured: bytecode compiled, files in the page cache
            _timed(command, environment)
        load_before = os.getloadavg()[0]
        walls: dict[str, list[float]] = {name: [] for name in commands}
        cpus: dict[str, list[float]] = {name: [] for name in commands}
        for _ in range(repeats):
            for name, command in commands.items():
                wall, cpu = _timed(command, environment)
                walls[name].append(wall)
                cpus[name].append(cpu)
        load_after = os.getloadavg()[0]
    rows = {name: {"wall_seconds_median": statistics.median(walls[name]),
                   "cpu_seconds_median": statistics.median(cpus[name]),
                   "wall_seconds_min": min(walls[name])} for name in commands}
    command_rows = [row for name, row in rows.items() if name.startswith("vehid ") and name != "vehid --help"]
    figures = {
        "repeats": repeats,
        "bytecode": "cached in a temporary folder" if bytecode_kept else "as configured",
        "load_average_1min": [load_before, load_after],
        "targets_seconds": {"vehid --help": HELP_TARGET_SECONDS, "any command --help or up to its work":
                            COMMAND_TARGET_SECONDS},
        "commands": rows,
        "slowest_command_wall_seconds_median": max(row["wall_seconds_median"] for row in command_rows),
        "slowest_command_cpu_seconds_median": max(row["cpu_seconds_median"] for row in command_rows),
    }
    record_figures("startup", figures)
    print(f"load average (1 min) {load_before:.2f} before, {load_after:.2f} after; medians of {repeats} runs; "
          f"bytecode {figures['bytecode']}")
    print(f"{'command':46s} {'wall s':>8s} {'cpu s':>8s} {'wall min':>9s}")
    for name, row in rows.items():
        print(f"{name:46s} {row['wall_seconds_median']:8.3f} {row['cpu_seconds_median']:8.3f} "
              f"{row['wall_seconds_min']:9.3f}")
    return figures


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7, help="runs of each command (default 7)")
    parser.add_argument("--as-configured", action="store_true",
                        help="measure with the environment's bytecode setting, even if it forbids writing bytecode")
    arguments = parser.parse_args()
    main(arguments.repeats, arguments.as_configured)
