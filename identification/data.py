"""The workbench's one data container for sampled input/output records.

Arrays are time-major: ``u`` is ``(N, n_u)``, ``y`` is ``(N, n_y)``, optional
states ``x`` are ``(N, n_x)``; ``t`` is ``(N,)`` and uniformly sampled.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import InputError

__all__ = ["IOData", "as_records", "read_hdf5"]

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
    x : array_like, shape (N, n_x), optional
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
        """Split in time into two records, the first holding ``fraction`` of the samples."""
        if not 0.0 < fraction < 1.0:
            raise InputError(f"split fraction must lie in (0, 1); got {fraction}")
        cut = int(round(fraction * self.n_samples))
        return self[:cut], self[cut:]

    def select_outputs(self, names: Sequence[str]) -> "IOData":
        """A record with only the named outputs, in the order given."""
        index = [self._column(self.output_names, name, "output") for name in names]
        return self.replace(
            y=self.y[:, index],
            output_names=tuple(self.output_names[i] for i in index),
            output_units=tuple(self.output_units[i] for i in index),
        )

    def select_inputs(self, names: Sequence[str]) -> "IOData":
        """A record with only the named inputs, in the order given."""
        index = [self._column(self.input_names, name, "input") for name in names]
        return self.replace(
            u=self.u[:, index],
            input_names=tuple(self.input_names[i] for i in index),
            input_units=tuple(self.input_units[i] for i in index),
        )

    def state(self, name: str) -> np.ndarray:
        """The time history of one named state, shape (N,)."""
        if self.x is None:
            raise InputError("this record holds no states")
        return self.x[:, self._column(self.state_names, name, "state")]

    def output(self, name: str) -> np.ndarray:
        """The time history of one named output, shape (N,)."""
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
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    def to_hdf5(self, group: Any) -> None:
        """Write into an open ``h5py.Group`` (time-first datasets, units as attributes)."""
        _write_iodata(group, self)

    @classmethod
    def from_hdf5(cls, group: Any) -> "IOData":
        """Read from an open ``h5py.Group`` written by :meth:`to_hdf5`."""
        return _read_iodata(group)


def _decode(values: Any) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def _write_iodata(group: Any, data: IOData) -> None:
    import json

    group.attrs["kind"] = "iodata"
    group.attrs["dt"] = data.dt
    group.attrs["meta_json"] = json.dumps(dict(data.meta), default=str)
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
    """One record or several as a tuple of records of one sample interval and the same channels.

    Several records of one experiment campaign identify one model; they must
    share ``dt`` (to 1e-9 relative) and the input and output names.
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
                "resample them to one rate (--resample HZ)"
            )
    return records
