"""The appendix's examples as `vehid study textbook` reports them (seed appendix A.2-A.5)."""

import json

import numpy as np
import pytest

from vehid.scenarios.cli import main
from vehid.scenarios.textbook import positivity_example, ud_example


def test_plain_update_loses_positivity_and_factorised_forms_do_not():
    """A.5's single-parameter example in float32: P0 = 1e7, phi = 1.7 then 0.5 (A.114-A.116)."""
    example = positivity_example()
    plain = np.array([np.nan if v is None else v for v in example["plain"]["P"]], dtype=float)
    assert plain[0] == -1.0  # K phi rounds to 1 + 2^-23 > 1: P(1) = P0 (1 - K phi) = -1 exactly in float32
    assert np.all(plain[1:4] < plain[0])  # with P < 0 and P phi^2 > -1, P(k+1) = P(k) (1 - K phi) grows more negative
    assert not np.all(np.isfinite(plain))  # 1 + P phi^2 reaches 0: the blow-out of A.116
    for form in ("sqrt", "ud"):
        P = np.array(example[form]["P"])
        assert np.all(P > 0)
        # exact P(k) = 1 / (1/P0 + sum phi^2): float32 carries ~7 digits
        exact = 1.0 / (1.0 / 1e7 + np.cumsum(np.square(example["phi"])))
        np.testing.assert_allclose(P, exact, rtol=1e-5)
        assert abs(example[form]["theta"][-1] - 2.0) < 0.1  # noise 0.1 over ~10 samples


def test_ud_step_equals_the_plain_covariance_update():
    example = ud_example()
    np.testing.assert_allclose(example["P_from_UD"], example["P_plain"], atol=1e-12)
    assert example["beta"] == pytest.approx(0.98 + 1.0 * 4.0 + 2.5 * 5.0)  # lambda + F'G by hand


def test_study_textbook_json_contract(capsys):
    assert main(["study", "textbook", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    rows = summary["kalman_example"]
    assert [row["k"] for row in rows] == [1, 2, 3, 4, 5]
    assert set(rows[0]) == {"k", "P_prior", "K", "P_post"}
    assert rows[0]["P_prior"] == pytest.approx(125.0) and rows[0]["K"] == pytest.approx(125 / 140)
    for key in ("rls_example", "gls_example", "positivity_example", "ud_example", "ekf_bicycle_example",
                "pencil_example"):
        assert key in summary
    assert main(["study", "textbook"]) == 0
    assert "P(k|k-1)" in capsys.readouterr().out
