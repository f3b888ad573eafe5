"""One module per ``vehid`` subcommand, discovered by :mod:`vehid.scenarios.cli`."""
