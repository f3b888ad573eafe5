"""Results archives: the value serializer's round trips, atomic writes, and every way to refuse a file."""

from __future__ import annotations

import dataclasses
import json
import os
from importlib import metadata

import h5py
import numpy as np
import pytest

from vehid.identification import (
    ArchiveError,
    IOData,
    append_history,
    fit_metrics,
    open_archive,
    read_archive,
    read_value,
    run_group,
    update_archive,
    write_archive,
    write_record,
    write_run,
    write_value,
)
from vehid.identification.dataio import archive as archive_module
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.vehicle import baseline
from vehid.vehicle.linearize import Linearization, VehicleMode


def _round_trip(tmp_path, value, **options):
    path = tmp_path / "values.h5"
    with h5py.File(path, "w") as handle:
        write_value(handle.create_group("g"), "v", value, **options)
    with h5py.File(path, "r") as handle:
        return read_value(handle["g"], "v")


def _same_array(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize(
    "value",
    [None, True, False, np.bool_(True), 0, -7, np.int64(2**40), 2.5, -0.0, np.float32(0.25),
     float("inf"), 1 + 2j, np.complex128(-3j), "text", "", "Ünïcode µ"],
    ids=repr,
)
def test_scalar_round_trip(tmp_path, value):
    back = _round_trip(tmp_path, value)
    assert back == value and type(back) is type(value.item() if isinstance(value, np.generic) else value)


def test_nan_scalar_round_trip(tmp_path):
    assert np.isnan(_round_trip(tmp_path, float("nan")))


@pytest.mark.parametrize(
    "array",
    [
        np.random.default_rng(0).normal(size=(50, 3)),
        np.array([np.nan, np.inf, -np.inf, -0.0, 5e-324]),
        np.arange(12, dtype=np.int32).reshape(3, 4),
        np.array([True, False, True]),
        np.array([1 + 2j, -3.5j]),
        np.array(4.0),
        np.zeros((0, 3)),
        np.ones((2, 3, 4), dtype=np.float32),
    ],
    ids=lambda a: f"{a.dtype}{a.shape}",
)
def test_array_round_trip_is_bitwise(tmp_path, array):
    back = _round_trip(tmp_path, array)
    assert isinstance(back, np.ndarray) and _same_array(back, array)


def test_array_units_attribute(tmp_path):
    path = tmp_path / "units.h5"
    with h5py.File(path, "w") as handle:
        write_value(handle, "speed", np.array([20.0, 21.0]), units="m/s")
        assert handle["speed"].attrs["units"] == "m/s"
        with pytest.raises(ArchiveError, match="units apply to arrays"):
            write_value(handle, "scalar", 1.0, units="m")


@pytest.mark.parametrize(
    "value",
    [
        (1, 2, 3),
        [1.5, -2.0],
        ((0, 1), (2, 3)),
        [[1.0, 2.0], [3.0, 4.0]],
        (),
        [],
        (True, False),
        ("a", "b", "µ"),
        ["lateral_acceleration", "yaw_rate"],
        [[1], [2, 3]],  # ragged: stored item by item
        (1, "a", None, 2.5),
        ([1, 2], (3, 4)),  # mixed containers keep their types
        (np.arange(3.0), np.eye(2)),
    ],
    ids=repr,
)
def test_sequence_round_trip(tmp_path, value):
    back = _round_trip(tmp_path, value)
    assert type(back) is type(value) and len(back) == len(value)
    for a, b in zip(back, value):
        if isinstance(b, np.ndarray):
            assert _same_array(a, b)
        else:
            assert a == b and type(a) is type(b)


def test_dicts_json_attribute_or_group(tmp_path):
    path = tmp_path / "dicts.h5"
    plain = {"order": 4, "names": ["a", "b"], "nested": {"x": 1.5, "flag": True}, "none": None}
    rich = {"theta": np.arange(3.0), "fixed_c": ((0, 1), (1, 2)), "inner": {"a": 1}, "n": np.int64(3)}
    with h5py.File(path, "w") as handle:
        write_value(handle, "plain", plain)
        write_value(handle, "rich", rich)
        assert "plain" in handle.attrs and json.loads(handle.attrs["plain"]) == plain
        assert isinstance(handle["rich"], h5py.Group)
    with h5py.File(path, "r") as handle:
        assert read_value(handle, "plain") == plain
        back = read_value(handle, "rich")
    assert list(back) == list(rich)
    assert _same_array(back["theta"], rich["theta"]) and back["fixed_c"] == rich["fixed_c"]
    assert back["inner"] == {"a": 1} and back["n"] == 3


def test_iodata_round_trip(tmp_path):
    t = np.arange(200) * 0.002
    data = IOData(
        t, np.sin(t), np.c_[np.cos(t), t], x=np.c_[t, -t, 2 * t],
        output_names=("yaw_rate", "roll_angle"), output_units=("rad/s", "rad"),
        meta={"seed": 3, "source": "test"},
    )
    back = _round_trip(tmp_path, data)
    assert isinstance(back, IOData)
    for key in ("t", "u", "y", "x"):
        assert _same_array(getattr(back, key), getattr(data, key))
    assert back.output_names == data.output_names and back.output_units == data.output_units
    assert dict(back.meta) == dict(data.meta)


def _modal_model() -> ModalModel:
    structure = ModalStructure.default(5, 2, 3)
    theta = np.random.default_rng(1).normal(size=structure.n_parameters)
    return ModalModel.from_parameters(
        structure, theta, input_names=("steer", "drive"), output_names=("a_y", "r", "phi"),
        meta={"estimator": "iekf", "passes": 12},
    )


def test_modal_model_and_structure_round_trip(tmp_path):
    model = _modal_model()
    back = _round_trip(tmp_path, model)
    assert isinstance(back, ModalModel) and back.structure == model.structure
    for name in "ABCD":
        assert _same_array(getattr(back, name), getattr(model, name))
    assert back.input_names == model.input_names and back.output_names == model.output_names
    assert back.meta == model.meta
    assert _round_trip(tmp_path, model.structure) == model.structure


def test_nested_dataclasses_round_trip(tmp_path):
    vehicle = baseline()
    assert _round_trip(tmp_path, vehicle) == vehicle  # four nested parameter dataclasses
    modes = (
        VehicleMode(complex(-2.4, 2.5), 0.55, 0.69, "yaw-sideslip", ("yaw_rate", "lateral_velocity")),
        VehicleMode(complex(-8.0, 0.0), 1.27, 1.0, "roll", ()),
    )
    rng = np.random.default_rng(2)
    linear = Linearization(
        A=rng.normal(size=(3, 3)), B=rng.normal(size=(3, 1)), C=rng.normal(size=(2, 3)),
        D=np.zeros((2, 1)), x0=np.zeros(3), u0=np.zeros(1), speed=20.0,
        state_names=("a", "b", "c"), input_names=("steer",), output_names=("y1", "y2"),
        modes=modes, vehicle="baseline",
    )
    back = _round_trip(tmp_path, linear)
    assert isinstance(back, Linearization) and back.modes == modes
    for item in dataclasses.fields(linear):
        a, b = getattr(back, item.name), getattr(linear, item.name)
        assert _same_array(a, b) if isinstance(b, np.ndarray) else a == b
    metrics = fit_metrics(np.c_[np.arange(1.0, 9.0)], np.c_[np.arange(1.0, 9.0) * 0.9])
    assert _same_array(_round_trip(tmp_path, metrics).r_squared, metrics.r_squared)


def test_dataclass_field_units_are_recorded(tmp_path):
    path = tmp_path / "units.h5"
    with h5py.File(path, "w") as handle:
        write_value(handle, "vehicle", baseline())
        units = json.loads(handle["vehicle/chassis"].attrs["vehid_units"])
    assert units["mass"] == "kg"


@dataclasses.dataclass(frozen=True)
class _Foreign:
    value: float = 1.0


def test_refuses_unregistered_classes_foreign_class_paths_and_unknown_schemas(tmp_path):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as handle:
        with pytest.raises(ArchiveError, match="no registered schema"):
            write_value(handle, "x", _Foreign())
        assert "x" not in handle
        # Class paths as archives once stored them: only the fixed table of known ones may be read.
        foreign = {"os": "os:system", "popen": "subprocess:Popen", "test": f"{__name__}:_Foreign",
                   "lookalike": "vehicle.evil:Payload", "missing": "identification.modal:NoSuchClass"}
        for name, target in foreign.items():
            handle.create_group(name).attrs["dataclass"] = target
        handle.create_group("codec").attrs["vehid_class"] = "subprocess:Popen"
        handle.create_group("unknown").attrs["vehid_schema"] = "popen"
        newer = handle.create_group("newer")
        newer.attrs.update({"vehid_schema": "fit_metrics", "vehid_schema_version": 2})
    with h5py.File(path, "r") as handle:
        for name, target in [*foreign.items(), ("codec", "subprocess:Popen")]:
            with pytest.raises(ArchiveError, match=f"names class '{target}'.*refusing"):
                read_value(handle, name)
        with pytest.raises(ArchiveError, match="schema 'popen', which this workbench does not know"):
            read_value(handle, "unknown")
        with pytest.raises(ArchiveError, match="version 2; this workbench reads version 1"):
            read_value(handle, "newer")


def test_stored_values_name_schemas_not_classes(tmp_path):
    with h5py.File(tmp_path / "schemas.h5", "w") as handle:
        write_value(handle, "model", _modal_model())
        write_value(handle, "vehicle", baseline())
        model, vehicle = handle["model"].attrs, handle["vehicle"].attrs
        assert (model["vehid_schema"], model["vehid_schema_version"]) == ("modal_model", 1)
        assert vehicle["vehid_schema"] == "vehicle_parameters"
        assert handle["vehicle/chassis"].attrs["vehid_schema"] == "vehicle_chassis"
        assert not any(key in group.attrs for group in (handle["model"], handle["vehicle"])
                       for key in ("dataclass", "vehid_class"))


@pytest.mark.parametrize(
    "value, message",
    [(object(), "cannot archive a value of type"), (b"bytes", "cannot archive"),
     (np.array(["a", "b"]), "dtype <U1"), ({1: "a"}, "str keys"), (np.datetime64("2024-01-01"), "cannot archive")],
    ids=["object", "bytes", "unicode-array", "int-key", "datetime"],
)
def test_refuses_unsupported_values(tmp_path, value, message):
    with h5py.File(tmp_path / "bad.h5", "w") as handle:
        with pytest.raises(ArchiveError, match=message):
            write_value(handle, "v", value)


def test_refuses_reserved_and_bad_names(tmp_path):
    with h5py.File(tmp_path / "names.h5", "w") as handle:
        for name in ("dataclass", "vehid_types", "a/b", ""):
            with pytest.raises(ArchiveError):
                write_value(handle, name, 1)


# ------------------------------------------------------------------ archives
def _write_small(path, *, config=None, marker=1):
    with write_archive(path, kind="identification", config=config or {"order": 4}, seeds=[0, marker]) as handle:
        t = np.arange(50) * 0.01
        write_record(handle, "identification", IOData(t, np.sin(t), np.cos(t)))
        write_run(handle, "n4", model=_modal_model(), state={"pass": marker})
    return path


def test_archive_header_and_contents(tmp_path):
    path = _write_small(tmp_path / "a.h5", config=baseline())
    with open_archive(path) as handle:
        attrs = dict(handle.attrs)
    assert attrs["schema_version"] == archive_module.SCHEMA_VERSION
    assert attrs["package_version"] == metadata.version("vehid")
    assert attrs["casadi_version"] == metadata.version("casadi")
    assert attrs["git_commit"]
    assert json.loads(attrs["config_json"])["chassis"]["mass"] == baseline().chassis.mass
    archive = read_archive(path, kinds=("identification",))
    assert archive.kind == "identification" and archive.seeds == [0, 1]
    assert archive.config == baseline()
    assert set(archive.records) == {"identification"} and archive.runs["n4"].state == {"pass": 1}
    assert archive.runs["n4"].model.structure == _modal_model().structure
    with pytest.raises(ArchiveError, match="expected one of: handling-study"):
        read_archive(path, kinds=("handling-study",))


def test_git_commit_is_unknown_without_git(monkeypatch):
    monkeypatch.setenv("PATH", "")
    assert archive_module._git_commit() == "unknown"


def test_checkpoints_append_history_pass_by_pass(tmp_path):
    path = _write_small(tmp_path / "a.h5")
    theta = np.arange(6.0)
    for k in range(3):
        with update_archive(path, kinds=("identification",)) as handle:
            run = run_group(handle, "n4")
            count = append_history(
                run, {"parameters": theta + k, "trace_p": 10.0 ** -k, "fit_filter": [99.0, 98.5]},
                units={"fit_filter": "%"},
            )
            write_run(handle, "n4", state={"pass": k + 1, "theta": theta + k})
        assert count == k + 1
    run = read_archive(path).runs["n4"]
    assert run.n_pass == 3 and run.history["parameters"].shape == (3, 6)
    assert _same_array(run.history["trace_p"], np.array([1.0, 0.1, 0.01]))
    assert run.history_units["fit_filter"] == "%" and run.state["pass"] == 3
    with update_archive(path) as handle:
        with pytest.raises(ArchiveError, match="this pass gives"):
            append_history(run_group(handle, "n4"), {"parameters": theta})
        with pytest.raises(ArchiveError, match="per pass"):
            append_history(run_group(handle, "n4"), {"parameters": theta[:2], "trace_p": 1.0, "fit_filter": [1, 2]})


def test_failed_write_leaves_previous_archive_and_no_temporary(tmp_path):
    path = _write_small(tmp_path / "a.h5", marker=1)
    before = path.read_bytes()
    with pytest.raises(RuntimeError, match="crash"):
        with write_archive(path, kind="identification", config={"order": 5}, seeds=[9]) as handle:
            write_run(handle, "n5", state={"pass": 1})
            raise RuntimeError("crash while writing")
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["a.h5"]
    with pytest.raises(RuntimeError, match="crash"):
        with update_archive(path) as handle:
            append_history(run_group(handle, "n4"), {"trace_p": 1.0})
            raise RuntimeError("crash during a checkpoint")
    assert path.read_bytes() == before and os.listdir(tmp_path) == ["a.h5"]
    with pytest.raises(RuntimeError):
        with write_archive(tmp_path / "new.h5", kind="identification"):
            raise RuntimeError("crash")
    assert os.listdir(tmp_path) == ["a.h5"]


def test_rejects_missing_file(tmp_path):
    with pytest.raises(ArchiveError, match="no such archive"):
        open_archive(tmp_path / "absent.h5")


def test_rejects_file_that_is_not_hdf5(tmp_path):
    path = tmp_path / "notes.h5"
    path.write_text("t,u,y\n0,1,2\n")
    with pytest.raises(ArchiveError, match="not an HDF5 file"):
        read_archive(path)


def test_rejects_foreign_hdf5(tmp_path):
    path = tmp_path / "foreign.h5"
    with h5py.File(path, "w") as handle:
        handle["x"] = np.arange(3)
    with pytest.raises(ArchiveError, match="not a workbench results archive .no schema_version"):
        read_archive(path)


def test_rejects_newer_schema_version(tmp_path):
    path = _write_small(tmp_path / "a.h5")
    with h5py.File(path, "r+") as handle:
        handle.attrs["schema_version"] = np.int64(99)
    with pytest.raises(ArchiveError, match="schema version 99, newer than this workbench reads"):
        read_archive(path)


def test_rejects_truncated_archive(tmp_path):
    whole = _write_small(tmp_path / "a.h5").read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(whole[: len(whole) // 2])
    with pytest.raises(ArchiveError, match="truncated or corrupt"):
        read_archive(cut)
    with pytest.raises(ArchiveError, match="truncated or corrupt"):
        with update_archive(cut):
            pass  # pragma: no cover


def test_rejects_missing_required_group(tmp_path):
    path = _write_small(tmp_path / "a.h5")
    with h5py.File(path, "r+") as handle:
        del handle["runs"]
    with pytest.raises(ArchiveError, match="lacks the required group 'runs'"):
        read_archive(path)


def test_rejects_empty_kind(tmp_path):
    with pytest.raises(ArchiveError, match="kind"):
        with write_archive(tmp_path / "a.h5", kind=""):
            pass  # pragma: no cover


def test_write_value_replaces_a_member_of_another_kind(tmp_path):
    with h5py.File(tmp_path / "replace.h5", "w") as handle:
        write_value(handle, "x", 1)
        write_value(handle, "x", np.arange(3.0))
        assert "x" not in handle.attrs and _same_array(read_value(handle, "x"), np.arange(3.0))
        write_value(handle, "x", None)
        assert "x" not in handle and read_value(handle, "x") is None
        with pytest.raises(ArchiveError, match="no member 'y'"):
            read_value(handle, "y")
