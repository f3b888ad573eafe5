"""Model structures, estimators and fit metrics. Knows nothing of vehicles."""

from .data import IOData, read_csv, read_hdf5
from .errors import ArchiveError, DivergenceError, ExcitationError, InputError, WorkbenchError
from .metrics import FitMetrics, fit_metrics, nrmse_fit, percentage_explanation, r_squared
from .spline import SplineBasis, covering_basis, resample

__all__ = [
    "IOData",
    "read_csv",
    "read_hdf5",
    "ArchiveError",
    "DivergenceError",
    "ExcitationError",
    "InputError",
    "WorkbenchError",
    "FitMetrics",
    "fit_metrics",
    "nrmse_fit",
    "percentage_explanation",
    "r_squared",
    "SplineBasis",
    "covering_basis",
    "resample",
]
