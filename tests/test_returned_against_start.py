"""Whether the held-out part ranks the model identify returns against its data start
(``benchmarks/returned_against_start.py``, whose modules are loaded here)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import load_benchmark_module


load_benchmark_module("_real_records")
benchmark = load_benchmark_module("returned_against_start")


@pytest.mark.parametrize("whole, parts, expected", [
    (+0.5, [0.1, 0.2, 3.0, 0.01], True),     # every part agrees with the whole
    (-1.0, [-0.2, -0.1, -4.0, -0.3], True),  # a loss the data show is a ranked loss
    (-1.0, [1.2, 5.4, 2.1, 3.7], False),     # the whole disagrees with every part (the tanks' case)
    (+2.7, [2.4, 3.7, 5.2, -1.1], False),    # one part the other way round
    (0.0, [0.0, 0.0, 0.0, 0.0], False),      # the same model twice ranks nothing
    (+0.3, [0.2, 0.0, 0.1, 0.4], False),     # a part without a difference does not agree
])
def test_a_difference_is_ranked_only_where_every_part_has_its_sign(whole, parts, expected):
    assert benchmark.ranks(whole, parts) is expected


def test_the_heat_exchangers_refined_model_leads_its_start_on_every_part_of_the_hold_out():
    """The default on the heat exchanger (last 30 % held out) returns the filter's model refined by its simulation
    error; the held-out part ranks it above the data start. Measured: +3.7 points on the whole and +3.7 to +10.4
    on each quarter (over fractions 0.3-0.4 the smallest quarter's lead is 2.6 points). Asserted: a lead on the
    whole and on every quarter, a sign and no figure, which a refinement that predicts worse than its start
    would break."""
    from vehid.identification import ReadSettings, identify

    entry = benchmark.records.record_set("exchanger")
    result = identify(str(entry.file), reading=ReadSettings(inputs=entry.inputs, outputs=entry.outputs, dt=entry.dt),
                      validation=0.3)
    row = benchmark.compare(result)
    assert row["model_returned"] == "filter"
    assert len(row["returned_minus_start_by_part"]) == benchmark.PARTS
    assert row["returned_minus_start"][0] > 0 and all(part[0] > 0 for part in row["returned_minus_start_by_part"])
    assert row["held_out_ranks"] == [True]
    # the whole part's fits are those the command reports for the returned model
    assert np.isclose(row["returned_fit_percent"][0], result.validation_fit_percent[0], atol=1e-9)
