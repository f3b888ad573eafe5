"""Exception types shared by the whole workbench.

Each class carries the exit status the command line ends with when it is
raised: 2 for bad input, 1 for a failed computation, 3 for a run that
finished with warnings under ``--strict``. The command line prints one line
and no traceback.
"""

from __future__ import annotations

__all__ = [
    "WorkbenchError",
    "InputError",
    "OptionError",
    "ExcitationError",
    "DivergenceError",
    "ArchiveError",
    "ConversionError",
    "StrictWarningsError",
    "SimulationError",
    "PartialResultError",
]


class WorkbenchError(Exception):
    """Base class of every error the workbench raises on purpose.

    Parameters
    ----------
    *args : object
        The message, as for any exception.
    options : tuple of str, optional
        The options the message names.

    Attributes
    ----------
    options : tuple of str
        The options the message names, each by its keyword in single quotes (``'schedule_knots'``,
        as scikit-learn names parameters): the library speaks of its keywords, and the command line
        shows each as its flag (``--schedule-knots``).
    """

    exit_status: int = 1
    options: tuple[str, ...] = ()

    def __init__(self, *args: object, options: tuple[str, ...] = ()):
        super().__init__(*args)
        self.options = tuple(options)


class InputError(WorkbenchError, ValueError):
    """Bad user input: wrong shape, non-finite values, unknown option or column.

    Parameters
    ----------
    *args : object
        The message, naming the problem.
    options : tuple of str, optional
        The options it names, by keyword.
    """

    exit_status = 2


class OptionError(InputError):
    """A bad option value or combination of options, naming the options by their keywords.

    Parameters
    ----------
    message : str
        What is wrong, naming each option by its keyword in single quotes (``'bootstrap'``).
    *options : str
        The options the message names (unquoted).
    """

    def __init__(self, message: str, *options: str):
        super().__init__(message, options=options)


class ExcitationError(InputError):
    """The data do not excite the model enough to identify its parameters.

    Parameters
    ----------
    *args : object
        The message: which regressor or mode lacks excitation.
    options : tuple of str, optional
        The options it names, by keyword (an order, say).
    """


class DivergenceError(WorkbenchError):
    """An estimator diverged (NaN or inf, covariance not positive definite, unstable model).

    Parameters
    ----------
    message : str
        What diverged, and where.
    last_good : object, optional
        Whatever the estimator had finished before it diverged.
    options : tuple of str, optional
        The options the message names, by keyword.

    Attributes
    ----------
    last_good : object or None
        Whatever the estimator had finished before it diverged (for the IEKF,
        the result holding every completed pass), so nothing computed is lost.
    """

    def __init__(self, message: str, last_good: object | None = None, *, options: tuple[str, ...] = ()):
        super().__init__(message, options=options)
        self.last_good = last_good


class ArchiveError(WorkbenchError):
    """A results archive is corrupt, truncated, of an unknown schema, or not a workbench archive.

    Exit status 2: a missing, foreign or corrupt file is bad input.

    Parameters
    ----------
    *args : object
        The message, naming the file and what is wrong with it.
    options : tuple of str, optional
        The options it names, by keyword.
    """

    exit_status = 2


class ConversionError(WorkbenchError):
    """An identified model cannot be brought to the requested form (e.g. modal); the input was good (exit 1)."""


class StrictWarningsError(WorkbenchError):
    """A run finished, but with warnings, and the user asked for ``--strict``.

    Attributes
    ----------
    warnings : tuple of str
        The warnings, one line each.
    summary : dict or None
        What the run produced, so that it can still be reported.
    text : str or None
        The run's text summary, printed before the exit status says that it had warnings.
    """

    exit_status = 3

    def __init__(self, warnings: tuple[str, ...] | list[str], summary: dict | None = None, text: str | None = None):
        super().__init__("; ".join(warnings))
        self.warnings = tuple(warnings)
        self.summary = summary
        self.text = text


class SimulationError(WorkbenchError):
    """A simulation left the physical envelope in which its model is valid, or failed outright.

    Attributes
    ----------
    partial : object or None
        The record up to the failure (for the vehicle, an IOData ending at the
        first sample outside the envelope), so nothing computed is lost.
    quantity : str or None
        What left the envelope (e.g. ``roll``, ``sideslip``, ``non-finite state``).
    value : float or None
        Its value there (SI units).
    time : float or None
        When (s).
    """

    def __init__(self, message: str, partial: object | None = None, *, quantity: str | None = None,
                 value: float | None = None, time: float | None = None):
        super().__init__(message)
        self.partial = partial
        self.quantity = quantity
        self.value = value
        self.time = time


class PartialResultError(WorkbenchError):
    """A run failed part of the way, after work worth keeping: the failure, and what was finished.

    Exit status 1. The command line prints ``text`` (the finished part's summary) before the error,
    and with ``--json`` reports ``summary`` with the error beside it.

    Parameters
    ----------
    message : str
        What failed, naming any option it advises by its keyword in single quotes.
    summary : dict
        What the run produced before it failed.
    text : str, optional
        The run's text summary.
    result : object, optional
        The run's typed result, which renders ``summary`` and ``text``.
    options : tuple of str, optional
        The options the message names, by keyword.

    Attributes
    ----------
    summary : dict
        What the run produced before it failed.
    text : str or None
        The run's text summary.
    result : object or None
        The run's typed result, holding everything that was finished (None where the run gave none).
    """

    exit_status = 1

    def __init__(self, message: str, summary: dict, text: str | None = None, *, result: object | None = None,
                 options: tuple[str, ...] = ()):
        super().__init__(message, options=options)
        self.summary = summary
        self.text = text
        self.result = result
