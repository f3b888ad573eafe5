"""The named choices and default settings of the estimators and of data preparation, as plain constants.

The modules that compute with them import them from here; the command line
reads them to list an option's choices and default without importing NumPy,
SciPy or CasADi, which would delay every ``--help`` by a second.
"""

from __future__ import annotations

__all__ = ["DETRENDS", "JITTER_TOLERANCE", "DISCRETIZATIONS", "COVARIANCE_FORMS", "TIMESCALES", "INITIAL_STATES",
           "C_PATTERNS", "SPLINE_NODES", "SPLINE_P", "SPLINE_PASSES"]

#: How offsets are estimated: each record's mean, a line through each record, or none.
DETRENDS = ("mean", "linear", "none")

#: Largest stray of a sample time from the uniform grid accepted without resampling, as a fraction of a step.
JITTER_TOLERANCE = 0.05

#: How the filter's continuous model is discretised per sample.
DISCRETIZATIONS = ("euler", "exact", "exact-zoh")

#: Covariance updates of the IEKF pass: Joseph's stabilised form or the paper's short form.
COVARIANCE_FORMS = ("joseph", "paper")

#: ``seconds``: the filter runs in the record's time unit and p is absolute (the paper);
#: ``auto``: time in samples inside the filter, p per dominant time constant (see :mod:`~vehid.identification.filtering.iekf`).
TIMESCALES = ("seconds", "auto")

#: Initial states of a simulation scored against a record: zero, or estimated from its first samples.
INITIAL_STATES = ("zero", "estimate")

#: The C patterns of the paper, by name (Best & Bogdanski 2017): ``all-ones``
#: ties every state to output 1 (Table 1, and Table 2's "first row fixed");
#: ``eq18`` is the three-output, n = 5 pattern of eq. 18; ``eq19`` the
#: order-study patterns of eq. 19 (n = 3..7, three outputs); ``default`` the
#: workbench's generalisation (pairs first, outputs assigned in turn).
C_PATTERNS = ("default", "all-ones", "eq18", "eq19")

#: The spline IEKF's defaults: nodes per nonlinearity, tuning parameter p, largest number of passes.
SPLINE_NODES = 5
SPLINE_P = 1e-7
SPLINE_PASSES = 60
