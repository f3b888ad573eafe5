"""Time as the user sees it: segments from the log's start, time columns by their header, messages in the axes' time.

The epoch-stamped log is the committed race-car log with 1.69e9 s added to its time and its header written as a
comment line (``# time(s),delta(rad),...``), as the race-car loggers publish theirs: its truth is the committed
file, row for row.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification import InputError, read_record
from vehid.identification.dataio.timewindow import TimeWindow, parse_time_window, parse_time_windows

ROOT = Path(__file__).resolve().parent.parent
RACE_LOG = ROOT / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
EPOCH = 1.69e9  # s: where the race-car loggers' Unix time stamps lie
HEADER = "time(s),delta(rad),vx(m/s),yawRate(rad/s),ayCG(m/s^2),beta_true(rad)"


@pytest.fixture(scope="module")
def committed():
    return np.loadtxt(RACE_LOG, delimiter=",", skiprows=2)


@pytest.fixture(scope="module")
def epoch_log(committed, tmp_path_factory):
    """The committed log stamped in epoch seconds (to 0.01 s, as committed), its header a comment line."""
    table = committed.copy()
    table[:, 0] += EPOCH
    path = tmp_path_factory.mktemp("epoch") / "race_epoch.csv"
    np.savetxt(path, table, delimiter=",", header=HEADER, fmt=["%.2f"] + ["%.6g"] * 5)
    return path


def test_a_comment_header_names_the_time_column_time_s(epoch_log, committed):
    data = read_record(epoch_log, inputs=["delta"], outputs=["yawRate", "ayCG"])  # no --time-column
    assert data.meta["time_base"]["time_offset"] == pytest.approx(EPOCH + 390.0, abs=1e-6)
    assert data.n_samples == 8000 and data.dt == pytest.approx(0.01, rel=1e-9)
    np.testing.assert_array_equal(data.y, committed[:, 3:5])


@pytest.mark.parametrize("header", ["t [s],u,y", "Time,u,y", "TIME [ms],u,y"])
def test_time_headers_with_units_are_time_columns(tmp_path, header):
    stamps = np.arange(50) * (0.01 if "ms" not in header else 10.0)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([stamps, np.sin(stamps), np.cos(stamps)]), delimiter=",", header=header,
               comments="", fmt="%.10g")
    assert read_record(path, inputs=["u"], outputs=["y"]).dt == pytest.approx(0.01, rel=1e-9)


def test_two_time_columns_are_named_for_the_user_to_choose(tmp_path):
    path = tmp_path / "two.csv"
    path.write_text("time(s),Time [ms],u,y\n0,0,1,2\n0.1,100,2,3\n0.2,200,3,5\n")
    with pytest.raises(InputError, match=r"two.csv has 2 time columns \(time\(s\), Time \[ms\]\)"):
        read_record(path, inputs=["u"], outputs=["y"])
    assert read_record(path, inputs=["u"], outputs=["y"], time_column="time(s)").n_samples == 3


def test_a_segment_from_the_log_start_on_epoch_time(epoch_log, committed):
    data = read_record(epoch_log, inputs=["delta"], outputs=["yawRate"], segment="+20:+130")
    # +20 s to the end (the log is 80 s long): rows 2000 on, time counted from the segment's first sample
    assert data.n_samples == 6000
    assert data.meta["time_base"]["time_offset"] == pytest.approx(EPOCH + 410.0, abs=1e-6)
    np.testing.assert_array_equal(data.u[:, 0], committed[2000:, 1])
    # on a log kept in its own time (390-470 s) a relative segment counts from 390 s as well
    near = read_record(RACE_LOG, inputs=["delta"], outputs=["yawRate"], segment="+20:+30")
    assert near.t[0] == pytest.approx(410.0) and near.t[-1] == pytest.approx(420.0)
    assert near.meta["time_base"]["segment"] == [pytest.approx(410.0), pytest.approx(420.0)]


def test_messages_print_time_as_the_axes_do(epoch_log):
    with pytest.raises(InputError) as caught:
        read_record(epoch_log, inputs=["delta"], outputs=["yawRate"], segment="20:130")
    assert str(caught.value) == (
        "the segment 20:130 s selects 0 samples of 'delta' in race_epoch.csv, which is 79.99 s long (file time "
        "1690000390 to 1690000469.99 s): a segment without + is in the file's time; +T0:+T1 counts from the "
        "log's first sample")
    with pytest.raises(InputError) as caught:  # a log in its own time: its own times, no hint
        read_record(RACE_LOG, inputs=["delta"], outputs=["yawRate"], segment="20:130")
    assert str(caught.value).endswith("which runs from 390 to 469.99 s")


@pytest.mark.parametrize("text, window", [
    ("+20:+130", TimeWindow(20.0, 130.0, True)),
    ("+20:", TimeWindow(20.0, np.inf, True)),
    (":+30", TimeWindow(-np.inf, 30.0, True)),
    ("390:400.5", TimeWindow(390.0, 400.5, False)),
    ("-5:", TimeWindow(-5.0, np.inf, False)),
])
def test_the_window_grammar(text, window):
    parsed = parse_time_window(text)
    assert parsed == window and parse_time_window(str(parsed)) == parsed  # written back as it reads


@pytest.mark.parametrize("text, message", [
    ("+20:130", "a segment '+20:130' mixes the file's time and time from the log's start"),
    ("+30:+20", "a segment needs T0 < T1; got +30:+20"),
    ("20", "a segment is T0:T1 in the file's time (s), or +T0:+T1"),
    ("a:b", "a segment is T0:T1 in the file's time (s), or +T0:+T1"),
])
def test_bad_windows_are_named(text, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)").replace("+", r"\+")):
        parse_time_window(text)


def test_several_windows_as_repeated_options_or_a_list():
    assert parse_time_windows(["+1:+2", "5:6,+8:+9"]) == (
        TimeWindow(1, 2, True), TimeWindow(5, 6, False), TimeWindow(8, 9, True))


def test_single_track_takes_a_relative_segment_of_an_epoch_log(epoch_log):
    """Before: "no channel 'vx'", the segment's own error hidden by the search for the speed channel."""
    done = run_vehid("identify", str(epoch_log), "--structure", "single-track", "--inputs", "delta",
                     "--schedule", "vx", "--outputs", "yawRate,ayCG", "--mass", "982", "--lf", "1.33",
                     "--lr", "1.07", "--segment", "+20:+130", "--json")
    assert done.returncode == 0, done.stderr[-800:]
    summary = json.loads(done.stdout)
    # 20 s to the end of the committed log (410-470 s): its speed range, read from the committed file
    table = np.loadtxt(RACE_LOG, delimiter=",", skiprows=2)
    inside = table[:, 0] >= 410.0 - 1e-9
    assert summary["speed_range_m_s"] == [pytest.approx(table[inside, 2].min()), pytest.approx(table[inside, 2].max())]
    wrong = run_vehid("identify", str(epoch_log), "--structure", "single-track", "--inputs", "delta",
                      "--schedule", "vx", "--outputs", "yawRate,ayCG", "--mass", "982", "--lf", "1.33",
                      "--lr", "1.07", "--segment", "20:60")
    assert wrong.returncode == 2 and "selects 0 samples" in wrong.stderr and "no channel" not in wrong.stderr
