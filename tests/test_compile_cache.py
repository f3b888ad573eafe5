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
