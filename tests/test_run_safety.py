"""`vehid identify`: resume that resumes, a final stop reason, safe --out for every method, one writer.

Each test reproduces a failure the issue found first (the README's `--resume` form returning the killed
run's model at once; "running" left in finished archives; --out overwriting its input or a foreign file,
or failing after the work on a directory; comparators ignoring --out; a second writer mixing runs).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from vehid.identification import IEKFOptions, ModalStructure, identify_iekf
from vehid.identification.dataio.archive import open_archive, read_archive
from vehid.identification.errors import ConversionError
from vehid.identification.dataio.iekf_archive import Checkpointer, read_iekf_run
from vehid.scenarios.cli import main
from vehid.identification.automatic import run as pipeline_run
from vehid.scenarios.linear_example import make_data


class _Killed(KeyboardInterrupt):
    """Stands for an interruption after a pass (Ctrl-C, a stopping signal): the archive is what it leaves."""


def _record(path, duration=20.0):
    data, _ = make_data(5, outputs=(0,), duration=duration)
    columns = [data.t, data.u[:, 0], data.u[:, 1], data.y[:, 0]]
    np.savetxt(path, np.column_stack(columns), delimiter=",", header="t,u1,u2,y1", comments="")
    return path


COMMON = ["--inputs", "u1,u2", "--outputs", "y1", "--order", "5", "--p", "0.5", "--quiet", "--json"]


def _summary(capsys):
    return json.loads(capsys.readouterr().out)


def test_resume_without_passes_runs_to_the_runs_own_budget(tmp_path, capsys, monkeypatch):
    record = _record(tmp_path / "record.csv")
    assert main(["identify", str(record), *COMMON, "--passes", "9", "--out", str(tmp_path / "whole.h5")]) == 0
    whole = _summary(capsys)
    with open_archive(tmp_path / "whole.h5") as handle:  # a finished archive says how it ended
        assert read_iekf_run(handle, "iekf").stop_reason == whole["stop_reason"] == "passes"

    real = Checkpointer.__call__

    def killed_after_four(self, record, so_far):
        real(self, record, so_far)
        if record.index == 4:
            raise _Killed()

    monkeypatch.setattr(Checkpointer, "__call__", killed_after_four)
    archive = tmp_path / "killed.h5"
    assert main(["identify", str(record), *COMMON, "--passes", "9", "--out", str(archive)]) == 130
    capsys.readouterr()
    monkeypatch.setattr(Checkpointer, "__call__", real)
    with open_archive(archive) as handle:
        killed = read_iekf_run(handle, "iekf")
    assert killed.passes_run == 4 and killed.stop_reason == "running"  # resumable, and says so

    # the README's form, no --passes: on to the run's own budget of 9 (it used to stop at once at 4)
    assert main(["identify", "--resume", str(archive), "--quiet", "--json"]) == 0
    resumed = _summary(capsys)
    assert resumed["passes_run"] == 9 and resumed["stop_reason"] == "passes"
    with open_archive(archive) as a, open_archive(tmp_path / "whole.h5") as b:
        final_resumed, final_whole = read_iekf_run(a, "iekf"), read_iekf_run(b, "iekf")
    assert final_resumed.stop_reason == "passes"  # no "running" once the run has ended
    # the same arithmetic from the same checkpointed state: bit for bit
    assert np.array_equal(final_resumed.model.parameters, final_whole.model.parameters)

    # an explicit --passes still sets a new budget; a finished run asked again does no pass
    assert main(["identify", "--resume", str(archive), "--passes", "11", "--quiet", "--json"]) == 0
    assert _summary(capsys)["passes_run"] == 11
    assert main(["identify", "--resume", str(archive), "--quiet", "--json"]) == 0
    assert _summary(capsys)["passes_run"] == 11


def test_fast_passes_are_checkpointed_together_and_none_is_lost(tmp_path, monkeypatch):
    """Passes are gathered until the time computed since the last checkpoint reaches COMPUTE_PER_CHECKPOINT
    times what that checkpoint took to write; the first is written at once, and a flush (an interrupted
    run) or the finish writes the rest. On a clock that this test moves: a pass takes 1 s, a write 2 s."""
    from vehid.identification.dataio.archive import write_archive
    from vehid.identification.dataio import iekf_archive

    clock = {"now": 0.0}

    class _Clock:
        @staticmethod
        def perf_counter():
            return clock["now"]

    real_update = iekf_archive.update_archive

    def slow_update(path):
        clock["now"] += 2.0
        return real_update(path)

    monkeypatch.setattr(iekf_archive, "time", _Clock)
    monkeypatch.setattr(iekf_archive, "update_archive", slow_update)
    data, _ = make_data(5, outputs=(0,), duration=4.0)
    structure = ModalStructure.default(5, data.n_u, data.n_y)
    options = IEKFOptions(p=0.5, passes=12, parameter_tolerance=0.0, trace_tolerance=0.0)
    archive = tmp_path / "run.h5"
    with write_archive(archive, kind="identification", config=options, seeds=[]):
        pass
    checkpoint = iekf_archive.Checkpointer(archive, "iekf")

    def stored_passes():
        with open_archive(archive) as handle:
            return read_iekf_run(handle, "iekf").passes_run if "runs" in handle else 0

    stored = []

    def on_pass(record, so_far):
        clock["now"] += 1.0
        checkpoint(record, so_far)
        stored.append(stored_passes())
        if record.index == 11:
            raise _Killed()

    with pytest.raises(_Killed):
        identify_iekf(data, structure, options=options, on_pass=on_pass)
    # pass 1 at once (no write timed yet); then 8 s of passes (4 x the 2 s write) before the next: pass 9
    assert iekf_archive.COMPUTE_PER_CHECKPOINT == 4.0
    assert stored == [1] * 8 + [9] * 3
    checkpoint.flush()  # what the command does on its way out of an interrupted run
    assert stored_passes() == 11
    whole = identify_iekf(data, structure, options=options)
    with open_archive(archive) as handle:
        kept = read_iekf_run(handle, "iekf")
    assert [record.index for record in kept.history] == list(range(1, 12))
    assert all(np.array_equal(a.parameters, b.parameters) for a, b in zip(kept.history, whole.history))
    assert np.array_equal(kept.model.parameters, whole.history[10].parameters)  # the model of pass 11


def test_a_run_killed_after_it_converged_resumes_converged():
    """Killed between the checkpoint of its converging pass and its stop check: no extra pass on resume."""
    data, _ = make_data(5, outputs=(0,), duration=20.0)
    structure = ModalStructure.default(5, data.n_u, data.n_y)
    # loose tolerances so that the run settles within a few passes (the rule, not the figures, is tested)
    options = IEKFOptions(p=0.5, passes=30, parameter_tolerance=0.1, trace_tolerance=0.1)  # measured: settles at pass 11
    whole = identify_iekf(data, structure, options=options)
    assert whole.stop_reason == "converged" and whole.passes_run < 30
    last = {}

    def kill_at_the_converging_pass(record, so_far):
        last["result"] = so_far
        if record.index == whole.passes_run:
            raise _Killed()

    with pytest.raises(_Killed):
        identify_iekf(data, structure, options=options, on_pass=kill_at_the_converging_pass)
    checkpoint = last["result"]
    assert checkpoint.stop_reason == "running" and checkpoint.passes_run == whole.passes_run
    resumed = identify_iekf(data, structure, options=options, resume=checkpoint)
    assert resumed.stop_reason == "converged" and resumed.passes_run == whole.passes_run
    assert np.array_equal(resumed.model.parameters, whole.model.parameters)


# ---------------------------------------------------------------- safe --out
def _no_work(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the identification started before the target was checked")

    monkeypatch.setattr(pipeline_run, "identify_iekf", refuse)


def test_out_refuses_the_input_file(tmp_path, capsys, monkeypatch):
    record = _record(tmp_path / "record.csv", duration=2.0)
    before = record.read_bytes()
    _no_work(monkeypatch)
    for extra in ([], ["--force"]):
        assert main(["identify", str(record), *COMMON, "--out", str(record), *extra]) == 2
        captured = capsys.readouterr()
        assert "is an input of this run" in captured.err and len(captured.err.strip().splitlines()) == 1
        assert json.loads(captured.out)["exit_status"] == 2
    assert record.read_bytes() == before


def test_out_refuses_a_foreign_file_unless_forced(tmp_path, capsys, monkeypatch):
    record = _record(tmp_path / "record.csv", duration=4.0)
    notes = tmp_path / "notes.h5"
    notes.write_text("my notes")
    real = pipeline_run.identify_iekf
    _no_work(monkeypatch)
    assert main(["identify", str(record), *COMMON, "--out", str(notes)]) == 2
    assert "not a workbench archive" in capsys.readouterr().err
    assert notes.read_text() == "my notes"
    monkeypatch.setattr(pipeline_run, "identify_iekf", real)
    assert main(["identify", str(record), *COMMON, "--passes", "2", "--out", str(notes), "--force"]) == 0
    assert read_archive(notes).runs["iekf"].n_pass == 2


@pytest.mark.parametrize("where", ["directory", "under-a-file"])
def test_out_on_a_directory_fails_before_any_work_with_one_line(where, tmp_path, capsys, monkeypatch):
    record = _record(tmp_path / "record.csv", duration=2.0)
    target = tmp_path if where == "directory" else record / "out.h5"
    cause = "Is a directory" if where == "directory" else "Not a directory"
    _no_work(monkeypatch)
    for method in ("iekf", "arx"):
        assert main(["identify", str(record), *COMMON, "--method", method, "--out", str(target)]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and str(target) in lines[0] and cause in lines[0], captured.err
        assert "internal error" not in captured.err


def test_comparators_archive_their_model(tmp_path, capsys):
    record = _record(tmp_path / "record.csv", duration=10.0)
    out = tmp_path / "arx.h5"
    assert main(["identify", str(record), *COMMON, "--method", "arx", "--out", str(out)]) == 0
    summary = _summary(capsys)
    assert summary["archive"] == str(out)
    archive = read_archive(out)
    run = archive.runs["arx"]
    assert np.allclose(np.sort_complex(run.model.eigenvalues()),
                       np.sort_complex([complex(*v) for v in summary["eigenvalues"]]), rtol=1e-12)
    assert np.allclose(run.metrics.percentage_explanation, summary["R"], rtol=1e-12)
    assert np.allclose(run.metrics.nrmse_fit, summary["fit_percent"], rtol=1e-12)
    assert archive.records["identification"].n_samples == 5000  # 10 s at 500 Hz
    assert main(["report", str(out), "--out", str(tmp_path / "figs"), "--dpi", "30", "--quiet"]) == 0


def _alternating_record(tmp_path):
    """y(k) = -0.5 y(k-1) + u(k-1): a discrete pole at -0.5, which has no continuous-time equivalent."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=2000)
    y = np.zeros(2000)
    for k in range(1, 2000):
        y[k] = -0.5 * y[k - 1] + u[k - 1]
    path = tmp_path / "alternating.csv"
    np.savetxt(path, np.column_stack([np.arange(2000) * 0.01, u, y]), delimiter=",", header="t,u,y", comments="")
    return path


def test_a_negative_real_discrete_pole_comes_back_as_a_labelled_discrete_model(tmp_path, capsys):
    """It used to exit 2 (as bad input) with no model; the estimate is right, only its continuous form does not exist."""
    path = _alternating_record(tmp_path)
    assert main(["identify", str(path), "--inputs", "u", "--outputs", "y", "--order", "1", "--method", "arx",
                 "--detrend", "none", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["time_domain"] == "discrete"
    assert summary["eigenvalues"][0] == pytest.approx(-0.5, abs=1e-6)  # noise-free: exact to rounding


def test_a_model_conversion_failure_on_good_input_exits_1(tmp_path, capsys, monkeypatch):
    """An estimate with no modal form is a failed computation (1), not bad input (it used to be 2)."""
    import vehid.identification.comparators as comparators
    def no_modal_form(*args, **kwargs):
        raise ConversionError("the arx model has no continuous modal form: a defective eigenvalue")

    monkeypatch.setattr(comparators, "identify_with", no_modal_form)
    path = _alternating_record(tmp_path)
    assert main(["identify", str(path), "--inputs", "u", "--outputs", "y", "--order", "1", "--method", "arx",
                 "--json"]) == 1
    captured = capsys.readouterr()
    assert "no continuous modal form" in captured.err and json.loads(captured.out)["exit_status"] == 1
