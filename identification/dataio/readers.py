"""Readers of measurement files: tolerant CSV, whitespace tables, MATLAB .mat, ASAM MDF4.

Every reader returns a :class:`RawRecord`: the chosen channels as they are in the file, each with the
time it was sampled at (none when time comes from ``dt``), and a way to name a sample's place ("line
57", "sample 57") for error messages; :mod:`vehid.identification.dataio.timebase` makes it uniformly sampled. The
files and channel names accepted are in docs/measured_data.md ("Files"). Text tables are parsed by
NumPy's C reader; on any irregularity a careful line-by-line pass reads the file again and either
parses it or names the column and line at fault.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..errors import InputError, OptionError

__all__ = ["RawRecord", "TEXT_SUFFIXES", "MAT_SUFFIXES", "MDF_SUFFIXES", "read_raw", "read_table",
           "read_mat", "read_mdf", "expand_channels"]

TEXT_SUFFIXES = (".csv", ".dat", ".txt")
MAT_SUFFIXES = (".mat",)
MDF_SUFFIXES = (".mf4", ".mdf")
_COMMENTS = ("#", "%", "//")
_NONE = ("none", "")  # a time column given as one of these is disabled


@dataclass(frozen=True, eq=False)
class RawRecord:
    """Chosen channels as read from a file, before any time-base handling.

    Attributes
    ----------
    source : str
        The file's name (for messages and metadata).
    names : tuple of str
        Channel names, in the order asked for.
    values : tuple of ndarray
        One 1-D float array per channel.
    times : tuple of (ndarray or None)
        The time of each channel's samples in seconds; ``None`` where the
        record has no time and ``dt`` must give it. Text and MATLAB files share
        one array among all channels; MDF channels each have their own.
    units : tuple of str
        Each channel's unit as the file states it; ``"-"`` where it does not.
    time_name : str or None
        The column or channel the time came from.
    locate : callable
        ``locate(channel_index, sample_index) -> str``, e.g. ``"line 57"``.
    time_unit : str or None
        The time column's unit as the file states it (units row or header
        cell, ``t(ms)``); None where the file does not say.
    """

    source: str
    names: tuple[str, ...]
    values: tuple[np.ndarray, ...]
    times: tuple[np.ndarray | None, ...]
    units: tuple[str, ...]
    time_name: str | None = None
    locate: Callable[[int, int], str] = field(default=lambda channel, k: f"sample {k + 1}")
    time_unit: str | None = None

    @property
    def shares_time(self) -> bool:
        """True when every channel has the same sample times (one array, or none)."""
        first = self.times[0]
        return all(t is first or (t is not None and first is not None and t.shape == first.shape
                                  and np.array_equal(t, first)) for t in self.times)


def _is_time_disabled(time_column: str | None) -> bool:
    return time_column is not None and time_column.strip().lower() in _NONE


def _check_dt(dt: float | None) -> None:
    if dt is not None and not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise OptionError(f"'dt' must be a positive number; got {dt!r}", "dt")


def _dt_conflict(path: Path, time_name: str) -> InputError:
    return OptionError(
        f"{path.name} has a time column {time_name!r}: 'dt' would override it; drop 'dt', "
        "or disable the time column with 'time_column' none", "dt", "time_column"
    )


_DECIMAL_COMMA = re.compile(r"^[+-]?[0-9]*,[0-9]+([eE][+-]?[0-9]+)?$")


def _float(cell: str, decimal_comma: bool = False) -> float | None:
    try:
        return float(cell.replace(",", ".") if decimal_comma else cell)
    except ValueError:
        return None


_SNIFF_BYTES = 65536  # the head of a file judged for being text: a header and many rows, read at once
# Leading bytes of formats that are saved under a text suffix by mistake, and what to do instead.
_SIGNATURES = (
    (b"\x89HDF\r\n\x1a\n", "it is an HDF5 file: give it the suffix .h5"),
    (b"PK\x03\x04", "it is a ZIP archive (an .xlsx workbook?): export the sheet as CSV"),
    (b"MATLAB", "it is a MATLAB file: give it the suffix .mat"),
    (b"\xd0\xcf\x11\xe0", "it is an old Office file (an .xls workbook?): export the sheet as CSV"),
    (b"%PDF", "it is a PDF document"),
)
_UTF16_MARKS = (b"\xff\xfe", b"\xfe\xff")
# Text never holds control characters other than tab, line feed, vertical tab, form feed and carriage return;
# in a table they are typos at most. A head with more than this share of them is not text.
_CONTROL_SHARE = 0.01
_CONTROL_BYTES = bytes(b for b in range(32) if b not in (9, 10, 11, 12, 13)) + b"\x7f"


def _not_text(path: Path) -> str | None:
    """Why the file cannot be a text table (from its first bytes), or None when it may be one."""
    with path.open("rb") as handle:
        head = handle.read(_SNIFF_BYTES)
    for signature, reason in _SIGNATURES:
        if head.startswith(signature):
            return reason
    if head.startswith(_UTF16_MARKS):
        return None
    controls = len(head) - len(head.translate(None, _CONTROL_BYTES))
    if b"\x00" in head or controls > _CONTROL_SHARE * len(head):
        return (f"it holds binary data ({controls} control bytes in its first {len(head)} bytes), "
                "not rows of numbers")
    return None


def _text_lines(path: Path) -> tuple[list[str], str]:
    """The file's first lines (enough to find its header) and the encoding that reads it."""
    reason = _not_text(path)
    if reason is not None:
        raise InputError(f"{path.name} is not a text table: {reason}")
    with path.open("rb") as handle:
        utf16 = handle.read(2) in _UTF16_MARKS  # "Unicode text" as spreadsheets save it
    for encoding in ("utf-16",) if utf16 else ("utf-8-sig", "latin-1"):
        try:
            with path.open(encoding=encoding, newline="") as handle:
                head = [line for _, line in zip(range(200), handle)]
            return head, encoding
        except UnicodeDecodeError:
            continue
    raise InputError(f"{path.name} is not a text table: it is not valid UTF-16 text")


def _split(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return [cell.strip('"\'') for cell in line.split()]
    return [cell.strip().strip('"\'').strip() for cell in next(csv.reader([line], delimiter=delimiter))]


def _is_comment(line: str) -> bool:
    return line.lstrip().startswith(_COMMENTS)


def _delimiter(first: str, suffix: str) -> str | None:
    counts = {d: first.count(d) for d in (",", ";", "\t")}
    best = max(counts, key=counts.get)
    if counts[best]:
        return best
    return "," if suffix == ".csv" and not first.split()[1:] else None


@dataclass(frozen=True)
class _Layout:
    delimiter: str | None
    header: tuple[str, ...] | None
    units: tuple[str, ...] | None
    skip: int  # lines before the first data line
    encoding: str
    decimal_comma: bool = False  # "0,5": files written with a European locale (then ';' or tabs separate)


def _uncommented(line: str) -> str:
    text = line.strip()
    marker = next(m for m in _COMMENTS if text.startswith(m))
    return text[len(marker):].strip()


def _comment_header(head: list[str], index: int, delimiter: str | None, width: int, comma: bool
                    ) -> tuple[str, ...] | None:
    """The header a logger wrote as the comment line just above the data (``# t(s),x(m)``, as NumPy's
    ``savetxt`` does), when that line splits into as many cells as a data row and is not all numbers."""
    above = index - 1
    while above >= 0 and not head[above].strip():
        above -= 1
    if above < 0 or not _is_comment(head[above]):
        return None
    cells = _split(_uncommented(head[above]), delimiter)
    while cells and not cells[-1]:  # a trailing delimiter on the header line, or on the data rows, is no column
        cells.pop()
    if len(cells) != width or all(_float(cell, comma) is not None for cell in cells if cell):
        return None
    return tuple(cells)


def _layout(path: Path) -> _Layout:
    head, encoding = _text_lines(path)
    index = 0
    while index < len(head) and (not head[index].strip() or _is_comment(head[index])):
        index += 1
    if index == len(head):
        raise InputError(f"{path.name} holds no data rows")
    first = head[index].rstrip("\r\n")
    delimiter = _delimiter(first, path.suffix.lower())
    cells = _split(first, delimiter)
    nearby = [c for line in head[index: index + 3] for c in _split(line.rstrip("\r\n"), delimiter)]
    comma = delimiter != "," and any(_DECIMAL_COMMA.match(c) for c in nearby)
    if all(_float(cell, comma) is not None for cell in cells if cell):
        width = len(cells)
        while width and not cells[width - 1]:
            width -= 1
        header = _comment_header(head, index, delimiter, width, comma)
        return _Layout(delimiter, header, None, index, encoding, comma)
    header = tuple(cells)
    if index + 1 < len(head):
        second = [c for c in _split(head[index + 1].rstrip("\r\n"), delimiter)]
        if any(second) and all(_float(c, comma) is None for c in second if c):
            return _Layout(delimiter, header, tuple(second), index + 2, encoding, comma)
    return _Layout(delimiter, header, None, index + 1, encoding, comma)


_UNIT_SUFFIX = re.compile(r"^(?P<name>.*?)\s*(?:\((?P<paren>[^()]*)\)|\[(?P<bracket>[^\[\]]*)\])$")


def _name_and_unit(cell: str) -> tuple[str, str | None]:
    """A header cell ``yaw_rate(rad/s)`` or ``yaw_rate [rad/s]`` as its name and unit; other cells have no unit."""
    found = _UNIT_SUFFIX.match(cell.strip())
    if found is None or not found["name"]:
        return cell.strip(), None
    unit = found["paren"] if found["paren"] is not None else found["bracket"]
    return found["name"], unit.strip()


def _has_column(header: tuple[str, ...], name: str) -> bool:
    return name in header or any(_name_and_unit(column)[0] == name for column in header)


#: Names a time column goes by without --time-column (compared in lower case, without the unit:
#: ``t``, ``t(s)``, ``t [s]``, ``Time``, ``time(ms)``), in order of preference.
TIME_COLUMN_NAMES = ("t", "time")


def _default_time_column(path: Path, header: tuple[str, ...] | None) -> str | None:
    """The header cell that is the time column by its name (:data:`TIME_COLUMN_NAMES`), or None.

    ``t`` (or ``t(s)``) is taken as it always was; otherwise a single cell named ``time`` in any case,
    with or without its unit. Two such cells are an error naming them: --time-column chooses.
    """
    if header is None:
        return None
    if _has_column(header, "t"):
        return "t"
    for name in TIME_COLUMN_NAMES[1:]:
        found = [cell for cell in header if _name_and_unit(cell)[0].strip().lower() == name]
        if len(found) > 1:
            raise OptionError(f"{path.name} has {len(found)} time columns ({', '.join(found)}): choose one with "
                              "'time_column' NAME", "time_column")
        if found:
            return found[0]
    return None


def _column_index(path: Path, header: tuple[str, ...] | None, name: str, kind: str) -> int:
    if header is not None:
        places = [i for i, column in enumerate(header) if column == name]
        if not places:  # a header cell with its unit, "t(s)", is named by "t" as well
            places = [i for i, column in enumerate(header) if _name_and_unit(column)[0] == name]
        if len(places) > 1:
            raise InputError(
                f"column name {name!r} appears {len(places)} times in {path.name} "
                f"(columns {', '.join(str(p + 1) for p in places)}): rename the duplicates"
            )
        if places:
            return places[0]
    if re.fullmatch(r"[1-9][0-9]*", name):
        return int(name) - 1
    if header is None:
        raise InputError(f"{path.name} has no header row: choose {kind} columns by number (1, 2, ...); got {name!r}")
    listed = ", ".join(h for h in header if h)
    raise InputError(f"unknown column {name!r} in {path.name}; columns: {listed}")


def _careful_parse(path: Path, layout: _Layout, columns: list[int], names: list[str]) -> tuple[np.ndarray, list[int]]:
    """Parse line by line: the values of the chosen columns and each row's line number, or a precise error."""
    rows: list[list[float]] = []
    lines: list[int] = []
    widest = max(columns)
    with path.open(encoding=layout.encoding, newline="") as handle:
        for number, line in enumerate(handle, start=1):
            if number <= layout.skip or not line.strip() or _is_comment(line):
                continue
            cells = _split(line.rstrip("\r\n"), layout.delimiter)
            if len(cells) <= widest:
                missing = next(n for c, n in zip(columns, names) if c >= len(cells))
                raise InputError(
                    f"{path.name}: line {number} has {len(cells)} values; every row must reach column "
                    f"{missing!r} (column {columns[names.index(missing)] + 1})"
                )
            row = []
            for column, name in zip(columns, names):
                value = _float(cells[column], layout.decimal_comma)
                if value is None:
                    shown = repr(cells[column]) if cells[column] else "a blank cell"
                    raise InputError(f"{path.name}: column {name!r} holds {shown} at line {number}, not a number")
                row.append(value)
            rows.append(row)
            lines.append(number)
    if not rows:
        raise InputError(f"{path.name} holds no data rows")
    return np.array(rows, dtype=float), lines


def _line_locator(path: Path, layout: _Layout, lines: list[int] | None) -> Callable[[int, int], str]:
    """Sample index -> "line L"; the line numbers are found by a scan only when a message needs them."""
    known: dict[str, list[int]] = {} if lines is None else {"lines": lines}

    def locate(channel: int, k: int) -> str:
        if "lines" not in known:
            found = []
            with path.open(encoding=layout.encoding, newline="") as handle:
                for number, line in enumerate(handle, start=1):
                    if number > layout.skip and line.strip() and not _is_comment(line):
                        found.append(number)
            known["lines"] = found
        numbers = known["lines"]
        return f"line {numbers[k]}" if 0 <= k < len(numbers) else f"sample {k + 1}"

    return locate


def read_table(
    path: str | Path,
    *,
    channels: Sequence[str],
    time_column: str | None = None,
    dt: float | None = None,
) -> RawRecord:
    """Read chosen columns of a CSV or whitespace-separated text table.

    Parameters
    ----------
    path : str or Path
        The ``.csv``, ``.dat`` or ``.txt`` file.
    channels : sequence of str
        Column names (or 1-based numbers) to read, inputs then outputs.
    time_column : str, optional
        The time column; default ``t`` when the header has one. ``"none"``
        disables it (then ``dt`` gives the time).
    dt : float, optional
        Sample interval in seconds, for a table without a time column. Given
        together with a time column it is an error, never a silent override.

    Returns
    -------
    RawRecord
        The columns as floats, with the time column's values and the units the file states.

    Examples
    --------
    A step of steer in a small table with a time column and a units row:

    >>> import pathlib, tempfile
    >>> from vehid.identification import read_table
    >>> table = "t,steer,yaw_rate\\ns,rad,rad/s\\n0.00,0.0,0.000\\n0.01,0.1,0.020\\n0.02,0.1,0.035\\n"
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "step.csv"
    ...     _ = path.write_text(table)
    ...     raw = read_table(path, channels=["steer", "yaw_rate"])
    >>> raw.names, raw.units, raw.time_name
    (('steer', 'yaw_rate'), ('rad', 'rad/s'), 't')
    >>> raw.values[1]
    array([0.   , 0.02 , 0.035])
    """
    path = _existing(path)
    _check_dt(dt)
    layout = _layout(path)
    names = [str(name).strip() for name in channels]
    indices = [_column_index(path, layout.header, name, "data") for name in names]
    time_name = _time_name(path, _default_time_column(path, layout.header) if time_column is None else None,
                           time_column, dt)
    read_names = list(names)
    if time_name is not None:
        indices.append(_column_index(path, layout.header, time_name, "time"))
        read_names.append(time_name)
    quoting = {"quotechar": '"'} if layout.delimiter is not None else {}
    if layout.decimal_comma:  # NumPy's reader knows only the decimal point: each cell converted in Python
        quoting["converters"] = lambda cell: float(cell.replace(",", "."))
    lines = None
    try:
        table = np.loadtxt(path, delimiter=layout.delimiter, skiprows=layout.skip, usecols=indices, ndmin=2,
                           comments="#", encoding=layout.encoding, dtype=float, **quoting)
        if table.shape[0] == 0:
            raise InputError(f"{path.name} holds no data rows")
    except ValueError as exc:
        if isinstance(exc, InputError):
            raise
        table, lines = _careful_parse(path, layout, indices, read_names)
    locate = _line_locator(path, layout, lines)
    bad = ~np.isfinite(table)
    if bad.any():
        row, column = (int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"{path.name}: column {read_names[column]!r} holds a non-finite value "
                         f"({table[row, column]}) at {locate(column, row)}")
    # columns stay views of the parsed table: a copy per column of a long file is memory for nothing
    t = table[:, -1] if time_name is not None else None
    units = tuple(_unit(layout, i) for i in indices[: len(names)])
    return RawRecord(
        source=path.name,
        names=tuple(names),
        values=tuple(table[:, i] for i in range(len(names))),
        times=(t,) * len(names),
        units=units,
        time_name=time_name,
        locate=locate,
        time_unit=_unit(layout, indices[-1]) if time_name is not None else None,
    )


def _unit(layout: _Layout, column: int) -> str:
    """A column's unit: from the units row, else from its header cell (``ay(m/s^2)``), else ``-``."""
    if layout.units and column < len(layout.units) and layout.units[column]:
        return layout.units[column]
    if layout.header and column < len(layout.header):
        unit = _name_and_unit(layout.header[column])[1]
        if unit:
            return unit
    return "-"


def _time_name(path: Path, found: str | None, time_column: str | None, dt: float | None, kind: str = "column"
               ) -> str | None:
    """The time column in use: given, or the one ``found`` by its name (``t``, ``time(s)``); None when
    disabled or absent."""
    if _is_time_disabled(time_column):
        if dt is None:
            raise OptionError(f"the time {kind} of {path.name} is disabled ('time_column' none): give 'dt'",
                              "time_column", "dt")
        return None
    if time_column is not None:
        if dt is not None:
            raise _dt_conflict(path, time_column)
        return time_column.strip()
    if found is not None:
        if dt is not None:
            raise _dt_conflict(path, found)
        return found
    if dt is None:
        raise OptionError(f"{path.name} has no time {kind} 't' or 'time': name one with 'time_column' NAME, "
                          "or give 'dt'", "time_column", "dt")
    return None


def _check_finite(path: Path, kind: str, names: Sequence[str], values: Sequence[np.ndarray]) -> None:
    for name, value in zip(names, values):
        if not np.all(np.isfinite(value)):
            k = int(np.flatnonzero(~np.isfinite(value))[0])
            raise InputError(f"{path.name}: {kind} {name!r} holds a non-finite value at sample {k + 1}")


def _existing(path: str | Path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such data file: {path}")
    return path


def _mat_variables(path: Path) -> tuple[Callable[[str], Any], list[str]]:
    """A lookup ``name -> array`` for a .mat file (v4-v7 by scipy.io, v7.3 by h5py) and its variable names."""
    import scipy.io

    try:
        contents = scipy.io.loadmat(path, simplify_cells=True)
    except NotImplementedError:
        return _mat73_variables(path)
    except (ValueError, TypeError, OSError) as exc:
        raise InputError(f"{path.name} is not a readable MATLAB .mat file ({exc})") from None
    contents = {k: v for k, v in contents.items() if not k.startswith("__")}

    def lookup(name: str) -> Any:
        value: Any = contents
        for part in name.split("."):
            if not isinstance(value, dict) or part not in value:
                return None
            value = value[part]
        return value

    return lookup, sorted(contents)


def _mat73_variables(path: Path) -> tuple[Callable[[str], Any], list[str]]:
    """MATLAB v7.3 files are HDF5; arrays are stored column-major, so each is transposed back."""
    import h5py

    with h5py.File(path, "r") as handle:
        names = sorted(k for k in handle.keys() if not k.startswith("#"))

    def lookup(name: str) -> Any:
        with h5py.File(path, "r") as handle:
            key = name.replace(".", "/")
            if key not in handle or not isinstance(handle[key], h5py.Dataset):
                return None
            dataset = handle[key]
            if dataset.dtype.kind not in "biuf":
                return dataset.dtype.str
            return np.asarray(dataset[()]).T

    return lookup, names


def _mat_matrix_columns(lookup: Callable[[str], Any], name: str) -> int | None:
    """The number of columns of variable ``name`` when it is a matrix (time along its longer side), else None."""
    value = lookup(name)
    if value is None:
        return None
    try:
        shape = np.shape(np.asarray(value, dtype=float))
    except (TypeError, ValueError):
        return None
    if len(shape) != 2 or min(shape) < 2:
        return None
    return min(shape) if shape[0] != shape[1] else shape[1]


def expand_channels(path: str | Path, names: Sequence[str]) -> tuple[str, ...]:
    """The channels that ``names`` stand for: a MATLAB matrix named without a column is all of its columns.

    ``y`` of an N x 2 matrix becomes ``y:1, y:2``, as ``iddata`` users name
    the outputs of a record; every other name (and every name of a file that
    is not a ``.mat`` file) stands for itself.
    """
    path = Path(path)
    names = [str(name).strip() for name in names]
    if path.suffix.lower() not in MAT_SUFFIXES or not path.is_file() or all(":" in name for name in names):
        return tuple(names)
    lookup, _ = _mat_variables(path)
    expanded: list[str] = []
    for name in names:
        columns = None if ":" in name else _mat_matrix_columns(lookup, name)
        expanded += [name] if columns is None else [f"{name}:{k}" for k in range(1, columns + 1)]
    return tuple(expanded)


def _mat_column(path: Path, lookup: Callable[[str], Any], spec: str, available: list[str]) -> np.ndarray:
    name, _, column = spec.partition(":")
    value = lookup(name)
    if value is None:
        raise InputError(f"unknown variable {name!r} in {path.name}; variables: {', '.join(available)}")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"variable {name!r} in {path.name} is not numeric") from None
    if array.ndim == 2 and 1 in array.shape:
        array = array.ravel()
    if array.ndim == 1:
        if column not in ("", "1"):
            raise InputError(f"variable {name!r} in {path.name} is a vector: it has no column {column}")
        return array
    if array.ndim != 2:
        raise InputError(f"variable {name!r} in {path.name} has shape {array.shape}: give a vector or a matrix")
    if array.shape[0] < array.shape[1]:
        array = array.T  # time runs along the longer side
    if not re.fullmatch(r"[1-9][0-9]*", column or ""):
        raise InputError(
            f"variable {name!r} in {path.name} is a {array.shape[0]}x{array.shape[1]} matrix: choose a column "
            f"as {name}:1 ... {name}:{array.shape[1]}"
        )
    if int(column) > array.shape[1]:
        raise InputError(f"variable {name!r} in {path.name} has {array.shape[1]} columns; asked for column {column}")
    return np.ascontiguousarray(array[:, int(column) - 1])


def read_mat(
    path: str | Path,
    *,
    channels: Sequence[str],
    time_column: str | None = None,
    dt: float | None = None,
) -> RawRecord:
    """Read variables or struct fields of a MATLAB ``.mat`` file.

    Parameters
    ----------
    path : str or Path
        The ``.mat`` file (MATLAB 5 to 7.3).
    channels : sequence of str
        ``name`` (a vector), ``struct.field`` or ``name:K`` (column K of a
        matrix whose longer side is time).
    time_column : str, optional
        The time variable; default ``t`` when the file has one; ``"none"`` disables it.
    dt : float, optional
        Sample interval when there is no time variable.

    Returns
    -------
    RawRecord
        The variables as float vectors, one shared time array (or None).
    """
    path = _existing(path)
    _check_dt(dt)
    lookup, available = _mat_variables(path)
    names = [str(name).strip() for name in channels]
    values = [_mat_column(path, lookup, name, available) for name in names]
    found = next((name for name in TIME_COLUMN_NAMES if lookup(name) is not None), None)
    time_name = _time_name(path, found if time_column is None else None, time_column, dt, kind="variable")
    t = _mat_column(path, lookup, time_name, available) if time_name is not None else None
    lengths = {v.size for v in values} | ({t.size} if t is not None else set())
    if len(lengths) > 1:
        sizes = ", ".join(f"{n} {v.size}" for n, v in zip(names, values))
        raise InputError(f"the chosen variables of {path.name} differ in length ({sizes}"
                         + (f", {time_name} {t.size}" if t is not None else "") + ")")
    _check_finite(path, "variable", names + ([time_name] if t is not None else []),
                  values + ([t] if t is not None else []))
    return RawRecord(path.name, tuple(names), tuple(values), (t,) * len(names), ("-",) * len(names), time_name)


def read_mdf(
    path: str | Path,
    *,
    channels: Sequence[str],
    time_column: str | None = None,
    dt: float | None = None,
) -> RawRecord:
    """Read channels of an ASAM MDF4 (``.mf4``) file by name, each with its own time stamps.

    Needs the optional extra ``mdf`` (``pip install vehid[mdf]``, asammdf).
    Channels at different rates are brought onto one time base by
    :func:`vehid.identification.dataio.timebase.uniform_record`.

    Parameters
    ----------
    path : str or Path
        The MDF file.
    channels : sequence of str
        Channel names, each occurring once in the file.
    time_column : str, optional
        Must be None or ``"none"``: every channel carries its own time stamps.
    dt : float, optional
        Must be None, for the same reason.

    Returns
    -------
    RawRecord
        The channels with their own time stamps and units.
    """
    path = _existing(path)
    if dt is not None:
        raise OptionError(f"{path.name} is an MDF file and carries its own time stamps: 'dt' does not apply "
                          "(use 'resample' HZ for another rate)", "dt", "resample")
    if time_column is not None and not _is_time_disabled(time_column):
        raise OptionError(f"{path.name} is an MDF file: each channel carries its own time stamps, "
                          "'time_column' does not apply", "time_column")
    try:
        from asammdf import MDF
    except ImportError:
        raise InputError("reading MDF4 files needs asammdf: pip install vehid[mdf]") from None
    try:
        mdf = MDF(path)
    except Exception as exc:  # asammdf raises many kinds on foreign files
        raise InputError(f"{path.name} is not a readable MDF file ({type(exc).__name__}: {exc})") from None
    try:
        names = [str(name).strip() for name in channels]
        values, times, units = [], [], []
        for name in names:
            places = mdf.channels_db.get(name, ())
            if not places:
                known = sorted(k for k in mdf.channels_db if k and not k.startswith("$") and k not in ("time", "t"))
                raise InputError(f"unknown channel {name!r} in {path.name}; channels: {', '.join(known[:30])}"
                                 + (" ..." if len(known) > 30 else ""))
            if len(places) > 1:
                raise InputError(f"channel {name!r} occurs {len(places)} times in {path.name} "
                                 f"(groups {', '.join(str(g) for g, _ in places)}): the name is ambiguous")
            group, index = places[0]
            signal = mdf.get(name, group=group, index=index)
            samples = np.asarray(signal.samples)
            if samples.dtype.kind not in "biuf" or samples.ndim != 1:
                raise InputError(f"channel {name!r} in {path.name} is not a numeric scalar signal")
            values.append(np.asarray(samples, dtype=float))
            times.append(np.asarray(signal.timestamps, dtype=float))
            units.append(str(signal.unit) or "-")
    finally:
        mdf.close()
    _check_finite(path, "channel", names, values)
    return RawRecord(path.name, tuple(names), tuple(values), tuple(times), tuple(units), "time stamps")


def _is_mdf(path: Path) -> bool:
    """An ASAM MDF file by its identification block ("MDF     " or "UnFinMF ")."""
    try:
        with path.open("rb") as handle:
            return handle.read(8) in (b"MDF     ", b"UnFinMF ")
    except OSError:
        return False


def read_raw(
    path: str | Path,
    *,
    channels: Sequence[str],
    time_column: str | None = None,
    dt: float | None = None,
) -> RawRecord:
    """Read the chosen channels of a measurement file; the reader is chosen by the file's suffix.

    ``.csv``, ``.dat``, ``.txt``: :func:`read_table` (a ``.dat`` that is an
    MDF file by its first bytes, as MDF3 loggers write them: :func:`read_mdf`);
    ``.mat``: :func:`read_mat`; ``.mf4``, ``.mdf``: :func:`read_mdf`.

    Parameters
    ----------
    path : str or Path
        The measurement file.
    channels : sequence of str
        The channels to read, inputs then outputs, as the file names them.
    time_column : str, optional
        The time column or variable (not for MDF files); ``"none"`` disables it.
    dt : float, optional
        Sample interval (s) of a file without time.

    Returns
    -------
    RawRecord
        The channels before any time-base handling (:func:`read_record` does that too).

    Examples
    --------
    A whitespace-separated table without a time column, its sample interval given:

    >>> import pathlib, tempfile
    >>> from vehid.identification import read_raw
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "log.txt"
    ...     _ = path.write_text("u y\\n1.0 0.0\\n1.0 0.5\\n1.0 0.75\\n")
    ...     raw = read_raw(path, channels=["u", "y"], time_column="none", dt=0.1)
    >>> raw.names, raw.times[0] is None, raw.values[1]
    (('u', 'y'), True, array([0.  , 0.5 , 0.75]))
    """
    suffix = Path(path).suffix.lower()
    if suffix in TEXT_SUFFIXES and _is_mdf(Path(path)):  # MDF3 loggers often name their files .dat
        return read_mdf(path, channels=channels, time_column=time_column, dt=dt)
    if suffix in TEXT_SUFFIXES:
        return read_table(path, channels=channels, time_column=time_column, dt=dt)
    if suffix in MAT_SUFFIXES:
        return read_mat(path, channels=channels, time_column=time_column, dt=dt)
    if suffix in MDF_SUFFIXES:
        return read_mdf(path, channels=channels, time_column=time_column, dt=dt)
    raise InputError(
        f"unknown data file type {suffix or '(none)'!r}: give a .h5, .csv, .dat, .txt, .mat or .mf4 file"
    )
