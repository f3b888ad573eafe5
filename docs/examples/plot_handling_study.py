"""
The handling study on a short record
====================================

The full-vehicle model is steered by the identification manoeuvre
(band-limited noise plus a sweep) and a fourth-order modal model from steer
to lateral acceleration, yaw rate and roll angle is identified by the IEKF,
then checked on a different manoeuvre. ``vehid study handling`` (``make
study``) runs the same on 30 s records for orders 2 to 6, adds the
spline-nonlinear models and writes an archive and a report.

The car is driven close to its grip limit, so the linear model is the best
linear description of a saturating car: its modes are slower than the car's
small-signal modes, which :func:`vehid.vehicle.linearize` gives.
"""

import os

import matplotlib.pyplot as plt
import numpy as np

from vehid.identification import IEKFOptions, ModalStructure, identify_iekf, percentage_explanation
from vehid.vehicle import baseline, linearize, make_manoeuvre, simulate

# Shortened under VEHID_DOCS_QUICK=1 (the documentation test); the study uses 30 s and 100 passes.
quick = os.environ.get("VEHID_DOCS_QUICK") == "1"
duration, passes = (5.0, 4) if quick else (30.0, 100)
outputs = ["lateral_acceleration", "yaw_rate", "roll_angle"]

# %%
# Two records of the baseline car at its default speed: one to identify from,
# one to validate on (a different manoeuvre, not only a different seed).
car = baseline()
records = {
    name: simulate(car, make_manoeuvre(name, seed=0, duration=duration)).select_outputs(outputs)
    for name in ("identification", "validation")
}
identification, validation = records["identification"], records["validation"]
print(identification.n_samples, "samples at", identification.dt, "s")

# %%
# One input, three outputs, four states. The settings that do not depend on
# units or record length: signals divided by their RMS, the start from the
# data, time counted in samples inside the filter.
structure = ModalStructure.default(4, 1, 3)
result = identify_iekf(identification, structure, options=IEKFOptions.invariant(passes=passes))
model = result.model
for name, record in records.items():
    fit = percentage_explanation(record.y, model.simulate_outputs(record.u, record.dt))
    print(f"R on {name}: " + ", ".join(f"{o} {r:.2f} %" for o, r in zip(outputs, fit)))

# %%
# The identified modes beside the car's own small-signal modes.
for mode in model.modes():
    print(f"identified: {mode.frequency_hz:.2f} Hz, damping {mode.damping:.2f}")
small_signal = linearize(car)
for label in ("yaw-sideslip", "roll"):
    for mode in small_signal.modes_labelled(label):
        print(f"car, {label}: {mode.frequency_hz:.2f} Hz, damping {mode.damping:.2f}")

# %%
# The validation record against the model's simulation. ``simulate`` returns a
# response: the record's time and inputs, the model's outputs, the record's own
# outputs as ``measured``, and a ``plot`` that draws both (black: the vehicle model).
response = model.simulate(validation)
print(f"largest residual: {np.max(np.abs(response.residuals), axis=0).round(3)}")
fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 6), layout="constrained")
response.plot(ax=axes, label="identified, n = 4")
fig.suptitle("Validation manoeuvre")

# %%
# The model's frequency response from steer, a response too.
fig, axes = plt.subplots(2, 3, sharex=True, figsize=(9, 5), layout="constrained")
model.frequency_response(np.logspace(-1, 1.2, 150)).plot(ax=axes, label="identified")
plt.show()
