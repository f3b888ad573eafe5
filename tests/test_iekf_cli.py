"""The identify, study linear-example and bench iekf commands: JSON contracts, bad input, checkpoint and resume."""

import json
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.dataio.archive import open_archive
from vehid.identification.dataio.iekf_archive import read_iekf_run
from vehid.identification.decisions import SCHEDULE_MARGIN
from vehid.identification.automatic.tuning import P_GRID, P_TOLERANCE, Q_SCHEDULES
from vehid.scenarios.linear_example import make_data

VEHID = [sys.executable, "-m", "vehid.scenarios.cli"]
IDENTIFY_KEYS = {"eigenvalues", "fit_percent", "passes_run", "discretization", "A", "B", "C", "D", "seconds"}


def _vehid(*args):
    """The command in this process: only its status, output and files are under test."""
    return run_vehid(*args)


def _write_csv(path, u, y, *, t=None, header="t,u1,u2,y1"):
    columns = [np.arange(len(u)) * 0.002 if t is None else t, u[:, 0], u[:, 1], y[:, 0]]
    np.savetxt(path, np.column_stack(columns), delimiter=",", header=header, comments="")
    return path


@pytest.fixture(scope="module")
def record_at_100_hz(tmp_path_factory):
    """The 100 s record of eq. 16 at every fifth sample (100 Hz, a fifth of the filter's work).

    Its inputs are linear between 50 Hz points, so the exact (first-order-hold) discretisation loses
    nothing by the coarser sampling: the fit is 99.9994 % at 100 Hz as at 500 Hz.
    """
    data, _ = make_data(4, outputs=(0,), duration=100.0)
    u, y = data.u[::5], data.y[::5]
    return _write_csv(tmp_path_factory.mktemp("data") / "record_100hz.csv", u, y, t=np.arange(len(u)) * 0.01)


def test_identify_json_summary(record_at_100_hz, tmp_path):
    completed = _vehid("identify", str(record_at_100_hz), "--inputs", "u1,u2", "--outputs", "y1", "--order", "5",
                       "--passes", "40", "--json", "--save-model", str(tmp_path / "model.json"))
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert IDENTIFY_KEYS <= set(summary)
    assert summary["discretization"] == "exact" and summary["passes_run"] <= 40
    assert len(summary["eigenvalues"]) == 5 and all(len(v) == 2 for v in summary["eigenvalues"])
    # eq. 15 from the 100 s record of eq. 16 (shorter records leave the weak modes slow to settle): within 2 %
    # (measured 0.55 % for the pair at -15 +- 10j and 0.7 % for the real pole; 0.05 % and 0.5 % at 500 Hz)
    found = [complex(*v) for v in summary["eigenvalues"]]
    for truth in (-15 + 10j, -15 - 10j, -8 + 40j, -8 - 40j, -4):
        assert min(abs(f - truth) for f in found) / abs(truth) < 0.02
    assert summary["R"][0] > 99.9
    assert json.loads((tmp_path / "model.json").read_text())["structure"]["n"] == 5
    # no --p: each p of the grid cross-validated on the halves with each Q schedule; the shrinking Q unless the
    # constant one's best beats its best by more than the schedule margin, then the largest p of that schedule
    # within the tolerance of the schedule's best
    tried = summary["p_tried"]
    assert [(row["p"], row["q_schedule"]) for row in tried] == [(p, q) for p in P_GRID for q in Q_SCHEDULES]
    fits = {(row["p"], row["q_schedule"]): row["cv_fit_percent"] for row in tried}
    best = {q: max(fit for (_, schedule), fit in fits.items() if schedule == q) for q in Q_SCHEDULES}
    schedule = "constant" if best["constant"] > best["shrinking"] + SCHEDULE_MARGIN else "shrinking"
    assert summary["q_schedule"] == schedule
    assert summary["p"] == max(p for (p, q), fit in fits.items() if q == schedule and fit >= best[q] - P_TOLERANCE)
    assert summary["tuning_seconds"] >= sum(row["seconds"] for row in tried) > 0


@pytest.mark.parametrize(
    "case, message",
    [
        ("nan", "non-finite"),
        ("short", "cannot identify"),
        ("constant", "constant"),
        ("column", "unknown column"),
        ("ragged", "every row"),
    ],
)
def test_identify_bad_input_is_one_clear_line(case, message, tmp_path):
    data, _ = make_data(4, outputs=(0,), duration=2.0)
    u, y = data.u.copy(), data.y.copy()
    path = tmp_path / "bad.csv"
    outputs = "y1"
    if case == "nan":
        y[100, 0] = np.nan
    if case == "short":
        u, y = u[:10], y[:10]
    if case == "constant":
        u[:, 1] = 0.3
    if case == "column":
        outputs = "y7"
    _write_csv(path, u, y)
    if case == "ragged":
        with path.open("a") as handle:
            handle.write("1.0,2.0\n")
    completed = _vehid("identify", str(path), "--inputs", "u1,u2", "--outputs", outputs, "--order", "5")
    assert completed.returncode == 2
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], completed.stderr
    assert "Traceback" not in completed.stderr


def test_unknown_option_is_a_usage_error(record_at_100_hz):
    completed = _vehid("identify", str(record_at_100_hz), "--frobnicate")
    assert completed.returncode == 2 and "Traceback" not in completed.stderr


def test_a_killed_run_resumes_to_the_same_parameters(tmp_path):
    """Kill the process after its archive holds some passes; resuming reaches the uninterrupted run's parameters."""
    data, _ = make_data(5, outputs=(0,), duration=40.0)
    record = _write_csv(tmp_path / "record.csv", data.u, data.y)
    # the absolute settings (fixed start, p in seconds): a run of 12 passes, long enough to be killed mid-way
    # (from the data start it converges by pass 3, before any kill could land)
    common = ["--inputs", "u1,u2", "--outputs", "y1", "--order", "5", "--passes", "12", "--p", "0.5", "--json",
              "--start", "default", "--timescale", "seconds", "--no-normalize"]
    whole = _vehid("identify", str(record), *common, "--out", str(tmp_path / "whole.h5"))
    assert whole.returncode == 0, whole.stderr
    archive = tmp_path / "killed.h5"
    process = subprocess.Popen([*VEHID, "identify", str(record), *common, "--out", str(archive)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    passes = 0
    while time.monotonic() < deadline and process.poll() is None:
        try:
            with h5py.File(archive, "r") as handle:
                passes = int(handle["runs/iekf/history"].attrs["n_pass"])
        except (OSError, KeyError):
            passes = 0
        if passes >= 3:
            process.send_signal(signal.SIGKILL)
            break
        time.sleep(0.01)
    process.wait()
    with open_archive(archive) as handle:
        interrupted = read_iekf_run(handle, "iekf")
    if interrupted.passes_run >= 12:
        pytest.skip("the run finished before it could be killed")  # a very fast machine; nothing to resume
    resumed = _vehid("identify", "--resume", str(archive), "--passes", "12", "--json")
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads(resumed.stdout)["passes_run"] == json.loads(whole.stdout)["passes_run"]
    # a given p is used as given, and the resumed run keeps it
    assert [json.loads(run.stdout)["p"] for run in (whole, resumed)] == [0.5, 0.5]
    assert json.loads(whole.stdout)["p_tried"] == [] and json.loads(whole.stdout)["tuning_seconds"] == 0
    with open_archive(archive) as a, open_archive(tmp_path / "whole.h5") as b:
        final_resumed, final_whole = read_iekf_run(a, "iekf"), read_iekf_run(b, "iekf")
    # the same arithmetic from the same checkpointed state: equal to rounding of the archive (exact)
    assert np.array_equal(final_resumed.model.parameters, final_whole.model.parameters)
    assert [r.index for r in final_resumed.history] == list(range(1, final_whole.passes_run + 1))


def test_study_linear_example_json(tmp_path, monkeypatch):
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path))
    completed = _vehid("study", "linear-example", "--case", "single-output", "--passes", "3", "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert IDENTIFY_KEYS | {"fit_percent_by_pass"} <= set(summary)
    assert len(summary["fit_percent_by_pass"]) == summary["passes_run"] == 3
    assert summary["discretization"] == "euler"
    assert (tmp_path / "linear_example_single-output.h5").exists()


@pytest.mark.parametrize("command", [["identify"], ["study", "linear-example"], ["bench", "iekf"]])
def test_help(command):
    completed = _vehid(*command, "--help")
    assert completed.returncode == 0 and "--json" in completed.stdout


@pytest.mark.parametrize("schedule", list(Q_SCHEDULES))
def test_the_archived_decisions_keep_the_Q_schedule(schedule, tmp_path):
    """A resumed run reports the schedule its tuning chose; an archive written before schedules were kept
    reads as the constant Q every run had then."""
    from vehid.identification.dataio.archive import update_archive, write_archive
    from vehid.identification.automatic.archiving import DECISIONS, archive_decisions, read_decisions
    from vehid.identification.automatic.tuning import PCandidate, PTuning

    tried = tuple(PCandidate(p, q, 90.0, 1.0) for p in P_GRID for q in Q_SCHEDULES)
    tuning = PTuning(P_GRID[1], tried, 6.0, start_fit=80.0, q_schedule=schedule)
    with write_archive(tmp_path / "run.h5", kind="identification") as handle:
        archive_decisions(handle, tuning, None)
    with open_archive(tmp_path / "run.h5", kinds=["identification"]) as handle:
        back, unstable = read_decisions(handle)
    assert back.q_schedule == schedule and back.p == tuning.p and unstable is None
    assert back.summary()["p_tried"] == tuning.summary()["p_tried"]
    with update_archive(tmp_path / "run.h5") as handle:  # as an older workbench wrote it
        stored = json.loads(handle.attrs[DECISIONS])
        del stored["tuning"]["q_schedule"]
        handle.attrs[DECISIONS] = json.dumps(stored)
    with open_archive(tmp_path / "run.h5", kinds=["identification"]) as handle:
        assert read_decisions(handle)[0].q_schedule == "constant"
