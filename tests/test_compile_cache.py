"""The compile cache's key: a library built by one compiler is never loaded for another."""

from __future__ import annotations

import ctypes
import os
import shutil
import stat

import pytest

from vehid.identification import compiled

SOURCE = "int vehid_answer(void) { return 42; }\n"


def _wrapper(folder, real: str, version: str):
    """A compiler that compiles with ``real`` and names itself ``version``, as an upgraded one would."""
    script = folder / "cc"
    script.write_text(f'#!/bin/sh\nif [ "$1" = --version ]; then echo "{version}"; exit 0; fi\nexec "{real}" "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)
    return str(script)


@pytest.mark.skipif(compiled.find_c_compiler() is None or os.name != "posix", reason="needs a C compiler and sh")
def test_a_compiler_of_another_version_compiles_anew(tmp_path, monkeypatch):
    monkeypatch.setenv("VEHID_CACHE_DIR", str(tmp_path / "cache"))
    real = compiled.find_c_compiler()
    (tmp_path / "old").mkdir()
    (tmp_path / "new").mkdir()
    old = _wrapper(tmp_path / "old", real, "cc 1.0")
    new = _wrapper(tmp_path / "new", real, "cc 2.0")
    # the same file name at the same path after an upgrade: only the version tells them apart
    shutil.copy2(new, tmp_path / "new_copy")
    first = compiled.build_shared_library("answer", SOURCE, compiler=old)
    again = compiled.build_shared_library("answer", SOURCE, compiler=old)
    assert again == first  # found on disk, not compiled twice
    os.replace(tmp_path / "new_copy", old)  # the compiler at the old path now says 2.0
    compiled._compiler_identity.cache_clear()  # a new process would ask it again
    upgraded = compiled.build_shared_library("answer", SOURCE, compiler=old)
    assert upgraded != first and upgraded.exists()
    assert ctypes.CDLL(str(upgraded)).vehid_answer() == 42
    assert compiled.build_shared_library("answer", SOURCE, compiler=new) != first


@pytest.mark.skipif(compiled.find_c_compiler() is None, reason="needs a C compiler")
def test_native_code_built_on_one_cpu_is_not_loaded_on_another(tmp_path, monkeypatch):
    """Two machines sharing a cache (a home folder on a network drive): code built for this very CPU is
    keyed by the CPU, so the other machine compiles its own; portable code is shared."""
    monkeypatch.setenv("VEHID_CACHE_DIR", str(tmp_path / "cache"))
    native = "-O2 -march=native" if compiled.platform.machine() in ("x86_64", "AMD64", "i686") else "-O2 -mcpu=native"
    monkeypatch.setattr(compiled, "_cpu_identity", lambda: "x86_64 model name : one CPU, flags : sse2 avx2")
    first = compiled.build_shared_library("answer", SOURCE, optimisation=native)
    assert compiled.build_shared_library("answer", SOURCE, optimisation=native) == first  # same CPU: found
    portable = compiled.build_shared_library("answer", SOURCE, optimisation="-O2")
    monkeypatch.setattr(compiled, "_cpu_identity", lambda: "x86_64 model name : one CPU, flags : sse2 avx2 avx512f")
    other = compiled.build_shared_library("answer", SOURCE, optimisation=native)
    assert other != first and other.exists()
    assert ctypes.CDLL(str(other)).vehid_answer() == 42
    assert compiled.build_shared_library("answer", SOURCE, optimisation="-O2") == portable


@pytest.mark.parametrize("flags, native", [("-O3 -march=native", True), ("-O2 -mcpu=native", True),
                                           ("-O1 -mtune=native", True), ("-O3", False), ("-O2 -march=x86-64", False)])
def test_every_flag_that_builds_for_this_cpu_keys_by_it(flags, native):
    assert compiled._native_code(flags) is native


# The first entries of /proc/cpuinfo on two Arm machines and two x86 machines (abridged).
_ARM = "processor\t: 0\nBogoMIPS\t: 50.00\nFeatures\t: fp asimd evtstrm aes pmull sha1 sha2 crc32\n" \
       "CPU implementer\t: 0x41\nCPU architecture: 8\nCPU variant\t: 0x3\nCPU part\t: {part}\n\nprocessor\t: 1\n"
_X86 = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel name\t: {name}\nflags\t\t: fpu sse2 {flags}\n\n" \
       "processor\t: 1\nmodel name\t: another\n"


@pytest.mark.parametrize("first, second", [
    (_ARM.format(part="0xd0c"), _ARM.format(part="0xd40")),  # Neoverse N1 and V1: same features listed
    (_X86.format(name="Xeon", flags="avx2"), _X86.format(name="Xeon", flags="avx2 avx512f")),
    (_X86.format(name="Xeon", flags="avx2"), _X86.format(name="EPYC", flags="avx2")),
])
def test_the_cpu_identity_tells_cpu_designs_apart(tmp_path, first, second):
    """What /proc/cpuinfo says of the first processor enters the key, on x86 and on Arm alike."""
    (tmp_path / "a").write_text(first)
    (tmp_path / "b").write_text(second)
    identity = compiled._cpu_identity(str(tmp_path / "a"))
    assert identity != compiled._cpu_identity(str(tmp_path / "b"))
    assert identity == compiled._cpu_identity(str(tmp_path / "a"))
    assert "another" not in identity and "processor" not in identity  # the first processor's entry only
