"""Acceptance on the 23-state source model driven along a speed ramp, against the car's own truth.

* The handling function's steady state over a range of lateral acceleration (ISO 4138, constant speed,
  steer steps) against its closed forms: the linearisation's values as the range shrinks, and the
  kinematics of a steady turn, ``a_y = V r``.
* The single-track understeer gradient and characteristic speed identified from a quasi-steady drive
  (slow steer along a slow ramp) against the car's own steady state over the lateral acceleration the
  drive reaches, at the ramp's ends and middle.
* The speed-scheduled model's modes against models identified at fixed speeds and the linearisation.

The records and identifications are those of ``benchmarks/source_acceptance.py`` (loaded here), which
measures the same figures over steer seeds 0-2; the tolerances below sit above that spread.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import load_benchmark_module

from vehid.identification.errors import InputError
from vehid.vehicle import baseline
from vehid.vehicle.handling import source_handling, source_steady_state


acceptance = load_benchmark_module("source_acceptance")
SPEEDS = (10.0, 30.0)


@pytest.fixture(scope="module")
def linearisation():
    return {m.speed: m for m in source_handling(baseline(), SPEEDS, simulate=False).linearisation}


# --- the steady state against its closed forms ---------------------------------------------------

def test_steady_state_tends_to_the_linearisation(linearisation):
    """Over +/-0.05 m/s^2 the steady states are the linearisation's (itself the bicycle closed form,
    tests/test_vehicle_handling.py): gains, understeer gradient and characteristic speed within 1e-4
    relative. Measured 2e-5: the nonlinearity grows as the square of the range (1 % at 1 m/s^2), so
    (0.05)^2 of it is 2.5e-5."""
    for steady in source_steady_state(baseline(), SPEEDS, lateral_acceleration=0.05):
        linear = linearisation[steady.speed]
        for name in ("yaw_rate_gain", "lateral_acceleration_gain", "understeer_gradient_deg_per_g",
                     "characteristic_speed_m_s"):
            assert getattr(steady, name) == pytest.approx(getattr(linear, name), rel=1e-4), name
        assert math.isnan(steady.critical_speed_m_s)


def test_steady_states_are_steady_turns_and_reach_the_stated_range():
    """Each steady state is a steady turn: ``a_y = V r`` within 2e-3 (measured 6e-4 at 4 m/s^2: the
    road-plane acceleration is the body's tilted by the roll angle, cos(2 deg) = 1 - 6e-4). The steps
    are sized by the linear gain, so the largest reaches the stated range to within the nonlinearity
    (measured 0.8-7 % short at 4 m/s^2, the tyres saturating) and never beyond it. The understeer
    gradient grows with the range, the front axle saturating first (a property of the baseline car:
    0.70, 0.71, 0.79-0.82 deg/g over 1, 2, 4 m/s^2)."""
    by_range = {level: source_steady_state(baseline(), SPEEDS, lateral_acceleration=level)
                for level in (1.0, 2.0, 4.0)}
    for level, states in by_range.items():
        for steady in states:
            lateral, yaw = np.array(steady.lateral_acceleration_values), np.array(steady.yaw_rate)
            np.testing.assert_allclose(lateral, steady.speed * yaw, rtol=2e-3)
            assert level * 0.85 < np.max(np.abs(lateral)) <= level * (1 + 1e-9)
            np.testing.assert_allclose(lateral[::-1], -lateral, rtol=1e-9)  # a symmetric car
    for index in range(len(SPEEDS)):
        gradients = [by_range[level][index].understeer_gradient_deg_per_g for level in (1.0, 2.0, 4.0)]
        assert gradients == sorted(gradients) and gradients[-1] > 1.1 * gradients[0]


@pytest.mark.parametrize("level", [0.0, -1.0, math.nan, math.inf])
def test_steady_state_refuses_a_range_that_is_not_one(level):
    with pytest.raises(InputError, match="lateral acceleration must be positive"):
        source_steady_state(baseline(), 20.0, lateral_acceleration=level)


def test_handling_command_gives_the_steady_state_and_names_saturation(capsys):
    """`vehid handling --source --steady-range A` reports the function's steady states; a range beyond
    the car's steady cornering (9 m/s^2: the baseline reaches 6.3 at 30 m/s) is named as a warning
    (exit 3 under --strict), a range that is not one is bad input (exit 2)."""
    from vehid.scenarios.cli import main

    assert main(["handling", "--source", "--speeds", "30", "--no-simulation", "--steady-range", "1.5", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    (entry,) = summary["steady_state"]
    (direct,) = source_steady_state(baseline(), 30.0, lateral_acceleration=1.5)
    assert entry["understeer_gradient_deg_per_g"] == pytest.approx(direct.understeer_gradient_deg_per_g, rel=1e-12)
    assert entry["reached_lateral_acceleration"] == pytest.approx(direct.reached_lateral_acceleration, rel=1e-12)
    assert summary["warnings"] == []
    argv = ["handling", "--source", "--speeds", "30", "--no-simulation", "--steady-range", "9"]
    assert main([*argv, "--strict"]) == 3
    assert "the tyres saturate" in capsys.readouterr().err
    assert main(["handling", "--source", "--steady-range", "0"]) == 2
    assert "--steady-range must be a positive" in capsys.readouterr().err


# --- single-track handling from a quasi-steady drive -------------------------------------------

@pytest.fixture(scope="module")
def single_track():
    return acceptance.single_track_case(0)


def test_single_track_handling_is_the_cars_steady_state(single_track):
    """The understeer gradient and characteristic speed of the single-track model identified on the
    quasi-steady ramp (240 s, 10-35 m/s, steer 0-0.5 Hz) agree with the car's steady state over the
    lateral acceleration the record reaches, at 10, 22.5 and 35 m/s, within the acceptance's 5 %.
    Measured over seeds 0-2: K -0.8 to +0.5 %, v_char -0.3 to +0.4 %. The reported std (3e-4 deg/g)
    says how closely the record fixes the parameters within the model, not how far the model's
    structure is from the car, so it is not the tolerance.

    A faster ramp is not a quasi-steady drive: accelerating, the car moves load to its rear axle and
    drives through its tyres, and the single-track model takes that into its stiffnesses: K +7.4 % on
    the 60 s ramp (0.54 m/s^2), +3.9 % on 120 s (benchmarks/source_acceptance.py)."""
    assert single_track["peak_lateral_acceleration"] < 2.0  # the linear range the reference is taken over
    for speed, (gradient, characteristic) in single_track["reference"].items():
        assert single_track["understeer_gradient_deg_per_g"] == pytest.approx(gradient, rel=0.05), speed
        assert single_track["characteristic_speed_m_s"] == pytest.approx(characteristic, rel=0.05), speed
    # the yaw inertia of a car without a roll-yaw product of inertia is its own: 10 % (measured 1.0-1.3 %)
    assert single_track["yaw_inertia"] == pytest.approx(baseline().chassis.yaw_inertia, rel=0.10)


# --- modes against speed ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def modes():
    return acceptance.scheduled_case(0)


def _log_distance(a: float, b: float) -> float:
    return abs(math.log(a / b))


def test_scheduled_modes_follow_the_speed(modes):
    """The scheduled family's yaw mode, identified on the 60 s ramp (0.54 m/s^2, 10-35 m/s), against
    second-order models identified by the same filter at 10, 20 and 30 m/s and the linearisation.

    Measured over seeds 0-2 (scheduled | fixed | linearisation, Hz): 10 m/s 2.71-2.94 | 2.75-2.87 |
    3.41; 20 m/s 1.23 | 1.24-1.25 | (2.14, damping 0.98); 30 m/s 0.88-0.89 | 0.87 | 1.00.

    * Scheduled against fixed speed, like for like (the same structure and filter): 10 % at every
      speed (measured -1.7 to +2.9 %, the seeds' spread of that difference 4.3 points at 10 m/s).
    * Against the linearisation, where its pair is a visible resonance (damping 0.76 at 10 m/s, 0.80
      at 30; at 20 m/s it is damped 0.98 and its residues cancel against a real pole at 6.6 Hz, so
      there is no mode there to compare): the order-2 models are compromises between two visible
      pairs (3.4 Hz in yaw rate, 4.8 Hz in lateral acceleration at 10 m/s), the fixed-speed ones as
      the scheduled: both within 25 % in frequency (measured 11-21 % scheduled, 13-19 % fixed) and
      0.15 in damping (measured 0.03-0.05 scheduled, 0.02-0.11 fixed).
    * Each scheduled mode is nearest the fixed-speed model of its own speed.
    """
    scheduled, fixed, linear = modes["scheduled"], modes["fixed"], modes["linearisation"]
    for speed in (10.0, 30.0):
        assert linear[speed][1] < 0.9  # a resonance visible at the outputs
        for family in (scheduled, fixed):
            assert family[speed][0] == pytest.approx(linear[speed][0], rel=0.25), speed
            assert family[speed][1] == pytest.approx(linear[speed][1], abs=0.15), speed
    assert linear[20.0][1] > 0.9
    for speed in acceptance.MODE_SPEEDS:
        assert scheduled[speed][0] == pytest.approx(fixed[speed][0], rel=0.10), speed
    for speed, (frequency, _) in scheduled.items():
        others = [fixed[v][0] for v in fixed if v != speed]
        assert all(_log_distance(frequency, fixed[speed][0]) < _log_distance(frequency, f) for f in others), speed
    # the property the schedule exists for: the yaw mode slows with speed, in the family as at fixed speeds
    for family in (scheduled, fixed):
        frequencies = [family[v][0] for v in acceptance.MODE_SPEEDS]
        assert frequencies == sorted(frequencies, reverse=True)


def test_scheduled_damping_agrees_with_the_fixed_speed_models(modes):
    """The acceptance's damping: the scheduled mode within 0.1 of the fixed-speed model at each speed.

    Measured over seeds 0-2 (scheduled - fixed): +0.060 to +0.074 at 10 m/s, -0.047 to -0.039 at 20,
    -0.060 to -0.047 at 30; the seeds move each difference by at most 0.014, so 0.1 sits above the
    largest by about twice that spread. The differences are systematic, not noise: the ramp holds each
    speed for a few seconds while the car accelerates, the fixed-speed record for 20 s at constant speed.
    Each knot starts from a linear estimate of the samples near it (identify_scheduled's local starts);
    started from the unscheduled model of the whole ramp (one mode of 2.1 Hz damped 0.998, a compromise
    over the speeds) the family stayed near critical damping (0.96-1.00) and fitted the ramp worse."""
    for speed in acceptance.MODE_SPEEDS:
        assert modes["scheduled"][speed][1] == pytest.approx(modes["fixed"][speed][1], abs=0.1), speed
