"""Every comparator identifies the paper's linear example (Best & Bogdanski 2017, eq. 15-16, output 1).

Noise-free data: 5,000 N(0, 1) points per input at 50 Hz, interpolated to 500 Hz, offsets +0.1/-0.1,
outputs by exact simulation of the pairs-first modal form (ModalModel.simulate, method="foh").
"""

import numpy as np
import pytest

from vehid.identification import ExcitationError, InputError, IOData, fit_metrics
from vehid.identification.comparators import COMPARATORS, _continuous_start, identify_with, register_comparator
from vehid.identification.models.modal import ModalModel
from vehid.identification.models.modal_structure import ModalStructure
from vehid.scenarios.linear_example import make_data, true_model

REQUIRED_FIT = 99.9  # percent, R of eq. 17


@pytest.fixture(scope="module")
def data():
    return make_data(0, outputs=(0,))[0]


@pytest.mark.parametrize("method", ["iekf", "arx", "rls", "n4sid", "output-error"])
def test_comparator_identifies_the_linear_example(data, method):
    result = identify_with(data, method=method, order=5)
    assert result.metrics.percentage_explanation[0] > REQUIRED_FIT
    assert result.model.structure == ModalStructure.default(5, 2, 1)
    assert result.seconds > 0
    # Noise-free data of the model class: the eigenvalues come out to ~1e-6; 1e-3 relative is a
    # loose bound that still fails a wrong pole (the nearest distinct one is 40 % away).
    found = np.sort_complex(result.model.eigenvalues())
    truth = np.sort_complex(true_model(1).eigenvalues())
    np.testing.assert_allclose(found, truth, rtol=1e-3)


def test_output_error_improves_a_poor_start(data):
    """From the true parameters perturbed by 10 % (fit ~96 %), on the first 20 s of the record."""
    short = data[:10000]
    truth = true_model(1)
    rng = np.random.default_rng(0)
    theta = truth.parameters * (1.0 + 0.1 * rng.standard_normal(truth.parameters.size))
    start = ModalModel.from_parameters(truth.structure, theta)
    start_fit = fit_metrics(short.y, start.simulate_outputs(short.u, short.dt)).percentage_explanation[0]
    result = identify_with(short, method="output-error", order=5, start=start)
    assert start_fit < 99.0
    assert result.metrics.percentage_explanation[0] > REQUIRED_FIT
    # noise-free data of the model class: the optimum is the truth, reached to ~1e-10
    np.testing.assert_allclose(result.model.parameters, truth.parameters, rtol=1e-6, atol=1e-8)


def test_registry_dispatches_and_rejects(data, monkeypatch):
    with pytest.raises(InputError, match="unknown method 'kalman'; use one of arx, iekf, n4sid, output-error, rls"):
        identify_with(data, method="kalman", order=5)
    with pytest.raises(InputError, match="unknown option"):
        identify_with(data, method="arx", order=5, lambda_=0.9)
    with pytest.raises(InputError, match="exists"):
        register_comparator("arx", COMPARATORS["arx"])
    monkeypatch.setitem(COMPARATORS, "truth", lambda d, *, order: true_model(1))
    result = identify_with(data[:2000], method="truth", order=5)
    assert result.metrics.percentage_explanation[0] == pytest.approx(100.0, abs=1e-9)


def test_comparators_name_bad_requests(data):
    with pytest.raises(InputError, match="order must be an integer >= 1"):
        identify_with(data, method="arx", order=0)
    still = data.replace(u=np.zeros_like(data.u))  # no excitation at all
    with pytest.raises(ExcitationError, match="identically zero"):
        identify_with(still[:3000], method="arx", order=5)
    with pytest.raises(InputError, match="start must be"):
        identify_with(data[:3000], method="output-error", order=5, start="iekf")


def test_output_error_starts_where_arx_and_n4sid_have_a_negative_real_pole():
    """y(k) = -0.5 y(k-1) + u(k-1): both linear starts are discrete-time; output-error used to exit with no model.

    Its start is then the ARX model with the pole moved to +0.5; the trust-region fit accepts only steps that
    lower the cost, so its simulation error cannot exceed the start's.
    """
    rng = np.random.default_rng(0)
    u = rng.normal(size=(2000, 1))
    y = np.zeros((2000, 1))
    for k in range(1, 2000):
        y[k] = -0.5 * y[k - 1] + u[k - 1]
    record = IOData(t=np.arange(2000) * 0.01, u=u, y=y)
    discrete = identify_with(record, method="arx", order=1).model
    assert discrete.eigenvalues()[0].real == pytest.approx(-0.5, abs=1e-9)  # noise-free: the true pole
    result = identify_with(record, method="output-error", order=1)
    assert isinstance(result.model, ModalModel)
    assert result.model.meta["start"] == "arx, negative real poles moved to the positive axis"
    start = _continuous_start(discrete, "arx", [record], 1)
    assert start.eigenvalues()[0].real == pytest.approx(np.log(0.5) / 0.01, rel=1e-9)  # |z| = 0.5 per sample

    def squared_error(model):
        return np.sum((model.simulate_outputs(u, 0.01) - y) ** 2)

    assert squared_error(result.model) <= squared_error(start)
