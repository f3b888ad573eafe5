"""Values that cannot change once made: a read-only mapping and the deep conversion to it.

A result is a frozen dataclass, and so is every part of it that has a type of its own. Some
parts are JSON entries another module writes (a residual test's per-output table, a knot's
coverage, a spline run's tried p values): those are kept as :class:`FrozenDict` and tuples,
read as the mappings and sequences they were, and never changed by a caller who reads them.
:func:`freeze` makes such a value (arrays become read-only copies), :func:`thaw` gives a fresh,
mutable copy for a caller that wants one (a summary a command adds keys to).

A result also holds values of other modules' types (the model, the estimator's run, the records),
which are frozen dataclasses whose arrays and ``meta`` mappings could still be changed in place,
and a result's rendering reads them. :func:`frozen_copy` gives the result its own unchangeable
copy of such a value, so that nothing a caller does to what it reads changes what the result says.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Union

__all__ = ["FrozenDict", "JsonValue", "freeze", "freeze_fields", "frozen_copy", "thaw"]

#: A value as a JSON summary holds it, frozen: numbers, text, None, arrays (read-only), tuples and FrozenDicts.
JsonValue = Union[None, bool, int, float, str, tuple, "FrozenDict", Any]


class FrozenDict(Mapping):
    """A mapping that cannot be changed: no item assignment, deletion or update.

    Equal to any mapping with the same items; its items keep their order.

    Parameters
    ----------
    items : mapping or iterable of pairs, optional
        The items, as ``dict`` takes them; none by default.

    Examples
    --------
    >>> entry = FrozenDict({"p": 1e-5, "q_schedule": "shrinking"})
    >>> entry["p"], dict(entry) == {"p": 1e-5, "q_schedule": "shrinking"}
    (1e-05, True)
    >>> entry["p"] = 1.0
    Traceback (most recent call last):
    ...
    TypeError: 'FrozenDict' object does not support item assignment
    """

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, Any] | Any = ()):
        object.__setattr__(self, "_items", dict(items))

    def __getitem__(self, key: str) -> Any:
        return self._items[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} cannot be changed")

    def __hash__(self) -> int:  # hashable where its values are, as a frozen dataclass is
        return hash(tuple(self._items.items()))

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self._items!r})"

    def __or__(self, other: Mapping[str, Any]) -> "FrozenDict":
        """A new FrozenDict with ``other``'s items added (or replacing these)."""
        return FrozenDict({**self._items, **freeze(dict(other))._items})


def freeze(value: Any) -> Any:
    """``value`` made unchangeable all the way down.

    Mappings become :class:`FrozenDict`, lists and tuples tuples, NumPy arrays read-only
    copies; dataclasses and other values are kept as they are (a frozen dataclass is
    frozen already).
    """
    import sys

    np = sys.modules.get("numpy")  # an array exists only once NumPy is imported
    if isinstance(value, FrozenDict):
        return value
    if isinstance(value, Mapping):
        return FrozenDict({key: freeze(item) for key, item in value.items()})
    if isinstance(value, (list, tuple)):
        return tuple(freeze(item) for item in value)
    if np is not None and isinstance(value, np.ndarray):
        if not value.flags.writeable:
            return value
        copy = value.copy()
        copy.flags.writeable = False
        return copy
    return value


def frozen_copy(value: Any, _copies: dict[int, Any] | None = None) -> Any:
    """``value``, or a copy of it, that cannot be changed all the way down, frozen dataclasses included.

    As :func:`freeze`, and further: the fields of a frozen dataclass are frozen the same way, the
    dataclass copied (without running its ``__post_init__``) where any field had to be, and kept
    as it is where none had (so freezing a frozen value again copies nothing). A value reached
    twice is copied once, so parts shared within ``value`` stay shared. Instances of other
    classes (a compiled function, a dataclass that is not frozen) are kept as they are.

    Examples
    --------
    >>> import numpy as np
    >>> from dataclasses import dataclass
    >>> @dataclass(frozen=True)
    ... class Fit:
    ...     parameters: np.ndarray
    ...     meta: dict
    >>> fit = Fit(np.array([1.0, 2.0]), {"source": "filter"})
    >>> kept = frozen_copy(fit)
    >>> kept.parameters.flags.writeable, kept.meta["source"], fit.parameters.flags.writeable
    (False, 'filter', True)
    >>> frozen_copy(kept) is kept
    True
    """
    import copy
    import dataclasses
    import sys

    copies = {} if _copies is None else _copies
    if id(value) in copies:
        return copies[id(value)]
    np = sys.modules.get("numpy")
    if np is not None and isinstance(value, np.ndarray):
        kept = freeze(value)
    elif isinstance(value, Mapping):
        items = {key: frozen_copy(item, copies) for key, item in value.items()}
        unchanged = isinstance(value, FrozenDict) and all(items[key] is value[key] for key in items)
        kept = value if unchanged else FrozenDict(items)
    elif isinstance(value, (list, tuple, set, frozenset)):
        items = [frozen_copy(item, copies) for item in value]
        if isinstance(value, (set, frozenset)):
            kept = value if isinstance(value, frozenset) else frozenset(items)
        elif isinstance(value, tuple) and all(new is old for new, old in zip(items, value)):
            kept = value
        else:
            kept = type(value)(*items) if hasattr(value, "_fields") else tuple(items)
    elif (dataclasses.is_dataclass(value) and not isinstance(value, type)
          and value.__dataclass_params__.frozen):
        fields = {field.name: getattr(value, field.name) for field in dataclasses.fields(value)}
        copies[id(value)] = value  # a part that refers back to its owner keeps the owner
        frozen = {name: frozen_copy(item, copies) for name, item in fields.items()}
        if all(frozen[name] is fields[name] for name in fields):
            kept = value
        else:
            kept = copy.copy(value)
            for name, item in frozen.items():
                object.__setattr__(kept, name, item)
    else:
        kept = value
    copies[id(value)] = kept
    return kept


def freeze_fields(instance: Any) -> None:
    """Make every field of a frozen dataclass ``instance`` unchangeable all the way down (:func:`frozen_copy`),
    in its ``__post_init__``: a result that owns what it holds."""
    import dataclasses

    copies: dict[int, Any] = {}
    for field in dataclasses.fields(instance):
        object.__setattr__(instance, field.name, frozen_copy(getattr(instance, field.name), copies))


def thaw(value: Any) -> Any:
    """A fresh, mutable copy of a frozen value: mappings as dicts and tuples as lists (arrays stay arrays)."""
    if isinstance(value, Mapping):
        return {key: thaw(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):  # a named tuple is a value of its own
        return [thaw(item) for item in value]
    return value
