"""The named choices of the estimators and scores, defined here once and importable without the numerical stack.

The modules that act on a choice import its names from here, so that a command
line can list them in its help (and check an argument against them) without
loading NumPy, SciPy or CasADi.
"""

from __future__ import annotations

__all__ = ["DATA_STARTS", "START_VALUES", "START_CHOICES", "TIMESCALES", "DISCRETIZATIONS", "COVARIANCE_FORMS",
           "C_PATTERNS", "INITIAL_STATES", "SCHEDULE_DEFAULT_KNOTS", "SCHEDULE_MIN_KNOTS", "SCHEDULE_MAX_KNOTS",
           "SCHEDULED_DEFAULT_P", "SCHEDULED_P_GRID"]

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

#: ``seconds``: the filter runs in the record's time unit and p is absolute (the paper);
#: ``auto``: time in samples inside the filter, p per dominant time constant.
TIMESCALES = ("seconds", "auto")

#: The filter's discretisations of the continuous model.
DISCRETIZATIONS = ("euler", "exact", "exact-zoh")

#: The covariance update: Joseph's stabilised form, or the paper's.
COVARIANCE_FORMS = ("joseph", "paper")

#: The output-matrix patterns of the modal structure.
C_PATTERNS = ("default", "all-ones", "eq18", "eq19")

#: How a linear model's simulation starts when it is scored: from rest, or from a least-squares state.
INITIAL_STATES = ("zero", "estimate")

#: Knots of a speed-scheduled modal model: the default count and its bounds.
SCHEDULE_DEFAULT_KNOTS = 5
SCHEDULE_MIN_KNOTS = 2
SCHEDULE_MAX_KNOTS = 9

#: The scheduled filter's p per dominant time constant, and the values tried on validation data
#: (largest first; the default alone without them).
SCHEDULED_DEFAULT_P = 1e-2
SCHEDULED_P_GRID = (1e-2, 1e-3)
