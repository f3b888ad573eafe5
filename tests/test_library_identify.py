"""`identify()` from Python gives what `vehid identify` gives on the same file, and checks its options once."""

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import library_spy, mutable_parts, printed_json, run_vehid, without_run_times

from vehid.identification.errors import InputError
from vehid.identification.jsonable import to_jsonable
from vehid.identification.pipeline import DEFAULT_PASSES, Identification, IdentifyOptions, identify
from vehid.identification.dataio.preparation import ReadSettings, read_record
from vehid.scenarios.cli import main

DRYER = Path(__file__).parent / "data" / "dryer" / "dryer.dat"
# both run the same arithmetic on the same samples in one process; 1e-9 leaves room only for
# the JSON round trip of the command's summary (shortest-repr floats, exact) and nothing else
AGREEMENT = 1e-9


def _command(capsys, *arguments):
    assert main(["identify", str(DRYER), "--inputs", "1", "--outputs", "2", "--dt", "0.08", "--json",
                 *arguments]) == 0
    return json.loads(capsys.readouterr().out)


def _dryer():
    return read_record(DRYER, ReadSettings(inputs=("1",), outputs=("2",), dt=0.08))


def _close(library, command):
    library = np.asarray(library, dtype=float)
    command = np.asarray(command, dtype=float)
    assert library.shape == command.shape
    assert np.allclose(library, command, rtol=AGREEMENT, atol=AGREEMENT * max(1.0, float(np.max(np.abs(command)))))


@pytest.fixture(scope="module")
def given_p_run():
    """The library's run with a given p and a held-out tail (the command's twin runs in the test)."""
    return identify(_dryer(), order=2, validation=0.3, options=IdentifyOptions(p=1e-4, passes=8))


def test_library_reproduces_the_command_model_and_scores(capsys, given_p_run):
    """A given p and a held-out tail: the model, its eigenvalues and every score agree to 1e-9."""
    summary = _command(capsys, "--order", "2", "--p", "1e-4", "--passes", "8", "--validation", "0.3")
    result = given_p_run
    assert isinstance(result, Identification)
    for name in "ABCD":
        _close(getattr(result.model, name), summary[name])
    eigenvalues = np.sort_complex(np.linalg.eigvals(result.model.A))
    reported = np.sort_complex(np.array([complex(re, im) for re, im in summary["eigenvalues"]]))
    _close(eigenvalues.real, reported.real)
    _close(eigenvalues.imag, reported.imag)
    _close(result.fit_percent, summary["fit_percent"])
    _close(result.estimation_fit_percent, summary["estimation_fit_percent"])
    _close(result.validation_fit_percent, summary["validation_fit_percent"])
    assert result.warnings == tuple(summary["warnings"])
    assert [row.order for row in result.orders] == [row["order"] for row in summary["orders_tried"]]
    assert {decision.name for decision in result.decisions} == set(summary.get("decision_margins", {}))
    # the result renders the command's summary: every key, and the same values (up to the JSON round trip)
    rendered = json.loads(json.dumps(to_jsonable(result.summary)))
    assert set(rendered) == set(summary)
    for key in ("order", "method", "passes_run", "stop_reason", "notes", "warnings", "p", "q_schedule",
                "decision_margins", "initial_state", "horizon"):
        assert rendered[key] == summary[key], key


def test_the_result_is_frozen_all_the_way_down(given_p_run):
    """Nothing the result holds can be changed: its summary, and the model, the records and the estimator's run it
    renders the summary from (their arrays and ``meta``); a caller that changes a rendered summary changes only
    its copy."""
    assert mutable_parts(given_p_run) == []
    assert mutable_parts(given_p_run.summary) == []
    with pytest.raises(TypeError):
        given_p_run.summary["order"] = 99
    with pytest.raises(ValueError):  # the summary's matrices are the model's
        given_p_run.model.A[0, 0] = 99.0
    with pytest.raises(TypeError):  # the summary's "start" is the filter's meta
        given_p_run.estimator.meta["p_start"] = 99.0
    rendered = given_p_run.render()
    rendered["order"], rendered["p_tried"][:] = 99, []
    assert given_p_run.render()["order"] == given_p_run.summary["order"] == 2
    assert given_p_run.render()["p_tried"] == [row.as_dict() for row in given_p_run.tuning.tried]


def test_the_command_prints_the_rendering_of_the_library_result(capsys, monkeypatch, tmp_path):
    """`vehid identify --json` calls the library's identify() once and prints its result's rendering, every key and
    value (the archive and the model file written by the library among them); identify() called from Python on
    the same file and settings renders the same summary, its run times aside."""
    import vehid.identification as package

    library, results = library_spy(monkeypatch, package, "identify")
    archive, model_file = tmp_path / "run.h5", tmp_path / "model.json"
    summary = _command(capsys, "--order", "2", "--p", "1e-4", "--passes", "8", "--validation", "0.3",
                       "--out", str(archive), "--save-model", str(model_file))
    (result,) = results
    assert summary == printed_json(result.render())
    assert summary["archive"] == str(archive) and summary["model_file"] == str(model_file)
    again = library(str(DRYER), order=2, validation=0.3, options=IdentifyOptions(p=1e-4, passes=8),
                    reading=ReadSettings(inputs=("1",), outputs=("2",), dt=0.08), out=archive, save_model=model_file,
                    force=True)
    assert without_run_times(printed_json(again.render())) == without_run_times(summary)


def test_options_are_checked_where_they_are_defined():
    """Each number is refused by name; the pass budget's default is the command's."""
    assert IdentifyOptions().passes == DEFAULT_PASSES
    for bad, name in ((dict(p=0.0), "p"), (dict(p=float("nan")), "p"), (dict(passes=0), "passes"),
                      (dict(passes=2.5), "passes"), (dict(horizon=0), "horizon"), (dict(nodes=1), "nodes"),
                      (dict(nonlinear_p=()), "nonlinear_p"), (dict(nonlinear_passes=0), "nonlinear_passes")):
        with pytest.raises(InputError, match=name):
            IdentifyOptions(**bad)


def test_identify_refuses_what_is_not_a_record():
    with pytest.raises(InputError, match="IOData"):
        identify(np.zeros((10, 2)))


def test_validation_records_in_memory_score_as_validation_files(capsys, tmp_path):
    """A validation record given to identify() is scored as the command scores the same samples given as a file."""
    table = np.loadtxt(DRYER)
    first, second = tmp_path / "first.dat", tmp_path / "second.dat"
    np.savetxt(first, table[:600])
    np.savetxt(second, table[600:])
    settings = ReadSettings(inputs=("1",), outputs=("2",), dt=0.08)
    assert main(["identify", str(first), "--inputs", "1", "--outputs", "2", "--dt", "0.08", "--order", "2",
                 "--p", "1e-4", "--passes", "8", "--validation-file", str(second), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    result = identify(read_record(first, settings), order=2, validation=[read_record(second, settings)],
                      options=IdentifyOptions(p=1e-4, passes=8))
    _close(result.model.A, summary["A"])
    _close(result.validation_fit_percent, summary["validation_fit_percent"])
    assert len(result.summary["validation_records"]) == len(summary["validation_records"]) == 1


def _readme_python_example() -> str:
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    blocks = readme.split("```python\n")[1:]
    assert len(blocks) == 1, "the README shows one Python example"
    return blocks[0].split("```")[0]


@pytest.fixture(scope="module")
def documented_command():
    """``vehid ARGUMENTS --json`` run from the clone's root (where the examples name their records), as a
    function; a command line two examples both name is run once and its summary given to each."""
    summaries: dict[tuple[str, ...], dict] = {}

    def summary_of(arguments: list[str]) -> dict:
        key = tuple(arguments)
        if key not in summaries:
            completed = run_vehid(*arguments, "--json", cwd=Path(__file__).resolve().parents[1])
            assert completed.returncode == 0, completed.stderr
            summaries[key] = json.loads(completed.stdout)
        return summaries[key]

    return summary_of


def test_the_readme_python_example_reproduces_the_command(capsys, monkeypatch, documented_command):
    """The README's example verbatim (default options: p by cross-validation) against the command it names."""
    code = _readme_python_example()
    command_line = next(line for line in code.splitlines() if line.startswith("# as: vehid identify "))
    arguments = command_line.removeprefix("# as: vehid ").split()
    monkeypatch.chdir(Path(__file__).resolve().parents[1])  # the example names the record from the clone's root
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    printed = capsys.readouterr()
    summary = documented_command(arguments)
    result = namespace["result"]
    for name in "ABCD":
        _close(getattr(result.model, name), summary[name])
    _close(result.validation_fit_percent, summary["validation_fit_percent"])
    assert result.warnings == tuple(summary["warnings"]) and printed.out.strip()


def test_the_gallery_example_reproduces_the_command(documented_command):
    """The measured-record example of the documentation's gallery, run as a user runs it, against the
    command its docstring names: the same model and held-out scores to 1e-9."""
    import runpy

    import matplotlib

    matplotlib.use("Agg")  # the example ends in plt.show(), which a test must not block on
    script = Path(__file__).resolve().parents[1] / "docs" / "examples" / "plot_measured_record.py"
    namespace = runpy.run_path(str(script), run_name="__main__")
    import matplotlib.pyplot as plt

    plt.close("all")
    docstring = namespace["__doc__"]
    # the command as the docstring shows it: two lines joined at the shell's continuation backslash
    command = " ".join(docstring.split("vehid identify ")[1].split("\n")[0:2]).replace("\\", " ").split()
    summary = documented_command(["identify", *command])  # it names the record from the clone's root
    result = namespace["result"]
    for name in "ABCD":
        _close(getattr(result.model, name), summary[name])
    _close(result.validation_fit_percent, summary["validation_fit_percent"])
    assert result.warnings == tuple(summary["warnings"])


def test_a_classical_method_runs_the_same_pipeline(capsys):
    """A comparator over a range of orders: the same order chosen, model and scores as the command's."""
    summary = _command(capsys, "--method", "n4sid", "--order", "2-3", "--validation", "0.3")
    result = identify(_dryer(), order="2-3", validation=0.3, options=IdentifyOptions(method="n4sid"))
    assert result.method == "n4sid" and result.order == summary["order"]
    for name in "ABCD":
        _close(getattr(result.model, name), summary[name])
    _close(result.validation_fit_percent, summary["validation_fit_percent"])
    assert [decision.name for decision in result.decisions] == ["order"]
    assert [row.order for row in result.orders] == [row["order"] for row in summary["orders_tried"]]


def test_the_library_is_one_function_under_every_name():
    """The package's identify and the pipeline module's are one function."""
    import vehid.identification as package

    assert package.identify is identify
    assert package.IdentifyOptions is IdentifyOptions and package.Identification is Identification


HEAVY = ("numpy", "scipy", "casadi", "h5py", "matplotlib")


def test_the_identify_options_register_without_the_numerical_stack():
    """The command module and its options (pipeline, schedule, single-track) import none of the heavy packages."""
    import subprocess
    import sys

    code = ("import argparse, sys\n"
            "import vehid.scenarios.commands.identify\n"
            "from vehid.scenarios.commands import identify_options as options\n"
            "parser = argparse.ArgumentParser()\n"
            "options.register_pipeline_options(parser)\n"
            "options.register_schedule_options(parser)\n"
            "options.register_single_track_options(parser)\n"
            f"print(sorted({{name.split('.')[0] for name in sys.modules}} & set({HEAVY!r})))\n")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert completed.stdout.strip() == "[]", completed.stdout


def test_the_scenarios_identification_modules_parse_no_arguments():
    """argparse lives with the commands: the pipeline's scenario modules take plain settings."""
    import ast

    root = Path(__file__).resolve().parents[1] / "scenarios"
    for name in ("scheduled_identify", "single_track_identify", "calibration", "model_checks"):
        tree = ast.parse((root / f"{name}.py").read_text(encoding="utf-8"))
        imported = {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
        imported |= {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) and node.module}
        assert "argparse" not in imported, name


def test_a_schedule_is_refused_where_it_does_not_fit_the_record():
    """One schedule value per sample of one record: anything else is named before any work."""
    record = _dryer()
    with pytest.raises(InputError, match="one finite value per sample"):
        identify(record, order=2, schedule=np.ones(record.n_samples - 1))
    with pytest.raises(InputError, match="one finite value per sample"):
        identify(record, order=2, schedule=np.full(record.n_samples, np.nan))
    with pytest.raises(InputError, match="one record"):
        identify([record, record], order=2, schedule=np.ones(record.n_samples))
    with pytest.raises(InputError, match="schedule_p"):
        IdentifyOptions(schedule_p=(0.0,))
