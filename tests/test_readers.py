"""Readers of measured files and the uniform time base: every format, every rejection with its exact message."""

import re

import h5py
import numpy as np
import pytest
import scipy.io

from vehid.identification import InputError, read_record
from vehid.identification.dataio.timebase import JITTER_TOLERANCE
from vehid.scenarios.commands.flags import command_line_message

NAMES_A_FLAG = re.compile(r"(?<![\w-])--[a-z]")


def _write(path, text):
    path.write_text(text)
    return path


def _rejects(message, path, **options):
    """``message`` as the command line shows it; the library's own names options by keyword, never by flag."""
    with pytest.raises(InputError) as caught:
        read_record(path, **options)
    assert not NAMES_A_FLAG.search(str(caught.value)), str(caught.value)
    assert command_line_message(caught.value) == message


# ----------------------------------------------------------------------------- CSV
def test_tolerant_csv_reads_only_the_chosen_columns(tmp_path):
    # quoted header, a units row, trailing commas, a text column, blank cells and a line of spaces elsewhere
    path = _write(tmp_path / "log.csv",
                  '"t","steer","note","ay",\n"s","rad","-","m/s2",\n0,0.1,start,1,\n0.5,0.2,,2,\n   \n'
                  '1.0,0.3,"a, b",3,\n1.5,0.4,,4,\n')
    data = read_record(path, inputs=["steer"], outputs=["ay"])
    np.testing.assert_array_equal(data.t, [0, 0.5, 1.0, 1.5])
    np.testing.assert_array_equal(data.u[:, 0], [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(data.y[:, 0], [1, 2, 3, 4])
    assert data.input_units == ("rad",) and data.output_units == ("m/s2",)
    assert data.meta["time_base"]["sample_jitter"] == 0.0


def test_semicolon_csv_and_named_time_column(tmp_path):
    path = _write(tmp_path / "log.csv", "time;steer;ay\n10;1;2\n10.1;2;3\n10.2;3;4\n")
    data = read_record(path, inputs=["steer"], outputs=["ay"], time_column="time")
    assert data.dt == pytest.approx(0.1) and data.t[0] == 10.0


def test_european_csv_with_decimal_commas(tmp_path):
    path = _write(tmp_path / "eu.csv", "Zeit;Lenkwinkel;Gierrate\n0,0;1,5;-2,25\n0,1;2,5;3e-1\n0,2;3,5;4,0\n")
    data = read_record(path, inputs=["Lenkwinkel"], outputs=["Gierrate"], time_column="Zeit")
    np.testing.assert_array_equal(data.u[:, 0], [1.5, 2.5, 3.5])
    np.testing.assert_array_equal(data.y[:, 0], [-2.25, 0.3, 4.0])
    assert data.dt == pytest.approx(0.1)


CSV = "t,u,y,u\n0,1,2,9\n0.5,2,3,9\n1,3,x,9\n1.5,4,5,9\n"


@pytest.mark.parametrize("options, message", [
    (dict(inputs=["u"], outputs=["y"]),
     "column name 'u' appears 2 times in bad.csv (columns 2, 4): rename the duplicates"),
    (dict(inputs=["1"], outputs=["y"]), "bad.csv: column 'y' holds 'x' at line 4, not a number"),
    (dict(inputs=["1"], outputs=["q"]), "unknown column 'q' in bad.csv; columns: t, u, y, u"),
    (dict(inputs=["1"], outputs=["3"], dt=0.1),
     "bad.csv has a time column 't': --dt would override it; drop --dt, or disable the time column with "
     "--time-column none"),
])
def test_csv_rejections(tmp_path, options, message):
    _rejects(message, _write(tmp_path / "bad.csv", CSV), **options)


def test_blank_and_short_rows_in_chosen_columns(tmp_path):
    _rejects("blank.csv: column 'y' holds a blank cell at line 3, not a number",
             _write(tmp_path / "blank.csv", "t,u,y\n0,1,2\n0.5,2,\n1,3,4\n"), inputs=["u"], outputs=["y"])
    _rejects("short.csv: line 4 has 2 values; every row must reach column 'y' (column 3)",
             _write(tmp_path / "short.csv", "t,u,y\n0,1,2\n0.5,2,3\n1,3\n"), inputs=["u"], outputs=["y"])
    _rejects("nan.csv: column 'y' holds a non-finite value (nan) at line 3",
             _write(tmp_path / "nan.csv", "t,u,y\n0,1,2\n0.5,2,nan\n1,3,4\n"), inputs=["u"], outputs=["y"])


def test_time_column_none_and_dt(tmp_path):
    path = _write(tmp_path / "log.csv", "stamp,u,y\n12:00:01,1,2\n12:00:02,2,3\n12:00:03,3,4\n")
    _rejects("log.csv has no time column 't' or 'time': name one with --time-column NAME, or give --dt", path,
             inputs=["u"], outputs=["y"])
    _rejects("the time column of log.csv is disabled (--time-column none): give --dt", path, inputs=["u"],
             outputs=["y"], time_column="none")
    data = read_record(path, inputs=["u"], outputs=["y"], dt=0.25)
    assert data.dt == 0.25 and data.t[-1] == 0.5
    _rejects("log.csv: column 'stamp' holds '12:00:01' at line 2, not a number", path, inputs=["u"],
             outputs=["y"], time_column="stamp")


# ------------------------------------------------------------------------ time base
def _timed(path, t):
    rows = "".join(f"{float(ti)!r},{float(np.sin(ti))!r},{float(np.cos(ti))!r}\n" for ti in t)
    return _write(path, "t,u,y\n" + rows)


def test_jitter_within_tolerance_is_accepted_and_reported(tmp_path):
    rng = np.random.default_rng(0)
    t = np.arange(500) * 0.02 + rng.uniform(-1.2e-5, 1.2e-5, 500)  # a 50 Hz logger's 1.2e-5 s jitter
    data = read_record(_timed(tmp_path / "j.csv", t), inputs=["u"], outputs=["y"])
    expected = np.max(np.abs(t - (t[0] + np.arange(500) * (t[-1] - t[0]) / 499))) / ((t[-1] - t[0]) / 499)
    assert data.meta["time_base"]["sample_jitter"] == pytest.approx(expected, rel=1e-9)
    assert data.meta["time_base"]["sample_jitter"] < 1.2e-3  # at most 2 * 1.2e-5 / 0.02
    np.testing.assert_allclose(np.diff(data.t), (t[-1] - t[0]) / 499, rtol=1e-12)


def test_time_base_rejections_name_the_first_offending_row(tmp_path):
    t = np.arange(20) * 0.1
    falling = t.copy()
    falling[7] = falling[6]
    _rejects("f.csv: time does not increase at line 9 (0.6 s after 0.6 s)", _timed(tmp_path / "f.csv", falling),
             inputs=["u"], outputs=["y"])
    gap = np.concatenate([t[:10], t[10:] + 1.0])
    _rejects("g.csv: gap in time at line 12: 1.1 s after the previous sample, 11.0 times the median step of 0.1 s; "
             "--resample HZ interpolates across it, --segment T0:T1 leaves it out",
             _timed(tmp_path / "g.csv", gap), inputs=["u"], outputs=["y"])
    jitter = t.copy()
    jitter[5] += 0.02
    _rejects(f"j.csv: sample times stray from a uniform grid by 0.2 of a step at line 7 (tolerance "
             f"{JITTER_TOLERANCE:g}): resample with --resample HZ, or widen --jitter-tolerance",
             _timed(tmp_path / "j.csv", jitter), inputs=["u"], outputs=["y"])
    # the same record resampled is accepted, and a segment avoids the gap
    assert read_record(tmp_path / "j.csv", inputs=["u"], outputs=["y"], resample=10.0).n_samples == 20
    assert read_record(tmp_path / "g.csv", inputs=["u"], outputs=["y"], segment="0:0.95").n_samples == 10
    _rejects("the segment 5:6 s selects 0 samples of 'u' in g.csv, which runs from 0 to 2.9 s",
             tmp_path / "g.csv", inputs=["u"], outputs=["y"], segment="5:6")


def _two_tones(rate, seconds=4.0):
    t = np.arange(int(seconds * rate)) / rate
    return t, np.sin(2 * np.pi * 2.0 * t), np.sin(2 * np.pi * 2.0 * t) + np.sin(2 * np.pi * 300.0 * t)


def _amplitude(signal, t, hz):
    middle = slice(len(t) // 4, 3 * len(t) // 4)  # away from the filters' ends
    s, c = np.sin(2 * np.pi * hz * t[middle]), np.cos(2 * np.pi * hz * t[middle])
    return np.hypot(np.mean(signal[middle] * s), np.mean(signal[middle] * c)) * 2


@pytest.mark.parametrize("how", [dict(resample=100.0), dict(decimate=10)])
def test_resampling_and_decimation_remove_what_would_alias(tmp_path, how):
    t, u, y = _two_tones(1000.0)
    path = tmp_path / "fast.csv"
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="", fmt="%.12g")
    data = read_record(path, inputs=["u"], outputs=["y"], **how)
    assert data.dt == pytest.approx(0.01)
    # 300 Hz would fold onto 0 Hz at 100 Hz (aliasing: 300 = 3 x 100); the filter leaves < 1 % of it, and the
    # 2 Hz tone keeps its amplitude to 1 % (both filters are flat to far better than that at 2 Hz)
    assert abs(_amplitude(data.y[:, 0] - data.u[:, 0], data.t, 0.0)) < 0.01
    assert np.max(np.abs(data.y[len(t) // 40: -len(t) // 40, 0] - data.u[len(t) // 40: -len(t) // 40, 0])) < 0.01
    assert _amplitude(data.u[:, 0], data.t, 2.0) == pytest.approx(1.0, rel=0.01)
    if "resample" in how:
        assert data.meta["time_base"]["resample"]["interpolation"] == "linear"
        assert data.meta["time_base"]["resample"]["filtered_channels"] == ["u", "y"]


def test_decimation_keeps_a_channel_far_from_zero_at_both_ends(tmp_path):
    """A speed of 10-35 m/s decimated by 5 starts near 10 and ends near 35: the filter's padding used to
    pull both ends towards zero (a ramp at 500 Hz once began at 6 m/s after decimation)."""
    t = np.arange(3001) * 0.002
    speed = 10.0 + 25.0 * t / t[-1]  # a straight ramp: any linear filter with unit gain leaves it as it is
    steer = 0.01 * np.sin(2 * np.pi * 1.0 * t)
    path = tmp_path / "ramp.csv"
    np.savetxt(path, np.column_stack([t, steer, speed]), delimiter=",", header="t,steer,speed", comments="",
               fmt="%.12g")
    data = read_record(path, inputs=["steer"], outputs=["speed"], decimate=5)
    # an odd reflection about the end samples continues a straight line exactly, so the ends keep the ramp to
    # rounding; 1e-6 m/s leaves room for the FIR's own ripple on a ramp (flat to far better than that)
    np.testing.assert_allclose(data.y[:, 0], speed[::5], atol=1e-6)
    assert data.n_samples == len(t[::5])


# -------------------------------------------------------------- whitespace tables
def test_daisy_style_dat_by_column_number(tmp_path):
    t = np.arange(50) * 0.5
    table = np.column_stack([t, np.sin(t), np.cos(t)])
    path = tmp_path / "exchanger.dat"
    # as DaISy publishes them: padded fields, three-digit exponents, tab-separated with a trailing tab
    path.write_text("".join("".join(f"  {value:.7e}".replace("e+0", "e+00").replace("e-0", "e-00") + "\t"
                                    for value in row) + "\n" for row in table))
    assert path.read_text().startswith("  0.0000000e+000\t  0.0000000e+000\t  1.0000000e+000\t\n")
    data = read_record(path, inputs=["2"], outputs=["3"], time_column="1")
    np.testing.assert_allclose(data.y[:, 0], np.cos(t), rtol=1e-7)
    assert data.dt == pytest.approx(0.5)
    by_dt = read_record(path, inputs=["2"], outputs=["3"], dt=0.5)
    np.testing.assert_array_equal(by_dt.u, data.u)
    _rejects("exchanger.dat has no header row: choose data columns by number (1, 2, ...); got 'u'", path,
             inputs=["u"], outputs=["3"], dt=0.5)


def test_whitespace_table_with_comments_and_header(tmp_path):
    path = _write(tmp_path / "run.txt", "% recorded on a test track\n# second comment\n t  steer   yaw\n"
                                        "0.0 1 2\n0.1 2 3\n\n0.2 3 4\n")
    data = read_record(path, inputs=["steer"], outputs=["yaw"])
    np.testing.assert_array_equal(data.y[:, 0], [2, 3, 4])


# --------------------------------------------------------------------------- MATLAB
def test_mat_variables_struct_fields_and_matrix_columns(tmp_path):
    t = np.arange(30) * 0.01
    path = tmp_path / "run.mat"
    scipy.io.savemat(path, {"t": t, "run": {"steer": np.sin(t), "speed": 20.0 + t},
                            "Y": np.column_stack([np.cos(t), 2 * np.cos(t)])})
    data = read_record(path, inputs=["run.steer"], outputs=["Y:2", "run.speed"])
    np.testing.assert_allclose(data.y[:, 0], 2 * np.cos(t))
    np.testing.assert_allclose(data.u[:, 0], np.sin(t))
    assert data.dt == pytest.approx(0.01)
    # a matrix named alone is every column (as iddata users expect); as the time it must be one column
    whole = read_record(path, inputs=["run.steer"], outputs=["Y"])
    assert whole.output_names == ("Y:1", "Y:2")
    np.testing.assert_allclose(whole.y, np.column_stack([np.cos(t), 2 * np.cos(t)]))
    _rejects("variable 'Y' in run.mat is a 30x2 matrix: choose a column as Y:1 ... Y:2", path,
             inputs=["run.steer"], outputs=["run.speed"], time_column="Y")
    _rejects("unknown variable 'yaw' in run.mat; variables: Y, run, t", path, inputs=["run.steer"], outputs=["yaw"])


def test_mat_v73_is_read_through_hdf5(tmp_path):
    path = tmp_path / "big.mat"
    t = np.arange(40) * 0.05
    with h5py.File(path, "w", userblock_size=512) as handle:
        # MATLAB stores column-major: a 40x1 vector is a (1, 40) dataset
        handle["t"] = t[None, :]
        handle["u"] = np.sin(t)[None, :]
        handle.create_group("s")["y"] = np.cos(t)[None, :]
    with open(path, "r+b") as handle:
        handle.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02IM")
    data = read_record(path, inputs=["u"], outputs=["s.y"])
    np.testing.assert_allclose(data.y[:, 0], np.cos(t))
    assert data.dt == pytest.approx(0.05)


# ----------------------------------------------------------------------------- MDF4
def test_mdf4_channels_at_two_rates_onto_one_time_base(tmp_path):
    asammdf = pytest.importorskip("asammdf")
    fast = np.arange(0, 2.0 + 1e-9, 0.01)
    slow = np.arange(0, 2.0 + 1e-9, 0.05)
    mdf = asammdf.MDF(version="4.10")
    mdf.append([asammdf.Signal(3.0 * fast + 1.0, fast, name="steer", unit="deg")])
    mdf.append([asammdf.Signal(-2.0 * slow, slow, name="yaw_rate", unit="rad/s")])
    path = tmp_path / "log.mf4"
    mdf.save(path, overwrite=True)
    mdf.close()
    data = read_record(path, inputs=["steer"], outputs=["yaw_rate"])
    # the slower channel is interpolated linearly onto the fastest channel's 100 Hz grid: exact for a ramp
    assert data.dt == pytest.approx(0.01) and data.n_samples == fast.size
    np.testing.assert_allclose(data.y[:, 0], -2.0 * data.t, atol=1e-12)
    np.testing.assert_allclose(data.u[:, 0], 3.0 * data.t + 1.0, atol=1e-12)
    assert data.input_units == ("deg",) and data.meta["time_base"]["resample"]["rate_hz"] == pytest.approx(100.0)
    _rejects("unknown channel 'roll' in log.mf4; channels: steer, yaw_rate", path, inputs=["steer"],
             outputs=["roll"])
    _rejects("log.mf4 is an MDF file and carries its own time stamps: --dt does not apply "
             "(use --resample HZ for another rate)", path, inputs=["steer"], outputs=["yaw_rate"], dt=0.1)
    # an MDF file named .dat (as MDF3 loggers name them) is known by its first bytes
    renamed = path.rename(tmp_path / "log.dat")
    np.testing.assert_array_equal(read_record(renamed, inputs=["steer"], outputs=["yaw_rate"]).y, data.y)


def test_unknown_file_type(tmp_path):
    _rejects("unknown data file type '.xlsx': give a .h5, .csv, .dat, .txt, .mat or .mf4 file",
             _write(tmp_path / "a.xlsx", "x"), inputs=["a"], outputs=["b"])


@pytest.mark.parametrize("options, message", [
    (dict(resample=-5.0), "the resampling rate must be a positive number of Hz; got -5.0"),
    (dict(decimate=2.5), "the decimation factor must be a whole number >= 1; got 2.5"),
    (dict(segment="3"), "--segment is T0:T1 in the file's time (s), or +T0:+T1 in seconds from the log's first "
                        "sample; got '3'"),
    (dict(segment="4:2"), "--segment needs T0 < T1; got 4:2"),
    (dict(jitter_tolerance=0.7), "the jitter tolerance is a fraction of a step in [0, 0.5); got 0.7"),
    (dict(dt=-1.0, time_column="none"), "--dt must be a positive number; got -1.0"),
])
def test_time_base_option_rejections(tmp_path, options, message):
    _rejects(message, _timed(tmp_path / "ok.csv", np.arange(20) * 0.1), inputs=["u"], outputs=["y"], **options)
