"""Every identified model meets one protocol (identification.protocol).

Independent truth: modes from the closed forms f = |lambda| / 2 pi and
zeta = -Re(lambda) / |lambda| on eigenvalues written down by hand; the
discrete equivalent of a continuous model (exact for inputs linear between
samples) simulating the same samples; scipy's frequency responses.
"""

import functools
import importlib.util
import json

import numpy as np
import pytest
from scipy.io import loadmat
from scipy.signal import dfreqresp, freqresp

from vehid.identification import (ArxModel, DiscreteModel, IdentifiedModel, IOData, ModalModel, ModalStructure, Mode,
                                  SplineModalModel, estimate_arx, estimate_subspace, identify_with)
from vehid.identification.errors import InputError
from vehid.identification.pencil import PencilModel
from vehid.identification.statespace import continuous_to_discrete

DT = 0.01
# rounding of an exact discretisation carried over 400 samples of an O(1) response
ALGEBRA = 1e-9


def _continuous() -> ModalModel:
    """Pairs -1.5 +/- 6j and -4 +/- 20j, a real pole at -3: every mode written down by hand."""
    structure = ModalStructure.default(5, 1, 2)
    theta = np.random.default_rng(0).uniform(-2.0, 2.0, structure.n_parameters)  # B, C and D entries
    theta[:5] = [-1.5, 6.0, -4.0, 20.0, -3.0]
    return ModalModel.from_parameters(structure, theta)


def _record(n: int = 400) -> IOData:
    t = np.arange(n) * DT
    u = np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sign(np.sin(2 * np.pi * 0.4 * t))
    return IOData(t=t, u=u[:, None], y=np.zeros((n, 2)))


def _discrete(model: ModalModel) -> DiscreteModel:
    return DiscreteModel(*continuous_to_discrete(model.A, model.B, model.C, model.D, DT, hold="foh"), DT)


@functools.cache
def _every_model() -> dict[str, object]:
    continuous = _continuous()
    record = _record()
    driven = record.replace(y=continuous.simulate_outputs(record.u, DT))
    single = driven.select_outputs(["y1"])
    Ad, Bd, Cd, Dd = continuous_to_discrete(continuous.A, continuous.B, continuous.C, continuous.D, DT)
    return {
        "modal": continuous,
        "spline-modal": SplineModalModel.from_linear(continuous, 5, np.ones(1), np.ones(2), DT),
        "discrete": _discrete(continuous),
        "arx": estimate_arx(single, na=2, nb=2).model,
        "pencil": PencilModel.from_state_space(Ad, Bd, Cd, Dd, dt=DT),
        "subspace": estimate_subspace(driven, order=5),
        "comparator-arx": identify_with(single, method="arx", order=2).model,
        "comparator-n4sid": identify_with(driven, method="n4sid", order=5, bootstrap=0).model,
    }


MODEL_KINDS = ("modal", "spline-modal", "discrete", "arx", "pencil", "subspace", "comparator-arx", "comparator-n4sid")


@pytest.mark.parametrize("name", MODEL_KINDS)
def test_every_model_meets_the_protocol(name, tmp_path):
    model = _every_model()[name]
    assert isinstance(model, IdentifiedModel)
    A, B, C, D, dt = model.to_statespace()
    assert A.shape[0] == A.shape[1] == B.shape[0] == C.shape[1] and D.shape == (C.shape[0], B.shape[1])
    assert dt is None or dt == pytest.approx(DT)
    record = _record()
    simulated = model.simulate(record)
    assert isinstance(simulated, IOData) and simulated.y.shape == (record.n_samples, C.shape[0])
    np.testing.assert_array_equal(simulated.u, record.u)
    np.testing.assert_array_equal(simulated.y, model.simulate_outputs(record.u, record.dt))
    modes = model.modes()
    assert modes and all(isinstance(mode, Mode) for mode in modes)
    assert model.frequency_response([0.5, 2.0, 7.0]).shape == (3, C.shape[0], B.shape[1])
    assert len(model.eigenvalues()) == A.shape[0]
    assert model.to_casadi().n_in() >= 1
    assert loadmat(model.save_mat(tmp_path / "model.mat"))["A"].shape == A.shape
    assert isinstance(json.loads(model.save_json(tmp_path / "model.json").read_text()), dict)
    if importlib.util.find_spec("control") is None:
        with pytest.raises(ImportError, match="python-control"):
            model.to_control()
    else:
        assert model.to_control().nstates == A.shape[0]


def test_modes_follow_the_closed_form_in_hertz():
    written = [complex(-1.5, 6.0), complex(-4.0, 20.0), complex(-3.0, 0.0)]
    for model in (_continuous(), _discrete(_continuous())):
        modes = model.modes()
        assert [mode.eigenvalue for mode in modes] == pytest.approx(written, abs=1e-9)
        for mode, value in zip(modes, written):
            assert mode.frequency_hz == pytest.approx(abs(value) / (2 * np.pi), rel=1e-12)
            assert mode.damping == pytest.approx(-value.real / abs(value), rel=1e-12)
    assert Mode.of(complex(2.0, 0.0)).damping == -1.0  # an unstable real pole
    assert Mode.of(complex(-1.0, -3.0)) == Mode.of(complex(-1.0, 3.0))  # a pair is one mode


def test_a_discrete_model_simulates_its_continuous_equivalent():
    """The first-order-hold equivalent is exact for inputs linear between samples: the same samples to rounding."""
    continuous = _continuous()
    record = _record()
    np.testing.assert_allclose(_discrete(continuous).simulate(record).y, continuous.simulate(record).y,
                               rtol=0, atol=ALGEBRA)


def test_frequency_responses_match_scipy():
    continuous = _continuous()
    f_hz = np.array([0.1, 1.0, 3.2, 10.0])
    response = continuous.frequency_response(f_hz)
    for output in range(2):
        _, expected = freqresp((continuous.A, continuous.B, continuous.C[[output]], continuous.D[[output]]),
                               w=2 * np.pi * f_hz)
        np.testing.assert_allclose(response[:, output, 0], expected, rtol=1e-12)
    discrete = _discrete(continuous)
    _, expected = dfreqresp((discrete.A, discrete.B, discrete.C[[0]], discrete.D[[0]], DT), w=2 * np.pi * f_hz * DT)
    # scipy goes through transfer-function polynomials, which lose ~1e-10 relative here
    np.testing.assert_allclose(discrete.frequency_response(f_hz)[:, 0, 0], expected, rtol=1e-8)


def test_discrete_forms_without_a_sample_interval_say_so():
    with pytest.raises(InputError, match="no sample interval"):
        ArxModel(np.array([1.0, -0.5]).reshape(2, 1, 1), np.ones((2, 1, 1))).modes()
