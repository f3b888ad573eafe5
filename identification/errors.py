"""Exception types shared by the whole workbench.

The command line maps :class:`InputError` to exit status 2 and any other
:class:`WorkbenchError` to exit status 1, printing one line and no traceback.
"""

from __future__ import annotations

__all__ = [
    "WorkbenchError",
    "InputError",
    "ExcitationError",
    "DivergenceError",
    "ArchiveError",
]


class WorkbenchError(Exception):
    """Base class of every error the workbench raises on purpose."""


class InputError(WorkbenchError, ValueError):
    """Bad user input: wrong shape, non-finite values, unknown option or column."""


class ExcitationError(InputError):
    """The data do not excite the model enough to identify its parameters."""


class DivergenceError(WorkbenchError):
    """An estimator diverged (NaN or inf, covariance not positive definite, unstable model).

    Attributes
    ----------
    last_good : object or None
        Whatever the estimator had finished before it diverged (for the IEKF,
        the result holding every completed pass), so nothing computed is lost.
    """

    def __init__(self, message: str, last_good: object | None = None):
        super().__init__(message)
        self.last_good = last_good


class ArchiveError(WorkbenchError):
    """A results archive is corrupt, truncated, of an unknown schema, or not a workbench archive."""
