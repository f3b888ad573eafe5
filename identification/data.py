"""The workbench's one data container for sampled input/output records.

Arrays are time-major: ``u`` is ``(N, n_u)``, ``y`` is ``(N, n_y)``, optional
states ``x`` are ``(N, n_states)``; ``t`` is ``(N,)`` and uniformly sampled.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from .choices import DETREND
from .errors import ExcitationError, InputError
from .optionspec import check_value

__all__ = ["IOData", "as_records", "read_hdf5", "check_channels", "LARGEST_MAGNITUDE", "SMALLEST_MAGNITUDE",
           "ROUNDING_UNITS"]

_UNIFORM_TOLERANCE = 1e-6  # relative spread of sample intervals accepted as uniform


def _as_2d(name: str, value: Any, n_rows: int | None) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2:
        raise InputError(f"{name} must be a 2-D array (N, n_{name}); got shape {array.shape}")
    if n_rows is not None and array.shape[0] != n_rows:
        raise InputError(
            f"{name} has {array.shape[0]} samples but t has {n_rows}: lengths must match"
        )
    if not np.all(np.isfinite(array)):
        bad = np.argwhere(~np.isfinite(array))[0]
        raise InputError(
            f"{name} contains a non-finite value (NaN or inf) at sample {bad[0]}, column {bad[1]}"
        )
    array = array.copy()
    array.setflags(write=False)
    return array


def _names(kind: str, given: Sequence[str] | None, count: int) -> tuple[str, ...]:
    if given is None:
        return tuple(f"{kind}{i + 1}" for i in range(count))
    names = tuple(str(name) for name in given)
    if len(names) != count:
        raise InputError(f"{len(names)} {kind} names given for {count} {kind} columns")
    return names


def _units(given: Sequence[str] | None, count: int, kind: str) -> tuple[str, ...]:
    if given is None:
        return ("-",) * count
    units = tuple(str(unit) for unit in given)
    if len(units) != count:
        raise InputError(f"{len(units)} {kind} units given for {count} {kind} columns")
    return units


@dataclass(frozen=True, eq=False)
class IOData:
    """A uniformly sampled input/output record, validated on construction.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times in seconds, strictly increasing and uniformly spaced.
    u : array_like, shape (N, n_u)
        Inputs.
    y : array_like, shape (N, n_y)
        Outputs.
    x : array_like, shape (N, n_states), optional
        States, where the record comes from a simulation.
    input_names, output_names, state_names : sequence of str, optional
        Column names; default ``u1, u2, ...``, ``y1, ...``, ``x1, ...``.
    input_units, output_units, state_units : sequence of str, optional
        Units of each column; default ``"-"``.
    meta : mapping, optional
        Free-form metadata (JSON-serialisable values): seed, source, manoeuvre.

    Raises
    ------
    InputError
        On a wrong shape, mismatched lengths, non-finite values, fewer than two
        samples, or a non-uniform time base.
    """

    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    x: np.ndarray | None = None
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    state_names: tuple[str, ...] | None = None
    input_units: tuple[str, ...] | None = None
    output_units: tuple[str, ...] | None = None
    state_units: tuple[str, ...] | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1:
            raise InputError(f"t must be 1-D (N,); got shape {t.shape}")
        if t.size < 2:
            raise InputError(f"a record needs at least 2 samples; got {t.size}")
        if not np.all(np.isfinite(t)):
            raise InputError("t contains a non-finite value (NaN or inf)")
        steps = np.diff(t)
        if np.any(steps <= 0):
            raise InputError("t must be strictly increasing")
        if np.ptp(steps) > _UNIFORM_TOLERANCE * steps.mean():
            raise InputError("t must be uniformly sampled (one fixed dt)")
        t = t.copy()
        t.setflags(write=False)
        set_ = object.__setattr__
        set_(self, "t", t)
        u = _as_2d("u", self.u, t.size)
        y = _as_2d("y", self.y, t.size)
        set_(self, "u", u)
        set_(self, "y", y)
        set_(self, "input_names", _names("u", self.input_names, u.shape[1]))
        set_(self, "output_names", _names("y", self.output_names, y.shape[1]))
        set_(self, "input_units", _units(self.input_units, u.shape[1], "input"))
        set_(self, "output_units", _units(self.output_units, y.shape[1], "output"))
        if self.x is not None:
            x = _as_2d("x", self.x, t.size)
            set_(self, "x", x)
            set_(self, "state_names", _names("x", self.state_names, x.shape[1]))
            set_(self, "state_units", _units(self.state_units, x.shape[1], "state"))
        else:
            set_(self, "state_names", None)
            set_(self, "state_units", None)
        set_(self, "meta", MappingProxyType(dict(self.meta)))

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t.size)

    @property
    def n_u(self) -> int:
        """Number of inputs."""
        return int(self.u.shape[1])

    @property
    def n_y(self) -> int:
        """Number of outputs."""
        return int(self.y.shape[1])

    @property
    def dt(self) -> float:
        """Sample interval in seconds."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    @property
    def duration(self) -> float:
        """Length of the record in seconds."""
        return float(self.t[-1] - self.t[0])

    def __getitem__(self, index: slice) -> "IOData":
        """Slice in time: ``data[1000:2000]``."""
        if not isinstance(index, slice):
            raise TypeError("IOData supports slicing in time only, e.g. data[100:200]")
        return self.replace(
            t=self.t[index],
            u=self.u[index],
            y=self.y[index],
            x=None if self.x is None else self.x[index],
        )

    def split(self, fraction: float) -> tuple["IOData", "IOData"]:
        """Split in time into two records.

        Parameters
        ----------
        fraction : float
            Share of the samples in the first record, in (0, 1).

        Returns
        -------
        tuple of IOData
            The first ``round(fraction N)`` samples and the rest.
        """
        if not 0.0 < fraction < 1.0:
            raise InputError(f"split fraction must lie in (0, 1); got {fraction}")
        cut = int(round(fraction * self.n_samples))
        return self[:cut], self[cut:]

    def select_outputs(self, names: Sequence[str]) -> "IOData":
        """Keep only the named outputs.

        Parameters
        ----------
        names : sequence of str
            Output names, in the order wanted.

        Returns
        -------
        IOData
            The record with those outputs.
        """
        index = [self._column(self.output_names, name, "output") for name in names]
        return self.replace(
            y=self.y[:, index],
            output_names=tuple(self.output_names[i] for i in index),
            output_units=tuple(self.output_units[i] for i in index),
        )

    def select_inputs(self, names: Sequence[str]) -> "IOData":
        """Keep only the named inputs.

        Parameters
        ----------
        names : sequence of str
            Input names, in the order wanted.

        Returns
        -------
        IOData
            The record with those inputs.
        """
        index = [self._column(self.input_names, name, "input") for name in names]
        return self.replace(
            u=self.u[:, index],
            input_names=tuple(self.input_names[i] for i in index),
            input_units=tuple(self.input_units[i] for i in index),
        )

    def state(self, name: str) -> np.ndarray:
        """Return the time history of one named state.

        Parameters
        ----------
        name : str
            One of ``state_names``.

        Returns
        -------
        ndarray, shape (N,)
            The state, in its unit.
        """
        if self.x is None:
            raise InputError("this record holds no states")
        return self.x[:, self._column(self.state_names, name, "state")]

    def output(self, name: str) -> np.ndarray:
        """Return the time history of one named output.

        Parameters
        ----------
        name : str
            One of ``output_names``.

        Returns
        -------
        ndarray, shape (N,)
            The output, in its unit.
        """
        return self.y[:, self._column(self.output_names, name, "output")]

    @staticmethod
    def _column(names: Sequence[str], name: str, kind: str) -> int:
        try:
            return list(names).index(name)
        except ValueError:
            raise InputError(
                f"unknown {kind} {name!r}; available: {', '.join(names)}"
            ) from None

    def replace(self, **changes: Any) -> "IOData":
        """Return a copy with some fields changed, validated again.

        Parameters
        ----------
        **changes
            New values of fields (``t``, ``u``, ``output_names``, ...).

        Returns
        -------
        IOData
            The new record.
        """
        return dataclasses.replace(self, **changes)

    def to_hdf5(self, group: Any) -> None:
        """Write into an open HDF5 group: time-first datasets, units as attributes.

        Parameters
        ----------
        group : h5py.Group
            The open group, written into.
        """
        _write_iodata(group, self)

    @classmethod
    def from_hdf5(cls, group: Any) -> "IOData":
        """Read a record that :meth:`to_hdf5` wrote.

        Parameters
        ----------
        group : h5py.Group
            The open group.

        Returns
        -------
        IOData
            The record.
        """
        return _read_iodata(group)


def _decode(values: Any) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def _write_iodata(group: Any, data: IOData) -> None:
    import json

    from .jsonable import json_default

    group.attrs["kind"] = "iodata"
    group.attrs["dt"] = data.dt
    group.attrs["meta_json"] = json.dumps(dict(data.meta), default=json_default)
    ds = group.create_dataset("t", data=data.t)
    ds.attrs["units"] = "s"
    for key, array, names, units in (
        ("u", data.u, data.input_names, data.input_units),
        ("y", data.y, data.output_names, data.output_units),
        ("x", data.x, data.state_names, data.state_units),
    ):
        if array is None:
            continue
        ds = group.create_dataset(key, data=array)
        ds.attrs["names"] = list(names)
        ds.attrs["units"] = list(units)


def _read_iodata(group: Any) -> IOData:
    import json

    try:
        fields: dict[str, Any] = {"t": group["t"][()]}
        for key, names_field, units_field in (
            ("u", "input_names", "input_units"),
            ("y", "output_names", "output_units"),
            ("x", "state_names", "state_units"),
        ):
            if key in group:
                fields[key] = group[key][()]
                fields[names_field] = _decode(group[key].attrs["names"])
                fields[units_field] = _decode(group[key].attrs["units"])
        meta = json.loads(group.attrs.get("meta_json", "{}"))
    except KeyError as missing:
        raise InputError(f"HDF5 group {group.name!r} is not a workbench record: missing {missing}") from None
    return IOData(meta=meta, **fields)


def read_hdf5(path: str | Path, group: str | None = None) -> IOData:
    """Read a record from a workbench HDF5 file.

    Parameters
    ----------
    path : str or Path
        The file.
    group : str, optional
        The group holding the record; by default ``/data`` if present, else the
        first group whose ``kind`` attribute is ``iodata``, else the root.

    Returns
    -------
    IOData
        The record.
    """
    import h5py

    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such data file: {path}")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"{path} is not a readable HDF5 file ({exc})") from None
    with handle:
        if group is not None:
            if group not in handle:
                raise InputError(f"{path} has no group {group!r}")
            return _read_iodata(handle[group])
        if "data" in handle and "t" in handle["data"]:
            return _read_iodata(handle["data"])
        found: list[str] = []
        handle.visititems(
            lambda name, obj: found.append(name)
            if getattr(obj, "attrs", {}).get("kind") == "iodata"
            else None
        )
        if found:
            return _read_iodata(handle[found[0]])
        return _read_iodata(handle)


def as_records(data: "IOData | Sequence[IOData]") -> tuple[IOData, ...]:
    """Check one record or several as records of one sample interval and the same channels.

    Several records of one experiment campaign identify one model; they must
    share ``dt`` (to 1e-9 relative) and the input and output names.

    Parameters
    ----------
    data : IOData or sequence of IOData
        One record, or several.

    Returns
    -------
    tuple of IOData
        The records.

    Raises
    ------
    InputError
        For no record, an item that is not a record, or records that differ in ``dt`` or channels.
    """
    records = (data,) if isinstance(data, IOData) else tuple(data)
    if not records:
        raise InputError("give at least one record")
    for index, record in enumerate(records):
        if not isinstance(record, IOData):
            raise InputError(f"record {index + 1} is a {type(record).__name__}, not IOData")
    first = records[0]
    for index, record in enumerate(records[1:], start=2):
        if (record.input_names, record.output_names) != (first.input_names, first.output_names):
            raise InputError(
                f"record {index} has channels {', '.join(record.input_names)} -> {', '.join(record.output_names)}; "
                f"record 1 has {', '.join(first.input_names)} -> {', '.join(first.output_names)}"
            )
        if not math.isclose(record.dt, first.dt, rel_tol=1e-9):
            raise InputError(
                f"record {index} is sampled every {record.dt:.9g} s, record 1 every {first.dt:.9g} s: "
                "resample them to one rate ('resample' HZ)", options=("resample",)
            )
    return records


# The estimators form products of up to four signal values (a covariance of a gain between two channels is the
# square of a ratio of squares); each stays a finite, normal double when every channel's magnitude lies within
# the fourth roots of the largest and the smallest normal double (1.2e77 and 1.2e-77): the powers of ten inside.
LARGEST_MAGNITUDE = 1e76
SMALLEST_MAGNITUDE = 1e-76
#: A channel whose variation is within this many rounding units (machine epsilon times its level) of a
#: constant, or an output within as many of a multiple of an input, holds rounding noise where the
#: estimators need a signal: after its offset is removed, rounding is more than a thousandth of what is left.
ROUNDING_UNITS = 1000.0


def _spread(t: np.ndarray, values: np.ndarray, detrend: str) -> float:
    """RMS of what is left of a column once its offset (mean, or line in time with ``detrend="linear"``) is gone."""
    if detrend == "linear" and values.size > 2:
        elapsed = t - t[0]
        design = np.column_stack([np.ones_like(elapsed), elapsed / max(float(elapsed[-1]), 1e-300)])
        coefficients = np.linalg.lstsq(design, values, rcond=None)[0]
        return float(np.sqrt(np.mean((values - design @ coefficients) ** 2)))
    return float(np.std(values))


def _power_of_ten(level: float) -> str:
    return f"1e{-int(round(math.log10(level))):d}"


def _channel_problem(kind: str, name: str, columns: list[np.ndarray], times: list[np.ndarray], detrend: str,
                     scale: float) -> InputError | None:
    """The error saying why one channel (its column in every record, scaled) cannot identify a model, or None."""
    level = max(float(np.max(np.abs(column))) for column in columns)
    every = " in every record" if len(columns) > 1 else ""
    nothing = "nothing is excited" if kind == "input" else "there is no response to identify"
    if level == 0.0:
        return ExcitationError(f"{kind} {name!r} is zero throughout{every}: {nothing}")
    raw = f" ({level / abs(scale):.3g} before 'scale')" if scale != 1.0 else ""
    if level > LARGEST_MAGNITUDE or level < SMALLEST_MAGNITUDE:
        if level > LARGEST_MAGNITUDE:
            found = f"reaches {level:.3g}{raw}: values beyond {LARGEST_MAGNITUDE:.0e} overflow"
        else:
            found = f"is at most {level:.3g}{raw} in magnitude: values below {SMALLEST_MAGNITUDE:.0e} underflow"
        return InputError(f"{kind} {name!r} {found} the squares and products the estimators form; rescale it, "
                          f"e.g. 'scale' {name}={_power_of_ten(level)}", options=("scale",))
    if all(np.all(column == column[0]) for column in columns):
        values = ", ".join(f"{column[0]:.6g}" for column in columns[:3]) + (", ..." if len(columns) > 3 else "")
        return ExcitationError(f"{kind} {name!r} is constant ({values} throughout{every}): {nothing}")
    # the column divided by its level first: squares of the spread then stay representable
    spread = max(_spread(t, column / level, detrend) for t, column in zip(times, columns))
    rounding = ROUNDING_UNITS * np.finfo(float).eps
    if spread <= rounding:
        if detrend == "linear" and max(float(np.std(column / level)) for column in columns) > rounding:
            return ExcitationError(f"{kind} {name!r} is a straight line in time{every}: 'detrend' linear leaves "
                                   f"nothing of it; {nothing}", options=("detrend",))
        return ExcitationError(f"{kind} {name!r} is nearly constant{every}: it varies by {spread:.1g} of its level "
                               f"{level:.6g}, within rounding error; {nothing}")
    return None


def _copy_of_input(output: list[np.ndarray], inputs: list[list[np.ndarray]], input_names: Sequence[str]
                   ) -> tuple[str, float] | None:
    """The input an output is a multiple of (plus an offset) in every record, to rounding error, and the factor."""
    tolerance = ROUNDING_UNITS * np.finfo(float).eps
    for name, column in zip(input_names, inputs):
        factors = []
        for y, u in zip(output, column):
            y_level, u_level = float(np.max(np.abs(y))), float(np.max(np.abs(u)))
            y_part, u_part = (y - y.mean()) / y_level, (u - u.mean()) / u_level
            power = float(np.dot(u_part, u_part))
            if power == 0.0:
                break
            factor = float(np.dot(u_part, y_part)) / power
            residual = float(np.sqrt(np.mean((y_part - factor * u_part) ** 2)))
            if residual > tolerance * (1.0 + abs(factor)):
                break
            factors.append(factor * y_level / u_level)
        else:
            if factors and np.allclose(factors, factors[0], rtol=1e-9):
                return name, factors[0]
    return None


def check_channels(records: "IOData | Sequence[IOData]", *, detrend: str = "mean",
                   input_scale: Sequence[float] | None = None, output_scale: Sequence[float] | None = None) -> None:
    """Refuse estimation records that cannot identify a model, naming the channel and the cause.

    Run on the records as read (each channel multiplied by its scale factor),
    before any offset is removed or any signal normalised, so that the cause
    is named rather than the non-finite numbers it would lead to.

    Parameters
    ----------
    records : IOData or sequence of IOData
        The raw estimation records of one model (same channels).
    detrend : {"mean", "linear", "none"}
        The offsets that will be removed: with ``"linear"`` a straight line in
        time is no excitation either.
    input_scale, output_scale : sequence of float, optional
        Factors the channels will be multiplied by (``--scale``); default 1.

    Raises
    ------
    ExcitationError
        A channel that is zero throughout, constant, or varies only within
        :data:`ROUNDING_UNITS` rounding units of its level; an output that is
        an input times a factor, plus an offset, to rounding error.
    InputError
        A channel whose largest magnitude lies outside
        [:data:`SMALLEST_MAGNITUDE`, :data:`LARGEST_MAGNITUDE`] (1e-76 to
        1e76), or that a scale factor makes overflow; an unknown ``detrend``.
    """
    check_value("detrend", detrend, DETREND)
    records = as_records(records)
    first = records[0]
    scales_u = np.ones(first.n_u) if input_scale is None else np.asarray(input_scale, dtype=float)
    scales_y = np.ones(first.n_y) if output_scale is None else np.asarray(output_scale, dtype=float)
    times = [record.t for record in records]
    # a factor that overflows a value is named below, never propagated; underflow is measured as a tiny level
    with np.errstate(over="ignore", under="ignore"):
        inputs = [[record.u[:, i] * scales_u[i] for record in records] for i in range(first.n_u)]
        outputs = [[record.y[:, j] * scales_y[j] for record in records] for j in range(first.n_y)]
        for kind, names, columns, scales in (("input", first.input_names, inputs, scales_u),
                                             ("output", first.output_names, outputs, scales_y)):
            for name, column, scale in zip(names, columns, scales):
                if not all(np.all(np.isfinite(c)) for c in column):
                    raise InputError(f"{kind} {name!r} times its scale factor {scale:g} overflows: choose a smaller "
                                     "factor")
                problem = _channel_problem(kind, name, column, times, detrend, float(scale))
                if problem is not None:
                    raise problem
        for name, column in zip(first.output_names, outputs):
            copied = _copy_of_input(column, inputs, first.input_names)
            if copied is not None:
                source, factor = copied
                how = "a copy of" if math.isclose(factor, 1.0, rel_tol=1e-9) else f"{factor:.6g} times"
                raise ExcitationError(f"output {name!r} is {how} input {source!r} (plus an offset at most), to rounding "
                                 "error: it copies the input, there are no dynamics to identify; check the channels "
                                 "chosen as outputs")
