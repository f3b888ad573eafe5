"""A small progress display on standard error.

It draws only when standard error is a terminal and the user did not ask for
quiet output, so that piped output and ``--json`` summaries stay clean.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

__all__ = ["Progress"]


class Progress:
    """A one-line progress bar: ``label [#####.....] 5/10 12.3 s``.

    Parameters
    ----------
    total : int
        Number of steps expected.
    label : str
        Text before the bar.
    enabled : bool, optional
        Draw at all; default: only when ``stream`` is a terminal.
    stream : file, optional
        Where to draw; default ``sys.stderr``.
    """

    def __init__(self, total: int, label: str, *, enabled: bool | None = None, stream: TextIO | None = None):
        self.total = max(int(total), 1)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = (self.stream.isatty() if enabled is None else enabled)
        self.count = 0
        self.note = ""
        self._start = time.perf_counter()

    def __enter__(self) -> "Progress":
        self._draw()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def advance(self, steps: int = 1, note: str = "") -> None:
        """Count ``steps`` more done; ``note`` is shown after the bar (e.g. the current fit)."""
        self.count = min(self.count + steps, self.total)
        self.note = note
        self._draw()

    def _draw(self) -> None:
        if not self.enabled:
            return
        width = 24
        filled = int(width * self.count / self.total)
        elapsed = time.perf_counter() - self._start
        line = (
            f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] "
            f"{self.count}/{self.total} {elapsed:6.1f} s {self.note}"
        )
        self.stream.write(line[:160].ljust(80))
        self.stream.flush()

    def close(self) -> None:
        """Finish the line."""
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
            self.enabled = False
