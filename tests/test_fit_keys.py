"""One metric per key: every JSON key ending in ``fit_percent`` is the NRMSE fit of what the report draws.

A command's ``--json`` summary and the report of its archive (``vehid report``) score the same model on
the same record by the same rule (initial state, horizon), so each fit the summary states is the fit of
a curve the report draws: equal to rounding (1e-9 percentage points; the two are the same arithmetic
on the same samples, done twice). The tests walk a summary for every key whose name ends in
``fit_percent`` and look each up in its command's table below:

* ``drawn``: the key is the fit of a run's model on an archived record, by the command's rule, as the
  report's fits figure draws it;
* ``from_rest``: the key is the fit of a run's model simulated from rest over the estimation record (the
  paper's simulation, as ``fit_percent`` states it beside its ``R``), as the report draws it from rest;
* ``not_drawn``: the key scores something no archive keeps (a cross-validation's half records, a
  candidate that was not archived), with the reason.

A key that no table accounts for fails the test: a command that adds one adds its row here, and a
command (``vehid calibrate``, say) joins by a table of its own and a test that runs it.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Iterator, Mapping

import numpy as np
import pytest
from conftest import run_vehid

from vehid.identification.dataio.archive import read_archive
from vehid.scenarios.report import ScoringRule, _model_prediction, _schedule_of, _scoring_rule

TOLERANCE = 1e-9  # percentage points: one computation done twice on the same samples

#: resolves a key to ``(run, record)`` of the archive from the summary and the key's list indices
Where = Callable[[Mapping[str, Any], tuple[int, ...]], tuple[str, str]]


@dataclass(frozen=True)
class FitKeys:
    """What each ``*fit_percent`` key of one command's summary scores (module docstring)."""

    drawn: Mapping[str, Where]
    from_rest: Mapping[str, Where] = field(default_factory=dict)
    not_drawn: Mapping[str, str] = field(default_factory=dict)


def fit_keys(value: Any, path: str = "", indices: tuple[int, ...] = ()) -> Iterator[tuple[str, tuple[int, ...], Any]]:
    """Every key ending in ``fit_percent`` of a JSON value: its path (list entries as ``[]``), list indices, value."""
    if isinstance(value, Mapping):
        for key, item in value.items():
            where = f"{path}.{key}" if path else key
            if key.endswith("fit_percent") and item is not None:
                yield where, indices, item
            yield from fit_keys(item, where, indices)
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield from fit_keys(item, f"{path}[]", indices + (index,))


def check_fit_keys(summary: Mapping[str, Any], archive_path: Any, table: FitKeys) -> set[str]:
    """Compare every ``*fit_percent`` key of ``summary`` with the report's fits of ``archive_path``; the paths checked."""
    found = [key for key in fit_keys(summary) if key[0] not in table.not_drawn]
    for path, _, _ in found:
        assert path in table.drawn or path in table.from_rest, f"{path}: no table accounts for this key"
    archive = read_archive(archive_path)
    rule = _scoring_rule(archive)
    runs = _run_names(summary, archive)
    checked = set()
    for path, indices, value in found:
        run, record = (table.drawn.get(path) or table.from_rest[path])(summary, indices)
        run = runs.get(run, run)
        drawn = _model_prediction(archive.runs[run].model, archive.records[record],
                                  rule if path in table.drawn else ScoringRule(initial_state="zero"),
                                  _schedule_of(archive, record))
        assert drawn is not None, f"{path}: the report draws no {run} on {record}"
        stated = np.asarray(value, dtype=float)
        expected = drawn.fit if stated.ndim else np.mean(drawn.fit)  # a scalar key states the mean over outputs
        np.testing.assert_allclose(stated, expected, rtol=0, atol=TOLERANCE, err_msg=path)
        checked.add(path)
    return checked


RETURNED, LINEAR = "<returned>", "<linear>"  # runs a table names by role, resolved in the archive (_run_names)


def _returned(summary: Mapping[str, Any]) -> str:
    return RETURNED


def _linear(summary: Mapping[str, Any]) -> str:
    return LINEAR


def _run_names(summary: Mapping[str, Any], archive: Any) -> dict[str, str]:
    """The archive's runs of the roles: the model returned (the run the archive names), and the linear model (the
    filter's or its start, refined by its simulation error where the archive holds that run), whichever is returned."""
    from vehid.identification.automatic.archiving import SCORING_RULE

    choice = (summary.get("decision_margins", {}).get("model_returned") or {}).get("choice")
    linear = "start" if choice == "start" else "refined" if "refined" in archive.runs else "iekf"
    returned = (archive.summary or {}).get(SCORING_RULE, {}).get("returned_run")
    return {RETURNED: returned or linear, LINEAR: linear}


def _validation(index: int) -> str:
    return "validation" if index == 0 else f"validation_{index + 1}"


IDENTIFY = FitKeys(
    drawn={
        "estimation_fit_percent": lambda s, i: (_returned(s), "identification"),
        "validation_fit_percent": lambda s, i: (_returned(s), "validation"),  # one held-out part: the mean is its fit
        "validation_records[].fit_percent": lambda s, i: (_returned(s), _validation(i[0])),
        "orders_tried[].estimation_fit_percent": lambda s, i: (_linear(s), "identification"),
        "orders_tried[].validation_fit_percent": lambda s, i: (_linear(s), "validation"),
        "scheduled.estimation_fit_percent": lambda s, i: ("scheduled", "identification"),
        "scheduled.validation_fit_percent": lambda s, i: ("scheduled", "validation"),
        "scheduled.unscheduled.estimation_fit_percent": lambda s, i: (_linear(s), "identification"),
        "scheduled.unscheduled.validation_fit_percent": lambda s, i: (_linear(s), "validation"),
        "nonlinear.estimation_fit_percent": lambda s, i: ("nonlinear", "identification"),
        "nonlinear.validation_fit_percent": lambda s, i: ("nonlinear", "validation"),
        "start_kept.start_estimation_fit_percent": lambda s, i: ("start", "identification"),
        "start_kept.filter_estimation_fit_percent": lambda s, i: ("iekf", "identification"),
    },
    from_rest={
        "fit_percent": lambda s, i: (_returned(s), "identification"),
        "orders_tried[].fit_percent": lambda s, i: (_linear(s), "identification"),
        "scheduled.unscheduled.fit_percent": lambda s, i: (_linear(s), "identification"),
        "nonlinear.fit_percent": lambda s, i: ("nonlinear", "identification"),
    },
    not_drawn={
        "fit_percent_filter": "the filter's own discretisation of the model, not the exact simulation drawn",
        "start_cv_fit_percent": "two-fold cross-validation on half records",
        "p_tried[].cv_fit_percent": "two-fold cross-validation on half records",
        "scheduled.start_fit_percent": "the scheduled filter's start family, not archived",
        "scheduled.p_tried[].estimation_fit_percent": "each p's family; only the chosen one is archived",
        "scheduled.p_tried[].validation_fit_percent": "each p's family; only the chosen one is archived",
        "scheduled.output_map.fit_percent": "the output map tried, archived only where it is kept",
        "scheduled.output_map.tried[].estimation_fit_percent": "each output map tried, not archived",
        "scheduled.output_map.tried[].validation_fit_percent": "each output map tried, not archived",
        "nonlinear.start_fit_percent": "the spline filter's start, not archived",
        "nonlinear.p_tried[].estimation_fit_percent": "each p's spline model; only the chosen one is archived",
        "nonlinear.p_tried[].validation_fit_percent": "each p's spline model; only the chosen one is archived",
    },
)

LINEAR_EXAMPLE = FitKeys(drawn={"fit_percent": lambda s, i: (s["case"], "identification")})


def test_identify_states_the_fits_of_the_curves_its_report_draws(scheduled_race_car_run):
    """A scheduled run on the race car's lap (tests/conftest.py): the family, its linear start and the
    held-out part each scored as the report draws them."""
    summary, archive = scheduled_race_car_run
    checked = check_fit_keys(summary, archive, IDENTIFY)
    assert {"estimation_fit_percent", "validation_fit_percent", "validation_records[].fit_percent", "fit_percent",
            "scheduled.estimation_fit_percent", "scheduled.unscheduled.validation_fit_percent",
            "orders_tried[].estimation_fit_percent"} <= checked


def test_the_linear_example_states_the_fit_of_the_curve_its_report_draws(tmp_path):
    """The paper's single-output case, three passes: its fit_percent is the report's, from rest as the paper's R."""
    archive = tmp_path / "linear_example.h5"
    completed = run_vehid("study", "linear-example", "--case", "single-output", "--passes", "3", "--json", "--quiet",
                          "--out", archive)
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert check_fit_keys(summary, archive, LINEAR_EXAMPLE) == {"fit_percent"}
    # R beside it: the same simulation's eq. 17, so that the pair cannot describe two curves
    assert len(summary["R"]) == len(summary["fit_percent"]) and np.all(np.array(summary["R"]) > summary["fit_percent"])


def test_an_unaccounted_key_fails_the_check():
    """The check cannot pass over a key it does not know (a new one must be given its row)."""
    with pytest.raises(AssertionError, match="no table accounts"):
        check_fit_keys({"novel_fit_percent": [1.0]}, None, FitKeys(drawn={}))  # refused before any archive is read


def test_the_walk_finds_nested_keys_with_their_list_indices():
    summary = {"fit_percent": [1.0], "a": {"b_fit_percent": 2.0, "rows": [{"c_fit_percent": [3.0]}, {"x": 1}]},
               "other": None, "d_fit_percent": None}
    found = {(path, indices) for path, indices, _ in fit_keys(summary)}
    assert found == {("fit_percent", ()), ("a.b_fit_percent", ()), ("a.rows[].c_fit_percent", (0,))}
    assert all(re.search(r"fit_percent$", path) for path, _ in found)


# ``vehid calibrate`` keeps no archive: its report is the figure (--figure), which draws each car's outputs over
# the whole log (NaN where the model does not drive it) against the measured channels, the dashed line at
# ``estimation_samples``. Each key is ``(car, part)``: the NRMSE fit of that car's drawn curve on the part's
# driven samples, per --outputs channel; a ``{channel: fit}`` key scores the --check channels the same way.
CALIBRATE = {
    "estimation_fit_percent": ("calibrated", "estimation"),
    "validation_fit_percent": ("calibrated", "validation"),
    "check_fit_percent": ("calibrated", "validation"),
    "prior_validation_fit_percent": ("prior", "validation"),
    "prior_check_fit_percent": ("prior", "validation"),
    "start_validation_fit_percent": ("start", "validation"),
    "start_check_fit_percent": ("start", "validation"),
}


def check_calibrate_fit_keys(summary: Mapping[str, Any], drawn: Mapping[str, Any]) -> set[str]:
    """Compare every ``*fit_percent`` key of a calibrate summary with the NRMSE fit of the curves its figure draws
    (``drawn``: ``t``, ``measured``, ``predictions`` and ``names`` as given to the figure); the paths checked."""
    from vehid.identification.assessment.metrics import nrmse_fit

    checked = set()
    split = summary["estimation_samples"]
    measured = np.asarray(drawn["measured"])
    names = list(drawn["names"])
    for path, _, value in fit_keys(summary):
        assert path in CALIBRATE, f"{path}: no table accounts for this key"
        car, part = CALIBRATE[path]
        curve = np.asarray(drawn["predictions"][car])
        rows = np.arange(split) if part == "estimation" else np.arange(split, measured.shape[0])
        rows = rows[np.all(np.isfinite(curve[rows]), axis=1)]
        fits = dict(zip(names, nrmse_fit(measured[rows], curve[rows])))
        if isinstance(value, Mapping):
            stated, expected = [value[name] for name in value], [fits[name] for name in value]
        else:
            stated, expected = value, [fits[name] for name in names[:len(value)]]
        np.testing.assert_allclose(np.asarray(stated, dtype=float), expected, rtol=0, atol=TOLERANCE, err_msg=path)
        checked.add(path)
    return checked


def test_calibrate_states_the_fits_of_the_curves_its_figure_draws(tmp_path, monkeypatch, capsys):
    """A drive calibration (known cars over the committed race-car log, the filter left out: tests/
    test_drive_calibration.py) rendered by the command: every fit key is the NRMSE fit of a curve its figure
    draws, on the held-out samples the model drove (a gap left out of the held-out part is not scored)."""
    from test_drive_calibration import CHANNELS, RACE_LOG, _fake_calibration, _race_log

    from vehid.identification.errors import InputError
    from vehid.scenarios import plots
    from vehid.scenarios.cli import main

    log, _ = _race_log()
    fake = _fake_calibration(log)
    drawn: dict[str, Any] = {}
    plot_time_fits = plots.plot_time_fits

    def recording(t, measured, predictions, names, *args, **kwargs):
        drawn.update(t=t, measured=measured, predictions=predictions, names=names)
        return plot_time_fits(t, measured, predictions, names, *args, **kwargs)

    monkeypatch.setattr(plots, "plot_time_fits", recording)
    monkeypatch.setattr("vehid.vehicle.drive_calibration.calibrate_drive", lambda *args, **kwargs: fake)
    monkeypatch.setattr("vehid.vehicle.handling.source_handling",
                        lambda *args, **kwargs: (_ for _ in ()).throw(InputError("not needed here")))
    figure = tmp_path / "fits.png"
    status = main(["calibrate", str(RACE_LOG), *CHANNELS, "--check", "beta_true=sideslip", "--figure", str(figure),
                   "--json"])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    checked = check_calibrate_fit_keys(json.loads(captured.out), drawn)
    assert checked == set(CALIBRATE)
    # the left-out gap is drawn as no curve (NaN) and so cannot enter a score
    assert np.all(np.isnan(drawn["predictions"]["calibrated"][fake.runs[0][1]:fake.runs[1][0]]))


def test_calibrate_check_refuses_an_unaccounted_key():
    with pytest.raises(AssertionError, match="no table accounts"):
        check_calibrate_fit_keys({"estimation_samples": 1, "novel_fit_percent": [1.0]},
                                 {"measured": np.zeros((2, 1)), "names": ["y"], "predictions": {}})
