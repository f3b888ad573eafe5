"""Diagnoses that name the cause: each bad record, file or command line is refused before any work with one
line that says what is wrong (and, under --json, one JSON object with `error` and `exit_status`).

Each case reproduces a failure once reported with a misleading message: a constant input reported as
non-finite values, a constant output as a non-finite B, values near 1e300 or 1e-300 as an output identically
zero, an output copying the input identified at 100 %, random bytes answered with a 10,059-byte line,
`--order 100` on 1,024 samples running for minutes, argparse's refusals printing no JSON object.
"""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest

from vehid.identification import (ExcitationError, InputError, IOData, ModalStructure, check_channels,
                                  estimate_subspace, identify_iekf, largest_subspace_order)
from vehid.identification.data import LARGEST_MAGNITUDE, SMALLEST_MAGNITUDE
from vehid.scenarios.cli import MESSAGE_LIMIT, main, one_line

N = 400  # samples of the small records below: every refusal comes before any estimation


def _record(rng=None, n=N):
    """A first-order lag driven by white noise: t, u, y."""
    rng = rng or np.random.default_rng(7)
    t = np.arange(n) * 0.01
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = 0.9 * y[k - 1] + 0.1 * u[k - 1]
    return t, u, y


def _csv(path, t, u, y):
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="", fmt="%.17g")
    return str(path)


def _refused(capsys, argv, *words, status=2):
    """``vehid argv --json``: exit status, one JSON object, one stderr line naming ``words``, no leaked warning."""
    assert main([*argv, "--json"]) == status
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert len(lines) == 1, captured.out
    body = json.loads(lines[0])
    assert body["exit_status"] == status
    err = captured.err.strip().splitlines()
    assert len(err) == 1, captured.err
    for text in (err[0], body["error"]):
        assert "non-finite" not in text and "Warning" not in text and "internal error" not in text, text
        for word in words:
            assert word in text, (word, text)
    return body["error"]


def _identify(path, *extra):
    return ["identify", path, "--inputs", "u", "--outputs", "y", "--order", "2", *extra]


# ------------------------------------------------------------------ constant, zero, out of range, copied
@pytest.mark.parametrize("case, words", [
    ("constant input", ("input 'u'", "constant", "nothing is excited")),
    ("zero input", ("input 'u'", "zero throughout", "nothing is excited")),
    ("nearly constant input", ("input 'u'", "nearly constant", "rounding")),
    ("constant output", ("output 'y'", "constant", "no response")),
    ("zero output", ("output 'y'", "zero throughout", "no response")),
    ("output copies input", ("output 'y'", "a copy of input 'u'")),
    ("output proportional to input", ("output 'y'", "2.5 times input 'u'")),
])
def test_a_record_that_cannot_identify_a_model_names_the_channel_and_cause(case, words, tmp_path, capsys):
    t, u, y = _record()
    u, y = {
        "constant input": (np.full(N, 2.0), y),
        "zero input": (np.zeros(N), y),
        # varies by 1e-14 of its level: below 1000 rounding units (2.2e-13), above one (2.2e-16)
        "nearly constant input": (1.0 + 1e-14 * u, y),
        "constant output": (u, np.full(N, 3.0)),
        "zero output": (u, np.zeros(N)),
        "output copies input": (u, u.copy()),
        "output proportional to input": (u, 2.5 * u + 1.0),
    }[case]
    _refused(capsys, _identify(_csv(tmp_path / "r.csv", t, u, y)), *words)


def test_a_straight_line_input_is_no_excitation_once_detrend_linear_removes_it(tmp_path, capsys):
    t, _, y = _record()
    path = _csv(tmp_path / "ramp.csv", t, 0.5 + 3.0 * t, y)
    _refused(capsys, _identify(path, "--detrend", "linear"), "input 'u'", "straight line", "--detrend linear")


@pytest.mark.parametrize("factor, words", [(1e300, ("reaches", "overflow", "--scale u=1e-")),
                                           (1e-300, ("at most", "underflow", "--scale u=1e"))])
def test_values_beyond_the_representable_range_are_refused_with_the_scale_that_cures_them(factor, words, tmp_path,
                                                                                         capsys):
    t, u, y = _record()
    path = _csv(tmp_path / "scaled.csv", t, u * factor, y * factor)
    message = _refused(capsys, _identify(path, "--method", "arx"), "input 'u'", *words)
    cure = message.split("--scale ")[1].split()[0]  # the factor the message proposes
    assert main(_identify(path, "--method", "arx", "--scale", cure, "--scale", cure.replace("u=", "y="),
                          "--json")) == 0
    assert json.loads(capsys.readouterr().out)["order"] == 2


def test_the_range_bounds_are_the_fourth_roots_of_the_double_range_and_work_inside(tmp_path, capsys):
    """Inside the bounds the estimate does not depend on the units: ARX normalises each signal by its RMS."""
    assert LARGEST_MAGNITUDE ** 4 <= np.finfo(float).max and SMALLEST_MAGNITUDE ** 4 >= np.finfo(float).tiny
    t, u, y = _record()
    eigenvalues = []
    for factor in (1.0, 1e70, 1e-70):  # inside 1e+-76 by more than a decade, the record peaking near 3
        assert main(_identify(_csv(tmp_path / "r.csv", t, u * factor, y * factor), "--method", "arx", "--json")) == 0
        eigenvalues.append(np.array(json.loads(capsys.readouterr().out)["eigenvalues"]))
    # scaling by a power of ten perturbs each value by rounding only: the poles agree to 1e-6 of the fastest
    for other in eigenvalues[1:]:
        np.testing.assert_allclose(other, eigenvalues[0], atol=1e-6 * np.abs(eigenvalues[0]).max())


def test_the_library_refuses_the_same_records_with_the_same_words():
    t, u, y = _record()
    with pytest.raises(ExcitationError, match="input 'u1' is constant"):
        check_channels(IOData(t=t, u=np.full(N, 2.0), y=y))
    with pytest.raises(InputError, match="overflow"):
        check_channels(IOData(t=t, u=u * 1e300, y=y))
    # the filter checks its records by the same rule: a zero input is named before it is normalised
    with pytest.raises(ExcitationError, match="input 'u1' is zero throughout"):
        identify_iekf(IOData(t=t, u=np.zeros(N), y=y), ModalStructure.default(2, 1, 1))
    check_channels(IOData(t=t, u=u, y=y))  # a healthy record passes


def test_a_channel_constant_in_one_record_only_is_still_excited():
    t, u, y = _record()
    excited = IOData(t=t, u=u, y=y)
    idle = IOData(t=t, u=np.full(N, 1.0), y=np.full(N, 0.5))
    check_channels([excited, idle])
    with pytest.raises(ExcitationError, match="in every record"):
        check_channels([idle, idle.replace(u=np.full(N, 3.0))])


# ------------------------------------------------------------------------------------- files that are not text
def test_random_bytes_under_a_text_suffix_are_one_short_line_naming_the_file(tmp_path, capsys):
    path = tmp_path / "random.csv"
    path.write_bytes(np.random.default_rng(3).bytes(10_000))
    message = _refused(capsys, _identify(str(path)), "random.csv", "not a text table")
    assert len(message) < 200  # was 10,059 characters of decoded bytes


def test_an_hdf5_file_under_a_text_suffix_is_named_as_such(tmp_path, capsys):
    import h5py

    path = tmp_path / "run.csv"
    with h5py.File(path, "w") as handle:
        handle["x"] = np.arange(3.0)
    _refused(capsys, _identify(str(path)), "run.csv", "not a text table", "HDF5", ".h5")


def test_utf16_text_as_spreadsheets_save_it_is_read(tmp_path):
    from vehid.identification import read_table

    t, u, y = _record()
    plain = _csv(tmp_path / "plain.csv", t, u, y)
    wide = tmp_path / "wide.csv"
    wide.write_text((tmp_path / "plain.csv").read_text(encoding="utf-8"), encoding="utf-16")
    a = read_table(plain, channels=["u", "y"])
    b = read_table(wide, channels=["u", "y"])
    for x, z in zip(a.values, b.values):
        np.testing.assert_array_equal(x, z)  # the same decimal text parsed: bit-identical


# -------------------------------------------------------------------------------------------- orders
def test_an_order_the_record_cannot_support_is_refused_up_front_with_the_bound(tmp_path, capsys):
    t, u, y = _record(n=1024)
    path = _csv(tmp_path / "r.csv", t, u, y)
    # (1024 + 1) / (4 (1 + 1 + 1)) = 85.4: orders up to 85
    _refused(capsys, ["identify", path, "--inputs", "u", "--outputs", "y", "--order", "100"], "--order 100",
             "1024 estimation samples", "up to 85")
    # a range is chosen on a held-out part: the bound is the estimation part's, by the same closed form
    message = _refused(capsys, ["identify", path, "--inputs", "u", "--outputs", "y", "--order", "2-100"], "up to")
    samples = int(re.search(r"(\d+) estimation samples", message).group(1))
    assert samples < 1024 and f"up to {(samples + 1) // 12} " in message


@pytest.mark.parametrize("n_u, n_y", [(1, 1), (2, 1), (1, 3), (3, 2)])
def test_the_order_bound_is_the_closed_form_of_the_subspace_hankel_matrix(n_u, n_y):
    for samples in (10, 11, 12, 100, 1024, 5000):
        assert largest_subspace_order(samples, n_u, n_y) == (samples + 1) // (4 * (1 + n_u + n_y))
    # two records pool their columns: each gives N_k - 4n + 1 of the 4n (n_u + n_y) needed
    assert largest_subspace_order([500, 500], n_u, n_y) >= largest_subspace_order(500, n_u, n_y)


def test_the_subspace_estimator_works_at_the_bound_and_refuses_above_it():
    rng = np.random.default_rng(11)
    samples = 300
    limit = largest_subspace_order(samples, 1, 1)
    u, y = rng.standard_normal((samples, 1)), rng.standard_normal((samples, 1))
    with pytest.raises(InputError, match="too few"):
        estimate_subspace((u, y), order=limit + 1)
    try:
        estimate_subspace((u, y), order=limit)
    except ExcitationError:
        pass  # the data matrix was formed; white noise may reveal fewer states, which is another question


def test_auto_orders_are_cut_to_the_supported_ones():
    from vehid.identification.automatic.plan import supported_orders

    t, u, y = _record(n=60)  # (60 + 1) // 12 = 5
    record = IOData(t=t, u=u, y=y)
    assert supported_orders(list(range(1, 9)), True, (record,), "auto") == [1, 2, 3, 4, 5]
    with pytest.raises(InputError, match="up to 5"):
        supported_orders([6], False, (record,), "6")


# ---------------------------------------------------------------------------------- the command line's face
@pytest.mark.parametrize("argv, word", [
    (["--ordr", "4"], "--ordr"), (["--dt", "abc"], "'abc'"), (["--method", "foo"], "'foo'"),
])
def test_argument_errors_print_the_json_object_under_json(argv, word, tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["identify", str(tmp_path / "r.csv"), "--inputs", "u", "--outputs", "y", *argv, "--json"])
    assert stop.value.code == 2
    captured = capsys.readouterr()
    body = json.loads(captured.out)
    assert body["exit_status"] == 2 and word in body["error"]
    assert len(captured.err.strip().splitlines()) == 1 and word in captured.err and "usage:" not in captured.err


def test_argument_errors_without_json_print_no_json(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["identify", "--ordr", "4"])
    assert capsys.readouterr().out == ""


def test_a_long_message_becomes_one_readable_line():
    garbage = "".join(chr(c) for c in np.random.default_rng(5).integers(0, 256, 10_059))
    line = one_line(f"unknown column 'u'; columns: {garbage}")
    assert len(line) <= MESSAGE_LIMIT and "\n" not in line and line.isprintable()
    assert line.startswith("unknown column 'u'; columns: ") and line.endswith("characters cut)")
    traced = one_line('failed\nTraceback (most recent call last):\n  File "x.py", line 1, in <module>\n    f()\nValueError')
    assert traced == "failed"
    assert one_line("short message") == "short message"
    # a wrapped array in a message is part of it; a quoted stack frame and its source line are not
    assert one_line("singular values [1.0 2.0\n 3.0]") == "singular values [1.0 2.0 3.0]"
    assert one_line('bad value\n  File "m.py", line 3, in f\n    g()\nmore') == "bad value more"


def test_a_python_warning_is_logged_as_one_line_without_its_source(monkeypatch, capsys):
    import vehid.scenarios.commands.linearize as command

    def warns(args):
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            np.array([0.0]) / np.array([0.0])
        return {}, ""

    monkeypatch.setattr(command, "run", warns)  # register() hands the module's run to the parser
    previous = warnings.showwarning
    try:
        assert main(["linearize"]) == 0
    finally:
        warnings.showwarning = previous
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["vehid: WARNING: RuntimeWarning: invalid value encountered in divide"], err
