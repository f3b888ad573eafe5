"""The envelope campaign's report: modes and fits against speed, the scheduled model, a table per vehicle.

Per vehicle ``<vehicle>_modes.png`` (identified modes, the vehicle's own and
the scheduled model's against speed) and ``<vehicle>_fits.png`` (validation R
against speed); ``tables.md``; and each scheduled family as one CasADi
Function ``(x, u, speed) -> (xdot, y)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from .figure_style import add_legend, new_figure, style_axes

__all__ = ["envelope_figures", "write_envelope_report"]


def envelope_figures(result: Any) -> dict[str, Figure]:
    """The report's figures for an :class:`~scenarios.envelope.EnvelopeResult`, by file stem."""
    summary = result.summary
    figures: dict[str, Figure] = {}
    vehicles = list(dict.fromkeys(row["vehicle"] for row in summary["rows"]))
    orders = sorted({row["order"] for row in summary["rows"]})
    colours = {order: f"C{k}" for k, order in enumerate(orders)}
    for vehicle in vehicles:
        rows = [row for row in summary["rows"] if row["vehicle"] == vehicle]
        fig = new_figure((9.0, 6.5))
        freq_ax, damp_ax = fig.subplots(2, 1, sharex=True)
        for order in orders:
            points = [(row["speed"], m) for row in rows if row["order"] == order for m in row["modes"]]
            if points:
                speeds = [p[0] for p in points]
                freq_ax.plot(speeds, [p[1]["frequency_hz"] for p in points], "o", color=colours[order],
                             label=f"identified, n = {order}")
                damp_ax.plot(speeds, [p[1]["damping"] for p in points], "o", color=colours[order])
            family = result.scheduled.get((vehicle, order, result.config.seeds[0]))
            if family is not None:
                sweep = np.linspace(family.grid[0], family.grid[-1], 41)
                modes = np.array([family.model_at(v).mode_eigenvalues() for v in sweep])
                magnitude = np.abs(modes)
                freq_ax.plot(sweep, magnitude / (2 * np.pi), "-", lw=0.8, color=colours[order])
                damp_ax.plot(sweep, -modes.real / magnitude, "-", lw=0.8, color=colours[order])
        grid_rows = sorted({row["speed"]: row for row in rows}.items())
        labels = sorted({m["label"] for _, row in grid_rows for m in row["vehicle_modes"]})
        for style, label in zip(("k-", "k--", "k:"), labels):
            values = [(speed, m) for speed, row in grid_rows for m in row["vehicle_modes"] if m["label"] == label]
            freq_ax.plot([v[0] for v in values], [v[1]["frequency_hz"] for v in values], style, lw=2,
                         label=f"vehicle {label}")
            damp_ax.plot([v[0] for v in values], [v[1]["damping"] for v in values], style, lw=2)
        freq_ax.set_ylabel("frequency (Hz)")
        damp_ax.set_ylabel("damping ratio")
        damp_ax.set_xlabel("speed (m/s)")
        freq_ax.set_title(f"{vehicle}: modes against speed (lines: scheduled model)")
        for ax in (freq_ax, damp_ax):
            style_axes(ax)
        add_legend(freq_ax)
        figures[f"{vehicle}_modes"] = fig

        fig = new_figure((9.0, 4.5))
        ax = fig.subplots()
        for order in orders:
            mine = [row for row in rows if row["order"] == order]
            ax.plot([r["speed"] for r in mine], [r["linear_validation_R"] for r in mine], "o-", color=colours[order],
                    label=f"linear, n = {order}")
            if any(r["nonlinear_validation_R"] is not None for r in mine):
                ax.plot([r["speed"] for r in mine], [r["nonlinear_validation_R"] for r in mine], "s--",
                        color=colours[order], label=f"nonlinear, n = {order}")
        off = [item for item in summary["scheduled"]["off_grid"] if item["vehicle"] == vehicle]
        if off:
            ax.plot([i["speed"] for i in off], [i["validation_R"] for i in off], "k*", ms=10, label="scheduled model")
        ax.set_xlabel("speed (m/s)")
        ax.set_ylabel("validation R (%)")
        ax.set_title(f"{vehicle}: fit on validation data per job")
        style_axes(ax)
        add_legend(ax)
        figures[f"{vehicle}_fits"] = fig
    return figures


def write_envelope_report(result: Any, out_dir: str | Path) -> list[Path]:
    """Write the figures, the tables and the scheduled models' CasADi exports into ``out_dir``."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for stem, fig in envelope_figures(result).items():
        path = folder / f"{stem}.png"
        fig.savefig(path, dpi=110)
        written.append(path)
    table = folder / "tables.md"
    table.write_text("```\n" + result.text + "\n```\n")
    written.append(table)
    for (vehicle, order, seed), family in result.scheduled.items():
        path = folder / f"{vehicle}_n{order}_s{seed}_scheduled.casadi"
        family.to_casadi().save(str(path))
        written.append(path)
    return written
