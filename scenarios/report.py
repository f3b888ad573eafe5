"""Write report figures to disk and tables to markdown.

:func:`write_report` saves each figure as a PNG and all of them, one per
page, in a single PDF. :func:`markdown_table` turns rows of results (a list
of dicts, as in the paper's Table 5) into a markdown table.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from matplotlib.backends.backend_pdf import PdfPages
from matplotlib.figure import Figure

from identification.errors import InputError

__all__ = ["write_report", "markdown_table", "format_cell", "format_eigenvalues"]

_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")


def write_report(
    figures: Mapping[str, Figure],
    out_dir: str | Path,
    *,
    dpi: int = 120,
    pdf_name: str = "report.pdf",
    title: str = "vehid report",
) -> list[Path]:
    """Save every figure as ``<name>.png`` and all of them in one PDF.

    Parameters
    ----------
    figures : mapping of str to Figure
        File stem (letters, digits, ``_.-``) to figure, in page order.
    out_dir : str or Path
        Created if missing.
    dpi : int
        Resolution of the PNGs (the PDF is vector).
    pdf_name : str
        File name of the PDF.
    title : str
        The PDF's title metadata.

    Returns
    -------
    list of Path
        The PNGs in the order given, then the PDF.
    """
    if not figures:
        raise InputError("a report needs at least one figure")
    for name, figure in figures.items():
        if not _SAFE_NAME.fullmatch(name):
            raise InputError(f"figure name {name!r} must be letters, digits, '_', '.', '-' (a file stem)")
        if not isinstance(figure, Figure):
            raise InputError(f"figure {name!r} is a {type(figure).__name__}, not a matplotlib Figure")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, figure in figures.items():
        path = out_dir / f"{name}.png"
        figure.savefig(path, dpi=dpi, format="png")
        paths.append(path)
    pdf_path = out_dir / pdf_name
    with PdfPages(pdf_path, metadata={"Title": title, "Creator": "vehid"}) as pdf:
        for figure in figures.values():
            pdf.savefig(figure)
    paths.append(pdf_path)
    return paths


def format_eigenvalues(values: Any, digits: int = 3) -> str:
    """Eigenvalues as in the paper's Table 5: each conjugate pair once as ``a ± bj``, real ones as ``a``.

    Examples
    --------
    >>> format_eigenvalues([complex(-2.4, 2.5), complex(-2.4, -2.5), -13.0])
    '-2.4 ± 2.5j, -13'
    """
    values = np.asarray(values, dtype=complex).ravel()
    shown = [v for v in values if v.imag >= 0]
    return ", ".join(
        f"{v.real:.{digits}g} ± {v.imag:.{digits}g}j" if v.imag > 0 else f"{v.real:.{digits}g}" for v in shown
    )


def format_cell(value: Any, digits: int = 4) -> str:
    """One table cell: numbers to ``digits`` significant figures, complex sequences as eigenvalues.

    ``None`` and NaN become an empty cell; ``|`` is escaped for markdown.
    """
    if value is None:
        text = ""
    elif isinstance(value, (bool, np.bool_)):
        text = "yes" if value else "no"
    elif isinstance(value, (int, np.integer)):
        text = str(int(value))
    elif isinstance(value, (float, np.floating)):
        text = "" if math.isnan(value) else f"{float(value):.{digits}g}"
    elif isinstance(value, (complex, np.complexfloating)):
        text = format_eigenvalues([value, np.conj(value)], digits)
    elif isinstance(value, (list, tuple, np.ndarray)):
        items = list(np.asarray(value).ravel()) if isinstance(value, np.ndarray) else list(value)
        if items and all(isinstance(v, (complex, np.complexfloating)) for v in items):
            text = format_eigenvalues(items, digits)
        else:
            text = ", ".join(format_cell(v, digits) for v in items)
    else:
        text = str(value)
    return text.replace("|", "\\|").replace("\n", " ")


def markdown_table(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[str] | None = None,
    *,
    headers: Mapping[str, str] | None = None,
    digits: int | Mapping[str, int] = 4,
) -> str:
    """A markdown table from a list of dicts (one row each), e.g. the paper's Table 5.

    Parameters
    ----------
    rows : sequence of mapping
        One dict per row; missing keys give empty cells.
    columns : sequence of str, optional
        Keys to show, in order; default: every key, in order of first appearance.
    headers : mapping of str to str, optional
        Header text per key (default: the key).
    digits : int or mapping of str to int
        Significant figures of numbers, for all columns or per column.

    Returns
    -------
    str
        The table, numeric columns right-aligned, ending in a newline.

    Examples
    --------
    >>> print(markdown_table([{"n": 2, "eigenvalues": [complex(-2.3, 1.7)], "R": 99.60}],
    ...                      headers={"R": "R (%)"}), end="")
    | n | eigenvalues | R (%) |
    | ---: | --- | ---: |
    | 2 | -2.3 ± 1.7j | 99.6 |
    """
    if columns is None:
        columns = list(dict.fromkeys(key for row in rows for key in row))
    if not columns:
        raise InputError("a table needs at least one column")
    headers = dict(headers or {})

    def places(key: str) -> int:
        return digits.get(key, 4) if isinstance(digits, Mapping) else digits

    def numeric(key: str) -> bool:
        cells = [row.get(key) for row in rows if row.get(key) is not None]
        return bool(cells) and all(
            isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))
            for v in cells
        )

    lines = [
        "| " + " | ".join(format_cell(headers.get(key, key)) for key in columns) + " |",
        "| " + " | ".join("---:" if numeric(key) else "---" for key in columns) + " |",
    ]
    for row in rows:
        lines.append("| " + " | ".join(format_cell(row.get(key), places(key)) for key in columns) + " |")
    return "\n".join(lines) + "\n"
