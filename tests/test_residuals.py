"""Residual tests: whiteness, input cross-correlation, Ljung-Box, innovation consistency, and the identify command's keys."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import returned_run, run_vehid
from scipy.signal import lfilter

from vehid.identification.dataio.archive import open_archive, read_archive, update_archive
from vehid.identification.comparators import identify_with
from vehid.identification.errors import InputError
from vehid.identification.filtering.iekf import IEKFOptions, identify_iekf
from vehid.identification.dataio.iekf_archive import append_iekf_pass, read_iekf_run
from vehid.identification.models.modal_structure import ModalStructure
from vehid.identification.assessment.residuals import nis_band, residual_tests
from vehid.identification.dataio.storage import read_value
from vehid.scenarios import calibration
from vehid.scenarios.handling_study import HandlingConfig, make_records, with_sensor_noise
from vehid.scenarios.linear_example import make_data, true_model
from vehid.scenarios.model_checks import model_residual_tests
from vehid.scenarios.report import archive_figures


def test_white_residuals_pass_with_the_nominal_false_alarm_rate():
    """100 white residual series of 1000 samples beside a smooth (low-passed) input.

    Each 99 % test rejects about 1 (binomial, P(X > 6) < 1e-3). The largest
    cross-correlation over 51 lags of a smooth input would exceed the
    per-lag band far more often: that is why the verdict uses the
    portmanteau with the input's autocorrelation.
    """
    rng = np.random.default_rng(0)
    rejected = {"white": 0, "independent": 0, "max over the band": 0}
    for _ in range(100):
        u = lfilter([0.1], [1.0, -0.9], rng.standard_normal(1000))[:, None]
        tests = residual_tests(u, rng.standard_normal((1000, 1)))
        rejected["white"] += int(not tests.white[0])
        rejected["independent"] += int(not tests.independent[0])
        rejected["max over the band"] += int(tests.input_correlation_max[0] > tests.bound)
    assert rejected["white"] <= 6 and rejected["independent"] <= 6, rejected
    assert rejected["max over the band"] > 6, rejected


def test_coloured_or_input_correlated_residuals_are_flagged():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((4000, 1))
    coloured = lfilter([1.0], [1.0, -0.3], rng.standard_normal(4000))[:, None]
    tests = residual_tests(u, coloured)
    assert tests.residual_whiteness_p[0] < 1e-6 and not tests.adequate
    leaking = rng.standard_normal((4000, 1)) + 0.2 * np.roll(u, 3, axis=0)  # the residual follows the input 3 samples late
    tests = residual_tests(u, leaking)
    lags = np.arange(-tests.lags, tests.lags + 1)
    assert tests.input_correlation_max[0] > 3 * tests.bound and tests.input_correlation_p[0] < 1e-6
    assert lags[np.argmax(np.abs(tests.cross_correlation[:, 0, 0]))] == 3


def test_nis_band_holds_consistent_innovations():
    """The mean of e'e for unit-variance innovations lies in the 99 % band in about 99 of 100 trials (at most 4 out)."""
    rng = np.random.default_rng(2)
    low, high = nis_band(2000, 3)
    outside = sum(not low <= np.mean(np.sum(rng.standard_normal((2000, 3)) ** 2, axis=1)) <= high for _ in range(100))
    assert outside <= 4


@pytest.mark.parametrize("low_order, adequate_order", [(2, 4)])
def test_residual_tests_flag_too_low_an_order_and_pass_the_true_one(low_order, adequate_order):
    """The calibration system (two pairs) with 10 % output noise, identified by the IEKF."""
    data, _ = calibration.make_record(21, 0.1, duration=30.0)
    verdicts = {}
    for order in (low_order, adequate_order):
        structure = ModalStructure.default(order, 1, 1)
        model = identify_iekf(data, structure, options=IEKFOptions(**calibration.IEKF_SETTINGS)).model
        verdicts[order] = model_residual_tests(model, data)
    assert not verdicts[low_order].adequate
    assert verdicts[adequate_order].adequate


def test_residual_tests_on_the_paper_linear_example():
    """Eq. 15, output 1, 10 % noise, 20 s (Table 4 tuning p = 0.001, 40 passes).

    n = 3 leaves the -15 +/- 10j pair in the residuals and is flagged; n = 4
    (the paper's chosen order: the real pole at -4 is weak in output 1)
    passes, and so does the true model (measured p-values in
    benchmarks/residual_adequacy.py: whiteness 0.40, cross-correlation 1.0).
    """
    data, _ = make_data(0, outputs=(0,), noise_ratio=0.1, duration=20.0)
    options = IEKFOptions(p=1e-3, passes=40, normalize=True)
    verdicts = {}
    for order in (3, 4):
        model = identify_iekf(data, ModalStructure.from_pattern("all-ones", order, 2, 1), options=options).model
        verdicts[order] = model_residual_tests(model, data)
    assert not verdicts[3].adequate
    assert verdicts[4].adequate
    assert model_residual_tests(true_model(1), data).adequate


def _csv(tmp_path, seed=3):
    data, _ = calibration.make_record(seed, 0.1, duration=20.0)
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack([data.t, data.u, data.y]), delimiter=",", header="t,u,y", comments="")
    return path


def _identify(*arguments):
    return run_vehid("identify", *arguments, "--quiet")


def test_identify_json_carries_modes_with_std_and_residual_keys(tmp_path):
    path = _csv(tmp_path)
    archive = tmp_path / "run.h5"
    done = _identify(str(path), "--inputs", "u", "--outputs", "y", "--order", "4", "--normalize", "--p", "0.001",
                     "--passes", "15", "--json", "--out", str(archive))
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert len(summary["modes"]) == 2
    for mode in summary["modes"]:
        assert set(mode) >= {"eigenvalue", "eigenvalue_std", "frequency_hz", "frequency_hz_std", "damping", "damping_std"}
        assert len(mode["eigenvalue_std"]) == 2 and mode["frequency_hz_std"] > 0
    assert len(summary["residual_whiteness_p"]) == 1 and len(summary["input_correlation_max"]) == 1
    assert len(summary["innovation_nis"]) == summary["passes_run"]
    returned = returned_run(archive)  # the residual tests are the returned model's (the filter's, or it refined)
    with open_archive(archive) as handle:
        run = read_iekf_run(handle, "iekf")
        tests = read_value(handle[f"runs/{returned}"], "residual_tests")
    assert run.model.parameter_covariance is not None
    assert np.isfinite(run.history[-1].nis)
    np.testing.assert_allclose(tests.residual_whiteness_p, summary["residual_whiteness_p"])
    figures = archive_figures(read_archive(archive))
    assert {"innovation_consistency_iekf", f"residual_tests_identification_{returned}"} <= set(figures)
    # two modes: one marker line plus an ellipse and its mirror image per pair
    assert len(figures["eigenvalues"].axes[0].get_lines()) >= 1 + 2 * 2
    text = _identify(str(path), "--inputs", "u", "--outputs", "y", "--order", "4", "--normalize", "--p", "0.001",
                     "--passes", "5")
    assert text.returncode == 0, text.stderr
    assert "\u00b1" in text.stdout and "whiteness p" in text.stdout


def test_an_archive_without_the_nis_column_still_reads_and_resumes(tmp_path):
    """Runs archived before the history recorded the NIS keep their columns when resumed."""
    path = _csv(tmp_path, seed=5)
    archive = tmp_path / "run.h5"
    assert _identify(str(path), "--inputs", "u", "--outputs", "y", "--order", "4", "--passes", "2", "--out",
                     str(archive)).returncode == 0
    with update_archive(archive) as handle:  # as an older workbench wrote it
        del handle["runs/iekf/history/nis"]
    with open_archive(archive) as handle:
        previous = read_iekf_run(handle, "iekf")
    assert np.isnan(previous.history[-1].nis)
    with update_archive(archive) as handle:
        append_iekf_pass(handle, "iekf", previous.history[-1].__class__(**{**previous.history[-1].__dict__, "index": 3}),
                         previous)
    with open_archive(archive) as handle:
        assert "nis" not in handle["runs/iekf/history"] and read_iekf_run(handle, "iekf").passes_run == 3


def test_an_exact_fit_is_not_called_coloured():
    """Noise-free data and the true model leave rounding (1e-16): the tests must not reject it."""
    data, _ = calibration.make_record(2, 0.0, duration=20.0)
    tests = model_residual_tests(calibration.true_model(), data)
    assert tests.exact[0] and tests.adequate
    with pytest.raises(InputError, match="constant"):  # without the outputs' scale, as any residual
        residual_tests(data.u, data.y - calibration.true_model().simulate_outputs(data.u, data.dt))


@pytest.mark.parametrize("excitation_seed, noise_seed", [(0, 13), (1, 12)])
def test_residual_tests_on_the_noisy_handling_study(excitation_seed, noise_seed):
    """The handling study in its linear regime with sensor noise: n = 2 is flagged on both records, n = 8 passes.

    Records of 10 s at a tenth of the steer amplitude with the noise of
    ``handling_study.SENSOR_NOISE``; the IEKF at the invariant settings (50
    passes), refined by output error from its model, tested on both records
    (``benchmarks/residual_adequacy.py``). Independent truth: the vehicle's
    linearisation has two lightly damped modes (yaw-sideslip and roll) and
    the tyres' relaxation lags between steer and forces, which two states
    cannot hold, so an n = 2 model leaves input-driven response in its
    residuals.

    Measured over excitation seeds 0 and 1 by noise seeds 11-15 (ten
    pairs): n = 2 fails the input cross-correlation test on both records in
    all ten (lateral acceleration p below 1e-25). n = 8 passes every test on
    the identification record in all ten (smallest whiteness p 0.059,
    smallest input-correlation p 0.093) and on the validation record in nine
    (at 0/15 its residuals there are coloured: the record it was not fitted
    to). n = 6 is in between: the IEKF diverged in two pairs, and of the
    other eight the yaw rate's residual is coloured in three (p 6e-5 to
    2e-4) where n = 8's is white. Both cases here are pairs where n = 6 fails, so the test
    does not rest on a favourable seed; it asserts for n = 8 the verdict that
    held in all ten pairs (the identification record).
    """
    records = with_sensor_noise(make_records(HandlingConfig(duration=10.0, amplitude_scale=0.1, seed=excitation_seed)),
                                noise_seed)
    data = records["identification"]
    for order in (2, 8):
        start = identify_iekf(data, ModalStructure.default(order, data.n_u, data.n_y),
                              options=IEKFOptions.invariant(passes=50)).model
        model = identify_with(data, method="output-error", order=order, start=start.with_parameter_covariance(None)).model
        for name, record in records.items():
            tests = model_residual_tests(model, record)
            if order == 2:
                assert not tests.adequate and not tests.independent.all(), (name, tests.input_correlation_p)
            elif name == "identification":
                assert tests.adequate, (tests.residual_whiteness_p, tests.input_correlation_p)
