"""Do the standard deviations hold on real logs? Disjoint parts of one drive, identified one by one.

Each log is cut into equal disjoint parts (the committed race car's 80 s lap,
``tests/data/race_car_250lm``, into four of 20 s; a longer drive given as
argument, such as the 550 s upstream record of the same car, into five of
110 s). On each part, as ``vehid identify`` runs it:

* the single-track model (``--structure single-track --schedule vx``, mass
  982 kg, CG to axles 1.33 / 1.07 m, outputs yaw rate and lateral
  acceleration): front and rear cornering stiffness, yaw inertia and the
  understeer gradient;
* the speed-scheduled modal model (``--schedule vx``): its understeer
  gradient at :data:`SPEED` m/s (which every part's speed range covers) by
  the handling metrics of the scheduled family.

For each quantity the table gives the parts' estimates and, before (the
filter's covariance pass for the single-track, the formal Gauss-Newton
covariance of white residuals for the scheduled family) and after (the
delete-one-block jackknife the workbench now reports): the range of the
stated standard deviations, how many pairs of parts agree within their 95 %
intervals (``|x_i - x_j| <= 1.96 sqrt(s_i^2 + s_j^2)``) and the median stated
std over the spread (sample standard deviation) of the parts' estimates.
Honest bars make about 95 % of pairs agree with a ratio near one; the goal is
at least 80 % of pairs and a ratio of at most 2. Variants of the jackknife
are tabled beside the command's (the single-track's one-step form with 6, 8
and 10 blocks and the linearised form with 8; the scheduled family's
one-step form), with the single-track's seconds per part for the fit and for
the jackknife.

``python benchmarks/segment_consistency.py [DRIVE.csv]``: without a drive
(or where its file is missing) the committed log alone. A drive file has the
committed log's columns (``t,delta,vx,yawRate,ayCG``, SI). Figures go to
``results/benchmarks.json`` under ``segment_consistency``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from vehid.identification.assessment.segments import pair_agreement
from vehid.identification.data import IOData
from vehid.identification.filtering.greybox import GreyBoxOptions
from vehid.identification.filtering.greybox_structure import simulation_fit_covariance
from vehid.scenarios.benchmarking import record_figures
from vehid.scenarios.single_track_identify import _substeps, fit_log
from vehid.scenarios.single_track_segments import JACKKNIFE_FORM
from vehid.vehicle.single_track import SingleTrackConfig, single_track_handling

ROOT = Path(__file__).resolve().parents[1]
RACE_LOG = ROOT / "tests" / "data" / "race_car_250lm" / "20140222_01_01_03_250lm.csv"
MASS, LF, LR = 982.0, 1.33, 1.07
#: Speed (m/s) of the scheduled model's understeer gradient: inside every part's range on both logs.
SPEED = 30.0
QUANTITIES = ("cornering_stiffness_front", "cornering_stiffness_rear", "yaw_inertia", "understeer_gradient")
#: The single-track's jackknife variants tabled beside the command's (one-step, 8 blocks): form and blocks.
VARIANTS = (("one-step", 6), ("one-step", 8), ("one-step", 10), ("linearised", 8))


def read_log(path: Path) -> tuple[np.ndarray, dict[str, int]]:
    """The table of a log (a header row of names, perhaps a row of units) and its columns by name."""
    with path.open() as handle:
        names = handle.readline().strip().split(",")
        second = handle.readline().strip().split(",")
    units_row = not all(_is_number(cell) for cell in second)
    table = np.genfromtxt(path, delimiter=",", skip_header=2 if units_row else 1)
    return table, {name: index for index, name in enumerate(names)}


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parts_of(path: Path, count: int) -> list[tuple[float, float]]:
    table, _ = read_log(path)
    t = table[:, 0]
    edges = np.linspace(t[0], t[-1] + (t[1] - t[0]), count + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:])]


def _record(path: Path, span: tuple[float, float]) -> IOData:
    table, column = read_log(path)
    keep = (table[:, 0] >= span[0] - 1e-9) & (table[:, 0] < span[1] - 1e-9)
    rows = table[keep]
    return IOData(t=rows[:, 0], u=rows[:, [column["delta"], column["vx"]]],
                  y=rows[:, [column["yawRate"], column["ayCG"]]],
                  input_names=("delta", "vx"), output_names=("yawRate", "ayCG"))


def single_track_parts(path: Path, spans: list[tuple[float, float]]) -> dict[str, Any]:
    """Each part's single-track estimates with the filter's and the jackknife's standard deviations."""
    config = SingleTrackConfig(MASS, LF, LR)
    rows: dict[str, Any] = {"before": [], **{_variant(*v): [] for v in VARIANTS}, "values": [], "seconds": []}
    for span in spans:
        record = _record(path, span)
        began = time.perf_counter()
        result = fit_log(config, record, options=GreyBoxOptions(substeps=_substeps(config, record)))
        fitted = time.perf_counter() - began
        gradient = single_track_handling(config, result.parameters, result.covariance, speeds=()).understeer_gradient
        rows["values"].append([*result.parameters[:3], gradient.value])
        rows["before"].append([*result.std[:3], gradient.std])
        for form, blocks in VARIANTS:
            began = time.perf_counter()
            covariance, _ = simulation_fit_covariance(result.model, result.parameters, record,
                                                      substeps=result.options.substeps, blocks=blocks, form=form)
            jackknife = time.perf_counter() - began
            honest = single_track_handling(config, result.parameters, covariance, speeds=()).understeer_gradient
            rows[_variant(form, blocks)].append([*np.sqrt(np.diag(covariance))[:3], honest.std])
            if (form, blocks) == (JACKKNIFE_FORM, 8):
                rows["seconds"].append({"fit": fitted, "jackknife": jackknife})
    return rows


def _variant(form: str, blocks: int) -> str:
    return f"after_{form}_{blocks}_blocks"


def scheduled_parts(path: Path, spans: list[tuple[float, float]]) -> dict[str, Any]:
    """Each part's scheduled family (``vehid identify --schedule vx``): understeer gradient at :data:`SPEED`."""
    from vehid.identification.filtering.scheduled_iekf import HOLD_OF, scheduled_simulation_covariance
    from vehid.scenarios.commands.identify import identify_from_args, options_from_args
    from vehid.scenarios.commands.parser import build_parser
    from vehid.vehicle.handling import handling_metrics

    rows: dict[str, Any] = {"values": [], "before": [], "after": [], "one_step": [], "returned": [], "seconds": []}
    for start, end in spans:
        argv = ["identify", str(path), "--inputs", "delta", "--outputs", "yawRate,ayCG", "--schedule", "vx",
                "--segment", f"{start:.6g}:{end:.6g}", "--quiet"]
        args = build_parser(argv).parse_args(argv)
        began = time.perf_counter()
        result = identify_from_args(args, options_from_args(args))  # the command's own call of the library
        plan = result.plan
        rows["seconds"].append(time.perf_counter() - began)
        family = result.scheduled.model
        rows["returned"].append(result.scheduled.summary["model_returned"])
        hold = HOLD_OF[result.estimator.options.discretization]
        formal = scheduled_simulation_covariance(family, plan.records[0], plan.schedule.estimation[0], hold,
                                                 jackknife=False)
        one_step = scheduled_simulation_covariance(family, plan.records[0], plan.schedule.estimation[0], hold,
                                                   form="one-step")
        metrics = {}
        for label, model in (("after", family), ("before", family.with_parameters(family.parameters, formal)),
                             ("one_step", family.with_parameters(family.parameters, one_step))):
            # outputs and steer by position: a family may name its channels y1, y2, u1 (the names in the preparation)
            metrics[label] = handling_metrics(model, [SPEED], yaw_rate=model.output_names[0],
                                              lateral_acceleration=model.output_names[1], steer=model.input_names[0],
                                              wheelbase=LF + LR)[0]
        rows["values"].append(metrics["after"].understeer_gradient_deg_per_g)
        for label in ("before", "after", "one_step"):
            rows[label].append(metrics[label].std["understeer_gradient_deg_per_g"])
    return rows


def judged(values: Any, stds: Any) -> dict[str, Any]:
    """Pairs agreeing within 95 %, the stds' range and the median std over the parts' spread."""
    values, stds = np.asarray(values, dtype=float), np.asarray(stds, dtype=float)
    agreement = pair_agreement(values, stds)
    spread = float(np.std(values, ddof=1))
    return {"stds": stds.tolist(), "agreeing": agreement.agreeing, "pairs": agreement.pairs,
            "median_std_over_spread": float(np.median(stds)) / spread if spread > 0 else float("inf")}


def tables(path: Path, count: int) -> dict[str, Any]:
    spans = parts_of(path, count)
    single = single_track_parts(path, spans)
    values = np.array(single["values"])
    figures: dict[str, Any] = {"log": path.name, "parts": spans, "single_track": {}, "scheduled": {}}
    for index, name in enumerate(QUANTITIES):
        entry = {"values": values[:, index].tolist(), "spread": float(np.std(values[:, index], ddof=1)),
                 "before": judged(values[:, index], np.array(single["before"])[:, index])}
        for variant in VARIANTS:
            entry[_variant(*variant)] = judged(values[:, index], np.array(single[_variant(*variant)])[:, index])
        entry["after"] = entry[_variant(JACKKNIFE_FORM, 8)]
        figures["single_track"][name] = entry
    figures["single_track_seconds"] = single["seconds"]
    scheduled = scheduled_parts(path, spans)
    figures["scheduled"] = {
        f"understeer_gradient_at_{SPEED:g}_m_s": {
            "values": scheduled["values"], "spread": float(np.std(scheduled["values"], ddof=1)),
            "before": judged(scheduled["values"], scheduled["before"]),
            "after": judged(scheduled["values"], scheduled["after"]),
            "after_one-step_8_blocks": judged(scheduled["values"], scheduled["one_step"])},
        "model_returned": scheduled["returned"], "seconds": scheduled["seconds"]}
    return figures


def _print(figures: dict[str, Any]) -> None:
    print(f"\n{figures['log']}: {len(figures['parts'])} parts "
          + ", ".join(f"{a:.6g}-{b:.6g} s" for a, b in figures["parts"]))
    header = (f"{'quantity':<34} {'parts':<40} {'before: std':<22} {'agree':>6} {'ratio':>6}   "
              f"{'after: std':<22} {'agree':>6} {'ratio':>6}")
    print(header)
    rows = [(f"single-track {name}", entry) for name, entry in figures["single_track"].items()]
    rows += [(f"scheduled {name}", entry) for name, entry in figures["scheduled"].items() if name.startswith("under")]
    for label, entry in rows:
        values = ", ".join(f"{v:.4g}" for v in entry["values"])
        cells = []
        for key in ("before", "after"):
            judged_entry = entry[key]
            stds = judged_entry["stds"]
            cells.append(f"{min(stds):.3g}-{max(stds):.3g}".ljust(22) + f" {judged_entry['agreeing']:>2}/"
                         f"{judged_entry['pairs']:<3} {judged_entry['median_std_over_spread']:>6.2f}")
        print(f"{label:<34} {values:<40} {cells[0]}   {cells[1]}")
    print("jackknife variants (pairs agreeing, median std / spread):")
    for name, entry in figures["single_track"].items():
        print(f"  single-track {name:<27} " + "   ".join(
            f"{form} {blocks}: {entry[_variant(form, blocks)]['agreeing']}/{entry[_variant(form, blocks)]['pairs']} "
            f"{entry[_variant(form, blocks)]['median_std_over_spread']:.2f}" for form, blocks in VARIANTS))
    for name, entry in figures["scheduled"].items():
        if name.startswith("under"):
            variant = entry["after_one-step_8_blocks"]
            print(f"  scheduled {name:<30} one-step 8: {variant['agreeing']}/{variant['pairs']} "
                  f"{variant['median_std_over_spread']:.2f}")
    seconds = figures["single_track_seconds"]
    print("single-track seconds per part (fit, jackknife): "
          + ", ".join(f"{s['fit']:.2f} + {s['jackknife']:.2f}" for s in seconds))
    print("scheduled model returned per part: " + ", ".join(figures["scheduled"]["model_returned"])
          + "; seconds " + ", ".join(f"{s:.1f}" for s in figures["scheduled"]["seconds"]))


def main(drive: Path | None = None) -> dict[str, Any]:
    figures: dict[str, Any] = {"race_car_lap": tables(RACE_LOG, 4)}
    _print(figures["race_car_lap"])
    if drive is not None and drive.is_file():
        figures["drive"] = tables(drive, 5)
        _print(figures["drive"])
    elif drive is not None:
        print(f"\n{drive} not found: the committed log alone")
    path = record_figures("segment_consistency", figures)
    print(f"figures in {path}")
    return figures


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else None)
