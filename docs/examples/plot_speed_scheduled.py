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

The command line does this and more (p chosen on the held-out part, the
family returned only where it validates better than the unscheduled model,
modes with their standard deviations in the JSON, each knot's data and the
checks of its physics)::

    vehid identify tests/data/race_car_250lm/20140222_01_01_03_250lm.csv \\
        --inputs delta --outputs yawRate,ayCG --schedule vx --validation 0.4 \\
        --quantities yaw_rate,lateral_acceleration --lf 1.33 --lr 1.07

A fit is not yet a car: the last section checks the family's physics at its
knots and says which knots rest on too few samples.
"""

import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import vehid
from vehid.identification import (
    IEKFOptions,
    ModalStructure,
    identify_iekf,
    nrmse_fit,
    prepare,
    prepare_validation,
    read_record,
)
from vehid.identification.filtering.scheduled_iekf import ScheduledIEKFOptions, identify_scheduled
from vehid.scenarios.plausibility_checks import model_findings
from vehid.vehicle.plausibility import steer_band_hz

# Shortened under VEHID_DOCS_QUICK=1 (the documentation test): fewer passes.
quick = os.environ.get("VEHID_DOCS_QUICK") == "1"
passes, scheduled_passes, refine = (8, 4, 2) if quick else (40, 40, 10)

# The log ships with the repository's tests; this path holds in a clone.
path = Path(vehid.__file__).resolve().parent / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"

# %%
# Read the speed as a further column, then set it aside as the schedule: it
# is a measured condition of the car, not an input the model responds to.
raw = read_record(path, inputs=("delta", "vx"), outputs=("yawRate", "ayCG"))
speed = raw.u[:, 1]
raw = raw.select_inputs(("delta",))
raw_estimation, raw_validation = raw.split(0.6)
cut = raw_estimation.n_samples
(estimation,), preparation = prepare(raw_estimation)
validation = prepare_validation(raw_validation, preparation)
speed_estimation, speed_validation = speed[:cut], speed[cut:]
print(f"speed {speed.min():.1f} to {speed.max():.1f} m/s; {estimation.n_samples} estimation and "
      f"{validation.n_samples} held-out samples")

# %%
# The unscheduled start: a second-order modal model (one mode) by the IEKF
# with the settings that do not depend on units or record length.
start = identify_iekf(estimation, ModalStructure.default(2, 1, 2), options=IEKFOptions.invariant(passes=passes)).model

# %%
# The family: the start's coefficients at every knot of a grid spread over
# the speeds the estimation part covers, then moved by the filter.
result = identify_scheduled(estimation, speed_estimation, start, variable="vx",
                            options=ScheduledIEKFOptions(passes=scheduled_passes, min_passes=scheduled_passes // 2,
                                                         refine_iterations=refine))
family = result.model
print("knots at", ", ".join(f"{v:.1f}" for v in family.grid), "m/s")
# Each knot's samples (those nearer it than any other knot) and the steer's RMS there: where they are too
# few to say its modes, its ordinates are extrapolated from its neighbours' data.
for knot in family.meta["knot_coverage"]:
    print(f"  {knot['value']:.1f} m/s: {knot['seconds']:.1f} s of data, steer RMS {knot['excitation']:.2f} of the "
          f"lap's" + (" (extrapolated)" if knot["extrapolated"] else ""))

# %%
# Both on the held-out 40 %, simulated from rest along the measured speed.
fits = {
    "unscheduled": nrmse_fit(validation.y, start.simulate_outputs(validation.u, validation.dt)),
    "speed-scheduled": nrmse_fit(validation.y, family.simulate_outputs(validation.u, validation.dt,
                                                                       schedule=speed_validation)),
}
for name, fit in fits.items():
    print(f"{name}: held-out NRMSE fit yaw rate {fit[0]:.1f} %, lateral acceleration {fit[1]:.1f} %")

# %%
# The mode against speed, with two standard deviations from the filter's
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
for value in (family.grid[0], float(np.median(speed_estimation)), family.grid[-1]):
    family.frequency_response(np.logspace(-1, 1, 120), schedule=value).plot(ax=axes, label=f"{value:.0f} m/s")
fig.suptitle("Steer to yaw rate and lateral acceleration, at three speeds")
plt.show()

# %%
# Is it a car? In a steady turn the lateral acceleration is the speed times
# the yaw rate, a car's yaw rate does not answer the steer at once, its modes
# are damped: each knot is checked against published ranges
# (:mod:`vehid.vehicle.plausibility`), with the car's wheelbase of 2.4 m.
# Where the car seldom holds a steady turn, or a knot has few samples, the
# family's steady gains are not a car's, and the checks say so.
findings = model_findings(family, list(family.grid), roles={"yaw_rate": 0, "lateral_acceleration": 1}, wheelbase=2.4,
                          band_hz=steer_band_hz(estimation.u[:, 0], estimation.dt),
                          top_speed=float(speed_estimation.max()))
for finding in findings:
    print(finding.warning())
print(f"{len(findings)} implausible results")
