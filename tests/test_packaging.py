"""The workbench installs as one package, ``vehid``, whose subpackages are the
repository's top-level folders; nothing else lands at the top level.

These tests build from a copy of the tracked files (a fresh clone without
``.venv`` or build leftovers), so they check what a user's install gets.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SUBPACKAGES = ("vehicle", "identification", "scenarios")


def _run(command, cwd, env=None, timeout=300):
    done = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{command} failed:\n{done.stdout}\n{done.stderr}"
    return done


@pytest.fixture(scope="module")
def fresh_copy(tmp_path_factory) -> Path:
    """The tracked files of the working tree, as a clone would have them."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    target = tmp_path_factory.mktemp("clone") / "workbench"
    for name in listed.decode().split("\0"):
        if name and not name.startswith("tests/data/") and (ROOT / name).is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, target / name)
    return target


@pytest.fixture(scope="module")
def wheel(fresh_copy, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(out),
          str(fresh_copy)], cwd=out)
    (found,) = out.glob("vehid-*.whl")
    return found


def test_the_installed_package_is_vehid_with_the_three_folders_as_subpackages():
    import vehid
    from vehid import identification, scenarios, vehicle

    for module, folder in ((identification, "identification"), (scenarios, "scenarios"), (vehicle, "vehicle")):
        assert Path(module.__file__).resolve() == ROOT / folder / "__init__.py"
    assert Path(vehid.__file__).resolve() == ROOT / "__init__.py"


def test_generic_top_level_names_are_not_installed(tmp_path):
    # run outside the repository, so the working directory cannot supply the folders
    for name in SUBPACKAGES:
        done = subprocess.run([sys.executable, "-c", f"import {name}"], cwd=tmp_path, capture_output=True, text=True)
        assert done.returncode != 0 and "ModuleNotFoundError" in done.stderr, name
    _run([sys.executable, "-c", "import vehid.identification.filtering.iekf, vehid.vehicle.model, vehid.scenarios.cli"],
         cwd=tmp_path)


def test_console_script_and_module_entry_point(tmp_path):
    script = Path(sys.executable).with_name("vehid")
    assert script.exists(), "the console script is installed beside the interpreter"
    assert "identify" in _run([str(script), "--help"], cwd=tmp_path).stdout
    assert "identify" in _run([sys.executable, "-m", "vehid.scenarios.cli", "--help"], cwd=tmp_path).stdout


def test_wheel_holds_only_the_vehid_package_and_its_script(wheel):
    with zipfile.ZipFile(wheel) as archive:
        names = archive.namelist()
        entry_points = next(n for n in names if n.endswith("entry_points.txt"))
        scripts = archive.read(entry_points).decode()
    top = {name.split("/")[0] for name in names if not name.split("/")[0].endswith(".dist-info")}
    assert top == {"vehid"}
    for folder in SUBPACKAGES:
        assert f"vehid/{folder}/__init__.py" in names
    assert "vehid/scenarios/commands/identify.py" in names
    assert "vehid = vehid.scenarios.cli:main" in scripts
    assert not any(name.startswith("vehid/tests/") or name.startswith("vehid/benchmarks/") for name in names)


def test_regular_install_from_a_fresh_clone_runs_the_command_line(wheel, tmp_path):
    target = tmp_path / "site"
    _run([sys.executable, "-m", "pip", "install", "--no-deps", "--quiet", "--target", str(target), str(wheel)],
         cwd=tmp_path)
    env = {**os.environ, "PYTHONPATH": str(target)}
    done = _run([sys.executable, "-c", "import vehid.identification.models.modal as m; print(m.__file__)"], cwd=tmp_path,
                env=env)
    assert Path(done.stdout.strip()).is_relative_to(target)
    assert "linearize" in _run([sys.executable, "-m", "vehid.scenarios.cli", "--help"], cwd=tmp_path, env=env).stdout


def test_editable_install_from_a_fresh_clone_follows_its_sources(fresh_copy, tmp_path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp_path)
    python = venv / "bin" / "python"
    # the new environment sees this one's packages (numpy, casadi, pip, setuptools) through a path file
    site = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=tmp_path).stdout.strip())
    ours = [p for p in sys.path if p.endswith("site-packages")]
    (site / "parent.pth").write_text("\n".join(ours) + "\n")
    _run([str(python), "-m", "pip", "install", "--no-deps", "--quiet", "-e",
          str(fresh_copy)], cwd=tmp_path)
    done = _run([str(python), "-c", "import vehid.identification as m; print(m.__file__)"], cwd=tmp_path)
    assert Path(done.stdout.strip()).resolve() == (fresh_copy / "identification" / "__init__.py").resolve()
    assert "identify" in _run([str(venv / "bin" / "vehid"), "--help"], cwd=tmp_path).stdout
