"""The ``vehid`` command line's entry point (:func:`main`, the console script's, as ``vehid.scenarios.cli.main``).

Subcommands live one per module in :mod:`vehid.scenarios.commands`; each defines
``NAME``, ``GROUP`` (``None`` for a top-level command, else a key of
:data:`~vehid.scenarios.commands.parser.GROUPS`), ``HELP`` and
``register(parser)``, which adds its arguments and sets ``handler``:
``(args) -> (summary: dict, text: str)``. The parser is built in
:mod:`vehid.scenarios.commands.parser`; here the summary becomes the
``--json`` object, and every failure one line on standard error with the exit
status of the README's contract (2 bad input, 1 failed computation, 3 warnings
under ``--strict``, 128 + the signal's number).
"""

from __future__ import annotations

import json
import logging
import sys
import warnings
from typing import Any, Callable, Sequence

from vehid.identification.errors import DivergenceError, PartialResultError, StrictWarningsError, WorkbenchError
from vehid.identification.jsonable import to_jsonable
from vehid.scenarios.commands.flags import command_line_message
from vehid.scenarios.commands.parser import GROUPS, MESSAGE_LIMIT, UsageError, build_parser, one_line

__all__ = ["main", "build_parser", "to_jsonable", "one_line", "MESSAGE_LIMIT", "GROUPS"]

log = logging.getLogger("vehid")

def _configure_logging(args: Any) -> None:
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
    """Whether a command line, even one the parser refuses, asks for ``--json`` (or an abbreviation the parser accepts)."""
    for token in argv:
        if token == "--":
            return False
        if len(token) >= 3 and "--json".startswith(token):
            return True
    return False


def _failed(args: Any, exc: BaseException, status: int, summary: dict | None = None,
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
    # What only a running command needs (worker processes, signal handling) is imported once it runs.
    from vehid.identification.blas import one_blas_thread
    from vehid.scenarios.shutdown import PATH_ERRNOS, signal_name, stopping_on_signals

    handler: Callable[[Any], tuple[dict, str]] = args.handler
    try:
        # until the result is printed: a signal before then ends with 128 + its number
        with stopping_on_signals(), one_blas_thread():
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
    except PartialResultError as exc:  # the finished part is still reported, then the failure
        if not args.json and exc.text:
            sys.stdout.write(exc.text.rstrip("\n") + "\n")
            sys.stdout.flush()
        text = command_line_message(exc)  # the options its advice names, as flags
        print(f"vehid: error: {one_line(text)}", file=sys.stderr)
        return _failed(args, exc, exc.exit_status, exc.summary, message=text)
    except DivergenceError as exc:
        text = command_line_message(exc)  # the options it names, as flags
        print(f"vehid: diverged: {one_line(text)}", file=sys.stderr)
        return _failed(args, exc, exc.exit_status, message=text)
    except WorkbenchError as exc:
        text = command_line_message(exc)
        print(f"vehid: error: {one_line(text)}", file=sys.stderr)
        return _failed(args, exc, exc.exit_status, message=text)
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


def _print_result(args: Any, summary: dict, text: str) -> None:
    if args.json:
        sys.stdout.write(json.dumps(to_jsonable(summary), allow_nan=False) + "\n")
    elif text:
        sys.stdout.write(text.rstrip("\n") + "\n")
    sys.stdout.flush()  # the result is out before the signals' default action is back


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
