"""The vehicle stays in its valid range or says so: up-front checks, the run-time envelope, memory.

Each case of the issue is reproduced here: a 3 m CG height rolled to 619 deg,
0.1 m/s slid at 90 deg of sideslip, 80 m/s spun the car, 60 m/s at 100 Hz
reached 3e49 - all with exit status 0 - and a 1e6 s record ran out of memory
after the work had started.
"""

import dataclasses
import json
import math
import time

import numpy as np
import pytest

from vehid.identification.data import read_hdf5
from vehid.identification.errors import InputError, WorkbenchError
from vehid.vehicle import baseline, build_vehicle_model, simulate
from vehid.vehicle.manoeuvres import identification, step
from conftest import run_vehid


def _cli(argv):
    done = run_vehid(*argv, "--json")
    return done.returncode, json.loads(done.stdout), done.stderr


def _vehicle_file(tmp_path, text):
    path = tmp_path / "vehid.vehicle.toml"
    path.write_text('base = "baseline"\n' + text)
    return str(path)


# --- up front: bad vehicles and speeds are input errors (exit 2), before any work -------------------

def test_a_vehicle_that_tips_before_it_slides_is_rejected(tmp_path):
    """3 m CG height on a 1.52 m track: t / (2 h) = 0.25 g, far below the tyres' friction (0.89)."""
    status, body, err = _cli(["simulate", "--vehicle", _vehicle_file(tmp_path, "[chassis]\ncg_height = 3.0\n")])
    assert status == 2 and body["exit_status"] == 2
    assert "tip over" in body["error"] and "0.253" in body["error"]
    assert len(err.strip().splitlines()) == 1


def test_a_vehicle_unstable_in_roll_is_rejected():
    """No springs' worth of roll stiffness against m g h: the body falls over at rest."""
    base = baseline()
    soft = dataclasses.replace(base.suspension, front_wheel_rate=1000.0, rear_wheel_rate=1000.0,
                               front_anti_roll_bar=0.0, rear_anti_roll_bar=0.0)
    with pytest.raises(InputError, match="unstable in roll"):
        dataclasses.replace(base, suspension=soft)


@pytest.mark.parametrize("speed, words", [("0.1", "below the model's valid range"),
                                          ("80", "above the model's valid range")])
def test_speeds_outside_the_valid_range_are_rejected(speed, words):
    """0.1 m/s (slid at 90 deg sideslip) and 80 m/s (spun) exit 2 and name the range 3-50 m/s."""
    status, body, _ = _cli(["simulate", "--speed", speed])
    assert status == 2 and words in body["error"] and "3-50 m/s" in body["error"]


def test_sixty_metres_per_second_at_100_hz_is_refused():
    """The issue's 60 m/s at 100 Hz reached 3e49 and returned without an error."""
    with pytest.raises(InputError, match="above the model's valid range"):
        simulate(baseline(), identification(seed=0, dt=0.01), speed=60.0)


def test_a_step_too_long_for_rk4_is_refused_naming_one_that_works():
    """At 20 m/s the 30 Hz wheel modes (|lambda| = 190 1/s) are unstable under RK4 at 50 Hz."""
    manoeuvre = step(amplitude=math.radians(0.5), duration=2.0, dt=0.02)
    with pytest.raises(InputError, match=r"too long for the RK4 simulator.*use dt <= 0\.01") as caught:
        simulate(baseline(), manoeuvre)
    stable = float(str(caught.value).rsplit("dt <= ", 1)[1].split()[0])
    assert 0.01 < stable < 0.02


def test_rk4_stability_bound_is_the_textbook_one():
    """|R(z)| = 1 where RK4's stability region meets the axes: z = -2.7853 and z = +/-2.8284j
    (Hairer & Wanner, Solving ODEs II, section IV.2), to the digits printed there."""
    from vehid.vehicle.validity import largest_stable_step, rk4_amplification

    assert rk4_amplification(np.array([-2.7853])) == pytest.approx(1.0, abs=1e-4)
    assert rk4_amplification(np.array([2.8284j])) == pytest.approx(1.0, abs=1e-4)
    assert largest_stable_step(np.array([-1.0]), 10.0) == pytest.approx(2.7853, abs=1e-4)


# --- memory is checked before the run -------------------------------------------------------------

def test_a_record_too_large_for_memory_is_refused_before_any_work():
    """1e6 s at 500 Hz is 5e8 samples, some 400 GiB of arrays: refused at once with the estimate."""
    started = time.perf_counter()
    status, body, _ = _cli(["simulate", "--duration", "1e6"])
    assert time.perf_counter() - started < 5.0  # nothing was built or integrated
    assert status == 2 and "GiB" in body["error"] and "available" in body["error"]


def test_memory_estimate_against_the_available_memory(monkeypatch):
    """With 1 MB available a 30 s record (15 001 samples x 35 columns x 8 bytes x 3 copies = 12.6 MB) is refused
    before the model is trimmed."""
    import vehid.vehicle.simulation as simulation
    import vehid.vehicle.validity as validity
    monkeypatch.setattr(validity, "available_memory_bytes", lambda: 1_000_000)
    monkeypatch.setattr(simulation, "build_vehicle_model", lambda *_: pytest.fail("work started"))
    with pytest.raises(InputError, match="0.0117 GiB"):
        simulate(baseline(), np.zeros(15001))
    assert simulation.check_record_memory.__module__ == "vehid.vehicle.simulation"


# --- during the run: the physical envelope --------------------------------------------------------

def test_wheelspin_beyond_the_grip_limit_stops_the_run_with_the_partial_record(tmp_path, monkeypatch):
    """The identification input at 40 m/s asks for more than the tyres can give: the PI hold spins a
    front wheel up (slip ratio past 0.5 at 6.6 s). A failed computation, exit 1, one line, the
    quantity, its value and the time named; the record up to that sample is kept."""
    with pytest.raises(WorkbenchError) as caught:
        simulate(baseline(), identification(seed=0), speed=40.0)
    error = caught.value
    assert error.exit_status == 1
    assert error.quantity == "longitudinal tyre slip" and abs(error.value) > 0.5
    assert "t = 6.602 s" in str(error) and "kappa_f" in str(error)
    partial = error.partial
    assert partial.meta["partial"] is True and partial.n_samples == 3302
    assert partial.t[-1] == pytest.approx(error.time)
    kappa = np.abs(partial.x[:, [partial.state_names.index(f"kappa_{c}") for c in ("fl", "fr", "rl", "rr")]])
    assert np.max(kappa[:-1]) <= 0.5 < np.max(kappa[-1])  # it ends at the first sample outside
    monkeypatch.chdir(tmp_path)  # a relative --out is taken from the working directory
    status, body, err = _cli(["simulate", "--speed", "40", "--out", "spin.h5"])
    assert status == 1 and body["exit_status"] == 1 and "longitudinal tyre slip" in body["error"]
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "3302 samples" in body["error"] and read_hdf5(tmp_path / "spin.h5").n_samples == 3302


def test_excessive_roll_stops_the_run():
    """A tall car on soft springs without bars (legal: t / 2h = 1.01, K_phi = 2.7 m g h) rolls
    m h / (K_phi - m g h) = 35 deg/g: past the 15 deg limit well inside the grip limit."""
    base = baseline()
    params = dataclasses.replace(
        base,
        chassis=dataclasses.replace(base.chassis, cg_height=0.75),
        suspension=dataclasses.replace(base.suspension, front_wheel_rate=12000.0, rear_wheel_rate=12000.0,
                                       front_anti_roll_bar=0.0, rear_anti_roll_bar=0.0),
    )
    with pytest.raises(WorkbenchError, match="roll angle") as caught:
        simulate(params, step(amplitude=math.radians(3.0), duration=3.0))
    assert math.degrees(abs(caught.value.value)) > 15.0
    assert caught.value.partial.n_samples > 250  # the step starts at 0.5 s


def test_an_exploding_integration_is_stopped(monkeypatch):
    """The issue's 60 m/s at 100 Hz with both up-front checks (speed range, RK4 step) switched off:
    the integration explodes (it reached 3e49), and the envelope stops it at the first sample
    outside (a wheel's slip ratio, 0.75 s in), keeping only finite values before it."""
    import vehid.vehicle.model as model
    import vehid.vehicle.simulation as simulation
    monkeypatch.setattr(simulation, "check_rk4_step", lambda *_: None)
    monkeypatch.setattr(model, "check_speed_range", lambda speed: speed)
    manoeuvre = identification(seed=0, dt=0.01)
    with pytest.raises(WorkbenchError, match="left its valid envelope") as caught:
        simulate(baseline(), manoeuvre, speed=60.0)
    partial = caught.value.partial
    assert caught.value.time < 2.0 and partial.n_samples < manoeuvre.n_samples
    assert np.all(np.isfinite(partial.x)) and np.max(np.abs(partial.x[:, :9])) < 1e3


def test_envelope_scan_names_the_first_sample_and_prefers_non_finite():
    from vehid.vehicle.validity import first_violation

    model = build_vehicle_model(baseline())
    states = np.tile(model.trim(20.0), (6, 1))
    outputs = np.tile(np.asarray(model.outputs(states[0], 0.0, 20.0)).ravel(), (6, 1))
    assert first_violation(states, model.state_names, outputs, model.output_names, 20.0) is None
    exploded = states.copy()
    exploded[4, model.state_index("w")] = 3e49
    exploded[5, model.state_index("v")] = np.nan
    found = first_violation(exploded, model.state_names, outputs, model.output_names, 20.0, state_offset=10)
    assert (found.quantity, found.sample, found.column) == ("state magnitude", 14, "w")
    exploded[4, model.state_index("u")] = np.inf
    found = first_violation(exploded, model.state_names, outputs, model.output_names, 20.0)
    assert (found.quantity, found.sample) == ("non-finite value", 4)
    slow = outputs.copy()
    slow[2, model.output_index("speed")] = 15.0  # 25 % below the reference
    found = first_violation(states, model.state_names, slow, model.output_names, 20.0)
    assert (found.quantity, found.sample) == ("speed departure", 2) and found.value == pytest.approx(-0.25)


def test_the_default_manoeuvres_stay_inside_the_envelope():
    """The study's records (identification, validation, the ramp past the grip limit) are valid runs."""
    from vehid.vehicle.manoeuvres import ramp, validation

    for manoeuvre in (identification(seed=0), validation(seed=0), ramp()):
        assert simulate(baseline(), manoeuvre).n_samples == manoeuvre.n_samples
