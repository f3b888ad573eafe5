"""One exit-status contract, per command: 0 success, 2 bad input, 1 failed computation; with --json a failure
prints exactly one JSON object with `error` and `exit_status`; operating-system errors name the path and the
cause, never "internal error".

Bad input is real input wherever a command takes any (a missing file, a corrupt archive, a bad option). A
failed computation is provoked by standing in for the command's computation where no small real input makes
it fail (the contract under test is the command's, not the estimator's); the real cases are tested with
their commands (divergence, model conversion, an order that diverges).
"""

from __future__ import annotations

import errno
import importlib
import json

import pytest

from vehid.identification.errors import DivergenceError
from vehid.scenarios.cli import main

COMMANDS = {  # every subcommand; test_every_command_is_covered fails when one is added without a row below
    ("identify",), ("report",), ("simulate",), ("linearize",), ("study", "handling"),
    ("study", "linear-example"), ("study", "textbook"), ("bench", "iekf"), ("study", "envelope"),
    ("handling",), ("calibrate",),
}


_CALIBRATE_CHANNELS = ("--inputs", "delta", "--speed", "vx", "--outputs", "yawRate,ayCG", "--quantities",
                       "yaw_rate,lateral_acceleration")


def _check(capsys, argv, status, *words):
    """Run ``argv --json``: the status, one JSON object on stdout, one line on stderr naming ``words``."""
    assert main([*argv, "--json"]) == status
    captured = capsys.readouterr()
    lines = captured.out.strip().splitlines()
    assert len(lines) == 1, captured.out
    body = json.loads(lines[0])
    assert body["exit_status"] == status and isinstance(body["error"], str) and body["error"]
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "internal error" not in err[0] and "Traceback" not in captured.err, captured.err
    for word in words:
        assert word in err[0] and word in body["error"], (word, err[0])
    return body


def test_every_command_is_covered():
    from vehid.scenarios.commands.parser import command_modules

    found = {(m.NAME,) if m.GROUP is None else (m.GROUP, m.NAME) for m in command_modules()}
    assert found == COMMANDS


# ---------------------------------------------------------------- bad input: 2
def _corrupt_archive(tmp_path):
    from vehid.identification import write_archive

    path = tmp_path / "corrupt.h5"
    with write_archive(path, kind="identification"):
        pass
    data = bytearray(path.read_bytes())
    path.write_bytes(bytes(data[: len(data) // 2]))  # truncated, as by a full disk or an interrupted copy
    return path


@pytest.mark.parametrize("case", [
    "identify-missing", "identify-resume-foreign", "identify-resume-corrupt", "report-missing", "report-corrupt",
    "simulate-missing-vehicle", "linearize-missing-vehicle", "handling-resume-missing", "handling-bad-orders",
    "linear-example-bad-passes", "textbook-unwritable", "bench-unwritable", "identify-save-model-directory",
    "report-out-is-a-file", "envelope-bad-speeds", "envelope-out-is-a-directory",
    "vehicle-handling-missing", "vehicle-handling-corrupt", "vehicle-handling-bad-speeds", "calibrate-missing-log",
])
def test_bad_input_exits_2(case, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "results"))
    missing = str(tmp_path / "absent.h5")
    foreign = tmp_path / "foreign.csv"
    foreign.write_text("t,u,y\n0,0,0\n")
    if case == "identify-missing":
        _check(capsys, ["identify", str(tmp_path / "absent.csv"), "--inputs", "u", "--outputs", "y"], 2, "absent.csv")
    elif case == "identify-resume-foreign":
        _check(capsys, ["identify", "--resume", str(foreign)], 2, "foreign.csv")
    elif case == "identify-resume-corrupt":
        _check(capsys, ["identify", "--resume", str(_corrupt_archive(tmp_path))], 2, "corrupt.h5")
    elif case == "report-missing":
        _check(capsys, ["report", missing], 2, "absent.h5")
    elif case == "report-out-is-a-file":  # refused before drawing, and the file is left alone
        from vehid.identification import write_archive

        with write_archive(tmp_path / "a.h5", kind="identification"):
            pass
        monkeypatch.setattr("vehid.scenarios.report.archive_figures", None)  # drawing would fail loudly
        _check(capsys, ["report", str(tmp_path / "a.h5"), "--out", str(foreign)], 2, "foreign.csv", "Not a directory")
        assert foreign.read_text() == "t,u,y\n0,0,0\n"
    elif case == "report-corrupt":
        _check(capsys, ["report", str(_corrupt_archive(tmp_path))], 2, "corrupt.h5")
    elif case == "simulate-missing-vehicle":
        _check(capsys, ["simulate", "--vehicle", str(tmp_path / "car.toml"), "--duration", "1"], 2, "car.toml")
    elif case == "linearize-missing-vehicle":
        _check(capsys, ["linearize", "--vehicle", str(tmp_path / "car.toml")], 2, "car.toml")
    elif case == "handling-resume-missing":
        _check(capsys, ["study", "handling", "--resume", missing], 2, "absent.h5")
    elif case == "handling-bad-orders":
        _check(capsys, ["study", "handling", "--orders", "9"], 2, "from 2 to 8")
    elif case == "envelope-bad-speeds":
        _check(capsys, ["study", "envelope", "--speeds", "0", "--linear-only"], 2, "speed")
    elif case == "envelope-out-is-a-directory":
        (tmp_path / "campaign.h5").mkdir()
        _check(capsys, ["study", "envelope", "--speeds", "15", "--orders", "2", "--linear-only",
                        "--out", str(tmp_path / "campaign.h5")], 2, "campaign.h5", "directory")
    elif case == "vehicle-handling-missing":
        _check(capsys, ["handling", missing, "--speeds", "20"], 2, "absent.h5")
    elif case == "vehicle-handling-corrupt":
        _check(capsys, ["handling", str(_corrupt_archive(tmp_path)), "--speeds", "20"], 2, "corrupt.h5")
    elif case == "calibrate-missing-log":
        _check(capsys, ["calibrate", missing, *_CALIBRATE_CHANNELS], 2, "absent.h5")
    elif case == "vehicle-handling-bad-speeds":
        _check(capsys, ["handling", "--source", "--speeds", "20,fast"], 2, "fast")
    elif case == "linear-example-bad-passes":
        _check(capsys, ["study", "linear-example", "--passes", "0"], 2, "passes")
    elif case == "identify-save-model-directory":  # IsADirectoryError after the work: the path and the cause
        folder = tmp_path / "model.json"
        folder.mkdir()
        data = tmp_path / "record.csv"
        data.write_text("t,u,y\n" + "".join(f"{k * 0.01},{(-1) ** (k // 3)},{(-1) ** (k // 4)}\n" for k in range(300)))
        _check(capsys, ["identify", str(data), "--inputs", "u", "--outputs", "y", "--order", "2", "--method", "arx",
                        "--save-model", str(folder)], 2, str(folder), "Is a directory")
    else:  # a protected file the command must write: the path and the cause (PermissionError is a bad target)
        target = str(tmp_path / "results" / "benchmarks.json")

        def refused(*args, **kwargs):
            raise PermissionError(errno.EACCES, "Permission denied", target)

        if case == "textbook-unwritable":
            monkeypatch.setattr("vehid.scenarios.textbook.run_all", refused)
            _check(capsys, ["study", "textbook"], 2, target, "Permission denied")
        else:
            monkeypatch.setattr("vehid.scenarios.iekf_benchmark.measure_iekf", refused)
            _check(capsys, ["bench", "iekf", "--repeats", "1"], 2, target, "Permission denied")


# -------------------------------------------------------- failed computation: 1
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_failed_computation_exits_1(command, tmp_path, capsys, monkeypatch):
    """Each command's computation stood in for by one that diverges: exit 1 and one JSON object."""
    from vehid.identification import write_archive

    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path))

    def diverge(*args, **kwargs):
        raise DivergenceError("pass 3: the filter produced non-finite values")

    argv = list(command)
    if command == ("identify",):
        monkeypatch.setattr("vehid.identification.automatic.run.identify_iekf", diverge)
        data = tmp_path / "record.csv"
        data.write_text("t,u,y\n" + "".join(f"{k * 0.01},{(-1) ** k},{k % 3}\n" for k in range(100)))
        argv += [str(data), "--inputs", "u", "--outputs", "y", "--order", "2"]
    elif command == ("report",):
        monkeypatch.setattr("vehid.scenarios.report.archive_figures", diverge)
        archive = tmp_path / "a.h5"
        with write_archive(archive, kind="identification"):
            pass
        argv += [str(archive)]
    elif command == ("simulate",):
        monkeypatch.setattr("vehid.vehicle.simulate", diverge)
        argv += ["--duration", "1"]
    elif command == ("linearize",):
        monkeypatch.setattr(importlib.import_module("vehid.vehicle.linearize"), "linearize", diverge)
    elif command == ("study", "handling"):
        monkeypatch.setattr("vehid.scenarios.handling_study.run_study", diverge)
        monkeypatch.setattr("vehid.scenarios.handling_study.make_records", lambda config: {})
        argv += ["--orders", "2", "--out", str(tmp_path / "h.h5")]
    elif command == ("study", "linear-example"):
        monkeypatch.setattr("vehid.scenarios.linear_example.run_case", diverge)
    elif command == ("study", "textbook"):
        monkeypatch.setattr("vehid.scenarios.textbook.run_all", diverge)
    elif command == ("study", "envelope"):
        monkeypatch.setattr("vehid.scenarios.envelope.run_campaign", diverge)
        argv += ["--speeds", "15", "--orders", "2", "--linear-only"]
    elif command == ("calibrate",):
        monkeypatch.setattr("vehid.vehicle.drive_calibration.calibrate_drive", diverge)
        log = tmp_path / "log.csv"
        log.write_text("t,delta,vx,yawRate,ayCG\n" + "".join(
            f"{k * 0.01},{0.01 * (-1) ** k},20,{0.1 * (-1) ** k},{(-1) ** k}\n" for k in range(200)))
        argv += [str(log), *_CALIBRATE_CHANNELS]
    elif command == ("handling",):
        monkeypatch.setattr("vehid.vehicle.handling.source_handling", diverge)
        argv += ["--source", "--speeds", "20"]
    else:
        monkeypatch.setattr("vehid.scenarios.iekf_benchmark.measure_iekf", diverge)
    _check(capsys, argv, 1, "non-finite")


def test_a_full_disk_names_the_file_and_exits_1(tmp_path, capsys, monkeypatch):
    """An OSError that is not the user's path (here: no space left) is a failure (1), named, never "internal"."""
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path))
    target = str(tmp_path / "linear_example_single-output.h5")

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", target)

    monkeypatch.setattr("vehid.scenarios.linear_example.run_case", full)
    _check(capsys, ["study", "linear-example"], 1, target, "No space left on device")


def test_a_full_disk_while_writing_an_archive_names_it(tmp_path, capsys, monkeypatch):
    """fsync reporting ENOSPC (a full disk found at flush): the error names the archive the user gave, not the
    hidden copy being written, exits 1, and leaves no partial file behind."""
    from vehid.identification.dataio import archive as archive_module

    data = tmp_path / "record.csv"
    data.write_text("t,u,y\n" + "".join(f"{k * 0.01},{(-1) ** (k // 3)},{(-1) ** (k // 4)}\n" for k in range(300)))
    archive = tmp_path / "run.h5"

    def full(path):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(archive_module, "_sync", full)
    _check(capsys, ["identify", str(data), "--inputs", "u", "--outputs", "y", "--order", "2", "--out", str(archive)],
           1, str(archive), "No space left on device")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["record.csv"]


def test_an_interrupt_still_prints_one_json_object(tmp_path, capsys, monkeypatch):
    """SIGTERM (raised as Interrupted by the handler the CLI installs) ends with 128 + 15 and one JSON object."""
    import signal

    from vehid.scenarios.shutdown import Interrupted

    def stopped(**options):
        raise Interrupted(signal.SIGTERM)

    monkeypatch.setattr("vehid.scenarios.textbook.run_all", stopped)
    body = _check(capsys, ["study", "textbook"], 128 + signal.SIGTERM, "interrupted by SIGTERM")
    assert body["error"] == "interrupted by SIGTERM"
