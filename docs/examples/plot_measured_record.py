"""
A measured record: the hair dryer
=================================

A published laboratory record (DaISy, the hair dryer: heater voltage in,
outlet air temperature out, 1000 samples at 0.08 s) read from its raw file
and identified by the automatic pipeline that ``vehid identify`` runs: the
offsets removed, the last 30 % held out, p chosen by cross-validation, the
start or the filter's model returned, the initial state of each scored
record estimated. The call below gives the model and the scores of::

    vehid identify tests/data/dryer/dryer.dat --inputs 1 --outputs 2 --dt 0.08 \\
        --order 2 --validation 0.3

N4SID, run through the same pipeline, is the comparator.
"""

from pathlib import Path

import matplotlib.pyplot as plt

import vehid
from vehid.identification import IdentifyOptions, identify, read_record
from vehid.identification.assessment.validation import predict

# The records ship with the repository's tests; this path holds in a clone.
path = Path(vehid.__file__).resolve().parent / "tests" / "data" / "dryer" / "dryer.dat"

# %%
# Read the columns as published (no header: columns by number) and identify.
# Everything the command decides by itself is in the typed result: the
# decisions with their margins, the warnings, the scores per data set.
record = read_record(path, inputs=("1",), outputs=("2",), dt=0.08)
result = identify(record, order=2, validation=0.3)
print("held-out NRMSE fit", [round(fit, 1) for fit in result.validation_fit_percent], "%")
for decision in result.decisions:
    print(f"{decision.name}: {decision.choice} (runner-up {decision.runner_up}, {decision.measure})")
print("warnings:", list(result.warnings) or "none")

# %%
# The comparator on the same split and with the same scoring.
subspace = identify(record, order=2, validation=0.3, options=IdentifyOptions(method="n4sid"))
print("N4SID held-out NRMSE fit", [round(fit, 1) for fit in subspace.validation_fit_percent], "%")

# %%
# The held-out samples (offsets removed as the pipeline removed them) against
# both models, each from its estimated initial state as the scores take it.
held_out = result.plan.validation[0]
fig, axis = plt.subplots(figsize=(8, 3.5), layout="constrained")
axis.plot(held_out.t, held_out.y[:, 0], color="black", label="measured")
for name, identified in (("IEKF pipeline", result), ("N4SID", subspace)):
    axis.plot(held_out.t, predict(identified.model, held_out)[:, 0], "--", label=name)
axis.set_xlabel("time [s]")
axis.set_ylabel("outlet temperature\n(offset removed)")
axis.legend()
plt.show()
