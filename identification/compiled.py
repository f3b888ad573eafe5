"""Compile CasADi functions to native code, cached on disk.

A function is generated to C, hashed (source, compiler flags, CasADi version), compiled once into a
shared library under the cache directory (``$VEHID_CACHE_DIR``, else ``$XDG_CACHE_HOME/vehid`` or
``~/.cache/vehid``) and loaded with ``casadi.external``; without a C compiler it runs in CasADi's
virtual machine and a warning says so. The key holds no host name, so a shared cache works: it names the
machine type, the compiler's own account of its version (a compiler upgrade recompiles rather than
loading a library built by another), native code also the CPU type; processes on one host wait for each
other's build (a file lock).
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import casadi as ca
import numpy as np

__all__ = [
    "cache_directory",
    "compile_function",
    "build_shared_library",
    "generate_c",
    "find_c_compiler",
    "NoCompilerWarning",
    "CompiledRecursion",
    "compile_driver",
]

_LOCK = threading.RLock()
_LOADED: dict[str, ca.Function] = {}


class NoCompilerWarning(RuntimeWarning):
    """No C compiler was found; CasADi's virtual machine runs instead (slower)."""


def cache_directory() -> Path:
    """Directory where compiled functions are kept."""
    explicit = os.environ.get("VEHID_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "vehid"


def find_c_compiler() -> str | None:
    """The C compiler to use: ``$CC`` if set, else ``cc``, ``gcc`` or ``clang`` on PATH."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def compile_function(
    function: ca.Function,
    *,
    optimisation: str = "-O2",
    allow_fallback: bool = True,
) -> ca.Function:
    """Return a compiled equivalent of ``function``, built once and cached.

    Parameters
    ----------
    function : casadi.Function
        The function to compile (SX or MX based). Its name names the files.
    optimisation : str
        Optimisation flag handed to the compiler. Large generated functions
        compile much faster at ``-O1`` for a small loss of speed.
    allow_fallback : bool
        Without a C compiler, return ``function`` itself with a
        :class:`NoCompilerWarning` (True) or raise ``RuntimeError`` (False).

    Returns
    -------
    casadi.Function
        Same inputs, outputs and names, evaluated by native code.
    """
    compiler = find_c_compiler()
    if compiler is None:
        if not allow_fallback:
            raise RuntimeError("no C compiler found (set CC or install gcc)")
        warnings.warn(
            f"no C compiler found: {function.name()} runs in CasADi's virtual machine "
            "(install gcc or set CC for compiled speed)",
            NoCompilerWarning,
            stacklevel=2,
        )
        return function

    name = function.name()
    library = build_shared_library(name, generate_c(function), optimisation=optimisation, compiler=compiler)
    with _LOCK:
        key = str(library)
        if key not in _LOADED:
            _LOADED[key] = ca.external(name, key)
        return _LOADED[key]


def generate_c(function: ca.Function, *more: ca.Function) -> str:
    """The C source CasADi generates for ``function`` and any ``more`` (no header, no main).

    It defines ``int NAME(const casadi_real** arg, casadi_real** res,
    casadi_int* iw, casadi_real* w, int mem)`` and ``NAME_work(...)`` for
    each, with ``casadi_real`` double and ``casadi_int`` long long int, so
    that a hand-written driver appended to it can call them in a loop.
    """
    with tempfile.TemporaryDirectory(prefix="vehid-gen-") as scratch:
        source_name = f"{function.name()}.c"
        generator = ca.CodeGenerator(source_name, {"with_header": False})
        for each in (function, *more):
            generator.add(each)
        # The prefix names the directory, so no process-wide working directory changes hands.
        generator.generate(scratch + os.sep)
        return Path(scratch, source_name).read_text()


# The lines of the first processor's entry in /proc/cpuinfo that tell one CPU design from another:
# x86 its model name and instruction-set flags; Arm its implementer, architecture, variant, part and
# features; RISC-V its ISA string and micro-architecture.
_CPU_FIELDS = ("model name", "flags", "CPU implementer", "CPU architecture", "CPU variant", "CPU part", "Features",
               "isa", "uarch")


def _cpu_identity(cpuinfo: str = "/proc/cpuinfo") -> str:
    """The machine type and CPU design and features, as far as the system tells."""
    identity = platform.machine()
    try:
        with open(cpuinfo) as handle:
            for line in handle:
                if line.split(":", 1)[0].strip() in _CPU_FIELDS:
                    identity += line
                if line.strip() == "" and identity != platform.machine():
                    break  # the first processor's entry is enough: a machine's CPUs share one design
    except OSError:
        identity += platform.processor()
    return identity


def _native_code(optimisation: str) -> bool:
    """Whether the flags build for this very CPU (``-march=native``, ``-mcpu=native``, ``-mtune=native``)."""
    return any(flag.endswith("=native") for flag in optimisation.split())


@functools.lru_cache(maxsize=None)
def _compiler_identity(compiler: str) -> str:
    """What ``compiler --version`` says, with the resolved file's size and time: two builds of the same
    version string from different packages still differ in the file. Asked once per compiler and process."""
    try:
        done = subprocess.run([compiler, "--version"], capture_output=True, text=True, timeout=60, check=False)
        version = done.stdout.strip() or done.stderr.strip()
    except (OSError, subprocess.SubprocessError) as exc:
        version = f"unknown ({type(exc).__name__})"
    try:
        status = Path(compiler).resolve().stat()
        version += f"\n{status.st_size} {status.st_mtime_ns}"
    except OSError:
        pass
    return version


@contextmanager
def _host_lock(path: Path) -> Iterator[None]:
    """An exclusive lock between processes (POSIX ``flock``): parallel workers on one host compile a
    library once, the others wait for it. Without ``fcntl`` each process may compile (still safe)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def build_shared_library(
    name: str,
    source: str,
    *,
    optimisation: str = "-O2",
    compiler: str | None = None,
) -> Path:
    """Compile C ``source`` into a shared library under the cache, once; return its path.

    The library's file name carries a hash of the source, the compiler and
    its version, flags, CasADi version and machine type, so a changed model,
    option or compiler compiles anew and an unchanged one is found on disk.
    Raises ``RuntimeError`` when no compiler is available or compilation fails.
    """
    compiler = compiler or find_c_compiler()
    if compiler is None:
        raise RuntimeError("no C compiler found (set CC or install gcc)")
    digest = hashlib.sha256()
    parts = [source, compiler, _compiler_identity(compiler), optimisation, ca.__version__, platform.machine()]
    if _native_code(optimisation):
        parts.append(_cpu_identity())  # native code must not be loaded on another CPU sharing the cache
    for part in parts:
        digest.update(part.encode())
        digest.update(b"\0")
    key = digest.hexdigest()[:20]
    directory = cache_directory()
    directory.mkdir(parents=True, exist_ok=True)
    library = directory / f"{name}_{key}.so"
    with _LOCK, _host_lock(directory / f".{name}_{key}.lock"):
        if library.exists():
            return library
        with tempfile.TemporaryDirectory(prefix="vehid-cc-") as scratch:
            source_path = Path(scratch, f"{name}.c")
            source_path.write_text(source)
            staged = Path(scratch, f"{name}.so")
            command = [compiler, "-shared", "-fPIC", *optimisation.split(), "-o", str(staged), source_path.name, "-lm"]
            completed = subprocess.run(command, cwd=scratch, capture_output=True, text=True, check=False)
            if completed.returncode != 0:
                raise RuntimeError(f"compiling {name} failed:\n{completed.stderr.strip()[-2000:]}")
            # Copy then rename so that a concurrent process never loads a half-written library.
            partial = directory / f".{name}_{key}.{os.getpid()}.tmp"
            shutil.copyfile(staged, partial)
            os.replace(partial, library)
    return library


_RECURSION_DRIVER = r"""
/* Simulation driver: x <- f(x, u_k, u_k+1, p) over the record, writing each
   step's output and the state before it. u, outputs and states are time-major. */
#include <stdlib.h>
#include <string.h>
int vehid_recursion(long long int n_samples, long long int n_states, long long int n_u, long long int n_out,
                    const double* u, const double* params, double* x, double* outputs, double* states) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  STEP_work(&sz_arg, &sz_res, &sz_iw, &sz_w);
  const casadi_real** arg = malloc(sizeof(casadi_real*) * (sz_arg > 4 ? sz_arg : 4));
  casadi_real** res = malloc(sizeof(casadi_real*) * (sz_res > 2 ? sz_res : 2));
  casadi_int* iw = malloc(sizeof(casadi_int) * (sz_iw > 0 ? sz_iw : 1));
  casadi_real* w = malloc(sizeof(casadi_real) * (sz_w > 0 ? sz_w : 1));
  double* next = malloc(sizeof(double) * (n_states > 0 ? n_states : 1));
  if (!arg || !res || !iw || !w || !next) return -1;
  int status = 0;
  long long int k;
  for (k = 0; k < n_samples; ++k) {
    memcpy(states + k * n_states, x, sizeof(double) * n_states);
    arg[0] = x;
    arg[1] = u + k * n_u;
    arg[2] = u + (k + 1 < n_samples ? k + 1 : k) * n_u;
    arg[3] = params;
    res[0] = next;
    res[1] = outputs + k * n_out;
    if (STEP(arg, res, iw, w, 0)) { status = 1; break; }
    memcpy(x, next, sizeof(double) * n_states);
  }
  free(arg); free(res); free(iw); free(w); free(next);
  return status;
}
"""


def compile_driver(
    step: ca.Function | tuple[ca.Function, ...],
    driver_source: str,
    *,
    library_name: str,
    entry: str,
    n_integers: int,
    n_arrays: int,
    optimisation: str = "-O2",
) -> Any:
    """Compile ``step`` with a hand-written C driver that calls it in a loop; return the driver.

    ``driver_source`` calls the step as ``STEP(...)`` and ``STEP_work(...)``;
    those names are replaced by the generated function's. The driver's entry
    point ``entry`` takes ``n_integers`` ``long long`` arguments, then
    ``n_arrays`` ``double*``, and returns an ``int`` status (the ctypes function).
    A tuple of functions is generated together; ``STEP`` names the first, the
    driver may call the others by their own names.
    """
    import ctypes

    steps = step if isinstance(step, tuple) else (step,)
    name = steps[0].name()
    driver = driver_source.replace("STEP_work", f"{name}_work").replace("STEP(", f"{name}(")
    library = build_shared_library(library_name, generate_c(*steps) + driver, optimisation=optimisation)
    function = getattr(ctypes.CDLL(str(library)), entry)
    function.argtypes = [ctypes.c_longlong] * n_integers + [ctypes.POINTER(ctypes.c_double)] * n_arrays
    function.restype = ctypes.c_int
    return function


class CompiledRecursion:
    """Run ``x_next, out = step(x, u_k, u_next, params)`` over a record in compiled code.

    Call with ``(x0 (n_states,), u (N, n_u), params (n_p,))``; returns
    ``(outputs (N, n_out), states (N, n_states))`` where ``states[k]`` is the
    state before step k and ``outputs[k]`` the step's second output.
    Without a C compiler the step is lifted with ``mapaccum`` in CasADi's
    virtual machine instead (with a :class:`NoCompilerWarning`).
    """

    def __init__(self, step: ca.Function, *, optimisation: str = "-O2"):
        self.step = step
        self.n_states = step.size1_in(0)
        self.n_u = step.size1_in(1)
        self.n_p = step.size1_in(3)
        self.n_out = step.size1_out(1)
        self._function = None
        if find_c_compiler() is None:
            warnings.warn(
                f"no C compiler found: {step.name()} runs in CasADi's virtual machine "
                "(install gcc or set CC for compiled speed)",
                NoCompilerWarning,
                stacklevel=2,
            )
            return
        self._function = compile_driver(
            step, _RECURSION_DRIVER, library_name=f"{step.name()}_recursion", entry="vehid_recursion",
            n_integers=4, n_arrays=5, optimisation=optimisation,
        )

    def __call__(self, x0, u, params):
        import ctypes

        x = np.array(x0, dtype=float).ravel().copy()
        u = np.ascontiguousarray(u, dtype=float)
        params = np.ascontiguousarray(params, dtype=float).ravel()
        n = u.shape[0]
        if self._function is None:
            lifted = self.step.mapaccum(f"{self.step.name()}_vm", n)
            u_next = np.vstack([u[1:], u[-1:]])
            xs, outs = lifted(x, u.T, u_next.T, np.tile(params[:, None], (1, n)))
            states = np.hstack([x[:, None], np.asarray(xs)[:, :-1]]).T
            return np.asarray(outs).T, states
        outputs = np.empty((n, self.n_out))
        states = np.empty((n, self.n_states))
        as_p = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
        status = self._function(
            n, self.n_states, self.n_u, self.n_out, as_p(u), as_p(params if params.size else np.zeros(1)),
            as_p(x), as_p(outputs), as_p(states),
        )
        if status:
            raise RuntimeError(f"the compiled recursion {self.step.name()} failed (status {status})")
        return outputs, states
