"""The BLAS thread pool while the workbench computes.

The workbench's linear algebra runs on small matrices (a filter's covariance
of a few dozen states, a least-squares problem of a few hundred columns),
time step after time step. A multithreaded BLAS (OpenBLAS by default in
NumPy's and SciPy's wheels) starts its threads on such products and leaves
them spinning between calls: on a 2-core machine one `vehid identify` run
spent 9.3 s of CPU for 7.1 s of wall time with two BLAS threads and 6.8 s
for 7.0 s with one (``benchmarks/blas_threads.py`` measures it), and
parallel work (two test workers, a study's worker processes) lost the spun
time to each other. So the workbench's commands, its worker processes and
:func:`vehid.identification.identify` compute with one BLAS thread, and so do the
estimators' entry points (``identify_iekf`` and its spline, scheduled and grey-box
forms, ``identify_with``) where a script calls them directly.

A user who has chosen a thread count in the environment (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` and the like) keeps it: the limit
applies only where none is set. The limit is lifted when the computation
ends, so a notebook's own work keeps its threads.
"""

from __future__ import annotations

import functools
import os
import sys
from contextlib import ExitStack, contextmanager
from typing import Any, Callable, Iterator

__all__ = ["THREAD_VARIABLES", "blas_threads_chosen", "one_blas_thread", "on_one_blas_thread"]

# The variables by which a user sets the BLAS (and OpenMP) thread count of OpenBLAS, MKL, BLIS and Accelerate.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")

# What the block sets: each BLAS's own variable (OpenMP's, read by other libraries too, is left alone).
_LIBRARY_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


def blas_threads_chosen() -> bool:
    """Whether the environment sets a BLAS or OpenMP thread count (the user's choice, kept)."""
    return any(os.environ.get(name, "").strip() for name in THREAD_VARIABLES)


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Compute with one BLAS thread inside the block, unless the environment chose a thread count.

    A BLAS library loaded inside the block (a command's first NumPy import, SciPy's
    own BLAS) reads its thread variable (``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``,
    ``BLIS_NUM_THREADS``), set to 1 for the block and the processes started in it,
    and unset afterwards (none was set, or the block would not limit anything). Libraries already loaded
    (NumPy imported by a notebook) are limited at run time through threadpoolctl,
    and given their threads back when the block ends. A command therefore pays no
    import for the limit before its work begins.
    """
    if blas_threads_chosen():
        yield
        return
    with ExitStack() as loaded_libraries:
        if "numpy" in sys.modules:
            import scipy.linalg  # noqa: F401  (its own BLAS, loaded before the variables are set: it keeps its threads after)
            from threadpoolctl import threadpool_limits

            loaded_libraries.enter_context(threadpool_limits(limits=1, user_api="blas"))
        for name in _LIBRARY_VARIABLES:
            os.environ[name] = "1"
        try:
            yield
        finally:
            for name in _LIBRARY_VARIABLES:
                os.environ.pop(name, None)


def on_one_blas_thread(function: Callable[..., Any]) -> Callable[..., Any]:
    """``function``, computing inside :func:`one_blas_thread`: the estimators' entry points, so that a
    script or notebook calling them directly computes as the commands do."""

    @functools.wraps(function)
    def on_one_thread(*args: Any, **kwargs: Any) -> Any:
        with one_blas_thread():
            return function(*args, **kwargs)

    return on_one_thread
