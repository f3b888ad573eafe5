"""What every report figure shares: page size, fonts, a canvas without pyplot, legends beside the data, channel labels.

Kept apart from the plots so that the figure modules (:mod:`.plots`,
:mod:`.pole_map`, the study reports) draw alike without importing each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from vehid.identification.errors import InputError

__all__ = ["REPORT_SIZE", "new_figure", "figure_of_size", "style_axes", "add_legend", "figure_legend", "known_unit", "with_unit",
           "channel_label", "display_samples", "OUTLIER_SPREADS", "robust_range", "set_robust_limits"]

#: Default figure size in inches: legible on an A4 page at 100 % with 9-10 pt text.
REPORT_SIZE = (7.0, 4.5)

_LEGEND_SIZE = 9  # [pt]
_TICK_SIZE = 9  # [pt]
_MAX_LEGEND_ENTRIES = 12  # more lines than this get no legend (it would hide the data)

def new_figure(size: tuple[float, float] = REPORT_SIZE) -> Figure:
    """An empty figure with an Agg canvas and constrained layout (no pyplot)."""
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_of_size(fig: Figure | None, size: tuple[float, float]) -> Figure:
    if fig is None:
        return new_figure(size)
    if fig.axes:
        raise InputError("pass an empty figure (fig.clear() first): this plot lays out its own axes")
    return fig


def style_axes(ax: Axes) -> Axes:
    ax.grid(True, alpha=0.3)
    ax.tick_params(labelsize=_TICK_SIZE)
    return ax


def add_legend(ax: Axes, **options: Any) -> None:
    """The axis's legend beside it, right of the frame, so that it never hides a stretch of the data."""
    handles, labels = ax.get_legend_handles_labels()
    if 0 < len(handles) <= _MAX_LEGEND_ENTRIES:
        ax.legend(**{"fontsize": _LEGEND_SIZE, "loc": "upper left", "bbox_to_anchor": (1.02, 1.0),
                     "borderaxespad": 0.0, **options})


def figure_legend(fig: Figure, ax: Axes) -> None:
    """One legend for the whole figure, right of every axis, from the entries of ``ax``.

    For grids whose axes share the same lines: a legend beside one axis would
    sit in the gap between two columns.
    """
    handles, labels = ax.get_legend_handles_labels()
    if 0 < len(handles) <= _MAX_LEGEND_ENTRIES:
        fig.legend(handles, labels, loc="outside right center", fontsize=_LEGEND_SIZE)  # clear of a long title


def known_unit(unit: str | None) -> str:
    """A channel's unit for a label, or "" where none was given ("-" is what a record without units holds)."""
    unit = "" if unit is None else str(unit).strip()
    return "" if unit in ("", "-") else unit


def with_unit(label: str, unit: str | None) -> str:
    unit = known_unit(unit)
    return f"{label} ({unit})" if unit else label


def channel_label(name: str) -> str:
    """A channel name fit for a title: a bare column number (a text table without header) reads ``column 2``."""
    name = str(name)
    return f"column {name}" if name.isdigit() else name


def display_samples(x: Any, y: Any, bins: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` thinned for drawing by a min/max envelope over ``bins`` stretches; see below.

    Parameters
    ----------
    x : array_like, shape (N,)
    y : array_like, shape (N,)
    bins : int
        Number of stretches; a report axis is about 700-900 pixels wide, so
        1000 stretches (two points each) leave every pixel column its extremes.

    Returns
    -------
    x_shown, y_shown : ndarray, shape (M,)
        ``M <= 2 * bins + 2``; every sample when ``N <= 2 * bins``. The first
        and last samples, each stretch's minimum and maximum (in time order)
        are kept, so the drawn line reaches every peak of the series.
    """
    x = np.asarray(x, dtype=float).ravel()
    y = np.asarray(y, dtype=float).ravel()
    count = y.size
    if x.size != count:
        raise InputError(f"x has {x.size} samples but y has {count}")
    if bins < 1:
        raise InputError(f"bins must be at least 1; got {bins}")
    if count <= 2 * bins:
        return x, y
    width = -(-count // bins)
    padded = np.concatenate([y, np.full(width * bins - count, np.nan)]).reshape(bins, width)
    finite = np.isfinite(padded)
    has_finite = finite.any(axis=1)
    lows = np.argmin(np.where(finite, padded, np.inf), axis=1)
    highs = np.argmax(np.where(finite, padded, -np.inf), axis=1)
    starts = np.arange(bins) * width
    kept = np.concatenate([starts[has_finite] + lows[has_finite], starts[has_finite] + highs[has_finite],
                           np.flatnonzero(~np.isfinite(y)), [0, count - 1]])  # gaps stay gaps
    kept = np.unique(kept[kept < count])
    return x[kept], y[kept]


#: How far from the median, in robust standard deviations (1.4826 median absolute deviations), a value still
#: sets an axis's range: a sine's extremes lie within 1.5 of them and a settling fit's first passes within
#: a few, while a one-sample spike or a diverged prediction lies thousands away
OUTLIER_SPREADS = 30.0
_PAD = 0.05  # of the range, each side
_SPREAD_FLOOR = 1e-3  # of a constant series' magnitude: the span its axis is given


def robust_range(values: Any, *, log: bool = False, outliers: bool = True) -> tuple[float, float] | None:
    """The range of ``values`` without their outliers: the finite values within :data:`OUTLIER_SPREADS` robust
    standard deviations of their median (in decades where ``log``, positive values only). Where most values
    are equal (no spread), the others count up to the first that lies that factor farther from the
    median than the one before. With ``outliers`` False, every finite value counts. None where no value is
    finite."""
    v = np.asarray(values, dtype=float).ravel()
    v = v[np.isfinite(v) & (v > 0)] if log else v[np.isfinite(v)]
    if v.size == 0:
        return None
    if log:
        v = np.log10(v)
    if not outliers:
        return (10.0 ** v.min(), 10.0 ** v.max()) if log else (float(v.min()), float(v.max()))
    median = float(np.median(v))
    deviation = np.abs(v - median)
    spread = 1.4826 * float(np.median(deviation))
    if spread > 0:
        kept = v[deviation <= OUTLIER_SPREADS * spread]
    else:  # most values equal (a settled fit, a flat phase): the others count up to a jump by that factor
        steps = np.unique(deviation[deviation > 0])
        jumps = np.flatnonzero(steps[1:] > OUTLIER_SPREADS * steps[:-1])
        reach = steps[jumps[0]] if jumps.size else (steps[-1] if steps.size else 0.0)
        kept = v[deviation <= reach]
    low, high = float(kept.min()), float(kept.max())
    return (10.0**low, 10.0**high) if log else (low, high)


def set_robust_limits(ax: Axes, values: Any, *, extra: Any = None, axis: str = "y", log: bool = False,
                      outliers: bool = True) -> int:
    """Set ``ax``'s ``axis`` range from ``values`` without their outliers (:func:`robust_range`), widened to take in
    ``extra`` (other curves, bands) only as far as one more such range each side, then padded.

    A spike in a record, a failed candidate's diverging prediction or a confidence band that
    runs to nothing then leaves the data's own range legible; what lies beyond is cut at the frame.
    With ``outliers`` False every value of ``values`` is in range (curves that are all data, whose
    ``extra`` bands may run off). Returns how many of ``values`` lie beyond the range set (a caller
    may say so).
    """
    found = robust_range(values, log=log, outliers=outliers)
    if found is None:
        return 0
    low, high = (np.log10(found[0]), np.log10(found[1])) if log else found
    span = high - low if high > low else max(abs(high), 1.0) * _SPREAD_FLOOR
    if extra is not None:
        more = np.asarray(extra, dtype=float).ravel()
        more = more[np.isfinite(more) & (more > 0)] if log else more[np.isfinite(more)]
        if more.size:
            more = np.log10(more) if log else more
            low, high = max(min(low, float(more.min())), low - span), min(max(high, float(more.max())), high + span)
            span = high - low
    low, high = low - _PAD * span, high + _PAD * span
    limits = (10.0**low, 10.0**high) if log else (low, high)
    (ax.set_ylim if axis == "y" else ax.set_xlim)(*limits)
    v = np.asarray(values, dtype=float).ravel()
    return int(np.count_nonzero(np.isfinite(v) & ((v < limits[0]) | (v > limits[1]))))
