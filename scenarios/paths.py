"""Where the workbench writes its output, and which run wrote it.

One rule for every command: a path given on the command line (``--out``,
``--save-model``) means what it means to every other program, relative to
the working directory; only a command's default output, when no path is
given, goes to the results folder (``$VEHID_RESULTS_DIR``, else ``results/``).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

__all__ = ["OUT_RULE", "HDF5_SUFFIXES", "results_directory", "results_path", "run_digest"]

#: The rule, as each command's ``--help`` states it.
OUT_RULE = "a relative path is taken from the working directory"


#: File name endings of the HDF5 files the workbench writes.
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")


def results_directory() -> Path:
    """The results folder: ``$VEHID_RESULTS_DIR`` if set, else ``results/`` in the working directory.

    Created if missing.
    """
    path = Path(os.environ.get("VEHID_RESULTS_DIR") or "results")
    path.mkdir(parents=True, exist_ok=True)
    return path


def results_path(out: str | Path | None, default: str) -> Path:
    """Where to write: ``out`` as given (relative to the working directory), else ``default`` in the results folder."""
    if out:
        return Path(out)
    return results_directory() / default


# Options that choose where or how the output is shown or written, or how the work is spread over
# processes: they change no result, so rerunning with other values is the same run.
_NOT_THE_RUN = frozenset({
    "handler", "out", "force", "resume", "save_model", "json", "quiet", "verbose", "strict", "no_report",
    "workers", "executor", "scheduler", "output_run",
})


def _file_digest(path: str) -> str:
    digest = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _identity(value: Any) -> Any:
    """A setting as it enters the run's digest: a file named by its content, so a moved copy is the same run."""
    if isinstance(value, (list, tuple)):
        return [_identity(item) for item in value]
    if isinstance(value, (str, os.PathLike)) and str(value):
        try:
            if os.path.isfile(value):  # read each time: a timestamp may not change when a file is rewritten
                return {"file": _file_digest(os.fspath(value))}
        except OSError:
            pass  # unreadable here: the command's own check names it
    return value


def run_digest(args: Any) -> str:
    """The digest that says which run a command line asks for: the command, its settings and its input files' content.

    ``args`` is the parsed command line (its ``handler`` and option attributes).

    Two command lines with the same digest compute the same thing, so the
    second may replace the first's output; where, how verbosely and by how
    many processes the work is done does not enter (see ``_NOT_THE_RUN``).
    """
    handler = getattr(args, "handler", None)
    command = f"{getattr(handler, '__module__', '')}.{getattr(handler, '__name__', '')}"
    settings = {name: _identity(value) for name, value in sorted(vars(args).items()) if name not in _NOT_THE_RUN}
    text = json.dumps({"command": command, "settings": settings}, sort_keys=True, default=str)
    return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()
