"""`vehid report`: what a small archive written with the archive API yields; bad archives fail cleanly."""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest

from vehid.identification import IOData, append_history, read_archive, run_group, write_archive, write_record, write_run
from vehid.identification.assessment.metrics import fit_metrics
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.cli import main
from vehid.scenarios.report import archive_figures, archive_table

OUTPUTS = ("yaw_rate", "roll_angle")
UNITS = ("rad/s", "rad")


def _model(n: int) -> ModalModel:
    structure = ModalStructure.default(n, 1, 2)
    theta = structure.initial_parameters(sigma=-3.0, omega=4.0, omega_spread=1.5)
    theta[structure.slices()["B"]] = np.linspace(0.5, 1.5, n)
    return ModalModel.from_parameters(structure, theta, input_names=("steer",), output_names=OUTPUTS)


def _small_archive(path):
    dt = 0.01
    t = np.arange(400) * dt
    steer = np.sin(2 * np.pi * 0.7 * t) + 0.3 * np.sin(2 * np.pi * 2.1 * t)
    source = _model(4)
    y = source.simulate_outputs(steer, dt) + 1e-3 * np.random.default_rng(0).normal(size=(t.size, 2))
    data = IOData(t, steer, y, input_names=("steer",), output_names=OUTPUTS, output_units=UNITS)
    with write_archive(path, kind="identification", config={"orders": [2, 4]}, seeds=[0]) as handle:
        write_record(handle, "identification", data)
        for n in (2, 4):
            model = _model(n)
            run = run_group(handle, f"n{n}")
            for k in range(5):
                append_history(run, {
                    "parameters": model.parameters * (1 + 0.5 * np.exp(-k)),
                    "fit_filter": [95.0 + k, 96.0 + k * 0.5],
                    "fit_continuous": [94.0 + k, 95.0 + k * 0.5],
                    "trace_p": 10.0 ** (1 - k),
                    "min_eig_p": 10.0 ** (-2 - k),
                    "seconds": 0.1,
                }, units={"fit_filter": "%", "fit_continuous": "%", "seconds": "s"})
            write_run(handle, f"n{n}", model=model, metrics=fit_metrics(y, model.simulate_outputs(steer, dt)))
    return path


def test_archive_figures_and_table_cover_everything_present(tmp_path):
    archive = read_archive(_small_archive(tmp_path / "study.h5"))
    figures = archive_figures(archive, window=(1.0, 3.0), max_lag=20)
    assert set(figures) == {
        "parameters_n2", "parameters_n4", "convergence_n2", "convergence_n4", "orders", "eigenvalues",
        "bode", "residuals_identification_n2", "residuals_identification_n4", "fits_identification",
        "residual_tests_identification_n2", "residual_tests_identification_n4",
    }
    assert [ax.get_title().split(" (")[0] for ax in figures["parameters_n4"].axes] == ["modal", "B", "C", "D"]
    assert len(figures["orders"].axes[0].get_lines()) == 2
    assert len(figures["fits_identification"].axes[0].get_lines()) == 1 + 2
    rows = archive_table(archive)
    assert [row["run"] for row in rows] == ["n2", "n4"] and rows[1]["n"] == 4 and rows[1]["passes"] == 5
    assert rows[1]["R filter (%)"] == pytest.approx(np.mean([99.0, 98.0]))
    assert rows[1]["R identification (%)"] > 99.0  # the source model itself, 0.1 % noise


def test_report_command_writes_figures_pdf_and_table(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path / "results"))
    monkeypatch.chdir(tmp_path)  # a relative --out is taken from the working directory, as by every command
    path = tmp_path / "history.h5"
    with write_archive(path, kind="identification") as handle:
        for k in range(4):
            append_history(run_group(handle, "n3"), {"fit_filter": [90.0 + k], "trace_p": 10.0 ** -k})
    status = main(["report", str(path), "--out", "figs", "--dpi", "30", "--json"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    summary = json.loads(captured.out)
    assert summary["kind"] == "identification" and summary["runs"] == ["n3"]
    assert summary["figures"] == ["convergence_n3"]
    folder = tmp_path / "figs"
    assert not (tmp_path / "results" / "figs").exists()
    assert (folder / "convergence_n3.png").is_file()
    pdf = (folder / "report.pdf").read_bytes()
    assert len(re.findall(rb"/Type\s*/Page\b(?!s)", pdf)) == 1
    table = (folder / "summary.md").read_text()
    assert "| run | passes | R filter (%) | trace(P) |" in table  # no model: no order or eigenvalue column
    assert "| n3 | 4 | 93 | 0.001 |" in table


def test_report_rejects_foreign_and_empty_archives(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("VEHID_RESULTS_DIR", str(tmp_path))
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as handle:
        handle["x"] = np.arange(3)
    assert main(["report", str(foreign)]) == 2  # a foreign file is bad input
    assert "not a workbench results archive" in capsys.readouterr().err
    with write_archive(tmp_path / "empty.h5", kind="identification"):
        pass
    assert main(["report", str(tmp_path / "empty.h5")]) == 2
    assert "nothing to draw" in capsys.readouterr().err


@pytest.mark.parametrize("option", [["--max-lag", "0"], ["--window", "3", "1"], ["--dpi", "5"]])
def test_report_rejects_bad_options(capsys, tmp_path, option):
    assert main(["report", str(tmp_path / "absent.h5"), *option]) == 2
    assert "vehid: error:" in capsys.readouterr().err
