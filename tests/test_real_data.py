"""Identification on public measured records (tests/data), scored on held-out data.

The records, split and score are those of ``benchmarks/real_data.py`` (its
module ``benchmarks/_real_records.py`` is loaded here): the first 70 % of a
record estimates, the last 30 % validates, and the score is MATLAB
``compare``'s NRMSE fit of the model simulated on the validation input from
its least-squares initial state. Floors are measured hold-out fits minus a
margin stated with each case.
"""

from __future__ import annotations

import hashlib
import importlib.util
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from identification import IEKFOptions, IOData, ModalStructure, identify_iekf
from identification.comparators import identify_with
from identification.metrics import nrmse_fit

ROOT = Path(__file__).resolve().parent.parent


def _load_records_module():
    spec = importlib.util.spec_from_file_location("_real_records", ROOT / "benchmarks" / "_real_records.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up by name
    spec.loader.exec_module(module)
    return module


records = _load_records_module()

# Sizes stated by the publishers (DaISy descriptions; the cascaded tanks' 2 x 1024 samples).
PUBLISHED_SHAPES = {"ballbeam": (1000, 1, 1), "dryer": (1000, 1, 1), "robot_arm": (1024, 1, 1),
                    "exchanger": (4000, 1, 1), "cd_player_arm": (2048, 2, 2), "cascaded_tanks": (2048, 1, 1)}


@pytest.mark.parametrize("entry", records.RECORD_SETS, ids=lambda e: e.name)
def test_committed_record_is_the_published_file(entry):
    """Each raw file is byte for byte the one its SOURCE.md names (SHA-256), with the published size."""
    folder = entry.file.parent
    source = (folder / "SOURCE.md").read_text()
    for data_file in sorted(p for p in folder.iterdir() if p.name != "SOURCE.md"):
        digest = hashlib.sha256(data_file.read_bytes()).hexdigest()
        assert re.search(rf"`{re.escape(data_file.name)}`[^\n]*\n?[^\n]*{digest}", source), data_file.name
    (u_est, y_est), (u_val, y_val) = records.load(entry)
    samples, n_u, n_y = PUBLISHED_SHAPES[entry.name]
    assert len(u_est) + len(u_val) == samples and u_est.shape[1] == n_u and y_est.shape[1] == n_y
    assert np.all(np.isfinite(u_est)) and np.all(np.isfinite(y_val))


def test_score_is_matlab_fit_and_recovers_the_initial_state():
    """The benchmark's fit equals the workbench's NRMSE fit, and the least-squares x0 of a known system is exact."""
    rng = np.random.default_rng(0)
    A = np.array([[0.9, 0.2], [-0.2, 0.9]])
    B, C, D = np.array([[1.0], [0.5]]), np.array([[1.0, -1.0]]), np.array([[0.1]])
    u = rng.standard_normal((200, 1))
    x0 = np.array([3.0, -2.0])
    forced, free = records.discrete_responses(A, B, C, D, u)
    y = forced + free @ x0
    fits, x0_hat = records.fit_from_estimated_state(forced, free, y)
    np.testing.assert_allclose(x0_hat, x0, rtol=1e-10)  # noise-free: exact up to rounding
    assert fits == pytest.approx([100.0], abs=1e-9)
    y_noisy = y + 0.3 * rng.standard_normal(y.shape)
    assert records.nrmse_fit(y_noisy, y) == pytest.approx(list(nrmse_fit(y_noisy, y)), rel=1e-12)


def _holdout_fit(model, entry, centred: bool, time_factor: float = 1.0) -> list[float]:
    (u_est, y_est), (u_val, y_val) = records.load(entry)
    if centred:
        u_val, y_val = u_val - u_est.mean(axis=0), y_val - y_est.mean(axis=0)
    dt = entry.dt * time_factor
    return records.fit_of_linear_simulator(lambda u, x0: model.simulate(u, dt, x0=x0), model.structure.n, u_val, y_val)


def _estimation(entry, centred: bool, time_factor: float = 1.0) -> IOData:
    (u_est, y_est), _ = records.load(entry)
    if centred:
        u_est, y_est = u_est - u_est.mean(axis=0), y_est - y_est.mean(axis=0)
    return IOData(t=np.arange(len(u_est)) * entry.dt * time_factor, u=u_est, y=y_est)


# Hold-out floors. Measured on the workbench as it stands, with the benchmark's split
# and score (benchmarks/real_data.py reports the same figures through the command line);
# each floor is the measured fit less MARGIN. The cases are ones whose result does not
# move when the data are perturbed by 1e-7 relative (checked when the floors were set;
# the heat exchanger at the default time base is not such a case: its IEKF run flips
# between converging and diverging). "centred": the estimation means are removed from
# both parts first, as the benchmark does for the peers, because the workbench does not
# remove offsets itself yet. A time factor of 0.01 counts time in hundredths of the
# published unit: the IEKF's default start values are absolute (rad/s), and on these
# records they only fit the faster time base.
IEKF_CASES = [
    # set, centred, time factor, options, measured hold-out fit per output
    ("dryer", True, 1.0, {}, [82.45]),
    ("cd_player_arm", True, 1.0, {}, [29.62, 76.47]),  # output 1 moves by 0.4 under perturbation
    ("exchanger", True, 0.01, {"normalize": True}, [62.15]),
    ("cascaded_tanks", True, 0.01, {}, [71.11]),
]
COMPARATOR_CASES = [
    ("robot_arm", False, "n4sid", [96.80]),
    ("robot_arm", False, "output-error", [94.42]),
    ("exchanger", True, "n4sid", [58.30]),
    ("cascaded_tanks", True, "n4sid", [69.74]),
]
# 3 points: the runs use no random numbers, so a re-run reproduces the figure to rounding
# (0.4 point at most under perturbation, above); a loss of 3 points on held-out data is
# one a user would notice.
MARGIN = 3.0


@pytest.mark.parametrize("name, centred, time_factor, options, measured", IEKF_CASES, ids=[c[0] for c in IEKF_CASES])
def test_iekf_holdout_fit_on_measured_record(name, centred, time_factor, options, measured):
    entry = records.record_set(name)
    data = _estimation(entry, centred, time_factor)
    result = identify_iekf(data, ModalStructure.default(4, data.n_u, data.n_y), options=IEKFOptions(**options))
    fits = _holdout_fit(result.model, entry, centred, time_factor)
    assert np.all(np.array(fits) >= np.array(measured) - MARGIN), (fits, measured)


@pytest.mark.parametrize("name, centred, method, measured", COMPARATOR_CASES,
                         ids=[f"{c[0]}-{c[2]}" for c in COMPARATOR_CASES])
def test_comparator_holdout_fit_on_measured_record(name, centred, method, measured):
    entry = records.record_set(name)
    outcome = identify_with(_estimation(entry, centred), method=method, order=4)
    fits = _holdout_fit(outcome.model, entry, centred)
    assert np.all(np.array(fits) >= np.array(measured) - MARGIN), (fits, measured)
