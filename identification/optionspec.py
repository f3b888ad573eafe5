"""Options declared once, each with its default, the values it may take and its help, and checked when built.

An options dataclass declares each field with :func:`option` and calls
:func:`check_options` first thing in its ``__post_init__``; a bad value then
raises :class:`~vehid.identification.errors.OptionError` naming the option by
its keyword, before any work. :func:`option_specs` lists the declarations: the
table the command line reads for its flags' defaults, choices and help, and
from which :func:`parameters_section` writes the class's documentation.
Rules across options (one option that only applies with another) stay in the
class's ``__post_init__``, after the table's checks, raising the same error.

The values an option may take are small constraint objects, one per kind:
:class:`OneOf` (named choices, or a registry read when checked),
:class:`Number` (finite, with bounds, whole or not), :class:`Numbers` (a
sequence of such numbers, of a length, increasing or not) and :data:`BOOLEAN`.
Several classes share one constraint where they take the same setting (a
speed-scheduled family's knots, a spline's nodes), so that its bounds are
stated once. (scikit-learn declares its estimators' ``_parameter_constraints``
in the same spirit and checks them in one place.)

This module imports nothing heavy: a command line lists the defaults in its
help without loading the numerical stack.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import numbers
import re
import textwrap
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Mapping

from vehid.identification.errors import OptionError

__all__ = ["Constraint", "OneOf", "Number", "Numbers", "Boolean", "BOOLEAN", "POSITIVE", "OptionSpec", "option",
           "option_specs", "check_options", "check_value", "documented", "parameters_section", "renamed_options"]

_SPEC = "vehid.option"  # the key of a field's metadata that holds its declaration


class Constraint:
    """What values an option may take: :meth:`conform` returns the value (as stored) or raises ValueError."""

    def conform(self, value: Any) -> Any:
        raise NotImplementedError

    def describe(self) -> str:
        """The allowed values as the end of "NAME must be ...", e.g. ``a whole number from 2 to 9``."""
        raise NotImplementedError

    def type_name(self) -> str:
        """The numpydoc type of such a value (``int``, ``float``, ``str``, ...)."""
        raise NotImplementedError


@dataclass(frozen=True)
class OneOf(Constraint):
    """One of named choices: a tuple, or a function returning them (a registry, read when a value is checked).

    A registry is called each time, so that a choice registered later is accepted.
    """

    values: tuple[str, ...] | Callable[[], Iterable[str]]

    @property
    def choices(self) -> tuple[str, ...]:
        return tuple(self.values() if callable(self.values) else self.values)

    def conform(self, value: Any) -> Any:
        if not isinstance(value, str) or value not in self.choices:
            raise ValueError
        return value

    def describe(self) -> str:
        return "one of " + ", ".join(self.choices)

    def type_name(self) -> str:
        if callable(self.values):  # a registry is read when a value is checked, not when the class is documented
            return "str"
        return "{" + ", ".join(repr(c) for c in self.choices) + "}"


@dataclass(frozen=True)
class Number(Constraint):
    """A finite real number between optional bounds (open or closed), whole or not.

    A whole number may be given as an integral float (``5.0``); it is stored as an int.
    """

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    whole: bool = False

    def conform(self, value: Any) -> Any:
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
            raise ValueError
        if self.whole:
            if value != int(value):
                raise ValueError
            value = int(value)
        if self.low is not None and (value <= self.low if self.low_open else value < self.low):
            raise ValueError
        if self.high is not None and (value >= self.high if self.high_open else value > self.high):
            raise ValueError
        return value

    def _noun(self, plural: bool) -> str:
        kind = "whole number" if self.whole else "number"
        return kind + "s" if plural else f"a {kind}"

    def phrase(self, plural: bool = False) -> str:
        """The allowed numbers in words, singular (``a positive number``) or plural (``positive numbers``)."""
        noun = self._noun(plural)
        bare = noun if plural else noun[2:]
        low, high = self.low, self.high
        if low == 0 and self.low_open and high is None:
            return ("positive " if plural else "a positive ") + bare
        if low is not None and high is not None:
            if self.whole and not self.low_open and not self.high_open:
                return f"{noun} from {_number(low)} to {_number(high)}"
            return (f"{noun} in {'(' if self.low_open else '['}{_number(low)}, "
                    f"{_number(high)}{')' if self.high_open else ']'}")
        if low is not None:
            return f"{noun} {'>' if self.low_open else '>='} {_number(low)}"
        if high is not None:
            return f"{noun} {'<' if self.high_open else '<='} {_number(high)}"
        return ("finite " if plural else "a finite ") + bare

    def describe(self) -> str:
        return self.phrase()

    def type_name(self) -> str:
        return "int" if self.whole else "float"


@dataclass(frozen=True)
class Numbers(Constraint):
    """A sequence of numbers each allowed by ``each``, ``fewest`` to ``most`` of them, strictly increasing if asked.

    Any sequence is stored as a tuple of floats (an options object stays hashable and frozen).
    """

    each: Number = Number()
    fewest: int = 1
    most: int | None = None
    increasing: bool = False

    def conform(self, value: Any) -> Any:
        if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
            raise ValueError
        values = tuple(float(self.each.conform(item)) for item in value)
        if len(values) < self.fewest or (self.most is not None and len(values) > self.most):
            raise ValueError
        if self.increasing and any(b <= a for a, b in zip(values, values[1:])):
            raise ValueError
        return values

    def describe(self) -> str:
        if self.most is None:
            count = "one or more" if self.fewest == 1 else f"at least {self.fewest}"
        elif self.most == self.fewest:
            count = str(self.fewest)
        else:
            count = f"{self.fewest} to {self.most}"
        return f"{count} {self.each.phrase(plural=True)}" + (", strictly increasing" if self.increasing else "")

    def type_name(self) -> str:
        return "tuple of float"


@dataclass(frozen=True)
class Boolean(Constraint):
    """True or False (numpy's booleans too, stored as Python's)."""

    def conform(self, value: Any) -> Any:
        if type(value).__name__ not in ("bool", "bool_"):
            raise ValueError
        return bool(value)

    def describe(self) -> str:
        return "True or False"

    def type_name(self) -> str:
        return "bool"


BOOLEAN = Boolean()
#: A positive finite number (a tuning parameter p, a variance).
POSITIVE = Number(low=0, low_open=True)


def _number(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True)
class OptionSpec:
    """One option's declaration: the row of the table for ``name``.

    Attributes
    ----------
    name : str
        The option's keyword (the field's name).
    default : object
        Its default value.
    allowed : Constraint or None
        The values it may take (None: any, checked where it is used).
    help : str
        What it does, in a phrase; other options are named in double backquotes (````start````),
        which the command line shows as their flags.
    optional : bool
        None is allowed too (for a default chosen by the run).
    """

    name: str
    default: Any
    allowed: Constraint | None
    help: str
    optional: bool = False

    @property
    def choices(self) -> tuple[str, ...] | None:
        """The named choices of a :class:`OneOf` option; None for any other kind."""
        return self.allowed.choices if isinstance(self.allowed, OneOf) else None

    def check(self, value: Any) -> Any:
        """Check a value of this option.

        Parameters
        ----------
        value : object
            The value given.

        Returns
        -------
        object
            The value as the options object stores it (a sequence becomes a tuple, say).

        Raises
        ------
        OptionError
            Naming this option, for a value it does not allow.
        """
        return check_value(self.name, value, self.allowed, optional=self.optional)


def option(default: Any, allowed: Constraint | None = None, *, help: str, optional: bool | None = None) -> Any:
    """A dataclass field declared with its default, allowed values and help (a row of :func:`option_specs`).

    ``optional`` (None allowed) defaults to whether the default is None.
    """
    optional = default is None if optional is None else optional
    spec = OptionSpec("", default, allowed, help, optional)
    return dataclasses.field(default=default, metadata={_SPEC: spec})


def option_specs(options: Any) -> dict[str, OptionSpec]:
    """List the declared options of an options class.

    Parameters
    ----------
    options : type or object
        An options dataclass (``IdentifyOptions``, say) or an instance of one.

    Returns
    -------
    dict of str to OptionSpec
        By name, in the order of its fields.
    """
    return {field.name: dataclasses.replace(field.metadata[_SPEC], name=field.name)
            for field in dataclasses.fields(options) if _SPEC in field.metadata}


def check_value(name: str, value: Any, allowed: Constraint | None, *, optional: bool = False) -> Any:
    """``value`` as stored (a sequence becomes a tuple of floats, say), or :class:`OptionError` naming ``name``."""
    if value is None and optional:
        return None
    if allowed is None:
        return value
    try:
        return allowed.conform(value)
    except (ValueError, TypeError, OverflowError):
        # None, where allowed, goes unsaid: it means "not given", which a command line cannot say otherwise
        raise OptionError(f"'{name}' must be {allowed.describe()}; got {value!r}", name) from None


@contextmanager
def renamed_options(names: Mapping[str, str]) -> Iterator[None]:
    """Within, an :class:`OptionError` naming an option of ``names`` names it by its new name instead.

    For settings that reach an options object under other names (a study's ``nonlinear_p``
    is its spline filter's ``p``), so that the error speaks of the names the caller gave.
    """
    try:
        yield
    except OptionError as exc:
        if not set(exc.options) & set(names):
            raise
        text = str(exc)
        for old, new in names.items():
            text = text.replace(f"'{old}'", f"'{new}'")
        raise OptionError(text, *(names.get(name, name) for name in exc.options)) from exc


def check_options(options: Any) -> None:
    """Check every declared field of a dataclass instance (frozen or not), storing each value as conformed."""
    for name, spec in option_specs(options).items():
        value = getattr(options, name)
        conformed = spec.check(value)
        if conformed is not value:
            object.__setattr__(options, name, conformed)


# numpydoc's sections that follow Parameters: the written section goes before the first of them the class's own
# docstring has (its Examples, say), and the docstring ends on a line of its own, as numpydoc's validation wants
_SECTIONS_AFTER_PARAMETERS = re.compile(
    r"^(Attributes|Methods|Returns|Yields|Receives|Other Parameters|Raises|Warns|Warnings|See Also|Notes"
    r"|References|Examples)\n-+$", re.MULTILINE)


def documented(cls: type) -> type:
    """Class decorator: the class's docstring with the Parameters section written from its declarations."""
    text = inspect.cleandoc(cls.__doc__ or "")
    later = _SECTIONS_AFTER_PARAMETERS.search(text)
    head, tail = (text, "") if later is None else (text[:later.start()].rstrip(), "\n\n" + text[later.start():])
    cls.__doc__ = head + "\n\n" + parameters_section(option_specs(cls)) + tail + "\n"
    return cls


def parameters_section(specs: Mapping[str, OptionSpec]) -> str:
    """The numpydoc ``Parameters`` section of the options, written from their declarations."""
    lines = ["Parameters", "----------"]
    for spec in specs.values():
        kind = spec.allowed.type_name() if spec.allowed is not None else "object"
        lines.append(f"{spec.name} : {kind}{' or None' if spec.optional else ''}, default {spec.default!r}")
        wanted = f" Must be {spec.allowed.describe()}." if isinstance(spec.allowed, (Number, Numbers)) else ""
        lines += textwrap.wrap(f"{spec.help[:1].upper()}{spec.help[1:]}.{wanted}", width=100,
                               initial_indent="    ", subsequent_indent="    ")
    return "\n".join(lines)
