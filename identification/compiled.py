"""Compile CasADi functions to native code, cached on disk.

A function is generated to C, hashed (generated source, compiler flags and
CasADi version), compiled once with the system C compiler into a shared
library under the cache directory and loaded with ``casadi.external``. A
second run with the same function finds the library and does not compile.
Where no C compiler is found, the function runs in CasADi's virtual machine
and a warning says so.

The cache directory is ``$VEHID_CACHE_DIR`` if set, else
``$XDG_CACHE_HOME/vehid`` or ``~/.cache/vehid``.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path

import casadi as ca

__all__ = [
    "cache_directory",
    "compile_function",
    "build_shared_library",
    "generate_c",
    "find_c_compiler",
    "NoCompilerWarning",
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


def generate_c(function: ca.Function) -> str:
    """The C source CasADi generates for ``function`` (no header, no main).

    It defines ``int NAME(const casadi_real** arg, casadi_real** res,
    casadi_int* iw, casadi_real* w, int mem)`` and ``NAME_work(...)``, with
    ``casadi_real`` double and ``casadi_int`` long long int, so that a
    hand-written driver appended to it can call the function in a loop.
    """
    with tempfile.TemporaryDirectory(prefix="vehid-gen-") as scratch:
        source_name = f"{function.name()}.c"
        generator = ca.CodeGenerator(source_name, {"with_header": False})
        generator.add(function)
        previous = os.getcwd()
        try:
            os.chdir(scratch)
            generator.generate()
        finally:
            os.chdir(previous)
        return Path(scratch, source_name).read_text()


def _cpu_identity() -> str:
    """The machine type and CPU model and flags, as far as the system tells."""
    identity = platform.machine()
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith(("model name", "flags")):
                    identity += line
                if line.strip() == "":
                    break
    except OSError:
        identity += platform.processor()
    return identity


def build_shared_library(
    name: str,
    source: str,
    *,
    optimisation: str = "-O2",
    compiler: str | None = None,
) -> Path:
    """Compile C ``source`` into a shared library under the cache, once; return its path.

    The library's file name carries a hash of the source, compiler, flags and
    CasADi version, so a changed model or option compiles anew and an
    unchanged one is found on disk. Raises ``RuntimeError`` when no compiler
    is available or compilation fails.
    """
    compiler = compiler or find_c_compiler()
    if compiler is None:
        raise RuntimeError("no C compiler found (set CC or install gcc)")
    digest = hashlib.sha256()
    parts = [source, compiler, optimisation, ca.__version__]
    if "-march=native" in optimisation:
        parts.append(_cpu_identity())  # native code must not be loaded on another CPU sharing the cache
    for part in parts:
        digest.update(part.encode())
        digest.update(b"\0")
    key = digest.hexdigest()[:20]
    directory = cache_directory()
    directory.mkdir(parents=True, exist_ok=True)
    library = directory / f"{name}_{key}.so"
    with _LOCK:
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
