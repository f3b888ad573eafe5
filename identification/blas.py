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
:func:`vehid.identification.identify` compute with one BLAS thread.

A user who has chosen a thread count in the environment (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` and the like) keeps it: the limit
applies only where none is set. The limit is lifted when the computation
ends, so a notebook's own work keeps its threads.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator

__all__ = ["THREAD_VARIABLES", "blas_threads_chosen", "one_blas_thread"]

# The variables by which a user sets the BLAS (and OpenMP) thread count of OpenBLAS, MKL, BLIS and Accelerate.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def blas_threads_chosen() -> bool:
    """Whether the environment sets a BLAS or OpenMP thread count (the user's choice, kept)."""
    return any(os.environ.get(name, "").strip() for name in THREAD_VARIABLES)


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Compute with one BLAS thread inside the block, unless the environment chose a thread count.

    NumPy's and SciPy's BLAS libraries are loaded first, so that both are limited (a
    library loaded inside the block would keep its threads).
    """
    if blas_threads_chosen():
        yield
        return
    import numpy  # noqa: F401  (loads NumPy's BLAS)
    import scipy.linalg  # noqa: F401  (loads SciPy's BLAS, a separate library)
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield
