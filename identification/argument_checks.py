"""Checks of the arguments the classical estimators, the model conversions and the comparators take."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from .data import IOData
from .errors import InputError

__all__ = ["io_arrays", "finite_matrix", "non_negative_int", "positive_int", "forgetting_factor", "per_input"]


def finite_matrix(name: str, value: Any, *, ndim: int = 2) -> np.ndarray:
    """``value`` as a float array of ``ndim`` dimensions (a 1-D array becomes one column), all finite."""
    array = np.asarray(value, dtype=float)
    if ndim == 2 and array.ndim == 1:
        array = array[:, None]
    if array.ndim != ndim:
        raise InputError(f"{name} must be a {ndim}-D array; got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(array))[0]
        raise InputError(f"{name} contains a non-finite value (NaN or inf) at index {tuple(int(i) for i in bad)}")
    return array


def io_arrays(data_or_arrays: Any) -> tuple[np.ndarray, np.ndarray, float | None]:
    """``(u, y, dt)`` from an :class:`IOData` or a ``(u, y)`` pair (then ``dt`` is None).

    ``u`` is (N, n_u), ``y`` (N, n_y), both finite and of one length.
    """
    if isinstance(data_or_arrays, IOData):
        return np.asarray(data_or_arrays.u), np.asarray(data_or_arrays.y), data_or_arrays.dt
    if not isinstance(data_or_arrays, (tuple, list)) or len(data_or_arrays) != 2:
        raise InputError("give an IOData record or a pair (u, y) of time-major arrays")
    u = finite_matrix("u", data_or_arrays[0])
    y = finite_matrix("y", data_or_arrays[1])
    if u.shape[0] != y.shape[0]:
        raise InputError(f"u has {u.shape[0]} samples but y has {y.shape[0]}: lengths must match")
    return u, y, None


def non_negative_int(value: Any, name: str) -> int:
    """``value`` as an int >= 0, or an InputError naming it."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InputError(f"{name} must be an integer >= 0; got {value!r}")
    return int(value)


def positive_int(value: Any, name: str) -> int:
    """``value`` as an int >= 1, or an InputError naming it."""
    if non_negative_int(value, name) < 1:
        raise InputError(f"{name} must be an integer >= 1; got {value!r}")
    return int(value)


def per_input(value: Any, n_u: int, name: str, *, minimum: int = 0) -> tuple[int, ...]:
    """An order given once for all inputs or once per input, as a tuple of n_u ints >= ``minimum``."""
    values: Sequence[Any] = [value] * n_u if np.isscalar(value) else list(value)
    if len(values) != n_u:
        raise InputError(f"{name} needs one value per input ({n_u}); got {len(values)}")
    checked = tuple(non_negative_int(v, name) for v in values)
    if any(v < minimum for v in checked):
        raise InputError(f"{name} must be >= {minimum} for every input; got {checked}")
    return checked


def forgetting_factor(value: Any) -> float:
    """A forgetting factor lambda in (0, 1], or an InputError."""
    try:
        lam = float(value)
    except (TypeError, ValueError):
        raise InputError(f"the forgetting factor must be a number in (0, 1]; got {value!r}") from None
    if not (math.isfinite(lam) and 0.0 < lam <= 1.0):
        raise InputError(f"the forgetting factor must lie in (0, 1]; got {value!r}")
    return lam
