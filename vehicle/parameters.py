"""Parameters of the full-vehicle source model: frozen dataclasses, one per subsystem.

Every field carries its unit and source in the dataclass field metadata
(``unit``, ``source``); :func:`describe` lists them. Named vehicles are
constructors (:func:`baseline`, :func:`understeer`, :func:`saloon`) or data files
(:func:`load_vehicle`); change one value with :func:`dataclasses.replace`.

The baseline is a generic mid-size front-drive saloon; the tyre is the TNO
205/60R15 MF-Tyre 6.2 sample data reduced to zero camber, nominal pressure, no
turn slip, unit scaling factors and zero shift terms (so that the car is
left/right symmetric). Equations: Pacejka, Tire and Vehicle Dynamics, 3rd ed.
(2012), section 4.3.2.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from vehid.identification.errors import InputError
from vehid.identification.dataio.storage import register_codec

__all__ = [
    "ChassisParameters",
    "SuspensionParameters",
    "TyreParameters",
    "DriveParameters",
    "SteeringParameters",
    "AeroParameters",
    "VehicleParameters",
    "GRAVITY",
    "baseline",
    "understeer",
    "saloon",
    "named_vehicle",
    "load_vehicle",
    "vehicle_from_mapping",
    "describe",
    "static_axle_loads",
    "roll_stiffness",
    "peak_lateral_friction",
    "lateral_curvature",
    "longitudinal_curvature",
    "static_stability_factor",
    "has_aerodynamics",
    "NAMED_VEHICLES",
]

GRAVITY = 9.81  # [m/s^2] standard gravity, rounded as in vehicle-dynamics texts

_TNO = "TNO MF-Tyre 6.2 sample 205/60R15"
_SALOON = "generic mid-size front-drive saloon (workbench vehicle spec)"
_PACEJKA_A3 = "Pacejka, Tire and Vehicle Dynamics, 3rd ed. (2012), appendix 3, 205/60R15 car tyre"
_GILLESPIE = "Gillespie, Fundamentals of Vehicle Dynamics (1992), ch. 6 and 8"


def _p(value: float, unit: str, source: str) -> Any:
    return field(default=value, metadata={"unit": unit, "source": source})


def _fields_documented(cls: type) -> type:
    """Class decorator: the docstring's Parameters section written from each field's unit and source.

    The fields' metadata is where a value's unit and source are stated; the
    reference shows them from there rather than from a second copy.
    """
    lines = ["Parameters", "----------"]
    for item in dataclasses.fields(cls):
        # a source's |x| is an absolute value, which reStructuredText would read as a substitution
        unit, source = item.metadata["unit"], item.metadata["source"].rstrip(".").replace("|", "\\|")
        lines += [f"{item.name} : float, default {item.default!r}",
                  f"    {'Dimensionless' if unit == '-' else f'In {unit}'}: {source}."]
    cls.__doc__ = inspect.cleandoc(cls.__doc__ or "") + "\n\n" + "\n".join(lines) + "\n"
    return cls


@_fields_documented
@dataclass(frozen=True)
class ChassisParameters:
    """Rigid body: mass, inertia and geometry (CG at the origin of the body axes)."""

    mass: float = _p(1450.0, "kg", f"{_SALOON}; CommonRoad vehicle 3: 1479 kg")
    roll_inertia: float = _p(550.0, "kg m^2", f"I_xx about the CG; CommonRoad vehicle 3: 480")
    pitch_inertia: float = _p(2300.0, "kg m^2", "I_yy about the CG; CommonRoad vehicle 3: 2204")
    yaw_inertia: float = _p(2500.0, "kg m^2", "I_zz about the CG; CommonRoad vehicle 3: 2473")
    roll_yaw_product: float = _p(0.0, "kg m^2", "I_xz; zero for a symmetric saloon")
    cg_to_front_axle: float = _p(1.08, "m", "a; 60 % front load on a 2.70 m wheelbase")
    cg_to_rear_axle: float = _p(1.62, "m", "b; CommonRoad vehicle 1 (Ford Escort): 63 % front")
    front_track: float = _p(1.55, "m", _SALOON)
    rear_track: float = _p(1.52, "m", _SALOON)
    cg_height: float = _p(0.55, "m", "h above the ground; CommonRoad vehicle 1: 0.558 m")

    @property
    def wheelbase(self) -> float:
        """L = a + b (m)."""
        return self.cg_to_front_axle + self.cg_to_rear_axle


@_fields_documented
@dataclass(frozen=True)
class SuspensionParameters:
    """Quarter-car struts at the four corners (rates at the wheel) and anti-roll bars."""

    front_wheel_rate: float = _p(27000.0, "N/m", "per corner; ride about 1.25 Hz")
    rear_wheel_rate: float = _p(24000.0, "N/m", "per corner; ride about 1.45 Hz")
    front_damping: float = _p(2600.0, "N s/m", "damper rate at the wheel; ride damping about 0.4")
    rear_damping: float = _p(2100.0, "N s/m", "damper rate at the wheel; ride damping about 0.4")
    front_anti_roll_bar: float = _p(28000.0, "N m/rad", "about 5 deg/g roll gradient, roll axis at the ground")
    rear_anti_roll_bar: float = _p(9000.0, "N m/rad", "about 5 deg/g roll gradient, roll axis at the ground")


@_fields_documented
@dataclass(frozen=True)
class TyreParameters:
    """Magic Formula 6.2 coefficients (camber 0, nominal pressure), relaxation lengths, wheel.

    Coefficient names follow Pacejka (2012), section 4.3.2, and the TNO ``.tir``
    file; shift terms are zero and therefore absent.
    """

    nominal_load: float = _p(4000.0, "N", f"FNOMIN, {_TNO}")
    rolling_radius: float = _p(0.304, "m", f"effective rolling radius R_e; R0 = 0.3135 m in {_TNO}")
    wheel_inertia: float = _p(1.0, "kg m^2", "wheel and driveline spin inertia per wheel")
    # Pure longitudinal slip
    PCX1: float = _p(1.579, "-", _TNO)
    PDX1: float = _p(1.0422, "-", _TNO)
    PDX2: float = _p(-0.0827, "-", _TNO)
    PEX1: float = _p(0.11185, "-", _TNO)
    PEX2: float = _p(0.3127, "-", _TNO)
    PEX3: float = _p(0.0, "-", _TNO)
    PEX4: float = _p(0.001603, "-", _TNO)
    PKX1: float = _p(21.69, "-", _TNO)
    PKX2: float = _p(13.774, "-", _TNO)
    PKX3: float = _p(-0.4119, "-", _TNO)
    # Longitudinal force in combined slip
    RBX1: float = _p(12.531, "-", _TNO)
    RBX2: float = _p(9.532, "-", _TNO)
    RCX1: float = _p(1.019, "-", _TNO)
    REX1: float = _p(-0.4487, "-", _TNO)
    REX2: float = _p(-0.4726, "-", _TNO)
    # Pure lateral slip
    PCY1: float = _p(1.3332, "-", _TNO)
    PDY1: float = _p(0.8784, "-", _TNO)
    PDY2: float = _p(-0.06445, "-", _TNO)
    PEY1: float = _p(-0.8227, "-", _TNO)
    PEY2: float = _p(-0.6062, "-", _TNO)
    PEY3: float = _p(0.09825, "-", _TNO)
    PKY1: float = _p(-15.314, "-", _TNO)
    PKY2: float = _p(1.7044, "-", _TNO)
    PKY4: float = _p(1.9896, "-", _TNO)
    # Lateral force in combined slip
    RBY1: float = _p(10.615, "-", _TNO)
    RBY2: float = _p(7.705, "-", _TNO)
    RBY3: float = _p(0.0, "-", _TNO)
    RCY1: float = _p(1.0585, "-", _TNO)
    REY1: float = _p(0.3132, "-", _TNO)
    REY2: float = _p(0.0, "-", _TNO)
    # First-order relaxation (transient slip)
    front_lateral_relaxation: float = _p(0.345, "m", "|K_ya| / lateral stiffness at static front load (MF 6.2, PCFY1)")
    rear_lateral_relaxation: float = _p(0.289, "m", "|K_ya| / lateral stiffness at static rear load (MF 6.2, PCFY1)")
    front_longitudinal_relaxation: float = _p(0.243, "m", "K_xk / longitudinal stiffness at static front load (PCFX1)")
    rear_longitudinal_relaxation: float = _p(0.157, "m", "K_xk / longitudinal stiffness at static rear load (PCFX1)")
    # Scale of the front cornering stiffness: a stand-in for steering compliance.
    front_cornering_scale: float = _p(1.0, "-", "LKY on the front tyres; 0.75 in the 'understeer' variant")
    # Its rear counterpart: with both, a calibration sets the front/rear balance and the level apart.
    rear_cornering_scale: float = _p(1.0, "-", "LKY on the rear tyres (wider or stiffer rear tyres: above 1)")
    # Friction scaling: raise it for sticky (track) tyres, lower it for a wet road.
    friction_scale: float = _p(1.0, "-", "LMUX = LMUY on all four tyres: peak forces scale, slip stiffnesses do not")
    # Aligning moment (eq. 4.E31-4.E49 and 4.E71-4.E78 at gamma = 0, no shifts): the pneumatic trail
    QBZ1: float = _p(12.035, "-", f"trail slope factor B_t at FNOMIN; {_PACEJKA_A3}")
    QBZ2: float = _p(-1.33, "-", f"variation of B_t with load; {_PACEJKA_A3}")
    QBZ3: float = _p(0.0, "-", f"variation of B_t with load squared; {_PACEJKA_A3}")
    QCZ1: float = _p(1.2923, "-", f"shape factor C_t of the trail; {_PACEJKA_A3}")
    QDZ1: float = _p(0.09068, "-", f"peak trail D_t = QDZ1 R0 F_z / FNOMIN; {_PACEJKA_A3}")
    QDZ2: float = _p(-0.00565, "-", f"variation of the peak trail with load; {_PACEJKA_A3}")
    QEZ1: float = _p(-1.7924, "-", f"curvature E_t of the trail; {_PACEJKA_A3}")
    QEZ2: float = _p(0.8975, "-", f"variation of E_t with load; {_PACEJKA_A3}")
    QEZ3: float = _p(0.0, "-", f"variation of E_t with load squared; {_PACEJKA_A3}")
    QEZ4: float = _p(0.2895, "-", f"variation of E_t with the sign of the slip; {_PACEJKA_A3}")
    unloaded_radius: float = _p(0.3135, "m", f"R0, the length that scales the trail; {_TNO}")


@_fields_documented
@dataclass(frozen=True)
class DriveParameters:
    """PI speed hold; the drive torque is split between the axles, equally between an axle's wheels."""

    speed_gain: float = _p(2.0, "1/s", "k_p: torque = m R_e (k_p e + k_i e_I); holds 20 m/s within about 0.1 m/s")
    speed_integral_gain: float = _p(1.0, "1/s^2", "k_i of the PI speed hold")
    front_drive_share: float = _p(1.0, "-", "share of the drive torque on the front axle: 1 front-wheel drive, "
                                            "0 rear-wheel drive, between: a fixed all-wheel-drive split")
    slip_limit: float = _p(0.0, "-", "slip ratio beyond which a wheel's drive or brake torque fades (traction "
                                     "control and anti-lock brakes), the brakes then shared by the axles' loads "
                                     "as they are; 0: neither")


@_fields_documented
@dataclass(frozen=True)
class SteeringParameters:
    """The steering system: ratio, and the compliance between steering wheel and road wheels.

    The model's input ``steer`` is the steering-wheel angle divided by ``ratio``
    (the road-wheel angle of a rigid steering system). A torsional spring of
    compliance ``compliance`` between the steering wheel and the road wheels
    yields, quasi-statically, to the moments about the steering axes: the road
    wheels stand at ``steer + compliance * M`` with ``M`` the sum over both front
    wheels of the tyre's aligning moment and of its lateral force acting at the
    mechanical (caster) trail behind the steering axis. A compliance of zero is
    a rigid steering system (the road-wheel angle is the input).
    """

    ratio: float = _p(16.0, "-", f"overall ratio, steering wheel to road wheel; passenger cars 15-20 ({_GILLESPIE})")
    compliance: float = _p(0.0, "rad/(N m)", "road-wheel angle per kingpin moment, both wheels; 0: rigid")
    mechanical_trail: float = _p(0.02, "m", f"caster trail at the ground; passenger cars 10-30 mm ({_GILLESPIE})")


@_fields_documented
@dataclass(frozen=True)
class AeroParameters:
    """Aerodynamic drag and downforce, from the dynamic pressure ``q = rho u^2 / 2`` of the forward speed.

    Drag ``C_d A q`` acts at the CG against the forward speed; downforce
    ``C_z A q`` on each axle presses the body down above that axle (a negative
    area is lift). None on the baseline, whose speed range stops where they stop
    being small (:mod:`vehid.vehicle.validity`).
    """

    air_density: float = _p(1.2, "kg/m^3", "dry air at 20 deg C and sea-level pressure")
    drag_area: float = _p(0.0, "m^2", f"C_d A; a mid-size saloon about 0.6-0.7 ({_GILLESPIE.replace('6 and 8', '4')})")
    front_downforce_area: float = _p(0.0, "m^2", "C_z A on the front axle (negative: lift)")
    rear_downforce_area: float = _p(0.0, "m^2", "C_z A on the rear axle (negative: lift)")


@dataclass(frozen=True)
class VehicleParameters:
    """A whole vehicle: chassis, suspension, tyre and drive, plus a name for reports.

    Parameters
    ----------
    chassis : ChassisParameters
        Mass, inertia and geometry.
    suspension : SuspensionParameters
        Wheel rates, dampers and anti-roll bars.
    tyre : TyreParameters
        The Magic Formula tyre, the same at the four corners.
    drive : DriveParameters
        The speed hold and the drive split.
    name : str, default "baseline"
        The vehicle's name in reports.
    steering : SteeringParameters
        Ratio and compliance of the steering system.
    aerodynamics : AeroParameters
        Drag and downforce (none by default).

    Raises
    ------
    InputError
        For values out of range or a car that would roll over before its tyres slide.
    """

    chassis: ChassisParameters = field(default_factory=ChassisParameters)
    suspension: SuspensionParameters = field(default_factory=SuspensionParameters)
    tyre: TyreParameters = field(default_factory=TyreParameters)
    drive: DriveParameters = field(default_factory=DriveParameters)
    name: str = "baseline"
    steering: SteeringParameters = field(default_factory=SteeringParameters)
    aerodynamics: AeroParameters = field(default_factory=AeroParameters)

    def __post_init__(self) -> None:
        _validate(self)


_SECTIONS = {
    "chassis": ChassisParameters,
    "suspension": SuspensionParameters,
    "tyre": TyreParameters,
    "drive": DriveParameters,
    "steering": SteeringParameters,
    "aerodynamics": AeroParameters,
}
# Sections and fields a vehicle file may leave out: their defaults (a rigid steering system, unit
# friction scaling, the aligning moment of the published tyre) keep files written before them valid.
_OPTIONAL_SECTIONS = ("steering", "aerodynamics")
_OPTIONAL_FIELDS = {
    "drive": ("front_drive_share", "slip_limit"),
    "tyre": ("friction_scale", "rear_cornering_scale", "QBZ1", "QBZ2", "QBZ3", "QCZ1", "QDZ1", "QDZ2", "QEZ1",
             "QEZ2", "QEZ3", "QEZ4",
             "unloaded_radius"),
}

# Fields that must be strictly positive (masses, inertias, lengths, stiffnesses) ...
_POSITIVE = {
    "chassis": ("mass", "roll_inertia", "pitch_inertia", "yaw_inertia", "cg_to_front_axle",
                "cg_to_rear_axle", "front_track", "rear_track", "cg_height"),
    "suspension": ("front_wheel_rate", "rear_wheel_rate"),
    "tyre": ("nominal_load", "rolling_radius", "wheel_inertia", "front_lateral_relaxation",
             "rear_lateral_relaxation", "front_longitudinal_relaxation",
             "rear_longitudinal_relaxation", "front_cornering_scale", "rear_cornering_scale", "PCX1", "PDX1", "PKX1",
             "PCY1", "PDY1", "PKY2", "PKY4", "friction_scale", "unloaded_radius"),
    "drive": (),
    "steering": ("ratio",),
    "aerodynamics": ("air_density",),
}
# ... and those that may be zero (a car without a rear bar, a frictionless damper, no speed hold).
_NON_NEGATIVE = {
    "suspension": ("front_damping", "rear_damping", "front_anti_roll_bar", "rear_anti_roll_bar"),
    "drive": ("speed_gain", "speed_integral_gain", "front_drive_share", "slip_limit"),
    "steering": ("compliance", "mechanical_trail"),
    "aerodynamics": ("drag_area",),
}


def _validate(params: VehicleParameters) -> None:
    for section, cls in _SECTIONS.items():
        group = getattr(params, section)
        if not isinstance(group, cls):
            raise InputError(f"vehicle {section} must be {cls.__name__}; got {type(group).__name__}")
        for item in dataclasses.fields(group):
            value = getattr(group, item.name)
            unit = item.metadata.get("unit", "-")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"vehicle parameter {section}.{item.name} must be a number; got {value!r}")
            if not math.isfinite(value):
                raise InputError(f"vehicle parameter {section}.{item.name} is not finite ({value})")
            if item.name in _POSITIVE[section] and value <= 0:
                raise InputError(
                    f"vehicle parameter {section}.{item.name} must be positive; got {value} {unit}"
                )
            if item.name in _NON_NEGATIVE.get(section, ()) and value < 0:
                raise InputError(
                    f"vehicle parameter {section}.{item.name} must not be negative; got {value} {unit}"
                )
    if params.drive.front_drive_share > 1:
        raise InputError(f"vehicle parameter drive.front_drive_share is a share of the drive torque, at most 1; "
                         f"got {params.drive.front_drive_share}")
    if params.drive.slip_limit >= 0.5:
        raise InputError(f"vehicle parameter drive.slip_limit is a slip ratio below the envelope's 0.5 (a wheel "
                         f"spinning up or locking); got {params.drive.slip_limit}")
    if params.tyre.PKY1 >= 0:
        raise InputError("vehicle parameter tyre.PKY1 must be negative (ISO sign: F_y opposes slip)")
    _check_curvature(params.tyre)
    chassis = params.chassis
    inertia_det = chassis.roll_inertia * chassis.yaw_inertia - chassis.roll_yaw_product**2
    if inertia_det <= 0:
        raise InputError("vehicle inertia is not positive definite: I_xx I_zz must exceed I_xz^2")
    _check_static_stability(params)


def _check_curvature(tyre: TyreParameters) -> None:
    """Reject curvature factors above 1 at loads from none to twice the nominal (Pacejka 2012, eq. 4.E14 and
    4.E24: ``E <= 1``): beyond it the force turns round at large slip and pushes the way the tyre slides."""
    loads = [k / 10 - 1 for k in range(21)]  # dfz from -1 to 1
    lateral = [lateral_curvature(dfz, side, tyre) for dfz in loads for side in (-1, 1)]
    longitudinal = [longitudinal_curvature(dfz, side, tyre) for dfz in loads for side in (-1, 1)]
    for names, values in (("PEY1, PEY2, PEY3", lateral), ("PEX1, PEX2, PEX3, PEX4", longitudinal)):
        if max(values) > 1:
            raise InputError(f"vehicle parameters tyre.{names} give a curvature factor of {max(values):.3g}, above 1 "
                             "at a load between none and twice the nominal: the force would turn round at large "
                             "slip (E <= 1)")


def longitudinal_curvature(dfz, sign, tyre: TyreParameters):
    """The tyre's curvature factor ``E_x`` at load increment ``dfz`` and slip sign ``sign`` (eq. 4.E14);
    floats or CasADi SX, as :mod:`vehid.vehicle.tyre` builds its forces from it."""
    return (tyre.PEX1 + tyre.PEX2 * dfz + tyre.PEX3 * dfz**2) * (1 - tyre.PEX4 * sign)


def lateral_curvature(dfz, sign, tyre: TyreParameters):
    """The tyre's curvature factor ``E_y`` at load increment ``dfz`` and slip sign ``sign`` (eq. 4.E24 at
    gamma = 0); floats or CasADi SX, as :mod:`vehid.vehicle.tyre` builds its forces from it."""
    return (tyre.PEY1 + tyre.PEY2 * dfz) * (1 - tyre.PEY3 * sign)


def roll_stiffness(params: VehicleParameters) -> float:
    """Total roll stiffness ``K_phi = sum(k t^2 / 2 + K_arb)`` of springs and bars (N m/rad)."""
    c, s = params.chassis, params.suspension
    return (s.front_wheel_rate * c.front_track**2 / 2 + s.front_anti_roll_bar
            + s.rear_wheel_rate * c.rear_track**2 / 2 + s.rear_anti_roll_bar)


def peak_lateral_friction(params: VehicleParameters) -> float:
    """The tyres' peak lateral friction ``mu_y = (PDY1 + PDY2 dfz) LMUY`` at the mean static corner load (eq. 4.E23)."""
    tyre = params.tyre
    corner_load = params.chassis.mass * GRAVITY / 4
    return tyre.friction_scale * (tyre.PDY1 + tyre.PDY2 * (corner_load - tyre.nominal_load) / tyre.nominal_load)


def has_aerodynamics(params: VehicleParameters) -> bool:
    """True when the vehicle carries aerodynamic drag (its speed range then reaches further)."""
    return params.aerodynamics.drag_area > 0


def static_stability_factor(params: VehicleParameters) -> float:
    """``t / (2 h)`` with the narrower track: the lateral acceleration (in g) that tips a rigid car over."""
    c = params.chassis
    return min(c.front_track, c.rear_track) / (2 * c.cg_height)


def _check_static_stability(params: VehicleParameters) -> None:
    """Reject a vehicle the model cannot represent: one that falls over in roll, or tips before it slides.

    * Roll: with the roll axis at the ground, gravity's moment ``m g h phi``
      must be smaller than the springs' and bars' ``K_phi phi``, or the body
      falls over at rest.
    * Rollover: a car whose static stability factor ``t / (2 h)`` is below its
      tyres' friction ``mu_y`` lifts its inner wheels before its tyres slide
      (NHTSA's rollover resistance rating rests on this factor; road cars have
      1.0-1.5, this baseline 1.38, against mu_y of about 0.88). The model has
      no bump stops or rollover kinematics, so such a car would roll on without
      bound (a 3 m CG height reaches hundreds of degrees).
    """
    c = params.chassis
    weight_moment = c.mass * GRAVITY * c.cg_height
    stiffness = roll_stiffness(params)
    if stiffness <= weight_moment:
        raise InputError(
            f"vehicle is unstable in roll: springs and bars give K_phi = {stiffness:.4g} N m/rad, "
            f"no more than m g h = {weight_moment:.4g} N m/rad (CG height {c.cg_height} m)"
        )
    factor, friction = static_stability_factor(params), peak_lateral_friction(params)
    if factor <= friction:
        raise InputError(
            f"vehicle would tip over before its tyres slide: static stability factor t / (2 h) = {factor:.3g} "
            f"(track {min(c.front_track, c.rear_track)} m, CG height {c.cg_height} m) is below the tyres' "
            f"friction {friction:.3g}; the model has no rollover, so the CG must be lower than "
            f"{min(c.front_track, c.rear_track) / (2 * friction):.3g} m"
        )


def baseline() -> VehicleParameters:
    """Make the baseline saloon: 1450 kg, 60 % front load, near-neutral handling (< 1 deg/g).

    Returns
    -------
    VehicleParameters
        Every field at its default, rigid steering, no aerodynamics.
    """
    return VehicleParameters()


def understeer() -> VehicleParameters:
    """The baseline with the front cornering stiffness scaled by 0.75.

    With road-wheel steer as input and no compliance, tyre load sensitivity is the
    only understeer source; the scale stands in for steering compliance and
    brings the understeer gradient into the 2-4 deg/g range of real saloons.
    :func:`saloon` models the compliance itself.

    Returns
    -------
    VehicleParameters
        Named ``"understeer"``.
    """
    base = baseline()
    return dataclasses.replace(
        base, tyre=dataclasses.replace(base.tyre, front_cornering_scale=0.75), name="understeer"
    )


# Steering compliance of the saloon (rad per N m of kingpin moment, both wheels): a stiffness of
# 20 kN m/rad at the road wheels, about 78 N m/rad (1.4 N m/deg) at the steering wheel through the
# 16:1 ratio. With the front axle's lateral force acting at the pneumatic plus mechanical trail
# (about 28 + 20 mm) it adds W_f (t_p + t_m) / K_s = 8.5 kN * 0.048 m / 20 kN m/rad, about 1.2 deg/g,
# to the understeer gradient (the steering-compliance term of Gillespie 1992, ch. 6), which takes
# the near-neutral baseline (0.7 deg/g) to about 1.9 deg/g.
_SALOON_STEERING_COMPLIANCE = 1 / 20_000.0


def saloon() -> VehicleParameters:
    """The baseline with its steering system: ratio 16, compliance, aligning moment fed back.

    The default car for new work. Its road-wheel angles yield to the front tyres'
    aligning moments and to their lateral forces at the caster trail, so its
    understeer gradient is that of a production saloon rather than the
    near-neutral baseline's (:func:`vehid.vehicle.handling.source_handling`
    reports it). The model's input stays the steering-wheel angle over the
    ratio; the paper's studies keep the baseline, whose steering is rigid.

    Returns
    -------
    VehicleParameters
        Named ``"saloon"``.
    """
    base = baseline()
    return dataclasses.replace(
        base, steering=dataclasses.replace(base.steering, compliance=_SALOON_STEERING_COMPLIANCE), name="saloon"
    )


NAMED_VEHICLES = {"baseline": baseline, "understeer": understeer, "saloon": saloon}


def named_vehicle(spec: str | Path | VehicleParameters) -> VehicleParameters:
    """Return the vehicle a name, a file or a vehicle value stands for.

    Parameters
    ----------
    spec : str, path or VehicleParameters
        A name (``baseline``, ``understeer``, ``saloon``), a TOML or JSON file, or the vehicle itself.

    Returns
    -------
    VehicleParameters
        The vehicle.
    """
    if isinstance(spec, VehicleParameters):
        return spec
    text = str(spec)
    if text in NAMED_VEHICLES:
        return NAMED_VEHICLES[text]()
    path = Path(text)
    if path.suffix.lower() in (".toml", ".json") or path.exists():
        return load_vehicle(path)
    raise InputError(
        f"unknown vehicle {text!r}: give {', '.join(NAMED_VEHICLES)} or a .toml/.json file"
    )


def vehicle_from_mapping(data: Mapping[str, Any], *, origin: str = "vehicle data") -> VehicleParameters:
    """Build a vehicle from a nested mapping ``{section: {field: value}}``.

    Sections are ``chassis``, ``suspension``, ``tyre``, ``drive``, ``steering``
    and ``aerodynamics`` (the last two may be left out: a rigid steering system, no
    aerodynamic forces); top-level
    ``name`` is optional. Every field of every section must be given unless a
    top-level ``base`` names a vehicle (``baseline``, ``understeer`` or ``saloon``) whose
    values fill the gaps. Unknown sections or fields are an error.
    """
    if not isinstance(data, Mapping):
        raise InputError(f"{origin}: expected a table of sections")
    unknown = set(data) - set(_SECTIONS) - {"name", "base"}
    if unknown:
        raise InputError(
            f"{origin}: unknown section(s) {', '.join(sorted(unknown))}; "
            f"allowed: {', '.join(_SECTIONS)}, name, base"
        )
    base_name = data.get("base")
    if base_name is not None and (not isinstance(base_name, str) or base_name not in NAMED_VEHICLES):
        raise InputError(
            f"{origin}: unknown base vehicle {base_name!r}; allowed: {', '.join(NAMED_VEHICLES)}"
        )
    base = NAMED_VEHICLES[base_name]() if base_name else None
    groups: dict[str, Any] = {}
    for section, cls in _SECTIONS.items():
        if section in _OPTIONAL_SECTIONS and section not in data and base is None:
            groups[section] = cls()
            continue
        values = data.get(section, {})
        if not isinstance(values, Mapping):
            raise InputError(f"{origin}: section {section!r} must be a table of fields")
        names = {item.name for item in dataclasses.fields(cls)}
        extra = set(values) - names
        if extra:
            raise InputError(
                f"{origin}: unknown field(s) in [{section}]: {', '.join(sorted(extra))}"
            )
        if base is None:
            missing = names - set(values) - set(_OPTIONAL_FIELDS.get(section, ()))
            if missing:
                raise InputError(
                    f"{origin}: missing field(s) in [{section}]: {', '.join(sorted(missing))} "
                    "(or set base = \"baseline\" to take defaults)"
                )
            groups[section] = cls(**values)
        else:
            groups[section] = dataclasses.replace(getattr(base, section), **values)
    name = data.get("name", origin)
    return VehicleParameters(**groups, name=str(name))


def load_vehicle(path: str | Path) -> VehicleParameters:
    """Read a vehicle from a TOML or JSON file.

    Parameters
    ----------
    path : str or path
        The file; its layout is :func:`vehicle_from_mapping`'s.

    Returns
    -------
    VehicleParameters
        The vehicle, checked.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such vehicle file: {path}")
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(path.read_text())
        else:
            data = tomllib.loads(path.read_text())
    except (json.JSONDecodeError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path} is not a readable vehicle file ({exc})") from None
    if not isinstance(data, Mapping):
        raise InputError(f"{path.name}: expected a table of sections, got a JSON {type(data).__name__}")
    data = dict(data)
    data.setdefault("name", path.stem)
    return vehicle_from_mapping(data, origin=path.name)


def describe(params: VehicleParameters) -> list[tuple[str, float, str, str]]:
    """Every parameter as ``(section.field, value, unit, source)``."""
    rows = []
    for section in _SECTIONS:
        group = getattr(params, section)
        for item in dataclasses.fields(group):
            rows.append(
                (f"{section}.{item.name}", getattr(group, item.name),
                 item.metadata.get("unit", "-"), item.metadata.get("source", ""))
            )
    return rows


def static_axle_loads(params: VehicleParameters) -> tuple[float, float]:
    """Static front and rear axle loads (N): ``m g b / L`` and ``m g a / L``."""
    c = params.chassis
    weight = c.mass * GRAVITY
    return weight * c.cg_to_rear_axle / c.wheelbase, weight * c.cg_to_front_axle / c.wheelbase


# Parameter sets are stored in archives (study configurations) under these schemas.
register_codec(ChassisParameters, "vehicle_chassis", legacy_path="vehicle.parameters:ChassisParameters")
register_codec(SuspensionParameters, "vehicle_suspension", legacy_path="vehicle.parameters:SuspensionParameters")
register_codec(TyreParameters, "vehicle_tyres", legacy_path="vehicle.parameters:TyreParameters")
register_codec(DriveParameters, "vehicle_drive", legacy_path="vehicle.parameters:DriveParameters")
register_codec(SteeringParameters, "vehicle_steering")
register_codec(AeroParameters, "vehicle_aerodynamics")
register_codec(VehicleParameters, "vehicle_parameters", legacy_path="vehicle.parameters:VehicleParameters")
