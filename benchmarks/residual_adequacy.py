"""Do the residual tests tell an adequate model from an under-modelled one?

1. The paper's linear example (eq. 15, output 1, 10 % output noise, 20 s):
   the IEKF at the Table 4 tuning (p = 0.001, 40 passes, normalised) for
   n = 3, 4, 5, each refined by output error from the IEKF's model, and the
   true model.
2. The handling study's archive (``results/handling_study.h5`` or the path
   given): every linear and nonlinear model on both records.

Prints per model the Ljung-Box p-value (``residual_whiteness_p``), the
largest input cross-correlation against its 99 % bound and the
cross-correlation portmanteau's p-value, and writes them to
``results/residual_adequacy.json``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from vehid.identification.archive import open_archive, read_records
from vehid.identification.comparators import identify_with
from vehid.identification.iekf import IEKFOptions, identify_iekf
from vehid.identification.iekf_archive import read_iekf_run
from vehid.identification.modal import ModalStructure
from vehid.identification.storage import read_group
from vehid.scenarios.linear_example import make_data, true_model
from vehid.scenarios.model_checks import model_residual_tests
from vehid.scenarios.paths import results_directory


def _row(label: str, tests) -> dict:
    row = {"model": label, "residual_whiteness_p": tests.residual_whiteness_p.tolist(),
           "input_correlation_max": tests.input_correlation_max.tolist(), "bound": tests.bound,
           "input_correlation_p": tests.input_correlation_p.tolist(), "adequate": tests.adequate}
    print(f"{label:38s} white p {[f'{v:.3g}' for v in row['residual_whiteness_p']]}  max |r_ue| "
          f"{[f'{v:.3f}' for v in row['input_correlation_max']]} (bound {tests.bound:.3f})  "
          f"r_ue p {[f'{v:.3g}' for v in row['input_correlation_p']]}  adequate {tests.adequate}")
    return row


def linear_example() -> list[dict]:
    data, _ = make_data(0, outputs=(0,), noise_ratio=0.1, duration=20.0)
    rows = [_row("eq. 15 true model", model_residual_tests(true_model(1), data))]
    for order in (3, 4, 5):
        structure = ModalStructure.from_pattern("all-ones", order, 2, 1)
        model = identify_iekf(data, structure, options=IEKFOptions(p=1e-3, passes=40, normalize=True)).model
        rows.append(_row(f"IEKF n = {order}", model_residual_tests(model, data)))
        refined = identify_with(data, method="output-error", order=order, start=model).model
        rows.append(_row(f"IEKF then output error n = {order}", model_residual_tests(refined, data)))
    return rows


def handling_study(path: Path) -> list[dict]:
    rows = []
    with open_archive(path, kinds=["handling-study"]) as archive:
        records = read_records(archive)
        models = {}
        for name in sorted(archive["runs"]):
            if name.startswith("linear-n"):
                models[name] = read_iekf_run(archive, name).model
            elif "model" in archive["runs"][name]:
                models[name] = read_group(archive["runs"][name]["model"])
    for record_name, data in records.items():
        for name, model in models.items():
            rows.append(_row(f"handling {name} on {record_name}",
                             model_residual_tests(model, data)))
    return rows


def main(handling_path: str | None = None) -> dict:
    figures = {"linear_example": linear_example()}
    path = Path(handling_path) if handling_path else results_directory() / "handling_study.h5"
    if path.exists():
        figures["handling_study"] = handling_study(path)
    else:
        print(f"no handling study archive at {path}: run `vehid study handling` first")
    (results_directory() / "residual_adequacy.json").write_text(json.dumps(figures, indent=2) + "\n")
    return figures


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
