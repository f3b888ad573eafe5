"""The source model's named choices and defaults, as plain constants.

The modules that compute with them import them from here; the command line
reads them to list an option's choices and default without importing NumPy
or CasADi.
"""

from __future__ import annotations

__all__ = ["MANOEUVRE_NAMES", "STEER_KINDS", "DEFAULT_SPEED"]

#: The steer manoeuvres, by name (:func:`vehid.vehicle.make_manoeuvre`); each is made by the
#: function of :mod:`vehid.vehicle.manoeuvres` of that name, a hyphen read as an underscore.
MANOEUVRE_NAMES = ("identification", "validation", "step", "sweep", "ramp", "speed-ramp", "speed-cycle")

#: What a replayed log's steer channel measures: the road-wheel angle, or the steering-wheel angle.
STEER_KINDS = ("road", "wheel")

DEFAULT_SPEED = 20.0  # [m/s] the handling study's trim speed (Best & Bogdanski, section 6)
