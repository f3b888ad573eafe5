"""The library's options as the command line's flags, and the library's messages in the command line's words.

The library names an option by its keyword (``schedule_knots``), the command
line by its flag (``--schedule-knots``). :func:`add_option` defines a flag from
an options class's declaration
(:func:`~vehid.identification.optionspec.option_specs`), taking its default,
choices and help from there, so that the two cannot drift apart.
:func:`command_line_message` shows an error's message with a flag wherever it
names an option (quoted, and listed in the error's
:attr:`~vehid.identification.errors.WorkbenchError.options`).

This module imports nothing heavy; a registry of choices (the estimators) is
read only when the flag is given or its help shown.
"""

from __future__ import annotations

import argparse
import re
from collections.abc import Mapping, Sequence
from typing import Any, Iterator

from vehid.identification.optionspec import Boolean, Number, OneOf, OptionSpec, option_specs

__all__ = ["FLAGS", "flag_of", "help_of", "add_option", "command_line_message"]

#: Keywords whose flag is not the keyword with dashes for underscores (none yet: keep it that way).
FLAGS: dict[str, str] = {}

_REFERENCE = re.compile(r"``([a-z][a-z0-9_]*)``")  # another option named in a declaration's help


def flag_of(name: str) -> str:
    """The flag of the option ``name``: ``--schedule-knots`` for ``schedule_knots``."""
    return FLAGS.get(name, "--" + name.replace("_", "-"))


def _default_text(spec: OptionSpec) -> str | None:
    if spec.default is None or spec.default is False or (isinstance(spec.default, (Mapping, tuple)) and
                                                          not spec.default):
        return None  # no default to state (none, off or empty): the help says what happens without the flag
    if spec.default is True:
        return "on"
    return f"{spec.default:g}" if isinstance(spec.default, float) else str(spec.default)


def help_of(spec: OptionSpec, note: str | None = None) -> str:
    """The flag's help: the declaration's, other options named by their flags, then a bounded whole number's range,
    the default and ``note``."""
    text = _REFERENCE.sub(lambda match: flag_of(match.group(1)), spec.help).replace("%", "%%")  # argparse expands %
    allowed = spec.allowed
    remarks = []
    if isinstance(allowed, OneOf) and callable(allowed.values):
        remarks.append("one of %(choices)s")  # a registry, read when the help is shown
    if isinstance(allowed, Number) and allowed.whole and allowed.low is not None and allowed.high is not None:
        remarks.append(allowed.describe().removeprefix("a whole number "))  # "from 2 to 9"
    remarks += [f"default {shown}" for shown in [_default_text(spec)] if shown is not None]
    if note:
        remarks.append(note)
    return text + (f" ({'; '.join(remarks)})" if remarks else "")


class _Registered(Sequence):
    """The choices of a registry, read when argparse checks a value or shows the help, not when the flag is defined.

    The flag then has a plain metavar: argparse formats it as soon as the flag is defined, and
    without one it would list the choices there.
    """

    def __init__(self, allowed: OneOf):
        self._allowed = allowed

    def __getitem__(self, index: Any) -> Any:
        return self._allowed.choices[index]

    def __len__(self) -> int:
        return len(self._allowed.choices)

    def __iter__(self) -> Iterator[str]:
        return iter(self._allowed.choices)

    def __contains__(self, value: object) -> bool:
        return value in self._allowed.choices


def add_option(parser: Any, options: type, name: str, *, note: str | None = None, **settings: Any) -> argparse.Action:
    """Define the flag of option ``name`` of the options class ``options`` on ``parser`` (or an argument group).

    Its default, choices, type (a number's) and help come from the declaration; a
    yes/no option is a switch (``--name``, or ``--name``/``--no-name`` where it is on by
    default). ``note`` is said after the default in the help; ``settings`` go to
    argparse as they are (a ``metavar``, an ``append`` action, or a ``default`` of None
    where the command tells a flag not given from one given).
    """
    spec = option_specs(options)[name]
    settings.setdefault("default", spec.default)
    allowed = spec.allowed
    if isinstance(allowed, Boolean):
        settings.setdefault("action", argparse.BooleanOptionalAction if spec.default else "store_true")
    elif isinstance(allowed, OneOf):
        settings["choices"] = _Registered(allowed) if callable(allowed.values) else allowed.choices
        if callable(allowed.values):
            settings.setdefault("metavar", name.upper())
    elif isinstance(allowed, Number) and "action" not in settings:
        settings.setdefault("type", int if allowed.whole else float)
    return parser.add_argument(flag_of(name), help=help_of(spec, note), **settings)


def _named_options(exc: BaseException) -> set[str]:
    """The options an error names, with those of the errors it was raised from."""
    names: set[str] = set()
    seen: set[int] = set()
    current: BaseException | None = exc
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        names.update(getattr(current, "options", ()) or ())
        current = current.__cause__ or (None if current.__suppress_context__ else current.__context__)
    return names


def command_line_message(exc: BaseException) -> str:
    """The error's message with each option it names (quoted: ``'schedule_knots'``) shown as its flag."""
    text = str(exc)
    for name in _named_options(exc):
        text = text.replace(f"'{name}'", flag_of(name))
    return text
