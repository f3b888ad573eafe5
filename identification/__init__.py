"""Model structures, estimators and fit metrics. Knows nothing of vehicles."""

from .archive import (
    SCHEMA_VERSION,
    Archive,
    RunRecord,
    append_history,
    open_archive,
    read_archive,
    read_history,
    read_records,
    read_run,
    run_group,
    update_archive,
    write_archive,
    write_record,
    write_run,
)
from .data import IOData, read_csv, read_hdf5
from .errors import ArchiveError, DivergenceError, ExcitationError, InputError, WorkbenchError
from .iekf import START_VALUES, FilterState, IEKFOptions, IEKFResult, PassRecord, identify_iekf
from .metrics import FitMetrics, fit_metrics, nrmse_fit, percentage_explanation, r_squared
from .modal import C_PATTERNS, ModalModel, ModalStructure
from .order import OrderAssessment, assess_orders
from .spline import SplineBasis, covering_basis, resample
from .storage import TRUSTED_PACKAGES, read_group, read_value, write_group, write_value

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
    "C_PATTERNS",
    "ModalModel",
    "ModalStructure",
    "START_VALUES",
    "FilterState",
    "IEKFOptions",
    "IEKFResult",
    "PassRecord",
    "identify_iekf",
    "OrderAssessment",
    "assess_orders",
    "SplineBasis",
    "covering_basis",
    "resample",
    "SCHEMA_VERSION",
    "Archive",
    "RunRecord",
    "write_archive",
    "update_archive",
    "open_archive",
    "read_archive",
    "write_record",
    "read_records",
    "run_group",
    "write_run",
    "read_run",
    "append_history",
    "read_history",
    "TRUSTED_PACKAGES",
    "write_value",
    "read_value",
    "write_group",
    "read_group",
]
