"""
A measured record: the hair dryer
=================================

A published laboratory record (DaISy, the hair dryer: heater voltage in,
outlet air temperature out, 1000 samples at 0.08 s) read from its raw file,
its offsets removed, the last 30 % held out. A fourth-order model is
identified by N4SID and by the IEKF, and both are scored on the
held-out samples by the NRMSE fit of MATLAB's ``compare``.

The command line does this and more (p by cross-validation, the choice
between start and filter, the initial state by least squares)::

    vehid identify tests/data/dryer/dryer.dat --inputs 1 --outputs 2 --dt 0.08 \\
        --order 4 --validation 0.3
"""

from pathlib import Path

import matplotlib.pyplot as plt

import vehid
from vehid.identification import (
    IEKFOptions,
    ModalStructure,
    identify_iekf,
    identify_with,
    nrmse_fit,
    prepare,
    prepare_validation,
    read_record,
)

# The records ship with the repository's tests; this path holds in a clone.
path = Path(vehid.__file__).resolve().parent / "tests" / "data" / "dryer" / "dryer.dat"

# %%
# Read the columns as published (no header: columns by number), cut off the
# held-out part, then remove the estimation part's means from both.
raw = read_record(path, inputs=("1",), outputs=("2",), dt=0.08)
raw_estimation, raw_validation = raw.split(0.7)
(estimation,), preparation = prepare(raw_estimation)
validation = prepare_validation(raw_validation, preparation)
print(estimation.n_samples, "estimation and", validation.n_samples, "held-out samples")

# %%
# N4SID as a comparator, and the IEKF with the settings that do not depend
# on units or record length (signals divided by their RMS, the start from the
# data, time counted in samples inside the filter).
subspace = identify_with(estimation, method="n4sid", order=4)
filtered = identify_iekf(estimation, ModalStructure.default(4, 1, 1), options=IEKFOptions.invariant(passes=20))
models = {"N4SID": subspace.model, "IEKF": filtered.model}
for name, model in models.items():
    fit = nrmse_fit(validation.y, model.simulate_outputs(validation.u, validation.dt))
    print(f"{name}: held-out NRMSE fit {fit[0]:.1f} %")

# %%
# The held-out samples against both models, simulated from rest.
fig, axis = plt.subplots(figsize=(8, 3.5), layout="constrained")
axis.plot(validation.t, validation.y[:, 0], color="black", label="measured")
for name, model in models.items():
    axis.plot(validation.t, model.simulate_outputs(validation.u, validation.dt)[:, 0], "--", label=name)
axis.set_xlabel("time [s]")
axis.set_ylabel("outlet temperature\n(offset removed)")
axis.legend()
plt.show()
