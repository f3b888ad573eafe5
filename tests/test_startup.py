"""The command line starts without importing what it computes with (speed itself: benchmarks/startup.py)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

HEAVY = ("numpy", "scipy", "casadi", "h5py", "matplotlib")


def _imported_after(code: str) -> list[str]:
    """The heavy packages a fresh interpreter holds after running ``code``."""
    probe = f"import sys\n{code}\nprint(__import__('json').dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))"
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_help_and_the_package_import_none_of_the_heavy_libraries():
    """What made ``vehid --help`` take seconds: every command imported, and with them SciPy, CasADi, h5py."""
    assert _imported_after("from vehid.scenarios.cli import build_parser\nbuild_parser(['--help'])") == []
    assert _imported_after("import vehid.identification") == []
    # a public name still arrives from the package, importing its own module only
    assert "casadi" not in _imported_after("from vehid.identification import nrmse_fit")


LIGHT_COMMANDS = [("identify",), ("report",), ("linearize",), ("study", "textbook"), ("bench", "iekf"), ("simulate",),
                  ("handling",), ("calibrate",), ("study", "linear-example"), ("study", "handling"),
                  ("study", "envelope")]


def test_a_commands_help_imports_none_of_what_it_computes_with():
    """These commands import their plotting, filters, vehicle model and archives when they run: their
    ``--help`` needs argparse alone (``report --help`` took 3.8 s of CPU when it imported matplotlib on the
    way, ``study envelope --help`` 1 s for NumPy, CasADi and h5py). One interpreter builds each parser in
    turn, so the first command that imports a heavy library is the one named."""
    probe = (
        "import json, sys\n"
        "from vehid.scenarios.cli import build_parser\n"
        f"found = {{}}\nfor words in {LIGHT_COMMANDS!r}:\n"
        "    build_parser([*words, '--help'])\n"
        f"    found[' '.join(words)] = sorted(m for m in {HEAVY!r} if m in sys.modules)\n"
        "print(json.dumps(found))"
    )
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert list(found) == [" ".join(words) for words in LIGHT_COMMANDS]
    assert {command: heavy for command, heavy in found.items() if heavy} == {}


def test_the_modules_a_command_reads_its_options_with_are_light():
    """The data options, output paths and shared option groups that any command may import at start."""
    modules = ("vehid.scenarios.data_options", "vehid.scenarios.paths", "vehid.scenarios.commands.arguments",
               "vehid.scenarios.study_settings", "vehid.identification.choices", "vehid.vehicle.choices", "vehid.vehicle")
    assert _imported_after("\n".join(f"import {module}" for module in modules)) == []


def test_the_vehicle_packages_names_keep_their_meaning_whatever_is_imported_first():
    """The package imports its modules on demand; the module ``linearize`` imported before the function
    ``linearize`` is asked for must not take its name."""
    probe = ("import inspect\nimport vehid.vehicle.linearize\nimport vehid.vehicle.replay\n"
             "from vehid.vehicle import linearize, simulate, DEFAULT_SPEED, MANOEUVRES\n"
             "from vehid.vehicle.choices import MANOEUVRE_NAMES\n"
             "print(inspect.isfunction(linearize), inspect.isfunction(simulate), DEFAULT_SPEED,"
             " tuple(MANOEUVRES) == MANOEUVRE_NAMES)")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["True", "True", "20.0", "True"]


def test_modules_of_the_command_package_without_register_are_no_commands(tmp_path):
    """The parser and the option groups live beside the commands; the discovery skips them unimported."""
    from vehid.scenarios.commands.parser import command_headers, literal_header

    modules = {header["module"].rpartition(".")[2] for header in command_headers()}
    assert "identify" in modules and "parser" not in modules and "arguments" not in modules
    helper = tmp_path / "helper.py"
    helper.write_text('"""Shared code."""\nNAME = "x"\nGROUP = None\nHELP = "y"\n\ndef registered():\n    pass\n')
    assert literal_header(helper) is False
    command = tmp_path / "command.py"
    command.write_text('"""A command."""\nimport argparse\nNAME = "x"\nGROUP = None\nHELP = "y"\n\n'
                       'def register(parser):\n    pass\n')
    assert literal_header(command) == {"NAME": "x", "GROUP": None, "HELP": "y", "doc": "A command."}
    computed = tmp_path / "computed.py"  # a header that is no literal: the module is imported instead
    computed.write_text('NAME = "x"\nGROUP = None\nHELP = "y" + "z"\n\ndef register(parser):\n    pass\n')
    assert literal_header(computed) is None


def test_the_command_list_read_from_source_is_the_one_the_modules_define():
    from vehid.scenarios.commands.parser import command_headers, command_modules

    from_source = {(h["GROUP"], h["NAME"], h["HELP"], h["module"]) for h in command_headers()}
    imported = {(m.GROUP, m.NAME, m.HELP, m.__name__) for m in command_modules()}
    assert from_source == imported


def test_a_chosen_command_gets_the_same_arguments_as_in_the_full_parser():
    from vehid.scenarios.cli import build_parser

    def options(parser, *words):
        for word in words:
            sub = next(a for a in parser._actions if a.dest in ("command", "subcommand"))
            parser = sub.choices[word]
        return sorted(tuple(a.option_strings) for a in parser._actions)

    full = build_parser()
    for words in (("identify",), ("study", "handling")):
        chosen = build_parser([*words, "--json"])
        assert options(chosen, *words) == options(full, *words)
        assert len(options(chosen, *words)) > 5  # the command's own arguments, not the common three alone
