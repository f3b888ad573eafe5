"""Durable, versioned HDF5 results archives.

One HDF5 file laid out as ``results/RESULTS_LAYOUT.md`` documents (schema version
:data:`SCHEMA_VERSION`): records are :class:`~identification.data.IOData`, runs are named groups of
per-pass histories and frozen values stored by :mod:`vehid.identification.dataio.storage`, never pickled. Writing is
atomic: the file is built under a temporary name beside the target and renamed over it only when the
``with`` block ends without an exception, so a crash never leaves a half-written archive.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import uuid
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from importlib import metadata
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import h5py
import numpy as np

from .archive_safety import archive_lock, verify_checksums, write_checksums
from ..data import IOData
from ..errors import ArchiveError
from ..jsonable import to_jsonable
from .storage import member_name, read_group, read_value, write_group

__all__ = [
    "SCHEMA_VERSION",
    "REQUIRED_GROUPS",
    "REQUIRED_ATTRIBUTES",
    "Archive",
    "RunRecord",
    "RunName",
    "write_archive",
    "update_archive",
    "open_archive",
    "read_archive",
    "write_record",
    "read_records",
    "run_group",
    "write_run",
    "read_run",
    "append_history",
    "read_history",
]

#: The layout version this module writes; archives with a larger one are refused.
#: Version 2 stores values under registered schemas where 1 named their classes; both read.
SCHEMA_VERSION = 2

#: Groups every archive holds (possibly empty).
REQUIRED_GROUPS = ("config", "data", "runs")

#: Root attributes every archive holds.
REQUIRED_ATTRIBUTES = (
    "schema_version",
    "kind",
    "package_version",
    "git_commit",
    "casadi_version",
    "seeds",
    "created",
    "config_json",
)

_RUN_MEMBERS = ("model", "metrics", "state")
SCHEDULE_MEMBER = "schedule"  # root member: the schedule channel of each record a scheduled run was fitted on


@dataclass(frozen=True)
class RunName:
    """The name of a run of one kind of model at one order: ``<kind>-n<order>``, e.g. ``linear-n4``.

    Parameters
    ----------
    kind : str
        The kind of model (``linear``, ``spline``, ...).
    order : int
        The model order.
    """

    kind: str
    order: int

    def __str__(self) -> str:
        return f"{self.kind}-n{self.order}"

    @classmethod
    def parse(cls, name: str) -> "RunName | None":
        """Read the kind and order a run name states.

        Parameters
        ----------
        name : str
            A run's name, e.g. ``"linear-n4"``.

        Returns
        -------
        RunName or None
            None for a name of another form.
        """
        kind, separator, order = str(name).rpartition("-n")
        return cls(kind, int(order)) if separator and kind and order.isdigit() else None


@dataclass(frozen=True, eq=False)
class RunRecord:
    """One run of an archive, read into memory.

    Attributes
    ----------
    name : str
        The run's name (``runs/<name>``).
    history : dict of str to ndarray
        Per-pass datasets, pass index first, e.g. ``parameters (n_pass, n_theta)``.
    history_units : dict of str to str
        The ``units`` attribute of each history dataset.
    model, metrics, state : object or None
        The values stored in ``runs/<name>/model``, ``metrics`` and ``state``.
    """

    name: str
    history: dict[str, np.ndarray]
    history_units: dict[str, str]
    model: Any = None
    metrics: Any = None
    state: Any = None

    @property
    def n_pass(self) -> int:
        """Number of completed passes recorded in the history."""
        return next((len(values) for values in self.history.values()), 0)


@dataclass(frozen=True, eq=False)
class Archive:
    """A whole archive read into memory by :func:`read_archive`.

    Attributes
    ----------
    kind : str
        What the archive holds, e.g. ``identification`` or ``handling-study``.
    schema_version : int
        The layout's version (:data:`SCHEMA_VERSION` when written by this workbench).
    package_version, git_commit, casadi_version, created : str
        Provenance: the workbench version, the commit of its working tree
        (``<sha>``, ``<sha>-dirty`` or ``unknown``), CasADi's version and the
        UTC time the archive was first written (ISO 8601).
    seeds : object
        The seeds the study used (decoded JSON).
    config : object
        The configuration: a dataclass or a dict, as written.
    records : dict of str to IOData
        The ``data/<record>`` groups.
    runs : dict of str to RunRecord
        The ``runs/<name>`` groups.
    summary : object or None
        The study's summary (root attribute ``summary_json``, decoded), written once a study finishes.
    schedule : object or None
        The root member ``schedule`` where a run was scheduled on a channel: its ``channel``, ``unit``
        and ``records`` (record name to the channel's samples, one per sample of that record).
    """

    kind: str
    schema_version: int
    package_version: str
    git_commit: str
    casadi_version: str
    seeds: Any
    created: str
    config: Any
    records: dict[str, IOData] = field(default_factory=dict)
    runs: dict[str, RunRecord] = field(default_factory=dict)
    summary: Any = None
    schedule: Any = None


def _package_version(name: str) -> str:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return "unknown"


def _git_commit() -> str:
    """The commit of the workbench's working tree, ``-dirty`` if it has changes; ``unknown`` without git."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()
        changes = subprocess.run(
            ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=10, check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if not head:
        return "unknown"
    return f"{head}-dirty" if changes else head


def _temporary_beside(path: Path) -> Path:
    # A hidden name in the same directory, so that os.replace is a rename on one file system.
    return path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")


def _sync(path: Path) -> None:
    """Flush a finished file (and, where possible, its directory entry) to disk."""
    with open(path, "rb") as handle:
        os.fsync(handle.fileno())


def _sync_directory(directory: Path) -> None:
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # pragma: no cover - platforms without directory handles
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover
        pass
    finally:
        os.close(fd)


@contextmanager
def _atomic(path: Path, prepare: Any, mode: str) -> Iterator[h5py.File]:
    # The writer's lock is held from before the copy to after the rename: two writers of one
    # archive cannot interleave (one is refused, naming the other).
    with archive_lock(path):
        temporary = _temporary_beside(path)
        try:
            try:
                prepare(temporary)
                with h5py.File(temporary, mode) as handle:
                    yield handle
                    write_checksums(handle)
                _sync(temporary)
                os.replace(temporary, path)
            except OSError as exc:  # a full disk, a vanished directory: name the archive, not the hidden copy
                if exc.filename not in (None, str(temporary)):
                    raise
                raise OSError(exc.errno, f"cannot write the archive ({exc.strerror or exc})", str(path)) from exc
            _sync_directory(path.parent)
        finally:
            if temporary.exists():
                temporary.unlink()


@contextmanager
def write_archive(
    path: str | Path,
    *,
    kind: str,
    config: Any = None,
    seeds: Any = None,
) -> Iterator[h5py.File]:
    """Write a new archive atomically.

    Parameters
    ----------
    path : str or Path
        The final name. Its directory is created if missing.
    kind : str
        What the archive holds, e.g. ``identification``, ``linear-example``,
        ``handling-study``.
    config : dataclass or dict, optional
        The study's configuration; stored in the ``config`` group (readable
        back as the same value) and as JSON in the ``config_json`` attribute.
    seeds : int, sequence or dict, optional
        The random seeds used; stored as JSON in the ``seeds`` attribute.

    Yields
    ------
    h5py.File
        The archive, open for writing under a temporary name, with the root
        attributes and the empty groups ``config``, ``data`` and ``runs``
        already written. Fill it with :func:`write_record`, :func:`write_run`,
        :func:`append_history` and :func:`~identification.dataio.storage.write_value`.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> target = pathlib.Path(tempfile.mkdtemp()) / "example.h5"
    >>> from vehid.identification.dataio.storage import write_value
    >>> with write_archive(target, kind="example", config={"order": 4}, seeds=[0]) as archive:
    ...     write_value(archive["config"], "note", "a doctest")
    >>> read_archive(target).config
    {'order': 4, 'note': 'a doctest'}
    """
    if not isinstance(kind, str) or not kind.strip():
        raise ArchiveError(f"an archive needs a non-empty kind string; got {kind!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _atomic(path, lambda temporary: None, "x") as handle:
        _write_header(handle, kind, config, seeds)
        yield handle


def _write_header(handle: h5py.File, kind: str, config: Any, seeds: Any) -> None:
    attrs = handle.attrs
    attrs["schema_version"] = np.int64(SCHEMA_VERSION)
    attrs["kind"] = kind
    attrs["package_version"] = _package_version("vehid")
    attrs["git_commit"] = _git_commit()
    attrs["casadi_version"] = _package_version("casadi")
    attrs["seeds"] = json.dumps(to_jsonable(seeds))
    attrs["created"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
    attrs["config_json"] = json.dumps(to_jsonable(config), sort_keys=True)
    write_group(handle.create_group("config"), {} if config is None else config)
    handle.create_group("data")
    handle.create_group("runs")


@contextmanager
def update_archive(path: str | Path, *, kinds: Sequence[str] | None = None) -> Iterator[h5py.File]:
    """Append to an existing archive atomically (checkpoints).

    The archive is checked as by :func:`open_archive`, copied to a temporary
    file beside it, yielded open for reading and writing, and renamed over the
    original when the block ends normally. On an exception the original is
    untouched and the copy removed. Each update copies the file once, which
    costs little for archives of histories and a few records.

    Parameters
    ----------
    path : str or Path
        An archive written by :func:`write_archive`.
    kinds : sequence of str, optional
        Accept only archives of these kinds.

    Yields
    ------
    h5py.File
    """
    path = Path(path)
    with archive_lock(path):
        open_archive(path, kinds).close()
        with _atomic(path, lambda temporary: shutil.copyfile(path, temporary), "r+") as handle:
            handle.attrs["updated"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
            handle.attrs["schema_version"] = np.int64(SCHEMA_VERSION)  # what is added now is in this layout
            yield handle


def open_archive(path: str | Path, kinds: Sequence[str] | None = None) -> h5py.File:
    """Open an archive read-only after checking that it is one this workbench can read.

    Parameters
    ----------
    path : str or Path
        The archive's file.
    kinds : sequence of str, optional
        Accept only archives of these kinds.

    Returns
    -------
    h5py.File
        Open read-only; close it (or use it in a ``with`` block).

    Raises
    ------
    ArchiveError
        Naming the problem: no such file; not an HDF5 file; truncated or
        corrupt; an HDF5 file that is not a workbench archive (no
        ``schema_version``); a newer schema version than this workbench reads;
        a missing root attribute or required group; a kind not in ``kinds``;
        a dataset or group whose content no longer matches the checksum
        written with it (:mod:`vehid.identification.dataio.archive_safety`).
    """
    path = Path(path)
    if not path.exists():
        raise ArchiveError(f"no such archive: {path}")
    if not path.is_file():
        raise ArchiveError(f"{path} is not a file")
    if not h5py.is_hdf5(path):
        raise ArchiveError(f"{path} is not an HDF5 file (no HDF5 signature): not a results archive")
    try:
        handle = h5py.File(path, "r")
    except OSError as exc:
        raise ArchiveError(f"{path} is truncated or corrupt: the HDF5 library cannot open it ({exc})") from None
    try:
        _check_archive(handle, path, kinds)
        verify_checksums(handle, path)
    except BaseException:
        handle.close()
        raise
    return handle


def _check_archive(handle: h5py.File, path: Path, kinds: Sequence[str] | None) -> None:
    try:
        attrs = dict(handle.attrs)
        members = set(handle.keys())
    except (OSError, RuntimeError, KeyError) as exc:
        raise ArchiveError(f"{path} is truncated or corrupt: its root group cannot be read ({exc})") from None
    if "schema_version" not in attrs:
        raise ArchiveError(
            f"{path} is an HDF5 file but not a workbench results archive (no schema_version attribute)"
        )
    version = attrs["schema_version"]
    if isinstance(version, (bool, np.bool_)) or not isinstance(version, (int, np.integer)) or version < 1:
        raise ArchiveError(f"{path} has an invalid schema_version {version!r}")
    if version > SCHEMA_VERSION:
        raise ArchiveError(
            f"{path} has schema version {int(version)}, newer than this workbench reads "
            f"(up to {SCHEMA_VERSION}): upgrade vehid to read it"
        )
    for name in REQUIRED_ATTRIBUTES:
        if name not in attrs:
            raise ArchiveError(f"{path} lacks the required root attribute {name!r}")
    for name in REQUIRED_GROUPS:
        if name not in members or not isinstance(handle.get(name), h5py.Group):
            raise ArchiveError(f"{path} lacks the required group {name!r}")
    kind = str(attrs["kind"])
    if kinds is not None and kind not in kinds:
        raise ArchiveError(f"{path} holds a {kind!r} archive; expected one of: {', '.join(kinds)}")


def read_archive(path: str | Path, kinds: Sequence[str] | None = None) -> Archive:
    """Read a whole archive into memory.

    Parameters
    ----------
    path : str or Path
        The archive's file.
    kinds : sequence of str, optional
        Accept only archives of these kinds.

    Returns
    -------
    Archive
        Its provenance, records and runs.

    Raises
    ------
    ArchiveError
        As :func:`open_archive`, or when a stored value cannot be read back.
    """
    with open_archive(path, kinds) as handle:
        try:
            attrs = handle.attrs
            return Archive(
                kind=str(attrs["kind"]),
                schema_version=int(attrs["schema_version"]),
                package_version=str(attrs["package_version"]),
                git_commit=str(attrs["git_commit"]),
                casadi_version=str(attrs["casadi_version"]),
                seeds=json.loads(attrs["seeds"]),
                created=str(attrs["created"]),
                config=read_group(handle["config"]),
                records=read_records(handle),
                runs={name: read_run(group) for name, group in handle["runs"].items()},
                summary=json.loads(attrs["summary_json"]) if "summary_json" in attrs else None,
                schedule=read_value(handle, SCHEDULE_MEMBER) if SCHEDULE_MEMBER in handle else None,
            )
        except (OSError, RuntimeError, KeyError) as exc:
            raise ArchiveError(f"{path} is truncated or corrupt: reading it failed ({exc})") from None


def write_record(archive: h5py.File, name: str, data: IOData) -> h5py.Group:
    """Store a record as ``data/<name>`` (replacing one of that name).

    Time-first datasets ``t``, ``u``, ``y`` (and ``x``) with ``names`` and
    ``units`` attributes, as :meth:`IOData.to_hdf5` writes them.

    Parameters
    ----------
    archive : h5py.File
        The archive, open for writing.
    name : str
        The record's name (letters, digits, ``_.-``).
    data : IOData
        The record.

    Returns
    -------
    h5py.Group
        ``data/<name>``.
    """
    member_name(name, "record")
    if not isinstance(data, IOData):
        raise ArchiveError(f"record {name!r} must be IOData; got {type(data).__name__}")
    parent = archive.require_group("data")
    if name in parent:
        del parent[name]
    group = parent.create_group(name)
    data.to_hdf5(group)
    return group


def read_records(archive: h5py.File) -> dict[str, IOData]:
    """Read every ``data/<name>`` record of an archive.

    Parameters
    ----------
    archive : h5py.File
        The open archive.

    Returns
    -------
    dict of str to IOData
        The records by name.
    """
    records: dict[str, IOData] = {}
    for name, group in archive.get("data", {}).items():
        try:
            records[name] = IOData.from_hdf5(group)
        except ValueError as exc:
            raise ArchiveError(f"record data/{name} cannot be read: {exc}") from None
    return records


def run_group(archive: h5py.File, name: str) -> h5py.Group:
    """Return the group ``runs/<name>``, created if missing.

    Parameters
    ----------
    archive : h5py.File
        The archive, open for writing.
    name : str
        The run's name.

    Returns
    -------
    h5py.Group
        ``runs/<name>``.
    """
    return archive.require_group("runs").require_group(member_name(name, "run"))


def write_run(
    archive: h5py.File,
    name: str,
    *,
    model: Any = None,
    metrics: Any = None,
    state: Any = None,
) -> h5py.Group:
    """Store the final model, the metrics and the resume state of run ``name``.

    Each value given (not ``None``) replaces the group ``runs/<name>/model``,
    ``metrics`` or ``state``; each is written as :func:`write_value` writes a
    group by :func:`~identification.dataio.storage.write_group` (a dataclass, a
    ``to_dict``/``to_hdf5`` object or a dict).

    Parameters
    ----------
    archive : h5py.File
        The archive, open for writing.
    name : str
        The run's name.
    model, metrics, state : object, optional
        The final model, its metrics and the estimator's resume state.

    Returns
    -------
    h5py.Group
        ``runs/<name>``.
    """
    run = run_group(archive, name)
    for member, value in (("model", model), ("metrics", metrics), ("state", state)):
        if value is None:
            continue
        if member in run:
            del run[member]
        write_group(run.create_group(member), value)
    return run


def read_run(run: h5py.Group) -> RunRecord:
    """Read one ``runs/<name>`` group into memory.

    Parameters
    ----------
    run : h5py.Group
        ``runs/<name>``.

    Returns
    -------
    RunRecord
        Its history, model, metrics and state.
    """
    history = read_history(run)
    units = {key: str(run["history"][key].attrs.get("units", "-")) for key in history}
    values = {member: read_group(run[member]) for member in _RUN_MEMBERS if member in run}
    return RunRecord(name=run.name.rsplit("/", 1)[-1], history=history, history_units=units, **values)


def append_history(
    run: h5py.Group,
    values: Mapping[str, Any],
    *,
    units: Mapping[str, str] | None = None,
) -> int:
    """Append one pass to the run's history: one row per dataset of ``runs/<name>/history``.

    Parameters
    ----------
    run : h5py.Group
        ``runs/<name>``, e.g. from :func:`run_group`.
    values : mapping of str to array_like
        This pass's values, e.g. ``parameters (n_theta,)``, ``fit_filter (n_y,)``,
        ``trace_p`` (scalar), ``seconds`` (scalar). The first pass fixes the
        names and shapes; every later pass must give the same names and shapes.
    units : mapping of str to str, optional
        Units of each entry, written on the first pass (default ``"-"``).

    Returns
    -------
    int
        The number of passes now recorded.

    Notes
    -----
    The datasets are chunked and resizable along the pass axis (pass index
    first: ``parameters (n_pass, n_theta)``).
    """
    history = run.require_group("history")
    units = dict(units or {})
    existing = set(history.keys())
    if existing and set(values) != existing:
        raise ArchiveError(
            f"history of {run.name} holds {sorted(existing)}; this pass gives {sorted(values)}"
        )
    if not values:
        raise ArchiveError("a pass needs at least one value to record")
    n_pass = int(history.attrs.get("n_pass", 0))
    for key, value in values.items():
        member_name(key, "history entry")
        row = np.asarray(value)
        if row.dtype.kind not in "biufc":
            raise ArchiveError(f"history entry {key!r} must be numeric; got dtype {row.dtype}")
        if key not in history:
            rows_per_chunk = max(1, min(256, 65536 // max(row.nbytes, 1)))
            dataset = history.create_dataset(
                key, shape=(0, *row.shape), maxshape=(None, *row.shape), dtype=row.dtype,
                chunks=(rows_per_chunk, *row.shape),
            )
            dataset.attrs["units"] = str(units.get(key, "-"))
        dataset = history[key]
        if dataset.shape[1:] != row.shape:
            raise ArchiveError(
                f"history entry {key!r} has shape {dataset.shape[1:]} per pass; got {row.shape}"
            )
        dataset.resize(n_pass + 1, axis=0)
        dataset[n_pass] = row
    history.attrs["n_pass"] = np.int64(n_pass + 1)
    return n_pass + 1


def read_history(run: h5py.Group) -> dict[str, np.ndarray]:
    """Read the per-pass datasets of ``runs/<name>/history``.

    Parameters
    ----------
    run : h5py.Group
        ``runs/<name>``.

    Returns
    -------
    dict of str to ndarray
        Each entry, pass index first; empty if no pass was recorded.
    """
    if "history" not in run:
        return {}
    return {key: dataset[...] for key, dataset in run["history"].items()}
