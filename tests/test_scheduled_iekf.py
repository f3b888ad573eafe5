"""Speed-scheduled modal models identified from one record whose speed varies.

Truth: the linear single-track (bicycle) model with fixed cornering stiffnesses, mass and yaw inertia,
states lateral velocity and yaw rate (Mitschke & Wallentowitz, ch. on the linear single-track model):

    m (vy' + v r) = -(Cf + Cr)/v vy - (lf Cf - lr Cr)/v r + Cf delta
    Iz r'         = -(lf Cf - lr Cr)/v vy - (lf^2 Cf + lr^2 Cr)/v r + lf Cf delta
    ay            = vy' + v r

with the speed v swept between 10 and 30 m/s; outputs yaw rate and lateral acceleration. The record is
the exact discretisation of that system over each sample (A(v) frozen at the sample's start, the steer
linear between samples), so the modes at each speed are the closed-form eigenvalues of A(v).
"""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
import scipy.signal
from conftest import run_vehid

from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
from vehid.identification.assessment.metrics import nrmse_fit
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.models.scheduled import OutputMap, ScheduledModalModel
from vehid.identification.filtering.scheduled_iekf import (ScheduledIEKFOptions, default_grid, identify_scheduled,
                                                             knot_cells)
from vehid.identification.dataio.storage import read_value, write_value
from vehid.identification.assessment.validation import score, split_holdout

MASS, YAW_INERTIA, LF, LR = 1500.0, 2500.0, 1.2, 1.5  # kg, kg m^2, m, m
CF, CR = 80_000.0, 100_000.0  # N/rad per axle: an understeering car
DT = 0.01  # s
DURATION = 120.0  # s: three speed cycles of 40 s
GRID = (10.0, 15.0, 20.0, 25.0, 30.0)  # m/s


def bicycle(v: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, B, C, D of the linear single-track model at speed v; outputs yaw rate and lateral acceleration."""
    A = np.array([[-(CF + CR) / (MASS * v), -v - (LF * CF - LR * CR) / (MASS * v)],
                  [-(LF * CF - LR * CR) / (YAW_INERTIA * v), -(LF**2 * CF + LR**2 * CR) / (YAW_INERTIA * v)]])
    B = np.array([CF / MASS, LF * CF / YAW_INERTIA])
    C = np.array([[0.0, 1.0], [A[0, 0], A[0, 1] + v]])
    D = np.array([0.0, CF / MASS])
    return A, B, C, D


def closed_form_mode(v: float) -> tuple[float, float]:
    """Natural frequency (Hz) and damping ratio of the complex pair of A(v)."""
    eigenvalue = np.linalg.eigvals(bicycle(v)[0])[0]
    return abs(eigenvalue) / (2 * np.pi), -eigenvalue.real / abs(eigenvalue)


def single_track_record(seed: int = 0, noise: float = 0.01, frozen: float | None = None, *, duration: float = DURATION,
                        dt: float = DT, speed_of=lambda t: 20.0 - 10.0 * np.cos(2 * np.pi * t / 40.0)
                        ) -> tuple[IOData, np.ndarray]:
    """Steer (band-limited to 2 Hz, 0.02 rad RMS), speed ``speed_of(t)`` (20 - 10 cos(2 pi t / 40) m/s), outputs
    with white noise of ``noise`` times their RMS; returns the record and the speed. With ``frozen`` the car's
    dynamics are those at that speed throughout, while the speed returned still varies (a channel they do not
    depend on)."""
    rng = np.random.default_rng(seed)
    samples = int(round(duration / dt))
    t = np.arange(samples) * dt
    speed = speed_of(t)
    b, a = scipy.signal.butter(4, 2.0, fs=1 / dt)
    steer = scipy.signal.lfilter(b, a, rng.standard_normal(samples))
    steer *= 0.02 / np.std(steer)
    blocks = np.zeros((samples, 4, 4))  # first-order hold: exp of [[A, B, 0], [0, 0, 1], [0, 0, 0]] dt per sample
    outputs = np.empty((samples, 2, 2))
    feedthrough = np.empty((samples, 2))
    for k in range(samples):
        A, B, C, D = bicycle(speed[k] if frozen is None else frozen)
        blocks[k, :2, :2], blocks[k, :2, 2], blocks[k, 2, 3] = A * dt, B * dt, 1.0
        outputs[k], feedthrough[k] = C, D
    E = _exponential(blocks)
    x = np.zeros(2)
    y = np.empty((samples, 2))
    for k in range(samples):
        y[k] = outputs[k] @ x + feedthrough[k] * steer[k]
        if k + 1 < samples:
            x = E[k, :2, :2] @ x + (E[k, :2, 2] - E[k, :2, 3]) * steer[k] + E[k, :2, 3] * steer[k + 1]
    y += noise * rng.standard_normal(y.shape) * y.std(axis=0)
    return IOData(t=t, u=steer[:, None], y=y, input_names=("delta",), output_names=("yawRate", "ayCG")), speed


def _exponential(blocks: np.ndarray) -> np.ndarray:
    """Matrix exponentials of a stack of small matrices by their Taylor series (vectorised).

    For norms below 2 the series to the 30th power leaves a remainder below 2^31 / 31! ~ 3e-25:
    the exponential to rounding (checked against scipy.linalg.expm in the test below).
    """
    assert np.max(np.linalg.norm(blocks, ord=1, axis=(1, 2))) < 2.0
    result = np.broadcast_to(np.eye(blocks.shape[1]), blocks.shape).copy()
    term = result.copy()
    for power in range(1, 31):
        term = term @ blocks / power
        result += term
    return result


def test_the_truth_uses_the_exact_exponential():
    rng = np.random.default_rng(7)
    blocks = rng.standard_normal((5, 4, 4)) * 0.1
    assert np.allclose(_exponential(blocks), [scipy.linalg.expm(b) for b in blocks], rtol=0, atol=1e-14)


@pytest.fixture(scope="module")
def identified():
    data, speed = single_track_record()
    estimation, validation = split_holdout(data, 0.3)
    split = estimation.n_samples
    # the unscheduled model of the default pipeline's filter settings, the start of the scheduled one
    linear = identify_iekf(estimation, ModalStructure.default(2, 1, 2), options=IEKFOptions.invariant()).model
    result = identify_scheduled(estimation, speed[:split], linear, variable="vx",
                                options=ScheduledIEKFOptions(grid=GRID))
    return result, linear, validation, speed[split:]


def test_modes_at_speeds_agree_with_the_closed_form(identified):
    result, _, _, _ = identified
    family = result.model
    for v in (10.0, 20.0, 30.0):
        (mode,) = family.model_at(v).uncertainty().modes
        frequency, damping = closed_form_mode(v)
        # model error, not noise, sets these tolerances (the std are far smaller): the true coefficients
        # vary as 1/v, the family's are linear between knots 5 m/s apart, and its states' gauge moves
        # with the speed. Over seeds 0-3 the largest deviations were 1.5 % in frequency and 0.029 in
        # damping (at 10 m/s, the most damped, always too high): tolerances 5 % and 0.05
        assert mode.frequency_hz == pytest.approx(frequency, rel=0.05)
        assert mode.damping == pytest.approx(damping, abs=0.05)
        assert np.isfinite(mode.frequency_hz_std) and mode.frequency_hz_std > 0
    # the property the schedule exists for: the yaw mode slows and loses damping with speed
    modes = [family.model_at(v).modes()[0] for v in GRID]
    assert all(a.frequency_hz > b.frequency_hz for a, b in zip(modes, modes[1:]))
    assert all(a.damping > b.damping for a, b in zip(modes, modes[1:]))


def test_scheduled_model_beats_the_unscheduled_one_on_held_out_data(identified):
    result, linear, validation, speed = identified
    scheduled = nrmse_fit(validation.y, result.model.simulate_outputs(validation.u, validation.dt, schedule=speed))
    unscheduled = score(linear, validation, initial_state="zero").fit
    # measured over seeds 0-3 (yaw rate / lateral acceleration): scheduled 94.5-98.8 / 97.9-98.5 %,
    # unscheduled 78.4-82.5 / 59.3-64.5 %. The scheduled model must win on every output, by a margin
    # (5 points) and to a floor (90 %) well inside that spread
    assert np.all(scheduled > unscheduled + 5.0)
    assert np.all(scheduled > 90.0)


def test_output_map_reproduces_an_affine_map_and_its_casadi_twin():
    import casadi as ca

    rng = np.random.default_rng(3)
    z = rng.standard_normal((400, 2)) * [1.0, 5.0]
    y = z * [0.8, -1.5] + [0.1, 2.0]  # piecewise-linear maps hold every affine one exactly
    fitted = OutputMap.fit(z, y, 5, ridge=0.0)
    assert np.allclose(fitted.apply(z), y, rtol=0, atol=1e-9)
    # beyond the end nodes the end segments continue: still the affine map
    far = np.array([[10.0, -40.0], [-10.0, 40.0]])
    assert np.allclose(fitted.apply(far), far * [0.8, -1.5] + [0.1, 2.0], rtol=0, atol=1e-9)
    saturating = OutputMap(np.array([[-1.0, 0.0, 1.0]]), np.array([[-0.5, 0.0, 0.5]]))
    symbol = ca.SX.sym("z", 1)
    twin = ca.Function("g", [symbol], [saturating.apply_casadi(symbol)])
    points = np.linspace(-3.0, 3.0, 61)
    assert np.allclose([float(twin(p)) for p in points], saturating.apply(points[:, None])[:, 0], rtol=0, atol=1e-12)
    assert OutputMap.from_dict(fitted.to_dict()).ordinates.tolist() == fitted.ordinates.tolist()


def test_output_map_does_not_lose_on_a_linear_truth(identified):
    # --schedule --nonlinear on a car that is linear in amplitude: the map fitted on the estimation part
    # must keep the scheduled model's hold-out fit. Seeds 0-1 measured a change of -0.01 to +0.3 points;
    # it may lose at most the 0.5 points the command asks a map to win by before it keeps one
    result, _, validation, speed = identified
    family = result.model
    data, whole_speed = single_track_record()  # the fixture's record, rebuilt: its estimation part
    estimation, _ = split_holdout(data, 0.3)
    linear = nrmse_fit(validation.y, family.simulate_outputs(validation.u, validation.dt, schedule=speed))
    outputs = family.simulate_outputs(estimation.u, estimation.dt, schedule=whole_speed[:estimation.n_samples])
    for count in (3, 5):
        mapped = dataclasses.replace(family, output_map=OutputMap.fit(outputs, estimation.y, count))
        fit = nrmse_fit(validation.y, mapped.simulate_outputs(validation.u, validation.dt, schedule=speed))
        assert np.all(fit > linear - 0.5), (count, fit, linear)
        again = ScheduledModalModel.from_dict(mapped.to_dict())
        assert np.array_equal(again.simulate_outputs(validation.u, validation.dt, schedule=speed),
                              mapped.simulate_outputs(validation.u, validation.dt, schedule=speed))


def test_covariance_travels_and_the_family_round_trips(identified, tmp_path):
    import h5py

    family = identified[0].model
    assert family.parameter_covariance is not None
    again = ScheduledModalModel.from_dict(family.to_dict())
    assert np.array_equal(again.parameters, family.parameters)
    assert np.array_equal(again.parameter_covariance, family.parameter_covariance)
    with h5py.File(tmp_path / "family.h5", "w") as archive:
        write_value(archive, "model", family)
    with h5py.File(tmp_path / "family.h5", "r") as archive:
        stored = read_value(archive, "model")
    assert np.array_equal(stored.parameters, family.parameters)
    assert np.allclose(stored.parameter_covariance, family.parameter_covariance, rtol=0, atol=0)
    rows = stored.modes_at(stored.grid)
    assert [row["value"] for row in rows] == list(GRID)
    assert all(np.isfinite(row["modes"][0]["damping_std"]) for row in rows)


def test_a_frozen_schedule_simulates_the_model_at_that_value():
    # between knots, at a constant schedule, the family is the linear model model_at(v): the input gauge
    # it simulates in and model_at's canonical form are one model there (similarity), to rounding
    structure = ModalStructure.default(2, 1, 2)
    rng = np.random.default_rng(2)
    offsets = rng.standard_normal((3, 2))
    theta = np.concatenate([[-3.0 - k, 6.0 + k, *rng.standard_normal(structure.n_parameters - 2), *offsets[k]]
                            for k in range(3)])
    family = ScheduledModalModel.from_parameters(structure, [10.0, 20.0, 30.0], theta, variable="vx")
    u = rng.standard_normal((400, 1))
    for v in (10.0, 17.5, 30.0):
        simulated = family.simulate_outputs(u, 0.01, schedule=np.full(400, v))
        # the output offset, linear in the schedule between grid values, is added to the linear model's outputs
        offset = [np.interp(v, [10.0, 20.0, 30.0], offsets[:, i]) for i in range(2)]
        reference = family.model_at(v).simulate_outputs(u, 0.01) + offset
        assert np.allclose(simulated, reference, rtol=0, atol=1e-9 * np.abs(reference).max())
    # the schedule as the last input column is the same simulation
    assert np.array_equal(family.simulate_outputs(np.column_stack([u, np.full(400, 17.5)]), 0.01),
                          family.simulate_outputs(u, 0.01, schedule=np.full(400, 17.5)))
    with pytest.raises(InputError, match="schedule"):
        family.simulate_outputs(u, 0.01)


def test_default_grid_sits_at_quantiles_and_refuses_a_constant_schedule():
    grid = default_grid(np.linspace(10.0, 30.0, 2001), 5)
    # quantiles of a uniform sweep are evenly spaced between its 2nd and 98th percentiles
    assert np.allclose(grid, np.linspace(10.4, 29.6, 5), atol=1e-9)
    with pytest.raises(InputError, match="barely varies"):
        default_grid(np.full(500, 20.0))
    # a schedule that dwells gets its crowded knots merged, not refused (tests/test_plausibility.py)


def test_knot_cells_split_the_record_by_nearest_knot():
    """The samples a knot's local start is found on: every sample in exactly one cell, the cell of its
    nearest knot (the end knots also take the samples beyond the grid, where the family holds them)."""
    schedule = np.random.default_rng(3).uniform(0.0, 50.0, 4000)
    grid = np.array([10.0, 15.0, 25.0, 40.0])
    cells = knot_cells(schedule, grid)
    joined = np.sort(np.concatenate(cells))
    np.testing.assert_array_equal(joined, np.arange(schedule.size))
    for k, rows in enumerate(cells):
        distances = np.abs(schedule[rows, None] - grid[None, :])
        assert np.all(distances[:, k] <= distances.min(axis=1)), k
    assert np.all(schedule[cells[0]] <= 12.5) and np.any(schedule[cells[0]] < 10.0)
    assert np.all(schedule[cells[-1]] >= 32.5) and np.any(schedule[cells[-1]] > 40.0)


def _vehid(*args):
    return run_vehid(*args)


def _write_log(path, seed):
    data, speed = single_track_record(seed=seed)
    np.savetxt(path, np.column_stack([data.t, data.u[:, 0], speed * 3.6, data.y]), delimiter=",",
               header="t,delta,vx_kmh,yawRate,ayCG", comments="")
    return path


@pytest.fixture(scope="module")
def speed_log(tmp_path_factory):
    return _write_log(tmp_path_factory.mktemp("logs") / "log.csv", 5)


def test_identify_schedule_json_contract_and_model_file(speed_log, tmp_path):
    import json

    model_file = tmp_path / "family.json"
    completed = _vehid("identify", str(speed_log), "--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule",
                       "vx_kmh", "--scale", "vx_kmh=0.2777777777777778", "--schedule-grid", ",".join(map(str, GRID)),
                       "--order", "2", "--p", "1e-5", "--passes", "20", "--validation", "0.3", "--json", "--quiet",
                       "--save-model", str(model_file), "--validation-file", str(_write_log(tmp_path / "other.csv", 6)))
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    entry = summary["scheduled"]
    assert entry["channel"] == "vx_kmh" and entry["grid"] == list(GRID)  # the schedule scaled to m/s, never offset
    assert [row["value"] for row in entry["modes_at"]] == list(GRID)
    for row in entry["modes_at"]:
        (mode,) = row["modes"]
        assert {"frequency_hz", "frequency_hz_std", "damping", "damping_std"} <= set(mode)
        frequency, damping = closed_form_mode(row["value"])
        # the command removes each channel's mean, which the family's output offsets absorb: the
        # tolerances of the test above hold (measured on this record: 0.7 % and 0.024 at most)
        assert mode["frequency_hz"] == pytest.approx(frequency, rel=0.05)
        assert mode["damping"] == pytest.approx(damping, abs=0.05)
    # the returned model's validation fit (held-out part and another drive, each with its own speed) is the
    # scheduled one, ahead of the unscheduled start on every output
    assert len(summary["validation_records"]) == 2
    assert np.all(np.array(summary["validation_fit_percent"]) > np.array(entry["unscheduled"]["validation_fit_percent"]))
    assert entry["model_returned"] == "scheduled" and summary["decision_margins"]["schedule"]["choice"] == "scheduled"
    saved = ScheduledModalModel.from_dict(json.loads(model_file.read_text()))
    assert saved.variable == "vx_kmh" and saved.parameter_covariance is not None
    from vehid.identification.dataio.model_files import check_model_target

    assert check_model_target(model_file) == model_file  # a rerun may replace the file it wrote (it has no A)


def test_identify_schedule_returns_the_unscheduled_model_where_the_dynamics_ignore_the_channel(tmp_path):
    import json

    # a car whose dynamics are those at 20 m/s throughout, logged with a varying speed channel: the
    # unscheduled model is right, so the family must not win by the margin; a note says so, and since the
    # model returned has no problem, --strict has no warning to stop on (exit 0)
    data, speed = single_track_record(seed=2, frozen=20.0)
    path = tmp_path / "frozen.csv"
    np.savetxt(path, np.column_stack([data.t, data.u[:, 0], speed, data.y]), delimiter=",",
               header="t,delta,vx,yawRate,ayCG", comments="")
    completed = _vehid("identify", str(path), "--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule", "vx",
                       "--order", "2", "--p", "1e-5", "--passes", "20", "--validation", "0.3", "--json", "--quiet",
                       "--strict")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    assert summary["scheduled"]["model_returned"] == "unscheduled" and summary["model_returned"] == "filter"
    assert summary["decision_margins"]["schedule"]["choice"] == "unscheduled"
    assert summary["validation_fit_percent"] == summary["scheduled"]["unscheduled"]["validation_fit_percent"]
    assert summary["warnings"] == [] and any("unscheduled model is returned" in line for line in summary["notes"])


def test_warnings_and_strict_concern_the_returned_family_not_its_discarded_start(tmp_path):
    """An oval-like drive: 42 s of speeds swept between 10 and 30 m/s, then 18 s held at 10 m/s (the held-out
    part). The unscheduled start averages the speeds and validates below zero on the slow part (its lateral
    acceleration gain is several times the slow car's); the family validates well and is returned. No
    warning speaks of the discarded start, --strict exits 0, its problems are notes, and the returned
    family's modes come first in the text and the JSON."""
    from vehid.identification.dataio.archive import read_archive

    data, speed = single_track_record(seed=7, duration=60.0, dt=0.02,
                                      speed_of=lambda t: np.where(t < 42.0, 20.0 - 10.0 * np.cos(2 * np.pi * t / 14.0), 10.0))
    path = tmp_path / "oval.csv"
    np.savetxt(path, np.column_stack([data.t, data.u[:, 0], speed, data.y]), delimiter=",",
               header="t,delta,vx,yawRate,ayCG", comments="")
    archive = tmp_path / "oval.h5"
    completed = _vehid("identify", str(path), "--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule", "vx",
                       "--order", "2", "--p", "1e-5", "--passes", "10", "--schedule-p", "1e-2", "--validation", "0.3",
                       "--strict", "--out", str(archive))
    assert completed.returncode == 0, completed.stderr
    summary = read_archive(archive).summary  # the command's JSON summary, kept with the archive
    start = summary["scheduled"]["unscheduled"]["validation_fit_percent"]
    # the case: the start explains less than the mean on the slow part (measured -51 % on ayCG), the family
    # explains nearly all of it (measured 97.6 and 98.5 %, 1 % output noise)
    assert min(start) < 0 and min(summary["validation_fit_percent"]) > 90.0
    assert summary["model_returned"] == "scheduled" and summary["warnings"] == []
    assert any(note.startswith("not returned, the linear") and "below zero" in note for note in summary["notes"])
    # the returned family's modes first: per knot in the JSON, before the start's in the text
    assert all("schedule_value" in mode for mode in summary["modes"]) and summary["linear_modes"]
    assert "schedule_value" not in summary["linear_modes"][0]
    text = completed.stdout
    assert text.index("modes of the returned scheduled model") < text.index("modes of the linear model")
    assert text.splitlines()[0].startswith("model returned: the scheduled family")


def test_identify_schedule_on_a_race_cars_log_is_stable_at_every_knot():
    import json
    from pathlib import Path

    # a real car's lap (tests/data/race_car_250lm/SOURCE.md): the filter once let the slowest knot drift
    # to an unstable real pole (estimation fit -15138 %). Properties, not figures: every knot stable,
    # the family's simulation explains more than the outputs' means, and the decision follows its rule
    log = Path(__file__).parent / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
    completed = _vehid("identify", str(log), "--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule", "vx",
                       "--order", "2", "--validation", "0.4", "--json", "--quiet")
    assert completed.returncode == 0, completed.stderr
    summary = json.loads(completed.stdout)
    entry = summary["scheduled"]
    assert all(mode["damping"] > 0 for row in entry["modes_at"] for mode in row["modes"])
    assert np.all(np.array(entry["estimation_fit_percent"]) > 0)
    margin = summary["decision_margins"]["schedule"]
    family = float(np.mean(entry["validation_fit_percent"]))
    unscheduled = float(np.mean(entry["unscheduled"]["validation_fit_percent"]))  # both by the run's one rule
    assert (entry["model_returned"] == "scheduled") == (family > unscheduled + 0.5)
    assert margin["choice"] == entry["model_returned"]


def test_identify_schedule_refuses_bad_input(speed_log, capsys):
    from vehid.scenarios.cli import main

    for args, message in ((("--schedule", "nonexistent"), "nonexistent"),
                          (("--schedule", "yawRate"), "also named"),
                          (("--schedule", "vx_kmh", "--schedule-grid", "30,10"), "increasing"),
                          (("--schedule", "vx_kmh", "--schedule-knots", "1"), "knots")):
        status = main(["identify", str(speed_log), "--inputs", "delta", "--outputs", "yawRate,ayCG", *args,
                       "--order", "2", "--quiet"])
        error = capsys.readouterr().err
        assert status == 2, error
        assert message in error and len(error.strip().splitlines()) == 1
