"""IEKF results: divergence keeps the last good pass, results round-trip through archives."""

import dataclasses

import numpy as np
import pytest

from vehid.identification import DivergenceError, IEKFOptions, ModalStructure, identify_iekf
from vehid.identification.dataio.archive import open_archive, read_archive, write_archive, write_run
from vehid.identification.dataio.iekf_archive import read_iekf_run, write_iekf_run
from vehid.identification.models.spline_modal import SplineModalModel
from vehid.scenarios.linear_example import make_data, true_model


@pytest.fixture(scope="module")
def two_passes():
    data, _ = make_data(6, outputs=(0,), duration=20.0)
    structure = ModalStructure.from_pattern("all-ones", 5, 2, 1)
    return data, structure, identify_iekf(data, structure, options=IEKFOptions(passes=2, min_passes=5))


def test_divergence_names_the_pass_and_keeps_the_last_good_one(two_passes):
    """Continue a healthy run from a state whose first mode grows at +200 1/s, with almost no freedom left
    (p = 1e-12): the states overflow in pass 3. Passes 1-2 must survive on the error."""
    data, structure, good = two_passes
    theta = good.state.theta.copy()
    theta[0] = 200.0  # sigma of the first pair: e^{200 x 20 s} overflows
    P = np.full_like(good.state.P, 0.0)
    broken = dataclasses.replace(good, state=dataclasses.replace(good.state, theta=theta, P=P))
    options = dataclasses.replace(good.options, p=1e-12, passes=3)
    with pytest.raises(DivergenceError, match="pass 3") as raised:
        identify_iekf(data, structure, options=options, resume=broken)
    assert "non-finite" in str(raised.value) or "unstable" in str(raised.value)
    last_good = raised.value.last_good
    assert last_good is not None and last_good.passes_run == 2
    assert np.array_equal(last_good.model.parameters, good.model.parameters)


def test_iekf_result_round_trips_through_an_archive(two_passes, tmp_path):
    _, _, result = two_passes
    path = tmp_path / "run.h5"
    with write_archive(path, kind="identification", config=result.options) as archive:
        write_iekf_run(archive, "iekf", result)
    with open_archive(path) as archive:
        again = read_iekf_run(archive, "iekf")
    assert again.options == result.options and again.structure == result.structure
    assert np.array_equal(again.model.parameters, result.model.parameters)
    assert np.array_equal(again.state.P, result.state.P) and again.dt == result.dt
    for a, b in zip(again.history, result.history):
        assert a.index == b.index and np.array_equal(a.fit_filter, b.fit_filter) and a.trace_p == b.trace_p
    assert read_archive(path).runs["iekf"].n_pass == 2


def test_spline_model_round_trips_through_an_archive(tmp_path):
    model = SplineModalModel.from_linear(true_model(), 5, np.array([1.0, 2.0]), np.array([3.0, 4.0, 5.0]), 0.002)
    gammas = model.structure.gammas(model.theta).copy()
    gammas[0] *= np.linspace(1.0, 0.7, 5)
    model = model.with_parameters(gammas.ravel())
    path = tmp_path / "spline.h5"
    with write_archive(path, kind="identification") as archive:
        write_run(archive, "nonlinear", model=model)
    again = read_archive(path).runs["nonlinear"].model
    assert isinstance(again, SplineModalModel) and again.structure == model.structure
    assert np.array_equal(again.theta, model.theta) and np.array_equal(again.ranges, model.ranges)
    u = np.sin(np.linspace(0, 30, 600))[:, None] * np.array([1.0, -0.5])
    assert np.array_equal(again.simulate_outputs(u), model.simulate_outputs(u))
