"""Where the workbench writes its output."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["results_directory"]


def results_directory() -> Path:
    """The results folder: ``$VEHID_RESULTS_DIR`` if set, else ``results/`` in the working directory.

    Created if missing.
    """
    path = Path(os.environ.get("VEHID_RESULTS_DIR") or "results")
    path.mkdir(parents=True, exist_ok=True)
    return path
