"""Model structures, estimators and fit metrics. Knows nothing of vehicles."""

from .archive import (
    SCHEMA_VERSION,
    Archive,
    RunName,
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
from .data import IOData, as_records, check_channels, read_hdf5
from .readers import RawRecord, read_mat, read_mdf, read_raw, read_table
from .timebase import JITTER_TOLERANCE, uniform_record
from .preparation import (DETRENDS, Preparation, ReadSettings, RecordOffsets, estimate_preparation, load_records,
                          prepare, prepare_validation, read_raw_records, read_record)
from .errors import ArchiveError, DivergenceError, ExcitationError, InputError, WorkbenchError
from .iekf import START_VALUES, FilterState, IEKFOptions, IEKFResult, PassRecord, identify_iekf
from .metrics import FitMetrics, fit_metrics, nrmse_fit, percentage_explanation, r_squared
from .modal import C_PATTERNS, ModalModel, ModalStructure
from .protocol import IdentifiedModel, Mode
from .discrete import DiscreteModel
from .spline_iekf import SplineIEKFOptions, SplineIEKFResult, identify_spline_iekf
from .spline_modal import SplineModalModel, SplineModalStructure
from .order import OrderAssessment, assess_orders
from .spline import SplineBasis, covering_basis, resample
from .storage import read_group, read_value, write_group, write_value
from .comparators import (COMPARATORS, ComparatorResult, identify_with, register_comparator)
from .ekf import EkfResult, NonlinearModel, ekf_joint
from .gls import GlsResult, estimate_gls
from .kalman import KalmanResult, SmootherResult, kalman_filter, kalman_predict, kalman_update, rts_smoother
from .least_squares import ArxModel, ArxResult, LeastSquaresResult, arx_regressors, estimate_arx, least_squares
from .pencil import PencilEstimate, PencilModel, estimate_pencil
from .recursive import RecursiveResult, estimate_arx_recursive, recursive_least_squares, rls_step
from .factorised import sqrt_step, ud_step
from .statespace import (balanced_truncation, continuous_to_discrete, discrete_to_continuous,
                         modal_structure_for, to_modal)
from .subspace import SubspaceResult, estimate_subspace, largest_subspace_order
from .residuals import ResidualTests, residual_tests
from .uncertainty import FrequencyResponseBand, ModelUncertainty, ModeEstimate, model_uncertainty

__all__ = [
    "IOData",
    "read_hdf5",
    "as_records",
    "check_channels",
    "RawRecord",
    "read_raw",
    "read_table",
    "read_mat",
    "read_mdf",
    "JITTER_TOLERANCE",
    "uniform_record",
    "DETRENDS",
    "ReadSettings",
    "RecordOffsets",
    "Preparation",
    "read_record",
    "estimate_preparation",
    "prepare",
    "load_records",
    "read_raw_records",
    "prepare_validation",
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
    "IdentifiedModel",
    "Mode",
    "DiscreteModel",
    "SplineModalModel",
    "SplineModalStructure",
    "SplineIEKFOptions",
    "SplineIEKFResult",
    "identify_spline_iekf",
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
    "RunName",
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
    "write_value",
    "read_value",
    "write_group",
    "read_group",
    "LeastSquaresResult",
    "least_squares",
    "ArxModel",
    "ArxResult",
    "arx_regressors",
    "estimate_arx",
    "RecursiveResult",
    "rls_step",
    "recursive_least_squares",
    "estimate_arx_recursive",
    "sqrt_step",
    "ud_step",
    "GlsResult",
    "estimate_gls",
    "KalmanResult",
    "SmootherResult",
    "kalman_predict",
    "kalman_update",
    "kalman_filter",
    "rts_smoother",
    "NonlinearModel",
    "EkfResult",
    "ekf_joint",
    "PencilModel",
    "PencilEstimate",
    "estimate_pencil",
    "continuous_to_discrete",
    "discrete_to_continuous",
    "modal_structure_for",
    "to_modal",
    "balanced_truncation",
    "SubspaceResult",
    "estimate_subspace",
    "largest_subspace_order",
    "COMPARATORS",
    "ComparatorResult",
    "identify_with",
    "register_comparator",
    "ResidualTests",
    "residual_tests",
    "ModeEstimate",
    "ModelUncertainty",
    "FrequencyResponseBand",
    "model_uncertainty",
]
