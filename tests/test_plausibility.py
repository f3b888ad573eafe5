"""Physical plausibility (vehid.vehicle.plausibility): each defect of a model that is not a car is first
reproduced (on the committed race-car log, or a textbook single-track car whose knots are given the
defects identified models showed), then named with its quantity, speed, range and likely cause; the
committed log read correctly raises no false alarm on the checks whose ranges it meets.

The race car's published values (mass 982 kg, CG to axles 1.33 and 1.07 m) come with its record
(tests/data/race_car_250lm/SOURCE.md names the source).
"""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.data import IOData
from vehid.identification.filtering.greybox_structure import simulate_greybox
from vehid.identification.filtering.scheduled_iekf import default_grid, knot_cells, knot_coverage
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.scheduled import schedule_models
from vehid.identification.models.statespace import to_modal
from vehid.scenarios import plausibility_checks
from vehid.scenarios.scheduled_identify import text_lines
from vehid.vehicle.plausibility import RANGES, sideslip_findings, single_track_findings, steer_band_hz
from vehid.vehicle.single_track import SingleTrackConfig, single_track_model

LOG = Path(__file__).parent / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
MASS, LF, LR = 982.0, 1.33, 1.07
CAR = SingleTrackConfig(MASS, LF, LR)
KEYS = {"quantity", "value", "range", "speed", "cause"}


def _single_track(*extra: str) -> dict:
    completed = run_vehid("identify", LOG, "--structure", "single-track", "--inputs", "delta", "--schedule", "vx",
                          "--outputs", "yawRate,ayCG", "--mass", MASS, "--lf", LF, "--lr", LR,
                          "--measured-sideslip", "beta_true", "--json", "--quiet", *extra)
    assert completed.returncode == 0, completed.stderr
    return json.loads(completed.stdout)


@pytest.fixture(scope="module")
def healthy():
    """The committed log read as it is: road-wheel angle (rad), the car's mass and axle distances."""
    return _single_track()


@pytest.fixture(scope="module")
def steering_wheel():
    """The same log with the steer 15 times larger: a steering-wheel angle given as the road-wheel angle."""
    return _single_track("--scale", "delta=15")


def _by_quantity(summary: dict) -> dict[str, list[dict]]:
    found: dict[str, list[dict]] = {}
    for entry in summary["plausibility"]:
        assert set(entry) == KEYS
        found.setdefault(entry["quantity"], []).append(entry)
    return found


def _warned(summary: dict, quantity: str) -> bool:
    return any(warning.startswith(f"implausible {quantity}") for warning in summary["warnings"])


def test_the_committed_log_read_correctly_raises_only_its_high_speed_overshoot(healthy):
    """Its values, computed here from the JSON, lie within every range of the parameters (measured: C / F_z
    8.9 and 12.9 /rad, dynamic index 0.76, understeer gradient 2.0 deg/g, predicted sideslip correlating
    0.97 with the measured), and none of those checks fires. The one finding is the linear model's yaw
    overshoot above its characteristic speed (measured 109 % at 60 m/s), a transient beyond the speeds
    of ISO 7401's road cars: named at such speeds only."""
    found = _by_quantity(healthy)
    parameters = {name: entry["value"] for name, entry in healthy["physical_parameters"].items()}
    load_front, load_rear = CAR.axle_loads
    assert RANGES["normalised_cornering_stiffness_per_rad"].contains(parameters["cornering_stiffness_front"] / load_front)
    assert RANGES["normalised_cornering_stiffness_per_rad"].contains(parameters["cornering_stiffness_rear"] / load_rear)
    assert RANGES["dynamic_index"].contains(parameters["yaw_inertia"] / (MASS * LF * LR))
    assert RANGES["understeer_gradient_deg_per_g"].contains(healthy["handling"]["understeer_gradient_deg_per_g"]["value"])
    assert set(found) <= {"yaw_rate_overshoot"}
    characteristic = healthy["handling"]["characteristic_speed_m_s"]["value"]
    for entry in found.get("yaw_rate_overshoot", []):
        assert entry["speed"] > characteristic and entry["value"] > 0.5 and "characteristic speed" in entry["cause"]
        assert _warned(healthy, "yaw_rate_overshoot")


def test_a_steering_wheel_angle_is_named_by_the_front_axle(steering_wheel):
    """The steer only enters the front slip angle, so a steer 15 times too large leaves the front axle 15
    times too soft (measured C_f / F_z 0.71 /rad; a race car's road-course logs gave below 1 /rad, where
    road tyres have 5-20) and the rear as it was. The finding names the steering ratio; the understeer
    gradient (measured 77 deg/g), which does not depend on speed in this model, is named once and without
    a speed; the yaw inertia follows."""
    found = _by_quantity(steering_wheel)
    stiffness = steering_wheel["physical_parameters"]["cornering_stiffness_front"]["value"]
    (front,) = found["normalised_cornering_stiffness_front_per_rad"]
    assert front["value"] == pytest.approx(stiffness / CAR.axle_loads[0], rel=1e-9) and front["value"] < 1.0
    assert front["range"] == [2.0, 40.0] and front["speed"] is None and "--steering-ratio" in front["cause"]
    assert "normalised_cornering_stiffness_rear_per_rad" not in found
    (gradient,) = found["understeer_gradient_deg_per_g"]
    assert gradient["speed"] is None and gradient["value"] > 6.0 and "steering-wheel angle" in gradient["cause"]
    (index,) = found["dynamic_index"]
    assert index["value"] > 1.5 and "front axle" in index["cause"]
    assert _warned(steering_wheel, "normalised_cornering_stiffness_front_per_rad")
    # the soft front axle lowers the characteristic speed to 4 m/s: the yaw rate overshoots 175 % at the log's
    # top speed, as the race car's default knots did at 10 m/s; named there (asserted above 100 %)
    top = max(found["yaw_rate_overshoot"], key=lambda entry: entry["speed"])
    assert top["speed"] == pytest.approx(steering_wheel["speed_range_m_s"][1], rel=0.01) and top["value"] > 1.0


def test_a_sideslip_sensor_of_the_other_sign_is_named():
    """The committed log's sideslip flipped, as a sensor of the other sign convention gives it: the model's
    prediction (measured correlation 0.97 with the log's own sign) runs opposite to it."""
    summary = _single_track("--scale", "beta_true=-1")
    (entry,) = _by_quantity(summary)["sideslip_correlation"]
    assert entry["value"] < -0.8 and "sign convention" in entry["cause"]


def _simulated_sideslip(config: SingleTrackConfig, parameters: list[float], data: np.ndarray) -> np.ndarray:
    t, steer, speed = data[:, 0], data[:, 1], data[:, 2]
    record = IOData(t=t - t[0], u=np.column_stack([steer, speed]), y=np.zeros((t.size, 1)))
    predicted, _ = simulate_greybox(single_track_model(dataclasses.replace(config, quantities=("sideslip",))),
                                    parameters, record, substeps=2)
    return predicted[:, 0]


def test_axles_a_saturating_fit_leaves_undetermined_are_named():
    """`--saturation` on the 550 s drive of the committed log's car returned C_f 149 and C_r 789 kN/rad,
    I_z 1959 kg m^2 and an axle friction of 1.05, whose predicted sideslip correlated -0.52 with the
    measured (the drive is not committed; its estimate is). On the committed lap that model's yaw rate
    still follows the log (it is asserted here, above 0.9), but its huge rear stiffness keeps its sideslip
    positive in a left turn where the car's is negative beyond about 12 m/s: the correlation is negative
    (measured -0.49). Both the rear axle (148 /rad) and the sideslip are named."""
    parameters = [148_647.0, 789_022.0, 1_958.7, 1.0485]
    saturating = dataclasses.replace(CAR, saturation=True)
    data = np.genfromtxt(LOG, delimiter=",", skip_header=2)
    record = IOData(t=data[:, 0] - data[0, 0], u=data[:, 1:3], y=np.zeros((len(data), 1)))
    yaw, _ = simulate_greybox(single_track_model(dataclasses.replace(saturating, quantities=("yaw_rate",))),
                              parameters, record, substeps=2)
    assert np.corrcoef(yaw[:, 0], data[:, 3])[0, 1] > 0.9
    (entry,) = sideslip_findings(data[:, 5], _simulated_sideslip(saturating, parameters, data))
    assert entry.quantity == "sideslip_correlation" and entry.value < 0 and "balance" in entry.cause
    rear = [f for f in single_track_findings(saturating, parameters) if "rear" in f.quantity]
    assert len(rear) == 1 and rear[0].value == pytest.approx(789_022.0 / CAR.axle_loads[1], rel=1e-9)
    # the healthy parameters' prediction follows the measured sideslip: nothing to name
    assert sideslip_findings(data[:, 5], _simulated_sideslip(CAR, [38_048.0, 68_781.0, 1_060.6], data)) == ()


# --- a scheduled family with the defects identified families showed -----------------------------------------

WHEELBASE = LF + LR
SPEEDS = (20.0, 30.0, 40.0, 50.0, 56.0)


def _car_at(speed: float) -> ModalModel:
    """The committed log's single-track car, linearised at ``speed``: outputs yaw rate and lateral acceleration."""
    from vehid.vehicle.single_track import IdentifiedSingleTrack

    car = IdentifiedSingleTrack(CAR, [38_048.0, 68_781.0, 1_060.6], None, (15.0, 60.0)).model_at(speed)
    A, B, C, D, _ = car.to_statespace()
    return dataclasses.replace(to_modal(A, B, C, D), input_names=("steer",),
                               output_names=("yaw_rate", "lateral_acceleration"))


def _family(changes: dict[float, dict[str, np.ndarray]]):
    models = {}
    for speed in SPEEDS:
        model = _car_at(speed)
        models[speed] = dataclasses.replace(model, **changes.get(speed, {})) if speed in changes else model
    return schedule_models(models)


def _findings(family, band_hz=None):
    return plausibility_checks.model_findings(family, list(SPEEDS), roles={"yaw_rate": 0, "lateral_acceleration": 1},
                                              wheelbase=WHEELBASE, band_hz=band_hz, top_speed=60.0)


def test_a_healthy_family_raises_nothing_at_the_iso_speeds():
    """The single-track car at each knot: steady turns exact, damped modes, quick yaw response; its yaw
    overshoot exceeds 50 % only from 40 m/s (measured 50.4 %), beyond its characteristic speed (26 m/s)."""
    findings = _findings(_family({}))
    assert {f.quantity for f in findings} <= {"yaw_rate_overshoot"}
    assert all(f.speed >= 40.0 for f in findings)


def test_steady_gains_that_break_a_turns_kinematics_are_named():
    """The scheduled model of the 550 s drive had a steady lateral-acceleration gain of 0.72, 0.40 and 0.28
    times V times its yaw-rate gain at 40, 50 and 56 m/s: given those knots, each is named at its speed
    with its ratio; the exact knots at 20 and 30 m/s are not."""
    factors = {40.0: 0.72, 50.0: 0.40, 56.0: 0.28}
    changes = {}
    for speed, factor in factors.items():
        model = _car_at(speed)
        changes[speed] = {"C": model.C * [[1.0], [factor]], "D": model.D * [[1.0], [factor]]}
    kinematic = [f for f in _findings(_family(changes)) if f.quantity == "steady_turn_kinematic_ratio"]
    # the model's speed is sqrt(v^2 + 0.1^2) (a floor at standstill): the exact ratio is 1 + 3e-6 at 40 m/s
    assert {f.speed: f.value for f in kinematic} == pytest.approx(factors, rel=1e-5)
    assert all(f.range == (0.85, 1.15) for f in kinematic)


def test_a_yaw_rate_that_answers_the_steer_at_once_is_named():
    """A knot whose yaw rate has a direct feed-through of 20 times its dynamic part's steady gain (the
    scheduled model's response time of "0 +/- 0 s" at 20 m/s): at once 20/21 of the steady yaw rate, beyond
    the 90 % of the response time, which is 0, named as a feed-through."""
    model = _car_at(20.0)
    steady = float(-(model.C @ np.linalg.solve(model.A, model.B))[0, 0])
    D = model.D.copy()
    D[0, 0] = 20.0 * steady
    found = [f for f in _findings(_family({20.0: {"D": D}})) if f.quantity == "yaw_rate_response_time_s"]
    assert [f.speed for f in found] == [20.0] and found[0].value == 0.0 and "feed-through" in found[0].cause


def test_an_undamped_mode_above_the_steers_band_is_named_as_noise():
    """A 19 Hz mode with damping 0 beside a steer that reaches 3 Hz (the committed log's steer: 2-4 Hz by
    its 40 dB band, measured 2.9 Hz) is noise fitted by the model; a lightly damped 1.5 Hz mode inside the
    band is not a car's."""
    data = np.genfromtxt(LOG, delimiter=",", skip_header=2)
    band = steer_band_hz(data[:, 1], 0.01)
    assert 2.0 < band < 4.0
    car = _car_at(30.0)
    for frequency, damping, where in ((19.0, 0.0, "above"), (1.5, 0.05, "inside")):
        omega = 2 * np.pi * frequency
        pole = complex(-damping * omega, omega * math.sqrt(1 - damping**2))
        block = np.array([[pole.real, pole.imag], [-pole.imag, pole.real]])
        A = np.block([[car.A, np.zeros((2, 2))], [np.zeros((2, 2)), block]])
        model = to_modal(A, np.vstack([car.B, [[1.0], [0.0]]]), np.hstack([car.C, 0.01 * np.ones((2, 2))]), car.D)
        (finding,) = plausibility_checks.model_findings(
            model, [30.0], roles={"yaw_rate": 0}, band_hz=band, top_speed=60.0, speed_known=False,
            metrics=())
        assert finding.quantity == "mode_damping" and finding.value == pytest.approx(damping, abs=1e-9)
        assert f"{frequency:.3g} Hz, {where} the" in finding.cause


# --- knots ----------------------------------------------------------------------------------------------------

def test_default_knots_are_not_crowded_where_the_record_dwells():
    """An oval: 90 % of the samples at 60-62 m/s, the rest spread over 40-60 m/s. Quantiles put three of five
    knots within 1.3 m/s (reproduced here); the default grid keeps every gap at least a quarter of the even
    spacing and every knot on at least 5 % of the samples (the crowded knots merge)."""
    rng = np.random.default_rng(4)
    oval = np.concatenate([rng.uniform(60.0, 62.0, 9000), rng.uniform(40.0, 60.0, 1000)])
    quantiles = np.quantile(oval, np.linspace(0.02, 0.98, 5))
    assert quantiles[3] - quantiles[1] < 1.3
    grid = default_grid(oval, 5)
    even = (grid[-1] - grid[0]) / 4
    assert grid[0] == pytest.approx(quantiles[0]) and grid[-1] == pytest.approx(quantiles[-1])
    assert grid.size < 5 and np.all(np.diff(grid) >= 0.25 * even)
    assert not np.any(grid[2:] - grid[:-2] < 1.3)  # no three knots within 1.3 m/s
    assert min(cell.size for cell in knot_cells(oval, grid)) >= 0.05 * oval.size
    # a track log keeps its quantile knots: the committed log's closest two lie 0.51 of the even spacing apart
    # (where the car is slow and its dynamics change fastest with speed)
    speed = np.genfromtxt(LOG, delimiter=",", skip_header=2)[:, 2]
    assert default_grid(speed, 5) == pytest.approx(np.quantile(speed, np.linspace(0.02, 0.98, 5)))
    # a schedule that dwells at one value keeps two knots, at its 2nd and 98th percentiles
    dwelling = np.concatenate([np.full(900, 12.0), np.linspace(12.0, 40.0, 100)])
    assert default_grid(dwelling, 5) == pytest.approx(np.quantile(dwelling, [0.02, 0.98]))


def test_a_knot_on_a_straight_is_marked_extrapolated(tmp_path, capsys):
    """A knot whose samples hold no steer rests on no data: marked in the family's coverage, in the
    scheduled entry's text, and at the speed `vehid handling` reports nearest it."""
    rng = np.random.default_rng(1)
    dt, n = 0.01, 6000
    speed = np.repeat([20.0, 30.0, 40.0], n // 3)
    steer = 0.02 * rng.standard_normal(n)
    steer[speed == 40.0] = 1e-4 * rng.standard_normal(n // 3)  # a straight at 40 m/s
    record = IOData(t=dt * np.arange(n), u=steer[:, None], y=np.zeros((n, 2)))
    coverage = knot_coverage(record, speed, np.array([20.0, 30.0, 40.0]), _car_at(30.0))
    assert [c.enough for c in coverage] == [True, True, False] and coverage[2].excitation < 0.1
    assert [c.seconds for c in coverage] == pytest.approx([20.0, 20.0, 20.0])
    entry = {"channel": "vx", "knots": 3, "p": 0.01, "passes_run": 1, "stop_reason": "converged",
             "unscheduled": {"estimation_fit_percent": [50.0, 50.0]},
             "modes_at": [{"value": v, "modes": [], "extrapolated": not c.enough} for v, c in zip((20, 30, 40), coverage)]}
    lines = text_lines(entry, ("yawRate", "ayCG"))
    assert [("extrapolated" in line) for line in lines[-3:]] == [False, False, True]
    family = schedule_models({v: _car_at(v) for v in (20.0, 30.0, 40.0)})
    family = dataclasses.replace(family, meta={"knot_coverage": [c.as_dict() for c in coverage]})
    path = tmp_path / "family.json"
    path.write_text(json.dumps(family.to_dict(), default=lambda a: np.asarray(a).tolist()))
    completed = run_vehid("handling", path, "--speeds", "20,30,38", "--wheelbase", WHEELBASE, "--json")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert [row["extrapolated"] for row in summary["metrics"]] == [False, False, True]
    assert any("38 m/s" in warning and "extrapolated" in warning for warning in summary["warnings"])
    assert summary["plausibility"] == []


# --- which models `vehid identify` takes for a car's ----------------------------------------------------------

def test_a_modal_model_is_a_cars_by_its_quantities():
    """Outputs named by --quantities (or named as the quantity) make a modal model a car's, checked at the speed
    its record states; without a yaw rate it is not checked at all (None: no JSON plausibility)."""
    from types import SimpleNamespace

    model = _car_at(30.0)
    steady = float(-(model.C @ np.linalg.solve(model.A, model.B))[0, 0])
    D = model.D.copy()
    D[0, 0] = 20.0 * steady  # the yaw rate answers at once
    model = dataclasses.replace(model, D=D, output_names=("yawRate", "ayCG"))
    n = 2000
    record = IOData(t=0.01 * np.arange(n), u=np.sin(np.arange(n) / 10.0)[:, None], y=np.zeros((n, 2)),
                    output_names=("yawRate", "ayCG"), meta={"speed": 30.0})
    plan = SimpleNamespace(records=(record,), schedule=None)
    found = {f.quantity: f for f in plausibility_checks.identify_findings(
        plan, model, quantities=("yaw_rate", "lateral_acceleration"), wheelbase=LF + LR)}
    assert found["yaw_rate_response_time_s"].speed == 30.0
    # the feed-through makes the steady yaw-rate gain 21 times the car's, whose a_y = V r held exactly
    assert found["steady_turn_kinematic_ratio"].value == pytest.approx(1 / 21, rel=1e-4)
    assert plausibility_checks.identify_findings(plan, model) is None


@pytest.mark.parametrize("extra, message", [
    (("--quantities", "yaw_rate"), "--quantities names 1 quantities for 2"),
    (("--quantities", "yaw_rate,roll"), "unknown quantity 'roll'"),
    (("--measured-sideslip", "beta_true"), "--structure single-track"),
])
def test_modal_quantities_are_checked_before_any_work(extra, message):
    completed = run_vehid("identify", LOG, "--inputs", "delta", "--outputs", "yawRate,ayCG", *extra)
    assert completed.returncode == 2 and message in completed.stderr
