"""
A speed-scheduled model of a real race car
==========================================

A real race car's lap (the committed log ``tests/data/race_car_250lm``: 80 s at
100 Hz, road-wheel angle in, yaw rate and lateral acceleration out, speed from
16 to 60 m/s; its ``SOURCE.md`` names the source and licence). Every gain and
mode of a car moves with its speed, so one linear model cannot follow a lap.
Here the modal coefficients are piecewise-linear splines in the measured speed
and the IEKF estimates their ordinates at the knots, starting from an
unscheduled model of the same samples. The last 40 % of the lap is held out.

One call of :func:`~vehid.identification.identify` with ``schedule`` does what
the command line does (p chosen on the held-out part, the family returned only
where it validates better than the unscheduled model, modes with their
standard deviations, each knot's data and the checks of its physics)::

    vehid identify tests/data/race_car_250lm/20140222_01_01_03_250lm.csv \\
        --inputs delta --outputs yawRate,ayCG --schedule vx --validation 0.4 \\
        --quantities yaw_rate,lateral_acceleration --lf 1.33 --lr 1.07

A fit is not yet a car: the last section reads the checks of the family's
physics at its knots, which say which knots rest on too few samples.
"""

import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import vehid
from vehid.identification import IdentifyOptions, ReadSettings, identify
from vehid.scenarios import CarChecks

# Shortened under VEHID_DOCS_QUICK=1 (the documentation test): a second-order model with p given, ten passes,
# three knots and one scheduled p, instead of the command's defaults (order 4, p and the scheduled p chosen by
# cross-validation, five knots).
quick = os.environ.get("VEHID_DOCS_QUICK") == "1"
order, options = (2, IdentifyOptions(p=1e-5, passes=10, schedule_knots=3, schedule_p=(1e-2,))) if quick else \
    (4, IdentifyOptions())

# The log ships with the repository's tests; this path holds in a clone.
path = Path(vehid.__file__).resolve().parent / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"

# %%
# The speed is read beside the steer and set aside as the schedule: it is a
# measured condition of the car, not an input the model responds to, and it is
# never offset. The checks of a car's physics need to know what each output
# measures and the car's wheelbase (1.33 + 1.07 m).
result = identify(path, reading=ReadSettings(inputs=("delta",), outputs=("yawRate", "ayCG")), schedule="vx",
                  order=order, validation=0.4, options=options, min_speed=5.0,
                  checks=CarChecks(quantities=("yaw_rate", "lateral_acceleration"), wheelbase=1.33 + 1.07))
family = result.scheduled.model
print(f"model returned: {result.returned}")
print("knots at", ", ".join(f"{v:.1f}" for v in family.grid), "m/s")
# Each knot's samples (those nearer it than any other knot) and the steer's RMS there: where they are too
# few to say its modes, its ordinates are extrapolated from its neighbours' data.
for knot in family.meta["knot_coverage"]:
    print(f"  {knot['value']:.1f} m/s: {knot['seconds']:.1f} s of data, steer RMS {knot['excitation']:.2f} of the "
          f"lap's" + (" (extrapolated)" if knot["extrapolated"] else ""))

# %%
# Both on the held-out 40 %, scored by the run's one rule (each simulated along
# the measured speed, its initial state estimated): the decision ``schedule``
# says which is returned and by what margin.
scheduled = result.scheduled.summary
fits = {"unscheduled": scheduled["unscheduled"]["validation_fit_percent"],
        "speed-scheduled": scheduled["validation_fit_percent"]}
for name, fit in fits.items():
    print(f"{name}: held-out NRMSE fit yaw rate {fit[0]:.1f} %, lateral acceleration {fit[1]:.1f} %")
(decision,) = [decision for decision in result.decisions if decision.name == "schedule"]
print(f"returned: {decision.choice} ({decision.score:.2f} against {decision.runner_up_score:.2f}; {decision.rule})")

# %%
# The first mode against speed, with two standard deviations from the
# covariance of the ordinates (the delta method, knot by knot).
speeds = np.linspace(family.grid[0], family.grid[-1], 25)
modes = [at["modes"][0] for at in family.modes_at(speeds)]
frequency = np.array([m["frequency_hz"] for m in modes])
frequency_std = np.array([m["frequency_hz_std"] for m in modes])
damping = np.array([m["damping"] for m in modes])
damping_std = np.array([m["damping_std"] for m in modes])

fig, (top, bottom) = plt.subplots(2, 1, sharex=True, figsize=(7, 5), layout="constrained")
top.plot(speeds, frequency, color="C0")
top.fill_between(speeds, frequency - 2 * frequency_std, frequency + 2 * frequency_std, color="C0", alpha=0.25)
top.set_ylabel("natural frequency [Hz]")
bottom.plot(speeds, damping, color="C1")
bottom.fill_between(speeds, damping - 2 * damping_std, damping + 2 * damping_std, color="C1", alpha=0.25)
bottom.set_ylabel("damping ratio")
bottom.set_xlabel("speed [m/s]")
for axis in (top, bottom):
    axis.plot(family.grid, np.interp(family.grid, speeds, frequency if axis is top else damping), "o",
              color="black", label="knots")
top.legend()
plt.show()

# %%
# At each value of its schedule the family is a linear model: its frequency
# response at the slowest knot, the middle of the lap's speeds and the
# fastest knot, drawn onto one pair of axes per output.
fig, axes = plt.subplots(2, 2, sharex=True, figsize=(8, 5), layout="constrained")
for value in (family.grid[0], float(np.median(result.plan.schedule.estimation[0])), family.grid[-1]):
    family.frequency_response(np.logspace(-1, 1, 120), schedule=value).plot(ax=axes, label=f"{value:.0f} m/s")
fig.suptitle("Steer to yaw rate and lateral acceleration, at three speeds")
plt.show()

# %%
# Is it a car? In a steady turn the lateral acceleration is the speed times
# the yaw rate, a car's yaw rate does not answer the steer at once, its modes
# are damped: the model returned is checked against published ranges
# (:mod:`vehid.vehicle.plausibility`), a family at each of its knots. Where the
# car seldom holds a steady turn, or a knot has few samples, the family's
# steady gains are not a car's, and the checks say so, each as a warning.
for finding in result.plausibility or ():
    print(finding.warning())
print(f"{len(result.plausibility or ())} implausible results; {len(result.warnings)} warnings in all")
