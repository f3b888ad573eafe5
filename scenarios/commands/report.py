"""Draw the figures and the summary table of a results archive.

Every model is scored as the identify command that wrote the archive scored
it (same initial-state rule, NRMSE fit beside R), and the command's verdict
(its scores and warnings, kept in the archive) heads summary.md and the text.

Draws whatever the archive (layout: results/RESULTS_LAYOUT.md) holds: parameter
development and convergence per run, the order study, eigenvalues, Bode plots,
time fits and residual tests per record. Writes the PNGs, a PDF and summary.md
to a folder that is absent, empty or an earlier report of the workbench (marked
by a hidden file listing the report's own files); any other folder is refused
unless --force, and even then only the report's own files are added or
replaced, never anything else deleted. An interrupted report leaves the
previous one.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from vehid.identification.errors import InputError
from vehid.scenarios.paths import OUT_RULE, results_path

NAME = "report"
GROUP = None
HELP = "draw the figures and summary table of a results archive"


def register(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("archive", help="an HDF5 results archive")
    parser.add_argument("--out", default=None,
                        help=f"output folder ({OUT_RULE}; default: <archive name>-report under the results folder)")
    parser.add_argument("--force", action="store_true",
                        help="write into a folder that is not an earlier report (its other files are kept)")
    parser.add_argument("--window", type=float, nargs=2, metavar=("T0", "T1"), default=None,
                        help="time range in seconds shown in the time-fit figures (default: all)")
    parser.add_argument("--max-lag", type=int, default=50,
                        help="largest lag of the residual autocorrelation, in samples (default 50)")
    parser.add_argument("--dpi", type=int, default=120, help="resolution of the PNGs (default 120)")
    parser.set_defaults(handler=run)


def run(args: argparse.Namespace) -> tuple[dict, str]:
    # matplotlib and h5py when the command runs, not when its --help is asked for
    from vehid.identification.dataio.archive import read_archive
    from vehid.identification.dataio.archive_safety import check_report_folder, writing_report_folder
    from vehid.scenarios.report import (archive_figures, archive_table, archive_verdict, markdown_table, verdict_lines,
                                        verdict_output_names, verdict_page, write_report)

    if args.max_lag < 1:
        raise InputError(f"--max-lag must be at least 1; got {args.max_lag}")
    if not 20 <= args.dpi <= 600:
        raise InputError(f"--dpi must lie in 20..600; got {args.dpi}")
    if args.window is not None and not (all(map(math.isfinite, args.window)) and args.window[0] < args.window[1]):
        raise InputError(f"--window needs two finite times T0 < T1; got {args.window}")
    path = Path(args.archive)
    archive = read_archive(path)
    folder = results_path(args.out, f"{path.stem}-report")
    check_report_folder(folder, force=args.force)  # before drawing: a file in its place, a folder of other files
    if archive.kind == "handling-study":
        from vehid.scenarios.handling_report import write_handling_report

        with writing_report_folder(folder, force=args.force) as partial:
            files = [folder / f.relative_to(partial) for f in write_handling_report(archive, partial)]
        summary = {"archive": str(path), "kind": archive.kind, "out": str(folder), "files": [str(f) for f in files]}
        return summary, f"{path.name} (handling study): wrote {len(files)} files to {folder}"
    figures = archive_figures(archive, window=tuple(args.window) if args.window else None, max_lag=args.max_lag)
    if not figures:
        raise InputError(f"nothing to draw in {path}: it holds no records and no runs with histories or models")
    rows = archive_table(archive)
    verdict = archive_verdict(archive)
    stated = verdict_lines(verdict, verdict_output_names(archive, verdict)) if verdict is not None else []
    if stated:  # the command's verdict is the report's first page
        figures = {"verdict": verdict_page(stated), **figures}
    with writing_report_folder(folder, force=args.force) as partial:
        files = write_report(figures, partial, dpi=args.dpi, title=f"vehid report: {path.name}")
        if rows or stated:
            table = partial / "summary.md"
            verdict_text = ("## Verdict of the identify command\n\n" + "".join(f"- {line}\n" for line in stated) + "\n"
                            if stated else "")
            table.write_text(f"# {path.name}: {archive.kind}\n\n" + verdict_text
                             + (markdown_table(rows) if rows else ""))
            files.append(table)
    files = [folder / file.relative_to(partial) for file in files]
    summary = {
        "archive": str(path),
        "kind": archive.kind,
        "schema_version": archive.schema_version,
        "records": sorted(archive.records),
        "runs": sorted(archive.runs),
        "figures": list(figures),
        "files": [str(file) for file in files],
    }
    if verdict is not None:  # the command's own scores and warnings, as it stated them
        summary["verdict"] = {key: verdict.get(key) for key in VERDICT_KEYS}
        summary["verdict"]["returned_run"] = (verdict.get("scoring_rule") or {}).get("returned_run")
    lines = [
        f"{path.name} ({archive.kind}): {len(archive.records)} record(s), {len(archive.runs)} run(s)",
        f"wrote {len(figures)} figures ({', '.join(figures)}) to {folder}",
        *stated,
    ]
    if rows:
        lines.append(markdown_table(rows).rstrip("\n"))
    return summary, "\n".join(lines)


VERDICT_KEYS = ("method", "order", "passes_run", "stop_reason", "estimation_fit_percent", "estimation_R",
                "validation_fit_percent", "validation_R", "initial_state", "horizon", "warnings", "notes")
