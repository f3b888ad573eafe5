"""Values that cannot change once made: a read-only mapping and the deep conversion to it.

A result is a frozen dataclass, and so is every part of it that has a type of its own. Some
parts are JSON entries another module writes (a residual test's per-output table, a knot's
coverage, a spline run's tried p values): those are kept as :class:`FrozenDict` and tuples,
read as the mappings and sequences they were, and never changed by a caller who reads them.
:func:`freeze` makes such a value (arrays become read-only copies), :func:`thaw` gives a fresh,
mutable copy for a caller that wants one (a summary a command adds keys to).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any, Union

__all__ = ["FrozenDict", "JsonValue", "freeze", "thaw"]

#: A value as a JSON summary holds it, frozen: numbers, text, None, arrays (read-only), tuples and FrozenDicts.
JsonValue = Union[None, bool, int, float, str, tuple, "FrozenDict", Any]


class FrozenDict(Mapping):
    """A mapping that cannot be changed: no item assignment, deletion or update.

    Equal to any mapping with the same items; its items keep their order.

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


def thaw(value: Any) -> Any:
    """A fresh, mutable copy of a frozen value: mappings as dicts and tuples as lists (arrays stay arrays)."""
    if isinstance(value, Mapping):
        return {key: thaw(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)) and not hasattr(value, "_fields"):  # a named tuple is a value of its own
        return [thaw(item) for item in value]
    return value
