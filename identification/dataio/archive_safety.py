"""Safe output files: writer locks, checks of a target before any work, checksums, whole-folder swaps.

:func:`archive_lock` is an ``flock`` on a hidden file beside the archive, so that the system releases it
when the holder dies, even by ``SIGKILL``; :func:`check_output_target` refuses a bad target before any
work, replacing an existing file only when it is the workbench's own output of the same kind and
the same run; :func:`write_checksums` and :func:`verify_checksums` find values changed on disk behind
the workbench's back (archives written without digests still read); :func:`replacing_directory` swaps a
finished folder in whole, so an interrupted writer leaves the old folder or the new one;
:func:`check_report_folder` and :func:`writing_report_folder` write a report folder that is absent,
empty or an earlier report (marked by :data:`REPORT_MARKER`), and never delete a file the report did
not write.
"""

from __future__ import annotations

import ctypes
import errno
import fcntl
import hashlib
import json
import os
import shutil
import socket
import uuid
import zlib
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

import h5py
import numpy as np

from ..choices import HDF5_SUFFIXES
from ..errors import ArchiveError, InputError

__all__ = [
    "ArchiveLockedError",
    "OutputTargetError",
    "archive_lock",
    "check_output_target",
    "check_output_folder",
    "check_report_folder",
    "report_files",
    "writing_report_folder",
    "output_identity",
    "OutputIdentity",
    "RUN_ATTRIBUTE",
    "settings_digest",
    "HDF5_SUFFIXES",
    "KIND_ATTRIBUTE",
    "REPORT_MARKER",
    "is_workbench_archive",
    "write_checksums",
    "verify_checksums",
    "replacing_directory",
    "os_error_text",
]

DIGEST_ATTRIBUTE = "vehid_digest"
#: Root attribute naming the digest scheme; its presence promises a digest on every object.
CHECKSUM_ATTRIBUTE = "vehid_checksums"
CHECKSUM_SCHEME = "crc32"  # against faults, not forgery: 25 times faster than a cryptographic hash here
#: Root attribute naming the run that wrote a file: a digest of the command, its settings and its inputs.
RUN_ATTRIBUTE = "vehid_run"

def _file_digest(path: str) -> str:
    digest = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _identity(value: Any) -> Any:
    """A setting as it enters a run's digest: a file named by its content, so a moved copy is the same run; a
    record in memory by its samples and names."""
    if isinstance(value, np.ndarray):
        return {"array": hashlib.blake2b(np.ascontiguousarray(value).tobytes(), digest_size=16).hexdigest(),
                "shape": list(value.shape)}
    if isinstance(value, Mapping):
        return {str(key): _identity(item) for key, item in value.items()}
    if hasattr(value, "__dataclass_fields__") and not isinstance(value, type):
        return {"type": type(value).__name__,
                **{name: _identity(getattr(value, name)) for name in value.__dataclass_fields__}}
    if isinstance(value, (list, tuple)):
        return [_identity(item) for item in value]
    if isinstance(value, (str, os.PathLike)) and str(value):
        try:
            if os.path.isfile(value):  # read each time: a timestamp may not change when a file is rewritten
                return {"file": _file_digest(os.fspath(value))}
        except OSError:
            pass  # unreadable here: the command's own check names it
    return value


def settings_digest(command: str, settings: Mapping[str, Any]) -> str:
    """The digest that says which run a command or a library call asks for (:data:`RUN_ATTRIBUTE`).

    ``settings`` are what the run computes from: its options, and its input files by their content
    (a moved copy is the same run) or its records by their samples. Two runs with the same digest
    compute the same thing, so the second may replace the first's output; where and how verbosely
    the work is done does not belong among the settings.
    """
    content = {name: _identity(value) for name, value in sorted(settings.items())}
    text = json.dumps({"command": command, "settings": content}, sort_keys=True, default=str)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()

#: Root attribute naming what an HDF5 output that is not a results archive holds (e.g. a simulated record).
KIND_ATTRIBUTE = "vehid_kind"
#: The file that marks a folder as a report of the workbench; it lists the report's own files.
REPORT_MARKER = ".vehid-report.json"


class ArchiveLockedError(InputError):
    """Another process is writing the archive (exit status 2: choose another file or wait)."""


class OutputTargetError(InputError):
    """The output target cannot or must not be written (a directory, an input, a foreign file, no permission)."""


def os_error_text(exc: OSError, path: str | Path | None = None) -> str:
    """``'<path>: <cause>'`` for an operating-system error, the path from the error if it has one."""
    name = exc.filename if exc.filename is not None else path
    cause = exc.strerror or str(exc) or type(exc).__name__
    return f"{name}: {cause}" if name is not None else cause


_HELD: dict[str, tuple[int, int]] = {}  # lock-file path -> (file descriptor, nesting depth) held by this process


def _lock_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.lock")


def _holder(lock_file: Path) -> str:
    try:
        text = lock_file.read_text().strip()
    except OSError:
        text = ""
    fields = dict(part.split("=", 1) for part in text.split() if "=" in part)
    if "pid" in fields:
        return f"process {fields['pid']} on host {fields.get('host', 'unknown')}"
    return "another process"


@contextmanager
def archive_lock(path: str | Path) -> Iterator[Path]:
    """Hold the exclusive writer's lock of ``path`` for the ``with`` block.

    Parameters
    ----------
    path : str or Path
        The archive (it need not exist yet). The lock is the hidden file
        ``.<name>.lock`` beside it, holding ``pid=<pid> host=<host>`` of the
        writer; it is removed when the lock is released.

    Yields
    ------
    Path
        The archive's path.

    Raises
    ------
    ArchiveLockedError
        Another process holds the lock; the message names it (pid and host).
    OutputTargetError
        The lock file cannot be created (the path and the cause named).

    Notes
    -----
    Re-entrant within one process: nested blocks on the same archive share
    the outer lock, so a command can hold it across a whole run while the
    archive functions take it for each write.
    """
    path = Path(path)
    lock_file = _lock_path(path.absolute())
    key = str(lock_file)
    if key in _HELD:
        fd, depth = _HELD[key]
        _HELD[key] = (fd, depth + 1)
        try:
            yield path
        finally:
            fd, depth = _HELD[key]
            _HELD[key] = (fd, depth - 1)
        return
    fd = _acquire(lock_file, path)
    _HELD[key] = (fd, 1)
    try:
        yield path
    finally:
        del _HELD[key]
        try:
            lock_file.unlink()
        except OSError:
            pass
        os.close(fd)  # closing the descriptor releases the flock


def _acquire(lock_file: Path, path: Path) -> int:
    while True:
        try:
            fd = os.open(lock_file, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputTargetError(f"cannot lock {path} for writing: {os_error_text(exc, lock_file)}") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno not in (errno.EWOULDBLOCK, errno.EACCES, errno.EAGAIN):
                raise OutputTargetError(f"cannot lock {path} for writing: {os_error_text(exc, lock_file)}") from None
            raise ArchiveLockedError(
                f"{path} is being written by {_holder(lock_file)}; wait for it to finish or choose another file"
            ) from None
        # The holder before us may have removed the file after we opened it: then our lock is on an
        # orphaned inode and a third process could lock a new file. Lock only the file the name points to.
        try:
            if os.stat(lock_file).st_ino == os.fstat(fd).st_ino:
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, f"pid={os.getpid()} host={socket.gethostname()}\n".encode())
    return fd


def is_workbench_archive(path: str | Path) -> bool:
    """True when ``path`` is an HDF5 file with the workbench's ``schema_version`` root attribute."""
    try:
        if not h5py.is_hdf5(path):
            return False
        with h5py.File(path, "r") as handle:
            return "schema_version" in handle.attrs
    except (OSError, RuntimeError):
        return False


@dataclass(frozen=True)
class OutputIdentity:
    """What a workbench output file holds and which run wrote it.

    Attributes
    ----------
    kind : str
        An archive's ``kind`` (``identification``, ``handling-study``, ...) or
        the :data:`KIND_ATTRIBUTE` of another HDF5 output (``simulated-record``).
    run : str or None
        The :data:`RUN_ATTRIBUTE` digest of the run that wrote it; None for
        files written before runs were recorded.
    """

    kind: str
    run: str | None


def output_identity(path: str | Path) -> OutputIdentity | None:
    """The kind and run of a workbench output file; None for any other file (text, CSV, foreign HDF5)."""
    try:
        if not h5py.is_hdf5(path):
            return None
        with h5py.File(path, "r") as handle:
            attrs = handle.attrs
            if "schema_version" in attrs:
                kind = str(attrs.get("kind", ""))
            elif KIND_ATTRIBUTE in attrs:
                kind = str(attrs[KIND_ATTRIBUTE])
            else:
                return None
            run = attrs.get(RUN_ATTRIBUTE)
            return OutputIdentity(kind, None if run is None else str(run))
    except (OSError, RuntimeError):
        return None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _refuse_to_replace(path: Path, cause: str) -> OutputTargetError:
    return OutputTargetError(
        f"{path} exists and {cause}; refusing to overwrite it (give 'force' to replace it, or choose another file)",
        options=("force",))


def check_output_target(
    path: str | Path,
    *,
    inputs: Iterable[str | Path | None] = (),
    force: bool = False,
    what: str = "archive",
    kind: str | None = None,
    run: str | None = None,
    identify: Callable[[Path], OutputIdentity | None] | None = None,
    suffixes: Iterable[str] | None = None,
) -> Path:
    """Check, before any work, that ``path`` may and can be written; returns it.

    Parameters
    ----------
    path : str or Path
        The file to be written (replaced atomically later).
    inputs : iterable of path
        Files the run reads; the target must be none of them (never, even
        with ``force``: the run would replace its own data).
    force : bool
        Allow replacing any existing file.
    what : str
        What is written, for the messages.
    kind : str, optional
        The kind of output the run writes: an existing file is replaced only
        if it is a workbench output of this kind. None accepts any workbench
        archive (the rule before kinds were checked).
    run : str, optional
        The digest of the run (see :data:`RUN_ATTRIBUTE`): an existing file
        is replaced only if the same run wrote it, so that rerunning a command
        replaces its own output while another run's result is kept.
    identify : callable, optional
        Tells what an existing file holds, for outputs that are not HDF5
        (e.g. model files); default :func:`output_identity`.
    suffixes : iterable of str, optional
        The name endings of the format written (e.g. ``.h5``): a name such
        as ``data.csv`` promises a format that would not be there.

    Raises
    ------
    OutputTargetError
        One line naming the path and the cause: a directory; one of the
        inputs; without ``force``, an existing file that is not a workbench
        output, is one of another kind, or was written by another run; a
        directory that cannot be created or written.
    """
    path = Path(path)
    for source in inputs:
        if source is not None and _same_file(path, Path(source)):
            raise OutputTargetError(f"the {what} {path} is an input of this run; choose another output file")
    if path.is_dir():
        raise OutputTargetError(f"cannot write the {what} {path}: {os.strerror(errno.EISDIR)}")
    if suffixes is not None and path.suffix.lower() not in {suffix.lower() for suffix in suffixes}:
        raise OutputTargetError(f"cannot write the {what} {path}: its name must end in "
                                f"{' or '.join(suffixes)}, the format written")
    if path.exists() and not force:
        identity = (identify or output_identity)(path)
        if identity is None or (kind is None and not is_workbench_archive(path)):
            raise _refuse_to_replace(path, f"is not a workbench {what}")
        if kind is not None and identity.kind != kind:
            raise _refuse_to_replace(path, f"holds a {identity.kind!r} output, not {kind!r}")
        if run is not None and identity.run is None:
            raise _refuse_to_replace(path, f"holds a {identity.kind!r} output that does not say which run wrote it")
        if run is not None and identity.run != run:
            raise _refuse_to_replace(path, f"holds the {identity.kind!r} output of another run (other settings or data)")
    _check_writable_directory(path, what)
    if path.exists() and not os.access(path, os.W_OK):
        # os.replace would succeed in a writable directory, but the user protected this file
        raise OutputTargetError(f"cannot write the {what} {path}: {os.strerror(errno.EACCES)}")
    return path


def _check_writable_directory(path: Path, what: str) -> None:
    """Create ``path``'s directory if missing and prove it writable by creating and removing a file there."""
    directory = path.parent
    existing = next(folder for folder in (directory, *directory.parents) if folder.exists())
    if not existing.is_dir():
        raise OutputTargetError(f"cannot write the {what} {path}: {existing}: {os.strerror(errno.ENOTDIR)}")
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.probe"
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        os.close(fd)
        probe.unlink()
    except OSError as exc:  # the probe's own name would only confuse: the target and the cause
        raise OutputTargetError(f"cannot write the {what} {path}: {exc.strerror or exc}") from None


def check_output_folder(folder: str | Path, *, what: str = "report folder") -> Path:
    """Check, before any work, that ``folder`` can be replaced by :func:`replacing_directory`; returns it.

    Raises
    ------
    OutputTargetError
        ``folder`` exists and is not a directory, or its parent cannot be
        created or written (the path and the cause named).
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputTargetError(f"cannot write the {what} {folder}: {os.strerror(errno.ENOTDIR)}")
    _check_writable_directory(folder, what)
    return folder


def _listed_name(name: Any) -> str | None:
    """A marker's file name if it stays inside the folder (relative, no ``..``), else None."""
    if not isinstance(name, str) or not name:
        return None
    parts = Path(name).parts
    if Path(name).is_absolute() or ".." in parts or name == REPORT_MARKER:
        return None
    return str(Path(*parts))


def report_files(folder: str | Path) -> set[str] | None:
    """The files (relative paths) an earlier report in ``folder`` wrote, or None if it holds no report marker."""
    try:
        listed = json.loads((Path(folder) / REPORT_MARKER).read_text())["files"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not isinstance(listed, list):
        return None
    return {name for name in map(_listed_name, listed) if name is not None}


def _entries(folder: Path) -> set[str]:
    """Every file and folder under ``folder``, as paths relative to it (symbolic links are not followed)."""
    found: set[str] = set()
    for root, directories, files in os.walk(folder):
        relative = Path(root).relative_to(folder)
        found.update(str(relative / name) for name in (*directories, *files))
    return found


def _foreign_entries(folder: Path, own: set[str]) -> set[str]:
    """What in ``folder`` the report did not write: entries neither listed in ``own`` nor a folder holding them."""
    holding = {str(parent) for name in own for parent in Path(name).parents if str(parent) != "."}
    return _entries(folder) - own - holding - {REPORT_MARKER}


def check_report_folder(folder: str | Path, *, force: bool = False, what: str = "report folder") -> Path:
    """Check, before any work, that a report may be written to ``folder``; returns it.

    A report folder may be absent, empty or an earlier report of the
    workbench (it holds :data:`REPORT_MARKER`); any other folder is refused
    unless ``force``, and even then :func:`writing_report_folder` only adds
    and replaces the report's own files beside what is there.

    Raises
    ------
    OutputTargetError
        One line naming the folder and the cause: a file in its place; a
        folder of other files (without ``force``); no permission.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputTargetError(f"cannot write the {what} {folder}: {os.strerror(errno.ENOTDIR)}")
    if folder.is_dir() and not force and report_files(folder) is None and any(folder.iterdir()):
        raise OutputTargetError(
            f"{folder} is a folder of other files, not a report of the workbench; refusing to write into it "
            "(give 'force' to add the report's files beside them, or choose another folder)", options=("force",))
    _check_writable_directory(folder, what)
    if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
        raise OutputTargetError(f"cannot write the {what} {folder}: {os.strerror(errno.EACCES)}")
    return folder


@contextmanager
def writing_report_folder(folder: str | Path, *, force: bool = False) -> Iterator[Path]:
    """Yield a fresh hidden folder to draw the report in; put its files in ``folder`` when the block ends normally.

    The report's files are listed in :data:`REPORT_MARKER` inside the folder.
    When ``folder`` is absent or holds nothing but an earlier report's own
    files, the new folder replaces it whole and in one step (as
    :func:`replacing_directory`). When it holds anything else (the input
    archive, the user's notes, a folder accepted with ``force``), each of
    the report's files is moved in on its own, the earlier report's files the
    new one lacks are removed, and nothing else is touched; the marker is
    written last. On an exception ``folder`` is left as it was.

    Raises
    ------
    OutputTargetError
        As :func:`check_report_folder`; or a file of the report would replace
        a folder that is there.
    """
    folder = check_report_folder(folder, force=force)
    fresh = _new_partial(folder, "report folder")
    try:
        yield fresh
        written = sorted(name for name in _entries(fresh) if not (fresh / name).is_dir())
        (fresh / REPORT_MARKER).write_text(json.dumps({"files": written}, indent=1) + "\n")
        earlier = (report_files(folder) or set()) if folder.is_dir() else set()
        if folder.is_dir() and (folder.is_symlink() or _foreign_entries(folder, earlier)):  # a link stays a link
            _merge_report(fresh, folder, written, earlier)
        else:
            _swap_in(fresh, folder)
    finally:
        if fresh.exists():
            shutil.rmtree(fresh, ignore_errors=True)


def _merge_report(fresh: Path, folder: Path, written: list[str], earlier: set[str]) -> None:
    """Move the report's files into a folder that holds other files too, touching nothing else."""
    for name in written:
        target = folder / name
        if target.is_dir() and not target.is_symlink():
            raise OutputTargetError(f"cannot write the report file {target}: {os.strerror(errno.EISDIR)}")
    for name in written:
        target = folder / name
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(fresh / name, target)
    for name in earlier.difference(written):
        stale = folder / name
        if stale.is_symlink() or stale.is_file():
            stale.unlink()
    os.replace(fresh / REPORT_MARKER, folder / REPORT_MARKER)  # last: the folder is marked once its files are in


def _value_bytes(value: Any) -> bytes:
    if isinstance(value, h5py.Empty):
        return b"<empty>"
    if isinstance(value, bytes):
        return value
    if isinstance(value, str):
        return value.encode("utf-8")
    array = np.asarray(value)
    if array.dtype.kind == "O":
        return repr([_value_bytes(item) for item in array.ravel().tolist()]).encode() + repr(array.shape).encode()
    return array.dtype.str.encode() + repr(array.shape).encode() + np.ascontiguousarray(array).tobytes()


def _digest(obj: h5py.HLObject) -> str:
    crc = 0
    for name in sorted(obj.attrs.keys()):
        if name in (DIGEST_ATTRIBUTE, CHECKSUM_ATTRIBUTE):
            continue
        crc = zlib.crc32(name.encode() + b"\0" + _value_bytes(obj.attrs[name]) + b"\0", crc)
    if isinstance(obj, h5py.Dataset):
        crc = zlib.crc32(b"data\0", crc)
        crc = zlib.crc32(_value_bytes(h5py.Empty(obj.dtype) if obj.shape is None else obj[()]), crc)
    else:
        crc = zlib.crc32(("members\0" + "\0".join(sorted(obj.keys()))).encode(), crc)
    return f"{crc:08x}"


def _objects(handle: h5py.File) -> list[h5py.HLObject]:
    found: list[h5py.HLObject] = [handle]
    handle.visititems(lambda name, obj: found.append(obj))
    return found


def write_checksums(handle: h5py.File) -> None:
    """Store the digest of every group's and dataset's content in its ``vehid_digest`` attribute.

    Call last, when nothing else will change: the digest covers the object's
    attributes, a dataset's bytes and a group's member names.
    """
    handle.attrs[CHECKSUM_ATTRIBUTE] = CHECKSUM_SCHEME
    for obj in _objects(handle):
        obj.attrs[DIGEST_ATTRIBUTE] = _digest(obj)


def verify_checksums(handle: h5py.File, path: str | Path) -> None:
    """Check every digest written by :func:`write_checksums`.

    Raises
    ------
    ArchiveError
        Naming the first dataset or group whose content no longer matches
        its digest (or lacks one in an archive that promises digests).
        An archive without the root ``vehid_checksums`` attribute (written
        before checksums existed) is not checked.
    """
    if CHECKSUM_ATTRIBUTE not in handle.attrs:
        return
    scheme = handle.attrs[CHECKSUM_ATTRIBUTE]
    if scheme != CHECKSUM_SCHEME:
        raise ArchiveError(f"{path} uses the checksum scheme {scheme!r}, which this workbench does not know")
    for obj in _objects(handle):
        kind = "dataset" if isinstance(obj, h5py.Dataset) else "group"
        try:
            stored = obj.attrs.get(DIGEST_ATTRIBUTE)
            actual = _digest(obj)
        except (OSError, RuntimeError, ValueError, TypeError) as exc:
            raise ArchiveError(f"{path} is corrupt: its {kind} {obj.name} cannot be read ({exc})") from None
        if stored is None:
            raise ArchiveError(f"{path} is corrupt: its {kind} {obj.name} has no checksum")
        if stored != actual:
            raise ArchiveError(
                f"{path} is corrupt: the {kind} {obj.name} does not match its checksum "
                "(changed on disk after it was written)"
            )


_RENAME_EXCHANGE = 2  # renameat2 flag (Linux): swap two names atomically
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two existing names in one step where the system can (Linux renameat2); False where it cannot."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    result = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    return result == 0


@contextmanager
def replacing_directory(folder: str | Path) -> Iterator[Path]:
    """Yield a fresh hidden directory beside ``folder``; swap it in for ``folder`` when the block ends normally.

    On Linux the old and new folders change places in one ``renameat2``
    call, so at every instant ``folder`` is either the complete old folder
    or the complete new one; elsewhere the old folder is first renamed aside
    (a crash in between leaves it under its hidden name). The old folder is
    removed afterwards; on an exception the new one is removed and the old
    one is left as it was. Leftovers of writers that were killed (hidden
    ``.<name>.*.partial`` folders of dead processes) are removed first.
    """
    folder = check_output_folder(folder, what="folder")
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputTargetError(f"cannot write the folder {folder}: {os_error_text(exc)}") from None
    fresh = _new_partial(folder, "folder")
    try:
        yield fresh
        _swap_in(fresh, folder)
    finally:
        if fresh.exists():
            shutil.rmtree(fresh, ignore_errors=True)


def _partial_name(folder: Path) -> Path:
    """A hidden sibling of ``folder`` that names this process, so that a later writer can tell it is dead."""
    return folder.with_name(f".{folder.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.partial")


def _new_partial(folder: Path, what: str) -> Path:
    """A fresh hidden folder beside ``folder`` to write in, once dead writers' leftovers are removed."""
    try:
        _remove_dead_partials(folder)
        fresh = _partial_name(folder)
        fresh.mkdir()
    except OSError as exc:
        raise OutputTargetError(f"cannot write the {what} {folder}: {os_error_text(exc)}") from None
    return fresh


def _swap_in(fresh: Path, folder: Path) -> None:
    """Put the complete folder ``fresh`` in the place of ``folder`` (if any) and remove the old one.

    On Linux the two change places in one ``renameat2`` call; elsewhere the
    old folder is renamed aside first, so a crash in between leaves it under
    a hidden name rather than half-replaced.
    """
    if folder.exists() and _exchange(fresh, folder):
        shutil.rmtree(fresh, ignore_errors=True)  # now the old folder
    elif folder.exists():
        aside = _partial_name(folder)
        os.replace(folder, aside)
        os.replace(fresh, folder)
        shutil.rmtree(aside, ignore_errors=True)
    else:
        os.replace(fresh, folder)


def _remove_dead_partials(folder: Path) -> None:
    for candidate in folder.parent.glob(f".{folder.name}.*.partial"):
        parts = candidate.name[len(folder.name) + 2:].split(".")
        try:
            pid = int(parts[0])
        except (ValueError, IndexError):
            continue
        if pid == os.getpid() or _alive(pid):
            continue
        shutil.rmtree(candidate, ignore_errors=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
