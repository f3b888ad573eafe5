"""Report figures legible at page size: every figure of a report drawn from a real record, checked on the renderer.

The checks look at what matplotlib's Agg renderer lays out (``fig.canvas.draw()``,
then each artist's window extent in pixels): no two texts overlap, no text runs
past the edge of the figure, no axis is left empty and no legend lies on top of
the data. The records are the public ones under ``tests/data`` (the dryer and the
flexible robot arm of DaISy), the handling study's archive and a scheduled run on the committed race car's lap.
"""

from __future__ import annotations

import itertools
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.figure import Figure

from vehid.identification.dataio.archive import read_archive
from vehid.identification.assessment.metrics import percentage_explanation
from vehid.scenarios import plots
from vehid.scenarios.cli import main
from vehid.scenarios.handling_report import handling_figures
from vehid.identification.automatic.archiving import SCORING_RULE
from vehid.scenarios.report import archive_figures, archive_table, archive_verdict, verdict_lines, verdict_output_names, verdict_page

DATA = Path(__file__).parent / "data"

# Text boxes are the glyphs' ink plus ascent and descent, so neighbours in a
# line of tick labels may share a pixel column without anything overlapping
# on screen; an overlap counts once it exceeds this many pixels both ways.
OVERLAP_PX = 1.0
# A text may end on the figure's last pixel row or column (rounding of the
# extent to the pixel grid); beyond that it is cut off.
EDGE_PX = 0.5


def _texts(fig: Figure, renderer) -> list[tuple[str, object]]:
    """Every text drawn on the figure with its window extent: titles, labels, tick labels in view, notes, legends."""
    found: list[tuple[str, object]] = []
    seen: set[int] = set()  # the figure's title is also one of its texts

    def add(text, where: str) -> None:
        if text is not None and id(text) not in seen and text.get_visible() and text.get_text().strip():
            seen.add(id(text))
            found.append((f"{where} {text.get_text()!r}", text.get_window_extent(renderer)))

    add(fig._suptitle, "figure title")
    for text in fig.texts:
        add(text, "figure text")
    for legend in fig.legends:
        for text in legend.get_texts():
            add(text, "figure legend")
    for index, ax in enumerate(fig.axes):
        if not ax.get_visible():
            continue
        where = f"axis {index}"
        for text in (ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label,
                     ax.xaxis.get_offset_text(), ax.yaxis.get_offset_text()):
            add(text, where)
        for axis in (ax.xaxis, ax.yaxis):
            low, high = sorted(axis.get_view_interval())
            margin = 1e-9 * max(abs(low), abs(high), 1e-300)
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if low - margin <= tick.get_loc() <= high + margin:
                    add(tick.label1, f"{where} tick")
                    add(tick.label2, f"{where} tick")
        for text in ax.texts:
            add(text, f"{where} note")
        if ax.get_legend() is not None:
            for text in ax.get_legend().get_texts():
                add(text, f"{where} legend")
    return found


def _data_points(ax) -> np.ndarray:
    """Pixel positions of the finite vertices of the axis's lines that fall inside its frame."""
    frame = ax.get_window_extent()
    points = []
    for line in ax.get_lines():
        xy = np.column_stack([np.asarray(line.get_xdata(), dtype=float), np.asarray(line.get_ydata(), dtype=float)])
        xy = xy[np.all(np.isfinite(xy), axis=1)]
        if xy.size:
            pixels = line.get_transform().transform(xy)
            inside = ((pixels[:, 0] >= frame.x0) & (pixels[:, 0] <= frame.x1)
                      & (pixels[:, 1] >= frame.y0) & (pixels[:, 1] <= frame.y1))
            points.append(pixels[inside])
    return np.concatenate(points) if points else np.empty((0, 2))


def legibility_problems(fig: Figure) -> list[str]:
    """What keeps a figure from being read: overlapping or cut-off text, empty axes, legends over the data."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    problems = []
    texts = _texts(fig, renderer)
    page = fig.bbox
    for name, box in texts:
        if (box.x0 < page.x0 - EDGE_PX or box.y0 < page.y0 - EDGE_PX
                or box.x1 > page.x1 + EDGE_PX or box.y1 > page.y1 + EDGE_PX):
            problems.append(f"cut off by the figure's edge: {name}")
    for (first, a), (second, b) in itertools.combinations(texts, 2):
        width = min(a.x1, b.x1) - max(a.x0, b.x0)
        height = min(a.y1, b.y1) - max(a.y0, b.y0)
        if width > OVERLAP_PX and height > OVERLAP_PX:
            problems.append(f"overlap: {first} and {second}")
    visible = [ax for ax in fig.axes if ax.get_visible()]
    for index, ax in enumerate(visible):
        drawn = len(_data_points(ax)) or any(len(c.get_paths()) for c in ax.collections) or ax.patches or ax.images
        if not drawn:
            problems.append(f"axis {index} ({ax.get_title() or ax.get_ylabel()!r}) shows no data")
    legends = [ax.get_legend() for ax in visible if ax.get_legend() is not None] + list(fig.legends)
    for legend in legends:
        box = legend.get_window_extent(renderer)
        for ax in visible:
            points = _data_points(ax)
            covered = np.count_nonzero((points[:, 0] > box.x0) & (points[:, 0] < box.x1)
                                       & (points[:, 1] > box.y0) & (points[:, 1] < box.y1))
            if covered:
                problems.append(f"legend {[t.get_text() for t in legend.get_texts()]} covers {covered} data points")
    return problems


def _assert_legible(figures: dict[str, Figure]) -> None:
    assert figures
    found = {name: legibility_problems(fig) for name, fig in figures.items()}
    assert not any(found.values()), {name: problems for name, problems in found.items() if problems}


# ------------------------------------------------------------ the checks see what they look for
def test_the_checks_find_overlap_cut_off_text_empty_axes_and_a_legend_on_the_data():
    fig = plots.new_figure()
    full, empty = fig.subplots(1, 2)
    full.plot(np.linspace(0, 1, 50), np.linspace(0, 1, 50), label="data")
    full.legend(loc="center")  # on the diagonal the line runs along
    full.text(0.1, 0.8, "first note")
    full.text(0.1, 0.8, "second note")
    fig.text(0.98, 0.5, "a note that runs off the page")
    problems = legibility_problems(fig)
    assert any(p.startswith("overlap:") and "first note" in p and "second note" in p for p in problems)
    assert any(p.startswith("cut off") and "runs off the page" in p for p in problems)
    assert any(p.startswith("axis 1") and p.endswith("shows no data") for p in problems)
    assert any(p.startswith("legend ['data'] covers") for p in problems)


# ------------------------------------------------------------ reports of real records
def test_every_figure_of_a_report_on_the_dryer_record_is_legible():
    """The committed archive of an N4SID run on the DaISy dryer (see tests/data/archives/README.md)."""
    _assert_legible(archive_figures(read_archive(DATA / "archives" / "identify_n4sid.h5")))


@pytest.fixture(scope="module")
def robot_arm_figures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("robot_arm")
    archive = folder / "robot_arm.h5"
    status = main(["identify", str(DATA / "robot_arm" / "robot_arm.dat"), "--inputs", "1", "--outputs", "2",
                   "--dt", "0.1", "--order", "4", "--method", "n4sid", "--validation", "0.3", "--quiet",
                   "--out", str(archive)])
    assert status == 0
    return archive_figures(read_archive(archive))


def test_every_figure_of_a_report_on_the_robot_arm_record_is_legible(robot_arm_figures):
    assert {"eigenvalues", "bode", "fits_identification", "fits_validation"} <= set(robot_arm_figures)
    _assert_legible(robot_arm_figures)


def test_channel_names_of_a_headerless_table_read_as_columns(robot_arm_figures):
    """The record's channels are its columns 1 (torque) and 2 (acceleration); no unit is known, none is invented."""
    bode = robot_arm_figures["bode"]
    assert bode._suptitle.get_text() == "Frequency response from column 1"
    assert bode.axes[0].get_title() == "column 2"
    assert "(-" not in bode.axes[0].get_ylabel()
    assert robot_arm_figures["fits_validation"].axes[0].get_ylabel() == "column 2"


def test_a_long_real_record_is_drawn_as_its_envelope_and_kept_whole(tmp_path):
    """The DaISy heat exchanger: 4,000 rows, of which 70 % identify; more samples than a report axis has pixels."""
    archive = tmp_path / "exchanger.h5"
    assert main(["identify", str(DATA / "exchanger" / "exchanger.dat"), "--inputs", "2", "--outputs", "3",
                 "--dt", "1", "--order", "2", "--method", "n4sid", "--validation", "0.3", "--quiet",
                 "--out", str(archive)]) == 0
    stored = read_archive(archive)
    record = stored.records["identification"]
    assert record.n_samples + stored.records["validation"].n_samples == 4000  # every row kept in the archive
    figures = archive_figures(stored)
    measured = figures["fits_identification"].axes[0].get_lines()[0]
    drawn = np.asarray(measured.get_ydata())
    assert len(drawn) < record.n_samples and len(drawn) <= 2002  # thinned for the page ...
    assert drawn.max() == record.y[:, 0].max() and drawn.min() == record.y[:, 0].min()  # ... with its extremes
    _assert_legible(figures)


def test_a_report_of_a_scheduled_run_on_a_real_log_draws_the_family_names_the_channels_and_is_legible(
        scheduled_race_car_run):
    """The race car's lap identified with ``--schedule vx`` (tests/conftest.py): the family is drawn in the fits,
    frequency-response and eigenvalue figures, the returned model first and marked; every figure and the verdict
    page name the log's channels (never ``y1``, ``y2``); and the pages that show the family are legible (the
    residual pages are those of every report, checked on the robot arm's above)."""
    summary, path = scheduled_race_car_run
    archive = read_archive(path)
    figures = archive_figures(archive)
    verdict = archive_verdict(archive)
    figures["verdict"] = verdict_page(verdict_lines(verdict, verdict_output_names(archive, verdict)))
    returned = f"{verdict[SCORING_RULE]['returned_run']} (returned)"  # the run the archive names as returned
    for name in ("fits_identification", "fits_validation"):
        for ax in figures[name].axes:
            legend = [text.get_text() for text in ax.get_legend().get_texts()]
            assert legend[1].startswith(returned) and any(text.startswith("scheduled") for text in legend), legend
    for name in ("bode", "eigenvalues"):
        legend = figures[name].legends[0] if figures[name].legends else figures[name].axes[0].get_legend()
        frozen = [text.get_text() for text in legend.get_texts() if text.get_text().startswith("scheduled")]
        assert len(frozen) == 3 and all("at vx = " in text and text.endswith(" m/s") for text in frozen), frozen
    texts = [text for fig in figures.values() for text in fig.findobj(lambda artist: hasattr(artist, "get_text"))]
    shown = " ".join(text.get_text() for text in texts)
    assert "yawRate" in shown and "ayCG" in shown and not re.search(r"\by[12]\b", shown)
    _assert_legible({name: figures[name] for name in ("verdict", "fits_identification", "fits_validation", "bode",
                                                      "eigenvalues", "convergence_iekf")})
    # the summary table too: asking the family for its eigenvalues without a speed stopped `vehid report`
    rows = {row["run"]: row for row in archive_table(archive)}
    assert all(len(row["eigenvalues"]) > 0 for row in rows.values()), rows
    for name, run in archive.runs.items():
        if hasattr(run.model, "grid"):  # a family's are those of its middle knot, drawn in the figures
            knot = float(run.model.grid[run.model.grid.size // 2])
            assert np.allclose(sorted(rows[name]["eigenvalues"], key=lambda z: (z.real, z.imag)),
                               sorted(run.model.model_at(knot).eigenvalues(), key=lambda z: (z.real, z.imag)))


@pytest.mark.slow
def test_every_figure_of_the_handling_report_is_legible():
    _assert_legible(handling_figures(read_archive(DATA / "archives" / "handling_study.h5")))


# ------------------------------------------------------------ the pole map
def test_a_wide_band_pole_is_marked_at_the_edge_and_the_slow_modes_fill_the_map():
    slow = np.array([-0.8 + 6.0j, -0.8 - 6.0j, -1.5 + 11.0j, -1.5 - 11.0j, -4.0])
    fast = np.array([-2900.0, -3100.0])
    fig = plots.plot_eigenvalue_map({"identified": np.concatenate([slow, fast])})
    (ax,) = fig.axes
    left, right = ax.get_xlim()
    bottom, top = ax.get_ylim()
    # Every slow pole inside the frame, and the frame no wider than a few times the slow modes' reach:
    # the map separates them instead of stacking them at the origin.
    assert left < slow.real.min() and right > 0 and bottom < -11.0 < 11.0 < top
    assert right - left < 3 * np.abs(slow).max() and top < 3 * np.abs(slow).max()
    # The two fast poles, outside, are drawn at the left edge and counted with their values.
    edge = [line for line in ax.get_lines() if line.get_marker() == "<"]
    assert len(edge) == 2 and all(left <= line.get_xdata()[0] <= right for line in edge)
    note = " ".join(ax.get_xlabel().splitlines()[1:])
    assert note.startswith("2 eigenvalues beyond the view") and "-2.9e+03" in note and "-3.1e+03" in note
    assert not legibility_problems(fig)


def test_labels_of_a_crowded_map_do_not_overlap():
    """Five models of the same plant (an order study) whose modes nearly coincide, as in the handling study."""
    rng = np.random.default_rng(3)
    base = np.array([-1.0 + 7.0j, -2.5 + 9.0j, -3.0 + 2.0j])
    models = {}
    for n in range(2, 7):
        modes = base[: min(3, n // 2 + 1)] * (1 + 0.03 * rng.normal(size=min(3, n // 2 + 1)))
        models[f"n = {n}"] = np.concatenate([modes, modes.conj()])
    fig = plots.plot_eigenvalue_map(models, reference_eigenvalues=np.concatenate([base, base.conj()]))
    assert len(fig.axes[0].texts) >= 3
    assert not legibility_problems(fig)


def test_eigenvalue_view_resolves_the_most_poles():
    assert plots.eigenvalue_view([-1 + 3j, -1 - 3j, -2 + 8j, -2 - 8j, -3000.0]) == pytest.approx(abs(-2 + 8j))
    # Two real poles far apart: either view resolves one, and the wider one hides nothing.
    assert plots.eigenvalue_view([-0.5, -3000.0]) == 3000.0
    # A drift pole near zero does not shrink the map below the resonances.
    assert plots.eigenvalue_view([-1e-4, -0.02 + 3.7j, -0.02 - 3.7j, -0.03 + 8j, -0.03 - 8j]) == pytest.approx(
        abs(-0.03 + 8j))
    assert plots.eigenvalue_view([0.0]) == 1.0


# ------------------------------------------------------------ long records
def test_display_samples_keep_every_peak_of_a_long_record():
    rng = np.random.default_rng(7)
    count, bins = 39_000, 1000
    t = np.arange(count) * 0.01
    y = np.cumsum(rng.normal(size=count)) + 5.0 * (rng.random(count) > 0.9995)  # a random walk with rare spikes
    shown_t, shown_y = plots.display_samples(t, y, bins)
    assert shown_t.size <= 2 * bins + 2 and np.all(np.diff(shown_t) > 0)
    # Each stretch's extremes, computed directly, are among the drawn points (the envelope is exact).
    width = -(-count // bins)
    for start in range(0, count, width):
        stretch = slice(start, start + width)
        drawn = shown_y[(shown_t >= t[stretch][0]) & (shown_t <= t[stretch][-1])]
        assert drawn.max() == y[stretch].max() and drawn.min() == y[stretch].min()
    assert shown_t[0] == t[0] and shown_t[-1] == t[-1]
    short_t, short_y = plots.display_samples(t[:500], y[:500], bins)
    assert np.array_equal(short_t, t[:500]) and np.array_equal(short_y, y[:500])


def test_time_fits_of_a_long_record_draw_an_envelope_and_score_every_sample():
    rng = np.random.default_rng(11)
    t = np.arange(39_000) * 0.002
    y = np.column_stack([np.sin(2 * np.pi * 0.3 * t) + 0.2 * rng.normal(size=t.size)])
    predicted = np.sin(2 * np.pi * 0.3 * t)[:, None]
    fig = plots.plot_time_fits(t, y, {"model": predicted}, ["SW_pos_obd"], ["deg"])
    (ax,) = fig.axes
    measured, model = ax.get_lines()
    assert len(measured.get_xdata()) <= 2002 and np.max(measured.get_ydata()) == y.max()
    assert np.min(measured.get_ydata()) == y.min()
    expected = percentage_explanation(y, predicted)[0]  # over all 39,000 samples
    assert ax.get_legend().get_texts()[1].get_text() == f"model (R = {expected:.2f} %)"
    assert ax.get_ylabel() == "SW_pos_obd (deg)"
    assert not legibility_problems(fig)

