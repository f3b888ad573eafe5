"""One output rule for every command that writes: nothing a user had is lost without --force.

The matrix puts each writing command's output option on what a user may already have there (a text file,
a CSV table, a foreign HDF5 file, a workbench archive of another kind, a folder of their own files), by a
relative and by an absolute path, and checks that the command refuses with exit status 2 and one line,
before any work, leaving every byte as it was. With --force, only the workbench's own output replaces
things, and in a report folder nothing that is not the report's is deleted. Below the matrix, one test per
file the workbench used to destroy, each reproducing the failure first reported.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest

from vehid.identification import write_archive
from vehid.identification.dataio.archive import read_archive
from vehid.identification.dataio.archive_safety import (REPORT_MARKER, OutputTargetError, check_report_folder,
                                                output_identity, writing_report_folder)
from vehid.scenarios.cli import build_parser, main
from vehid.scenarios.linear_example import make_data
from vehid.scenarios.commands.arguments import run_digest
from vehid.scenarios.paths import OUT_RULE, results_path


def _record(path: Path, duration: float = 2.0) -> Path:
    data, _ = make_data(5, outputs=(0,), duration=duration)
    np.savetxt(path, np.column_stack([data.t, data.u[:, 0], data.u[:, 1], data.y[:, 0]]), delimiter=",",
               header="t,u1,u2,y1", comments="")
    return path


# A classical fit on 1,000 samples: the cheapest identify that writes an archive and a model file.
ARX = ["--inputs", "u1,u2", "--outputs", "y1", "--order", "2", "--method", "arx", "--quiet", "--json"]


def _no_work(monkeypatch) -> None:
    """Make every command's computation fail loudly: a refusal must come before any of it."""
    import vehid.vehicle
    from vehid.scenarios import envelope, handling_study, linear_example
    from vehid.identification.automatic import intake

    def refuse(*args, **kwargs):
        raise AssertionError("the work started before the output was checked")

    # the commands import what they compute with when they run: the refusal is set where they find it
    monkeypatch.setattr(intake, "plan_run", refuse)
    monkeypatch.setattr(vehid.vehicle, "simulate", refuse)
    monkeypatch.setattr(handling_study, "make_records", refuse)
    monkeypatch.setattr(linear_example, "run_case", refuse)
    monkeypatch.setattr(envelope, "run_campaign", refuse)


# ---------------------------------------------------------------- what a user may have
def _text(path: Path) -> Path:
    path.write_text("notes of a week's test drives\n")
    return path


def _csv(path: Path) -> Path:
    path.write_text("t,u,y\n0,1,2\n0.01,1,2\n")
    return path


def _foreign_hdf5(path: Path) -> Path:
    with h5py.File(path, "w") as handle:
        handle["measurement"] = np.arange(10.0)
    return path


def _archive_of(kind: str):
    def make(path: Path) -> Path:
        with write_archive(path, kind=kind, config={"a": 1}):
            pass
        return path
    return make


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# Every command that writes, its option that names the output, and the arguments around it.
WRITERS = {
    "simulate": (["simulate", "--manoeuvre", "step", "--duration", "0.5"], "--out"),
    "identify": (["identify", "{record}", *ARX], "--out"),
    "identify-model": (["identify", "{record}", *ARX], "--save-model"),
    "study handling": (["study", "handling", "--orders", "2", "--linear-only", "--no-report"], "--out"),
    "study linear-example": (["study", "linear-example"], "--out"),
    "study envelope": (["study", "envelope", "--speeds", "15", "--orders", "2", "--no-report"], "--out"),
}

# What each writer's output target may hold; the other-kind archive is of a kind the command does not write.
EXISTING = {
    "text file": _text,
    "CSV table": _csv,
    "foreign HDF5": _foreign_hdf5,
    "other-kind archive": None,  # chosen per command below
}
_OTHER_KIND = {"study handling": "identification"}


def test_every_command_with_an_output_option_is_in_the_matrix():
    """A new command that writes a user-named file must get its row in WRITERS (or the report's tests), and
    its --help must state the one rule for relative paths."""
    parser = build_parser()
    named = set()

    def walk(p, prefix):
        for action in p._actions:
            if action.__class__.__name__ == "_SubParsersAction":
                for name, sub in action.choices.items():
                    walk(sub, [*prefix, name])
            elif set(action.option_strings) & {"--out", "--save-model"}:
                named.add((" ".join(prefix), action.option_strings[0]))
                assert OUT_RULE in action.help, (prefix, action.help)  # each --help says what a relative path means

    walk(parser, [])
    covered = {(argv[0] if argv[0] != "study" else f"study {argv[1]}", option)
               for argv, option in WRITERS.values()} | {("report", "--out")}
    # calibrate writes a vehicle file (TOML), not an archive: tests/test_calibrate.py checks that it never replaces
    # an existing file without --force and refuses before any computation
    covered |= {("calibrate", "--out")}
    assert named == covered


def _target_name(writer: str, existing: str) -> str:
    option = WRITERS[writer][1]
    if option == "--save-model":
        return {"text file": "model.json", "CSV table": "model.json", "foreign HDF5": "model.mat",
                "other-kind archive": "model.mat"}[existing]
    # an HDF5 name: the content, not the name, says the file is the user's
    return "existing.h5"


@pytest.mark.parametrize("relative", [True, False], ids=["relative", "absolute"])
@pytest.mark.parametrize("existing", list(EXISTING))
@pytest.mark.parametrize("writer", list(WRITERS))
def test_an_existing_file_is_kept_and_refused_before_any_work(writer, existing, relative, tmp_path, capsys,
                                                              monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "results"))
    record = _record(tmp_path / "record.csv")
    target = tmp_path / _target_name(writer, existing)
    make = EXISTING[existing] or _archive_of(_OTHER_KIND.get(writer, "handling-study"))
    make(target)
    before = target.read_bytes()
    entries = sorted(p.name for p in tmp_path.iterdir())
    _no_work(monkeypatch)
    argv, option = WRITERS[writer]
    argv = [a.replace("{record}", str(record)) for a in argv]
    named = target.name if relative else str(target)
    status = main([*argv, option, named, "--json"])
    captured = capsys.readouterr()
    assert status == 2, captured.err
    lines = captured.err.strip().splitlines()
    # the remedy is named: --force, or for a campaign (only ever continued) --resume
    remedy = "--resume" if writer == "study envelope" else "--force"
    assert len(lines) == 1 and named in lines[0] and remedy in lines[0], captured.err
    assert json.loads(captured.out)["exit_status"] == 2
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name != "results") == entries  # nothing new, no lock left


@pytest.mark.parametrize("writer", list(WRITERS))
def test_a_directory_as_an_output_file_is_refused_before_any_work(writer, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    record = _record(tmp_path / "record.csv")
    folder = tmp_path / ("model.json" if WRITERS[writer][1] == "--save-model" else "folder.h5")
    folder.mkdir()
    (folder / "thesis.tex").write_text("draft")
    _no_work(monkeypatch)
    argv, option = WRITERS[writer]
    argv = [a.replace("{record}", str(record)) for a in argv]
    assert main([*argv, option, folder.name, "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Is a directory" in err[0], err
    assert _snapshot(folder) == {"thesis.tex": b"draft"}


@pytest.mark.parametrize("writer", list(WRITERS))
def test_a_name_of_another_format_is_refused_before_any_work(writer, tmp_path, capsys, monkeypatch):
    """``--out run.csv`` would get HDF5 and ``--save-model m.xlsx`` nothing readable: both refused up front."""
    monkeypatch.chdir(tmp_path)
    record = _record(tmp_path / "record.csv")
    _no_work(monkeypatch)
    argv, option = WRITERS[writer]
    argv = [a.replace("{record}", str(record)) for a in argv]
    name = "m.xlsx" if option == "--save-model" else "run.csv"
    assert main([*argv, option, name, "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and name in err[0], err
    assert not (tmp_path / name).exists()


# ---------------------------------------------------------------- with --force, and the same run
def test_force_replaces_a_file_with_the_workbench_output(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    record = _record(tmp_path / "record.csv")
    _text(tmp_path / "old.h5")
    _csv(tmp_path / "model.json")
    assert main(["identify", str(record), *ARX, "--out", "old.h5", "--save-model", "model.json", "--force"]) == 0
    capsys.readouterr()
    assert read_archive(tmp_path / "old.h5").kind == "identification"
    assert set(json.loads((tmp_path / "model.json").read_text())) >= {"A", "B", "C", "D", "structure"}


def test_a_rerun_replaces_its_own_output_and_another_run_does_not(tmp_path, capsys, monkeypatch):
    """The same command line on the same data may replace its archive; other settings or data may not."""
    monkeypatch.chdir(tmp_path)
    record = _record(tmp_path / "record.csv")
    argv = ["identify", "record.csv", *ARX, "--out", "run.h5", "--save-model", "model.json"]
    assert main(argv) == 0
    first = output_identity(tmp_path / "run.h5")
    assert first.kind == "identification" and first.run
    assert main(argv) == 0  # the same run again replaces its own archive and model file
    capsys.readouterr()
    before = (tmp_path / "run.h5").read_bytes()
    assert main([*[a if a != "2" else "3" for a in argv]]) == 2  # another order: another run
    assert "another run" in capsys.readouterr().err
    _record(record, duration=2.5)  # other data under the same name: another run
    assert main(argv) == 2
    assert (tmp_path / "run.h5").read_bytes() == before
    assert main([*argv, "--force"]) == 0


def test_the_run_digest_names_files_by_content(tmp_path):
    import argparse

    def args(**values):
        return argparse.Namespace(handler=test_the_run_digest_names_files_by_content, **values)

    assert run_digest(args(order=2, out="a.h5", json=True)) == run_digest(args(order=2, out="b.h5", json=False))
    assert run_digest(args(order=2)) != run_digest(args(order=3))
    first, copy = _csv(tmp_path / "a.csv"), _csv(tmp_path / "b.csv")
    assert run_digest(args(data=[str(first)])) == run_digest(args(data=[str(copy)]))  # a copy is the same data
    copy.write_text("t,u,y\n0,1,2\n0.01,1,3\n")
    assert run_digest(args(data=[str(first)])) != run_digest(args(data=[str(copy)]))


def test_simulate_replaces_its_own_record_only(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    argv = ["simulate", "--manoeuvre", "step", "--duration", "0.5", "--out", "step.h5", "--json"]
    assert main(argv) == 0
    assert main(argv) == 0  # the same simulation again
    capsys.readouterr()
    before = (tmp_path / "step.h5").read_bytes()
    assert main([*argv, "--speed", "25"]) == 2
    assert "another run" in capsys.readouterr().err and (tmp_path / "step.h5").read_bytes() == before
    assert main([*argv, "--speed", "25", "--force"]) == 0


# ---------------------------------------------------------------- report folders
def _identification_archive(path: Path) -> Path:
    from vehid.identification import append_history, run_group

    with write_archive(path, kind="identification") as handle:
        for k in range(3):
            append_history(run_group(handle, "n3"), {"fit_filter": [90.0 + k], "trace_p": 10.0 ** -k})
    return path


@pytest.mark.parametrize("relative", [True, False], ids=["relative", "absolute"])
def test_report_refuses_a_folder_of_other_files(relative, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "thesis"
    folder.mkdir()
    (folder / "draft.tex").write_text("chapter 1")
    archive = _identification_archive(folder / "run.h5")  # the input archive lives in the folder too
    before = _snapshot(folder)
    named = "thesis" if relative else str(folder)
    assert main(["report", str(archive), "--out", named, "--dpi", "30", "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and named in err[0] and "--force" in err[0], err
    assert _snapshot(folder) == before


def test_report_with_force_adds_its_files_and_deletes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "thesis"
    (folder / "figures").mkdir(parents=True)
    (folder / "draft.tex").write_text("chapter 1")
    (folder / "figures" / "photo.png").write_bytes(b"\x89PNG mine")
    archive = _identification_archive(folder / "run.h5")
    before = _snapshot(folder)
    assert main(["report", str(archive), "--out", "thesis", "--dpi", "30", "--json", "--force"]) == 0
    written = json.loads(capsys.readouterr().out)["files"]
    after = _snapshot(folder)
    assert all(after[name] == content for name, content in before.items())  # every file of the user's kept
    assert {os.path.relpath(f, folder) for f in written} | {REPORT_MARKER} == set(after) - set(before)
    check_report_folder(folder)  # now marked: the next report needs no --force, and keeps the user's files


def test_an_earlier_report_is_replaced_without_its_stale_files(tmp_path):
    folder = tmp_path / "report"
    with writing_report_folder(folder) as partial:
        (partial / "summary.md").write_text("old")
        (partial / "convergence_n9.png").write_text("old")
    (folder / "my_notes.txt").write_text("mine")  # the user adds a file to the report folder
    check_report_folder(folder)  # an earlier report: accepted without --force
    with writing_report_folder(folder) as partial:
        (partial / "summary.md").write_text("new")
    assert _snapshot(folder).keys() == {"summary.md", "my_notes.txt", REPORT_MARKER}
    assert (folder / "summary.md").read_text() == "new" and (folder / "my_notes.txt").read_text() == "mine"
    with writing_report_folder(tmp_path / "empty") as partial:  # an absent folder is created
        (partial / "a.png").write_text("x")
    (tmp_path / "blank").mkdir()
    check_report_folder(tmp_path / "blank")  # an empty folder is accepted
    with pytest.raises(OutputTargetError, match="not a report of the workbench"):
        check_report_folder(tmp_path)


def test_a_report_folder_given_as_a_link_stays_a_link(tmp_path):
    real = tmp_path / "real"
    with writing_report_folder(real) as partial:
        (partial / "summary.md").write_text("old")
    (tmp_path / "link").symlink_to(real, target_is_directory=True)
    with writing_report_folder(tmp_path / "link") as partial:
        (partial / "summary.md").write_text("new")
    assert (tmp_path / "link").is_symlink() and (real / "summary.md").read_text() == "new"


def test_a_forged_marker_cannot_reach_outside_the_folder(tmp_path):
    folder = tmp_path / "report"
    folder.mkdir()
    (tmp_path / "precious.txt").write_text("keep")
    (folder / REPORT_MARKER).write_text(json.dumps({"files": ["../precious.txt", str(tmp_path / "precious.txt")]}))
    with writing_report_folder(folder) as partial:
        (partial / "summary.md").write_text("new")
    assert (tmp_path / "precious.txt").read_text() == "keep"


def test_study_refuses_a_report_folder_of_other_files_before_any_work(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _no_work(monkeypatch)
    for argv in (["study", "handling", "--orders", "2", "--linear-only"],
                 ["study", "envelope", "--speeds", "15", "--orders", "2"]):
        folder = tmp_path / "mine"
        folder.mkdir(exist_ok=True)
        (folder / "notes.txt").write_text("mine")
        assert main([*argv, "--out", "mine.h5", "--json"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "mine" in err[0] and "not a report" in err[0], err
        assert _snapshot(folder) == {"notes.txt": b"mine"} and not (tmp_path / "mine.h5").exists()


# ---------------------------------------------------------------- one rule for relative paths
def test_relative_outputs_are_taken_from_the_working_directory(tmp_path, capsys, monkeypatch):
    """The README's `vehid simulate --out data.h5` then `vehid identify data.h5` failed: the record had gone
    under results/ while identify looked in the working directory."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "results"))
    assert main(["simulate", "--manoeuvre", "step", "--duration", "0.5", "--out", "data.h5", "--quiet"]) == 0
    assert (tmp_path / "data.h5").is_file()
    assert main(["identify", "data.h5", "--inputs", "steer", "--outputs", "yaw_rate", "--order", "2",
                 "--method", "arx", "--out", "run.h5", "--save-model", "model.json", "--quiet"]) == 0
    capsys.readouterr()
    assert (tmp_path / "run.h5").is_file() and (tmp_path / "model.json").is_file()
    results = tmp_path / "results"
    assert not results.exists() or not any(results.iterdir())  # nothing went to the results folder


def test_default_outputs_stay_in_the_results_folder(tmp_path, monkeypatch):
    from vehid.scenarios.handling_study import archive_path

    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "elsewhere"))
    assert archive_path(None) == tmp_path / "elsewhere" / "handling_study.h5"
    assert results_path(None, "x-report") == tmp_path / "elsewhere" / "x-report"
    assert results_path("mine/x.h5", "unused.h5") == Path("mine/x.h5")
    monkeypatch.delenv("VEHID_RESULTS_DIR")
    assert archive_path(None) == Path("results") / "handling_study.h5"  # `make study` writes results/handling_study.h5


# ---------------------------------------------------------------- the files once destroyed
def test_simulate_onto_notes_or_a_table_keeps_them(tmp_path, capsys, monkeypatch):
    """`vehid simulate --manoeuvre step --out notes.txt` (or data.csv) overwrote the file with HDF5, exit 0."""
    monkeypatch.chdir(tmp_path)
    for name, make in (("notes.txt", _text), ("data.csv", _csv), ("data.h5", _csv)):
        before = make(tmp_path / name).read_bytes()
        for force in ([], ["--force"]):
            if name == "data.h5" and force:
                continue
            assert main(["simulate", "--manoeuvre", "step", "--duration", "0.5", "--out", name, *force]) == 2
            assert (tmp_path / name).read_bytes() == before
    capsys.readouterr()
    assert main(["simulate", "--manoeuvre", "step", "--duration", "0.5", "--out", "data.h5", "--force"]) == 0
    assert output_identity(tmp_path / "data.h5").kind == "simulated-record"


def test_identify_onto_a_handling_study_keeps_it(tmp_path, capsys, monkeypatch):
    """`vehid identify data.csv ... --out study_copy.h5` replaced a handling-study archive with its own."""
    record = _record(tmp_path / "record.csv")
    study = _archive_of("handling-study")(tmp_path / "study_copy.h5")
    before = study.read_bytes()
    _no_work(monkeypatch)
    assert main(["identify", str(record), *ARX, "--out", str(study)]) == 2
    err = capsys.readouterr().err
    assert "'handling-study'" in err and "--force" in err and study.read_bytes() == before


def test_report_into_a_folder_of_sixty_files_keeps_them_all(tmp_path, capsys):
    """`vehid report archive.h5 --out DIR` on a folder of about 60 files (notes, a thesis draft, the input
    archive itself) left only the 13 report files."""
    folder = tmp_path / "work"
    folder.mkdir()
    for k in range(58):
        (folder / f"note_{k:02d}.txt").write_text(f"note {k}")
    (folder / "thesis.tex").write_text("draft")
    archive = _identification_archive(folder / "archive.h5")
    before = _snapshot(folder)
    assert main(["report", str(archive), "--out", str(folder), "--dpi", "30", "--quiet"]) == 2
    assert _snapshot(folder) == before
    assert main(["report", str(archive), "--out", str(folder), "--dpi", "30", "--quiet", "--force"]) == 0
    capsys.readouterr()
    after = _snapshot(folder)
    assert all(after[name] == content for name, content in before.items()) and len(after) > len(before)
    assert read_archive(archive).kind == "identification"  # the input survives, readable


def test_save_model_is_checked_before_the_identification(tmp_path, capsys, monkeypatch):
    """`--save-model m.xlsx` (or a directory) was refused only after the identification had run."""
    record = _record(tmp_path / "record.csv")
    (tmp_path / "models").mkdir()
    _no_work(monkeypatch)
    for target in ("m.xlsx", str(tmp_path / "models")):
        assert main(["identify", str(record), *ARX, "--save-model", target]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and target in err[0], err
