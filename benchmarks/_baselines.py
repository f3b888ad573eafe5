"""The figures a benchmark measured before, kept in the repository, and the check of a new run against them.

``results/`` is not committed, so a benchmark whose figures fall leaves no
trace there. Each benchmark that guards its figures keeps them in
``benchmarks/baselines/NAME.json``: one entry per scored case (a record, a
method and a split; a seed pair, an order and a p), each a list of per-output
fits in percent, so that no output hides behind a mean. A new run compares
every case both runs scored, output by output, and names each output that
lost more than :data:`TOLERANCE` points; the script then exits non-zero.
A case the new run ran and could not score (a failed run) is named too,
and so is an output whose fit is no longer finite; a case it did not run (a
run of some records only) is not compared. After a
deliberate change of figures, ``--update-baseline`` writes the new run's
figures as the baseline, to be committed with the change that moved them.

This module needs only the standard library, so the test suite reads the
committed files with it as the benchmarks do.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

DIRECTORY = Path(__file__).resolve().parent / "baselines"
#: Points of fit any output may lose against the baseline before a run counts as a regression.
TOLERANCE = 1.0

Figures = Mapping[str, Sequence[float | None]]


def path(name: str) -> Path:
    """The committed baseline file of benchmark ``name``."""
    return DIRECTORY / f"{name}.json"


def load(name: str) -> dict[str, Any] | None:
    """The committed baseline of benchmark ``name`` (``figures`` and what they were measured with), or None."""
    try:
        return json.loads(path(name).read_text())
    except FileNotFoundError:
        return None


def save(name: str, figures: Figures, *, about: Mapping[str, Any]) -> Path:
    """Write ``figures`` as benchmark ``name``'s baseline, with ``about`` (settings, what they score)."""
    DIRECTORY.mkdir(exist_ok=True)
    target = path(name)
    content = {**about, "tolerance_points": TOLERANCE,
               "figures": {case: [_rounded(fit) for fit in fits] for case, fits in sorted(figures.items())}}
    target.write_text(json.dumps(content, indent=1) + "\n")
    return target


def _rounded(fit: float | None) -> float | None:
    return None if fit is None or not math.isfinite(fit) else round(float(fit), 2)


def regressions(previous: Figures, current: Figures, tolerance: float = TOLERANCE) -> list[str]:
    """One line per output of a case that lost more than ``tolerance`` points against ``previous``.

    Only the cases both hold are compared: ``previous``'s others were not
    run (a run of some records only), ``current``'s others are new. A case
    run without a score (an empty list: the run failed) or with another
    number of outputs is named, as is an output whose fit was finite and no
    longer is. Figures are compared as stored, to the hundredth of a point.
    """
    lines = []
    for case, before in previous.items():
        if case not in current:
            continue
        after = current[case]
        if len(after) != len(before):
            lines.append(f"{case}: {len(after)} outputs scored, the baseline has {len(before)} ({_shown(before)})")
            continue
        for output, (old, new) in enumerate(zip(before, after), start=1):
            if old is None:
                continue
            new = _rounded(new)
            if new is None:
                lines.append(f"{case}, output {output}: no finite fit (baseline {old:.2f} %)")
            elif new < old - tolerance:
                lines.append(f"{case}, output {output}: {new:.2f} % against {old:.2f} % ({new - old:+.2f} points)")
    return lines


def check(name: str, current: Figures, *, update: bool, about: Mapping[str, Any]) -> list[str]:
    """Compare ``current`` with benchmark ``name``'s baseline and print the outcome; the regressions found.

    With ``update`` (or where no baseline exists yet) ``current`` becomes the
    baseline instead; nothing is then compared.
    """
    baseline = load(name)
    if update or baseline is None:
        written = save(name, current, about=about)
        print(f"baseline written: {written} ({len(current)} cases)")
        return []
    lines = regressions(baseline["figures"], current, baseline.get("tolerance_points", TOLERANCE))
    compared = len(set(baseline["figures"]) & set(current))
    if lines:
        print(f"REGRESSION against {path(name).name}: {len(lines)} output(s) lost more than "
              f"{baseline.get('tolerance_points', TOLERANCE):g} points:")
        for line in lines:
            print(f"   {line}")
    else:
        print(f"no output lost more than {baseline.get('tolerance_points', TOLERANCE):g} points against "
              f"{path(name).name} ({compared} cases compared)")
    return lines


def _shown(fits: Sequence[float | None]) -> str:
    return " / ".join("none" if fit is None else f"{fit:.2f}" for fit in fits)
