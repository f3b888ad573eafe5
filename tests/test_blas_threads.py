"""The workbench computes with one BLAS thread and leaves the process's BLAS as it found it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from vehid.identification.blas import blas_threads_chosen

pytest.importorskip("threadpoolctl")


def _seen_by_a_new_process(code: str) -> dict:
    """What ``code``, run in a new interpreter, printed as JSON (the suite's own processes are limited already)."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_a_fresh_process_loads_its_blas_on_one_thread_inside_the_block_and_sets_nothing_after():
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
        "print(json.dumps({'inside': inside, 'child': child, 'same': before == after}))\n"
    )
    seen = _seen_by_a_new_process(code)
    if blas_threads_chosen():  # the machine's environment chose a count: kept, and nothing to check here
        return
    assert seen["inside"] and set(seen["inside"]) == {1}
    assert seen["child"] == "1"  # worker processes started in the block inherit the limit
    assert seen["same"]


def test_libraries_already_loaded_are_limited_inside_and_given_their_threads_back():
    # a notebook's process: NumPy's and SciPy's BLAS are loaded before the block (in a process of its own,
    # since the suite's processes compute on one thread already)
    code = (
        "import json\n"
        "import numpy, scipy.linalg, threadpoolctl\n"
        "from vehid.identification.blas import one_blas_thread\n"
        "def counts():\n"
        "    return [e['num_threads'] for e in threadpoolctl.threadpool_info() if e['user_api'] == 'blas']\n"
        "before = counts()\n"
        "with one_blas_thread():\n"
        "    inside = counts()\n"
        "print(json.dumps({'before': before, 'inside': inside, 'after': counts()}))\n"
    )
    seen = _seen_by_a_new_process(code)
    assert seen["after"] == seen["before"]
    if not blas_threads_chosen():
        assert seen["inside"] and set(seen["inside"]) == {1}
    else:
        assert seen["inside"] == seen["before"]
