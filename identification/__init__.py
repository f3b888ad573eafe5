"""Model structures, estimators and fit metrics. Knows nothing of vehicles."""

from .comparators import (COMPARATORS, ComparatorResult, identify_with, register_comparator)
from .data import IOData, read_csv, read_hdf5
from .ekf import EkfResult, NonlinearModel, ekf_joint
from .errors import ArchiveError, DivergenceError, ExcitationError, InputError, WorkbenchError
from .gls import GlsResult, estimate_gls
from .kalman import KalmanResult, SmootherResult, kalman_filter, kalman_predict, kalman_update, rts_smoother
from .least_squares import ArxModel, ArxResult, LeastSquaresResult, arx_regressors, estimate_arx, least_squares
from .metrics import FitMetrics, fit_metrics, nrmse_fit, percentage_explanation, r_squared
from .modal import ModalModel, ModalStructure
from .pencil import PencilEstimate, PencilModel, estimate_pencil
from .recursive import RecursiveResult, estimate_arx_recursive, recursive_least_squares, rls_step
from .factorised import sqrt_step, ud_step
from .statespace import (balanced_truncation, continuous_to_discrete, discrete_to_continuous,
                         modal_structure_for, to_modal)
from .subspace import SubspaceResult, estimate_subspace

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
    "ModalModel",
    "ModalStructure",
    # classical estimators (seed appendix A.2-A.5)
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
    # comparators beside the IEKF
    "COMPARATORS",
    "ComparatorResult",
    "identify_with",
    "register_comparator",
]
