"""The ``vehid`` command line.

Subcommands live one per module in :mod:`vehid.scenarios.commands`; each defines
``NAME``, ``GROUP`` (``None`` for a top-level command, else a key of
:data:`GROUPS`), ``HELP`` and ``register(parser)``, which adds its arguments
and sets ``handler``: ``(args) -> (summary: dict, text: str)``. Here the
summary becomes the ``--json`` object, and every failure one line on standard
error with the exit status of the README's contract (2 bad input, 1 failed
computation, 3 warnings under ``--strict``, 128 + the signal's number).
"""

from __future__ import annotations

import argparse
import ast
import importlib
import json
import logging
import pkgutil
import sys
import warnings
from pathlib import Path
from typing import Any, Callable, NoReturn, Sequence

from vehid.identification.errors import DivergenceError, StrictWarningsError, WorkbenchError
from vehid.identification.jsonable import to_jsonable
from vehid.scenarios.shutdown import PATH_ERRNOS, signal_name, stopping_on_signals

__all__ = ["main", "build_parser", "to_jsonable"]

log = logging.getLogger("vehid")

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


class _Parser(argparse.ArgumentParser):
    """argparse with the workbench's error contract: one line on standard error, exit status 2.

    argparse's own ``error`` prints the whole usage block before the message;
    the usage stays one ``--help`` away. :func:`main` adds the JSON object
    when the command line asks for ``--json``.
    """

    def error(self, message: str) -> NoReturn:
        line = one_line(f"{self.prog}: error: {message} (see {self.prog} --help)")
        sys.stderr.write(line + "\n")
        raise UsageError(line)


def _common_options() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    output = common.add_argument_group("output")
    output.add_argument("--json", action="store_true", help="print one JSON summary object on stdout")
    output.add_argument("--quiet", action="store_true", help="no progress display; warnings and errors only")
    output.add_argument("--verbose", action="store_true", help="log progress details (and tracebacks of internal errors)")
    return common


def _command_modules() -> list[Any]:
    import vehid.scenarios.commands as package
    modules = []
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{package.__name__}.{info.name}")
        if hasattr(module, "register"):
            modules.append(module)
    return modules


_HEADER_NAMES = ("NAME", "GROUP", "HELP")


def _command_headers() -> list[dict[str, Any]]:
    """Each command module's ``NAME``, ``GROUP``, ``HELP``, docstring and module name, read from its source.

    Importing a command imports what it computes with (CasADi, SciPy, h5py,
    matplotlib), which costs seconds; the list of commands and their one-line
    help need only these constants. A module whose constants are not plain
    literals is imported instead.
    """
    import vehid.scenarios.commands as package
    headers = []
    for info in sorted(pkgutil.iter_modules(package.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module_name = f"{package.__name__}.{info.name}"
        header = _literal_header(Path(package.__path__[0]) / f"{info.name}.py")
        if header is None:
            module = importlib.import_module(module_name)
            if not hasattr(module, "register"):
                continue
            header = {key: getattr(module, key) for key in _HEADER_NAMES} | {"doc": module.__doc__}
        headers.append(header | {"module": module_name})
    return headers


def _literal_header(source: Path) -> dict[str, Any] | None:
    """``NAME``, ``GROUP``, ``HELP`` and the docstring of a command's source, or None if not all are literals."""
    try:
        tree = ast.parse(source.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return None
    found: dict[str, Any] = {}
    defines_register = False
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "register":
            defines_register = True
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            if node.targets[0].id in _HEADER_NAMES:
                try:
                    found[node.targets[0].id] = ast.literal_eval(node.value)
                except ValueError:
                    return None
    if not defines_register or set(found) != set(_HEADER_NAMES):
        return None
    return found | {"doc": ast.get_docstring(tree, clean=False)}


def _chosen_command(argv: Sequence[str]) -> tuple[str, ...]:
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
    common = _common_options()
    parser = _Parser(
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
    chosen = None if argv is None else _chosen_command(argv)
    for header in _command_headers():
        words = (header["NAME"],) if header["GROUP"] is None else (header["GROUP"], header["NAME"])
        target = top if header["GROUP"] is None else group_parsers[header["GROUP"]]
        command = target.add_parser(
            header["NAME"],
            help=header["HELP"],
            description=(header["doc"] or header["HELP"]).strip(),
            parents=[common],
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        if chosen is None or chosen == words:
            importlib.import_module(header["module"]).register(command)
    return parser


def _configure_logging(args: argparse.Namespace) -> None:
    level = logging.INFO if args.verbose else (logging.ERROR if args.quiet else logging.WARNING)
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("vehid: %(levelname)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)
    warnings.showwarning = _show_warning


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: Any = None, line: str | None = None) -> None:
    """A Python warning as one logged line: its category and message, never the file, line number or source."""
    logging.getLogger("py.warnings").warning("%s", one_line(f"{category.__name__}: {message}"))


def _asks_for_json(argv: Sequence[str]) -> bool:
    """Whether a command line, even one argparse refuses, asks for ``--json`` (or an abbreviation argparse accepts)."""
    for token in argv:
        if token == "--":
            return False
        if len(token) >= 3 and "--json".startswith(token):
            return True
    return False


def _failed(args: argparse.Namespace, exc: BaseException, status: int, summary: dict | None = None,
            message: str | None = None) -> int:
    """The exit status of a failed command; with ``--json`` still one JSON object on stdout."""
    if args.json:
        body = dict(summary or {})
        body.update({"error": one_line(str(exc) if message is None else message), "exit_status": status})
        sys.stdout.write(json.dumps(to_jsonable(body), allow_nan=False) + "\n")
    return status


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(argv)
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:  # the README's promise: with --json, one JSON object on every failure
        if _asks_for_json(argv):
            sys.stdout.write(json.dumps({"error": exc.line, "exit_status": exc.code}) + "\n")
            sys.stdout.flush()
        raise
    _configure_logging(args)
    handler: Callable[[argparse.Namespace], tuple[dict, str]] = args.handler
    try:
        with stopping_on_signals():  # until the result is printed: a signal before then ends with 128 + its number
            summary, text = handler(args)
            _print_result(args, summary, text)
    except StrictWarningsError as exc:
        if not args.json and exc.text:  # the run's result is still the result; the status says it had warnings
            sys.stdout.write(exc.text.rstrip("\n") + "\n")
            sys.stdout.flush()
        for line in exc.warnings:
            print(f"vehid: warning: {one_line(line)}", file=sys.stderr)
        print("vehid: error: warnings under --strict", file=sys.stderr)
        return _failed(args, exc, exc.exit_status, exc.summary)
    except DivergenceError as exc:
        print(f"vehid: diverged: {one_line(str(exc))}", file=sys.stderr)
        return _failed(args, exc, exc.exit_status)
    except WorkbenchError as exc:
        print(f"vehid: error: {one_line(str(exc))}", file=sys.stderr)
        return _failed(args, exc, exc.exit_status)
    except KeyboardInterrupt as exc:
        name, status = signal_name(exc)
        print(f"vehid: interrupted by {name}", file=sys.stderr)
        return _failed(args, exc, status, message=f"interrupted by {name}")
    except OSError as exc:  # a file read or written: its name and the cause, never "internal error"
        from vehid.identification.dataio.archive_safety import os_error_text  # h5py: imported when needed
        text = os_error_text(exc)
        print(f"vehid: error: {one_line(text)}", file=sys.stderr)
        return _failed(args, exc, 2 if exc.errno in PATH_ERRNOS else 1, message=text)
    except Exception as exc:  # an unexpected failure: one line, traceback on request
        if args.verbose:
            log.exception("internal error")
        print(
            one_line(f"vehid: internal error: {type(exc).__name__}: {exc}") + " (rerun with --verbose for the traceback)",
            file=sys.stderr,
        )
        return _failed(args, exc, 1)
    # Past this point a SIGTERM or SIGHUP has its default action again: the process ends by the signal
    # (a shell shows 128 + its number), the work and its output being complete.
    return 0


def _print_result(args: argparse.Namespace, summary: dict, text: str) -> None:
    if args.json:
        sys.stdout.write(json.dumps(to_jsonable(summary), allow_nan=False) + "\n")
    elif text:
        sys.stdout.write(text.rstrip("\n") + "\n")
    sys.stdout.flush()  # the result is out before the signals' default action is back


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
