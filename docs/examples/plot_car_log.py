"""
A car's log: the scheduled model and the single-track car on a real lap
=======================================================================

The workflow of the guide page "A car's log", from Python, on the committed
race-car lap (``tests/data/race_car_250lm``: 80 s at 100 Hz, road-wheel
angle in, yaw rate and lateral acceleration out, speed 16 to 60 m/s; its
``SOURCE.md`` names the source and licence). Two models of the same samples,
the last 40 % held out:

- the speed-scheduled modal family, as ``vehid identify --schedule vx`` returns it;
- the physical single-track car (cornering stiffnesses and yaw inertia, with
  the car's mass 982 kg and its CG 1.33 m behind the front axle and 1.07 m
  ahead of the rear), as ``vehid identify --structure single-track`` returns it,

each drawn against the measured lap by its response object's ``plot()``, and
the single-track car's handling against speed, as ``vehid handling`` gives it.
"""

import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import vehid
from vehid.identification import IdentifyOptions, ReadSettings, identify, read_record
from vehid.scenarios import CarChecks, handling, identify_single_track
from vehid.vehicle.handling import HandlingResponse
from vehid.vehicle.single_track import SingleTrackConfig

# Shortened under VEHID_DOCS_QUICK=1 (the documentation test): the scheduled family of a second-order model
# with p given, ten passes, three knots and one scheduled p, instead of the command's defaults (order 4, p and
# the scheduled p chosen by cross-validation, five knots). The single-track car runs as the command runs it.
quick = os.environ.get("VEHID_DOCS_QUICK") == "1"
order, options = (2, IdentifyOptions(p=1e-5, passes=10, schedule_knots=3, schedule_p=(1e-2,))) if quick else \
    (4, IdentifyOptions())

# The log ships with the repository's tests; this path holds in a clone.
path = Path(vehid.__file__).resolve().parent / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
reading = ReadSettings(inputs=("delta",), outputs=("yawRate", "ayCG"))

# %%
# The speed-scheduled family
# --------------------------
# ``schedule="vx"`` reads the speed beside the steer and makes it the
# schedule; the checks of a car's physics need what each output measures and
# the wheelbase. The result is the command's: its text is what
# ``vehid identify ... --schedule vx`` prints.
result = identify(path, reading=reading, schedule="vx", order=order, validation=0.4, options=options,
                  checks=CarChecks(quantities=("yaw_rate", "lateral_acceleration"), wheelbase=1.33 + 1.07))
print(f"model returned: {result.returned}; held-out NRMSE fit "
      + ", ".join(f"{name} {fit:.1f} %" for name, fit in zip(reading.outputs, result.validation_fit_percent)))
family = result.scheduled.model
for knot in family.meta["knot_coverage"]:
    print(f"  knot {knot['value']:.1f} m/s: {knot['seconds']:.1f} s of data"
          + (" (extrapolated)" if knot["extrapolated"] else ""))

# %%
# Each ``plot()`` draws onto the axes it is given (without them, onto a
# Figure of its own outside pyplot). The family driven by the held-out steer along the held-out speed, from
# rest (the speed its last input), against the measured outputs (offsets removed, as the model was
# identified): :meth:`~vehid.identification.TimeResponse.plot` draws each
# output with the measurement under it.
held_out = result.plan.validation[0]
speed = result.plan.schedule.validation[0]
along_speed = held_out.replace(u=np.column_stack([held_out.u, speed]), input_names=held_out.input_names + ("vx",),
                               input_units=held_out.input_units + ("m/s",))
fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5), layout="constrained")
family.simulate(along_speed).plot(ax=axes, label="speed-scheduled family")
fig.suptitle("Held-out part of the lap: the scheduled family")
plt.show()

# %%
# The single-track car
# --------------------
# The physical model needs no offsets and no schedule of knots: its
# coefficients follow the speed by their physics. ``measured_sideslip`` checks
# its predicted sideslip against the log's measured one, without fitting it.
car = SingleTrackConfig(mass=982.0, cg_to_front_axle=1.33, cg_to_rear_axle=1.07)
single_track = identify_single_track(path, schedule="vx", config=car, validation=0.4, reading=reading,
                                     measured_sideslip="beta_true")
for estimate in single_track.parameters:
    print(f"{estimate.name}: {estimate.value:.4g} +/- {2 * estimate.std:.2g} {estimate.unit} (2 sigma)")
print("held-out NRMSE fit", [round(fit, 1) for fit in single_track.validation_fit_percent], "%")

# %%
# The car driven by the whole lap's steer along its measured speed, from
# straight running (the simulation's inputs are the steer, then the speed).
lap = read_record(path, inputs=("delta", "vx"), outputs=("yawRate", "ayCG"))
fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5), layout="constrained")
single_track.model.simulate(lap).plot(ax=axes, label="single-track car")
fig.suptitle("The whole lap: the single-track car")
plt.show()

# %%
# Its handling against speed (yaw-rate and lateral-acceleration gains per
# radian of road-wheel angle, understeer gradient in deg/g), each metric with
# a band of two standard deviations from the parameters' covariance: what ``vehid handling`` prints
# as a table, drawn by :meth:`~vehid.vehicle.handling.HandlingResponse.plot`.
metrics = handling(single_track.model, speeds=np.linspace(17.0, 60.0, 6))
fig, axes = plt.subplots(1, 3, figsize=(9, 3.2), layout="constrained")
HandlingResponse(metrics.metrics, label="single-track car").plot(ax=axes)
plt.show()
