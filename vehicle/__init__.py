"""The full-vehicle source model: parameters, symbolic CasADi model, compiled simulator, manoeuvres."""

from .linearize import Linearization, Mode, linearize
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
    TyreParameters,
    VehicleParameters,
    baseline,
    load_vehicle,
    named_vehicle,
    understeer,
)
from .simulation import DEFAULT_DT, rk4_simulator, simulate

__all__ = [
    "Linearization",
    "Mode",
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
    "TyreParameters",
    "VehicleParameters",
    "baseline",
    "understeer",
    "load_vehicle",
    "named_vehicle",
    "simulate",
    "rk4_simulator",
]
