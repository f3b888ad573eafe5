"""Handling metrics against speed, drawn: the figure of :class:`~vehicle.handling.HandlingResponse` and
:class:`~vehicle.handling.SourceHandling`.

One panel per metric, one line per model (or source), each value with a band of ``band_sigmas`` standard
deviations where the metrics carry them (the delta method's, from a parameter covariance). Nothing here
imports ``matplotlib.pyplot``: a new Figure gets its own Agg canvas, and the Figure is returned.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from vehid.identification.errors import InputError

__all__ = ["plot_handling", "BAND_SIGMAS"]

#: Bands of +/- 2 standard deviations: about 95 % under the delta method's normal approximation.
BAND_SIGMAS = 2.0


def _panel_label(name: str, unit: str) -> str:
    words = name.replace("_deg_per_g", "").replace("_hz", "").replace("_deg", "").replace("_m_s", "")
    words = words.removesuffix("_s").replace("_", " ")
    return f"{words} ({unit})" if unit not in ("", "-") else words


def plot_handling(curves: Mapping[str, Sequence[Any]], names: Sequence[str], units: Mapping[str, str], *,
                  ax: Any = None, title: str | None = None, band_sigmas: float = BAND_SIGMAS) -> Any:
    """Each metric of ``names`` against speed, one line per curve, with its band where known.

    Parameters
    ----------
    curves : mapping of str to sequence of HandlingMetrics
        Label to the metrics at each speed.
    names : sequence of str
        The metrics drawn (names of :data:`~vehicle.handling.METRIC_UNITS`), one panel each.
    units : mapping of str to str
        Each metric's unit, for the labels.
    ax : matplotlib Axes or sequence of Axes, optional
        One Axes per metric of ``names``. Default: a new Figure, leaving out the metrics no curve has.
    title : str, optional
        The Figure's title (only on a new Figure).
    band_sigmas : float
        Half-width of the bands in standard deviations.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.axes import Axes

    unknown = [name for name in names if name not in units]
    if unknown:
        raise InputError(f"unknown handling metric {unknown[0]!r}; use {', '.join(units)}")
    if not curves:
        raise InputError("give at least one curve of handling metrics")
    if ax is None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        names = [name for name in names
                 if any(math.isfinite(getattr(m, name)) for metrics in curves.values() for m in metrics)] or list(names)
        fig = Figure(figsize=(7.0, max(3.0, 1.2 + 1.8 * len(names))), layout="constrained")
        FigureCanvasAgg(fig)
        axes = list(fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0])
        fig.suptitle(f"{title or 'Handling against speed'} (bands: +/- {band_sigmas:g} std)")
    else:
        axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
        if len(axes) != len(names) or not all(isinstance(item, Axes) for item in axes):
            raise InputError(f"ax must hold one matplotlib Axes per metric ({len(names)}); got {len(axes)}")
        fig = axes[0].figure
    for axis, name in zip(axes, names):
        for label, metrics in curves.items():
            ordered = sorted(metrics, key=lambda m: m.speed)
            speed = np.array([m.speed for m in ordered])
            value = np.array([getattr(m, name) for m in ordered])
            spread = band_sigmas * np.array([m.std[name] for m in ordered])
            (line,) = axis.plot(speed, value, marker="o", label=label)
            if np.any(np.isfinite(spread)):
                axis.fill_between(speed, value - spread, value + spread, color=line.get_color(), alpha=0.2,
                                  linewidth=0)
        axis.set_ylabel(_panel_label(name, units[name]), fontsize=9)
        axis.grid(True, alpha=0.3)
    axes[-1].set_xlabel("speed (m/s)")
    axes[0].legend(fontsize=8)
    return fig
