"""One conversion of workbench values to JSON-ready Python values.

Used for the command line's ``--json`` summaries and for the JSON attributes
of archives (configuration, seeds, summaries).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Mapping
from typing import Any

__all__ = ["to_jsonable", "json_default"]


def json_default(value: Any) -> Any:
    """``json.dumps``'s ``default`` where a value is written as it is: a read-only mapping (a frozen result's
    :class:`~vehid.identification.frozen.FrozenDict`, a record's ``meta``) as the dict it reads as, anything
    else JSON cannot hold as its text."""
    return dict(value) if isinstance(value, Mapping) else str(value)


def to_jsonable(value: Any) -> Any:
    """A JSON-ready copy of ``value``.

    Dataclasses and objects with ``to_dict`` become dicts, arrays and tuples
    lists, numpy scalars Python numbers, complex numbers ``[re, im]``, NaN and
    inf ``null``; anything else unknown becomes its ``str``.

    Examples
    --------
    >>> import numpy as np
    >>> to_jsonable({"e": np.array([complex(-1, 2)]), "n": float("nan"), "k": np.int64(3)})
    {'e': [[-1.0, 2.0]], 'n': None, 'k': 3}
    """
    # A NumPy value exists only once NumPy is imported; not importing it here keeps the command
    # line's start-up (which needs this function) free of NumPy's import time.
    np = sys.modules.get("numpy")
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: to_jsonable(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if np is not None and isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, complex) or (np is not None and isinstance(value, np.complexfloating)):
        return [to_jsonable(float(value.real)), to_jsonable(float(value.imag))]
    if np is not None and isinstance(value, np.generic):
        return to_jsonable(value.item())
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if hasattr(value, "to_dict"):
        return to_jsonable(value.to_dict())
    return str(value)
