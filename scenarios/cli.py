"""The ``vehid`` command line: its entry point and parser, under the name the console script calls.

The command line lives in :mod:`vehid.scenarios.commands`: :func:`main` in
:mod:`~vehid.scenarios.commands.main`, one module per subcommand, each a client
of the library's functions. Nothing here reads a parsed command line.
"""

from __future__ import annotations

import sys

from vehid.identification.jsonable import to_jsonable
from vehid.scenarios.commands.main import main
from vehid.scenarios.commands.parser import GROUPS, MESSAGE_LIMIT, build_parser, one_line

__all__ = ["main", "build_parser", "to_jsonable", "one_line", "MESSAGE_LIMIT", "GROUPS"]

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
