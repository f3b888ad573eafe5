"""The paper's linear example (Best & Bogdanski 2017, section 4): Tables 1-4 and the order study.

Independent truth: the eigenvalues of eq. 15 (and their Euler equivalents
(e^{lambda T} - 1)/T, where the paper's Euler filter converges), the paper's
printed tables, and the true model's own fit to noisy data.
"""

import numpy as np
import pytest

from vehid.scenarios import linear_example
from vehid.scenarios.linear_example import PAPER, euler_equivalent, make_data, true_model

TRUE_EIGENVALUES = np.array([-15 + 10j, -15 - 10j, -8 + 40j, -8 - 40j, -4 + 0j])


def run_case(case, **settings):
    """A case of the linear example without the models' parameter covariances, which no test here reads
    (they cost one more pass and the fit's sensitivity per run, a tenth of the order study)."""
    return linear_example.run_case(case, parameter_covariance=False, **settings)


def _matched_relative_error(found, reference):
    """Largest relative distance after pairing each reference eigenvalue with its nearest found one."""
    found = list(np.asarray(found, dtype=complex))
    worst = 0.0
    for value in reference:
        nearest = min(found, key=lambda candidate: abs(candidate - value))
        found.remove(nearest)
        worst = max(worst, abs(nearest - value) / abs(value))
    return worst


def test_data_follow_eq16():
    data, clean = make_data(0)
    assert data.n_samples == 50_000 and data.dt == pytest.approx(0.002)
    # 50 Hz points linearly interpolated: every 10th sample is a knot, the ones between lie on the chord
    u = data.u[:, 0] - 0.1
    assert np.allclose(u[5], 0.5 * (u[0] + u[10]), atol=1e-12)
    assert abs(np.mean(data.u[:, 0]) - 0.1) < 0.05 and abs(np.mean(data.u[:, 1]) + 0.1) < 0.05  # offsets; 5,000 N(0,1) draws: 3 sigma = 0.04
    assert np.array_equal(data.y, clean)


def test_table1_euler_filter_converges_to_the_euler_equivalent():
    """Table 1 over six data realisations.

    The pairs: within 1 % of the Euler equivalents of eq. 15 and 3 % of the paper's values, on every seed.
    The weak real pole (the paper calls it insensitive) has a fixed point that depends on the realisation,
    because the Euler model cannot represent first-order-hold data exactly: measured -3.957 to -4.061 over
    seeds 0-5 (Euler equivalent -3.984, paper -4.09), fully converged (unchanged from pass 60 to 300).
    The same two tolerances are therefore applied to its mean over the six realisations.
    """
    euler_pairs = euler_equivalent(TRUE_EIGENVALUES[:4])
    paper = np.array(PAPER["single-output"]["eigenvalues"])
    paper_pairs = paper[np.abs(paper.imag) > 0]
    weak_poles = []
    for seed in range(6):
        run = run_case("single-output", discretization="euler", seed=seed).runs["single-output"]
        eigenvalues = run.model.eigenvalues()
        pairs = eigenvalues[np.abs(eigenvalues.imag) > 0]
        assert _matched_relative_error(pairs, euler_pairs) < 0.01
        assert _matched_relative_error(pairs, paper_pairs) < 0.03
        weak_poles.append(eigenvalues[np.abs(eigenvalues.imag) == 0][0].real)
        # R with the filter's discretisation after two passes (paper: 99.4 %)
        assert run.history[1].mean_fit_filter >= 99.4
        # D of the Euler model is not zero: [0.0123, -0.0023] (paper: [0.0123, -0.002])
        assert np.allclose(run.model.D, [[0.0123, -0.0023]], atol=3e-4)
        # the Euler model is not the continuous system: simulated exactly it explains at most ~97.5 %
        assert run.history[-1].mean_fit_continuous < 98.0
    weak = float(np.mean(weak_poles))
    assert abs(weak - euler_equivalent(-4.0).real) / 3.984 < 0.01
    assert abs(weak - (-4.09)) / 4.09 < 0.03


def test_table1_paper_start_explains_the_output_after_two_passes():
    # from the paper's start (sigma = -1, omega = 1) R reaches the paper's 99.4 % within two passes too
    run = run_case("single-output", discretization="euler", start="paper", passes=2).runs["single-output"]
    assert run.history[1].mean_fit_filter >= 99.4


def test_table1_exact_filter_recovers_the_continuous_system():
    result = run_case("single-output", discretization="exact")
    run = result.runs["single-output"]
    assert _matched_relative_error(run.model.eigenvalues(), TRUE_EIGENVALUES) < 0.01
    assert np.max(np.abs(run.model.D)) < 1e-3
    truth = true_model()
    order = np.argsort(np.abs(run.model.parameters[:5]))
    assert np.allclose(np.abs(run.model.parameters[:5])[order], np.abs(truth.parameters[:5])[np.argsort(np.abs(truth.parameters[:5]))], rtol=1e-3)
    assert run.history[-1].mean_fit_continuous > 99.99


def test_table2_three_outputs_with_first_row_fixed_fit_nearly_perfectly():
    result = run_case("three-output", discretization="euler", passes=20)
    run = result.runs["three-output"]
    # the paper: R near 100 % (while trace(P) and some parameters drift; not asserted: realisation-dependent)
    assert run.history[-1].mean_fit_filter > 99.9


def test_table3_eq18_pattern_finds_all_five_eigenvalues_on_most_seeds():
    # The paper finds all five with the eq. 18 pattern; the outcome depends on the data realisation,
    # so five seeds are run and at least four must find every eigenvalue within 2 % (exact mode).
    # The verdict is decided once four seeds found them or two missed: the seeds left cannot change it.
    found = missed = 0
    for seed in range(5):
        if found >= 4 or missed >= 2:
            break
        result = run_case("three-output-constrained", discretization="exact", seed=seed, passes=25)
        if _matched_relative_error(result.runs["three-output-constrained"].model.eigenvalues(), TRUE_EIGENVALUES) < 0.02:
            found += 1
        else:
            missed += 1
    assert found >= 4


def test_table4_noise():
    result = run_case("noise", discretization="euler")
    rows = {row["noise"]: row for row in result.rows}
    assert set(rows) == {"10 %", "30 %", "50 %", "70 %"}
    for level in ("10 %", "30 %"):
        assert rows[level]["R_clean"] >= 99.5
    for row in rows.values():
        # as good as the true model on the same noisy data, to half a point
        assert abs(row["R_noisy"] - row["R_noisy_true_model"]) <= 0.5
        assert row["paper_R_noisy"] == PAPER["noise"]["R_noisy"][float(row["noise"].split()[0]) / 100]


@pytest.mark.slow
def test_order_study_prefers_four_or_five_states():
    result = run_case("orders", discretization="euler", passes=40)
    rows = {row.order: row for row in result.orders.rows}
    # R grows with n from 3 to 5 (filter discretisation, mean over the three outputs)
    assert rows[3].mean_fit_filter < rows[4].mean_fit_filter < rows[5].mean_fit_filter
    assert rows[3].mean_fit_filter < 99.5  # n = 3 fits poorly (paper)
    assert result.orders.chosen_order in (4, 5)
    # n = 6 and 7 are over-parameterised: trace(P) does not settle (paper: "P diverges markedly")
    assert not rows[6].converged and not rows[7].converged


def test_the_default_covariance_form_stays_positive_definite_where_the_papers_does_not():
    """Same data, same start: the paper's P update (eq. 13) leaves P indefinite after some passes
    (measured smallest eigenvalue -0.0076), the default congruence + Joseph form keeps it positive
    definite (1e-5), and both reach the same model."""
    paper = run_case("single-output", discretization="euler", covariance="paper", start="paper", passes=30)
    robust = run_case("single-output", discretization="euler", covariance="joseph", start="paper", passes=30)
    paper_run, robust_run = paper.runs["single-output"], robust.runs["single-output"]
    assert min(record.min_eig_p for record in paper_run.history) < 0
    assert min(record.min_eig_p for record in robust_run.history) > 0
    assert _matched_relative_error(paper_run.model.eigenvalues(), robust_run.model.eigenvalues()) < 0.01
