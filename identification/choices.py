"""The named choices and default settings of the estimators, the scores and data preparation, as plain constants.

The modules that compute with them import them from here; the command line
reads them to list an option's choices and default (and check an argument
against them) without importing NumPy, SciPy or CasADi, which would delay
every ``--help`` by a second. The constraints below state, once, the values
of a setting that several options objects take
(:mod:`~vehid.identification.optionspec`).
"""

from __future__ import annotations

from vehid.identification.optionspec import Number, Numbers, OneOf

__all__ = ["HDF5_SUFFIXES", "DETRENDS", "DETREND", "SPLINE_MIN_NODES", "SPLINE_MAX_NODES", "SPLINE_NODE_COUNT",
           "SCHEDULE_KNOT_COUNT", "SCHEDULE_GRID", "JITTER_TOLERANCE", "DATA_STARTS", "START_VALUES", "START_CHOICES",
           "DISCRETIZATIONS", "COVARIANCE_FORMS", "TIMESCALES", "INITIAL_STATES", "C_PATTERNS", "SPLINE_NODES",
           "SPLINE_P", "SPLINE_PASSES", "SCHEDULE_DEFAULT_KNOTS", "SCHEDULE_MIN_KNOTS", "SCHEDULE_MAX_KNOTS",
           "SCHEDULED_DEFAULT_P", "SCHEDULED_P_GRID", "ESTIMATORS"]

#: File name endings of the HDF5 files the workbench reads and writes.
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")

#: How offsets are estimated: each record's mean, a line through each record, or none.
DETRENDS = ("mean", "linear", "none")
DETREND = OneOf(DETRENDS)

#: Largest stray of a sample time from the uniform grid accepted without resampling, as a fraction of a step.
JITTER_TOLERANCE = 0.05

#: Starts taken from the record: a subspace model of it, or modes spread across its band.
DATA_STARTS = ("data", "band")

#: Named start values: (sigma, omega, omega spread between pairs). The paper's sigma = -1 finds the
#: eigenvalues far less often than faster oscillatory modes (docs/iekf_tuning.md), hence ``default``.
START_VALUES = {
    "default": (-10.0, 10.0, 0.5),
    "paper": (-1.0, 1.0, 0.0),
}

#: Every start: the fixed ones of :data:`START_VALUES` and those taken from the data.
START_CHOICES = (*DATA_STARTS, *START_VALUES)

#: How the filter's continuous model is discretised per sample.
DISCRETIZATIONS = ("euler", "exact", "exact-zoh")

#: Covariance updates of the IEKF pass: Joseph's stabilised form or the paper's short form.
COVARIANCE_FORMS = ("joseph", "paper")

#: ``seconds``: the filter runs in the record's time unit and p is absolute (the paper);
#: ``auto``: time in samples inside the filter, p per dominant time constant
#: (see :mod:`~vehid.identification.filtering.iekf`).
TIMESCALES = ("seconds", "auto")

#: Initial states of a simulation scored against a record: zero, or estimated from its first samples.
INITIAL_STATES = ("zero", "estimate")

#: The C patterns of the paper, by name (Best & Bogdanski 2017): ``all-ones``
#: ties every state to output 1 (Table 1, and Table 2's "first row fixed");
#: ``eq18`` is the three-output, n = 5 pattern of eq. 18; ``eq19`` the
#: order-study patterns of eq. 19 (n = 3..7, three outputs); ``default`` the
#: workbench's generalisation (pairs first, outputs assigned in turn).
C_PATTERNS = ("default", "all-ones", "eq18", "eq19")

#: The built-in estimators by name (``--method``): the IEKF and the classical comparators, the keys of
#: :data:`~vehid.identification.comparators.COMPARATORS` before any other is registered.
ESTIMATORS = ("iekf", "arx", "rls", "n4sid", "output-error")

#: Nodes per spline: the paper found the symbolic model manageable up to 9.
SPLINE_MIN_NODES = 3
SPLINE_MAX_NODES = 9
SPLINE_NODE_COUNT = Number(low=SPLINE_MIN_NODES, high=SPLINE_MAX_NODES, whole=True)

#: The spline IEKF's defaults: nodes per nonlinearity, tuning parameter p, largest number of passes.
SPLINE_NODES = 5
SPLINE_P = 1e-7
SPLINE_PASSES = 60

#: Knots of a speed-scheduled modal model: the default count and its bounds.
SCHEDULE_DEFAULT_KNOTS = 5
SCHEDULE_MIN_KNOTS = 2
SCHEDULE_MAX_KNOTS = 9
SCHEDULE_KNOT_COUNT = Number(low=SCHEDULE_MIN_KNOTS, high=SCHEDULE_MAX_KNOTS, whole=True)
#: Knots given as such: finite and strictly increasing, as many as a default grid may have.
SCHEDULE_GRID = Numbers(fewest=SCHEDULE_MIN_KNOTS, most=SCHEDULE_MAX_KNOTS, increasing=True)

#: The scheduled filter's p per dominant time constant, and the values tried on validation data
#: (largest first; the default alone without them).
SCHEDULED_DEFAULT_P = 1e-2
SCHEDULED_P_GRID = (1e-2, 1e-3)
