"""`vehid simulate` and `vehid linearize`: the JSON keys other tools read, and bad input (exit 2)."""

import json
import subprocess
import sys

import pytest

from vehid.identification.data import read_hdf5
from vehid.scenarios.cli import main
from conftest import run_vehid


def _run_json(argv):
    done = run_vehid(*argv, "--json")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_simulate_step_summary_keys(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a relative --out is taken from the working directory
    summary = _run_json(["simulate", "--manoeuvre", "step", "--amplitude-deg", "0.3",
                                 "--duration", "6", "--out", "step.h5"])
    for key in ("peak_lateral_acceleration", "min_speed", "max_speed", "seconds",
                "yaw_rate_gain", "lateral_acceleration_gain", "roll_gain"):
        assert isinstance(summary[key], float), key
    # Baseline closed forms at 20 m/s: r/delta = 6.27 1/s, a_y/delta = 2.19 m/s^2/deg (3 %),
    # roll/delta = (dphi/da_y)(a_y/delta) = 0.512 deg/(m/s^2) * 2.19 m/s^2/deg = 1.12 deg/deg:
    # a degree/radian slip in any of the three would be off by a factor of 57.
    assert summary["yaw_rate_gain"] == pytest.approx(6.27, rel=0.03)
    assert summary["lateral_acceleration_gain"] == pytest.approx(2.19, rel=0.03)
    assert summary["roll_gain"] == pytest.approx(1.12, rel=0.03)
    record = read_hdf5(tmp_path / "step.h5")
    assert record.n_samples == 3001 and record.x.shape == (3001, 23)
    assert record.output_names[:3] == ("lateral_acceleration", "yaw_rate", "roll_angle")


def test_simulate_identification_summary():
    summary = _run_json(["simulate", "--manoeuvre", "identification", "--duration", "4"])
    assert "yaw_rate_gain" not in summary
    assert 19.5 < summary["min_speed"] <= summary["max_speed"] < 20.5


def test_linearize_modes():
    summary = _run_json(["linearize", "--vehicle", "understeer", "--speed", "25"])
    labels = [mode["label"] for mode in summary["modes"]]
    for label in ("roll", "yaw-sideslip", "heave", "pitch", "wheel"):
        assert label in labels
    for mode in summary["modes"]:
        assert set(mode) >= {"frequency_hz", "damping", "label"}


def _bad_vehicle(tmp_path, text):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    return str(path)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "--speed", "0"], "speed must be positive"),
        (["simulate", "--manoeuvre", "step", "--amplitude-deg", "35"], "30 deg"),
        (["simulate", "--amplitude-deg", "nan"], "finite"),
        (["simulate", "--duration", "-1"], "duration"),
        (["simulate", "--seed", "-1"], "seed must be a non-negative integer"),
        (["linearize", "--speed", "-3"], "speed must be positive"),
        (["linearize", "--speed", "80"], "above the model's valid range (3-50 m/s)"),
        (["simulate", "--vehicle", "VEHICLE:base = \"baseline\"\n[chassis]\nmass = 0.0\n"], "mass must be positive"),
        (["linearize", "--vehicle", "VEHICLE:base = \"baseline\"\n[chassis]\nwings = 2\n"], "unknown field"),
        (["simulate", "--vehicle", "VEHICLE:base = \"baseline\"\n[tyre]\nwheel_inertia = -1.0\n"], "wheel_inertia"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, argv, message):
    argv = [_bad_vehicle(tmp_path, a[8:]) if a.startswith("VEHICLE:") else a for a in argv]
    done = run_vehid(*argv)
    err = done.stderr
    assert done.returncode == 2
    assert len(err.strip().splitlines()) == 1 and message in err and "Traceback" not in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["simulate", "--amplitude-deg", "abc"], "invalid float value"),
        (["simulate", "--manoeuvre", "slalom"], "invalid choice"),
        (["linearize", "--speed"], "expected one argument"),
        (["simulate", "--wings"], "unrecognized arguments"),
    ],
)
def test_malformed_arguments_exit_2_with_one_line(capsys, argv, message):
    """argparse's own errors keep the CLI's contract too: exit 2, one line, no usage block."""
    with pytest.raises(SystemExit) as stop:
        main(argv)
    err = capsys.readouterr().err
    assert stop.value.code == 2
    assert len(err.strip().splitlines()) == 1 and message in err and "usage:" not in err


def test_bad_input_from_a_real_process(tmp_path):
    completed = subprocess.run(
        [sys.executable, "-m", "vehid.scenarios.cli", "simulate", "--speed", "-2", "--json"],
        capture_output=True, text=True, check=False,
    )
    assert completed.returncode == 2
    # With --json a failure is still exactly one JSON object, naming the error and the status.
    body = json.loads(completed.stdout)
    assert body["exit_status"] == 2 and "speed" in body["error"]
    assert completed.stderr.count("\n") == 1 and "Traceback" not in completed.stderr
