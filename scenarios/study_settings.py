"""The studies' cases and default settings, as plain constants.

The studies (:mod:`~vehid.scenarios.linear_example`,
:mod:`~vehid.scenarios.handling_study`, :mod:`~vehid.scenarios.envelope`)
take their defaults from here; the command line reads them to show an
option's default and choices without importing the filters, the vehicle
model or HDF5.
"""

from __future__ import annotations

from vehid.vehicle.choices import DEFAULT_SPEED

__all__ = ["LINEAR_EXAMPLE_CASES", "STUDY_LINEAR_P", "STUDY_LINEAR_PASSES", "HANDLING_ORDERS", "HANDLING_SEED",
           "HANDLING_DURATION", "HANDLING_AMPLITUDE_SCALE", "HANDLING_VEHICLE", "HANDLING_SPEED",
           "ENVELOPE_EXECUTORS", "ENVELOPE_ARCHIVE_KIND", "ENVELOPE_AMPLITUDE_FRACTION", "ENVELOPE_DURATION",
           "ENVELOPE_P", "ENVELOPE_PASSES"]

#: The linear example's cases: the paper's Tables 1-4 and its order study.
LINEAR_EXAMPLE_CASES = ("single-output", "three-output", "three-output-constrained", "noise", "orders")

# The linear IEKF of the vehicle studies (normalised data, exact discretisation).
STUDY_LINEAR_P = 1e-5
STUDY_LINEAR_PASSES = 100

# The handling study (the paper's section 6).
HANDLING_ORDERS = (2, 3, 4, 5, 6)
HANDLING_SEED = 0
HANDLING_DURATION = 30.0  # [s]
HANDLING_AMPLITUDE_SCALE = 1.0  # [-] the paper's nonlinear range
HANDLING_VEHICLE = "baseline"
HANDLING_SPEED = DEFAULT_SPEED  # [m/s]

# The envelope campaign.
ENVELOPE_EXECUTORS = ("process", "dask")
ENVELOPE_ARCHIVE_KIND = "envelope-campaign"
ENVELOPE_AMPLITUDE_FRACTION = 0.1  # [-] of each speed's grip limit: the linear range
ENVELOPE_DURATION = 30.0  # [s]
ENVELOPE_P = 1e-3
ENVELOPE_PASSES = 30
