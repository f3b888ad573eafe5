"""Clean shutdown: signals stop a command and every worker process it started, with nothing left behind.

:func:`stopping_on_signals` makes SIGTERM and SIGHUP unwind the command as
Ctrl-C does, through its ``finally`` blocks, so that temporary files are
removed, locks released and archives left at their last checkpoint.
:func:`run_in_workers` runs jobs in spawned processes owned by the caller:
on any exception there every worker is terminated, killed after
:data:`GRACE` seconds and reaped. Workers ignore SIGINT (the parent decides)
and die with their parent even under ``kill -9`` (:mod:`vehid.scenarios._parent_watch`).
"""

from __future__ import annotations

import errno
import os
import pickle
import queue as queue_module
import signal
import sys
import threading
import time
from contextlib import contextmanager
from multiprocessing import get_context
from typing import Any, Callable, Iterator, Sequence

from vehid.identification.blas import one_blas_thread
from vehid.identification.errors import WorkbenchError

from ._parent_watch import ENVIRONMENT, die_with_parent

__all__ = [
    "GRACE",
    "PATH_ERRNOS",
    "Interrupted",
    "WorkerError",
    "stopping_on_signals",
    "raise_if_interrupted",
    "signal_name",
    "run_in_workers",
]

#: Seconds a terminated worker gets to end before it is killed.
GRACE = 2.0

#: Operating-system errors that mean a bad path given by the user (exit status 2); others are failures (1).
PATH_ERRNOS = frozenset({errno.ENOENT, errno.EACCES, errno.EPERM, errno.EISDIR, errno.ENOTDIR, errno.EROFS,
                         errno.ENAMETOOLONG, errno.EEXIST, errno.ELOOP})

_STOPPING_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))

#: Stopping signals received within the innermost :func:`stopping_on_signals` block, oldest first.
_RECEIVED: list[int] = []


class Interrupted(KeyboardInterrupt):
    """A signal asked the command to stop (SIGTERM, SIGHUP); handled like Ctrl-C."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class WorkerError(WorkbenchError):
    """A worker process ended without delivering its job's result (killed, crashed)."""


def signal_name(exc: BaseException) -> tuple[str, int]:
    """The signal behind an interrupt and the exit status it gives (128 + its number)."""
    signum = getattr(exc, "signum", signal.SIGINT)
    return signal.Signals(signum).name, 128 + int(signum)


@contextmanager
def stopping_on_signals() -> Iterator[None]:
    """Within the block, SIGTERM, SIGHUP and (where Python handles it) SIGINT raise :class:`Interrupted` in the main thread.

    A signal whose exception the interpreter swallows (the handler ran inside
    a weakref callback or a ``__del__``, where Python only reports it as
    "Exception ignored") is still acted on: :class:`Interrupted` is raised
    again where :func:`raise_if_interrupted` is called and at the latest when
    the block ends, so the command never finishes as if it had not been asked
    to stop. Outside the main thread (where Python cannot handle signals) the
    block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        # Remembered before raising: a handler that runs inside a weakref callback, a __del__ or a
        # library's cleanup has its exception printed as "Exception ignored" and dropped, and the
        # command would otherwise finish with exit status 0 as if never asked to stop.
        _RECEIVED.append(signum)
        raise Interrupted(signum)

    previous_hook = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if isinstance(info.exc_value, Interrupted):  # remembered in _RECEIVED and raised again below: not news
            return
        previous_hook(info)

    sys.unraisablehook = unraisable
    # Ctrl-C too, where Python's own KeyboardInterrupt handler has it (not where it is ignored): that
    # handler's exception can be swallowed in the same places, and is then remembered alike
    handled = _STOPPING_SIGNALS + ((signal.SIGINT,) if signal.getsignal(signal.SIGINT) is signal.default_int_handler
                                   else ())
    previous = {signum: signal.signal(signum, stop) for signum in handled}
    outer = list(_RECEIVED)
    _RECEIVED.clear()
    try:
        yield
        raise_if_interrupted()
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # a failure that ran over a swallowed signal: the signal decides the exit
        if _RECEIVED:
            raise Interrupted(_RECEIVED[0]) from exc
        raise
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        sys.unraisablehook = previous_hook
        _RECEIVED[:] = outer


def raise_if_interrupted() -> None:
    """Raise :class:`Interrupted` if a stopping signal arrived whose exception was swallowed on the way.

    Long loops call it where they wait (as :func:`run_in_workers` does) so that
    such a signal stops the command within a moment rather than at its end.
    """
    if _RECEIVED:
        raise Interrupted(_RECEIVED[0])



def _portable(exc: BaseException) -> BaseException:
    try:
        pickle.loads(pickle.dumps(exc))
        return exc
    except Exception:  # an exception that does not pickle still reaches the parent, as text
        return WorkerError(f"{type(exc).__name__}: {exc}")


def _worker_main(function: Callable[..., Any], jobs: Any, results: Any, parent_pid: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent stops us; Ctrl-C is its to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent_pid)  # already done at import of scenarios when the environment named us; idempotent

    def report(message: Any) -> None:
        results.put(("message", None, message))

    with one_blas_thread():  # as in the parent command (vehid.identification.blas)
        while True:
            item = jobs.get()
            if item is None:
                return
            index, job = item
            try:
                value = function(job, report)
            except BaseException as exc:  # handed to the parent, which stops the others
                results.put(("error", index, _portable(exc)))
                return
            results.put(("done", index, value))


def _stop(processes: Sequence[Any]) -> None:
    """Terminate every live worker, kill those still alive after GRACE seconds, reap them all."""
    for process in processes:
        if process.is_alive():
            process.terminate()
    deadline = time.monotonic() + GRACE
    for process in processes:
        process.join(max(0.0, deadline - time.monotonic()))
    for process in processes:
        if process.is_alive():
            process.kill()
            process.join(GRACE)


def run_in_workers(
    function: Callable[[Any, Callable[[Any], None]], Any],
    jobs: Sequence[Any],
    workers: int,
    *,
    on_message: Callable[[Any], None] | None = None,
    on_result: Callable[[Any, Any], None] | None = None,
) -> list[Any]:
    """Run ``function(job, report)`` for every job in ``workers`` spawned processes; results in job order.

    Parameters
    ----------
    function : callable
        A top-level (picklable) function; ``report(message)`` sends a
        picklable message to this process (progress).
    jobs : sequence
        Picklable jobs, started in the order given.
    workers : int
        Processes at once.
    on_message : callable, optional
        Called in this process with each message as it arrives.
    on_result : callable, optional
        Called in this process with ``(job, result)`` as each job finishes
        (e.g. to checkpoint it).

    Raises
    ------
    BaseException
        The first job's exception (the other workers are stopped first);
        :class:`WorkerError` when a worker died without a result; an
        interrupt of this process, after every worker has been stopped.
    """
    context = get_context("spawn")  # forking a process that holds threads (BLAS, CasADi) is unsafe
    job_queue, results = context.Queue(), context.Queue()
    for index, job in enumerate(jobs):
        job_queue.put((index, job))
    for _ in range(workers):
        job_queue.put(None)
    processes = [context.Process(target=_worker_main, args=(function, job_queue, results, os.getpid()),
                                 name=f"vehid-worker-{k}", daemon=True) for k in range(workers)]
    outcomes: dict[int, Any] = {}
    try:
        announced = os.environ.get(ENVIRONMENT)
        os.environ[ENVIRONMENT] = str(os.getpid())  # read by each worker at its very start (scenarios/__init__)
        try:
            for process in processes:
                process.start()
        finally:
            if announced is None:
                del os.environ[ENVIRONMENT]
            else:
                os.environ[ENVIRONMENT] = announced
        all_ended_before = False
        while len(outcomes) < len(jobs):
            raise_if_interrupted()
            crashed = [p for p in processes if p.exitcode not in (None, 0)]
            if crashed:  # killed or crashed: its job will never report
                raise WorkerError(f"worker process {crashed[0].pid} ended with exit code {crashed[0].exitcode} "
                                  "before its job was done")
            try:
                kind, index, value = results.get(timeout=0.2)
            except queue_module.Empty:
                # every worker gone and the pipe empty twice in a row: what they sent has been read
                all_ended = all(process.exitcode is not None for process in processes)
                if all_ended and all_ended_before:
                    raise WorkerError("the worker processes ended before every job was done") from None
                all_ended_before = all_ended
                continue
            if kind == "message":
                if on_message is not None:
                    on_message(value)
            elif kind == "error":
                raise value
            else:
                outcomes[index] = value
                if on_result is not None:
                    on_result(jobs[index], value)
        for process in processes:
            process.join(GRACE)
    finally:
        _stop(processes)
        for pipe in (job_queue, results):
            pipe.cancel_join_thread()
            pipe.close()
    return [outcomes[index] for index in range(len(jobs))]
