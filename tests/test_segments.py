"""Contiguous parts of a record: blocks, the delete-one-block jackknife and the agreement of parts.

Closed forms first (the jackknife of a mean, one-step replicates of a linear fit, agreement counted on
given numbers, the t factor against its table), then coverage of the intervals on a regression whose
residuals are coloured, then the committed race car's log cut into four 20 s parts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vehid.identification.assessment.segments import (
    UncertaintyMethod,
    block_edges,
    block_plan,
    homogeneity,
    interval_scale,
    jackknife_covariance,
    one_step_replicates,
    pair_agreement,
    refit_replicates,
    segment_consistency,
)
from vehid.identification.assessment.uncertainty import fit_covariance
from vehid.identification.errors import InputError

LOG = Path(__file__).parent / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"


def test_jackknife_variance_of_a_sample_mean_is_s_squared_over_n():
    # Efron 1982, eq. 3.2: the delete-one replicates of a mean give exactly s^2 / n (algebra: 1e-12)
    x = np.random.default_rng(0).normal(3.0, 2.0, size=37)
    replicates = (x.sum() - x) / (x.size - 1)
    assert jackknife_covariance(replicates)[0, 0] == pytest.approx(np.var(x, ddof=1) / x.size, rel=1e-12)
    # refits of the mean without each block of one sample are those replicates, and a failed refit is counted
    edges = block_edges(x.size, x.size)
    found, failed = refit_replicates(lambda kept: np.mean(np.concatenate([x[part] for part in kept])), edges)
    np.testing.assert_allclose(found.ravel(), replicates, rtol=1e-12)
    assert failed == ()
    _, failed = refit_replicates(lambda kept: None if kept[0].stop == 3 else 0.0, edges)
    assert failed == (3,)


def test_one_step_replicates_of_a_linear_fit_are_its_exact_refits():
    # on a linear least-squares fit one Gauss-Newton step is the minimiser: each replicate is the fit without
    # its block (1e-9 relative: the triangular solves against lstsq, both near machine precision)
    rng = np.random.default_rng(1)
    x = np.column_stack([np.ones(600), rng.normal(size=600), np.sin(np.arange(600) / 30.0)])
    y = x @ [1.0, -2.0, 0.5] + 0.3 * rng.normal(size=600)
    theta = np.linalg.lstsq(x, y, rcond=None)[0]
    errors = x @ theta - y
    edges = block_edges(600, 6)
    blocks = [slice(a, b) for a, b in zip(edges[:-1], edges[1:])]
    replicates = one_step_replicates(theta, [x[b] for b in blocks], [x[b].T @ errors[b] for b in blocks],
                                     form="one-step")
    for k, block in enumerate(blocks):
        kept = np.ones(600, dtype=bool)
        kept[block] = False
        exact = np.linalg.lstsq(x[kept], y[kept], rcond=None)[0]
        np.testing.assert_allclose(replicates[k], exact, rtol=1e-9)
    # a parameter that one block alone determines has no replicate without it
    lonely = np.zeros((600, 1))
    lonely[edges[2]:edges[3]] = 1.0
    with pytest.raises(InputError, match="block 3"):
        one_step_replicates(np.zeros(2), [np.hstack([x[b, :1], lonely[b]]) for b in blocks], np.zeros((6, 2)),
                            form="one-step")


def test_linearised_replicates_give_the_block_sandwich():
    # with the whole record's curvature the jackknife's covariance is K / (K - 1) H^-1 sum (g_k - mean)(...)' H^-1
    # (algebra, 1e-10), whatever the estimate's own step (a filter's estimate is not the minimiser)
    rng = np.random.default_rng(2)
    edges = block_edges(500, 5)
    jacobians = [rng.normal(size=(b - a, 3)) * [1.0, 1e3, 1e-2] for a, b in zip(edges[:-1], edges[1:])]
    gradients = rng.normal(size=(5, 3))
    replicates = one_step_replicates(np.ones(3), jacobians, gradients)
    inverse = np.linalg.inv(sum(j.T @ j for j in jacobians))
    centred = gradients - gradients.mean(axis=0)
    np.testing.assert_allclose(jackknife_covariance(replicates), 5 / 4 * inverse @ centred.T @ centred @ inverse,
                               rtol=1e-10)


def test_agreement_is_counted_pair_by_pair_within_the_intervals():
    # z sqrt(0.5^2 + 0.5^2) = 1.386 at 95 %: 0 and 1 agree, 3 agrees with neither; a part without an estimate
    # is not judged
    found = pair_agreement([0.0, 1.0, 3.0, np.nan], [0.5, 0.5, 0.5, 0.5])
    assert (found.pairs, found.agreeing, found.disagreeing) == (3, 1, ((0, 2), (1, 2)))
    assert found.share == pytest.approx(1 / 3)
    # the bound is the two-sided test of equal means: just inside and just outside it
    bound = 1.959963984540054 * np.hypot(0.3, 0.4)
    assert pair_agreement([0.0, bound * (1 - 1e-9)], [0.3, 0.4]).agreeing == 1
    assert pair_agreement([0.0, bound * (1 + 1e-9)], [0.3, 0.4]).agreeing == 0


def test_consistency_names_the_quantities_whose_parts_disagree():
    spans = [(150.0 + 110 * i, 260.0 + 110 * i) for i in range(5)]
    stiffness = {"values": [41.6e3, 38.0e3, 39.7e3, 33.5e3, 34.9e3], "stds": [400.0] * 5, "unit": "N/rad",
                 "label": "front cornering stiffness", "display_unit": "kN/rad", "display_factor": 1e-3}
    inertia = {"values": [1250.0, 1240.0, 1260.0, 1255.0, 1245.0], "stds": [20.0] * 5, "unit": "kg m^2"}
    found = segment_consistency(spans, {"cornering_stiffness_front": stiffness, "yaw_inertia": inertia})
    assert [q.name for q in found.failing] == ["cornering_stiffness_front"] and not found.consistent
    warning = found.warning("the single-track model")
    assert "front cornering stiffness 33.5-41.6 kN/rad (0 of 10 pairs agree)" in warning
    assert "across 5 parts" in warning and "yaw_inertia" not in warning
    entry = found.as_dict()
    assert entry["parts"][3]["estimates"]["cornering_stiffness_front"] == {"value": 33.5e3, "std": 400.0,
                                                                          "unit": "N/rad"}
    assert entry["agreement"]["yaw_inertia"]["holds"] and entry["agreement"]["yaw_inertia"]["agreeing"] == 10
    assert segment_consistency(spans, {"yaw_inertia": inertia}).warning() is None
    # one pair in three outside its interval (2 of 3 agree, below 80 %) but Cochran's Q = 7.29 on 2 degrees of
    # freedom (p = exp(-7.29 / 2) = 0.026) does not reject one common value at 1 %: not named
    chance = {"values": [0.0, 1.0, 3.0], "stds": [0.8] * 3, "unit": "-"}
    found = segment_consistency(spans[:3], {"x": chance})
    assert found.quantities[0].agreement.agreeing == 2 and found.consistent
    assert found.quantities[0].homogeneity_p == pytest.approx(np.exp(-(42 / 9 / 0.64) / 2), rel=1e-9)
    with pytest.raises(InputError, match="3 estimates for 5 parts"):
        segment_consistency(spans, {"x": {"values": [1, 2, 3], "stds": [1, 1, 1]}})


def test_homogeneity_is_cochrans_q():
    # two estimates 0 and 2 with unit std: Q = 1 + 1 = 2 on one degree of freedom, P(chi2_1 > 2) = 0.15730
    # (table); a part without an estimate is left out
    statistic, dof, p = homogeneity([0.0, 2.0, np.nan], [1.0, 1.0, 1.0])
    assert (statistic, dof) == (pytest.approx(2.0, rel=1e-12), 1) and p == pytest.approx(0.15730, abs=1e-5)
    assert homogeneity([1.0], [1.0]) == (0.0, 0, 1.0)


def test_blocks_and_the_t_factor():
    edges = block_edges(1003, 8)
    assert edges[0] == 0 and edges[-1] == 1003 and np.ptp(np.diff(edges)) <= 1
    assert np.diff(block_plan(1000, min_length=100)).tolist() == [125] * 8  # at most 8 blocks
    assert block_plan(1000, min_length=300) is None  # three blocks of the correlation time: too few
    # t(7) at 97.5 % is 2.3646243 (any t table), z 1.9599640; t(1) 12.706205
    assert interval_scale(7) == pytest.approx(2.3646243 / 1.9599640, rel=1e-6)
    assert interval_scale(1) == pytest.approx(12.706205 / 1.9599640, rel=1e-6)
    method = UncertaintyMethod("block-jackknife", "one-step", 8, (125, 126), (1.25, 1.26), 7, 1.2065)
    assert UncertaintyMethod.from_dict(method.as_dict()) == method


def _coverage(rho_noise: float, seeds: int) -> tuple[float, float]:
    """Coverage of the slope's 95 % interval, jackknife and formal, over ``seeds`` regressions (seeds 0, 1, ...).

    ``y = 1 + 2 x + e`` over 2000 samples, ``x`` and ``e`` each AR(1) (``x`` with 0.95, ``e`` with
    ``rho_noise``): where both are coloured, the slope's variance is about ``(1 + 0.95 rho) / (1 - 0.95 rho)``
    times what white residuals would give.
    """
    from scipy.signal import lfilter

    inside = np.zeros(2)
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        x = lfilter([1.0], [1.0, -0.95], rng.standard_normal(2000))
        e = lfilter([1.0], [1.0, -rho_noise], rng.standard_normal(2000))
        design = np.column_stack([np.ones(2000), x])
        theta = np.linalg.lstsq(design, 1.0 + 2.0 * x + e, rcond=None)[0]
        residuals = (design @ theta - (1.0 + 2.0 * x + e))[:, None]
        for column, jackknife in enumerate((True, False)):
            covariance, _ = fit_covariance(design, residuals, jackknife=jackknife)
            inside[column] += abs(theta[1] - 2.0) <= 1.959964 * np.sqrt(covariance[1, 1])
    return tuple(inside / seeds)


def test_jackknife_intervals_hold_where_residuals_are_coloured_and_formal_ones_do_not():
    # 300 regressions: a calibrated 95 % interval covers 91.5-98.5 % of them (binomial 99 % range). With
    # residuals AR(1) at 0.9 the formal interval is about 3.6 times too narrow and covers some 40 % (measured
    # 38 %); the jackknife (blocks of 250 samples, some 13 correlation times) covers 95 % (measured 94.0 %).
    # With white residuals both hold (measured 93.3 % and 94.3 %).
    jackknife, formal = _coverage(0.9, 300)
    assert 0.915 <= jackknife <= 0.985 and formal < 0.6, (jackknife, formal)
    jackknife, formal = _coverage(0.0, 300)
    assert 0.915 <= jackknife <= 0.985 and 0.915 <= formal <= 0.985, (jackknife, formal)


@pytest.fixture(scope="module")
def race_car_parts():
    """The committed lap cut into four 20 s parts, each identified (single-track) as the command does."""
    from vehid.identification.data import IOData
    from vehid.identification.filtering.greybox import GreyBoxOptions
    from vehid.scenarios.single_track_identify import _substeps, fit_log
    from vehid.vehicle.single_track import SingleTrackConfig

    table = np.genfromtxt(LOG, delimiter=",", skip_header=2)
    config = SingleTrackConfig(982.0, 1.33, 1.07)  # the car's published mass and axle distances
    parts = []
    for start in (390.0, 410.0, 430.0, 450.0):
        rows = table[(table[:, 0] >= start - 1e-9) & (table[:, 0] < start + 20.0 - 1e-9)]
        record = IOData(t=rows[:, 0], u=rows[:, 1:3], y=rows[:, 3:5])
        parts.append((record, fit_log(config, record, options=GreyBoxOptions(substeps=_substeps(config, record)))))
    return config, parts


def _judged(config, parts, covariances):
    """Per quantity: pairs agreeing within 95 % and the median std over the parts' spread."""
    from vehid.vehicle.single_track import single_track_handling

    values, stds = [], []
    for (_, result), covariance in zip(parts, covariances):
        gradient = single_track_handling(config, result.parameters, covariance, speeds=()).understeer_gradient
        values.append([*result.parameters[:3], gradient.value])
        stds.append([*np.sqrt(np.diag(covariance))[:3], gradient.std])
    values, stds = np.array(values), np.array(stds)
    return [(pair_agreement(values[:, i], stds[:, i]).share, np.median(stds[:, i]) / np.std(values[:, i], ddof=1))
            for i in range(4)]


def test_the_filters_bars_on_the_committed_lap_do_not_hold(race_car_parts):
    # the defect: the grey-box filter's covariance pass (white innovations), which the command reported, makes
    # the four parts' understeer gradients (1.08, 1.53, 1.50, 2.48 deg/g, std 0.009-0.040) agree in 1 of 6
    # pairs; every quantity's std is 3-12 % of the parts' spread
    config, parts = race_car_parts
    for share, ratio in _judged(config, parts, [result.covariance for _, result in parts]):
        assert share < 0.8 and ratio < 0.5


def test_the_reported_bars_on_the_committed_lap_hold_and_are_not_simply_wide(race_car_parts):
    # what the command reports now (the fit's block jackknife): for front and rear cornering stiffness, yaw
    # inertia and understeer gradient, at least 80 % of the part pairs agree within their 95 % intervals and
    # the median std is at most twice the parts' spread (measured: 6 of 6 pairs each; ratios 0.50, 0.82, 1.65,
    # 0.69)
    from vehid.scenarios.single_track_segments import honest_covariance

    config, parts = race_car_parts
    covariances = []
    for record, result in parts:
        covariance, method = honest_covariance(result.model, result, record)
        assert method.name == "block-jackknife" and method.blocks == 8
        covariances.append(covariance)
    for share, ratio in _judged(config, parts, covariances):
        assert share >= 0.8 and ratio <= 2.0
