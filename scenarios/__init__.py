"""Studies that wire the vehicle model and the identification methods together, and the ``vehid`` CLI."""

from ._parent_watch import watch_if_worker as _watch_if_worker

_watch_if_worker()  # first of all: a worker whose parent dies while it starts up must not outlive it
