"""Windows of a record's time as the user writes them, and times as the user reads them.

One grammar serves every option that names a stretch of a log (``--segment``, ``--exclude``):
``T0:T1`` is the file's own time in seconds, ``+T0:+T1`` seconds from the log's first sample
(either end may be empty: ``+20:`` is from 20 s after the start to the end). Relative windows are
what the figures' axes show on a log stamped in epoch seconds, where the file's time is 1.7e9 s.
Messages print times the same way as the axes (:func:`time_text`): the file's own time where the
record keeps it, else seconds from the log's start. docs/measured_data.md ("Time base") states the rules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import InputError

__all__ = ["TimeWindow", "parse_time_window", "parse_time_windows", "edge_slack", "window_mask", "time_text",
           "span_text"]

_GRAMMAR = "T0:T1 in the file's time (s), or +T0:+T1 in seconds from the log's first sample"


@dataclass(frozen=True)
class TimeWindow:
    """``start <= t <= stop``: in the file's time, or (``from_start``) in seconds from the log's first sample.

    Attributes
    ----------
    start, stop : float
        The window's ends in seconds; ``-inf`` and ``inf`` where the text left an end empty.
    from_start : bool
        The ends count from the log's first sample (written ``+T0:+T1``).
    """

    start: float = -math.inf
    stop: float = math.inf
    from_start: bool = False

    def __post_init__(self) -> None:
        if math.isnan(self.start) or math.isnan(self.stop) or not self.start < self.stop:
            raise InputError(f"a time window needs T0 < T1; got {self}")

    def in_file_time(self, first: float) -> tuple[float, float]:
        """The window's ends in the file's time, for a log whose first sample is at file time ``first``."""
        shift = float(first) if self.from_start else 0.0
        return self.start + shift, self.stop + shift

    def __str__(self) -> str:
        sign = "+" if self.from_start else ""

        def end(value: float) -> str:
            return "" if math.isinf(value) else f"{sign}{value:g}"

        return f"{end(self.start)}:{end(self.stop)}"


def _end(text: str, whole: str, what: str, options: tuple[str, ...]) -> tuple[float, bool | None]:
    """One end of a window: its value and whether it is relative (None where the end is empty)."""
    text = text.strip()
    if not text:
        return math.nan, None
    relative = text.startswith("+")
    try:
        value = float(text[1:] if relative else text)
    except ValueError:
        raise InputError(f"{what} is {_GRAMMAR}; got {whole!r}", options=options) from None
    if not math.isfinite(value):
        raise InputError(f"{what} is {_GRAMMAR}; got {whole!r}", options=options)
    return value, relative


def parse_time_window(value: str | Sequence[float] | TimeWindow | None, what: str = "a segment", *,
                      option: str | None = None) -> TimeWindow | None:
    """``"T0:T1"``, ``"+T0:+T1"`` (either end may be empty), a pair in the file's time, or a window.

    Parameters
    ----------
    value : str, (float, float), TimeWindow or None
    what : str
        How a message names the window (``"a segment"``).
    option : str, optional
        The option that gave the window, named by the messages (as ``'exclude'``) in place of ``what``.

    Raises
    ------
    InputError
        Not of the grammar, ``T0 >= T1``, or one end relative and the other not (``+20:130`` says
        neither which time the window is in nor what the user meant).
    """
    if value is None or isinstance(value, TimeWindow):
        return value
    options = (option,) if option else ()
    what = f"'{option}'" if option else what
    if isinstance(value, str):
        start, colon, stop = value.partition(":")
        if not colon:
            raise InputError(f"{what} is {_GRAMMAR}; got {value!r}", options=options)
        (low, low_relative), (high, high_relative) = _end(start, value, what, options), _end(stop, value, what, options)
        kinds = {kind for kind in (low_relative, high_relative) if kind is not None}
        if len(kinds) > 1:
            raise InputError(f"{what} {value!r} mixes the file's time and time from the log's start: write both "
                             "ends with + (from the start) or neither (file time)", options=options)
        low = -math.inf if low_relative is None else low
        high = math.inf if high_relative is None else high
        if not low < high:
            raise InputError(f"{what} needs T0 < T1; got {value}", options=options)
        return TimeWindow(low, high, bool(kinds and kinds.pop()))
    pair = tuple(float(v) for v in value)
    if len(pair) != 2:
        raise InputError(f"{what} is a pair (T0, T1); got {value!r}", options=options)
    if not pair[0] < pair[1]:  # also NaN
        raise InputError(f"{what} needs T0 < T1; got {pair[0]:g}:{pair[1]:g}", options=options)
    return TimeWindow(*pair)


def parse_time_windows(values: str | Sequence[str | TimeWindow] | None, option: str = "exclude"
                       ) -> tuple[TimeWindow, ...]:
    """Several windows: repeated options, or one text listing them separated by commas (errors name ``option``)."""
    if values is None:
        return ()
    items = [values] if isinstance(values, (str, TimeWindow)) else list(values)
    windows: list[TimeWindow] = []
    for item in items:
        parts = item.split(",") if isinstance(item, str) else [item]
        windows += [parse_time_window(part, option=option) for part in parts
                    if not isinstance(part, str) or part.strip()]
    return tuple(windows)


def edge_slack(file_time: float, step: float) -> float:
    """How far outside a window a sample may lie and still be in it: a millionth of a step, and a few
    rounding units of the file's time (epoch seconds resolve only 2.4e-7 s), so that a window that names a
    sample's stamp keeps it."""
    return 1e-6 * abs(step) + 4.0 * float(np.spacing(abs(file_time)))


def window_mask(t: np.ndarray, window: TimeWindow, time_offset: float = 0.0, log_start: float | None = None
                ) -> np.ndarray:
    """Which samples of a record lie in the window.

    ``t`` is the record's time, ``time_offset`` the file time of ``t = 0`` (the record's
    ``meta["time_base"]["time_offset"]``) and ``log_start`` the file time of the log's first sample,
    from which ``+T0:+T1`` counts (``meta["time_base"]["log_start"]``; default the record's first sample).
    The ends are compared in the record's time, with :func:`edge_slack`.
    """
    t = np.asarray(t, dtype=float)
    if window.from_start:  # the log's first sample in the record's time: small, whatever the file's time
        first = float(t[0]) if log_start is None else log_start - time_offset
        low, high = window.start + first, window.stop + first
    else:
        low, high = window.start - time_offset, window.stop - time_offset
    slack = edge_slack(time_offset + float(t[-1]), float(t[1] - t[0]) if t.size > 1 else 0.0)
    return (t >= low - slack) & (t <= high + slack)


def _number(value: float) -> str:
    """A time to a hundredth of a millisecond, without trailing zeros (epoch seconds keep their decimals)."""
    text = f"{value:.5f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def time_text(t: float, time_offset: float = 0.0) -> str:
    """A record's time as its axes show it: ``"12.5 s"``, or ``"12.5 s from the log's start"`` where the
    record's time counts from its first sample (``time_offset``, the file time of ``t = 0``, is not zero)."""
    return f"{_number(t)} s" + (" from the log's start" if time_offset else "")


def span_text(first: float, last: float, time_offset: float = 0.0) -> str:
    """Where a record lies in time, for messages: ``"runs from 390 to 470 s"``, or, where its time counts
    from its first sample, ``"is 80 s long (file time 1690000390 to 1690000470 s)"``."""
    if not time_offset:
        return f"runs from {_number(first)} to {_number(last)} s"
    return (f"is {_number(last - first)} s long (file time {_number(first + time_offset)} to "
            f"{_number(last + time_offset)} s)")
