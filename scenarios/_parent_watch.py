"""Let a worker process end when the process that started it ends.

Standard library only, because :mod:`scenarios` imports it first: a spawned
worker imports the parent's main module (the command line, and with it the
whole workbench) before any worker code runs, which takes seconds, and a
parent killed meanwhile must not leave it running. The parent names itself
in the environment variable :data:`ENVIRONMENT` while it starts its workers.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time

ENVIRONMENT = "VEHID_WORKER_PARENT"
_PR_SET_PDEATHSIG = 1
_watched: set[int] = set()


def die_with_parent(parent_pid: int) -> None:
    """End this process (SIGKILL on Linux, else within half a second) when ``parent_pid`` is no longer its parent."""
    if parent_pid in _watched:
        return
    _watched.add(parent_pid)
    if sys.platform.startswith("linux"):
        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # pragma: no cover - no prctl: the watchdog below still works
            pass
    if os.getppid() != parent_pid:  # the parent died before we could ask
        os._exit(1)

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def watch_if_worker() -> None:
    """In a worker started by :func:`vehid.scenarios.shutdown.run_in_workers`, die with the parent from now on."""
    value = os.environ.get(ENVIRONMENT, "")
    if value.isdigit() and int(value) != os.getpid():
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group; the parent stops us
        die_with_parent(int(value))
