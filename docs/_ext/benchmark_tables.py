"""Sphinx extension: the page of measured figures, generated from ``benchmarks.json``.

Every script in ``benchmarks/`` merges its figures into one JSON file, one
section per script, each with ``measured_at`` and ``machine``. A page whose
source holds the line ``.. benchmark-figures::`` gets that line replaced, when
Sphinx reads it, by one heading per section and tables of its figures, so the
documentation shows what was measured without anyone copying numbers into
prose. The file is read from the ``benchmarks_json`` configuration value; a
missing file gives a note saying how to produce it, not a failure, since the
figures are measured per machine and not kept in the repository.

The layout is found from the data, not from a list of known sections:

- a mapping whose values are all mappings of plain values becomes one table,
  a row per key (records, methods, orders);
- a list of mappings of plain values becomes one table, a row per item;
- the plain values of any other mapping become a two-column table, and its
  nested containers follow under their own headings.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

PLACEHOLDER = ".. benchmark-figures::"
_ADORNMENTS = "=-~^\"'"
_PROVENANCE = ("measured_at", "machine")


def _is_plain(value: Any) -> bool:
    """A value shown in one table cell: a number, a string, a flag, or a short list of those."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return True
    if isinstance(value, list):
        return len(value) <= 12 and all(v is None or isinstance(v, (bool, int, float, str)) for v in value)
    return False


def _number_text(value: float) -> str:
    if math.isnan(value):
        return "n/a"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if value != 0.0 and (abs(value) >= 1e6 or abs(value) < 1e-3):
        return f"{value:.3e}"
    # Four significant figures: more than any of these measurements repeats to.
    return f"{value:.4g}"


def cell_text(value: Any) -> str:
    """reStructuredText of one table cell."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return _number_text(value)
    if isinstance(value, list):
        return ", ".join(cell_text(v) for v in value)
    text = str(value).replace("\n", " ").strip()
    if not text:
        return ""
    # Literal text needs no escaping of the characters rst would read as markup.
    return "``" + text.replace("``", "` `") + "``"


def _label(key: str) -> str:
    return key.replace("_", " ")


def _heading(text: str, level: int) -> list[str]:
    mark = _ADORNMENTS[min(level, len(_ADORNMENTS) - 1)]
    return [text, mark * max(len(text), 3), ""]


def _list_table(header: list[str], rows: list[list[str]]) -> list[str]:
    lines = [".. list-table::", "   :header-rows: 1", ""]
    for row in [header, *rows]:
        lines.append("   * - " + (row[0] or " "))
        lines.extend("     - " + (cell or " ") for cell in row[1:])
    return [*lines, ""]


def _is_row_table(value: Any) -> bool:
    if isinstance(value, dict):
        return bool(value) and all(isinstance(v, dict) and v and all(_is_plain(x) for x in v.values())
                                   for v in value.values())
    if isinstance(value, list):
        return bool(value) and all(isinstance(v, dict) and v and all(_is_plain(x) for x in v.values())
                                   for v in value)
    return False


def _columns(rows: list[dict[str, Any]]) -> list[str]:
    columns: list[str] = []
    for row in rows:
        columns.extend(key for key in row if key not in columns)
    return columns


def _row_table(value: Any, first: str) -> list[str]:
    if isinstance(value, dict):
        keys, rows = [str(k) for k in value], list(value.values())
        columns = _columns(rows)
        header = [first, *(_label(c) for c in columns)]
        body = [[cell_text(key), *(cell_text(row.get(c)) for c in columns)] for key, row in zip(keys, rows)]
    else:
        columns = _columns(value)
        header = [_label(c) for c in columns]
        body = [[cell_text(row.get(c)) for c in columns] for row in value]
    return _list_table(header, body)


def render_value(value: Any, title: str, level: int) -> list[str]:
    """reStructuredText of one (nested) figure under a heading of ``level``."""
    lines = _heading(title, level) if title else []
    if _is_row_table(value):
        return [*lines, *_row_table(value, "")]
    if not isinstance(value, dict):
        if _is_plain(value):
            return [*lines, cell_text(value) or "(empty)", ""]
        # A long list of plain values or of containers: one row per item.
        rows = [[str(i), cell_text(v) if _is_plain(v) else cell_text(json.dumps(v))] for i, v in enumerate(value)]
        return [*lines, *_list_table(["item", "value"], rows)]
    plain = {k: v for k, v in value.items() if _is_plain(v) and k not in _PROVENANCE}
    nested = {k: v for k, v in value.items() if not _is_plain(v) and k not in _PROVENANCE}
    if plain:
        lines += _list_table(["figure", "value"], [[cell_text(k), cell_text(v)] for k, v in plain.items()])
    for key, inner in nested.items():
        lines += render_value(inner, _label(str(key)), level + 1)
    return lines


def provenance(section: dict[str, Any]) -> str:
    """One sentence saying when and on what the section was measured."""
    parts = []
    when = section.get("measured_at")
    if when:
        parts.append(f"Measured {when}")
    machine = section.get("machine")
    if isinstance(machine, dict):
        described = ", ".join(f"{_label(str(k))} {v}" for k, v in machine.items())
        parts.append(f"on a machine with {described}" if parts else f"Machine: {described}")
    return (" ".join(parts) + ".") if parts else ""


def render_figures(figures: dict[str, Any], source_name: str) -> list[str]:
    """The generated part of the page: one heading per section of the figures file."""
    if not figures:
        return [f"The figures file ``{source_name}`` holds no sections yet.", ""]
    count = f"{len(figures)} section" + ("" if len(figures) == 1 else "s")
    lines = [f"Generated from ``{source_name}`` ({count}).", ""]
    for name in sorted(figures):
        section = figures[name]
        lines += _heading(_label(name), 0)
        if isinstance(section, dict):
            sentence = provenance(section)
            if sentence:
                lines += [sentence.replace("*", r"\*"), ""]
        lines += render_value(section, "", 0)
    return lines


def _display_name(path: Path, root: Path) -> str:
    # Pages show the file relative to the repository, never a machine's own folders.
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return path.name


def _substitute(app: Any, docname: str, source: list[str]) -> None:
    text = source[0]
    if PLACEHOLDER not in text:
        return
    path = Path(app.config.benchmarks_json)
    name = _display_name(path, Path(app.confdir).parent)
    # Noted even while missing: Sphinx then reads this page again at every build,
    # until the file appears, and after that whenever it changes.
    app.env.note_dependency(str(path))
    if path.exists():
        try:
            figures = json.loads(path.read_text())
        except json.JSONDecodeError as error:
            raise ValueError(f"{name} is not valid JSON: {error}") from error
        if not isinstance(figures, dict):
            raise ValueError(f"{name} must hold one JSON object of sections, found {type(figures).__name__}")
        generated = render_figures(figures, name)
    else:
        generated = [
            f"No figures file here yet (``{name}``): ``make bench`` runs every script in ``benchmarks/``, "
            "each of which measures on this machine and adds its section to the file.",
            "",
        ]
    source[0] = text.replace(PLACEHOLDER, "\n".join(generated))


def setup(app: Any) -> dict[str, Any]:
    app.add_config_value("benchmarks_json", "", "env")
    app.connect("source-read", _substitute)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
