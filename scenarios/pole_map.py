"""The eigenvalue map: poles in the complex plane at a reach that separates the ones that matter.

Drawn by :func:`plot_eigenvalue_map` (re-exported by :mod:`.plots`): poles
beyond the view are marked at its edge and listed, each mode is labelled once
with its frequency and damping where the label covers nothing else, and
models with a parameter covariance get 95 % confidence ellipses.
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
import scipy.linalg
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox
from scipy.stats import chi2

from .figure_style import REPORT_SIZE, add_legend, new_figure, style_axes

__all__ = ["eigenvalue_view", "plot_eigenvalue_map", "ELLIPSE_SCALE"]


def _eigenvalues(model: Any) -> np.ndarray:
    if hasattr(model, "eigenvalues"):
        return np.asarray(model.eigenvalues(), dtype=complex)
    if hasattr(model, "A"):
        return np.linalg.eigvals(np.asarray(model.A, dtype=float))
    return np.asarray(model, dtype=complex).ravel()


#: A pole nearer the origin than this fraction of the view's reach is drawn on top of it: not resolved.
_RESOLVED_FRACTION = 0.05
#: Where a pole's label may go, tried in turn: (dx, dy) in points from the pole, alignment.
_LABEL_PLACES = tuple(
    (sign_x * 6, sign_y * (4 + 11 * ring), "left" if sign_x > 0 else "right", "bottom" if sign_y > 0 else "top")
    for ring in range(5) for sign_y in (1, -1) for sign_x in (1, -1)
)


def eigenvalue_view(eigenvalues: Any) -> float:
    """The reach ``|lambda|`` up to which an eigenvalue map is drawn, so that the poles that matter are seen.

    A map must separate its poles: one nearer the origin than 5 % of the
    axis' reach sits on the origin's marker. Of the candidate reaches (each
    eigenvalue's magnitude), the one that resolves the most eigenvalues, those
    with ``5 % of the reach <= |lambda| <= reach``, is chosen; on a tie the
    wider one, so that nothing is left out for nothing. A record with a
    wide-band mode at thousands of rad/s beside several slow modes is then
    drawn at the slow modes' scale and the fast one marked at the edge.

    Parameters
    ----------
    eigenvalues : array_like of complex
        Every eigenvalue to be drawn (all models and any reference); each
        conjugate pair counts once.

    Returns
    -------
    float
        The reach in rad/s, 1.0 where every eigenvalue is zero or none is finite.

    Examples
    --------
    >>> round(eigenvalue_view([-1 + 3j, -1 - 3j, -2 + 8j, -2 - 8j, -3000.0]), 3)  # |-2 + 8j|
    8.246
    >>> eigenvalue_view([-0.5, -3000.0])  # one each: the wider view loses nothing
    3000.0
    """
    values = np.asarray(eigenvalues, dtype=complex).ravel()
    magnitudes = np.abs(values[np.isfinite(values) & (values.imag >= 0)])
    candidates = np.unique(magnitudes[magnitudes > 0])
    best, best_count = 1.0, -1
    for reach in candidates[::-1]:  # widest first, so that a tie keeps the wider view
        count = np.count_nonzero((magnitudes >= _RESOLVED_FRACTION * reach) & (magnitudes <= reach))
        if count > best_count:
            best, best_count = float(reach), count
    return best


def _format_pole(value: complex) -> str:
    return f"{value.real:.3g} \u00b1 {abs(value.imag):.3g}j" if value.imag != 0 else f"{value.real:.3g}"


def _view_limits(shown: np.ndarray, reach: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits around the shown eigenvalues and the imaginary axis, with room for labels."""
    if shown.size == 0:
        return (-reach, 0.1 * reach), (-reach, reach)
    low, high = min(shown.real.min(), 0.0), max(shown.real.max(), 0.0)
    top = float(np.abs(shown.imag).max())
    width = high - low
    if width == 0.0:
        width = 0.2 * max(top, reach)
        low -= width
    if top == 0.0:
        top = 0.4 * width  # real poles only: a band around the real axis
    return (low - 0.08 * width, high + 0.08 * width), (-1.18 * top, 1.18 * top)


def _edge_marker(value: complex, x_limits: tuple[float, float], y_limits: tuple[float, float]) -> tuple[float, float, str]:
    """Where a pole outside the view meets its edge, and a triangle pointing the way out."""
    inset_x = 0.02 * (x_limits[1] - x_limits[0])
    inset_y = 0.03 * (y_limits[1] - y_limits[0])
    x = float(np.clip(value.real, x_limits[0] + inset_x, x_limits[1] - inset_x))
    y = float(np.clip(value.imag, y_limits[0] + inset_y, y_limits[1] - inset_y))
    if value.real < x_limits[0]:
        return x, y, "<"
    if value.real > x_limits[1]:
        return x, y, ">"
    return x, y, "^" if value.imag > 0 else "v"


def _overlap(box: Any, others: Sequence[Any]) -> float:
    area = 0.0
    for other in others:
        width = min(box.x1, other.x1) - max(box.x0, other.x0)
        height = min(box.y1, other.y1) - max(box.y0, other.y0)
        if width > 0 and height > 0:
            area += width * height
    return area


def _mode_clusters(values: np.ndarray, reach: float) -> list[np.ndarray]:
    """Eigenvalues grouped where they are the same mode of several models (within 8 % of their size).

    An order study's models share their dominant modes to a few percent; one
    label per mode keeps the map readable where one per model would pile up.
    """
    clusters: list[list[complex]] = []
    for value in sorted(values, key=abs):
        for members in clusters:
            if abs(value - members[0]) <= 0.08 * abs(members[0]) + 0.01 * reach:
                members.append(value)
                break
        else:
            clusters.append([value])
    return [np.asarray(members, dtype=complex) for members in clusters]


def _mode_text(members: np.ndarray) -> str:
    """Natural frequency (Hz) and damping ratio of a mode, as a range where several models differ."""
    magnitudes = np.abs(members)
    frequencies = magnitudes / (2 * np.pi)
    dampings = np.where(magnitudes > 0, -members.real / np.where(magnitudes > 0, magnitudes, 1.0), np.nan)

    def damping_text(value: float) -> str:
        return f"{value:.2f}" if not abs(value) < 0.095 else f"{value:.2g}"  # 0.005 must not read 0.00

    low, high = f"{frequencies.min():.2f}", f"{frequencies.max():.2f}"
    frequency = low if low == high else f"{low}-{high}"
    low, high = damping_text(np.nanmin(dampings)) if np.any(np.isfinite(dampings)) else "nan", \
        damping_text(np.nanmax(dampings)) if np.any(np.isfinite(dampings)) else "nan"
    damping = low if low == high else f"{low} to {high}"
    return f"{frequency} Hz, \u03b6 = {damping}"


def _place_labels(ax: Axes, notes: Sequence[Any], anchors: np.ndarray) -> None:
    """Move each pole's label to the first place beside its pole where it overlaps no other label or pole.

    The figure is laid out first (no pixels drawn), so the places are those
    of the page as saved; a label that fits nowhere takes the place of least
    overlap.
    """
    fig = ax.figure
    if not hasattr(fig.canvas, "get_renderer"):
        return  # a caller's figure without a pixel canvas: its labels keep their first place
    fig.draw_without_rendering()
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    to_pixels = ax.transData.transform
    half = 5.0 * fig.dpi / 72.0  # a marker of 7 pt, as a square of 10 pt
    points = to_pixels(np.c_[anchors.real, anchors.imag]) if len(anchors) else np.empty((0, 2))
    markers = [Bbox.from_extents(x - half, y - half, x + half, y + half) for x, y in points]
    placed: list[Any] = []
    order = sorted(notes, key=lambda note: -to_pixels(note.xy)[1])
    for note in order:
        where = to_pixels(note.xy)
        others = [m for m, p in zip(markers, points) if np.hypot(*(p - where)) > 0.5] + placed
        best, best_cost = _LABEL_PLACES[0], np.inf
        for place in _LABEL_PLACES:
            note.xyann = place[:2]
            note.set_horizontalalignment(place[2])
            note.set_verticalalignment(place[3])
            note.update_positions(renderer)
            box = Text.get_window_extent(note, renderer)
            outside = box.width * box.height - _overlap(box, [frame])
            cost = _overlap(box, others) + 4.0 * outside  # leaving the frame is worse than touching a label
            if cost < best_cost:
                best, best_cost = place, cost
            if cost == 0.0:
                break
        note.xyann = best[:2]
        note.set_horizontalalignment(best[2])
        note.set_verticalalignment(best[3])
        note.update_positions(renderer)
        placed.append(Text.get_window_extent(note, renderer))


def plot_eigenvalue_map(
    models: Mapping[str, Any],
    reference_eigenvalues: Any = None,
    *,
    annotate: bool = True,
    title: str = "Eigenvalues of the identified models",
    ax: Axes | None = None,
    confidence: bool = True,
) -> Figure:
    """Eigenvalues in the complex plane, each oscillatory mode annotated with frequency and damping.

    Models that carry a parameter covariance get the 95 % confidence ellipse
    of each eigenvalue (delta method; chi-square with 2 degrees of freedom,
    a line along the real axis for a real pole) unless ``confidence`` is False.

    The axes reach as far as :func:`eigenvalue_view` says: far enough to
    separate the poles that matter. Eigenvalues beyond are drawn as open
    triangles at the edge, pointing their way, and counted and listed under
    the real axis. The same mode of several models (within 8 %) gets one
    label, its frequency and damping as a range; labels are placed where
    they overlap neither each other nor a pole; the legend sits beside the map.

    Parameters
    ----------
    models : mapping of str to ModalModel, (A, B, C, D)-like or eigenvalue array
        Anything with ``eigenvalues()``, an ``A`` attribute, or the eigenvalues.
    reference_eigenvalues : array_like of complex, optional
        The source model's eigenvalues, drawn as open black circles.
    annotate : bool
        Label each eigenvalue with non-negative imaginary part by its natural
        frequency ``|lambda| / 2 pi`` (Hz) and damping ratio ``-Re(lambda)/|lambda|``.
    """
    fig = new_figure(REPORT_SIZE) if ax is None else ax.figure
    ax = style_axes(fig.subplots() if ax is None else ax)
    markers = "xs^Dv<>p"
    eigenvalues = {label: _eigenvalues(model) for label, model in models.items()}
    reference = None if reference_eigenvalues is None else np.asarray(reference_eigenvalues, dtype=complex).ravel()
    everything = np.concatenate([*eigenvalues.values(), *([] if reference is None else [reference])]) \
        if eigenvalues or reference is not None else np.empty(0, dtype=complex)
    everything = everything[np.isfinite(everything)]
    reach = eigenvalue_view(everything)

    def in_view(values: np.ndarray) -> np.ndarray:
        return np.isfinite(values) & (np.abs(values) <= reach * (1 + 1e-9))

    x_limits, y_limits = _view_limits(everything[in_view(everything)], reach)
    notes, anchors, beyond, outlines, labelled = [], [], [], [], []
    for k, (label, values) in enumerate(eigenvalues.items()):
        model = models[label]
        inside = in_view(values)
        points = ax.plot(values[inside].real, values[inside].imag, linestyle="none", marker=markers[k % len(markers)],
                         markersize=7, markeredgewidth=1.6, label=label)
        color = points[0].get_color()
        if confidence and getattr(model, "parameter_covariance", None) is not None:
            for mode in model.uncertainty().modes:
                if in_view(np.array([mode.eigenvalue]))[0]:
                    outlines.extend(_ellipse(ax, mode.eigenvalue, mode.eigenvalue_covariance, color))
        for value in values[~inside & np.isfinite(values)]:
            x, y, marker = _edge_marker(value, x_limits, y_limits)
            ax.plot([x], [y], linestyle="none", marker=marker, markersize=8, markerfacecolor="none",
                    markeredgecolor=color, markeredgewidth=1.4)
            beyond.append(value)
        anchors.extend(values[inside])
        labelled.extend(values[inside & (values.imag >= 0)])
    if annotate:
        for members in _mode_clusters(np.asarray(labelled, dtype=complex), reach):
            centre = complex(np.mean(members))
            note = ax.annotate(_mode_text(members), (centre.real, centre.imag), textcoords="offset points",
                               xytext=(6, 4), fontsize=8)
            note.set_in_layout(False)  # placed after the layout, inside the frame
            notes.append(note)
    if reference is not None:
        inside = in_view(reference)
        ax.plot(reference[inside].real, reference[inside].imag, linestyle="none", marker="o", markersize=10,
                markerfacecolor="none", markeredgecolor="k", label="reference")
        for value in reference[~inside & np.isfinite(reference)]:
            x, y, marker = _edge_marker(value, x_limits, y_limits)
            ax.plot([x], [y], linestyle="none", marker=marker, markersize=9, markerfacecolor="none",
                    markeredgecolor="k")
            beyond.append(value)
        anchors.extend(reference[inside])
    if outlines:  # an ellipse may widen the view, but only so far that the poles stay apart
        outline = np.concatenate(outlines, axis=1)
        width, height = x_limits[1] - x_limits[0], y_limits[1] - y_limits[0]
        x_limits = (max(min(x_limits[0], outline[0].min()), x_limits[0] - width),
                    min(max(x_limits[1], outline[0].max()), x_limits[1] + width))
        y_limits = (max(min(y_limits[0], outline[1].min()), y_limits[0] - height),
                    min(max(y_limits[1], outline[1].max()), y_limits[1] + height))
    ax.set_xlim(x_limits)
    ax.set_ylim(y_limits)
    ax.axvline(0.0, color="k", linewidth=0.8)
    ax.axhline(0.0, color="k", linewidth=0.8)
    x_label = "real part (1/s)"
    if beyond:
        upper = sorted({complex(round(v.real, 12), round(abs(v.imag), 12)) for v in beyond}, key=abs)
        listed = ", ".join(_format_pole(v) for v in upper[:3]) + (", ..." if len(upper) > 3 else "")
        # the list on a line of its own: beside the legend the axis is narrower than the page
        x_label += f"\n{len(beyond)} eigenvalue{'s' if len(beyond) > 1 else ''} beyond the view (open triangles " \
                   f"at the edge):\n{listed}"
    ax.set_xlabel(x_label)
    ax.set_ylabel("imaginary part (rad/s)")
    ax.set_title(title)
    add_legend(ax)
    if notes:
        _place_labels(ax, notes, np.asarray(anchors, dtype=complex))
    return fig


ELLIPSE_SCALE = float(np.sqrt(chi2.ppf(0.95, 2)))  # 95 % region of a 2-D normal, in standard deviations


def _ellipse(ax: Axes, value: complex, covariance: np.ndarray, color: Any) -> list[np.ndarray]:
    """The 95 % ellipse of an eigenvalue (and its mirror image for a pair) from the covariance of (re, im).

    Returns the outlines drawn, each of shape (2, n_points): real and imaginary parts.
    """
    if not np.all(np.isfinite(covariance)):
        return []
    values, vectors = scipy.linalg.eigh(covariance)  # numpy's stalls under load with this BLAS
    angle = np.linspace(0.0, 2 * np.pi, 60)
    circle = np.vstack([np.cos(angle), np.sin(angle)])
    outline = vectors @ (ELLIPSE_SCALE * np.sqrt(np.maximum(values, 0.0))[:, None] * circle)
    ax.plot(value.real + outline[0], value.imag + outline[1], color=color, linewidth=0.9)
    drawn = [np.vstack([value.real + outline[0], value.imag + outline[1]])]
    if value.imag != 0:
        ax.plot(value.real + outline[0], -value.imag - outline[1], color=color, linewidth=0.9)
        drawn.append(np.vstack([value.real + outline[0], -value.imag - outline[1]]))
    return drawn
