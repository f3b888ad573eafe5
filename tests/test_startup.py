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


@pytest.mark.parametrize("words", [("report",), ("linearize",), ("study", "textbook"), ("bench", "iekf")])
def test_a_commands_help_imports_none_of_what_it_computes_with(words):
    """These commands import their plotting, filters and archives when they run: their ``--help`` needs
    argparse alone (``report --help`` took 3.8 s of CPU when it imported matplotlib on the way)."""
    assert _imported_after(f"from vehid.scenarios.cli import build_parser\nbuild_parser({[*words, '--help']!r})") == []


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
