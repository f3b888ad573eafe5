"""The rinse loop shared by the IEKFs, driven by scripted hooks whose every pass is known in advance."""

import numpy as np
import pytest

from vehid.identification import DivergenceError, IOData
from vehid.identification.filtering.iekf_pass import pack_covariance
from vehid.identification.filtering.rinse import Assessment, RinseHooks, rinse

DT = 0.01


def _hooks(passes, *, label="pass"):
    """One true state, one parameter; pass k sets theta to ``passes[k][0]`` and P to ``passes[k][1]``,
    innovations ``passes[k][2]`` (10 samples). The result is (stop reason, number of passes, theta)."""
    record = IOData(t=np.arange(10) * DT, u=np.zeros((10, 1)), y=np.zeros((10, 1)))
    ran = []

    def run_record(state, k):
        theta, P, innovations = passes[len(ran)]
        ran.append(k)
        return np.concatenate([[0.0, theta], pack_covariance(P)]), innovations

    return RinseHooks(
        (record,), run_record, lambda: np.eye(1),
        lambda theta, P: Assessment(theta.copy(), np.array([float(theta[0])]), np.array([float(theta[0])]), theta, P),
        lambda previous, current: abs(current.parameters[0] - previous.parameters[0]) < 1e-3,
        lambda reason, history, theta, P: (reason, len(history), float(theta[0])), 1, label=label,
    )


def test_stops_on_the_hooks_rule_and_records_each_pass():
    P = np.diag([0.0, 2.0])
    steps = [(1.0, P, np.full((10, 1), 2.0)), (1.5, P, np.ones((10, 1))), (1.5, P, np.ones((10, 1))), (9.0, P, None)]
    seen = []
    reason, passes, theta = rinse(_hooks(steps), np.array([0.0]), P, passes=10, min_passes=2,
                                  on_pass=lambda record, _: seen.append(record))
    assert (reason, passes, theta) == ("converged", 3, 1.5)  # pass 3 repeats pass 2: settled, pass 4 never runs
    assert [record.index for record in seen] == [1, 2, 3]
    # NIS with R = 1: the mean squared innovation; trace and smallest eigenvalue of P = diag(0, 2)
    assert [record.nis for record in seen] == [4.0, 1.0, 1.0]
    assert seen[0].trace_p == 2.0 and seen[0].min_eig_p == 0.0


def test_non_finite_values_name_the_pass_and_the_time_and_keep_the_last_good_pass():
    P = np.diag([0.0, 1.0])
    bad = np.zeros((10, 1))
    bad[3:] = np.nan
    with pytest.raises(DivergenceError, match=r"nonlinear pass 2: the filter produced non-finite values "
                                              r"from t = 0\.030 s \(try a lower p\)") as raised:
        rinse(_hooks([(1.0, P, np.zeros((10, 1))), (2.0, P, bad)], label="nonlinear pass"), np.array([0.0]), P,
              passes=5, min_passes=2)
    assert raised.value.last_good == ("diverged at pass 2", 1, 1.0)


def test_a_covariance_that_lost_positive_definiteness_stops_unless_the_form_may_lose_it():
    indefinite = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues -1 and 3
    steps = [(1.0, indefinite, np.zeros((10, 1)))]
    with pytest.raises(DivergenceError, match="pass 1: the covariance P lost positive definiteness") as raised:
        rinse(_hooks(steps), np.array([0.0]), np.eye(2), passes=1, min_passes=1)
    assert raised.value.last_good is None  # no pass finished
    assert rinse(_hooks(steps), np.array([0.0]), np.eye(2), passes=1, min_passes=1, check_covariance=False)[:2] == \
        ("passes", 1)
