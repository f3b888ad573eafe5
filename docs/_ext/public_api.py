"""The public API, and the docstring rules it is held to.

The public API is what the reference documents (``api_pages``): every name in
the ``__all__`` of ``vehid.identification``, ``vehid.vehicle`` and
``vehid.scenarios``, and, of each such class, the methods and properties the
class itself defines whose names do not begin with an underscore (the
reference leaves inherited members out, and so does this list). Constants are
data, not definitions with a docstring, and are not listed.

Sphinx's numpydoc validation (``docs/conf.py``) and the docstring test
(``tests/test_docstrings.py``) both read :data:`VALIDATION_CHECKS` from here.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import inspect
from typing import Any, Iterator

from api_pages import PACKAGES

# numpydoc's checks that every public docstring must pass. Left out: ES01 (an
# extended summary: a one-line method needs none), SA01 (See Also everywhere) and
# EX01 (Examples everywhere; the entry points below must have them instead).
VALIDATION_CHECKS = frozenset({
    # layout: summary right after the quotes, no stray blank lines, tabs or
    # unknown or misordered sections, directives with two colons
    "GL01", "GL02", "GL03", "GL05", "GL06", "GL07", "GL10",
    "GL08",  # a docstring at all
    # the summary: one line, capitalised, ending in a period, no leading space, an
    # imperative verb for functions ("Return", not "Returns")
    "SS01", "SS02", "SS03", "SS04", "SS05", "SS06",
    # every parameter documented, none that does not exist, in the signature's order,
    # each with a type and a description that is a sentence
    "PR01", "PR02", "PR03", "PR04", "PR05", "PR06", "PR07", "PR08", "PR09", "PR10",
    # a Returns section on whatever returns a value, each value described in a sentence
    "RT01", "RT02", "RT03", "RT04", "RT05",
    "YD01",  # a Yields section on generators
})

# A frozen dataclass's fields are its constructor's parameters; a result documents
# them as Attributes (what a reader of the result finds), which satisfies PR01. In
# Sphinx this is numpydoc's override of PR01 on a docstring with an Attributes
# section; the test is stricter and checks that every field is listed there.
ATTRIBUTES_SECTION = r"(?m)^Attributes\n-{10}$"

# The entry points a user starts from: each docstring has an Examples section that
# runs as a doctest (tests/test_docs.py runs every module's examples).
ENTRY_POINTS = (
    "vehid.identification.identify",
    "vehid.identification.IdentifyOptions",
    "vehid.identification.read_table",
    "vehid.identification.read_raw",
    "vehid.identification.read_record",
    "vehid.scenarios.identify_single_track",
    "vehid.scenarios.handling",
    "vehid.vehicle.simulate",
    "vehid.vehicle.make_manoeuvre",
    "vehid.vehicle.linearize",
)


def _is_definition(value: Any) -> bool:
    return inspect.isclass(value) or inspect.isroutine(inspect.unwrap(value)) or isinstance(value, functools._lru_cache_wrapper)


def data_names() -> Iterator[str]:
    """Yield the qualified names of the data the reference shows: constants and class attributes.

    Their documentation is a ``#:`` comment or the value's own docstring, not a
    numpydoc docstring; Sphinx's validation leaves them out, as the test does.

    Yields
    ------
    str
        A name such as ``vehid.identification.COMPARATORS`` or
        ``vehid.identification.ScheduledModalModel.is_linear``.
    """
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        for name in package.__all__:
            value = getattr(package, name)
            if not _is_definition(value):
                yield f"{package_name}.{name}"
            elif inspect.isclass(value):
                for member_name, member in vars(value).items():
                    if not member_name.startswith("_") and not _is_definition(member) and not isinstance(
                            member, (property, functools.cached_property, staticmethod, classmethod)):
                        yield f"{package_name}.{name}.{member_name}"


def public_objects() -> Iterator[tuple[str, Any]]:
    """Yield the qualified name and object of every definition of the public API.

    Yields
    ------
    name : str
        The name a user imports it by (``vehid.identification.IOData.split``).
    value : object
        The function, class, method or property.
    """
    for package_name in PACKAGES:
        package = importlib.import_module(package_name)
        for name in package.__all__:
            value = getattr(package, name)
            if not _is_definition(value):
                continue
            yield f"{package_name}.{name}", value
            if inspect.isclass(value):
                fields = {field.name for field in dataclasses.fields(value)} if dataclasses.is_dataclass(value) else set()
                for member_name, member in vars(value).items():
                    if member_name.startswith("_") or member_name in fields:
                        continue
                    if isinstance(member, (staticmethod, classmethod)):
                        member = member.__func__
                    if isinstance(member, (property, functools.cached_property)) or inspect.isfunction(member):
                        yield f"{package_name}.{name}.{member_name}", member
