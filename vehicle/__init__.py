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

import importlib
import sys
import types
from typing import Any

# submodule -> the public names it defines. Each name is imported from its module when first asked
# for, so that a light module of the package (its named choices, its parameters) does not pull in
# CasADi and the symbolic model with it.
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
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}


def __getattr__(name: str) -> Any:
    module = _MODULE_OF.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_MODULE_OF))


class _LazyPackage(types.ModuleType):
    """The package module, whose exported names win over its submodules' names.

    Importing a submodule makes it an attribute of its package; the function
    ``linearize`` would then be hidden by the module ``linearize`` that
    defines it, whichever was imported first.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _MODULE_OF and isinstance(value, types.ModuleType):
            return  # the submodule stays in sys.modules; the package's name keeps meaning the exported value
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _LazyPackage


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
