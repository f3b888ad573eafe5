"""Archives a user can trust: checksums catch values changed on disk, one writer at a time, safe targets,
report folders swapped in whole. Each test first reproduces the failure the workbench used to let through."""

from __future__ import annotations

import json
import os
import signal
import socket
import struct
import subprocess
import sys

import h5py
import numpy as np
import pytest

from vehid.identification import IOData, read_archive, write_archive, write_record, write_run
from vehid.identification.dataio.archive import open_archive, update_archive
from vehid.identification.dataio.archive_safety import (
    REPORT_MARKER,
    ArchiveLockedError,
    OutputTargetError,
    archive_lock,
    check_output_target,
    replacing_directory,
    writing_report_folder,
)
from vehid.identification.errors import ArchiveError
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.cli import main

CORRUPT_VALUE = 1.6e40  # the value the issue found overwritten on disk, unnoticed


def _archive(path):
    t = np.arange(200) * 0.01
    u = np.sin(t)[:, None]
    y = np.column_stack([np.cos(t), 0.5 * np.sin(2 * t)])
    structure = ModalStructure.default(2, 1, 2)
    theta = structure.initial_parameters(sigma=-2.0, omega=3.0)
    theta[structure.slices()["B"]] = [0.5, 1.5]
    model = ModalModel.from_parameters(structure, theta, input_names=("u",), output_names=("y1", "y2"))
    with write_archive(path, kind="identification", config={"order": 2}, seeds=[0]) as handle:
        write_record(handle, "identification", IOData(t, u, y))
        write_run(handle, "iekf", model=model)
    return path


def _overwrite_first_value(path, dataset_name, value=CORRUPT_VALUE):
    """Write ``value`` over the first element of a dataset in the file's bytes, as a disk fault or a stray tool would."""
    with h5py.File(path, "r") as handle:
        dataset = handle[dataset_name]
        offset = dataset.id.get_offset()
        if offset is None:  # chunked: the first chunk's place
            offset = dataset.id.get_chunk_info(0).byte_offset
        assert dataset.dtype == np.float64
    with open(path, "r+b") as raw:
        raw.seek(offset)
        raw.write(struct.pack("<d", value))


def test_a_value_overwritten_on_disk_is_caught_and_named(tmp_path):
    path = _archive(tmp_path / "run.h5")
    _overwrite_first_value(path, "data/identification/y")
    with h5py.File(path, "r") as raw:  # the failure: HDF5 itself reads the bad value without complaint
        assert raw["data/identification/y"][0, 0] == CORRUPT_VALUE
    with pytest.raises(ArchiveError, match=r"corrupt: the dataset /data/identification/y does not match its checksum"):
        read_archive(path)


def test_a_corrupt_model_fails_the_report_with_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "results"))
    path = _archive(tmp_path / "run.h5")
    _overwrite_first_value(path, "runs/iekf/model/A")
    assert main(["report", str(path), "--json"]) == 2
    captured = capsys.readouterr()
    assert "/runs/iekf/model/A" in captured.err and len(captured.err.strip().splitlines()) == 1
    assert '"exit_status": 2' in captured.out
    assert not (tmp_path / "results").exists() or not any((tmp_path / "results").iterdir())


def test_changed_attributes_and_checkpoints(tmp_path):
    path = _archive(tmp_path / "run.h5")
    with update_archive(path) as handle:  # a checkpoint rewrites the digests of what it changed
        handle["runs/iekf"].attrs["stop_reason"] = "converged"
    assert read_archive(path).runs["iekf"].model is not None
    with h5py.File(path, "r+") as handle:  # written behind the workbench's back
        handle["runs/iekf"].attrs["stop_reason"] = "passes"
    with pytest.raises(ArchiveError, match="the group /runs/iekf does not match its checksum"):
        open_archive(path)


def test_archives_without_checksums_still_read(tmp_path):
    path = _archive(tmp_path / "old.h5")
    with h5py.File(path, "r+") as handle:  # as written before checksums existed
        del handle.attrs["vehid_checksums"]
        handle.visititems(lambda name, obj: obj.attrs.__delitem__("vehid_digest"))
        del handle.attrs["vehid_digest"]
    archive = read_archive(path)
    assert archive.records["identification"].n_samples == 200


# ------------------------------------------------------------------ locking
_HOLDER = """
import sys, time
from vehid.identification.dataio.archive_safety import archive_lock
with archive_lock(sys.argv[1]):
    print("locked", flush=True)
    time.sleep(60)
"""


@pytest.fixture
def held_elsewhere(tmp_path):
    """The archive's lock held by another process (as by a running identification)."""
    path = tmp_path / "shared.h5"
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        yield path, holder.pid
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()


def test_a_second_writer_is_refused_naming_the_holder(held_elsewhere):
    path, pid = held_elsewhere
    with pytest.raises(ArchiveLockedError, match=rf"being written by process {pid} on host {socket.gethostname()}"):
        with write_archive(path, kind="identification"):
            pass
    assert not path.exists()


def test_the_lock_dies_with_its_holder(tmp_path):
    """A holder killed by SIGKILL leaves no stale lock: the next writer proceeds."""
    path = tmp_path / "shared.h5"
    holder = subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    holder.stdout.close()
    with write_archive(path, kind="identification"):
        pass
    assert read_archive(path).kind == "identification"


def test_the_lock_is_reentrant_within_a_process(tmp_path):
    path = tmp_path / "run.h5"
    with archive_lock(path):
        with write_archive(path, kind="identification"):
            pass
        with update_archive(path):
            pass
    assert not (tmp_path / ".run.h5.lock").exists()  # released and removed


# ----------------------------------------------------------- output targets
def test_target_checks(tmp_path):
    data = tmp_path / "record.csv"
    data.write_text("t,u,y\n0,0,0\n")
    with pytest.raises(OutputTargetError, match="is an input of this run"):
        check_output_target(data, inputs=[data], force=True)  # never, even forced
    with pytest.raises(OutputTargetError, match="exists and is not a workbench archive.*'force'"):
        check_output_target(data)
    assert check_output_target(data, force=True) == data
    with pytest.raises(OutputTargetError, match=f"{tmp_path}: Is a directory"):
        check_output_target(tmp_path)
    with pytest.raises(OutputTargetError, match=r"out.h5: .*record.csv: Not a directory"):
        check_output_target(data / "out.h5")
    archive = _archive(tmp_path / "old.h5")
    assert check_output_target(archive) == archive  # an archive may be replaced
    assert not list(tmp_path.glob(".*probe"))


def _unwritable_directory(tmp_path):
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        return locked
    if os.access("/sys", os.W_OK) and not _cannot_create("/sys"):
        pytest.skip("running as root with no read-only directory to test against")
    return "/sys"


def _cannot_create(directory):
    try:
        with open(os.path.join(directory, "vehid-probe"), "w"):
            pass
    except OSError:
        return True
    os.unlink(os.path.join(directory, "vehid-probe"))
    return False


def test_an_unwritable_directory_fails_before_any_work(tmp_path):
    directory = _unwritable_directory(tmp_path)
    with pytest.raises(OutputTargetError, match=r"cannot write the archive .*out\.h5: Permission denied"):
        check_output_target(os.path.join(directory, "out.h5"))


# ------------------------------------------------------------ report folders
def test_a_failed_report_leaves_the_old_folder(tmp_path):
    folder = tmp_path / "report"
    folder.mkdir()
    (folder / "table.md").write_text("old")
    (folder / "stale.png").write_text("old")
    with pytest.raises(RuntimeError):
        with replacing_directory(folder) as partial:
            (partial / "table.md").write_text("new")
            raise RuntimeError("drawing failed")
    assert sorted(p.name for p in folder.iterdir()) == ["stale.png", "table.md"]
    assert (folder / "table.md").read_text() == "old"
    with replacing_directory(folder) as partial:
        (partial / "table.md").write_text("new")
    assert [p.name for p in folder.iterdir()] == ["table.md"]  # no stale file beside the new ones
    assert (folder / "table.md").read_text() == "new"
    assert [p.name for p in tmp_path.iterdir()] == ["report"]


_KILLED_WRITER = """
import sys, time
from pathlib import Path
from vehid.identification.dataio.archive_safety import replacing_directory
with replacing_directory(sys.argv[1]) as partial:
    (partial / "table.md").write_text("new")
    print("half", flush=True)
    time.sleep(60)
"""


def test_a_writer_killed_mid_report_leaves_the_old_report(tmp_path):
    folder = tmp_path / "report"
    folder.mkdir()
    (folder / "table.md").write_text("old")
    (folder / "report.pdf").write_text("old")
    writer = subprocess.Popen([sys.executable, "-c", _KILLED_WRITER, str(folder)], stdout=subprocess.PIPE, text=True)
    assert writer.stdout.readline().strip() == "half"
    writer.send_signal(signal.SIGKILL)
    writer.wait()
    writer.stdout.close()
    assert sorted(p.name for p in folder.iterdir()) == ["report.pdf", "table.md"]
    assert (folder / "table.md").read_text() == "old"
    with replacing_directory(folder) as partial:  # the next writer clears the dead one's leftovers
        (partial / "table.md").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_a_second_identify_on_the_same_archive_exits_2_before_any_work(held_elsewhere, tmp_path, capsys):
    """Two `vehid identify --out same.h5` at once used to leave one run's record with the other's model."""
    path, pid = held_elsewhere
    record = tmp_path / "record.csv"
    t = np.arange(500) * 0.01
    np.savetxt(record, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="t,u,y", comments="")
    assert main(["identify", str(record), "--inputs", "u", "--outputs", "y", "--order", "2", "--out", str(path),
                 "--json"]) == 2
    captured = capsys.readouterr()
    assert f"process {pid} on host {socket.gethostname()}" in captured.err
    assert len(captured.err.strip().splitlines()) == 1 and not path.exists()
    assert main(["identify", "--resume", str(path)]) == 2  # a resume is a writer too


def test_the_report_folder_holds_no_stale_files(tmp_path, capsys):
    """A new report replaces an earlier one: no stale table or PDF of an earlier run beside the new files."""
    from vehid.identification import append_history, run_group

    path = tmp_path / "run.h5"
    with write_archive(path, kind="identification") as handle:
        for k in range(4):
            append_history(run_group(handle, "n3"), {"fit_filter": [90.0 + k], "trace_p": 10.0 ** -k})
    folder = tmp_path / "figs"
    with writing_report_folder(folder) as partial:  # an earlier report, of another archive
        (partial / "summary.md").write_text("stale")
        (partial / "convergence_n9.png").write_text("stale")
    assert main(["report", str(path), "--out", str(folder), "--dpi", "30", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert sorted(p.name for p in folder.iterdir() if p.name != REPORT_MARKER) == sorted(
        os.path.basename(f) for f in summary["files"])
    assert "convergence_n9.png" not in summary["files"] and all(os.path.exists(f) for f in summary["files"])
