"""The real-data benchmark's like-for-like rules: the peers' order search, the perturbed records, the splits.

``benchmarks/_peers_runner.py`` gives every peer library the order search
``vehid identify --order 2-8`` gets, and ``benchmarks/real_data.py`` reruns
the default identify on perturbed copies of each record and at other
held-out fractions. The peers themselves live in their own virtual
environment; these tests stand in for them with models whose outputs are
known exactly.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from conftest import load_benchmark_module
from scipy.io import loadmat

from vehid.identification import IOData
from vehid.identification.automatic.orders import ORDER_TOLERANCE, choose_order


load_benchmark_module("_baselines")  # real_data imports it by this name, as the runner does _real_records
records = load_benchmark_module("_real_records")
runner = load_benchmark_module("_peers_runner")


@pytest.mark.parametrize("seed", range(20))
def test_peer_order_choice_is_identifys(seed):
    """On the same fits, the peers' order rule picks the order identify's own ``choose_order`` picks."""
    rng = np.random.default_rng(seed)
    orders = range(2, 9)
    # fits bunched within a couple of points, so that the tolerance decides; some orders failed
    fits = {n: None if rng.random() < 0.2 else float(90 + rng.uniform(-2, 2)) for n in orders}
    if all(f is None for f in fits.values()):
        fits[5] = 90.0
    rows = [{"order": n, "eligible": f is not None, "ranking_fit": np.nan if f is None else f} for n, f in fits.items()]
    assert records.choose_order(fits, ORDER_TOLERANCE) == choose_order(rows)


def test_no_eligible_order_gives_none():
    assert records.choose_order({2: None, 3: float("nan"), 4: float("-inf")}) is None


# A fourth-order plant of two decoupled lightly damped modes, each seen at the output.
MODES = [(0.95, 0.25), (0.7, 1.2)]  # radius, angle (rad) of each complex pair


def _block(radius, angle):
    c, s = radius * np.cos(angle), radius * np.sin(angle)
    return np.array([[c, -s], [s, c]])


def _plant(modes):
    n = 2 * len(modes)
    A = np.zeros((n, n))
    for i, mode in enumerate(modes):
        A[2 * i:2 * i + 2, 2 * i:2 * i + 2] = _block(*mode)
    B = np.tile([[1.0], [0.0]], (len(modes), 1))
    C = np.tile([[0.0, 1.0]], (1, len(modes)))
    return A, B, C, np.zeros((1, 1))


def _padded(model, order):
    """The model with ``order - n`` extra states that neither the input reaches nor the output sees."""
    A, B, C, D = model
    extra = order - A.shape[0]
    return (np.block([[A, np.zeros((A.shape[0], extra))], [np.zeros((extra, A.shape[0])), 0.5 * np.eye(extra)]]),
            np.vstack([B, np.zeros((extra, 1))]), np.hstack([C, np.zeros((1, extra))]), D)


def _stand_in_peer(u, y, order):
    """The first mode alone below order 4 (order 3 fails, as peers do at some orders), the whole plant from 4 up."""
    if order == 3:
        raise np.linalg.LinAlgError("no realisation of this order")
    return _plant(MODES[:1]) if order < 4 else _padded(_plant(MODES), order)


@pytest.mark.parametrize("rule", ["holdout", "estimation-split"])
def test_peer_search_chooses_the_smallest_order_that_explains_the_data(rule, monkeypatch):
    """Orders 4-8 reproduce the plant exactly (their fits tie), order 2 misses a mode: 4 is chosen, 3 recorded."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal((800, 1))
    u -= u.mean(axis=0)  # a centred input, so removing the estimation means changes nothing
    forced, _ = records.discrete_responses(*_plant(MODES), u)
    y = forced
    cut = records.split_index(len(u), 0.3)
    estimation, validation = (u[:cut], y[:cut]), ((u[cut:], y[cut:]), (np.zeros(1), np.zeros(1)))
    monkeypatch.setitem(runner.LINEAR_PEERS, "stand-in", _stand_in_peer)
    options = SimpleNamespace(orders=tuple(range(2, 9)), rule=rule, tolerance=ORDER_TOLERANCE, inner_holdout=0.3)
    row = runner.search("stand-in", estimation, validation, options)
    assert row["order"] == 4, row
    # the exact plant, from the least-squares initial state: the fit is 100 % up to rounding
    assert row["validation_fit_percent"][0] == pytest.approx(100.0, abs=1e-6)
    assert row["fit_by_order"][2] < 100.0 - 10 * ORDER_TOLERANCE  # a missing mode costs far more than the tolerance
    assert row["fit_by_order"][3] is None and 3 in row["errors_by_order"]
    assert ("selection_fit_by_order" in row) == (rule == "estimation-split")


@pytest.mark.parametrize("fraction", [0.3, 0.3333, 0.35, 0.4])
@pytest.mark.parametrize("name", ["dryer", "cd_player_arm"])
def test_benchmark_splits_are_identifys_at_every_fraction(name, fraction):
    """At each held-out fraction the benchmark's split is ``IOData.split``'s, as ``identify --validation`` makes it."""
    (u_est, _), (u_val, _) = records.load(records.record_set(name), fraction)
    n = len(u_est) + len(u_val)
    data = IOData(t=np.arange(n, dtype=float), u=np.zeros((n, 1)), y=np.zeros((n, 1)))
    estimation, validation = data.split(1.0 - fraction)
    assert (estimation.n_samples, validation.n_samples) == (len(u_est), len(u_val))


@pytest.mark.parametrize("name", ["dryer", "cascaded_tanks"])
def test_perturbed_copy_differs_by_the_perturbation_alone(name, tmp_path):
    """Every number of the copy is the original times ``1 + r z``, z the seed's normal draws, to within rounding."""
    entry = records.record_set(name)
    relative = 1e-6
    copy = records.perturbed_copy(entry, tmp_path, relative, seed=3)
    assert copy.suffix == entry.file.suffix
    if entry.file.suffix == ".mat":
        original = {k: np.asarray(v, float) for k, v in loadmat(entry.file).items() if not k.startswith("__")}
        perturbed = {k: np.asarray(v, float) for k, v in loadmat(copy).items() if not k.startswith("__")}
        assert perturbed.keys() == original.keys()
        rng = np.random.default_rng(3)
        draws = {k: rng.standard_normal(v.shape) for k, v in original.items()}  # the copy's order of draws
        pairs = [(original[k], perturbed[k], draws[k]) for k in original]
    else:
        original, perturbed = np.loadtxt(entry.file, ndmin=2), np.loadtxt(copy, ndmin=2)
        pairs = [(original, perturbed, np.random.default_rng(3).standard_normal(original.shape))]
    for x, x_copy, z in pairs:
        assert x_copy.shape == x.shape
        # 17 significant digits hold a double exactly: what is left is a few units of the last place
        assert np.all(np.abs(x_copy - x * (1.0 + relative * z)) <= 4 * np.finfo(float).eps * np.abs(x))
        assert np.any(x_copy != x)
    (u_est, y_est), (u_val, y_val) = records.load(entry, file=copy)
    (u0, y0), (u1, y1) = records.load(entry)
    assert [a.shape for a in (u_est, y_est, u_val, y_val)] == [a.shape for a in (u0, y0, u1, y1)]


def test_peers_are_scored_as_identify_scores_and_their_order_chosen_on_those_scores():
    """A stable peer model keeps compare's figure (the same least-squares initial state); an unstable one is
    predicted 10 samples ahead, as identify scores its own unstable models; the order is chosen again on these."""
    from vehid.identification.assessment.validation import UNSTABLE_HORIZON, score
    from vehid.identification.classical.subspace import estimate_subspace
    from vehid.identification.models.discrete import DiscreteModel

    real_data = load_benchmark_module("real_data")
    entry = records.record_set("dryer")
    estimation, validation = records.load(entry, 0.3)
    u_offset, y_offset = records.validation_offsets(entry, estimation, validation)
    (u, y) = estimation
    fit = estimate_subspace((u - u.mean(axis=0), y - y.mean(axis=0)), order=2)
    stable = (fit.A, fit.B, fit.C, fit.D)
    growing = (fit.A * 1.02 / np.max(np.abs(np.linalg.eigvals(fit.A))), fit.B, fit.C, fit.D)  # 2 % a sample
    models = {order: {key: np.atleast_2d(m).tolist() for key, m in zip("ABCD", model)}
              for order, model in ((2, stable), (3, _padded(growing, 3)))}
    failed = {key: np.full(shape, np.nan).tolist()  # a peer that returned no finite model at order 4
              for key, shape in zip("ABCD", ((4, 4), (4, 1), (1, 4), (1, 1)))}
    compare = {order: records.score_discrete(*(np.asarray(models[order][k]) for k in "ABCD"),
                                             validation[0], validation[1], u_offset, y_offset)
               for order in models}
    row = {"order": 3, "validation_fit_percent": compare[3], "models_by_order": {**models, 4: failed},
           "fit_by_order": {order: fits[0] for order, fits in compare.items()}}
    narx = {"order": 2, "validation_fit_percent": [50.0]}
    peers = {"sets": {"dryer": {"0.3": {"stand-in": row, "narx": narx}}}}
    real_data.score_as_identify(peers, "holdout")

    held_out = IOData(t=np.arange(len(validation[0])) * entry.dt, u=validation[0] - u_offset,
                      y=validation[1] - y_offset)
    unstable = DiscreteModel(*(np.asarray(models[3][k]) for k in "ABCD"), entry.dt)
    assert not unstable.is_stable()
    predicted = float(score(unstable, held_out, horizon=UNSTABLE_HORIZON).fit[0])
    assert row["fit_by_order"][2] == pytest.approx(compare[2][0], abs=1e-9)  # stable: compare's own rule
    assert row["fit_by_order"][3] == pytest.approx(predicted, abs=1e-9)
    assert row["fit_by_order"][4] is None  # no fit, and no failure of the whole benchmark
    assert abs(predicted - compare[3][0]) > 1.0  # the two rules differ on the growing model
    assert row["order"] == records.choose_order(row["fit_by_order"], ORDER_TOLERANCE)
    assert row["validation_fit_percent"][0] == pytest.approx(row["fit_by_order"][row["order"]], abs=1e-12)
    assert row["compare_order"] == 3 and row["compare_fit_percent"] == compare[3]
    assert row["scored_as"] == "identify" and "models_by_order" not in row
    assert narx == {"order": 2, "validation_fit_percent": [50.0], "scored_as": "compare"}  # no model: as it came
