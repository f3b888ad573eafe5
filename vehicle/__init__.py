"""The full-vehicle source model: parameters, symbolic CasADi model, compiled simulator, manoeuvres.

Typical use::

    from vehid.vehicle import baseline, simulate, linearize
    from vehid.vehicle.manoeuvres import identification

    record = simulate(baseline(), identification(seed=0))   # IOData, 30 s at 500 Hz
    handling = record.select_outputs(["lateral_acceleration", "yaw_rate", "roll_angle"])
    modes = linearize(baseline(), speed=20.0).modes

A run that leaves the model's physical envelope (:data:`ENVELOPE`) raises
``vehid.identification.errors.SimulationError`` with the record up to that point;
speeds outside ``MIN_SPEED``-``MAX_SPEED`` (m/s) are input errors.
"""

from .linearize import Linearization, VehicleMode, linearize
from .manoeuvres import MANOEUVRES, Manoeuvre, make_manoeuvre
from .model import (
    CORNERS,
    DEFAULT_SPEED,
    INPUT_NAMES,
    OUTPUT_NAMES,
    STATE_NAMES,
    VehicleModel,
    build_vehicle_model,
)
from .parameters import (
    ChassisParameters,
    DriveParameters,
    SuspensionParameters,
    AeroParameters,
    SteeringParameters,
    TyreParameters,
    VehicleParameters,
    baseline,
    saloon,
    load_vehicle,
    named_vehicle,
    understeer,
)
from .simulation import DEFAULT_DT, rk4_simulator, simulate
from .validity import ENVELOPE, MAX_SPEED, MAX_SPEED_AERO, MIN_SPEED

__all__ = [
    "Linearization",
    "VehicleMode",
    "linearize",
    "MANOEUVRES",
    "Manoeuvre",
    "make_manoeuvre",
    "CORNERS",
    "DEFAULT_SPEED",
    "DEFAULT_DT",
    "INPUT_NAMES",
    "OUTPUT_NAMES",
    "STATE_NAMES",
    "VehicleModel",
    "build_vehicle_model",
    "ChassisParameters",
    "DriveParameters",
    "SuspensionParameters",
    "AeroParameters",
    "SteeringParameters",
    "TyreParameters",
    "VehicleParameters",
    "baseline",
    "understeer",
    "saloon",
    "load_vehicle",
    "named_vehicle",
    "simulate",
    "rk4_simulator",
    "ENVELOPE",
    "MIN_SPEED",
    "MAX_SPEED",
    "MAX_SPEED_AERO",
]
