"""`vehid identify --structure single-track`: JSON contract, units, hold-out validation, warnings and bad input."""

import json

import numpy as np
import pytest
from conftest import library_spy, mutable_parts, printed_json, run_vehid, without_run_times

from vehid.identification.data import IOData
from vehid.identification.filtering.greybox_structure import simulate_greybox
from vehid.scenarios.cli import main
from vehid.vehicle.manoeuvres import band_limited_noise
from vehid.vehicle.single_track import SingleTrackConfig, single_track_model

TRUTH = {"cornering_stiffness_front": 80_000.0, "cornering_stiffness_rear": 100_000.0, "yaw_inertia": 2500.0}
GEOMETRY = ["--mass", "1500", "--lf", "1.2", "--lr", "1.5"]
DEG = np.pi / 180.0


def _vehid(*args):
    return run_vehid(*args)


def _drive(rng: np.random.Generator, n: int, *parameters: list[float]) -> tuple[IOData, list[np.ndarray]]:
    """``n`` samples at 100 Hz, speed 10 -> 30 m/s, 0-2 Hz steer, and the car's outputs with each set of parameters."""
    dt = 0.01
    t = dt * np.arange(n)
    steer = 0.02 * band_limited_noise(n, dt, 2.0, rng)
    record = IOData(t=t, u=np.column_stack([steer, 10.0 + 20.0 * t / t[-1]]), y=np.zeros((n, 2)))
    model = single_track_model(SingleTrackConfig(1500.0, 1.2, 1.5))
    return record, [simulate_greybox(model, theta, record)[0] for theta in parameters]


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    """90 s at 100 Hz, speed 10 -> 30 m/s, 0-2 Hz steer; yaw rate logged in deg/s; 3 % noise per output."""
    rng = np.random.default_rng(5)
    record, (y,) = _drive(rng, 9000, list(TRUTH.values()))
    t, steer, speed = record.t, record.u[:, 0], record.u[:, 1]
    y += 0.03 * np.std(y, axis=0) * rng.standard_normal(y.shape)
    path = tmp_path_factory.mktemp("logs") / "log.csv"
    np.savetxt(path, np.column_stack([t, steer, speed, y[:, 0] / DEG, y[:, 1]]), delimiter=",",
               header="t,delta,vx,yawRate,ayCG", comments="")
    return path


def _identify(log, *extra):
    return _vehid("identify", str(log), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                  "--outputs", "yawRate,ayCG", "--quantities", "yaw_rate,lateral_acceleration",
                  "--scale", f"yawRate={DEG!r}", *extra)


def test_the_command_prints_the_rendering_of_the_library_result(log, monkeypatch):
    """`vehid identify --structure single-track --json` calls identify_single_track() once and prints its result's
    rendering, every key and value; the library called from Python on the same log and settings renders the same
    summary, its run time aside."""
    from vehid.identification.dataio.preparation import ReadSettings
    from vehid.scenarios import single_track_identify

    library, results = library_spy(monkeypatch, single_track_identify, "identify_single_track")
    completed = _identify(log, *GEOMETRY, "--validation", "0.3", "--json")
    assert completed.returncode == 0, completed.stderr
    (result,) = results
    summary = json.loads(completed.stdout)
    assert summary == printed_json(result.render())
    # frozen all the way down, the model and the filter's run the summary is rendered from included
    assert mutable_parts(result) == []
    with pytest.raises(ValueError):
        result.estimator.nrmse_fit_percent[0] = 99.0
    again = library(str(log), schedule="vx", config=SingleTrackConfig(1500.0, 1.2, 1.5), validation=0.3,
                    reading=ReadSettings(inputs=("delta",), outputs=("yawRate", "ayCG")), scale=[f"yawRate={DEG!r}"])
    assert without_run_times(printed_json(again.render())) == without_run_times(summary)


def test_json_contract_and_recovery(log):
    completed = _identify(log, *GEOMETRY, "--validation", "0.3", "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    parameters = summary["physical_parameters"]
    assert set(parameters) == set(TRUTH)
    for name, truth in TRUTH.items():
        entry = parameters[name]
        assert entry["unit"] == {"yaw_inertia": "kg m^2"}.get(name, "N/rad")
        # 3 % noise on 6300 samples: within 3 reported sigma (99.7 %) and 1 % (measured 0.03-0.16 %)
        assert abs(entry["value"] - truth) < 3 * entry["std"] and abs(entry["value"] / truth - 1) < 0.01
    handling = summary["handling"]
    gradient = 1500.0 / 2.7 * (1.5 / 80_000.0 - 1.2 / 100_000.0) * 9.81 * 180.0 / np.pi  # 2.108 deg/g
    assert handling["understeer_gradient_deg_per_g"]["value"] == pytest.approx(gradient, rel=0.01)
    assert handling["understeer_gradient_deg_per_g"]["std"] > 0
    assert handling["understeer_gradient_deg_per_g"]["unit"] == "deg/g"
    assert handling["characteristic_speed_m_s"]["value"] == pytest.approx(np.sqrt(720.0), rel=0.01)
    assert handling["characteristic_speed_m_s"]["std"] > 0 and "critical_speed_m_s" not in handling
    # the held-out tail (24-30 m/s, faster than any estimation sample) is predicted as well as the noise
    # allows: the NRMSE fit of a 3 % noise is near 97 % (measured 95.1 and 96.9 %)
    assert len(summary["validation_fit_percent"]) == 2 and min(summary["validation_fit_percent"]) > 90.0
    assert summary["stop_reason"] == "converged" and summary["warnings"] == []
    assert summary["speed_range_m_s"][1] == pytest.approx(24.0, abs=0.01)  # estimated on the first 70 % only


def test_vehicle_file_and_text_summary(log, tmp_path):
    vehicle = tmp_path / "car.toml"
    vehicle.write_text('base = "baseline"\n[chassis]\nmass = 1500.0\ncg_to_front_axle = 1.2\ncg_to_rear_axle = 1.5\n')
    completed = _identify(log, "--vehicle", str(vehicle), "--passes", "40")
    assert completed.returncode == 0, completed.stderr
    assert "cornering_stiffness_front" in completed.stdout and "understeer gradient" in completed.stdout


def test_warnings_under_strict_exit_3(log):
    # two passes cannot meet the stop rule from a start 20-60 % off: a warning, and exit 3 under --strict
    completed = _identify(log, *GEOMETRY, "--passes", "2", "--strict", "--json")
    assert completed.returncode == 3, completed.stderr
    assert "did not converge" in completed.stderr


@pytest.mark.parametrize("extra, message", [
    (["--mass", "1500", "--lf", "1.2"], "--lr"),
    ([*GEOMETRY, "--quantities", "yaw_rate"], "--quantities names 1 quantities for 2"),
    ([*GEOMETRY, "--quantities", "yaw_rate,roll"], "unknown quantity 'roll'"),
    ([*GEOMETRY, "--detrend", "linear"], "--detrend does not apply"),
    ([*GEOMETRY, "--steering-ratio", "0"], "steering ratio"),
])
def test_bad_input_exit_2(log, extra, message, capsys):
    status = main(["identify", str(log), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                   "--outputs", "yawRate,ayCG", *extra])
    error = capsys.readouterr().err
    assert status == 2, error
    assert message in error and len(error.strip().splitlines()) == 1


def test_speed_channel_is_required(log, capsys):
    status = main(["identify", str(log), "--structure", "single-track", "--inputs", "delta",
                   "--outputs", "yawRate,ayCG", *GEOMETRY])
    assert status == 2 and "--schedule" in capsys.readouterr().err


def test_sensor_offsets_have_their_own_key(log, capsys):
    status = main(["identify", str(log), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                   "--outputs", "yawRate,ayCG", "--scale", f"yawRate={DEG!r}", *GEOMETRY, "--offsets", "--json"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    summary = json.loads(captured.out)
    assert set(summary["physical_parameters"]) == set(TRUTH)  # the car's parameters only
    offsets = summary["sensor_offsets"]
    assert set(offsets) == {"steer_offset", "yaw_rate_offset", "lateral_acceleration_offset"}  # named by quantity
    # the log has none: each offset within three of its std of zero
    assert all(abs(entry["value"]) < 3 * entry["std"] for entry in offsets.values())
    assert len(summary["parameter_correlation"]) == len(summary["parameter_names"]) == 6


def test_slow_parts_take_substeps_and_standstill_is_left_out(tmp_path, capsys):
    """A log from 1.5 m/s, kept whole with --min-speed 1, needs several RK4 steps per sample (the bicycle's
    modes near 200 1/s) and is warned about; from standstill the samples below 5 m/s are left out by default
    (before: refused), and kept with --min-speed none the log is refused, naming the cure."""
    dt, n = 0.01, 3000
    t = dt * np.arange(n)
    steer = 0.02 * band_limited_noise(n, dt, 2.0, np.random.default_rng(2))
    cases = ((1.5, ["--min-speed", "1"], 0), (0.0, [], 0), (0.0, ["--min-speed", "none"], 2))
    for first_speed, extra, expected in cases:
        speed = first_speed + 10.0 * t / t[-1]
        record = IOData(t=t, u=np.column_stack([steer, speed]), y=np.zeros((n, 2)))
        y, _ = simulate_greybox(single_track_model(SingleTrackConfig(1500.0, 1.2, 1.5)), list(TRUTH.values()),
                                record, substeps=10)
        path = tmp_path / f"slow_{first_speed}.csv"
        np.savetxt(path, np.column_stack([t, steer, speed, y]), delimiter=",", header="t,delta,vx,r,ay",
                   comments="")
        status = main(["identify", str(path), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                       "--outputs", "r,ay", *GEOMETRY, "--json", *extra])
        captured = capsys.readouterr()
        assert status == expected, captured.err
        if expected == 0:
            summary = json.loads(captured.out)
            # noise-free: the generating parameters to 1 % despite the slow start
            for name, truth in TRUTH.items():
                assert summary["physical_parameters"][name]["value"] == pytest.approx(truth, rel=0.01)
            slow = int(np.count_nonzero(speed < 5.0))  # 1500 samples from rest, 1052 from 1.5 m/s
            if extra:
                assert any("below 5 m/s" in line for line in summary["warnings"])
                assert summary["left_out"]["below_min_speed"] == int(np.count_nonzero(speed < 1.0)) == 0
            else:
                assert summary["left_out"]["below_min_speed"] == summary["left_out"]["samples"] == slow
                assert summary["speed_range_m_s"][0] >= 5.0 and summary["warnings"] == []
        else:
            assert "--min-speed" in captured.err


def test_a_workbench_record_gives_its_speed_output_as_the_schedule(tmp_path, capsys):
    """The source car's own record (HDF5): steer is its input, speed one of its outputs."""
    assert main(["simulate", "--manoeuvre", "sweep", "--amplitude-deg", "0.3", "--duration", "20",
                 "--out", str(tmp_path / "sweep.h5"), "--quiet"]) == 0
    capsys.readouterr()
    status = main(["identify", str(tmp_path / "sweep.h5"), "--structure", "single-track", "--inputs", "steer",
                   "--schedule", "speed", "--outputs", "yaw_rate,lateral_acceleration", "--vehicle", "baseline",
                   "--json"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    summary = json.loads(captured.out)
    assert summary["speed_range_m_s"] == pytest.approx([20.0, 20.0], abs=0.1)  # the speed hold's 20 m/s
    # a plausible car: stiffnesses of 5-30 times each axle's static load per radian, the yaw inertia
    # within a factor 2 of the car's 2500 kg m^2
    loads = (1450 * 9.81 * 1.62 / 2.7, 1450 * 9.81 * 1.08 / 2.7)
    for name, load in zip(("cornering_stiffness_front", "cornering_stiffness_rear"), loads):
        assert 5 * load < summary["physical_parameters"][name]["value"] < 30 * load
    assert 1250 < summary["physical_parameters"]["yaw_inertia"]["value"] < 5000
    status = main(["identify", str(tmp_path / "sweep.h5"), "--structure", "single-track", "--inputs", "steer",
                   "--schedule", "vx", "--outputs", "yaw_rate", "--vehicle", "baseline", "--quantities", "yaw_rate"])
    assert status == 2 and "no channel 'vx'" in capsys.readouterr().err


def _lateral_record(peak_g: float) -> IOData:
    from vehid.vehicle.single_track import GRAVITY

    t = np.arange(200) * 0.01
    ay = peak_g * GRAVITY * np.sin(2 * np.pi * t)  # reaches its peak within the record (t = 0.25 s)
    return IOData(t=t, u=np.column_stack([0.01 * np.sin(2 * np.pi * t), np.full_like(t, 20.0)]),
                  y=np.column_stack([ay / 20.0, ay]))


@pytest.mark.parametrize(("friction", "peak_estimation", "peak_validation", "expected"), [
    (1.2, 0.9, 1.0, ()),  # both parts within the friction limit mu g: nothing to say
    (1.2, 0.9, 1.4, ("validation part reaches 1.40 g",)),  # held-out cornering beyond mu g: extrapolated
    (0.5, 0.9, 0.4, ("below the 0.90 g",)),  # the estimate contradicts its own data
])
def test_friction_below_the_logged_cornering_is_named(friction, peak_estimation, peak_validation, expected):
    from vehid.scenarios.single_track_identify import _friction_warnings

    # the saturating axles bound the model's lateral acceleration by mu g (static loads, |tanh| < 1):
    # a log cornering beyond that cannot be reproduced, and the warning must say which part does
    config = SingleTrackConfig(1500.0, 1.2, 1.5, saturation=True)
    parameters = np.array([60e3, 60e3, 1500.0, friction])
    warnings = _friction_warnings(config, parameters, _lateral_record(peak_estimation),
                                  _lateral_record(peak_validation))
    assert len(warnings) == len(expected)
    for warning, text in zip(warnings, expected):
        assert text in warning and f"{friction:.2f}" in warning


def test_saved_model_gives_its_handling_and_page(log, tmp_path, capsys):
    """`--save-model` keeps the identified single-track model; `vehid handling` reads it as a model over
    speed (the log's speeds by default, its own wheelbase) and its metrics, from the model linearised at
    each speed, are the closed forms the identification reports: the understeer gradient within 1e-3
    (measured 4e-4 at 10 m/s: the model's speed is sqrt(v^2 + 0.1^2), a shift of 5e-5 that the difference
    ``1 - L r / (v delta)`` magnifies) and its std, central differences against exact derivatives, within 2 %."""
    model_file, figure = tmp_path / "car.json", tmp_path / "handling.png"
    assert main(["identify", str(log), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                 "--outputs", "yawRate,ayCG", "--scale", f"yawRate={DEG!r}", *GEOMETRY, "--json", "--quiet",
                 "--save-model", str(model_file)]) == 0
    identified = json.loads(capsys.readouterr().out)
    assert identified["model_file"] == str(model_file)
    # a file the workbench wrote is its own to replace: a rerun with the same --save-model was refused as "not a
    # workbench model file"
    from vehid.identification.dataio.model_files import check_model_target

    assert check_model_target(model_file) == model_file
    assert main(["handling", str(model_file), "--figure", str(figure), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["scheduled"] is True and summary["wheelbase"] == pytest.approx(2.7)
    low, high = identified["speed_range_m_s"]
    speeds = [row["speed"] for row in summary["metrics"]]
    assert len(speeds) == 3 and low <= speeds[0] < speeds[1] < speeds[2] <= high
    reported = identified["handling"]["understeer_gradient_deg_per_g"]
    for row in summary["metrics"]:
        assert row["understeer_gradient_deg_per_g"]["value"] == pytest.approx(reported["value"], rel=1e-3)
        assert row["understeer_gradient_deg_per_g"]["std"] == pytest.approx(reported["std"], rel=0.02)
    assert summary["warnings"] == [] and figure.stat().st_size > 0
    # the handling numbers' standard deviations come from the covariance identify measured, and say so
    assert summary["uncertainty_method"] == identified["uncertainty_method"]
    assert summary["uncertainty_method"]["name"] == "block-jackknife"
    # the model file is JSON only
    assert main(["identify", str(log), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                 "--outputs", "yawRate,ayCG", *GEOMETRY, "--save-model", str(tmp_path / "car.mat")]) == 2
    assert "saved as .json" in capsys.readouterr().err


def test_a_car_that_changes_halfway_is_named_and_a_steady_one_is_not(log, tmp_path, capsys):
    """The log's parts are identified one by one (JSON ``segments``): a car whose front axle loses 40 % of its
    cornering stiffness halfway through an 80 s log (a tyre change, say) has its four 20 s parts disagree, and
    one warning says that the model does not hold over the whole log; the steady car of the other tests has
    its parts agree (its run above has no warning).

    Both halves are simulated over the whole log and joined at 40 s (the join's transient lasts some 0.2 s).
    With 3 % noise the parts' front stiffnesses (80 and 48 kN/rad) lie more than 50 of their stds apart
    (measured: 0.06-0.5 kN/rad), so every pair across the change disagrees: 2 of 6 pairs agree; the rear
    stiffness and the yaw inertia, unchanged, agree in 6 of 6."""
    rng = np.random.default_rng(8)
    record, (before, after) = _drive(rng, 8000, list(TRUTH.values()), [48_000.0, *list(TRUTH.values())[1:]])
    y = np.where((record.t < 40.0)[:, None], before, after)
    y += 0.03 * np.std(y, axis=0) * rng.standard_normal(y.shape)
    path = tmp_path / "changing.csv"
    np.savetxt(path, np.column_stack([record.t, record.u, y]), delimiter=",", header="t,delta,vx,yawRate,ayCG",
               comments="")
    assert main(["identify", str(path), "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                 "--outputs", "yawRate,ayCG", *GEOMETRY, "--json"]) == 0
    captured = capsys.readouterr()
    segments = json.loads(captured.out)["segments"]
    assert [(part["start_s"], part["end_s"]) for part in segments["parts"]] == [
        (pytest.approx(20.0 * i), pytest.approx(20.0 * (i + 1))) for i in range(4)]
    front = segments["agreement"]["cornering_stiffness_front"]
    assert front["agreeing"] == 2 and not front["holds"] and not segments["consistent"]
    assert segments["agreement"]["cornering_stiffness_rear"]["holds"] and segments["agreement"]["yaw_inertia"]["holds"]
    assert segments["uncertainty_method"]["name"] == "block-jackknife"
    warnings = [line for line in captured.err.splitlines() if "does not hold over the whole log" in line]
    assert len(warnings) == 1 and "front cornering stiffness" in warnings[0] and "across 4 parts" in warnings[0]
