"""One module per ``vehid`` subcommand, discovered by :mod:`~vehid.scenarios.commands.parser`; the entry point is
:func:`~vehid.scenarios.commands.main.main`."""
