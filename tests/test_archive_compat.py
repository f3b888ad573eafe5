"""Archives written before the codec registry still read and report; every registered type round-trips.

The fixtures in tests/data/archives were written by the workbench while
stored values named their Python classes (README.md there names the
commands). The expected report files are those the reader of that time drew
from them: a reader that loses a run, a record or a model loses a figure.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import casadi as ca
import h5py
import numpy as np
import pytest
import scipy.signal

from vehid.identification.dataio import archive as archive_module
from vehid.identification.dataio import storage
from vehid.identification.dataio.archive import read_archive
from vehid.identification.dataio.archive_safety import write_checksums
from vehid.identification import ArxModel, DiscreteModel, IOData, estimate_subspace
from vehid.identification.models.discrete import ContinuousModel
from vehid.identification.classical.pencil import PencilModel
from vehid.identification.models.scheduled import schedule_models
from vehid.identification.models.statespace import continuous_to_discrete
from vehid.identification.filtering.spline_iekf import SplineIEKFOptions
from vehid.identification.dataio.storage import read_value, write_value
from vehid.vehicle.linearize import linearize
from vehid.vehicle.parameters import AeroParameters, baseline, saloon
from vehid.vehicle.single_track import IdentifiedSingleTrack, SingleTrackConfig
from conftest import run_vehid

ARCHIVES = Path(__file__).parent / "data" / "archives"

IDENTIFY_FIGURES = {"bode", "eigenvalues", "fits_identification"}
EXPECTED_FILES = {
    "identify_iekf.h5": IDENTIFY_FIGURES | {
        "convergence_iekf", "innovation_consistency_iekf", "parameters_iekf", "residual_tests_identification_iekf",
        "residual_tests_identification_nonlinear", "residuals_identification_iekf",
        "residuals_identification_nonlinear", "report.pdf", "summary.md"},
    "identify_n4sid.h5": IDENTIFY_FIGURES | {
        "residual_tests_identification_n4sid", "residuals_identification_n4sid", "report.pdf", "summary.md"},
    "envelope.h5": {"bode", "eigenvalues", "report.pdf", "summary.md"},
    "handling_study.h5": {
        "bode", "eigenvalues", "fits_identification", "fits_validation", "linear_convergence", "linear_parameters",
        "mode_amplitude", "nonlinear_convergence", "orders", "residual_tests_linear", "residual_tests_nonlinear",
        "residuals", "splines", "nonlinear_n2.casadi", "report.pdf", "table.md"},
}


def _stems(files):
    return {Path(f).stem if f.endswith(".png") else Path(f).name for f in files}


@pytest.mark.parametrize("name", sorted(EXPECTED_FILES))
def test_an_archive_written_before_schemas_reports(name, tmp_path):
    out = tmp_path / "report"
    done = run_vehid("report", ARCHIVES / name, "--out", out, "--dpi", "30", "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert _stems(summary["files"]) == EXPECTED_FILES[name]
    assert all(Path(f).stat().st_size > 0 for f in summary["files"])


def test_old_models_read_back_as_they_were_stored():
    archive = read_archive(ARCHIVES / "identify_iekf.h5")
    model = archive.runs["iekf"].model
    with h5py.File(ARCHIVES / "identify_iekf.h5", "r") as handle:  # the stored matrices, read without any codec
        assert handle["runs/iekf/model"].attrs["vehid_class"] == "identification.modal:ModalModel"
        assert np.array_equal(model.A, np.asarray(handle["runs/iekf/model/A"][...]))
    assert archive.config.passes == 3 and archive.runs["nonlinear"].model.structure.linear.n == 2


def _legacy_values():
    """Every value stored in the fixtures under a class path, read back, by schema."""
    values = {}
    for path in sorted(ARCHIVES.glob("*.h5")):
        with h5py.File(path, "r") as handle:
            def visit(name, member):
                path_attr = member.attrs.get("dataclass", member.attrs.get("vehid_class"))
                if isinstance(member, h5py.Group) and path_attr is not None:
                    parent, _, leaf = name.rpartition("/")
                    value = read_value(handle[parent] if parent else handle, leaf)
                    values.setdefault(storage.LEGACY_CLASS_PATHS[str(path_attr)], value)
            handle.visititems(visit)
    return values


def _same(a, b) -> bool:
    if isinstance(a, (np.generic, int, float, complex)) and not isinstance(a, np.ndarray):
        return a == b or (a != a and b != b)  # NumPy scalars come back as Python numbers, by design
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc")
    if isinstance(a, ca.Function):  # a grey-box model's: the same algorithm, names and all
        return a.serialize() == b.serialize()
    if dataclasses.is_dataclass(a):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a) if f.init)
    if hasattr(a, "to_dict"):
        return _same(a.to_dict(), b.to_dict())
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return a == b or (a != a and b != b)


def test_every_registered_type_round_trips(tmp_path):
    values = _legacy_values()
    vehicle = baseline()
    linear = values["modal_model"]
    values.update({
        "modal_structure": linear.structure,
        "spline_modal_structure": values["spline_modal_model"].structure,
        "scheduled_modal_model": schedule_models({10.0: linear, 20.0: linear}),
        "spline_iekf_options": SplineIEKFOptions(),
        "io_data": read_archive(ARCHIVES / "identify_n4sid.h5").records["identification"],
        "vehicle_parameters": vehicle, "vehicle_chassis": vehicle.chassis, "vehicle_suspension": vehicle.suspension,
        "vehicle_tyres": vehicle.tyre, "vehicle_drive": vehicle.drive, "vehicle_steering": saloon().steering,
        "vehicle_aerodynamics": AeroParameters(drag_area=0.7, rear_downforce_area=0.4),
    })
    # every protocol class, built from the legacy modal model: the same system as each class holds it
    dt = 0.01
    Ad, Bd, Cd, Dd = continuous_to_discrete(linear.A, linear.B, linear.C, linear.D, dt, hold="foh")
    numerator, denominator = scipy.signal.ss2tf(Ad, Bd[:, :1], Cd[:1], Dd[:1, :1])
    u = np.random.default_rng(0).standard_normal((400, Bd.shape[1]))
    y = DiscreteModel(Ad, Bd, Cd, Dd, dt).simulate_outputs(u)
    values.update({
        "continuous_model": ContinuousModel(linear.A, linear.B, linear.C, linear.D),
        "discrete_model": DiscreteModel(Ad, Bd, Cd, Dd, dt),
        "arx_model": ArxModel(denominator.reshape(-1, 1, 1), numerator.reshape(-1, 1, 1), dt),
        "pencil_model": PencilModel.from_state_space(Ad, Bd, Cd, Dd, dt=dt),
        "subspace_model": estimate_subspace(IOData(t=np.arange(400) * dt, u=u, y=y), order=Ad.shape[0]),
    })
    linearisation = linearize(vehicle, speed=20.0)
    values.update({"vehicle_linearization": linearisation, "vehicle_mode": linearisation.modes[0]})
    car = IdentifiedSingleTrack(SingleTrackConfig(mass=1500.0, cg_to_front_axle=1.2, cg_to_rear_axle=1.5),
                                [80_000.0, 100_000.0, 2500.0], np.diag([1e6, 1e6, 1e2]), (10.0, 30.0), {"log": "x"})
    record = IOData(t=np.arange(400) * dt, u=u, y=y)
    values.update({"single_track_model": car, "single_track_at_speed": car.model_at(20.0),
                   "single_track_config": car.config, "grey_box_model": car.greybox,
                   "time_response": values["discrete_model"].simulate(record)})
    assert set(values) == set(storage._SCHEMAS)  # a type registered later needs an example here
    with h5py.File(tmp_path / "all.h5", "w") as handle:
        for schema, value in values.items():
            assert storage._SCHEMAS[schema][0] is type(value)
            write_value(handle, schema, value)
            assert handle[schema].attrs["vehid_schema"] == schema
    with h5py.File(tmp_path / "all.h5", "r") as handle:
        for schema, value in values.items():
            assert _same(read_value(handle, schema), value), schema


def test_the_stored_nonlinear_history_is_the_series_the_summary_once_carried():
    # The report now draws the nonlinear convergence from runs/nonlinear-n<n>/history; a study
    # written before it carried the same series in its JSON summary, so both must agree exactly.
    archive = read_archive(ARCHIVES / "handling_study.h5")
    (run,) = archive.summary["nonlinear_runs"]
    history = archive.runs[f"nonlinear-n{run['order']}"].history
    assert np.array_equal(history["fit_filter"], np.array(run["fit_filter_by_pass"]))
    assert np.array_equal(history["trace_p"], np.array(run["trace_p_by_pass"]))


@pytest.mark.parametrize("attribute, value, message", [
    ("vehid_schema", "popen", "schema 'popen', which this workbench does not know"),
    ("dataclass", "subprocess:Popen", "names class 'subprocess:Popen'.*refusing"),
], ids=["unknown-schema", "foreign-class-path"])
def test_report_refuses_a_value_it_cannot_rebuild_with_exit_2(attribute, value, message, tmp_path):
    path = tmp_path / "tampered.h5"
    shutil.copyfile(ARCHIVES / "identify_n4sid.h5", path)
    with h5py.File(path, "r+") as handle:  # a consistent archive (checksums rewritten) that names a stranger
        model = handle["runs/n4sid/model"]
        for key in ("vehid_class", "vehid_schema"):
            model.attrs.pop(key, None)
        model.attrs[attribute] = value
        write_checksums(handle)
    done = run_vehid("report", path, "--out", tmp_path / "report")
    assert done.returncode == 2
    assert re.search(message, done.stderr)
    assert not (tmp_path / "report").exists()


def test_an_old_identification_run_resumes_and_its_archive_is_marked_with_the_new_layout(tmp_path):
    path = tmp_path / "run.h5"
    shutil.copyfile(ARCHIVES / "identify_iekf.h5", path)
    done = run_vehid("identify", "--resume", path, "--passes", "4", "--json", "--quiet")
    assert done.returncode == 0, done.stderr
    archive = read_archive(path)
    assert archive.runs["iekf"].n_pass == 4 and archive.schema_version == archive_module.SCHEMA_VERSION
    with h5py.File(path, "r") as handle:
        assert handle["runs/iekf/model"].attrs["vehid_schema"] == "modal_model"
