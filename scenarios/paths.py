"""Where the workbench writes its output.

One rule for every command: a path given on the command line (``--out``,
``--save-model``) means what it means to every other program, relative to
the working directory; only a command's default output, when no path is
given, goes to the results folder (``$VEHID_RESULTS_DIR``, else ``results/``).
"""

from __future__ import annotations

import os
from pathlib import Path

from vehid.identification.choices import HDF5_SUFFIXES

__all__ = ["OUT_RULE", "HDF5_SUFFIXES", "FIGURE_SUFFIXES", "results_directory", "results_path", "check_figure_target"]

#: The rule, as each command's ``--help`` states it.
OUT_RULE = "a relative path is taken from the working directory"
#: The files a figure is written to.
FIGURE_SUFFIXES = (".png", ".pdf", ".svg")


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


def check_figure_target(figure: str | os.PathLike | None, force: bool) -> Path | None:
    """The figure's path, checked before any work: a figure suffix, an existing folder, no file unless ``force``.

    Errors name the options ``figure`` and ``force`` (:class:`~vehid.identification.errors.OptionError`).
    """
    from vehid.identification.errors import OptionError

    if figure is None:
        return None
    path = Path(figure)
    if path.suffix.lower() not in FIGURE_SUFFIXES:
        raise OptionError(f"'figure' takes a {', '.join(FIGURE_SUFFIXES)} file; got {str(figure)!r}", "figure")
    if not path.parent.is_dir():
        raise OptionError(f"'figure': no folder {str(path.parent)!r}", "figure")
    if path.is_dir() or (path.exists() and not force):
        raise OptionError(f"'figure' {str(figure)!r} exists: choose another name or give 'force'", "figure", "force")
    return path
