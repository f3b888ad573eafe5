"""The single-track structure on a real race car's log (tests/data/race_car_250lm, see its SOURCE.md).

The car's mass and geometry are not published: the tests assume 1100 kg and 1.2 m from the centre
of gravity to each axle. The understeer gradient and the characteristic speed depend on the
cornering stiffnesses per unit mass and on the axle distances only, so the assumed mass does not
move them; the assertions are physical properties, not figures measured on one machine.
"""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import run_vehid

LOG = Path(__file__).parent / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
MASS, LF, LR = 1100.0, 1.2, 1.2


def _single_track(*outputs_and_quantities: str, extra: tuple[str, ...] = ()) -> dict:
    outputs, quantities = outputs_and_quantities
    completed = run_vehid(
        "identify", LOG, "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
        "--outputs", outputs, "--quantities", quantities, "--mass", MASS, "--lf", LF, "--lr", LR,
        "--validation", "0.4", "--json", *extra)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout)


@pytest.fixture(scope="module")
def yaw_and_lateral():
    return _single_track("yawRate,ayCG", "yaw_rate,lateral_acceleration")


@pytest.fixture(scope="module")
def with_sideslip():
    return _single_track("yawRate,ayCG,beta_true", "yaw_rate,lateral_acceleration,sideslip")


def test_physical_parameters_are_plausible_with_honest_std(yaw_and_lateral):
    parameters = yaw_and_lateral["physical_parameters"]
    for name in ("cornering_stiffness_front", "cornering_stiffness_rear", "yaw_inertia"):
        entry = parameters[name]
        # a stiffness or an inertia is positive, and a std larger than the value would say nothing
        assert entry["value"] > 0 and 0 < entry["std"] < entry["value"] and np.isfinite(entry["std"]), name
    # a car's yaw inertia is near m l_f l_r (its dynamic index near 1; cars lie within about 0.7-1.3):
    # a factor of three either way only rejects a parameter that has left physics
    index = parameters["yaw_inertia"]["value"] / (MASS * LF * LR)
    assert 1 / 3 < index < 3
    gradient = yaw_and_lateral["handling"]["understeer_gradient_deg_per_g"]
    # race cars are set up close to neutral, mildly understeering; no car is 10 deg/g either way
    assert -10 < gradient["value"] < 10 and 0 < gradient["std"] < abs(gradient["value"])


def test_held_out_lap_is_explained_better_than_by_its_mean(yaw_and_lateral):
    # a physical model of the car's lateral dynamics must explain more than each output's mean on the held-out
    # 40 % of the lap (NRMSE fit > 0); measured 68 / 71 %
    assert all(fit > 0 for fit in yaw_and_lateral["validation_fit_percent"])


def test_a_measured_sideslip_tightens_every_parameter(yaw_and_lateral, with_sideslip):
    # a further independent measurement of the same states can only add information: each std shrinks
    # (measured on this log: by factors of 1.5 for the yaw inertia to 10 for the rear stiffness)
    for name, entry in yaw_and_lateral["physical_parameters"].items():
        assert with_sideslip["physical_parameters"][name]["std"] < entry["std"], name
    assert all(fit > 0 for fit in with_sideslip["validation_fit_percent"])


def test_saturating_axles_that_cannot_reach_the_logged_cornering_say_so():
    # the lap's held-out 40 % corners to 1.38 g (a third of it beyond 0.9 g) while the estimation part
    # reaches 1.05 g: the friction is at best bounded from below by the estimation part, and the
    # filter's estimate (measured 0.96) caps the simulated response below the held-out cornering, so
    # the hold-out fit falls far below the linear axles' (measured -22 / -12 % against 68 / 71 %).
    # Whatever the estimate, a fit below the linear model's must come with a warning that says why.
    summary = _single_track("yawRate,ayCG", "yaw_rate,lateral_acceleration", extra=("--saturation",))
    friction = summary["physical_parameters"]["axle_friction"]["value"]
    data = np.genfromtxt(LOG, delimiter=",", skip_header=2)
    held_out_peak = np.max(np.abs(data[int(round(0.6 * len(data))):, 4])) / 9.81  # g as the single-track model takes it
    if friction < held_out_peak:
        assert any("friction is extrapolated" in warning for warning in summary["warnings"])
    if min(summary["validation_fit_percent"]) < 0:
        assert any("axle_friction" in warning for warning in summary["warnings"])


def _modal(*options: str) -> dict:
    completed = run_vehid("identify", LOG, "--inputs", "delta", "--outputs", "yawRate,ayCG", "--validation", "0.4",
                          "--json", *options)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout)


@pytest.fixture(scope="module")
def default_and_scheduled():
    # both at the command's default order (4): the comparison below is of the scheduling alone
    return _modal(), _modal("--schedule", "vx")


@pytest.mark.slow  # the two identifications take about half a minute of one core
def test_default_and_scheduled_paths_explain_the_held_out_lap(default_and_scheduled):
    # hold-out NRMSE fit (yaw rate, lateral acceleration) measured with the hold-out fraction moved over
    # 0.35 / 0.40 / 0.45 and the data perturbed at 1e-9 relative: default 68.9-71.1 / 62.2-63.4 %,
    # scheduled 70.6-76.1 / 69.1-74.3 % (the perturbation alone moved the scheduled yaw rate by 2.0
    # points at 0.45). Floors sit below the lowest, beyond that spread and the difference between
    # machines seen so far (1.6 points on the scheduled yaw rate)
    default, scheduled = default_and_scheduled
    assert np.all(np.asarray(default["validation_fit_percent"]) > [63.0, 58.0])
    assert np.all(np.asarray(scheduled["validation_fit_percent"]) > [66.0, 66.0])


@pytest.mark.slow  # the two identifications take about half a minute of one core
def test_speed_scheduling_explains_the_lateral_acceleration_better(default_and_scheduled):
    # the lateral-acceleration gain of a car grows with the square of speed below the characteristic
    # speed, so a model that follows speed must explain it better than one that cannot: measured 6.9-11.7
    # points ahead over the perturbations above; asserted 3 points ahead. (On the yaw rate the lead was
    # -0.5 to 5.8 points, within the spread, and is not asserted.)
    default, scheduled = default_and_scheduled
    assert scheduled["validation_fit_percent"][1] > default["validation_fit_percent"][1] + 3.0
