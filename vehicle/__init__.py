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

from __future__ import annotations

from vehid.identification.lazy_exports import export_lazily

# submodule -> the public names it defines, each imported when first asked for: a light module of the
# package (its named choices, its parameters) does not pull in CasADi and the symbolic model with it.
_EXPORTS: dict[str, tuple[str, ...]] = {
    "linearize": ("Linearization", "VehicleMode", "linearize"),
    "manoeuvres": ("MANOEUVRES", "Manoeuvre", "make_manoeuvre"),
    "model": ("CORNERS", "INPUT_NAMES", "OUTPUT_NAMES", "STATE_NAMES", "VehicleModel", "build_vehicle_model"),
    "choices": ("DEFAULT_SPEED",),
    "parameters": ("ChassisParameters", "DriveParameters", "SuspensionParameters", "AeroParameters",
                   "SteeringParameters", "TyreParameters", "VehicleParameters", "baseline", "saloon", "load_vehicle",
                   "named_vehicle", "understeer"),
    "simulation": ("DEFAULT_DT", "rk4_simulator", "simulate"),
    "validity": ("ENVELOPE", "MAX_SPEED", "MAX_SPEED_AERO", "MIN_SPEED"),
}
export_lazily(__name__, _EXPORTS)


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
