"""The ``vehid`` argument parser: the workbench's error contract, the command list and each command's arguments.

Subcommands live one per module in this package; each defines ``NAME``,
``GROUP`` (``None`` for a top-level command, else a key of :data:`GROUPS`),
``HELP`` and ``register(parser)``, which adds its arguments and sets
``handler``. A module without ``register`` (this one, the shared option
groups of :mod:`~vehid.scenarios.commands.arguments`) is no command.

Building the parser imports only the command the command line names: the
others are listed from constants read in their source, since importing a
command may import what it computes with.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import pkgutil
import re
import sys
from pathlib import Path
from typing import Any, NoReturn, Sequence

from vehid.scenarios.commands.arguments import common_options

__all__ = ["GROUPS", "MESSAGE_LIMIT", "UsageError", "WorkbenchParser", "build_parser", "command_headers",
           "command_modules", "chosen_command", "one_line"]

GROUPS = {
    "study": "reproduce a study of the paper or the textbook appendix",
    "bench": "measure speed against a baseline in the same run",
}

MESSAGE_LIMIT = 400  # characters of an error line: a message past this is cut, the cause is said in its first words


def one_line(text: str, limit: int = MESSAGE_LIMIT) -> str:
    """``text`` as one readable line: no traceback or source lines, no control characters, at most ``limit`` characters.

    Messages quote what they were given (a column name, a library's own
    message); a binary file or a library's multi-line report would otherwise
    print kilobytes or a stack of lines where one line is the contract.
    """
    kept: list[str] = []
    after_frame = False
    for line in str(text).splitlines():
        stripped = line.strip()
        if stripped.startswith("Traceback (most recent call last)"):
            break  # what follows is the stack, not the message
        quoted_source = after_frame and line[:1].isspace()
        after_frame = stripped.startswith('File "')
        if after_frame or quoted_source:
            continue  # a stack frame and the source line it quotes
        if stripped:
            kept.append(stripped)
    joined = " ".join(kept)
    readable = "".join(c if c.isprintable() else "?" for c in joined)
    if len(readable) <= limit:
        return readable
    return readable[: limit - 30].rstrip() + f" ... ({len(readable) - limit + 30} characters cut)"


class UsageError(SystemExit):
    """A malformed command line: exit status 2, with the one line that says what is wrong."""

    def __init__(self, line: str):
        super().__init__(2)
        self.line = line


class WorkbenchParser(argparse.ArgumentParser):
    """argparse with the workbench's error contract: one line on standard error, exit status 2.

    argparse's own ``error`` prints the whole usage block before the message;
    the usage stays one ``--help`` away. The command line's ``main`` adds the
    JSON object when it is asked for ``--json``.
    """

    def error(self, message: str) -> NoReturn:
        line = one_line(f"{self.prog}: error: {message} (see {self.prog} --help)")
        sys.stderr.write(line + "\n")
        raise UsageError(line)


def _command_sources() -> list[tuple[str, Path]]:
    """(module name, source file) of each public module of this package, by name."""
    package_name = __name__.rpartition(".")[0]
    folder = Path(__file__).parent
    return [(f"{package_name}.{info.name}", folder / f"{info.name}.py")
            for info in sorted(pkgutil.iter_modules([str(folder)]), key=lambda m: m.name)
            if not info.name.startswith("_")]


def command_modules() -> list[Any]:
    """Every command's module, imported (those that define ``register``)."""
    modules = []
    for module_name, _ in _command_sources():
        module = importlib.import_module(module_name)
        if hasattr(module, "register"):
            modules.append(module)
    return modules


HEADER_NAMES = ("NAME", "GROUP", "HELP")


def command_headers() -> list[dict[str, Any]]:
    """Each command module's ``NAME``, ``GROUP``, ``HELP``, docstring and module name, read from its source.

    Importing a command may import what it computes with (CasADi, SciPy,
    h5py, matplotlib), which costs seconds; the list of commands and their
    one-line help need only these constants. A module whose constants are not
    plain literals is imported instead; one without ``register`` is skipped.
    """
    headers = []
    for module_name, source in _command_sources():
        header = literal_header(source)
        if header is False:
            continue
        if header is None:
            module = importlib.import_module(module_name)
            if not hasattr(module, "register"):
                continue
            header = {key: getattr(module, key) for key in HEADER_NAMES} | {"doc": module.__doc__}
        headers.append(header | {"module": module_name})
    return headers


_REGISTER = re.compile(r"^def register\(", re.MULTILINE)
# The constants and the docstring come before a command's first function or class: only that head is parsed.
_FIRST_DEFINITION = re.compile(r"^(?:def |class |async def |@)", re.MULTILINE)


def literal_header(source: Path) -> dict[str, Any] | bool | None:
    """``NAME``, ``GROUP``, ``HELP`` and the docstring of a command's source.

    False if the source defines no top-level ``register`` (no command);
    None if they cannot be read as literals from the source's head (the
    module is then imported).
    """
    try:
        text = source.read_text(encoding="utf-8")
    except (OSError, ValueError):
        return None
    if not _REGISTER.search(text):
        return False
    first = _FIRST_DEFINITION.search(text)
    try:
        tree = ast.parse(text[: first.start()] if first else text)
    except (SyntaxError, ValueError):
        return None
    found: dict[str, Any] = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            if node.targets[0].id in HEADER_NAMES:
                try:
                    found[node.targets[0].id] = ast.literal_eval(node.value)
                except ValueError:
                    return None
    if set(found) != set(HEADER_NAMES):
        return None
    return found | {"doc": ast.get_docstring(tree, clean=False)}


def chosen_command(argv: Sequence[str]) -> tuple[str, ...]:
    """The command words ``argv`` names: ``("identify",)`` or ``("study", "handling")``, as far as given.

    Before the command only ``-h``/``--help`` exist, so the first words that
    are not options name it.
    """
    words = [word for word in argv if not word.startswith("-")]
    if not words:
        return ()
    return tuple(words[:2]) if words[0] in GROUPS else (words[0],)


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The argument parser with every subcommand registered.

    Given the ``argv`` it is to parse, only the command that ``argv`` names is
    imported and gets its arguments; the others are listed with their help
    line alone, which is all argparse shows of a command not chosen.
    """
    parser = WorkbenchParser(
        prog="vehid",
        description="Vehicle-dynamics identification workbench: simulate a full-vehicle model, "
        "identify small modal models with the Identifying Extended Kalman Filter, report.",
    )
    top = parser.add_subparsers(dest="command", metavar="COMMAND")
    top.required = True
    group_parsers: dict[str, Any] = {}
    for group, help_text in GROUPS.items():
        group_parser = top.add_parser(group, help=help_text, description=help_text)
        sub = group_parser.add_subparsers(dest="subcommand", metavar="NAME")
        sub.required = True
        group_parsers[group] = sub
    chosen = None if argv is None else chosen_command(argv)
    common = common_options()
    for header in command_headers():
        words = (header["NAME"],) if header["GROUP"] is None else (header["GROUP"], header["NAME"])
        target = top if header["GROUP"] is None else group_parsers[header["GROUP"]]
        if chosen is not None and chosen != words:
            target.add_parser(header["NAME"], help=header["HELP"])  # listed by its help line, never parsed with
            continue
        command = target.add_parser(
            header["NAME"],
            help=header["HELP"],
            description=(header["doc"] or header["HELP"]).strip(),
            parents=[common],
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        importlib.import_module(header["module"]).register(command)
    return parser
