"""Where the workbench writes its output."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["results_directory", "results_path"]


def results_directory() -> Path:
    """The results folder: ``$VEHID_RESULTS_DIR`` if set, else ``results/`` in the working directory.

    Created if missing.
    """
    path = Path(os.environ.get("VEHID_RESULTS_DIR") or "results")
    path.mkdir(parents=True, exist_ok=True)
    return path


def results_path(out: str | Path | None, default: str) -> Path:
    """``out`` (``default`` when not given) as a path, relative ones under the results folder."""
    path = Path(out or default)
    return path if path.is_absolute() else results_directory() / path
