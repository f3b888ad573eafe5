"""Studies that wire the vehicle model and the identification methods together, and the ``vehid`` CLI."""
