"""The handling study (Best & Bogdanski 2017, section 6, Table 5): its command, table, modes and archive.

Independent truth: the vehicle's own linearisation (:func:`vehid.vehicle.linearize`)
for the modes, the paper's Table 5 for the table's shape, and the archive
read back from disk. The records are short (10 s) and the passes few, so that
the module runs in well under a minute; the full study's figures are in the
module notes of :mod:`vehid.scenarios.handling_study`.
"""

import json
import subprocess
import sys
from vehid.identification.models.spline_modal import SplineModalModel
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.dataio.archive import read_archive
from vehid.identification.errors import DivergenceError, InputError
from vehid.identification.filtering.spline_iekf import SplineIEKFOptions
from vehid.scenarios import handling_study
from vehid.scenarios.cli import main
from vehid.scenarios.commands.study_handling import text_of
from vehid.scenarios.handling_study import (
    OUTPUTS,
    HandlingConfig,
    compare_modes,
    make_records,
    parse_orders,
    run_study,
    study_linear_options,
    write_archive_for,
)

# Short records at full amplitude (the nonlinear range). p = 1e-3 converges fast enough for
# 20 passes on 10 s of data (measured mean R: 97.6 % for n = 2, 98.7 % for n = 3).
FAST = ["--orders", "2-3", "--duration", "10", "--passes", "20", "--p", "1e-3", "--seed", "0"]
# the study the signal test stops: FAST with three more orders, so that it is still running when stopped
STOPPED = ["--orders", "2-6", *FAST[2:]]
TABLE_KEYS = {"order", "linear_eigenvalues", "linear_identification_R", "nonlinear_identification_R",
              "linear_validation_R", "nonlinear_validation_R"}


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    """The command as a user runs it, two workers (a spawned process pool), JSON on stdout.

    Run through the console script's entry point in this process: the workers are spawned processes
    either way, and the vehicle's functions the command builds to simulate the records serve the
    tests below that simulate them again.
    """
    out = tmp_path_factory.mktemp("handling") / "handling_study.h5"
    completed = run_vehid("study", "handling", *FAST, "--workers", "2", "--json", "--out", str(out))
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout), out, completed.stderr


def test_json_summary_keys_and_types(study):
    summary, out, _ = study
    assert {"table", "chosen_order", "seconds", "vehicle_modes", "mode_comparison", "archive"} <= set(summary)
    assert isinstance(summary["chosen_order"], int) and summary["chosen_order"] in (2, 3)
    assert isinstance(summary["seconds"], float) and summary["seconds"] > 0
    assert summary["archive"] == str(out)
    for row in summary["table"]:
        assert set(row) == TABLE_KEYS
        assert isinstance(row["order"], int)
        for key in ("linear_identification_R", "linear_validation_R"):
            assert isinstance(row[key], float)
        for value in row["linear_eigenvalues"]:
            assert isinstance(value, list) and len(value) == 2 and all(isinstance(v, float) for v in value)


def test_table_rows(study):
    summary, _, stderr = study
    rows = summary["table"]
    assert [row["order"] for row in rows] == [2, 3]
    for row in rows:
        eigenvalues = np.array([complex(*value) for value in row["linear_eigenvalues"]])
        assert eigenvalues.size == row["order"] and np.all(eigenvalues.real < 0)
        # a linear model of a car at 90 % of grip: well above 95 %, short of the vehicle's own
        # linearisation's 99.99 % in the linear regime (measured 97.6-99.0 %)
        assert 95.0 < row["linear_identification_R"] < 99.9
        assert 95.0 < row["linear_validation_R"] < 99.9
    # the paper's shape: R grows with the order (n = 2: 97.6 %, n = 3: 98.7 % measured)
    assert rows[1]["linear_identification_R"] > rows[0]["linear_identification_R"]
    # the nonlinear identifications ran and were scored on both records
    assert all(row["nonlinear_identification_R"] is not None and row["nonlinear_validation_R"] is not None
               for row in rows)


def test_archive_round_trip(study):
    summary, out, _ = study
    archive = read_archive(out, kinds=("handling-study",))
    assert archive.kind == "handling-study" and archive.seeds == [0]
    assert set(archive.records) == {"identification", "validation"}
    for record in archive.records.values():
        assert record.output_names == OUTPUTS and record.input_names == ("steer",)
        assert record.n_samples == 5001 and record.dt == pytest.approx(0.002)
    assert {"linear-n2", "linear-n3"} <= set(archive.runs)
    by_order = {row["order"]: row for row in summary["table"]}
    for order in (2, 3):
        run = archive.runs[f"linear-n{order}"]
        assert run.n_pass == 20
        stored = np.sort_complex(run.model.eigenvalues())
        reported = np.sort_complex(np.array([complex(*v) for v in by_order[order]["linear_eigenvalues"]]))
        assert np.allclose(stored, reported, rtol=1e-12)
        # the stored model, simulated again over the stored record, scores what the summary says
        record = archive.records["validation"]
        again = np.mean(handling_study.explained_percent(run.model, record))
        assert again == pytest.approx(by_order[order]["linear_validation_R"], abs=1e-9)
        assert np.mean(run.metrics["identification_R"]) == pytest.approx(by_order[order]["linear_identification_R"], abs=1e-12)
    assert archive.config["orders"] == [2, 3] and archive.config["passes"] == 20


def test_records_start_at_the_trim():
    """The outputs start at zero, the state the models start from: no trim offset is needed."""
    records = make_records(HandlingConfig(orders=(2,), duration=5.0))
    for record in records.values():
        assert np.max(np.abs(record.y[0])) < 1e-12  # trim at zero steer, straight running: exactly zero but rounding
        assert np.max(np.abs(record.y), axis=0).min() > 1e-3  # and every output is excited


def test_linear_modes_near_the_vehicle_modes():
    """In the linear regime the order-3 model finds the vehicle's roll mode.

    At a tenth of the steer amplitude the vehicle's linearisation explains
    99.99 % of the data. The order-3 model's pair then lies at the roll mode:
    measured 1.40-1.48 Hz, damping 0.59-0.61 (30 s and 10 s records, p 1e-5
    to 1e-3) against the vehicle's 1.447 Hz and 0.575, hence 10 % in
    frequency and 0.1 in damping. The yaw-sideslip mode (2.14 Hz, damping
    0.98) is not pinned down by these data: nearly critically damped and close
    to the tyre lags, it can be placed elsewhere at no cost (a model with two
    pairs and two real poles explains 99.997 % with its poles at -26 +/- 14j
    and a double pole at -8.6). Its nearest identified mode is asserted only
    to be well damped and slower: measured damping 1.0, 0.96-1.07 Hz.
    """
    result = run_study(HandlingConfig(orders=(3,), duration=10.0, amplitude_scale=0.1,
                                      linear_options=study_linear_options(1e-3, 30), spline_options=None, workers=1))
    # measured 99.5718 % with OpenBLAS's Haswell, Sandybridge and Prescott kernels and with one BLAS thread,
    # equal to 13 digits: simulated data and a fixed p leave no decision to flip
    assert result.table[0].linear_identification_R > 99.5
    modes = {item.mode: item for item in result.mode_comparison}
    roll = modes["roll"]
    assert roll.vehicle_frequency_hz == pytest.approx(1.447, abs=1e-3)
    assert abs(roll.frequency_ratio - 1.0) < 0.10
    assert abs(roll.identified_damping - roll.vehicle_damping) < 0.10
    yaw = modes["yaw-sideslip"]
    assert yaw.identified_damping > 0.75
    assert 0.3 < yaw.frequency_ratio < 1.0


def test_compare_modes_picks_the_nearest_mode():
    from vehid.vehicle.linearize import VehicleMode

    roll = VehicleMode(complex(-5, 7), abs(complex(-5, 7)) / (2 * np.pi), 5 / abs(complex(-5, 7)), "roll", ("phi",))
    (found,) = compare_modes(3, [complex(-20, 0), complex(-4, -6.5)], {"roll": roll})  # a conjugate counts as its pair
    assert (found.order, found.mode) == (3, "roll")
    assert found.identified_eigenvalue == complex(-4, 6.5)
    assert found.identified_damping == pytest.approx(4 / abs(complex(-4, 6.5)), rel=1e-12)


def test_pool_and_single_process_agree(study):
    """The parallel run gives what one process gives: each order is a function of its data alone.

    Same compiled code and data, so the figures agree to rounding (1e-9 points leaves room for
    a BLAS that sums in another order in another process; measured: identical).
    """
    summary, _, _ = study
    single = run_study(HandlingConfig(orders=(2, 3), duration=10.0, linear_options=study_linear_options(1e-3, 20),
                                      spline_options=None, workers=1))
    for pooled, alone in zip(summary["table"], single.table):
        assert pooled["linear_identification_R"] == pytest.approx(alone.linear_identification_R, abs=1e-9)
        assert pooled["linear_validation_R"] == pytest.approx(alone.linear_validation_R, abs=1e-9)


def test_a_diverged_order_leaves_the_others_standing(monkeypatch, tmp_path):
    real = handling_study.identify_iekf

    def diverge_at_three(data, structure, **options):
        if structure.n == 3:
            raise DivergenceError("pass 1: the identified model is unstable", last_good=None)
        return real(data, structure, **options)

    monkeypatch.setattr(handling_study, "identify_iekf", diverge_at_three)
    result = run_study(HandlingConfig(orders=(2, 3), duration=5.0, linear_options=study_linear_options(1e-3, 3),
                                      spline_options=None, workers=1))
    failed = result.table[1]
    assert failed.linear_eigenvalues == () and failed.linear_identification_R is None
    assert "unstable" in result.linear_runs[1].error
    assert result.assessment.chosen_order == 2
    assert "(failed)" in text_of(result)
    assert set(read_archive(write_archive_for(result, tmp_path / "h.h5")).runs) == {"linear-n2"}

    def always_diverge(data, structure, **options):
        raise DivergenceError("pass 1: non-finite values", last_good=None)

    monkeypatch.setattr(handling_study, "identify_iekf", always_diverge)
    with pytest.raises(DivergenceError, match="no order gave a linear model"):
        run_study(HandlingConfig(orders=(2,), duration=5.0, linear_options=study_linear_options(passes=3),
                                 spline_options=None, workers=1))


@pytest.mark.parametrize(
    "options, message",
    [
        (["--orders", "7-2"], "runs backwards"),
        (["--orders", "1"], "from 2 to 8"),
        (["--orders", "2-9"], "from 2 to 8"),
        (["--orders", "four"], "orders must look like"),
        (["--nodes", "2"], "nodes must be a whole number from 3"),
        (["--nodes", "12"], "nodes must be a whole number from 3 to 9"),
        (["--nodes", "12", "--linear-only"], "nodes must be a whole number from 3 to 9"),
        (["--passes", "1"], "passes must be"),
        (["--workers", "0"], "workers must be"),
        (["--duration", "2"], "duration must be at least"),
        (["--amplitude-scale", "0"], "amplitude_scale must be a positive number"),
    ],
)
def test_bad_options_exit_2_with_one_line(options, message, capsys):
    assert main(["study", "handling", *options]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], captured.err


def test_parse_orders():
    assert parse_orders("2-6") == (2, 3, 4, 5, 6)
    assert parse_orders("4") == (4,)
    assert parse_orders(" 2, 4-5 ") == (2, 4, 5)
    for text in ("3,2", "2,2", "2-", ""):
        with pytest.raises(InputError):
            parse_orders(text)


# ----------------------------------------------------------------- the nonlinear call site
@dataclass(frozen=True, eq=False)
class _StandInRecord:  # only what the announced interface promises: no pass index
    fit_filter: np.ndarray
    trace_p: float

    @property
    def mean_fit_filter(self) -> float:
        return float(np.mean(self.fit_filter))


def _stand_in_model(linear, data, nodes):
    """A real spline model (so that it archives): the linear one, its first omega falling by 20 % over the amplitude."""
    model = SplineModalModel.from_linear(linear, nodes, np.abs(data.u).max(0), np.abs(data.y).max(0), data.dt)
    gammas = model.structure.gammas(model.theta).copy()
    gammas[1] *= np.linspace(1.0, 0.8, nodes)  # omega1 against the pair's amplitude
    return model.with_parameters(gammas.ravel())


@dataclass(frozen=True, eq=False)
class _StandInResult:
    model: object
    history: tuple
    seconds: float = 0.5
    stop_reason: str = "passes"


def test_nonlinear_call_site_with_a_stand_in(monkeypatch, tmp_path):
    """The study's one call site, fed by a stand-in with the announced interface of identification.filtering.spline_iekf."""
    calls = []

    def identify(data, linear_model, *, options, on_pass):
        calls.append(options)
        history = []
        for index in range(1, options.passes + 1):
            record = _StandInRecord(np.full(data.n_y, 99.0), 1e-3 * index)
            history.append(record)
            on_pass(record, None)
        return _StandInResult(_stand_in_model(linear_model, data, options.nodes), tuple(history))

    monkeypatch.setattr(handling_study, "identify_spline_iekf", identify)
    events = []
    spline = SplineIEKFOptions(nodes=7, passes=3)
    result = run_study(HandlingConfig(orders=(2,), duration=5.0, linear_options=study_linear_options(1e-3, 3),
                                      spline_options=spline, workers=1), on_event=events.append)
    assert calls == [spline]  # the configuration's own options, passed on whole
    assert [(e.stage, e.index) for e in events] == [("linear", 1), ("linear", 2), ("linear", 3),
                                                    ("nonlinear", 1), ("nonlinear", 2), ("nonlinear", 3)]
    row = result.table[0]
    outcome = result.outcomes[2]
    assert row.nonlinear_identification_R == pytest.approx(np.mean(handling_study.explained_percent(
        outcome.nonlinear.model, result.records["identification"])), abs=1e-12)
    assert row.nonlinear_validation_R is not None
    run = result.nonlinear_runs[0]
    assert run.passes_run == 3 and run.missing is None
    assert run.mode_frequency_hz[0][-1] < run.mode_frequency_hz[0][0]
    path = write_archive_for(result, tmp_path / "handling.h5")
    stored = read_archive(path).runs["nonlinear-n2"]
    assert stored.n_pass == 3 and np.allclose(stored.history["trace_p"], [1e-3, 2e-3, 3e-3])
    assert np.allclose(stored.metrics["validation_R"], outcome.nonlinear.fit_validation)


@pytest.mark.slow
def test_nonlinear_beats_linear_and_reaches_the_target_at_order_four():
    """Issue targets at n = 4, the paper's and our chosen order, with the study's default settings.

    Measured (seed 0): linear 99.26 / 98.82 %, nonlinear 99.66 / 99.59 % (identification / validation);
    with the tyre contact points on the road (they used to ride with the body: 99.28 / 98.85 % and
    99.65 / 99.59 %), the first mode's frequency falls from 1.01 to 0.87 Hz.
    The paper's vehicle: 99.79 / 99.37 % linear, 99.96 / 99.80 % nonlinear (Table 5).
    """
    result = run_study(HandlingConfig(orders=(4,), workers=1))
    row = result.table[0]
    assert row.nonlinear_identification_R > row.linear_identification_R
    assert row.nonlinear_validation_R > row.linear_validation_R
    assert row.nonlinear_validation_R >= 99.5
    # the first mode's frequency falls as its amplitude grows (the paper's Figure 8 reading)
    frequency = result.nonlinear_runs[0].mode_frequency_hz[0]
    assert frequency[-1] < frequency[0]


def test_report_writes_every_figure_the_table_and_the_casadi_export(study):
    """The study command writes its report folder beside the archive, as make study does."""
    import casadi as ca

    summary, archive, _ = study
    folder = archive.with_suffix("")
    assert summary["report"] == str(folder)
    files = {path.name for path in folder.iterdir()}
    expected = {"fits_identification.png", "fits_validation.png", "orders.png", "linear_parameters.png",
                "linear_convergence.png", "eigenvalues.png", "bode.png", "report.pdf", "table.md"}
    assert expected <= files
    if summary["table"][-1]["nonlinear_validation_R"] is not None:
        chosen = summary["chosen_order"]
        assert {"splines.png", "mode_amplitude.png", "residuals.png", f"nonlinear_n{chosen}.casadi"} <= files
        function = ca.Function.load(str(folder / f"nonlinear_n{chosen}.casadi"))
        assert function.size1_in(0) == 1 and function.size1_out(0) == 3
    table = (folder / "table.md").read_text()
    assert "nonlinear validation R %" in table and f"Chosen order: {summary['chosen_order']}" in table


# ------------------------------------------------------- resume and clean shutdown
def _study_table(summary):
    return [{key: row[key] for key in TABLE_KEYS} for row in summary["table"]]


def test_resume_of_a_truncated_study_redoes_only_what_is_missing(study, tmp_path, capsys):
    """An archive holding order 2 only (as a kill after its checkpoint leaves it) resumes to the uninterrupted numbers.

    The failure it reproduces: the study had no resume, so every interruption cost the whole study.
    Equal to the last bit: the finished order is read back exactly, the missing one is the same
    computation on the same records.
    """
    import shutil

    from vehid.identification.dataio.archive import update_archive

    summary, out, _ = study
    partial = tmp_path / "partial.h5"
    shutil.copyfile(out, partial)
    with update_archive(partial) as handle:  # what the archive held before order 3 finished
        for name in ("linear-n3", "nonlinear-n3"):
            del handle["runs"][name]
        done = json.loads(handle.attrs["orders_done_json"])
        del done["3"]
        handle.attrs["orders_done_json"] = json.dumps(done)
        del handle.attrs["summary_json"]
    events = []
    real = handling_study.run_order
    try:
        handling_study.run_order = lambda job, report=None: events.append(job.order) or real(job, report)
        assert main(["study", "handling", "--resume", str(partial), "--workers", "1", "--no-report",
                     "--quiet", "--json"]) == 0
    finally:
        handling_study.run_order = real
    resumed = json.loads(capsys.readouterr().out)
    assert events == [3] and resumed["resumed_orders"] == [2]
    assert _study_table(resumed) == _study_table(summary)
    assert resumed["chosen_order"] == summary["chosen_order"]
    assert read_archive(partial).runs.keys() == read_archive(out).runs.keys()


def test_resume_refuses_settings_and_foreign_files(tmp_path, capsys):
    assert main(["study", "handling", "--resume", str(tmp_path / "x.h5"), "--orders", "4"]) == 2
    assert "do not give --orders" in capsys.readouterr().err
    assert main(["study", "handling", "--resume", str(tmp_path / "absent.h5"), "--json"]) == 2
    captured = capsys.readouterr()
    assert "no such archive" in captured.err and json.loads(captured.out)["exit_status"] == 2


def _session_processes(session):
    """Live processes (not zombies) of a session, from /proc: {pid: (state, ppid)}."""
    import os

    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat") as handle:
                fields = handle.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        state, ppid, session_id = fields[0], int(fields[1]), int(fields[3])
        if session_id == session and state != "Z":
            found[int(entry)] = (state, ppid)
    return found


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the process tree from /proc")
@pytest.mark.parametrize("stop", ["SIGTERM", "SIGINT", "SIGKILL"])
def test_a_signal_stops_every_worker_and_leaves_a_readable_archive(stop, study, tmp_path, capsys):
    """SIGTERM, Ctrl-C (SIGINT to the process group) and the parent's death stop the workers within seconds.

    The failure it reproduces: workers kept running after their parent was killed, then hung on their
    pipes. The whole session of the study (its workers and helpers) must be gone within 10 s (a worker
    is terminated, then killed after 2 s; the kernel kills them when the parent dies).
    """
    import os
    import signal
    import time

    from vehid.scenarios.handling_resume import read_progress

    out = tmp_path / "stopped.h5"
    # started as from a terminal: a test run launched in the background of a non-interactive shell has
    # SIGINT ignored, the study would inherit that and rightly ignore Ctrl-C (a handler, unlike an
    # ignore, is reset to the default in the new program)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "vehid.scenarios.cli", "study", "handling", *STOPPED, "--linear-only",
             "--workers", "2", "--no-report", "--quiet", "--out", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    deadline = time.monotonic() + 120
    workers = {}
    while time.monotonic() < deadline and process.poll() is None:
        workers = {pid for pid, (_, ppid) in _session_processes(process.pid).items() if ppid == process.pid}
        if len(workers) >= 2 and out.exists():  # the records are checkpointed and the orders running
            break
        time.sleep(0.1)
    # into the orders: they still run 1.8-1.9 s after this point (measured); FAST's two orders after a 1 s
    # wait left 0.35-0.45 s, and on a quiet machine sometimes nothing, so that the test skipped
    time.sleep(0.3)
    if process.poll() is not None:  # on a fast machine the short study can end before the signal
        pytest.skip("the study finished before it could be stopped")
    stopped = time.monotonic()
    if stop == "SIGINT":
        os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole foreground group
    else:
        process.send_signal(getattr(signal, stop))
    stdout, stderr = process.communicate(timeout=30)
    while _session_processes(process.pid) and time.monotonic() - stopped < 10:
        time.sleep(0.1)
    assert _session_processes(process.pid) == {}, "processes of the study outlived it"
    assert time.monotonic() - stopped < 10
    if stop != "SIGKILL" and process.returncode == -getattr(signal, stop) and f"wrote {out}" in stdout:
        # The one window where the signal's default action ends the command: its result was complete and
        # printed (the CLI restores the handlers only after that), so there was nothing left to stop.
        pytest.skip("the study had finished and printed its result when the signal came")
    if stop != "SIGKILL":
        assert process.returncode == 128 + getattr(signal, stop)
        assert stderr.strip().splitlines() == [f"vehid: interrupted by {stop}"]
    else:
        assert process.returncode == -signal.SIGKILL
    assert not list(tmp_path.glob(".*.tmp")) or stop == "SIGKILL"  # temporary files cleaned up on a signal
    config, records, finished = read_progress(out)  # readable: the last complete checkpoint
    assert config.orders == (2, 3, 4, 5, 6) and set(records) == {"identification", "validation"}
    if stop == "SIGTERM":  # and it resumes to the numbers of the uninterrupted study (its linear columns)
        assert main(["study", "handling", "--resume", str(out), "--workers", "1", "--no-report", "--quiet",
                     "--json"]) == 0
        resumed = json.loads(capsys.readouterr().out)
        summary, _, _ = study
        by_order = {row["order"]: row for row in resumed["table"]}
        assert sorted(by_order) == [2, 3, 4, 5, 6]
        for whole in summary["table"]:  # each order is identified on its own: orders 2 and 3 as in FAST
            row = by_order[whole["order"]]
            for key in ("linear_eigenvalues", "linear_identification_R", "linear_validation_R"):
                assert row[key] == whole[key]


def test_config_holds_the_options_of_both_filters_and_archives_flat():
    """The options are validated by their own classes; the archive's flat settings (a public
    contract: the ``config`` key of the JSON summary) read back to the same configuration."""
    with pytest.raises(InputError, match="from 3 to 9"):
        HandlingConfig(spline_options=SplineIEKFOptions(nodes=12))
    with pytest.raises(InputError, match="passes must be a whole number >= 2"):
        HandlingConfig(linear_options=study_linear_options(passes=1))
    config = HandlingConfig(orders=(2, 4), linear_options=study_linear_options(1e-3, 20),
                            spline_options=SplineIEKFOptions(nodes=7, passes=4))
    stored = config.as_dict()
    assert list(stored) == ["orders", "seed", "duration", "amplitude_scale", "vehicle", "speed", "dt", "p", "passes",
                            "nodes", "nonlinear", "nonlinear_passes", "nonlinear_p", "workers"]
    assert HandlingConfig.from_dict(json.loads(json.dumps(stored))) == config
    linear_only = HandlingConfig(spline_options=None)
    assert HandlingConfig.from_dict(linear_only.as_dict()) == linear_only
    # an archive written before the options were composed: spline settings None meant the filter's defaults
    assert HandlingConfig.from_dict({**stored, "nonlinear_passes": None, "nonlinear_p": None}).spline_options == \
        SplineIEKFOptions(nodes=7)
