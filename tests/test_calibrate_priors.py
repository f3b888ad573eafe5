"""Priors and honest uncertainty of the grey-box calibration, on models small enough to check by hand.

Truth here is closed form: a parameter the output does not depend on keeps exactly its prior
uncertainty; an AR(1) series with coefficient a has the integrated autocorrelation time (1 + a) / (1 - a).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from vehid.identification.data import IOData
from vehid.identification.errors import InputError
from vehid.identification.assessment.segments import integrated_correlation_time
from vehid.identification.filtering.greybox import GreyBoxOptions, identify_greybox
from vehid.identification.filtering.greybox_structure import GreyBoxModel
from vehid.vehicle.calibration import _undetermined


def _lag_with_idle_parameter() -> GreyBoxModel:
    """dx/dt = (u - x) / tau, y = x, and a parameter ``idle`` that enters nothing the output sees."""
    x, u, theta, s = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("theta", 2), ca.SX.sym("s", 0)
    names = ["x", "u", "theta", "s"]
    # 0 * idle keeps the symbol in the expression graph without any influence
    rate = (u - x) / theta[0] + 0 * theta[1]
    return GreyBoxModel(
        dynamics=ca.Function("idle_lag_dynamics", [x, u, theta, s], [rate], names, ["xdot"]),
        output=ca.Function("idle_lag_output", [x, u, theta, s], [x], names, ["y"]),
        parameter_names=("time_constant", "idle"), parameter_units=("s", "-"), positive=(True, True),
        state_names=("x",), input_names=("u",),
    )


@pytest.fixture(scope="module")
def lag_record() -> IOData:
    dt, tau = 0.01, 0.3
    rng = np.random.default_rng(0)
    u = np.repeat(rng.standard_normal(100), 10)  # 0.1 s steps: well inside the lag's band
    x = np.zeros(u.size)
    for k in range(1, u.size):  # exact for an input held over each sample (the filter need not match it here)
        x[k] = x[k - 1] + (u[k - 1] - x[k - 1]) * (1 - np.exp(-dt / tau))
    y = x + 0.02 * rng.standard_normal(u.size)
    return IOData(t=dt * np.arange(u.size), u=u[:, None], y=y[:, None], input_names=("u",), output_names=("y",))


def test_per_parameter_prior_is_kept_where_the_data_say_nothing(lag_record):
    options = GreyBoxOptions(parameter_prior_std=(1.0, 0.3), passes=6)
    result = identify_greybox(lag_record, _lag_with_idle_parameter(), [0.25, 2.0], options=options)
    # nothing informs the idle parameter: it stays at its start and its std is its prior's, 30 % of
    # its value (the log-scaled prior 0.3 maps to 0.3 * value at the estimate); the NIS inflation
    # of the std is at most a few per cent with white noise and the right model
    assert result.parameters[1] == pytest.approx(2.0, rel=1e-9)
    assert result.std[1] / (0.3 * 2.0) == pytest.approx(np.sqrt(result.meta["covariance_inflation"]), rel=1e-6)
    # while the time constant is determined far below its own prior (relative std << 1)
    assert result.std[0] < 0.05 * result.parameters[0]


def test_per_parameter_prior_needs_one_value_per_parameter(lag_record):
    with pytest.raises(InputError, match="one per parameter"):
        identify_greybox(lag_record, _lag_with_idle_parameter(), [0.25, 2.0],
                         options=GreyBoxOptions(parameter_prior_std=(1.0,)))
    with pytest.raises(InputError, match="positive"):
        GreyBoxOptions(parameter_prior_std=(1.0, -0.1))


@pytest.mark.parametrize("a", [0.0, 0.5, 0.8])
def test_correlation_time_of_an_ar1_series(a):
    rng = np.random.default_rng(7)
    n = 40_000
    e = rng.standard_normal(n)
    series = np.empty(n)
    series[0] = e[0]
    for k in range(1, n):
        series[k] = a * series[k - 1] + e[k]
    expected = (1 + a) / (1 - a)
    found = integrated_correlation_time(series[:, None])[0]
    # the sum stops at the first non-positive lag, so it misses the tail a^k beyond (at most a few % for
    # these a with 40,000 samples, whose lag estimates scatter by 1/sqrt(n) = 0.005); 15 % covers both
    assert found == pytest.approx(expected, rel=0.15)
    assert found >= 1.0


def test_undetermined_uses_each_parameter_prior():
    names = ("a", "b")
    values = np.array([1.0, 10.0])
    correlation = np.eye(2)
    # b's std is 40 % of its value: determined under a prior of 1 (limit 50 %), not under 0.5 (limit 25 %)
    std = np.array([0.01, 4.0])
    assert _undetermined(names, values, std, correlation, 0.95, np.array([1.0, 1.0])) is None
    name, why = _undetermined(names, values, std, correlation, 0.95, np.array([1.0, 0.5]))
    assert name == "b" and "hardly narrowed" in why
    # a correlated pair: the one less certain relative to its size is held
    correlation = np.array([[1.0, 0.99], [0.99, 1.0]])
    std = np.array([0.01, 0.2])
    assert _undetermined(names, values, std, correlation, 0.95, np.array([1.0, 1.0]))[0] == "b"


def test_prior_option_takes_a_value_and_an_optional_std():
    from vehid.scenarios.commands.calibrate import _priors

    assert _priors(["tyre.PKY1=-15", "chassis.yaw_inertia=2500:250"]) == {"tyre.PKY1": -15.0,
                                                                          "chassis.yaw_inertia": (2500.0, 250.0)}
    with pytest.raises(InputError, match="NAME=VALUE"):
        _priors(["tyre.PKY1=-15:x"])
