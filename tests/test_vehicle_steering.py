"""The steering system of the source model: aligning moment, compliance, friction scaling.

The aligning moment is checked against the Magic Formula's closed form at pure
slip (Pacejka, Tire and Vehicle Dynamics, 3rd ed., 2012, eq. 4.E31-4.E44 at
zero camber, written out here in NumPy independently of the CasADi code), and
the compliance against the single-track argument for the steady-state gain.
"""

import dataclasses
import math

import numpy as np
import pytest

from vehid.identification.errors import InputError
from vehid.vehicle import baseline, build_vehicle_model, saloon
from vehid.vehicle.parameters import GRAVITY, TyreParameters, static_axle_loads, vehicle_from_mapping
from vehid.vehicle.tyre import aligning_moment, combined_forces, cornering_stiffness, lateral_force_pure

TYRE = TyreParameters()


def _closed_form_trail(alpha: np.ndarray, fz: float, tyre: TyreParameters) -> np.ndarray:
    """Pneumatic trail at pure slip, eq. 4.E33-4.E44 with gamma = 0 and no shifts."""
    dfz = (fz - tyre.nominal_load) / tyre.nominal_load
    b = tyre.QBZ1 + tyre.QBZ2 * dfz + tyre.QBZ3 * dfz**2
    c = tyre.QCZ1
    d = fz * tyre.unloaded_radius / tyre.nominal_load * (tyre.QDZ1 + tyre.QDZ2 * dfz)
    e = (tyre.QEZ1 + tyre.QEZ2 * dfz + tyre.QEZ3 * dfz**2) * (1 + tyre.QEZ4 * 2 / np.pi * np.arctan(b * c * alpha))
    bx = b * alpha
    cos_alpha = 1 / np.sqrt(1 + alpha**2)  # alpha is tan(slip angle): V_cx / V_c
    return d * np.cos(c * np.arctan(bx - e * (bx - np.arctan(bx)))) * cos_alpha


@pytest.mark.parametrize("fz", [2000.0, 4000.0, 6000.0])
def test_aligning_moment_is_the_magic_formula_at_pure_slip(fz):
    """M_z = -t F_y0 at zero slip ratio, over +/-15 deg.

    Tolerance 1e-9 relative to the largest moment: the two evaluations are the
    same algebra in different code; what differs is round-off and the smooth
    sign of the lateral force's curvature (width 1e-3, identical in both since
    F_y0 is taken from the model's own pure-slip function).
    """
    alphas = np.tan(np.deg2rad(np.linspace(-15, 15, 61)))
    model = np.array([float(aligning_moment(0.0, a, fz, TYRE)) for a in alphas])
    fy0 = np.array([float(lateral_force_pure(a, fz, TYRE)) for a in alphas])
    expected = -_closed_form_trail(alphas, fz, TYRE) * fy0
    assert np.max(np.abs(model - expected)) <= 1e-9 * np.max(np.abs(expected))


def test_aligning_moment_restores_towards_straight_ahead():
    """ISO 8855: a positive slip gives a negative force and a positive moment, which turns the wheel
    towards its direction of travel; the slope at zero is the trail times the cornering stiffness."""
    fz = 4000.0
    small = 1e-3
    moment = float(aligning_moment(0.0, small, fz, TYRE))
    force = float(combined_forces(0.0, small, fz, TYRE)[1])
    assert force < 0 < moment
    assert float(aligning_moment(0.0, -small, fz, TYRE)) < 0
    # d M_z / d alpha at zero = -D_t K_ya, D_t = QDZ1 R0 at the nominal load (eq. 4.E40, 4.E42).
    # Tolerance 1 %: the finite slip 1e-3 rad bends the trail and the force by (B alpha)^2 ~ 1e-4,
    # and the smooth sign of the force's curvature asymmetry (width 1e-3) shifts it by under 1 %.
    slope = (float(aligning_moment(0.0, small, fz, TYRE)) - float(aligning_moment(0.0, -small, fz, TYRE))) / (2 * small)
    expected = -TYRE.QDZ1 * TYRE.unloaded_radius * float(cornering_stiffness(fz, TYRE))
    assert slope == pytest.approx(expected, rel=1e-2)


def test_longitudinal_slip_lowers_the_trail_and_the_moment():
    """Combined slip (eq. 4.E73-4.E78): the equivalent slip grows with the slip ratio, the trail falls."""
    alpha, fz = math.tan(math.radians(2.0)), 4000.0
    pure = float(aligning_moment(0.0, alpha, fz, TYRE))
    for kappa in (0.02, 0.05, -0.05):
        combined = float(aligning_moment(kappa, alpha, fz, TYRE))
        assert 0 < combined < pure


def test_right_tyre_is_the_left_one_mirrored():
    """Mounted mirrored, a right tyre's moment is the left one's reflected: the car stays symmetric."""
    for alpha in (0.01, 0.05, 0.12):
        left = float(aligning_moment(0.01, alpha, 4200.0, TYRE))
        right = float(aligning_moment(0.01, -alpha, 4200.0, TYRE, mirrored=True))
        assert right == pytest.approx(-left, rel=1e-12)


def test_friction_scale_raises_the_peak_not_the_cornering_stiffness():
    sticky = dataclasses.replace(TYRE, friction_scale=1.5)
    fz = 4000.0
    peak = max(abs(float(lateral_force_pure(math.tan(math.radians(a)), fz, TYRE))) for a in np.linspace(1, 20, 200))
    peak_sticky = max(abs(float(lateral_force_pure(math.tan(math.radians(a)), fz, sticky)))
                      for a in np.linspace(1, 30, 300))
    # The peak factor D = mu_y F_z is reached exactly when C > 1 (sin at pi/2); a 0.1 deg grid
    # misses it by at most 1e-4 relative.
    assert peak_sticky / peak == pytest.approx(1.5, rel=1e-3)
    # Slope at zero slip against K_ya (eq. 4.E25), for both. Tolerance 1e-4: B = K_ya / (C D + eps_y)
    # with eps_y = 0.1 N of eq. 4.E26 against C D of about 5 kN (2e-5), and the finite slip 1e-6.
    expected = float(cornering_stiffness(fz, TYRE))
    for tyre in (TYRE, sticky):
        assert float(lateral_force_pure(1e-6, fz, tyre)) / 1e-6 == pytest.approx(expected, rel=1e-4)


def test_the_steered_car_keeps_23_states():
    model = build_vehicle_model(saloon())
    assert model.n_states == 23 and model.state_names == build_vehicle_model(baseline()).state_names
    assert np.asarray(model.xdot.shape).tolist() == [23, 1]


def _steady_gains(params, steer: float, speed: float) -> tuple[float, float]:
    model = build_vehicle_model(params)
    x = model.trim(speed, steer)
    y = np.asarray(model.outputs(x, steer, speed)).ravel()
    return y[model.output_index("yaw_rate")] / steer, y[model.output_index("lateral_acceleration")] / steer


@pytest.mark.parametrize("speed", [10.0, 30.0])
def test_compliance_lowers_the_steady_gain_by_the_single_track_ratio(speed):
    """Single-track argument: in a steady turn the front axle carries ``F_yf = m a_y b / L``, acting at
    the pneumatic plus mechanical trail, so the road wheels stand at ``delta = steer - c (t_p + t_m) F_yf``
    and, with ``a_y = G_a delta`` of the rigid car, ``delta / steer = 1 / (1 + c (t_p + t_m) m (b / L) G_a)``.

    The trail is the closed form at the static front corner load. Tolerance 1e-3 relative: both
    sides are exact to first order in the steer (0.06 deg here); left over are the smoothing of
    |V_cx| (2.5e-4 at 10 m/s) and load transfer, which changes the trail-force product only in
    second order.
    """
    steer = 1e-3
    rigid_yaw, rigid_lateral = _steady_gains(baseline(), steer, speed)
    params = saloon()
    yaw, lateral = _steady_gains(params, steer, speed)
    c = params.chassis
    front_corner = static_axle_loads(params)[0] / 2
    trail = float(_closed_form_trail(np.array([0.0]), front_corner, params.tyre)[0])
    factor = params.steering.compliance * (trail + params.steering.mechanical_trail) * c.mass * (
        c.cg_to_rear_axle / c.wheelbase)
    expected = 1 / (1 + factor * rigid_lateral)
    assert yaw / rigid_yaw == pytest.approx(expected, rel=1e-3)
    assert lateral / rigid_lateral == pytest.approx(expected, rel=1e-3)
    assert expected < 0.95  # a change 50 times the tolerance: the check can fail


def test_without_trail_the_compliance_does_nothing():
    """Compliance acts only through the moments: with no pneumatic and no caster trail it leaves the car
    as the rigid baseline (trim states equal to round-off)."""
    base = baseline()
    trailless = dataclasses.replace(
        saloon(), tyre=dataclasses.replace(base.tyre, QDZ1=0.0, QDZ2=0.0),
        steering=dataclasses.replace(saloon().steering, mechanical_trail=0.0),
    )
    steer = math.radians(1.0)
    x_rigid = build_vehicle_model(base).trim(20.0, steer)
    x_trailless = build_vehicle_model(trailless).trim(20.0, steer)
    assert np.max(np.abs(x_trailless - x_rigid)) < 1e-9


def test_vehicle_files_without_a_steering_section_stay_rigid():
    data = {section: dataclasses.asdict(getattr(baseline(), section)) for section in
            ("chassis", "suspension", "tyre", "drive")}
    for name in ("friction_scale", "QBZ1", "QDZ1"):  # written before these fields existed
        del data["tyre"][name]
    del data["drive"]["front_drive_share"]
    params = vehicle_from_mapping(data)
    assert params.steering.compliance == 0 and params.tyre.friction_scale == 1.0
    assert params.drive.front_drive_share == 1.0
    steered = vehicle_from_mapping({"base": "baseline", "steering": {"compliance": 5e-5, "ratio": 14.0}})
    assert steered.steering.ratio == 14.0
    with pytest.raises(InputError, match="steering.compliance must not be negative"):
        vehicle_from_mapping({"base": "baseline", "steering": {"compliance": -1e-5}})
    with pytest.raises(InputError, match="friction_scale must be positive"):
        vehicle_from_mapping({"base": "baseline", "tyre": {"friction_scale": 0.0}})
    with pytest.raises(InputError, match="front_drive_share is a share of the drive torque, at most 1"):
        vehicle_from_mapping({"base": "baseline", "drive": {"front_drive_share": 1.5}})


def test_the_steered_saloon_understeers_like_a_production_car():
    """Understeer gradient of the saloon from its exact steady states, 1.5-4 deg/g (passenger cars;
    the baseline, rigid, is near neutral below 1 deg/g): ``K = (steer - L r / V) / a_y``."""
    speed, steer = 20.0, math.radians(0.5)
    for params, low, high in ((saloon(), 1.5, 4.0), (baseline(), 0.0, 1.0)):
        yaw, lateral = _steady_gains(params, steer, speed)
        gradient = (1 - params.chassis.wheelbase * yaw / speed) / lateral
        assert low < math.degrees(gradient) * GRAVITY < high


def _aero_saloon():
    return vehicle_from_mapping({"base": "saloon", "name": "saloon-aero", "aerodynamics": {
        "drag_area": 0.7, "front_downforce_area": 0.3, "rear_downforce_area": 0.5}})


def test_aerodynamic_forces_in_a_steady_straight_run():
    """At 60 m/s: the tyres carry the weight plus the downforce (vertical balance, exact), each axle its
    share plus its own downforce, less or plus the drag's transfer ``D (h + z) / L``; the feed-forward
    carries the drag, so the PI integral stays near zero.

    Tolerances: the vertical balance 1e-6 relative (algebra, but the dynamic pressure takes u |u| with
    the smoothed |u|, which adds eps^2 / (2 u^2) = 1.4e-6 of the downforce, 1.5e-7 of the total).
    The axle split 0.5 % of the axle load: the contact points follow the body points at ground level
    below the struts, which move by ``h sin(theta)`` (5 mm at the 0.5 deg pitch here) when the body
    pitches, shifting some 30 N between axles.
    """
    params = _aero_saloon()
    model = build_vehicle_model(params)
    speed = 60.0
    x = model.trim(speed)
    y = np.asarray(model.outputs(x, 0.0, speed)).ravel()
    load = {c: y[model.output_index(f"tyre_load_{c}")] for c in ("fl", "fr", "rl", "rr")}
    q = 0.5 * params.aerodynamics.air_density * speed**2
    drag = params.aerodynamics.drag_area * q
    front_static, rear_static = static_axle_loads(params)
    weight = params.chassis.mass * GRAVITY
    total = sum(load.values())
    assert total == pytest.approx(weight + (params.aerodynamics.front_downforce_area + params.aerodynamics.rear_downforce_area) * q,
                                  rel=1e-6)
    transfer = drag * (params.chassis.cg_height + x[model.state_index("z")]) / params.chassis.wheelbase
    front = front_static + params.aerodynamics.front_downforce_area * q - transfer
    assert load["fl"] + load["fr"] == pytest.approx(front, rel=5e-3)
    assert abs(x[model.state_index("speed_error_integral")] * params.drive.speed_integral_gain) < 1e-3 * drag / (
        params.chassis.mass)


def test_aerodynamics_extend_the_speed_range():
    from vehid.vehicle.validity import MAX_SPEED, MAX_SPEED_AERO

    with pytest.raises(InputError, match=f"above the model's valid range \\(3-{MAX_SPEED:g} m/s\\)"):
        build_vehicle_model(saloon()).trim(60.0)
    x = build_vehicle_model(_aero_saloon()).trim(60.0)
    assert x[0] == pytest.approx(60.0, rel=1e-3)
    with pytest.raises(InputError, match=f"\\(3-{MAX_SPEED_AERO:g} m/s\\)"):
        build_vehicle_model(_aero_saloon()).trim(MAX_SPEED_AERO + 1)
