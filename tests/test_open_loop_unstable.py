"""Default `vehid identify` on an open-loop unstable plant: the growing mode is found, kept and said.

The truth is a simulated fourth-order plant with known poles (+0.3 and -0.5 rad/s, -1 +/- 3j), run in
closed loop under proportional output feedback (an open-loop unstable plant yields a record only so:
its open-loop response grows e-fold every 3.3 s), with white measurement noise. Its mirror image (the
real pole at -0.3 instead) is the stable control: there nothing may be assumed.
"""

import json

import numpy as np
import pytest
import scipy.linalg
from conftest import run_vehid

DT = 0.1  # s
POLES = np.array([0.3, -0.5, -1 + 3j, -1 - 3j])  # rad/s; the first is the one whose sign the control flips
GAIN = 1.0  # u = r - GAIN y: closed-loop poles -1.07 +/- 3.92j, -0.23 +/- 0.46j, all stable


def _record(real_pole: float, noise: float, samples: int = 1000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Input and measured output of the plant under feedback, driven by a reference held for ten samples."""
    A = np.zeros((4, 4))
    A[0, 0], A[1, 1] = real_pole, POLES[1].real
    A[2:, 2:] = [[POLES[2].real, POLES[2].imag], [-POLES[2].imag, POLES[2].real]]
    B, C = np.array([1.0, 1.0, 0.0, 2.0]), np.array([1.0, -0.6, 1.0, 0.0])
    exact = scipy.linalg.expm(np.block([[A, B[:, None]], [np.zeros((1, 5))]]) * DT)  # zero-order hold
    Ad, Bd = exact[:4, :4], exact[:4, 4]
    rng = np.random.default_rng(seed)
    reference = np.repeat(rng.standard_normal(samples // 10 + 1), 10)[:samples]
    x, u, y = np.zeros(4), np.zeros(samples), np.zeros(samples)
    for k in range(samples):
        y[k] = C @ x + noise * rng.standard_normal()
        u[k] = reference[k] - GAIN * y[k]
        x = Ad @ x + Bd * u[k]
    return u, y


def _identify(tmp_path, real_pole: float, noise: float, samples: int = 1000) -> dict:
    u, y = _record(real_pole, noise, samples)
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack([np.arange(len(u)) * DT, u, y]), delimiter=",", header="t,u,y", comments="")
    done = run_vehid("identify", path, "--inputs", "u", "--outputs", "y", "--validation", "0.3", "--json", "--quiet")
    assert done.returncode == 0, done.stderr[-500:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _eigenvalues(summary: dict) -> np.ndarray:
    return np.array([complex(*value) for value in summary["eigenvalues"]])


# Measured: the real pole 0.299 (noise 1 % of the output's RMS) and 0.294 (6 %), the pair within 1.4 %.
# 10 % of each pole's magnitude is five times the larger error; a stable model misses +0.3 by more than 100 %.
TOLERANCE = 0.10


@pytest.mark.parametrize("noise", [0.01, 0.05])
def test_default_identify_keeps_the_unstable_pole(tmp_path, noise):
    """Without --allow-unstable the plant is found open-loop unstable, said so, and every pole recovered."""
    summary = _identify(tmp_path, POLES[0].real, noise)
    found = _eigenvalues(summary)
    for pole in POLES:
        assert np.min(np.abs(found - pole)) <= TOLERANCE * abs(pole), (pole, found)
    assert summary["open_loop_unstable"]["assumed"]
    # a choice made for the user, said once as a note: a healthy run of an unstable plant has nothing to warn
    assert sum("treated as open-loop unstable" in line for line in summary["notes"]) == 1, summary["notes"]
    assert not any("open-loop unstable" in line for line in summary["warnings"]), summary["warnings"]
    assert summary["horizon"] == 10  # an unstable model is scored by k-step prediction
    # measured 95.2 and 92.2 %; the run that kept stability asked scored 37.7 % (noise 1 %)
    assert summary["validation_fit_percent"][0] > 85.0


def test_a_stable_plant_stays_stable(tmp_path):
    """The mirror plant (real pole at -0.3): no unstable start, nothing assumed, a stable model, the poles found.

    Stable, the two real poles (-0.3 and -0.5) have nearly alike responses, and 1000 samples do not tell them
    apart: over noise seeds 0-5 at 1 % noise three runs merge them into a complex pair and the others miss a
    pole by 2-36 %, with or without the refinement by simulation error (whose stated stds there are 0.32 and
    0.64 rad/s). With 3000 samples seeds 0-3 give -0.297/-0.503, -0.290/-0.532, -0.293/-0.520 and
    -0.307/-0.469, within 7 %, and seed 4 still merges them; seed 0, the one used, is within 1 % of both, far
    inside the tolerance.
    """
    summary = _identify(tmp_path, -POLES[0].real, 0.01, samples=3000)
    found = _eigenvalues(summary)
    assert not (summary.get("open_loop_unstable") or {}).get("assumed", False)
    assert np.all(found.real < 0) and summary["horizon"] is None
    assert not any("open-loop unstable" in line for line in summary["warnings"] + summary["notes"])
    for pole in (-POLES[0].real, *POLES[1:]):
        assert np.min(np.abs(found - pole)) <= TOLERANCE * abs(pole), (pole, found)


def test_the_text_summary_says_what_an_unstable_model_s_simulation_scores_mean(tmp_path):
    """The fits from rest and the residual tests simulate from rest, where the growing mode diverges: the text says
    so, once each."""
    u, y = _record(POLES[0].real, 0.01)
    path = tmp_path / "record.csv"
    np.savetxt(path, np.column_stack([np.arange(len(u)) * DT, u, y]), delimiter=",", header="t,u,y", comments="")
    done = run_vehid("identify", path, "--inputs", "u", "--outputs", "y", "--validation", "0.3")
    assert done.returncode == 0, done.stderr[-500:]
    lines = done.stdout.splitlines()
    r_line = next(line for line in lines if line.startswith("simulated from rest"))
    assert "unstable model's simulation diverges" in r_line
    assert sum("an unstable mode makes diverge" in line for line in lines) == 1
