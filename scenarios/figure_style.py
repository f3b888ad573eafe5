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
           "channel_label", "display_samples"]

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
