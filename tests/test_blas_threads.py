"""The workbench computes with one BLAS thread and leaves the process's BLAS as it found it."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from vehid.identification.blas import THREAD_VARIABLES

pytest.importorskip("threadpoolctl")

# A thread count of the user's: two threads. A BLAS caps the count at the cores the process may use,
# so the count expected is the smaller of the two (the new process reports its cores).
CHOSEN = "2"


def _seen_by_a_new_process(code: str, chosen: str | None) -> dict:
    """What ``code``, run in a new interpreter, printed as JSON.

    The suite's own processes are limited already, and the machine's environment may set a thread
    count of its own: the new process sees no thread variable but ``OPENBLAS_NUM_THREADS=chosen``
    (none at all for ``chosen=None``), so that both cases are checked on every machine.
    """
    environment = {name: value for name, value in os.environ.items() if name not in THREAD_VARIABLES}
    if chosen is not None:
        environment["OPENBLAS_NUM_THREADS"] = environment["MKL_NUM_THREADS"] = chosen
        environment["BLIS_NUM_THREADS"] = chosen
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False,
                          env=environment)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.parametrize("chosen", [None, CHOSEN], ids=["no-count-chosen", "count-chosen"])
def test_a_fresh_process_loads_its_blas_on_one_thread_inside_the_block_and_sets_nothing_after(chosen):
    # a command's process: NumPy and SciPy are first imported inside the block, their libraries read the
    # variable then; afterwards the environment is as before (processes the command starts later are not limited)
    code = (
        "import json, os\n"
        "from vehid.identification.blas import one_blas_thread\n"
        "before = {k: os.environ.get(k) for k in ('OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS', 'BLIS_NUM_THREADS')}\n"
        "with one_blas_thread():\n"
        "    import numpy, scipy.linalg, threadpoolctl\n"
        "    inside = [e['num_threads'] for e in threadpoolctl.threadpool_info() if e['user_api'] == 'blas']\n"
        "    child = os.environ.get('OPENBLAS_NUM_THREADS')\n"
        "after = {k: os.environ.get(k) for k in before}\n"
        "print(json.dumps({'inside': inside, 'child': child, 'same': before == after,\n"
        "                  'cores': len(os.sched_getaffinity(0))}))\n"
    )
    seen = _seen_by_a_new_process(code, chosen)
    assert seen["same"]
    assert seen["inside"]  # NumPy's BLAS is seen, or the counts below say nothing
    if chosen is None:
        assert set(seen["inside"]) == {1}
        assert seen["child"] == "1"  # worker processes started in the block inherit the limit
    else:  # the user's choice is kept, in this process and for the processes it starts
        assert set(seen["inside"]) == {min(int(chosen), seen["cores"])}
        assert seen["child"] == chosen


@pytest.mark.parametrize("chosen", [None, CHOSEN], ids=["no-count-chosen", "count-chosen"])
def test_libraries_already_loaded_are_limited_inside_and_given_their_threads_back(chosen):
    # a notebook's process: NumPy's and SciPy's BLAS are loaded before the block (in a process of its own,
    # since the suite's processes compute on one thread already)
    code = (
        "import json, os\n"
        "import numpy, scipy.linalg, threadpoolctl\n"
        "from vehid.identification.blas import one_blas_thread\n"
        "def counts():\n"
        "    return [e['num_threads'] for e in threadpoolctl.threadpool_info() if e['user_api'] == 'blas']\n"
        "before = counts()\n"
        "with one_blas_thread():\n"
        "    inside = counts()\n"
        "print(json.dumps({'before': before, 'inside': inside, 'after': counts(),\n"
        "                  'cores': len(os.sched_getaffinity(0))}))\n"
    )
    seen = _seen_by_a_new_process(code, chosen)
    assert seen["before"] and seen["after"] == seen["before"]
    if chosen is None:
        assert set(seen["inside"]) == {1}
    else:
        assert seen["inside"] == seen["before"] and set(seen["before"]) == {min(int(chosen), seen["cores"])}
