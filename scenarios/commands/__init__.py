"""One module per ``vehid`` subcommand, discovered by :mod:`scenarios.cli`."""
