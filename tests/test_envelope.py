"""The envelope campaign: grip-limit amplitude, jobs, archive and resume, process pool and Dask executors.

Campaigns here are small (two grid speeds and the midpoint, order 2, linear
only, 8 s records, few passes): the figures are not the point, the
mechanism is. Independent truths: the grip limit of a car without
aerodynamic forces does not depend on speed, and its small-steer gain is the
trim's; jobs are pure functions, so any executor, order of completion or
lost worker gives the same numbers.
"""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest

from vehid.identification.dataio.archive import read_archive
from vehid.identification.errors import InputError
from vehid.scenarios.cli import main
from vehid.scenarios.envelope import EnvelopeConfig, grip_limit, run_campaign
from vehid.vehicle import named_vehicle

SMALL = dict(speeds=(15.0, 25.0), orders=(2,), nonlinear=False, duration=8.0, passes=10)


def test_grip_limit_is_the_tyres_and_the_gain_the_trims():
    # No aerodynamic load: the grip limit is set by the tyres alone, the same at every speed (measured
    # 7.72-7.76 m/s^2 at 10-30 m/s; 3 % allows for load transfer and for tyre-geometry changes). The
    # small-steer gain is the steady state's: 2.187 m/s^2/deg from trim at 20 m/s, and the linearisation's
    # steady state is the same algebra, so 1e-3 (trim tolerance and rounding).
    params = named_vehicle("baseline")
    limits = [grip_limit(params, speed) for speed in (10.0, 20.0, 30.0)]
    accelerations = np.array([limit.lateral_acceleration for limit in limits])
    assert np.ptp(accelerations) < 0.03 * accelerations.mean()
    assert 0.7 * 9.81 < accelerations.mean() < 0.9 * 9.81
    assert limits[1].gain * np.pi / 180 == pytest.approx(2.187, rel=1e-3)
    assert limits[0].steer > limits[1].steer > limits[2].steer  # faster: less steer to the limit
    assert limits[1].amplitude(0.1) == pytest.approx(0.1 * accelerations[1] / limits[1].gain)


@pytest.mark.parametrize(
    "settings, message",
    [
        (dict(speeds=(20.0, 10.0)), "speeds must increase"),
        (dict(amplitude_fraction=1.5), "beyond its grip limit"),
        (dict(off_grid=(40.0,)), "off-grid speed 40 must lie strictly between"),
        (dict(vehicles=()), "vehicles must be"),
        (dict(seeds=(0, 0)), "seeds must be distinct"),
    ],
)
def test_bad_settings_are_named(settings, message):
    with pytest.raises(InputError, match=message):
        EnvelopeConfig(**settings)


@pytest.fixture(scope="module")
def pooled(tmp_path_factory):
    """The small campaign on a local pool of two spawned processes."""
    path = tmp_path_factory.mktemp("envelope") / "pool.h5"
    return run_campaign(EnvelopeConfig(**SMALL), out=path, executor="process", workers=2)


def test_campaign_archive_rows_and_scheduled_model(pooled):
    summary = pooled.summary
    assert set(summary) == {"executor", "jobs", "seconds", "rows", "scheduled"}
    assert summary["jobs"] == 3 and summary["executor"] == "process"
    assert [(row["speed"], row["grid"]) for row in summary["rows"]] == [(15.0, True), (20.0, False), (25.0, True)]
    for row in summary["rows"]:
        assert row["nonlinear_validation_R"] is None
        assert row["linear_validation_R"] > 98.0  # linear regime, 10 passes: measured 99.2-99.3 %
        assert len(row["modes"]) == 1 and {"frequency_hz", "damping"} <= set(row["modes"][0])
        assert {m["label"] for m in row["vehicle_modes"]} == {"yaw-sideslip", "roll"}
        for item in row["mode_comparison"]:  # the only identified mode is the nearest to each vehicle mode
            assert item["identified_frequency_hz"] == row["modes"][0]["frequency_hz"]
    (item,) = summary["scheduled"]["off_grid"]
    assert summary["scheduled"]["grid_speeds"] == [15.0, 25.0] and item["speed"] == 20.0
    # the scheduled model between 15 and 25 m/s against the model identified at 20 m/s: measured 0.46 points
    assert abs(item["validation_R"] - item["direct_validation_R"]) < 1.0
    archive = read_archive(pooled.archive)
    assert archive.kind == "envelope-campaign"
    assert sorted(archive.runs) == ["baseline-v15-n2-s0", "baseline-v20-n2-s0", "baseline-v25-n2-s0"]
    assert archive.runs["baseline-v20-n2-s0"].metrics["grid"] is False


def test_resume_skips_finished_jobs_and_settings_must_match(pooled, tmp_path, capsys):
    again = run_campaign(EnvelopeConfig(**SMALL), out=pooled.archive, resume=True, executor="process", workers=1)
    assert again.skipped == 3
    assert json.dumps(again.summary["rows"]) == json.dumps(pooled.summary["rows"])
    with pytest.raises(InputError, match="other job settings"):
        run_campaign(EnvelopeConfig(**{**SMALL, "passes": 6}), out=pooled.archive, resume=True)
    assert main(["study", "envelope", "--speeds", "15,25", "--out", str(pooled.archive), "--json"]) == 2
    assert "exists" in json.loads(capsys.readouterr().out)["error"]


@pytest.mark.slow
def test_dask_campaign_survives_a_killed_worker(tmp_path):
    """A local Dask cluster of two workers; one is killed (SIGKILL) while it holds a job.

    Dask reschedules the lost job on the other worker (or the restarted
    one); the campaign completes with the numbers of a run in one process,
    because each job is a pure function of its settings (same compiled code,
    same data: equal to rounding, 1e-9 points).
    """
    import threading

    from distributed import Client, LocalCluster

    config = EnvelopeConfig(**{**SMALL, "passes": 40})  # jobs of about a second: the kill lands mid-job
    reference = run_campaign(config, out=tmp_path / "one.h5", workers=1)
    killed: list[str] = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        stop = threading.Event()

        def kill_the_first_busy_worker() -> None:
            while not stop.is_set() and not killed:
                busy = [address for address, keys in client.processing().items() if keys]
                if busy:
                    pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
                    os.kill(pid, signal.SIGKILL)
                    killed.append(busy[0])
                stop.wait(0.02)

        killer = threading.Thread(target=kill_the_first_busy_worker)
        killer.start()
        try:
            result = run_campaign(config, out=tmp_path / "dask.h5", executor="dask",
                                  scheduler=cluster.scheduler_address)
        finally:
            stop.set()
            killer.join()
    assert killed, "no worker was seen busy: the test did not exercise a loss"
    assert result.summary["executor"] == "dask" and len(read_archive(tmp_path / "dask.h5").runs) == 3
    for mine, theirs in zip(result.summary["rows"], reference.summary["rows"]):
        assert (mine["speed"], mine["order"]) == (theirs["speed"], theirs["order"])
        assert mine["linear_validation_R"] == pytest.approx(theirs["linear_validation_R"], abs=1e-9)
        assert mine["modes"][0]["frequency_hz"] == pytest.approx(theirs["modes"][0]["frequency_hz"], rel=1e-9)
    assert result.summary["scheduled"]["off_grid"][0]["validation_R"] == pytest.approx(
        reference.summary["scheduled"]["off_grid"][0]["validation_R"], abs=1e-9)


@pytest.mark.parametrize(
    "options, message",
    [
        (["--speeds", "20,10"], "speeds must increase"),
        (["--speeds", "fast"], "speeds must be numbers"),
        (["--amplitude-fraction", "2"], "beyond its grip limit"),
        (["--seeds", "a"], "seeds must be whole numbers"),
        (["--scheduler", "tcp://127.0.0.1:1"], "needs --executor dask"),
        (["--off-grid", "50"], "must lie strictly between"),
    ],
)
def test_bad_options_exit_2_with_one_line(options, message, capsys, tmp_path):
    assert main(["study", "envelope", "--out", str(tmp_path / "x.h5"), *options]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert captured.out == "" and len(lines) == 1 and message in lines[0], captured.err
    assert not (tmp_path / "x.h5").exists()
