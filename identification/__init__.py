"""Model structures, estimators and fit metrics. Knows nothing of vehicles.

Every public name below is importable from here (``from vehid.identification
import IOData``), but its module is imported only when the name is first
asked for: the command line and any script that needs one estimator do not
pay for SciPy's signal processing, CasADi and HDF5 before they use them.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
from typing import Any

from .lazy_exports import export_lazily

# submodule -> the public names it defines
_EXPORTS: dict[str, tuple[str, ...]] = {
    "dataio.archive": ("SCHEMA_VERSION", "Archive", "RunName", "RunRecord", "append_history", "open_archive",
        "read_archive", "read_history", "read_records", "read_run", "run_group", "update_archive", "write_archive",
        "write_record", "write_run"),
    "data": ("IOData", "as_records", "check_channels", "read_hdf5"),
    "dataio.readers": ("RawRecord", "read_mat", "read_mdf", "read_raw", "read_table"),
    "dataio.timebase": ("JITTER_TOLERANCE", "uniform_record"),
    "dataio.preparation": ("DETRENDS", "Preparation", "ReadSettings", "RecordOffsets", "estimate_preparation",
        "load_records", "prepare", "prepare_validation", "read_raw_records", "read_record"),
    "errors": ("ArchiveError", "DivergenceError", "ExcitationError", "InputError", "OptionError", "WorkbenchError"),
    "optionspec": ("OptionSpec", "option_specs"),
    "filtering.iekf": ("START_VALUES", "FilterState", "IEKFOptions", "IEKFResult", "PassRecord", "identify_iekf"),
    "assessment.metrics": ("FitMetrics", "fit_metrics", "nrmse_fit", "percentage_explanation", "r_squared"),
    "models.modal": ("C_PATTERNS", "ModalModel", "ModalStructure"),
    "models.protocol": ("IdentifiedModel", "Mode", "signature_mismatches"),
    "models.responses": ("FrequencyResponse", "TimeResponse"),
    "models.discrete": ("ContinuousModel", "DiscreteModel"),
    "filtering.spline_iekf": ("SplineIEKFOptions", "SplineIEKFResult", "identify_spline_iekf"),
    "filtering.greybox": ("GreyBoxModel", "GreyBoxOptions", "GreyBoxResult", "identify_greybox", "simulate_greybox"),
    "filtering.greybox_model": ("IdentifiedGreyBox",),
    "models.spline_modal": ("SplineModalModel", "SplineModalStructure"),
    "assessment.order": ("OrderAssessment", "assess_orders"),
    "models.spline": ("SplineBasis", "covering_basis", "resample"),
    "dataio.storage": ("read_group", "read_value", "write_group", "write_value"),
    "comparators": ("COMPARATORS", "ComparatorResult", "identify_with", "register_comparator"),
    "classical.ekf": ("EkfResult", "NonlinearModel", "ekf_joint"),
    "classical.gls": ("GlsResult", "estimate_gls"),
    "classical.kalman": ("KalmanResult", "SmootherResult", "kalman_filter", "kalman_predict", "kalman_update", "rts_smoother"),
    "classical.least_squares": ("ArxModel", "ArxResult", "LeastSquaresResult", "arx_regressors", "estimate_arx", "least_squares"),
    "classical.pencil": ("PencilEstimate", "PencilModel", "estimate_pencil"),
    "classical.recursive": ("RecursiveResult", "estimate_arx_recursive", "recursive_least_squares", "rls_step"),
    "classical.factorised": ("sqrt_step", "ud_step"),
    "models.statespace": ("balanced_truncation", "continuous_to_discrete", "discrete_to_continuous", "hold_state_shift",
        "modal_structure_for", "to_modal"),
    "classical.subspace": ("SubspaceResult", "estimate_subspace", "largest_subspace_order"),
    "assessment.residuals": ("ResidualTests", "residual_tests"),
    "assessment.uncertainty": ("fit_covariance",),
    "models.delta_method": ("FrequencyResponseBand", "ModelUncertainty", "ModeEstimate", "model_uncertainty"),
    "assessment.segments": ("BlockJackknife", "SegmentConsistency", "UncertaintyMethod", "block_jackknife",
        "pair_agreement", "refit_replicates", "segment_consistency"),
    "models.scheduled": ("ModeMatch", "ScheduledModalModel", "schedule_models"),
    "filtering.scheduled_iekf": ("ScheduledIEKFOptions", "ScheduledIEKFResult", "identify_scheduled"),
    "pipeline": ("IdentifyOptions", "Identification", "identify"),
}
# The modules' former flat names (before the sub-packages by role), so that code importing
# ``vehid.identification.modal`` keeps working: each resolves to the very module object of its new
# place, so classes, isinstance checks and pickles agree whichever name imported them.
_FORMER_MODULES: dict[str, str] = {
    "protocol": "models.protocol",
    "statespace": "models.statespace",
    "discrete": "models.discrete",
    "modal": "models.modal",
    "spline": "models.spline",
    "spline_modal": "models.spline_modal",
    "scheduled": "models.scheduled",
    "iekf": "filtering.iekf",
    "iekf_pass": "filtering.iekf_pass",
    "iekf_kernel": "filtering.iekf_kernel",
    "filter_models": "filtering.filter_models",
    "rinse": "filtering.rinse",
    "start": "filtering.start",
    "spline_iekf": "filtering.spline_iekf",
    "scheduled_iekf": "filtering.scheduled_iekf",
    "greybox": "filtering.greybox",
    "iekf_archive": "dataio.iekf_archive",
    "least_squares": "classical.least_squares",
    "recursive": "classical.recursive",
    "gls": "classical.gls",
    "kalman": "classical.kalman",
    "ekf": "classical.ekf",
    "pencil": "classical.pencil",
    "factorised": "classical.factorised",
    "subspace": "classical.subspace",
    "metrics": "assessment.metrics",
    "multirecord": "assessment.multirecord",
    "validation": "assessment.validation",
    "residuals": "assessment.residuals",
    "uncertainty": "assessment.uncertainty",
    "order": "assessment.order",
    "readers": "dataio.readers",
    "timebase": "dataio.timebase",
    "preparation": "dataio.preparation",
    "archive": "dataio.archive",
    "archive_safety": "dataio.archive_safety",
    "storage": "dataio.storage",
}


class _FormerModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves a former module name to its module's new place."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        package, _, name = fullname.rpartition(".")
        if package != __name__ or name not in _FORMER_MODULES:
            return None
        return importlib.util.spec_from_loader(fullname, self)

    def create_module(self, spec: Any) -> Any:
        module = importlib.import_module(f"{__name__}.{_FORMER_MODULES[spec.name.rpartition('.')[2]]}")
        spec.loader_state = module.__spec__
        return module

    def exec_module(self, module: Any) -> None:
        # The module ran at its new place; the import system has just given it the former name's spec,
        # which would misplace its own relative imports: it gets its own spec back.
        module.__spec__ = module.__spec__.loader_state


if not any(isinstance(finder, _FormerModuleFinder) for finder in sys.meta_path):
    sys.meta_path.append(_FormerModuleFinder())

export_lazily(__name__, _EXPORTS)


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
    "OptionError",
    "WorkbenchError",
    "OptionSpec",
    "option_specs",
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
    "signature_mismatches",
    "FrequencyResponse",
    "TimeResponse",
    "ContinuousModel",
    "DiscreteModel",
    "SplineModalModel",
    "SplineModalStructure",
    "SplineIEKFOptions",
    "SplineIEKFResult",
    "identify_spline_iekf",
    "GreyBoxModel",
    "GreyBoxOptions",
    "GreyBoxResult",
    "identify_greybox",
    "simulate_greybox",
    "IdentifiedGreyBox",
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
    "hold_state_shift",
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
    "ModeMatch",
    "ScheduledModalModel",
    "schedule_models",
    "ScheduledIEKFOptions",
    "ScheduledIEKFResult",
    "identify_scheduled",
    "IdentifyOptions",
    "Identification",
    "identify",
]
