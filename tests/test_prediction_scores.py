"""The k-step-ahead score of an unstable model is a property of the model and the record, not of their units.

An open-loop unstable model's simulation grows without bound, so it is scored by predicting a few
samples ahead of a steady-state Kalman filter. The filter's process noise is set from the state
variance the record's input drives; set from a unit-variance input instead, it depended on the units
the input is given in (the same ball-and-beam model scored 89.2 % with its published input and 66.3 %
with the input in units 1000 times smaller).
"""

from __future__ import annotations

import numpy as np
import pytest

from vehid.identification import IOData
from vehid.identification.assessment.validation import UNSTABLE_HORIZON, predict, score
from vehid.identification.models.discrete import ContinuousModel

DT = 0.1


def _unstable_case():
    # a real pole at +0.4 rad/s (a ball leaving a tilted beam) beside a damped pair at 2 rad/s
    A = np.array([[0.4, 0.0, 0.0], [0.0, -0.3, 2.0], [0.0, -2.0, -0.3]])
    B = np.array([[0.5], [1.0], [0.2]])
    C = np.array([[1.0, 0.3, 0.0]])
    D = np.array([[0.0]])
    model = ContinuousModel(A, B, C, D)
    rng = np.random.default_rng(3)
    u = 0.01 * rng.standard_normal((400, 1))  # an input of small RMS in its own units
    # the record: the model's own short-horizon behaviour plus measurement noise (a growing simulation would
    # leave every floating-point range; the predictor only needs a record it can follow)
    truth = predict(model, IOData(t=np.arange(400) * DT, u=u, y=np.zeros((400, 1))), initial_state="zero",
                    horizon=None)
    y = np.clip(truth, -1e6, 1e6) + 0.05 * np.std(np.clip(truth, -1e6, 1e6)) * rng.standard_normal(truth.shape)
    return model, IOData(t=np.arange(400) * DT, u=u, y=y)


@pytest.mark.parametrize("input_factor, output_factor", [(1e-3, 1.0), (1e3, 1.0), (1.0, 1e-3), (1e2, 1e4)])
def test_k_step_predictions_follow_the_units_and_the_score_does_not_move(input_factor, output_factor):
    model, data = _unstable_case()
    assert not model.is_stable()
    # the same system with its input in units input_factor times larger and its output output_factor times
    rescaled_model = ContinuousModel(model.A, model.B / input_factor, model.C * output_factor,
                                     model.D * output_factor / input_factor)
    rescaled = IOData(t=data.t, u=data.u * input_factor, y=data.y * output_factor)
    original = predict(model, data, horizon=UNSTABLE_HORIZON)
    moved = predict(rescaled_model, rescaled, horizon=UNSTABLE_HORIZON)
    # a change of units is exact arithmetic up to rounding: 1e-7 relative leaves room for the Riccati solver's
    # iterations on rescaled matrices and nothing for a predictor that weighs the record differently
    np.testing.assert_allclose(moved, original * output_factor, rtol=1e-7, atol=1e-9 * np.abs(original).max() * output_factor)
    assert score(rescaled_model, rescaled, horizon=UNSTABLE_HORIZON).fit == pytest.approx(
        score(model, data, horizon=UNSTABLE_HORIZON).fit, abs=1e-6)
